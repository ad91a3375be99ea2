"""The slope section before meshing: polygons, joint sets, the clipped DFN (:class:`~fdem.geometry.section.Geometry`).

Imports nothing else of the package.
"""
