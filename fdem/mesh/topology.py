"""The exploded FDEM mesh: node splitting and crack-element insertion.

Every triangle owns its three nodes (node ``3*t + k`` is corner ``k`` of triangle ``t``), so
neighbouring triangles are tied only through four-node crack elements, one per interior edge
(Munjiza 2004, *The Combined Finite-Discrete Element Method*, ch. 8).

Crack-element node order
------------------------
For an interior edge shared by triangles A and B, with A traversing the edge ``p -> q``
counter-clockwise (so B traverses it ``q -> p``), the element's nodes are::

    crack_nodes[c] = [A_p, A_q, B_q, B_p]

Nodes 0 and 3 coincide in the reference state, and so do nodes 1 and 2. The unit tangent is
that of the element's mid-line, ``t = (m1 - m0)/|m1 - m0|`` with ``m0 = (x0 + x3)/2`` and
``m1 = (x1 + x2)/2`` (``(x1 - x0)/|x1 - x0|`` in the reference state), and the normal
``n = (t_y, -t_x)`` points out of A into B, so the opening at end 0 is ``(x3 - x0) . n`` and the
slip ``(x3 - x0) . t``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable
import numpy as np
from fdem.mesh.mesh import Mesh
from fdem.mesh.triangles import check_triangles, triangle_areas

__all__ = ["INTACT", "Topology", "build_topology", "ConformingTopology"]


INTACT = 0
"""Joint-set tag of a crack element that is an intact rock bridge."""


@dataclass(frozen=True)
class Topology:
    """Exploded mesh with crack elements.

    Attributes
    ----------
    x0 : (n_nodes, 2) float64
        Reference coordinates of the exploded nodes, ``n_nodes = 3 * n_tri`` [m].
    triangles : (n_tri, 3) int64
        Exploded node ids of each triangle, ``triangles[t] = [3t, 3t+1, 3t+2]``, counter-clockwise.
    mesh_node : (n_nodes,) int64
        Id of the shared mesh node that each exploded node was split from.
    triangle_body : (n_tri,) int32
        Body id of each triangle (bodies meet only through contact).
    crack_nodes : (n_crack, 4) int64
        ``[A_p, A_q, B_q, B_p]`` as in the module docstring.
    crack_triangles : (n_crack, 2) int64
        Triangles A and B on either side of each crack element.
    crack_tag : (n_crack,) int32
        0 for an intact rock bridge, ``j >= 1`` for an edge on DFN joint set ``j``.
    crack_length0 : (n_crack,) float64
        Reference edge length [m].
    boundary_edges : (n_boundary, 2) int64
        Exploded node ids of each external edge, in the counter-clockwise order of its triangle.
    boundary_triangle : (n_boundary,) int64
        Triangle that owns each external edge.
    mesh : Mesh
        The conforming mesh this topology was exploded from (physical groups live there).
    """

    x0: np.ndarray
    triangles: np.ndarray
    mesh_node: np.ndarray
    triangle_body: np.ndarray
    crack_nodes: np.ndarray
    crack_triangles: np.ndarray
    crack_tag: np.ndarray
    crack_length0: np.ndarray
    boundary_edges: np.ndarray
    boundary_triangle: np.ndarray
    mesh: Mesh = field(repr=False)

    @property
    def n_nodes(self) -> int:
        return self.x0.shape[0]

    @property
    def n_triangles(self) -> int:
        return self.triangles.shape[0]

    @property
    def n_cracks(self) -> int:
        return self.crack_nodes.shape[0]

    @cached_property
    def triangle_area0(self) -> np.ndarray:
        """(n_tri,) reference areas [m^2]."""
        return triangle_areas(self.x0, self.triangles)

    def nodes_where(self, predicate: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
        """Exploded node ids whose reference position satisfies ``predicate(x, y)`` (vectorised)."""
        mask = np.asarray(predicate(self.x0[:, 0], self.x0[:, 1]), dtype=bool)
        if mask.shape != (self.n_nodes,):
            raise ValueError(
                f"node predicate must return one boolean per node ({self.n_nodes}), got shape {mask.shape}"
            )
        return np.flatnonzero(mask)

    def nodes_in_group(self, name: str) -> np.ndarray:
        """Exploded node ids lying on the curves of physical group ``name`` (e.g. ``"bottom"``)."""
        mesh_nodes = self.mesh.group_nodes(name)
        return np.flatnonzero(np.isin(self.mesh_node, mesh_nodes))


def _half_edges(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Half-edge k of triangle t runs from corner k to corner k+1 (counter-clockwise).

    Returns the mesh-node start/end of each half-edge and its exploded start node, in the order
    ``h = 3 t + k``.
    """
    n_tri = triangles.shape[0]
    start = triangles.ravel()
    end = np.roll(triangles, -1, axis=1).ravel()
    exploded_start = np.arange(3 * n_tri, dtype=np.int64)
    return start, end, exploded_start


def _exploded_end(h: np.ndarray) -> np.ndarray:
    """Exploded node at the end of half-edge ``h = 3t + k``: corner ``(k+1) % 3`` of triangle t."""
    t, k = np.divmod(h, 3)
    return 3 * t + (k + 1) % 3


def build_topology(mesh: Mesh) -> Topology:
    """Explode a conforming triangle mesh and insert a crack element on every interior edge.

    Edges on curves of a joint-set physical group get that set's tag; all others are intact (0).
    Cost is O(n log n) in the number of triangles (one sort of the edge keys).
    """
    points = np.ascontiguousarray(mesh.points, dtype=np.float64)
    tris = np.ascontiguousarray(mesh.triangles, dtype=np.int64)
    check_triangles(points, tris)
    n_tri = tris.shape[0]
    n_pts = points.shape[0]

    start, end, _ = _half_edges(tris)
    lo, hi = np.minimum(start, end), np.maximum(start, end)
    key = lo * n_pts + hi
    order = np.argsort(key, kind="stable")
    key_sorted = key[order]

    # Runs of equal keys: length 1 -> external edge, 2 -> interior edge, more -> non-manifold.
    run_start = np.flatnonzero(np.r_[True, key_sorted[1:] != key_sorted[:-1]])
    run_len = np.diff(np.r_[run_start, key_sorted.size])
    if np.any(run_len > 2):
        r = run_start[np.argmax(run_len > 2)]
        h = order[r]
        raise ValueError(
            f"non-manifold mesh: edge between mesh nodes {start[h]} and {end[h]} at "
            f"{points[start[h]]} - {points[end[h]]} is shared by more than two triangles"
        )
    interior_runs = run_start[run_len == 2]
    h_a = order[interior_runs]
    h_b = order[interior_runs + 1]
    # Two triangles sharing an edge traverse it in opposite directions only if both are CCW.
    if np.any(start[h_a] != end[h_b]):
        raise ValueError("inconsistent triangle orientation across an interior edge")

    crack_nodes = np.column_stack([h_a, _exploded_end(h_a), h_b, _exploded_end(h_b)]).astype(np.int64)
    crack_triangles = np.column_stack([h_a // 3, h_b // 3]).astype(np.int64)
    seg = points[end[h_a]] - points[start[h_a]]
    crack_length0 = np.hypot(seg[:, 0], seg[:, 1])

    crack_tag = np.zeros(h_a.size, dtype=np.int32)
    joint_keys, joint_sets = mesh.joint_edge_keys()
    if joint_keys.size:
        crack_keys = key[h_a]
        pos = np.searchsorted(joint_keys, crack_keys)
        pos = np.minimum(pos, joint_keys.size - 1)
        hit = joint_keys[pos] == crack_keys
        crack_tag[hit] = joint_sets[pos[hit]]

    boundary_runs = run_start[run_len == 1]
    h_ext = np.sort(order[boundary_runs])
    boundary_edges = np.column_stack([h_ext, _exploded_end(h_ext)]).astype(np.int64)

    x0 = points[tris].reshape(-1, 2).copy()
    return Topology(
        x0=x0,
        triangles=np.arange(3 * n_tri, dtype=np.int64).reshape(n_tri, 3),
        mesh_node=tris.ravel().copy(),
        triangle_body=np.asarray(mesh.triangle_body, dtype=np.int32).copy(),
        crack_nodes=crack_nodes,
        crack_triangles=crack_triangles,
        crack_tag=crack_tag,
        crack_length0=crack_length0,
        boundary_edges=boundary_edges,
        boundary_triangle=h_ext // 3,
        mesh=mesh,
    )


@dataclass(frozen=True)
class ConformingTopology:
    """A conforming (shared-node) triangle mesh with the interface of :class:`fdem.mesh.topology.Topology`.

    Attributes
    ----------
    x0 : (n_nodes, 2) float64
        Reference node coordinates [m] (the mesh points).
    triangles : (n_tri, 3) int64
        Node ids of each triangle, counter-clockwise.
    mesh_node : (n_nodes,) int64
        Identity map (node ``i`` is mesh point ``i``).
    triangle_body : (n_tri,) int32
        Body id of each triangle.
    crack_nodes : (0, 4) int64
        No crack elements in a conforming mesh.
    crack_tag : (0,) int32
    mesh : Mesh
    """

    x0: np.ndarray
    triangles: np.ndarray
    mesh_node: np.ndarray
    triangle_body: np.ndarray
    mesh: Mesh = field(repr=False)
    crack_nodes: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.int64))
    crack_triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    crack_tag: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    crack_length0: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def from_mesh(cls, mesh: Mesh) -> "ConformingTopology":
        points = np.ascontiguousarray(mesh.points, dtype=np.float64)
        tris = np.ascontiguousarray(mesh.triangles, dtype=np.int64)
        check_triangles(points, tris)
        used = np.zeros(len(points), bool)
        used[tris.ravel()] = True
        if not used.all():
            raise ValueError(f"mesh has {int((~used).sum())} point(s) in no triangle, "
                             f"first: point {int(np.flatnonzero(~used)[0])}; remove them before building a model")
        return cls(x0=points, triangles=tris, mesh_node=np.arange(len(points), dtype=np.int64),
                   triangle_body=np.asarray(mesh.triangle_body, np.int32).copy(), mesh=mesh)

    @property
    def n_nodes(self) -> int:
        return self.x0.shape[0]

    @property
    def n_triangles(self) -> int:
        return self.triangles.shape[0]

    @property
    def n_cracks(self) -> int:
        return 0

    @cached_property
    def triangle_area0(self) -> np.ndarray:
        return triangle_areas(self.x0, self.triangles)

    def nodes_where(self, predicate) -> np.ndarray:
        mask = np.asarray(predicate(self.x0[:, 0], self.x0[:, 1]), dtype=bool)
        if mask.shape != (self.n_nodes,):
            raise ValueError(f"node predicate must return one boolean per node ({self.n_nodes}), got shape {mask.shape}")
        return np.flatnonzero(mask)

    def nodes_in_group(self, name: str) -> np.ndarray:
        return self.mesh.group_nodes(name)
