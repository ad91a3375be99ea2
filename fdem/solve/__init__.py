"""The time loop: the mechanical :class:`~fdem.solve.model.Model`, the :class:`~fdem.solve.simulation.Simulation`,
its energy ledger and damping, the static (geostatic) start, and checkpoints.
"""
