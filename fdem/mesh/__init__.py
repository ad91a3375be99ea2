"""Triangles of the section: triangle geometry, the :class:`~fdem.mesh.mesh.Mesh` and its files, Gmsh
triangulation, quality, and the exploded topology with its crack elements.
"""
