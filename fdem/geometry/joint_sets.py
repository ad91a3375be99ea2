"""Joint sets: the generators of a discrete fracture network's traces.

Each set produces straight segments (m) over a bounding box; :class:`fdem.geometry.section.Geometry`
clips them to the bodies. ``dip`` is the angle of a trace counter-clockwise from ``+x`` in
degrees, ``0 <= dip < 180``. Sets: :class:`PersistentSet` (parallel, persistent),
:class:`IntermittentSet` (en echelon traces with rock bridges), :class:`BrickSet` (the
four-slope fabric), :class:`SegmentSet` (explicit segments), :class:`StochasticSet` (seeded
random traces)."""
from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np

__all__ = ["PersistentSet", "IntermittentSet", "BrickSet", "SegmentSet", "StochasticSet", "BandedSet", "clip_to_x"]


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


def clip_to_x(segments: np.ndarray, x_low: float, x_high: float) -> np.ndarray:
    """The parts of ``segments`` (n, 2, 2) [m] with ``x_low <= x <= x_high``; segments wholly
    outside the band are dropped. A vertical segment is kept whole or dropped."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
    a, b = seg[:, 0], seg[:, 1]
    dx = b[:, 0] - a[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_low = np.where(dx != 0.0, (x_low - a[:, 0]) / dx, np.where(a[:, 0] >= x_low, -np.inf, np.inf))
        t_high = np.where(dx != 0.0, (x_high - a[:, 0]) / dx, np.where(a[:, 0] <= x_high, np.inf, -np.inf))
    t0 = np.maximum(0.0, np.where(dx >= 0.0, t_low, t_high))
    t1 = np.minimum(1.0, np.where(dx >= 0.0, t_high, t_low))
    keep = t1 > t0
    d = b - a
    return np.stack([a[keep] + t0[keep, None] * d[keep], a[keep] + t1[keep, None] * d[keep]], axis=1)


@dataclass(frozen=True)
class BandedSet:
    """A joint set kept out of bands of intact rock along the model's left and right sides:
    its joints only where ``x_low + band <= x <= x_high - band`` (``x_low``, ``x_high`` the
    domain's bounds). Lateral boundaries of a jointed model (rollers) would otherwise hold
    wedges cut by joints that meet them, and slip there belongs to the boundary, not to the
    slope (``docs/cases.md`` A, the high-angle slopes); an intact band keeps the boundary out
    of the mechanism. ``band`` [m] is the width of each band.
    """

    joints: object
    band: float

    def __post_init__(self):
        if not (math.isfinite(self.band) and self.band > 0):
            raise ValueError(f"band must be a positive width [m], got {self.band!r}")

    @property
    def name(self) -> str:
        return f"{getattr(self.joints, 'name', 'joints')} (intact {self.band:g} m bands at the sides)"

    def raw_segments(self, bounds) -> np.ndarray:
        x0, _, x1, _ = bounds
        if x1 - x0 <= 2.0 * self.band:
            raise ValueError(f"joint set {self.name!r}: bands of {self.band:g} m leave no room in a domain "
                             f"{x1 - x0:g} m wide")
        return clip_to_x(self.joints.raw_segments(bounds), x0 + self.band, x1 - self.band)
