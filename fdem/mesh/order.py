"""Memory order of a mesh: triangles along a space-filling curve, points in order of first use.

Why it matters: in the exploded mesh node ``3t + k`` is corner ``k`` of triangle ``t``, so the
triangle pass streams memory whatever the order, but a crack element (and a contact pair) reads
the nodes of two neighbouring triangles. Those nodes sit close in memory only where neighbouring
triangles have close numbers. Gmsh numbers the triangles of a jointed section in patches (one
front after another between the embedded joints), so neighbours can be tens of thousands of
rows apart. Numbering the triangles along a Hilbert curve through their centroids puts
neighbours in space next to each other in memory (the curve is continuous and fills the plane
cell by cell), and numbering the points in the order the renumbered triangles first use them
carries the same order to the shared nodes, hence to the edge keys that order the crack
elements (:func:`fdem.mesh.topology.build_topology`).

References: D. Hilbert (1891), Ueber die stetige Abbildung einer Linie auf ein Flaechenstueck,
Math. Ann. 38, 459-460; H. S. Warren, *Hacker's Delight*, 2nd ed. (2013), ch. 16 (the
bit-by-bit conversion from cell coordinates to the distance along the curve, and faster
variants); G. M. Morton (1966), *A computer oriented geodetic data base and a new
technique in file sequencing*, IBM.
"""
from __future__ import annotations

import numpy as np
from fdem.mesh.mesh import Mesh

__all__ = ["ORDERS", "BITS", "grid_coordinates", "hilbert_key", "morton_key", "curve_key", "triangle_order",
           "point_order", "renumber"]


ORDERS = ("hilbert", "morton")
"""Space-filling curves :func:`renumber` knows; ``None`` keeps a mesh's own numbering."""


BITS = 16
"""Bits per axis of the grid the curves run on: 65,536 cells a side, far finer than any mesh
the solver steps, so two triangles share a cell only if their centroids nearly coincide."""


def grid_coordinates(points: np.ndarray, bits: int = BITS) -> tuple[np.ndarray, np.ndarray]:
    """Integer cell coordinates ``(i, j)`` in ``[0, 2^bits)`` of ``points`` (n, 2) [m].

    ``i = floor((x - x_min) / L * 2^bits)`` (clipped to ``2^bits - 1``), likewise ``j``, with
    one scale ``L`` (the larger side of the bounding box) for both axes: square cells keep the
    curve's neighbourhoods round, so a long thin section is not stretched along its length.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got {p.shape}")
    if not 1 <= bits <= 31:
        raise ValueError(f"bits must lie in [1, 31], got {bits}")
    n = 1 << bits
    if p.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    lo = p.min(axis=0)
    span = float(np.ptp(p, axis=0).max())
    scale = n / span if span > 0 else 0.0
    q = np.minimum(np.floor((p - lo) * scale), n - 1).astype(np.int64)
    return q[:, 0], q[:, 1]


def hilbert_key(points: np.ndarray, bits: int = BITS) -> np.ndarray:
    """(n,) int64 distance along the Hilbert curve of order ``bits`` of each point (n, 2).

    Bit by bit from the coarsest level, with ``s = 2^(bits-1), ..., 1`` (Warren 2013, ch. 16):
    ``r_x = (i & s) > 0``, ``r_y = (j & s) > 0``, ``d += s^2 ((3 r_x) XOR r_y)``; then the
    quadrant is turned into the curve's base orientation: if ``r_y = 0``, reflect
    (``i, j -> N-1-i, N-1-j`` when ``r_x = 1``) and swap ``i`` and ``j``. Consecutive keys are
    edge-adjacent cells (the curve is continuous), which is what makes it a memory order.
    """
    i, j = grid_coordinates(points, bits)
    n = np.int64(1 << bits)
    d = np.zeros(i.shape, dtype=np.int64)
    s = n >> 1
    while s > 0:
        rx = (i & s) > 0
        ry = (j & s) > 0
        d += s * s * ((3 * rx.astype(np.int64)) ^ ry.astype(np.int64))
        reflect = rx & ~ry
        i = np.where(reflect, n - 1 - i, i)
        j = np.where(reflect, n - 1 - j, j)
        i, j = np.where(ry, i, j), np.where(ry, j, i)
        s >>= 1
    return d


def morton_key(points: np.ndarray, bits: int = BITS) -> np.ndarray:
    """(n,) int64 Morton (Z-order) key of each point (n, 2): the bits of ``i`` and ``j``
    interleaved, ``d = sum_b (bit_b(i) 2^(2b) + bit_b(j) 2^(2b+1))`` (Morton 1966).

    Cheaper than Hilbert but with jumps between quadrants (the Z's diagonal strokes)."""
    i, j = grid_coordinates(points, bits)
    d = np.zeros(i.shape, dtype=np.int64)
    for b in range(bits):
        d |= ((i >> b) & 1) << (2 * b)
        d |= ((j >> b) & 1) << (2 * b + 1)
    return d


def curve_key(points: np.ndarray, order: str = "hilbert", bits: int = BITS) -> np.ndarray:
    """The key of ``order`` (one of :data:`ORDERS`) of each point."""
    if order == "hilbert":
        return hilbert_key(points, bits)
    if order == "morton":
        return morton_key(points, bits)
    raise ValueError(f"unknown mesh order {order!r}; choose from {list(ORDERS)} or None")


def triangle_order(points: np.ndarray, triangles: np.ndarray, order: str = "hilbert") -> np.ndarray:
    """(n_tri,) old triangle ids in their new order: sorted by the curve key of the centroids
    ``(p0 + p1 + p2) / 3``; ties (coincident cells) keep their old relative order."""
    centroids = np.asarray(points, dtype=np.float64)[np.asarray(triangles)].mean(axis=1)
    return np.argsort(curve_key(centroids, order), kind="stable")


def point_order(triangles: np.ndarray, n_points: int) -> np.ndarray:
    """(n_points,) old point ids in their new order: the order in which ``triangles`` (already
    renumbered, read row by row) first use them; points no triangle uses go last, in their old
    order."""
    flat = np.asarray(triangles, dtype=np.int64).ravel()
    first = np.full(n_points, flat.size, dtype=np.int64)
    np.minimum.at(first, flat, np.arange(flat.size, dtype=np.int64))
    return np.argsort(first, kind="stable")


def renumber(mesh: Mesh, order: str | None = "hilbert") -> Mesh:
    """The same mesh with triangles along the curve ``order`` and points by first use.

    Every per-triangle array (``triangle_body``) moves with its triangle and every node id
    (``triangles``, ``lines``) is mapped to the new point numbers; corners keep their
    counter-clockwise order, line elements and physical groups keep theirs. ``order=None``
    returns ``mesh`` itself (a user's numbering is kept unless renumbering is asked for).
    """
    if order is None:
        return mesh
    tri_old = triangle_order(mesh.points, mesh.triangles, order)
    triangles = np.asarray(mesh.triangles, dtype=np.int64)[tri_old]
    pt_old = point_order(triangles, mesh.points.shape[0])
    new_id = np.empty_like(pt_old)
    new_id[pt_old] = np.arange(pt_old.size, dtype=np.int64)
    lines = np.asarray(mesh.lines, dtype=np.int64)
    return Mesh(
        points=np.ascontiguousarray(mesh.points[pt_old]),
        triangles=new_id[triangles],
        triangle_body=np.asarray(mesh.triangle_body)[tri_old].copy(),
        lines=new_id[lines] if lines.size else lines.copy(),
        line_group=np.asarray(mesh.line_group).copy(),
        group_names=tuple(mesh.group_names),
    )
