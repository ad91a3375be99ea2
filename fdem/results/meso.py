"""Meso-scale readings of a slope failure (the views of cases.md B, seed 001): crack initiation
order, fragment assemblies at a given time, principal-stress directions, force chains, the shape
of the magnitude distribution, and a recorder that keeps the states those views need.

Everything but :class:`MesoRecorder` is a plain function of arrays:

* :func:`initiation_order`: the first ``n`` breakages in time order, their rank and how the
  breakage front climbs (least-squares slope of elevation against rank [m per break]);
* :func:`fragments_at`: fragment labels at time ``t`` from each crack element's break time
  (an element is broken at ``t`` when it broke at or before ``t``), and
  :func:`assemblies`: those fragments with at least ``min_triangles`` triangles, relabelled
  ``0..k-1`` by decreasing area, the rest (single-triangle debris) ``-1``;
* :func:`principal_directions`: in-plane principal stresses and the direction of the most
  compressive one, ``theta = 0.5 atan2(2 s_xy, s_xx - s_yy)`` (Mohr's circle; tension positive);
* :func:`force_segments`: a force chain as segments between the centroids of the two
  triangles a force acts between, with its magnitude [N/m];
* :func:`floor_cracking`: broken crack elements below the toe's elevation, in the floor in
  front of the toe and under the slope, by depth below the toe;
* :func:`normality`: Shapiro-Wilk and Anderson-Darling tests of normality of the magnitudes
  (shape), and a two-sample-free Kolmogorov-Smirnov test against a given normal law (shape and
  place), e.g. the paper's N(-3.07, 0.495) (Shapiro & Wilk 1965; Anderson & Darling 1954;
  scipy.stats).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fdem.results.analysis import fragments

__all__ = ["initiation_order", "fragments_at", "assemblies", "assembly_table", "principal_directions",
           "direction_share", "force_segments", "floor_cracking", "normality", "MesoSnapshot", "MesoRecorder"]


def initiation_order(time, x, y, n: int | None = None) -> dict:
    """The first ``n`` breakages (all when ``None``) in time order.

    ``time`` [s], ``x``, ``y`` [m] (n_breaks,) each. Returns ``order`` (indices into the inputs,
    earliest first, stable for ties), ``rank`` (0 for the first), ``first`` ``(x, y)`` of the
    first break, and ``climb_m_per_break``: the least-squares slope of ``y`` against rank over
    the selected breaks (positive: the front climbs), NaN for fewer than two breaks.
    """
    time, x, y = (np.asarray(a, dtype=float).ravel() for a in (time, x, y))
    if not (time.size == x.size == y.size):
        raise ValueError(f"time, x, y must have the same length, got {time.size}, {x.size}, {y.size}")
    if n is not None and n < 1:
        raise ValueError(f"n must be at least 1, got {n}")
    order = np.argsort(time, kind="stable")[:n]
    rank = np.arange(order.size)
    climb = float(np.polyfit(rank, y[order], 1)[0]) if order.size >= 2 else math.nan
    first = (float(x[order[0]]), float(y[order[0]])) if order.size else (math.nan, math.nan)
    return {"order": order, "rank": rank, "first": first, "climb_m_per_break": climb}


def fragments_at(topology, break_time, t: float) -> tuple[int, np.ndarray]:
    """Fragments (connected triangles over the crack elements intact at time ``t`` [s]).

    ``break_time`` (n_cracks,) [s], NaN for an element that never broke
    (``CrackSet.break_time()``). Returns ``(n_fragments, label)`` as
    :func:`fdem.results.analysis.fragments`."""
    bt = np.asarray(break_time, dtype=float)
    if bt.shape != (topology.n_cracks,):
        raise ValueError(f"break_time must have shape ({topology.n_cracks},), got {bt.shape}")
    with np.errstate(invalid="ignore"):
        broken = bt <= t  # NaN compares False: intact
    return fragments(topology, broken)


def assemblies(label, area, min_triangles: int = 2) -> np.ndarray:
    """Fragments of at least ``min_triangles`` triangles relabelled ``0..k-1`` by decreasing
    area; smaller ones (single-triangle debris at the default) get ``-1``.

    ``label`` (n_tri,) fragment of each triangle, ``area`` (n_tri,) triangle areas [m^2]."""
    label = np.asarray(label, dtype=np.int64)
    area = np.asarray(area, dtype=float)
    if label.shape != area.shape:
        raise ValueError(f"label and area must have the same shape, got {label.shape}, {area.shape}")
    if min_triangles < 1:
        raise ValueError(f"min_triangles must be at least 1, got {min_triangles}")
    if label.size == 0:
        return label.copy()
    count = np.bincount(label)
    total = np.bincount(label, weights=area)
    keep = np.flatnonzero(count >= min_triangles)
    keep = keep[np.argsort(-total[keep], kind="stable")]
    new = np.full(count.size, -1, dtype=np.int64)
    new[keep] = np.arange(keep.size)
    return new[label]


def principal_directions(sxx, syy, sxy) -> dict[str, np.ndarray]:
    """In-plane principal stresses ``s1 >= s2`` [Pa] (tension positive) and ``theta2`` [rad], the
    direction of ``s2`` (the most compressive) from the x axis, in (-pi/2, pi/2].

    ``s1,2 = (sxx + syy)/2 +- sqrt(((sxx - syy)/2)^2 + sxy^2)``; the ``s1`` direction is
    ``theta1 = 0.5 atan2(2 sxy, sxx - syy)`` and ``theta2 = theta1 + pi/2``."""
    sxx, syy, sxy = (np.asarray(a, dtype=float) for a in (sxx, syy, sxy))
    mean, r = 0.5 * (sxx + syy), np.hypot(0.5 * (sxx - syy), sxy)
    theta1 = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    theta2 = theta1 + 0.5 * np.pi
    theta2 = np.where(theta2 > 0.5 * np.pi, theta2 - np.pi, theta2)
    return {"s1": mean + r, "s2": mean - r, "theta2": theta2}


def force_segments(centroids, pairs, magnitude) -> tuple[np.ndarray, np.ndarray]:
    """Force-chain segments: ``(segments (k, 4) [x_i, y_i, x_j, y_j] [m], magnitude (k,) [N/m])``
    between the centroids (n_tri, 2) of the triangles of each pair (k, 2); pairs with a zero
    force are dropped."""
    c = np.asarray(centroids, dtype=float)
    p = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    m = np.asarray(magnitude, dtype=float).ravel()
    if m.size != p.shape[0]:
        raise ValueError(f"magnitude has {m.size} entries for {p.shape[0]} pairs")
    if p.size and (p.min() < 0 or p.max() >= c.shape[0]):
        raise ValueError(f"pairs name triangles outside 0..{c.shape[0] - 1}")
    keep = m > 0
    return np.hstack([c[p[keep, 0]], c[p[keep, 1]]]), m[keep]


def floor_cracking(midpoints, broken, toe, toward: float = -1.0, bands=(1.0, 2.0, 4.0, 8.0)) -> dict:
    """Broken crack elements below the toe's elevation: how many and how deep.

    ``midpoints`` (n, 2) reference midpoints of the crack elements [m], ``broken`` (n,) bool,
    ``toe`` ``(x, y)`` of the slope toe [m], ``toward`` -1 when the slope faces -x. An element
    lies below the toe when its midpoint is below the toe's elevation, at depth
    ``d = y_toe - y`` [m]; it is in the floor when it also lies in front of the toe
    (``toward (x - x_toe) > 0``), else under the slope. Returns ``broken``, ``below_toe``,
    ``in_floor``, ``under_slope`` (counts), ``deepest_m`` (largest ``d``, 0 when none) and
    ``by_depth_m``: the broken elements below the toe with ``d`` in each band
    ``(0, b_0], (b_0, b_1], ..., (b_last, inf)``, keyed by the band's text.
    """
    mid = np.asarray(midpoints, dtype=float)
    brk = np.asarray(broken, dtype=bool)
    if mid.ndim != 2 or mid.shape[1] != 2 or brk.shape != (mid.shape[0],):
        raise ValueError(f"midpoints must be (n, 2) and broken (n,), got {mid.shape} and {brk.shape}")
    edges = np.asarray(bands, dtype=float)
    if edges.ndim != 1 or np.any(edges <= 0) or np.any(np.diff(edges) <= 0):
        raise ValueError(f"depth bands must be increasing positive depths [m], got {bands!r}")
    depth = float(toe[1]) - mid[brk, 1]
    front = toward * (mid[brk, 0] - float(toe[0])) > 0
    below = depth > 0
    d = depth[below]
    lows = np.concatenate([[0.0], edges])
    highs = np.concatenate([edges, [np.inf]])
    by_depth = {(f"{lo:g}-{hi:g}" if math.isfinite(hi) else f">{lo:g}"): int(np.sum((d > lo) & (d <= hi)))
                for lo, hi in zip(lows, highs)}
    return {"broken": int(brk.sum()), "below_toe": int(below.sum()), "in_floor": int(np.sum(below & front)),
            "under_slope": int(np.sum(below & ~front)), "deepest_m": float(d.max()) if d.size else 0.0,
            "by_depth_m": by_depth}


def normality(magnitudes, mean: float | None = None, std: float | None = None) -> dict:
    """Is the magnitude distribution normal? Shapiro-Wilk (``shapiro_p``), Anderson-Darling
    (``anderson_statistic`` against ``anderson_critical_5pct``: normal rejected at 5 % when
    above), sample skewness and, when ``mean`` and ``std`` are given, a Kolmogorov-Smirnov test
    of the sample against N(mean, std) (``ks_p``; tests shape and place together). Needs at
    least 3 finite values."""
    import warnings

    from scipy import stats

    m = np.asarray(magnitudes, dtype=float).ravel()
    m = m[np.isfinite(m)]
    if m.size < 3:
        raise ValueError(f"normality needs at least 3 finite magnitudes, got {m.size}")
    sw = stats.shapiro(m)
    with warnings.catch_warnings():  # scipy 1.17 announces a p-value form; the critical values are the test
        warnings.simplefilter("ignore", FutureWarning)
        ad = stats.anderson(m, dist="norm")
    i5 = int(np.argmin(np.abs(np.asarray(ad.significance_level) - 5.0)))
    out = {"n": int(m.size), "mean": float(m.mean()), "std": float(m.std(ddof=1)),
           "skewness": float(stats.skew(m)), "shapiro_W": float(sw.statistic), "shapiro_p": float(sw.pvalue),
           "anderson_statistic": float(ad.statistic), "anderson_critical_5pct": float(ad.critical_values[i5])}
    out["normal_at_5pct"] = bool(out["shapiro_p"] > 0.05 and out["anderson_statistic"] < out["anderson_critical_5pct"])
    if mean is not None and std is not None:
        if not std > 0:
            raise ValueError(f"std of the reference law must be > 0, got {std}")
        ks = stats.kstest(m, "norm", args=(mean, std))
        out.update({"reference_mean": float(mean), "reference_std": float(std), "ks_statistic": float(ks.statistic),
                    "ks_p": float(ks.pvalue)})
    return out


@dataclass
class MesoSnapshot:
    """One kept state: time [s], node positions (n_nodes, 2) [m], per-triangle stresses
    ``sxx, syy, sxy`` [Pa], contact pairs (k, 2) with their force magnitudes [N/m], crack-element
    normal and shear tractions (n_cracks,) [Pa], and the kinetic energy [J/m]."""

    time: float
    x: np.ndarray
    sxx: np.ndarray
    syy: np.ndarray
    sxy: np.ndarray
    contact_pairs: np.ndarray
    contact_force: np.ndarray
    crack_normal: np.ndarray
    crack_shear: np.ndarray
    kinetic: float = 0.0


@dataclass
class MesoRecorder:
    """Keeps a :class:`MesoSnapshot` of a running simulation every ``interval`` [s] of simulated
    time (first at the first history row), as a monitor column ``meso_snapshots`` (their count).
Attach it before the run writes its first history row (the header is fixed then).

    Memory: about ``(6 n_nodes + 3 n_tri + 2 n_cracks + 3 n_pairs) 8`` bytes a snapshot (0.2 MB at
    2,000 triangles). Snapshots taken before a resume are not restored."""

    interval: float
    snapshots: list = field(default_factory=list)

    def attach(self, sim) -> "MesoRecorder":
        if not (math.isfinite(self.interval) and self.interval > 0):
            raise ValueError(f"MesoRecorder.interval must be a positive time [s], got {self.interval!r}")
        self._next = -math.inf

        def keep(s):
            if s.state.time >= self._next:
                self.snapshots.append(self.take(s))
                self._next = s.state.time + self.interval
            return float(len(self.snapshots))

        sim.add_monitor("meso_snapshots", keep)
        return self

    def reset(self) -> None:
        """Forget the kept snapshots; the next history row takes one."""
        self.snapshots.clear()
        self._next = -math.inf

    @staticmethod
    def take(sim) -> MesoSnapshot:
        st = sim.stresses()
        x = sim.state.x
        if sim.contact is not None:
            pf = sim.contact.pair_forces()
            pairs, force = pf["pairs"], np.linalg.norm(pf["force"], axis=1)
        else:
            pairs, force = np.zeros((0, 2), np.int64), np.zeros(0)
        normal, shear = sim.cracks.tractions(x) if sim.cracks is not None else (np.zeros(0), np.zeros(0))
        v = sim.state.v
        kinetic = 0.5 * float(np.sum(sim.model.node_mass() * np.sum(v * v, axis=1)))
        return MesoSnapshot(float(sim.state.time), x.copy(), st["xx"].copy(), st["yy"].copy(), st["xy"].copy(),
                            pairs, force, normal, shear, kinetic)


def assembly_table(assembly, area, centroid_y) -> dict[str, np.ndarray]:
    """Per assembly ``k = 0..K-1`` (:func:`assemblies`; debris ``-1`` left out): ``area`` [m^2]
    and the area-weighted mean elevation ``y`` [m] of its triangles (``centroid_y``, e.g. the
    reference centroids, so that an assembly is placed where it formed)."""
    a = np.asarray(assembly, dtype=np.int64)
    w = np.asarray(area, dtype=float)
    y = np.asarray(centroid_y, dtype=float)
    keep = a >= 0
    k = int(a.max()) + 1 if keep.any() else 0
    total = np.bincount(a[keep], weights=w[keep], minlength=k)
    ybar = np.bincount(a[keep], weights=(w * y)[keep], minlength=k) / np.where(total > 0, total, 1.0)
    return {"area": total, "y": ybar}


def direction_share(theta, direction: float, tolerance: float) -> float:
    """Share of the axial directions ``theta`` [rad] within ``tolerance`` [rad] of ``direction``
    [rad], angles compared modulo pi (a stress direction has no sign). NaN when empty."""
    th = np.asarray(theta, dtype=float).ravel()
    if th.size == 0:
        return math.nan
    d = np.abs((th - direction + 0.5 * np.pi) % np.pi - 0.5 * np.pi)
    return float(np.mean(d <= tolerance))
