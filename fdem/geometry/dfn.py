"""The discrete fracture network (DFN) in plane section: joint traces clipped to the bodies, merged,
split at crossings and snapped (:class:`DFN`).

Conventions
-----------
* Coordinates in metres, ``x`` to the right, ``y`` up. Slopes have their toe on the left and
  their crest on the right, so the face rises from left to right.
* A joint's ``dip`` is the angle of its trace measured counter-clockwise from the ``+x`` axis,
  in degrees, ``0 <= dip < 180``. With the toe on the left, a joint with ``0 < dip < face angle``
  daylights in the face (an "inclined" or low-angle set); ``dip > 90`` dips into the slope
  (an "anti-inclined" set).
* Joint sets are numbered from 1 in the order they are given to
  :class:`~fdem.geometry.section.Geometry`; 0 is reserved
  for intact rock bridges.

No solver imports here: this subpackage only describes geometry.
"""
from __future__ import annotations

from dataclasses import dataclass
import numpy as np
from fdem.geometry.joint_sets import BrickSet, IntermittentSet, PersistentSet, SegmentSet, StochasticSet
from fdem.geometry.polygons import Polygon

__all__ = ["JointSet", "clip_segments", "merge_collinear", "split_at_crossings", "split_at_points", "DFN",
           "CoincidentJointsWarning", "cluster_points", "snap_vertices"]


JointSet = PersistentSet | IntermittentSet | BrickSet | SegmentSet | StochasticSet


def clip_segments(segments: np.ndarray, polygon: Polygon, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Parts of ``segments`` (k, 2, 2) inside ``polygon``; returns (pieces, index of source segment).

    Each segment is cut at its crossings with the polygon's edges and the pieces whose midpoints
    lie inside are kept (consecutive inside pieces are re-joined). Pieces lying on the boundary
    are dropped: a joint along the boundary is the boundary itself.
    """
    if len(segments) == 0:
        return np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64)
    p, d = segments[:, 0], segments[:, 1] - segments[:, 0]
    e0 = polygon.vertices
    e = np.roll(e0, -1, axis=0) - e0
    # Solve p + t d = e0 + u e for every (segment, edge) pair.
    denom = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    w = e0[None, :, :] - p[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[None, :, 1] - w[..., 1] * e[None, :, 0]) / denom
        u = (w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]) / denom
    ok = (np.abs(denom) > 1e-14) & (u >= -1e-12) & (u <= 1 + 1e-12) & (t > 0) & (t < 1)
    pieces, source = [], []
    for i in range(len(segments)):
        ts = np.unique(np.r_[0.0, t[i][ok[i]], 1.0])
        mids = p[i] + 0.5 * (ts[:-1] + ts[1:])[:, None] * d[i]
        inside = polygon.contains(mids) & ~_on_boundary(mids, polygon, tol)
        # Merge consecutive inside intervals into one piece.
        k = 0
        while k < len(inside):
            if inside[k]:
                j = k
                while j + 1 < len(inside) and inside[j + 1]:
                    j += 1
                pieces.append([p[i] + ts[k] * d[i], p[i] + ts[j + 1] * d[i]])
                source.append(i)
                k = j + 1
            else:
                k += 1
    if not pieces:
        return np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64)
    return np.array(pieces), np.array(source, dtype=np.int64)


def _point_segment_distance(points: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """(m, k) distances from points (m, 2) to segments (k, 2, 2)."""
    a, b = segs[:, 0], segs[:, 1]
    ab = b - a
    L2 = np.maximum((ab * ab).sum(axis=1), 1e-300)
    ap = points[:, None, :] - a[None, :, :]
    s = np.clip((ap * ab[None]).sum(axis=2) / L2[None], 0.0, 1.0)
    closest = a[None] + s[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2)


def _on_boundary(points: np.ndarray, polygon: Polygon, tol: float) -> np.ndarray:
    return _point_segment_distance(points, polygon.edges).min(axis=1) <= tol


def merge_collinear(segments: np.ndarray, set_ids: np.ndarray, tol: float,
                    overlaps: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Merge collinear segments that overlap or touch into one; the merged piece keeps the smallest set id.

    Segments are grouped by line (direction modulo 180 degrees and normal offset, within ``tol``)
    and their 1D intervals along the line are unioned. When ``overlaps`` is a list, every
    stretch where segments of two *different* sets lie on the same line and overlap (by more
    than ``tol``) is appended to it as ``(set_a, set_b, start (2,), end (2,))`` with
    ``set_a < set_b``: two sets that coincide there, which the merge would otherwise hide.
    """
    if len(segments) == 0:
        return segments, set_ids
    d = segments[:, 1] - segments[:, 0]
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), np.pi)
    ang[ang > np.pi - 1e-9] = 0.0
    t = np.column_stack([np.cos(ang), np.sin(ang)])
    n = np.column_stack([-t[:, 1], t[:, 0]])
    c = (segments[:, 0] * n).sum(axis=1)
    order = np.lexsort((c, np.round(ang / 1e-9)))
    out_s, out_id = [], []
    used = np.zeros(len(segments), dtype=bool)
    for a in order:
        if used[a]:
            continue
        # Members of this segment's line: same angle and offset within tolerance.
        same = (~used) & (np.abs(np.sin(ang - ang[a])) < 1e-9) & (np.abs(c - c[a]) <= tol)
        idx = np.flatnonzero(same)
        used[idx] = True
        s0 = (segments[idx, 0] * t[a]).sum(axis=1)
        s1 = (segments[idx, 1] * t[a]).sum(axis=1)
        lo, hi = np.minimum(s0, s1), np.maximum(s0, s1)
        k = np.argsort(lo)
        lo, hi, idx = lo[k], hi[k], idx[k]
        start, end, sid = lo[0], hi[0], set_ids[idx[0]]
        base = c[a] * n[a]
        if overlaps is not None and len(idx) > 1:
            ids_here = set_ids[idx]
            for m in range(1, len(idx)):
                prev = np.flatnonzero((hi[:m] > lo[m] + tol) & (ids_here[:m] != ids_here[m]))
                for q in prev:
                    stop = min(hi[q], hi[m])
                    if stop - lo[m] > tol:
                        sa, sb = sorted((int(ids_here[q]), int(ids_here[m])))
                        overlaps.append((sa, sb, base + lo[m] * t[a], base + stop * t[a]))
        for m in range(1, len(idx)):
            if lo[m] <= end + tol:
                end = max(end, hi[m])
                sid = min(sid, set_ids[idx[m]])
            else:
                out_s.append([base + start * t[a], base + end * t[a]])
                out_id.append(sid)
                start, end, sid = lo[m], hi[m], set_ids[idx[m]]
        out_s.append([base + start * t[a], base + end * t[a]])
        out_id.append(sid)
    return np.array(out_s), np.array(out_id, dtype=np.int32)


def split_at_crossings(segments: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split every segment where another segment crosses or touches it (X and T junctions).

    Returns (pieces (m, 2, 2), index of source segment (m,), crossing angles [deg] of all proper
    X and T crossings). Candidate pairs come from a uniform grid over segment bounding boxes, so
    the cost grows with the number of nearby pairs, not with the square of the segment count.
    """
    k = len(segments)
    if k == 0:
        return segments, np.zeros(0, dtype=np.int64), np.zeros(0)
    ii, jj = _candidate_pairs(segments, tol)
    p, d = segments[:, 0], segments[:, 1] - segments[:, 0]
    seg_length = np.linalg.norm(d, axis=1)
    pi, di, pj, dj = p[ii], d[ii], p[jj], d[jj]
    denom = di[:, 0] * dj[:, 1] - di[:, 1] * dj[:, 0]
    w = pj - pi
    Li, Lj = np.linalg.norm(di, axis=1), np.linalg.norm(dj, axis=1)
    nonpar = np.abs(denom) > 1e-12 * Li * Lj
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[:, 0] * dj[:, 1] - w[:, 1] * dj[:, 0]) / denom
        u = (w[:, 0] * di[:, 1] - w[:, 1] * di[:, 0]) / denom
    ti, tj = tol / Li, tol / Lj
    hit = nonpar & (t >= -ti) & (t <= 1 + ti) & (u >= -tj) & (u <= 1 + tj)
    ii, jj, t, u = ii[hit], jj[hit], np.clip(t[hit], 0, 1), np.clip(u[hit], 0, 1)
    ti, tj = ti[hit], tj[hit]
    sin_angle = np.abs(denom[hit]) / (Li[hit] * Lj[hit])
    angles = np.degrees(np.arcsin(np.clip(sin_angle, 0, 1)))
    # A crossing at both segments' endpoints is a shared vertex, not a junction.
    at_end_i = (t <= ti) | (t >= 1 - ti)
    at_end_j = (u <= tj) | (u >= 1 - tj)
    junction_angles = angles[~(at_end_i & at_end_j)]
    cuts = [[] for _ in range(k)]
    for a, b, ta, ub in zip(ii, jj, t, u):
        cuts[a].append(ta)
        cuts[b].append(ub)
    pieces, source = [], []
    for s in range(k):
        ts = np.unique(np.r_[0.0, np.asarray(cuts[s]), 1.0])
        # Collapse parameters closer than tol along the segment.
        keep = np.r_[True, np.diff(ts) * seg_length[s] > tol]
        ts = ts[keep]
        ts[-1] = 1.0
        for a, b in zip(ts[:-1], ts[1:]):
            pieces.append([p[s] + a * d[s], p[s] + b * d[s]])
            source.append(s)
    return np.array(pieces).reshape(-1, 2, 2), np.array(source, dtype=np.int64), junction_angles


def split_at_points(segments: np.ndarray, points: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Split segments wherever one of ``points`` (e.g. a corner of the body) lies on their interior.

    Returns (pieces, index of source segment). Without this a joint passing exactly through a
    boundary corner would leave that corner on a curve's interior and Gmsh a sliver there.
    """
    if len(segments) == 0 or len(points) == 0:
        return segments, np.arange(len(segments))
    a, d = segments[:, 0], segments[:, 1] - segments[:, 0]
    L = np.linalg.norm(d, axis=1)
    s = ((points[None, :, :] - a[:, None, :]) * d[:, None, :]).sum(-1) / (L * L)[:, None]
    closest = a[:, None, :] + s[..., None] * d[:, None, :]
    dist = np.linalg.norm(points[None] - closest, axis=-1)
    inside = (dist <= tol) & (s * L[:, None] > tol) & ((1 - s) * L[:, None] > tol)
    pieces, source = [], []
    for i in range(len(segments)):
        ts = np.r_[0.0, np.sort(s[i][inside[i]]), 1.0]
        for t0, t1 in zip(ts[:-1], ts[1:]):
            pieces.append([a[i] + t0 * d[i], a[i] + t1 * d[i]])
            source.append(i)
    return np.array(pieces), np.array(source, dtype=np.int64)


def _candidate_pairs(segments: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i < j) of segments whose bounding boxes overlap, found through a uniform grid."""
    lo = segments.min(axis=1) - tol
    hi = segments.max(axis=1) + tol
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    cell = max(float(np.median(lengths)), tol * 10)
    origin = lo.min(axis=0)
    c0 = np.floor((lo - origin) / cell).astype(np.int64)
    c1 = np.floor((hi - origin) / cell).astype(np.int64)
    ncols = int(c1[:, 0].max()) + 1
    seg_ids, cells = [], []
    for s in range(len(segments)):
        cx, cy = np.meshgrid(np.arange(c0[s, 0], c1[s, 0] + 1), np.arange(c0[s, 1], c1[s, 1] + 1))
        cells.append((cy * ncols + cx).ravel())
        seg_ids.append(np.full(cx.size, s))
    cells = np.concatenate(cells)
    seg_ids = np.concatenate(seg_ids)
    order = np.argsort(cells, kind="stable")
    cells, seg_ids = cells[order], seg_ids[order]
    bounds = np.flatnonzero(np.r_[True, cells[1:] != cells[:-1], True])
    pairs = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        members = seg_ids[a:b]
        if len(members) > 1:
            x, y = np.triu_indices(len(members), 1)
            pairs.append(np.column_stack([members[x], members[y]]))
    if not pairs:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    pairs = np.unique(np.sort(np.concatenate(pairs), axis=1), axis=0)
    i, j = pairs[:, 0], pairs[:, 1]
    overlap = np.all(lo[i] <= hi[j], axis=1) & np.all(lo[j] <= hi[i], axis=1)
    return i[overlap], j[overlap]


@dataclass(frozen=True)
class DFN:
    """The processed fracture network of a :class:`Geometry`.

    Attributes
    ----------
    segments : (k, 2, 2) float64
        Non-overlapping joint segments, split at every crossing, clipped to the bodies [m].
    set_id : (k,) int32
        Joint set of each segment, from 1.
    body : (k,) int32
        Body that holds each segment.
    crossing_angles : (m,) float64
        Angles between joints at their X and T junctions [deg].
    n_dropped_short : int
        Segments shorter than the minimum length that were dropped.
    """

    segments: np.ndarray
    set_id: np.ndarray
    body: np.ndarray
    crossing_angles: np.ndarray
    n_dropped_short: int = 0


class CoincidentJointsWarning(UserWarning):
    """Two joint sets have joints on the same line that overlap; the overlap becomes one joint
    of the lower-numbered set (one crack element cannot belong to two sets)."""


def cluster_points(points: np.ndarray, radius: float, prefer: np.ndarray | None = None) -> np.ndarray:
    """Index of the representative of each point after merging points closer than ``radius``.

    Clusters are the connected components of the "closer than radius" graph; the representative
    is the first ``prefer``-red member (e.g. a point on the boundary), else the lowest index.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(points)
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    rank = np.arange(n) - (n * prefer.astype(np.int64) if prefer is not None else 0)
    best = np.full(label.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(best, label, rank)
    rep_rank = best[label]
    return np.where(rep_rank < 0, rep_rank + n, rep_rank)


def snap_vertices(segments: np.ndarray, set_id: np.ndarray, body: Polygon, radius: float,
                  tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Move joint vertices closer than ``radius`` to the body's boundary onto it, and merge vertices
    closer than ``radius`` to each other, so no mesh feature is smaller than ``radius``.

    A joint bends by at most ``radius`` where this happens. Segments that collapse to a point or
    duplicate another are removed. Without it a junction 2 mm from the floor leaves a sliver
    whose altitude, not the element size, would set the explicit time step.
    """
    ends = segments.reshape(-1, 2).copy()
    corners = body.vertices
    d_corner = np.linalg.norm(ends[:, None, :] - corners[None], axis=2)
    k = np.argmin(d_corner, axis=1)
    to_corner = d_corner[np.arange(len(ends)), k] <= radius
    ends[to_corner] = corners[k[to_corner]]
    edges = body.edges
    a, ab = edges[:, 0], edges[:, 1] - edges[:, 0]
    t = np.clip(((ends[:, None] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None], 0, 1)
    closest = a[None] + t[..., None] * ab[None]
    dist = np.linalg.norm(ends[:, None] - closest, axis=2)
    e = np.argmin(dist, axis=1)
    dmin = dist[np.arange(len(ends)), e]
    to_edge = ~to_corner & (dmin <= radius)
    ends[to_edge] = closest[to_edge, e[to_edge]]
    on_boundary = to_corner | (dmin <= tol) | to_edge
    ends = ends[cluster_points(ends, radius, prefer=on_boundary)]
    segs = ends.reshape(-1, 2, 2)
    keep = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) > tol
    # A segment lying along the boundary after snapping is the boundary itself.
    mid = 0.5 * (segs[:, 0] + segs[:, 1])
    keep &= _point_segment_distance(mid, edges).min(axis=1) > tol
    segs, set_id = segs[keep], set_id[keep]
    key = np.sort(np.round(segs.reshape(-1, 4) / max(tol, 1e-300)).astype(np.int64).reshape(-1, 2, 2), axis=1)
    _, first = np.unique(key.reshape(-1, 4), axis=0, return_index=True)
    first = np.sort(first)
    return segs[first], set_id[first]
