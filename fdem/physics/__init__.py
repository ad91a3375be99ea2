"""The laws and their hosts: the elastic law, stable steps, crack-element properties and the
strength-reduction factor, the crack-element set, contact, boundaries and base shaking.
"""
