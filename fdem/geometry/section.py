"""The slope section: bodies and their clipped discrete fracture network (:class:`Geometry`).

What Gmsh triangulates (:func:`fdem.mesh.triangulate.mesh_geometry`): one or more
non-overlapping polygons and the joint traces inside them, split at their crossings and
snapped so that no two vertices are closer than the meshing tolerance."""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
import numpy as np
from fdem.geometry.dfn import CoincidentJointsWarning, DFN, _on_boundary, clip_segments, merge_collinear, snap_vertices, split_at_crossings, split_at_points
from fdem.geometry.joint_sets import SegmentSet
from fdem.geometry.polygons import Polygon

__all__ = ["Geometry"]


@dataclass(frozen=True)
class Geometry:
    """Bodies and joint sets of a plane-strain section (what Gmsh meshes; the mechanical model
    built on its mesh is :class:`fdem.solve.model.Model`).

    ``bodies`` are polygons that may touch but not overlap; separate bodies share no nodes in the
    mesh and interact only by contact (e.g. a block resting on an incline). ``joint_sets`` are
    numbered 1, 2, ... in the given order. Joint pieces shorter than ``min_joint_length`` [m] are
    dropped with a warning; crossings sharper than ``small_angle_warning`` [deg] are reported.
    """

    bodies: tuple[Polygon, ...]
    joint_sets: tuple = ()
    min_joint_length: float = 0.0
    small_angle_warning: float = 15.0

    def __post_init__(self):
        bodies = (self.bodies,) if isinstance(self.bodies, Polygon) else tuple(self.bodies)
        if not bodies:
            raise ValueError("a geometry needs at least one body")
        object.__setattr__(self, "bodies", bodies)
        object.__setattr__(self, "joint_sets", tuple(self.joint_sets))
        if self.min_joint_length < 0:
            raise ValueError(f"min_joint_length must be >= 0, got {self.min_joint_length}")
        for a in range(len(bodies)):
            for b in range(a + 1, len(bodies)):
                _check_no_overlap(bodies[a], bodies[b], self.tolerance)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        b = np.array([body.bounds for body in self.bodies])
        return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max())

    @property
    def size(self) -> float:
        x0, y0, x1, y1 = self.bounds
        return math.hypot(x1 - x0, y1 - y0)

    @property
    def tolerance(self) -> float:
        """Geometric tolerance: 1e-9 of the model size [m]."""
        return 1e-9 * self.size

    @property
    def area(self) -> float:
        return float(sum(b.area for b in self.bodies))

    def dfn(self) -> DFN:
        """Clip, merge and split every joint set into the network the mesh must conform to."""
        return self._dfn_cached()

    def _dfn_cached(self) -> DFN:
        cached = self.__dict__.get("_dfn")
        if cached is None:
            cached = self._build_dfn()
            object.__setattr__(self, "_dfn", cached)
        return cached

    def _build_dfn(self) -> DFN:
        tol = self.tolerance
        segs, ids, bodies = [], [], []
        for j, js in enumerate(self.joint_sets, start=1):
            raw = np.asarray(js.raw_segments(self.bounds), dtype=np.float64).reshape(-1, 2, 2)
            found = np.zeros(len(raw), dtype=bool)
            for b, body in enumerate(self.bodies):
                pieces, src = clip_segments(raw, body, tol)
                found[src] = True
                segs.append(pieces)
                ids.append(np.full(len(pieces), j, dtype=np.int32))
                bodies.append(np.full(len(pieces), b, dtype=np.int32))
            name = getattr(js, "name", f"set {j}")
            if isinstance(js, SegmentSet) and js.must_lie_inside and not found.all():
                i = int(np.argmin(found))
                raise ValueError(
                    f"joint set {j} ({name!r}): segment {i} from {tuple(raw[i, 0])} to {tuple(raw[i, 1])} "
                    f"lies outside the domain {self.bounds}")
            if not found.any():
                raise ValueError(f"joint set {j} ({name!r}) has no joint inside the domain {self.bounds}")
        if not segs:
            return DFN(np.zeros((0, 2, 2)), np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0))
        segs, ids, bodies = np.concatenate(segs), np.concatenate(ids), np.concatenate(bodies)

        out_s, out_id, out_b, angles = [], [], [], []
        n_short, shortest = 0, np.inf
        for b in range(len(self.bodies)):
            mine = bodies == b
            if not mine.any():
                continue
            coincide: list = []
            s, i = merge_collinear(segs[mine], ids[mine], tol, overlaps=coincide)
            if coincide:
                self._warn_coincident(coincide, b)
            pieces, src, ang = split_at_crossings(s, tol)
            pieces, src2 = split_at_points(pieces, self.bodies[b].vertices, tol)
            sid = i[src[src2]]
            lengths = np.linalg.norm(pieces[:, 1] - pieces[:, 0], axis=1)
            short = lengths < max(self.min_joint_length, 10 * tol)
            n_short += int(short.sum())
            if short.any():
                shortest = min(shortest, float(lengths[short].min()))
            pieces, sid = pieces[~short], sid[~short]
            if self.min_joint_length > 0:
                pieces, sid = snap_vertices(pieces, sid, self.bodies[b], self.min_joint_length, tol)
            out_s.append(pieces)
            out_id.append(sid)
            out_b.append(np.full(len(pieces), b, dtype=np.int32))
            angles.append(ang)
        segs, ids, bodies = np.concatenate(out_s), np.concatenate(out_id), np.concatenate(out_b)
        angles = np.concatenate(angles)
        if n_short:
            warnings.warn(
                f"dropped {n_short} joint segment(s) shorter than {self.min_joint_length:.3g} m "
                f"(shortest {shortest:.3g} m)", stacklevel=3)
        if angles.size and angles.min() < self.small_angle_warning:
            sharp = angles < self.small_angle_warning
            warnings.warn(
                f"{int(sharp.sum())} joint crossing(s) sharper than {self.small_angle_warning:g} deg "
                f"(worst {angles.min():.2f} deg): expect small mesh angles there", stacklevel=3)
        return DFN(segs, ids.astype(np.int32), bodies, angles, n_short)


    def _warn_coincident(self, overlaps: list, body: int) -> None:
        """Warn, once per pair of joint sets, that their joints coincide (see :class:`CoincidentJointsWarning`)."""
        by_pair: dict[tuple[int, int], list] = {}
        for sa, sb, p, q in overlaps:
            by_pair.setdefault((sa, sb), []).append((p, q))
        body_name = getattr(self.bodies[body], "name", "body")
        for (sa, sb), stretches in sorted(by_pair.items()):
            na = getattr(self.joint_sets[sa - 1], "name", f"set {sa}")
            nb = getattr(self.joint_sets[sb - 1], "name", f"set {sb}")
            total = sum(float(np.linalg.norm(q - p)) for p, q in stretches)
            p, q = stretches[0]
            warnings.warn(CoincidentJointsWarning(
                f"joint sets {sa} ({na!r}) and {sb} ({nb!r}) coincide in body {body} ({body_name!r}): "
                f"{len(stretches)} stretch(es) on the same lines, {total:.4g} m in all, first from "
                f"({p[0]:.4g}, {p[1]:.4g}) to ({q[0]:.4g}, {q[1]:.4g}) m; they are merged into one joint "
                f"tagged set {sa}. Check the sets' dip, spacing and offset if this is not intended"),
                stacklevel=4)


def _check_no_overlap(a: Polygon, b: Polygon, tol: float) -> None:
    """Raise if two bodies overlap (touching along edges or at corners is allowed)."""
    # Interior overlap shows as a vertex strictly inside the other polygon or a proper edge crossing.
    for p, q in ((a, b), (b, a)):
        inside = q.contains(p.vertices) & ~_on_boundary(p.vertices, q, tol)
        if inside.any():
            v = p.vertices[np.argmax(inside)]
            raise ValueError(f"bodies {p.name!r} and {q.name!r} overlap: vertex {tuple(v)} of {p.name!r} "
                             f"lies inside {q.name!r}")
    for ea in a.edges:
        for eb in b.edges:
            d1, d2 = ea[1] - ea[0], eb[1] - eb[0]
            denom = d1[0] * d2[1] - d1[1] * d2[0]
            if abs(denom) <= 1e-12 * np.linalg.norm(d1) * np.linalg.norm(d2):
                continue
            w = eb[0] - ea[0]
            t = (w[0] * d2[1] - w[1] * d2[0]) / denom
            u = (w[0] * d1[1] - w[1] * d1[0]) / denom
            eps = 1e-9
            if eps < t < 1 - eps and eps < u < 1 - eps:
                x = ea[0] + t * d1
                raise ValueError(f"bodies {a.name!r} and {b.name!r} overlap: their edges cross at {tuple(x)}")
