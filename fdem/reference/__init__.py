"""Closed forms that the verification checks against: Hoek-Bray planar sliding, Newmark's block.

Imports nothing else of the package (ground floor).
"""
