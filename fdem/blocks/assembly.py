"""The rigid blocks that the joints cut out of a :class:`~fdem.geometry.section.Geometry`, and
their interfaces (:func:`block_system`, :class:`BlockSystem`).

The same clipped, merged and split joint network the mesher conforms to
(:meth:`Geometry.dfn`) is used, so the blocks of the rigid-block model and the crack elements
of the FDEM model sit on the same joints. Three steps per body:

1. *Rock bridges.* A non-persistent joint ends inside intact rock. Its line is continued from
   each free end to the first joint, bridge or boundary it meets: that continuation is a rock
   bridge (tag 0, the intact rock's strength), the shortest path along which the intact rock
   must break for the joint to free a block. A brick fabric, whose cross joints end on the
   persistent ones, needs none.
2. *Blocks.* The body outline, the joints and the bridges, noded at every crossing
   (:func:`fdem.geometry.dfn.split_at_crossings`), form a planar graph; its bounded faces,
   traced edge by edge with the face on the left, are the blocks.
3. *Interfaces.* An edge between two blocks of a body is an interface tagged with its joint
   set (>= 1) or 0 for a rock bridge; an overlap of outlines of two bodies is a contact (tag
   :data:`CONTACT`). A block with an edge on a support line of the section (by default its
   bottom, left and right sides, where the FDEM model is fixed or on rollers) is fixed.

Units: m; block properties per metre of thickness (plane section).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from fdem.geometry.dfn import cluster_points, split_at_crossings
from fdem.geometry.section import Geometry

__all__ = ["CONTACT", "BRIDGE", "BlockSystem", "block_system", "polygon_properties", "rock_bridges",
           "polygonize", "merge_small_faces", "intact_cells", "SUPPORT_SIDES"]

CONTACT = -1
"""Tag of an interface between blocks of two different bodies (frictional contact)."""
BRIDGE = 0
"""Tag of a rock bridge (intact rock), as the crack elements' ``INTACT``."""
_OUTLINE = -2  # an edge of a body's outline (internal label)

SUPPORT_SIDES = ("bottom", "left", "right")
"""Sides of the section's bounding box that hold the blocks touching them (the FDEM model's
fixed base and side rollers)."""


@dataclass(frozen=True)
class BlockSystem:
    """Rigid blocks of a plane section and the interfaces between them.

    Blocks (``n``):

    polygons : tuple of (m_i, 2) float64, counter-clockwise corners [m]
    area : (n,) [m^2]; centroid : (n, 2) [m]
    polar_moment : (n,) second moment of area about the centroid ``int r^2 dA`` [m^4]
        (times the density: the moment of inertia per metre [kg m])
    body : (n,) int, the :class:`Geometry` body each block belongs to
    fixed : (n,) bool, held by a support (no degree of freedom)

    Interfaces (``k``):

    blocks : (k, 2) int, the two blocks ``(a, b)``
    ends : (k, 2, 2) float64, the interface's end points [m]
    normal : (k, 2) unit normal pointing from ``b`` into ``a``
    tag : (k,) int: joint set (>= 1), :data:`BRIDGE` (0) or :data:`CONTACT` (-1)
    """

    polygons: tuple
    area: np.ndarray
    centroid: np.ndarray
    polar_moment: np.ndarray
    body: np.ndarray
    fixed: np.ndarray
    blocks: np.ndarray
    ends: np.ndarray
    normal: np.ndarray
    tag: np.ndarray
    n_pruned: int = 0
    n_glued: int = 0
    bridges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))

    @property
    def n_blocks(self) -> int:
        return len(self.area)

    @property
    def n_interfaces(self) -> int:
        return len(self.tag)

    @property
    def length(self) -> np.ndarray:
        """(k,) interface lengths [m]."""
        return np.linalg.norm(self.ends[:, 1] - self.ends[:, 0], axis=1)

    @property
    def tangent(self) -> np.ndarray:
        """(k, 2) unit tangent, the normal turned 90 degrees counter-clockwise."""
        return np.column_stack([-self.normal[:, 1], self.normal[:, 0]])

    @property
    def free(self) -> np.ndarray:
        """Indices of the blocks that can move."""
        return np.flatnonzero(~self.fixed)

    def tag_lengths(self) -> dict[int, float]:
        """Total interface length [m] per tag."""
        L = self.length
        return {int(t): float(L[self.tag == t].sum()) for t in np.unique(self.tag)}

    def summary(self) -> dict:
        return {"n_blocks": self.n_blocks, "n_free": int((~self.fixed).sum()), "n_interfaces": self.n_interfaces,
                "interface_length_m_by_tag": self.tag_lengths(), "n_bridges": len(self.bridges),
                "n_pruned_edges": self.n_pruned, "n_glued_slivers": self.n_glued}


def polygon_properties(v: np.ndarray) -> tuple[float, np.ndarray, float]:
    """Area ``A`` [m^2], centroid [m] and polar second moment about the centroid ``J`` [m^4] of a
    counter-clockwise polygon (shoelace sums: ``A = 1/2 sum c_i``, ``c_i = x_i y_{i+1} - x_{i+1} y_i``,
    ``J_o = 1/12 sum c_i (x_i^2 + x_i x_{i+1} + x_{i+1}^2 + y_i^2 + y_i y_{i+1} + y_{i+1}^2)``,
    ``J = J_o - A |x_c|^2``), computed about the first corner for round-off."""
    o = v[0]
    p = v - o
    q = np.roll(p, -1, axis=0)
    cr = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    A = 0.5 * cr.sum()
    c = ((p + q) * cr[:, None]).sum(axis=0) / (6 * A)
    Jo = (cr * (p[:, 0] ** 2 + p[:, 0] * q[:, 0] + q[:, 0] ** 2 + p[:, 1] ** 2 + p[:, 1] * q[:, 1]
                + q[:, 1] ** 2)).sum() / 12
    return float(A), c + o, float(Jo - A * (c @ c))


# ------------------------------------------------------------------------------ rock bridges
def _ray_hit(p: np.ndarray, d: np.ndarray, segs: np.ndarray, tol: float) -> float:
    """Distance along the unit ray ``p + t d`` to the first of ``segs`` (k, 2, 2) it meets beyond
    ``tol`` (a collinear segment ahead counts at its nearer end); ``inf`` when none."""
    if len(segs) == 0:
        return math.inf
    a, e = segs[:, 0], segs[:, 1] - segs[:, 0]
    w = a - p
    den = d[0] * e[:, 1] - d[1] * e[:, 0]
    L = np.linalg.norm(e, axis=1)
    best = math.inf
    cross = np.abs(den) > 1e-12 * L
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / den
        u = (w[:, 0] * d[1] - w[:, 1] * d[0]) / den
    ok = cross & (t > tol) & (u >= -tol / np.maximum(L, 1e-300)) & (u <= 1 + tol / np.maximum(L, 1e-300))
    if ok.any():
        best = float(t[ok].min())
    # collinear segments ahead on the same line
    off = np.abs(w[:, 0] * d[1] - w[:, 1] * d[0])
    col = ~cross & (off <= tol)
    if col.any():
        ta, tb = w[col] @ d, (segs[col, 1] - p) @ d
        near = np.where((ta > tol) & (tb > tol), np.minimum(ta, tb), np.inf)
        if near.size:
            best = min(best, float(near.min()))
    return best


def rock_bridges(joints: np.ndarray, outline: np.ndarray, tol: float) -> np.ndarray:
    """Rock bridges (p, 2, 2) that continue every free end of ``joints`` (k, 2, 2) along its line
    to the first joint, outline edge (m, 2, 2) or earlier bridge it meets (module docstring).

    An end is free when no other joint piece starts or passes there and it is not on the outline.
    """
    if len(joints) == 0:
        return np.zeros((0, 2, 2))
    ends = joints.reshape(-1, 2)
    rep = cluster_points(ends, 10 * tol)
    count = np.bincount(rep, minlength=len(ends))[rep]
    bridges: list = []
    for k in np.flatnonzero(count == 1):
        seg, side = divmod(int(k), 2)
        p, q = joints[seg, side], joints[seg, 1 - side]
        others = np.concatenate([outline, np.delete(joints, seg, axis=0)] + ([np.array(bridges)] if bridges else []))
        if _distance_to_segments(p, others) <= 10 * tol:
            continue  # ends on the outline or on another joint's interior (a T junction)
        d = (p - q) / np.linalg.norm(p - q)
        t = _ray_hit(p, d, others, tol)
        if not math.isfinite(t):
            raise ValueError(f"rock bridge from the joint end {tuple(np.round(p, 6))} along {tuple(np.round(d, 4))} "
                             f"meets no joint or outline: is the joint inside its body?")
        bridges.append([p, p + t * d])
    return np.array(bridges).reshape(-1, 2, 2)


def _distance_to_segments(p: np.ndarray, segs: np.ndarray) -> float:
    if len(segs) == 0:
        return math.inf
    a, ab = segs[:, 0], segs[:, 1] - segs[:, 0]
    s = np.clip(((p - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
    return float(np.linalg.norm(a + s[:, None] * ab - p, axis=1).min())


def intact_cells(body, size: float, seed: int = 0) -> np.ndarray:
    """Edges (m, 2, 2) of a Voronoi tessellation of ``body`` into cells of about ``size`` [m]
    (seeds on a square grid of spacing ``size``, each moved at random by up to 0.35 ``size``),
    clipped to the body: interfaces of intact rock (tag 0) through which a mechanism may break
    the rock, as in a bonded-block model. Same ``seed``, same cells."""
    from scipy.spatial import Voronoi

    from fdem.geometry.dfn import clip_segments

    if not size > 0:
        raise ValueError(f"intact cell size must be positive, got {size} m")
    x0, y0, x1, y1 = body.bounds
    pad = 3 * size
    xs = np.arange(x0 - pad, x1 + pad + size, size)
    ys = np.arange(y0 - pad, y1 + pad + size, size)
    X, Y = np.meshgrid(xs, ys)
    rng = np.random.default_rng(seed)
    pts = np.column_stack([X.ravel(), Y.ravel()]) + rng.uniform(-0.35, 0.35, (X.size, 2)) * size
    vor = Voronoi(pts)
    ridges = np.array([r for r in vor.ridge_vertices if -1 not in r])
    segs = vor.vertices[ridges]
    pieces, _ = clip_segments(segs, body, 1e-9 * body.size)
    return pieces.reshape(-1, 2, 2)


# ------------------------------------------------------------------------------ faces
@dataclass(frozen=True)
class _Faces:
    points: np.ndarray      # (nv, 2)
    edges: np.ndarray       # (ne, 2) vertex pairs u -> v
    label: np.ndarray       # (ne,) tag of each edge
    left: np.ndarray        # (ne, 2) face on the left of u->v and of v->u (-1: outside)
    faces: list             # vertex loops of the bounded faces (counter-clockwise)
    n_pruned: int


def polygonize(segments: np.ndarray, labels: np.ndarray, tol: float, where: str = "body") -> _Faces:
    """Bounded faces of the planar graph of ``segments`` (k, 2, 2) (noded here at every crossing),
    each edge keeping the label of the segment it came from. Dangling edges are pruned first.

    Faces are traced with the face on the left: the half-edge after ``u -> v`` is the one leaving
    ``v`` next clockwise from ``v -> u``; bounded faces come out counter-clockwise (positive area),
    the outer face clockwise.
    """
    pieces, src, _ = split_at_crossings(segments, tol)
    lab = labels[src]
    ends = pieces.reshape(-1, 2)
    rep = cluster_points(ends, 10 * tol)
    ids, inv = np.unique(rep, return_inverse=True)
    points = ends[ids]
    e = inv.reshape(-1, 2)
    keep = e[:, 0] != e[:, 1]
    e, lab = e[keep], lab[keep]
    key = np.sort(e, axis=1)
    # duplicates (a joint on the same line as a bridge): the joint's label wins (higher tag)
    order = np.lexsort((-lab, key[:, 1], key[:, 0]))
    e, lab, key = e[order], lab[order], key[order]
    first = np.r_[True, np.any(key[1:] != key[:-1], axis=1)]
    e, lab = e[first], lab[first]
    n_pruned = 0
    while True:
        deg = np.bincount(e.ravel(), minlength=len(points))
        dangling = (deg[e[:, 0]] == 1) | (deg[e[:, 1]] == 1)
        if not dangling.any():
            break
        n_pruned += int(dangling.sum())
        e, lab = e[~dangling], lab[~dangling]
    ne = len(e)
    # half-edge h = 2 i (u -> v) and 2 i + 1 (v -> u)
    origin = np.r_[e[:, 0], e[:, 1]].reshape(2, -1).T.ravel()
    target = np.r_[e[:, 1], e[:, 0]].reshape(2, -1).T.ravel()
    vec = points[target] - points[origin]
    ang = np.arctan2(vec[:, 1], vec[:, 0])
    order = np.lexsort((ang, origin))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    start = np.searchsorted(origin[order], np.arange(len(points)))
    deg = np.bincount(origin, minlength=len(points))
    twin = np.arange(2 * ne) ^ 1
    t = twin
    v = origin[t]
    pos = rank[t] - start[v]
    nxt = order[start[v] + (pos - 1) % deg[v]]
    face_of = np.full(2 * ne, -1)
    loops, areas = [], []
    for h0 in range(2 * ne):
        if face_of[h0] >= 0:
            continue
        loop, h = [], h0
        while face_of[h] < 0:
            face_of[h] = len(loops)
            loop.append(origin[h])
            h = nxt[h]
        loops.append(np.array(loop))
        p = points[loop]
        areas.append(0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])))
    areas = np.array(areas)
    scale = np.ptp(points, axis=0).max() if len(points) else 1.0
    tiny = 1e-12 * scale * scale
    bounded = areas > tiny          # faces of |area| <= tiny (a cell edge grazing the outline) are dropped
    outer = np.flatnonzero(areas < -tiny)
    if len(outer) > 1:
        lone = loops[outer[np.argsort(areas[outer])[1]]]
        raise ValueError(f"{where}: the joints form {len(outer) - 1} closed cluster(s) touching neither the outline "
                         f"nor another joint (one near {tuple(np.round(points[lone].mean(axis=0), 3))}): "
                         f"a block with a hole is not modelled")
    index = np.full(len(loops), -1)
    index[bounded] = np.arange(int(bounded.sum()))
    left = index[face_of].reshape(-1, 2)
    return _Faces(points, e, lab, left, [loops[i] for i in np.flatnonzero(bounded)], n_pruned)


def _face_areas(f: _Faces) -> np.ndarray:
    out = []
    for loop in f.faces:
        p = f.points[loop]
        out.append(0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])))
    return np.array(out)


def merge_small_faces(f: _Faces, fraction: float, tol: float, where: str = "body",
                      on_support: Callable | None = None) -> tuple[_Faces, int]:
    """Glue every face smaller than ``fraction`` of the median face area to the neighbour it
    shares most intact rock (rock-bridge edges) with, or, with none, to the free neighbour it
    shares most boundary with (a fixed one, with an outline edge where ``on_support(midpoints)``
    holds, only when it has no free neighbour); the edges between them are dropped and the faces
    traced again, until none is left or none can be glued. Returns the faces and how many were
    glued. Gluing across a joint leaves a notch in it (a Voronoi sliver glued across the
    sliding joint of the coarse four-slope geometry raised its factor of safety from 2.2 to
    3.9); gluing a piece to the fixed ground does so for the joint it rests on.

    Why: where joints meet the outline at a small angle they cut slivers (a few cm^2 under a
    brick's corner); a sliver resting on a joint steeper than its friction angle is the
    "weakest mechanism" of the whole slope at a factor of safety that says nothing about the
    slope. Glued, it moves with its neighbour (its interfaces to it are intact rock)."""
    glued = 0
    for _ in range(20):
        areas = _face_areas(f)
        if len(areas) < 2:
            break
        small = np.flatnonzero(areas < fraction * np.median(areas))
        if small.size == 0:
            break
        inner = (f.left[:, 0] >= 0) & (f.left[:, 1] >= 0)
        L = np.linalg.norm(f.points[f.edges[:, 1]] - f.points[f.edges[:, 0]], axis=1)
        fixed = np.zeros(len(areas), dtype=bool)
        if on_support is not None and (~inner).any():
            mid = 0.5 * (f.points[f.edges[~inner, 0]] + f.points[f.edges[~inner, 1]])
            hit = np.asarray(on_support(mid), dtype=bool)
            face = np.max(f.left[~inner], axis=1)
            fixed[face[hit & (face >= 0)]] = True
        drop = np.zeros(len(f.edges), dtype=bool)
        for face in small[np.argsort(areas[small])]:
            mine = inner & ((f.left[:, 0] == face) | (f.left[:, 1] == face))
            if not mine.any():
                continue
            other = np.where(f.left[mine, 0] == face, f.left[mine, 1], f.left[mine, 0])
            # across intact rock first (gluing there changes no joint), then to a free neighbour
            intact = f.label[mine] == BRIDGE
            shared = np.bincount(other, weights=L[mine] * intact, minlength=len(areas))
            if not (shared > 0).any():
                shared = np.bincount(other, weights=L[mine], minlength=len(areas))
                if (shared[~fixed] > 0).any():
                    shared[fixed] = 0.0
            best = int(np.argmax(shared))
            drop |= mine & ((f.left[:, 0] == best) | (f.left[:, 1] == best))
            glued += 1
        if not drop.any():
            break
        keep = ~drop
        segs = np.stack([f.points[f.edges[keep, 0]], f.points[f.edges[keep, 1]]], axis=1)
        f = polygonize(segs, f.label[keep], tol, where)
    return f, glued


# ------------------------------------------------------------------------------ the system
def _on_support(mid: np.ndarray, bounds, sides: Sequence[str], tol: float) -> np.ndarray:
    x0, y0, x1, y1 = bounds
    lines = {"bottom": np.abs(mid[:, 1] - y0), "top": np.abs(mid[:, 1] - y1),
             "left": np.abs(mid[:, 0] - x0), "right": np.abs(mid[:, 0] - x1)}
    unknown = set(sides) - set(lines)
    if unknown:
        raise ValueError(f"supports: unknown side(s) {sorted(unknown)}; use {sorted(lines)} or a predicate")
    hit = np.zeros(len(mid), dtype=bool)
    for s in sides:
        hit |= lines[s] <= 10 * tol
    return hit


def block_system(geometry: Geometry, supports: Sequence[str] | Callable = SUPPORT_SIDES,
                 merge_below: float = 0.0, intact_cell_size: float | None = None, seed: int = 0) -> BlockSystem:
    """The blocks and interfaces of ``geometry`` (module docstring).

    ``supports``: sides of the section's bounding box (``"bottom"``, ``"left"``, ``"right"``,
    ``"top"``) or a predicate ``f(midpoints (m, 2)) -> (m,) bool`` on the midpoints of outline
    edges; a block with such an edge is fixed. ``merge_below``: glue blocks smaller than this
    fraction of the body's median block area to a neighbour (:func:`merge_small_faces`; 0: none).
    ``intact_cell_size`` [m]: also cut the intact rock into Voronoi cells of about this size
    (:func:`intact_cells`, ``seed``), bonded by rock-bridge interfaces: the rock between the
    joints may then break (bonded blocks); ``None``: the joints alone cut blocks.
    """
    tol = geometry.tolerance
    dfn = geometry.dfn()
    support_test = supports if callable(supports) else \
        (lambda mid: _on_support(mid, geometry.bounds, supports, tol))
    polys, bodies, fixed = [], [], []
    ia, ib, ends, normals, tags = [], [], [], [], []
    outline_edges = []      # (block, p, q) of edges on the outer face, for contacts between bodies
    all_bridges, n_pruned, n_glued = [], 0, 0
    for b, body in enumerate(geometry.bodies):
        outline = body.edges
        joints = dfn.segments[dfn.body == b]
        cells = np.zeros((0, 2, 2)) if intact_cell_size is None else intact_cells(body, intact_cell_size, seed + b)
        # bridges as without cells: the joint blocks' interfaces stay a subset of the cells',
        # so the cells only add mechanisms (F with cells <= F without)
        bridges = rock_bridges(joints, outline, tol)
        all_bridges.append(bridges)
        segs = np.concatenate([outline, joints, bridges, cells])
        labels = np.r_[np.full(len(outline), _OUTLINE), dfn.set_id[dfn.body == b],
                       np.full(len(bridges) + len(cells), BRIDGE)]
        f = polygonize(segs, labels.astype(np.int64), tol, where=f"body {b} ({body.name!r})")
        n_pruned += f.n_pruned
        if merge_below > 0:
            f, glued = merge_small_faces(f, merge_below, tol, where=f"body {b} ({body.name!r})",
                                         on_support=support_test)
            n_glued += glued
        base = len(polys)
        polys += [f.points[loop] for loop in f.faces]
        bodies += [b] * len(f.faces)
        fixed += [False] * len(f.faces)
        p, q = f.points[f.edges[:, 0]], f.points[f.edges[:, 1]]
        inner = (f.left[:, 0] >= 0) & (f.left[:, 1] >= 0)
        d = q - p
        L = np.linalg.norm(d, axis=1)
        nl = np.column_stack([-d[:, 1], d[:, 0]]) / L[:, None]   # left normal of u -> v: into face left[:, 0]
        ia.append(base + f.left[inner, 0])
        ib.append(base + f.left[inner, 1])
        ends.append(np.stack([p[inner], q[inner]], axis=1))
        normals.append(nl[inner])
        tags.append(np.where(f.label[inner] == _OUTLINE, BRIDGE, f.label[inner]))
        for i in np.flatnonzero(~inner):
            blk = f.left[i, 0] if f.left[i, 0] >= 0 else f.left[i, 1]
            if blk < 0:
                continue
            # orient the edge counter-clockwise around its block (block on the left)
            a, c = (p[i], q[i]) if f.left[i, 0] >= 0 else (q[i], p[i])
            outline_edges.append((base + int(blk), a, c))
    fixed = np.array(fixed, dtype=bool)
    if outline_edges:
        oblk = np.array([o[0] for o in outline_edges])
        oseg = np.array([[o[1], o[2]] for o in outline_edges])
        mid = oseg.mean(axis=1)
        hit = support_test(mid)
        fixed[np.unique(oblk[np.asarray(hit, dtype=bool)])] = True
        bodies_arr = np.array(bodies)
        ca, cb, ce, cn = _body_contacts(oblk, oseg, bodies_arr, tol)
        ia.append(ca)
        ib.append(cb)
        ends.append(ce)
        normals.append(cn)
        tags.append(np.full(len(ca), CONTACT))
    props = [polygon_properties(v) for v in polys]
    return BlockSystem(
        polygons=tuple(polys), area=np.array([p[0] for p in props]),
        centroid=np.array([p[1] for p in props]).reshape(-1, 2), polar_moment=np.array([p[2] for p in props]),
        body=np.array(bodies, dtype=np.int64), fixed=fixed,
        blocks=np.column_stack([np.concatenate(ia), np.concatenate(ib)]).astype(np.int64),
        ends=np.concatenate(ends).reshape(-1, 2, 2), normal=np.concatenate(normals).reshape(-1, 2),
        tag=np.concatenate(tags).astype(np.int64), n_pruned=n_pruned, n_glued=n_glued,
        bridges=np.concatenate(all_bridges).reshape(-1, 2, 2))


def _body_contacts(oblk: np.ndarray, oseg: np.ndarray, body: np.ndarray, tol: float):
    """Overlaps of outline edges of blocks of different bodies: contact interfaces.

    Two counter-clockwise outline edges in contact run in opposite directions on the same line;
    the overlap is the interface, its normal the left normal of block ``a``'s edge (into ``a``)."""
    d = oseg[:, 1] - oseg[:, 0]
    L = np.linalg.norm(d, axis=1)
    t = d / L[:, None]
    out_a, out_b, out_e, out_n = [], [], [], []
    for i in range(len(oseg)):
        j = np.arange(i + 1, len(oseg))
        j = j[body[oblk[j]] != body[oblk[i]]]
        if j.size == 0:
            continue
        anti = (t[j] @ t[i]) < -1 + 1e-9
        off = np.abs((oseg[j, 0, 0] - oseg[i, 0, 0]) * t[i, 1] - (oseg[j, 0, 1] - oseg[i, 0, 1]) * t[i, 0])
        j = j[anti & (off <= 10 * tol)]
        for k in j:
            s0 = (oseg[k] - oseg[i, 0]) @ t[i]
            lo, hi = max(0.0, s0.min()), min(L[i], s0.max())
            if hi - lo <= 10 * tol:
                continue
            out_a.append(oblk[i])
            out_b.append(oblk[k])
            out_e.append([oseg[i, 0] + lo * t[i], oseg[i, 0] + hi * t[i]])
            out_n.append([-t[i, 1], t[i, 0]])
    return (np.array(out_a, dtype=np.int64), np.array(out_b, dtype=np.int64),
            np.array(out_e).reshape(-1, 2, 2), np.array(out_n).reshape(-1, 2))
