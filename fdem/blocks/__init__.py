"""Rigid blocks cut out of a :class:`~fdem.geometry.section.Geometry` by its joints, and their
contact problem as a second-order cone program (docs/rigid_blocks.md).

* :mod:`~fdem.blocks.assembly`: the blocks and interfaces (joints, rock bridges, contacts between
  bodies, supports) of a geometry: :func:`~fdem.blocks.assembly.block_system`.
* :mod:`~fdem.blocks.strength`: the Mohr-Coulomb strength of each interface tag, reduced by F.
* :mod:`~fdem.blocks.cone`: the one place that calls the conic solver (Clarabel).
* :mod:`~fdem.blocks.limit`: static limit analysis: equilibrium, factor of safety by strength
  reduction, pseudo-static yield acceleration, collapse mechanism.
* :mod:`~fdem.blocks.dynamics`: hard and soft blocks, one cone program per implicit step.
* :mod:`~fdem.blocks.newmark`: the Newmark displacement of a mechanism.
* :mod:`~fdem.blocks.slope`: a slope's analysis in one call, and the line the slope cases print.
* :mod:`~fdem.blocks.pictures`: blocks and mechanisms drawn.

Floor 5: imports only ``geometry`` and ``io`` of the package.
"""
