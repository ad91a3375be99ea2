"""Slope profiles, joint sets and the discrete fracture network (DFN), in plane section.

Conventions
-----------
* Coordinates in metres, ``x`` to the right, ``y`` up. Slopes have their toe on the left and
  their crest on the right, so the face rises from left to right.
* A joint's ``dip`` is the angle of its trace measured counter-clockwise from the ``+x`` axis,
  in degrees, ``0 <= dip < 180``. With the toe on the left, a joint with ``0 < dip < face angle``
  daylights in the face (an "inclined" or low-angle set); ``dip > 90`` dips into the slope
  (an "anti-inclined" set).
* Joint sets are numbered from 1 in the order they are given to :class:`Geometry`; 0 is reserved
  for intact rock bridges.

No solver imports here: this module only describes geometry.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np

# ----------------------------------------------------------------------------- polygons


def _as_points(vertices, what: str) -> np.ndarray:
    pts = np.asarray(vertices, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{what}: vertices must be an (n, 2) array, got shape {pts.shape}")
    if len(pts) < 3:
        raise ValueError(f"{what}: a polygon needs at least 3 vertices, got {len(pts)}")
    if not np.all(np.isfinite(pts)):
        raise ValueError(f"{what}: vertices contain NaN or infinity")
    return pts


def signed_area(vertices: np.ndarray) -> float:
    """Shoelace area ``A = 1/2 sum(x_i y_{i+1} - x_{i+1} y_i)``, positive counter-clockwise [m^2]."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _segments_intersect_strictly(p, q, r, s, tol) -> bool:
    """True when segments pq and rs share a point other than a common endpoint."""
    d1, d2 = q - p, s - r
    denom = d1[0] * d2[1] - d1[1] * d2[0]
    rp = r - p
    if abs(denom) <= tol * (np.linalg.norm(d1) * np.linalg.norm(d2)):
        # Parallel: overlapping only if collinear and the projections overlap beyond a point.
        if abs(rp[0] * d1[1] - rp[1] * d1[0]) > tol * np.linalg.norm(d1) ** 2:
            return False
        L2 = float(d1 @ d1)
        t0, t1 = sorted(((r - p) @ d1 / L2, (s - p) @ d1 / L2))
        return min(t1, 1.0) - max(t0, 0.0) > tol
    t = (rp[0] * d2[1] - rp[1] * d2[0]) / denom
    u = (rp[0] * d1[1] - rp[1] * d1[0]) / denom
    return -tol <= t <= 1 + tol and -tol <= u <= 1 + tol


@dataclass(frozen=True)
class Polygon:
    """A simple (non-self-intersecting) polygon, stored counter-clockwise.

    Attributes
    ----------
    vertices : (n, 2) float64
        Corner coordinates [m], counter-clockwise, first vertex not repeated.
    name : str
        Used in error messages and as the body's name.
    """

    vertices: np.ndarray
    name: str = "body"

    def __post_init__(self):
        pts = _as_points(self.vertices, f"polygon {self.name!r}")
        # Drop a repeated closing vertex and consecutive duplicates.
        keep = np.r_[np.any(np.abs(np.diff(pts, axis=0)) > 0, axis=1), True]
        if np.allclose(pts[0], pts[-1]):
            keep[-1] = False
        pts = pts[keep]
        if len(pts) < 3:
            raise ValueError(f"polygon {self.name!r}: fewer than 3 distinct vertices")
        object.__setattr__(self, "vertices", pts)
        self._check_simple()
        area = signed_area(pts)
        if abs(area) <= 1e-12 * np.ptp(pts, axis=0).max() ** 2:
            raise ValueError(f"polygon {self.name!r}: zero area (collinear vertices)")
        if area < 0:
            object.__setattr__(self, "vertices", pts[::-1].copy())

    @property
    def area(self) -> float:
        return signed_area(self.vertices)

    @property
    def edges(self) -> np.ndarray:
        """(n, 2, 2) edges, edge i from vertex i to vertex i+1."""
        return np.stack([self.vertices, np.roll(self.vertices, -1, axis=0)], axis=1)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        (x0, y0), (x1, y1) = self.vertices.min(axis=0), self.vertices.max(axis=0)
        return float(x0), float(y0), float(x1), float(y1)

    @property
    def size(self) -> float:
        """Length of the bounding-box diagonal [m]: the scale of geometric tolerances."""
        x0, y0, x1, y1 = self.bounds
        return math.hypot(x1 - x0, y1 - y0)

    def _check_simple(self) -> None:
        e = self.edges
        n = len(e)
        tol = 1e-12
        for i in range(n):
            for j in range(i + 1, n):
                if j == i + 1 or (i == 0 and j == n - 1):
                    # Neighbouring edges may only share their common vertex (no fold-back).
                    a, b = (e[i], e[j]) if j == i + 1 else (e[j], e[i])
                    d1, d2 = a[1] - a[0], b[1] - b[0]
                    cross = d1[0] * d2[1] - d1[1] * d2[0]
                    if abs(cross) <= tol * np.linalg.norm(d1) * np.linalg.norm(d2) and d1 @ d2 < 0:
                        raise ValueError(
                            f"polygon {self.name!r} is self-intersecting: edges {i} and {j} fold back "
                            f"on each other at vertex {tuple(np.round(a[1], 9))}")
                    continue
                if _segments_intersect_strictly(e[i, 0], e[i, 1], e[j, 0], e[j, 1], tol):
                    raise ValueError(
                        f"polygon {self.name!r} is self-intersecting: edge {i} "
                        f"{tuple(np.round(e[i, 0], 6))}-{tuple(np.round(e[i, 1], 6))} crosses edge {j} "
                        f"{tuple(np.round(e[j, 0], 6))}-{tuple(np.round(e[j, 1], 6))}")

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Even-odd rule point-in-polygon test, vectorised over ``points`` (m, 2)."""
        pts = np.atleast_2d(points)
        x, y = pts[:, 0:1], pts[:, 1:2]
        a, b = self.vertices, np.roll(self.vertices, -1, axis=0)
        ay, by = a[:, 1][None, :], b[:, 1][None, :]
        ax, bx = a[:, 0][None, :], b[:, 0][None, :]
        straddles = (ay > y) != (by > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = ax + (y - ay) * (bx - ax) / (by - ay)
        return np.count_nonzero(straddles & (x < x_cross), axis=1) % 2 == 1


def simple_slope(height: float, face_angle: float, crest_length: float, toe_length: float,
                 base_depth: float, name: str = "slope") -> Polygon:
    """A single-face slope: toe floor on the left, face rising at ``face_angle`` [deg], crest on the right.

    The toe is at ``(toe_length, base_depth)``, the base at ``y = 0``; the model is
    ``toe_length + height/tan(face_angle) + crest_length`` wide and ``base_depth + height`` high.
    """
    return benched_slope([(height, face_angle, 0.0)], crest_length, toe_length, base_depth, name=name)


def benched_slope(benches: Sequence[tuple[float, float, float]], crest_length: float, toe_length: float,
                  base_depth: float, name: str = "slope") -> Polygon:
    """A benched slope: ``benches`` lists ``(bench height [m], face angle [deg], berm width [m])`` from the toe up.

    The berm width of the last bench is ignored (the crest plateau follows).
    """
    for label, value in (("crest_length", crest_length), ("toe_length", toe_length), ("base_depth", base_depth)):
        if not value > 0:
            raise ValueError(f"slope {name!r}: {label} must be positive, got {value}")
    if not benches:
        raise ValueError(f"slope {name!r}: at least one bench is needed")
    pts = [(0.0, 0.0)]
    x, y = toe_length, base_depth
    pts.append((0.0, y))
    pts.append((x, y))
    for k, (h, angle, berm) in enumerate(benches):
        if not h > 0:
            raise ValueError(f"slope {name!r}: bench {k} height must be positive, got {h}")
        if not 0 < angle <= 90:
            raise ValueError(f"slope {name!r}: bench {k} face angle must be in (0, 90] degrees, got {angle}")
        if berm < 0:
            raise ValueError(f"slope {name!r}: bench {k} berm width must be >= 0, got {berm}")
        x += h / math.tan(math.radians(angle)) if angle < 90 else 0.0
        y += h
        pts.append((x, y))
        if k < len(benches) - 1 and berm > 0:
            x += berm
            pts.append((x, y))
    x += crest_length
    pts.append((x, y))
    pts.append((x, 0.0))
    return Polygon(np.array(pts), name=name)


def rectangle(x0: float, y0: float, width: float, height: float, name: str = "block") -> Polygon:
    """An axis-aligned rectangle with lower-left corner ``(x0, y0)``."""
    if not (width > 0 and height > 0):
        raise ValueError(f"rectangle {name!r}: width and height must be positive, got {width}, {height}")
    return Polygon(np.array([[x0, y0], [x0 + width, y0], [x0 + width, y0 + height], [x0, y0 + height]]), name=name)


def disc(centre: tuple[float, float], radius: float, n_sides: int = 64, name: str = "disc") -> Polygon:
    """A regular ``n_sides``-gon inscribed in the circle of ``radius`` [m] (e.g. a Brazilian disc).

    Its area is ``n/2 r^2 sin(2 pi / n)``, within 0.2 % of ``pi r^2`` for 64 sides.
    """
    if not radius > 0:
        raise ValueError(f"disc {name!r}: radius must be positive, got {radius}")
    if n_sides < 8:
        raise ValueError(f"disc {name!r}: use at least 8 sides, got {n_sides}")
    a = 2 * np.pi * np.arange(n_sides) / n_sides
    return Polygon(np.column_stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)]), name=name)


# ----------------------------------------------------------------------------- joint sets


def _check_dip(dip: float, where: str) -> None:
    if not (0.0 <= dip < 180.0):
        raise ValueError(f"{where}: dip must be in [0, 180) degrees (angle of the trace from +x), got {dip}")


def _check_positive(value: float, label: str, where: str) -> None:
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{where}: {label} must be positive, got {value}")


def _direction(dip_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangent along a trace of angle ``dip`` and the unit normal 90 degrees counter-clockwise."""
    a = math.radians(dip_deg)
    t = np.array([math.cos(a), math.sin(a)])
    return t, np.array([-t[1], t[0]])


def _covering_lines(bounds, dip, spacing, offset):
    """Infinite lines of angle ``dip`` spaced ``spacing`` apart (normal offsets ``offset + k s``) that
    cross the bounding box, as long segments reaching past it. Returns (segments, normal offsets, t, n)."""
    x0, y0, x1, y1 = bounds
    t, n = _direction(dip)
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    c = corners @ n
    k0, k1 = math.floor((c.min() - offset) / spacing), math.ceil((c.max() - offset) / spacing)
    offsets = offset + spacing * np.arange(k0, k1 + 1)
    reach = math.hypot(x1 - x0, y1 - y0)
    centre = corners.mean(axis=0)
    base = centre + (offsets - centre @ n)[:, None] * n  # closest point of each line to the box centre
    segs = np.stack([base - reach * t, base + reach * t], axis=1)
    return segs, offsets, t, n


@dataclass(frozen=True)
class PersistentSet:
    """Parallel joints crossing the whole domain: angle ``dip`` [deg], ``spacing`` [m] normal to them.

    Line ``k`` satisfies ``n . x = offset + k * spacing`` with ``n`` the unit normal.
    """

    dip: float
    spacing: float
    offset: float = 0.0
    name: str = "persistent"

    def __post_init__(self):
        _check_dip(self.dip, f"joint set {self.name!r}")
        _check_positive(self.spacing, "spacing", f"joint set {self.name!r}")

    def raw_segments(self, bounds) -> np.ndarray:
        return _covering_lines(bounds, self.dip, self.spacing, self.offset)[0]


@dataclass(frozen=True)
class IntermittentSet:
    """Rows of collinear joints of ``trace_length`` separated by rock bridges of ``bridge_length``.

    Rows are ``row_spacing`` apart (normal distance); row ``k`` lies on ``n . x = offset + k *
    row_spacing`` and is shifted along its trace by ``k * stagger`` [m]; ``phase`` shifts every
    row along its trace. ``rows = (k_first, k_last)`` keeps only those rows (inclusive); by
    default the rows fill the domain.
    """

    dip: float
    trace_length: float
    bridge_length: float
    row_spacing: float
    stagger: float = 0.0
    offset: float = 0.0
    phase: float = 0.0
    rows: tuple[int, int] | None = None
    name: str = "intermittent"

    def __post_init__(self):
        where = f"joint set {self.name!r}"
        _check_dip(self.dip, where)
        _check_positive(self.trace_length, "trace_length", where)
        _check_positive(self.row_spacing, "row_spacing", where)
        if not self.bridge_length >= 0:
            raise ValueError(f"{where}: bridge_length must be >= 0, got {self.bridge_length}")

    def raw_segments(self, bounds) -> np.ndarray:
        x0, y0, x1, y1 = bounds
        _, offsets, t, n = _covering_lines(bounds, self.dip, self.row_spacing, self.offset)
        period = self.trace_length + self.bridge_length
        corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        along = corners @ t
        out = []
        for c in np.round((offsets - self.offset) / self.row_spacing).astype(int):
            if self.rows is not None and not (self.rows[0] <= c <= self.rows[1]):
                continue
            shift = self.phase + c * self.stagger
            k0 = math.floor((along.min() - shift) / period) - 1
            k1 = math.ceil((along.max() - shift) / period) + 1
            starts = shift + period * np.arange(k0, k1 + 1)
            base = (self.offset + c * self.row_spacing) * n
            a = base + starts[:, None] * t
            out.append(np.stack([a, a + self.trace_length * t], axis=1))
        return np.concatenate(out) if out else np.zeros((0, 2, 2))


@dataclass(frozen=True)
class BrickSet:
    """Blocky "brick" fabric: persistent joints at ``spacing`` s, crossed by non-persistent cross joints.

    Cross joints run at ``cross_dip`` (default ``dip + 90``) across one layer only, ``cross_spacing``
    d apart along the layer (default ``2 s``); neighbouring layers are offset by ``d/2`` (50 %
    overlap), the brick pattern of the four-slope case (cases.md A).
    """

    dip: float
    spacing: float
    cross_spacing: float | None = None
    cross_dip: float | None = None
    offset: float = 0.0
    phase: float = 0.0
    name: str = "brick"

    def __post_init__(self):
        where = f"joint set {self.name!r}"
        _check_dip(self.dip, where)
        _check_positive(self.spacing, "spacing", where)
        if self.cross_spacing is not None:
            _check_positive(self.cross_spacing, "cross_spacing", where)
        if self.cross_dip is not None:
            _check_dip(self.cross_dip, where + " (cross joints)")
            if abs(math.sin(math.radians(self.cross_dip - self.dip))) < 1e-6:
                raise ValueError(f"{where}: cross_dip must differ from dip, got {self.cross_dip}")

    @property
    def d(self) -> float:
        return 2.0 * self.spacing if self.cross_spacing is None else self.cross_spacing

    @property
    def cross_angle(self) -> float:
        return (self.dip + 90.0) % 180.0 if self.cross_dip is None else self.cross_dip

    def raw_segments(self, bounds) -> np.ndarray:
        persistent, offsets, t, n = _covering_lines(bounds, self.dip, self.spacing, self.offset)
        tc, _ = _direction(self.cross_angle)
        # A cross joint spans one layer, from line k to line k+1: along tc it travels s / (tc . n).
        rise = self.spacing / float(tc @ n)
        x0, y0, x1, y1 = bounds
        corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        along = corners @ t
        out = [persistent]
        for layer, c in enumerate(offsets[:-1]):
            k = int(round((c - self.offset) / self.spacing))
            shift = self.phase + (0.5 * self.d if k % 2 else 0.0)
            j0 = math.floor((along.min() - shift) / self.d) - 2
            j1 = math.ceil((along.max() - shift) / self.d) + 2
            a = c * n + (shift + self.d * np.arange(j0, j1 + 1))[:, None] * t
            out.append(np.stack([a, a + rise * tc], axis=1))
        return np.concatenate(out)


@dataclass(frozen=True)
class SegmentSet:
    """Explicit joint segments ``[(x0, y0, x1, y1), ...]`` [m]; each must reach inside the domain."""

    segments: np.ndarray
    name: str = "explicit"
    must_lie_inside: bool = True

    def __post_init__(self):
        s = np.asarray(self.segments, dtype=np.float64).reshape(-1, 2, 2)
        if not np.all(np.isfinite(s)):
            raise ValueError(f"joint set {self.name!r}: segment coordinates contain NaN or infinity")
        lengths = np.linalg.norm(s[:, 1] - s[:, 0], axis=1)
        if np.any(lengths <= 0):
            i = int(np.argmax(lengths <= 0))
            raise ValueError(f"joint set {self.name!r}: segment {i} has zero length at {tuple(s[i, 0])}")
        object.__setattr__(self, "segments", s)

    def raw_segments(self, bounds) -> np.ndarray:
        return self.segments


@dataclass(frozen=True)
class StochasticSet:
    """A random DFN: ``count`` joints with uniformly distributed centres in ``region`` (default: the
    domain's bounding box), trace lengths from ``length`` and dips from ``dip``.

    ``length`` is ``("lognormal", mean, sd)``, ``("exponential", mean)``, ``("uniform", lo, hi)``
    or ``("fixed", L)`` [m]; ``dip`` is ``("normal", mean, sd)``, ``("uniform", lo, hi)`` or
    ``("fixed", angle)`` [deg]. Same ``seed``, same network.
    """

    count: int
    length: tuple = ("fixed", 1.0)
    dip: tuple = ("fixed", 0.0)
    seed: int = 0
    region: tuple[float, float, float, float] | None = None
    name: str = "stochastic"

    def __post_init__(self):
        where = f"joint set {self.name!r}"
        if int(self.count) != self.count or self.count < 1:
            raise ValueError(f"{where}: count must be a positive integer, got {self.count}")
        if self.length[0] not in ("lognormal", "exponential", "uniform", "fixed"):
            raise ValueError(f"{where}: unknown trace-length distribution {self.length[0]!r}")
        if self.dip[0] not in ("normal", "uniform", "fixed"):
            raise ValueError(f"{where}: unknown dip distribution {self.dip[0]!r}")
        if any(not (p > 0) for p in self.length[1:]) and self.length[0] != "uniform":
            raise ValueError(f"{where}: trace-length parameters must be positive, got {self.length[1:]}")

    def _lengths(self, rng) -> np.ndarray:
        kind, *p = self.length
        if kind == "lognormal":  # parameters are the mean and sd of the length itself
            mean, sd = p
            sigma2 = math.log(1 + (sd / mean) ** 2)
            return rng.lognormal(math.log(mean) - sigma2 / 2, math.sqrt(sigma2), self.count)
        if kind == "exponential":
            return rng.exponential(p[0], self.count)
        if kind == "uniform":
            return rng.uniform(p[0], p[1], self.count)
        return np.full(self.count, float(p[0]))

    def _dips(self, rng) -> np.ndarray:
        kind, *p = self.dip
        if kind == "normal":
            d = rng.normal(p[0], p[1], self.count)
        elif kind == "uniform":
            d = rng.uniform(p[0], p[1], self.count)
        else:
            d = np.full(self.count, float(p[0]))
        return np.mod(d, 180.0)

    def raw_segments(self, bounds) -> np.ndarray:
        rng = np.random.default_rng(self.seed)
        x0, y0, x1, y1 = self.region if self.region is not None else bounds
        centres = np.column_stack([rng.uniform(x0, x1, self.count), rng.uniform(y0, y1, self.count)])
        lengths = self._lengths(rng)
        a = np.radians(self._dips(rng))
        half = 0.5 * lengths[:, None] * np.column_stack([np.cos(a), np.sin(a)])
        return np.stack([centres - half, centres + half], axis=1)


JointSet = PersistentSet | IntermittentSet | BrickSet | SegmentSet | StochasticSet


# ----------------------------------------------------------------------------- segment processing


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


# ----------------------------------------------------------------------------- the model


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


@dataclass(frozen=True)
class Geometry:
    """Bodies and joint sets of a plane-strain section (what Gmsh meshes; the mechanical model
    built on its mesh is :class:`fdem.model.Model`).

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


def __getattr__(name: str):
    """``fdem.geometry.Model``: the former name of :class:`Geometry`, kept as a deprecated alias."""
    if name == "Model":
        warnings.warn("fdem.geometry.Model is deprecated: use fdem.geometry.Geometry (fdem.model.Model is the "
                      "mechanical model)", DeprecationWarning, stacklevel=2)
        return Geometry
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
