"""Micro-seismic events from crack breakages: clustering, seismic moment, moment magnitude,
Gutenberg-Richter b-value and a comparison with a reference catalogue.

Input: the crack breakages of a run, a structured array with at least the fields ``time`` [s],
``x``, ``y`` [m] (crack midpoint), ``length`` [m] and ``energy`` [J per metre of thickness]
(:data:`fdem.physics.cracks.EVENT_DTYPE`, ``CrackSet.events``; ``mode`` is used when present).
Everything here is a plain function of arrays, so it works on a live run or a saved state.

Clustering (after Hazzard & Young 2002, *Tectonophysics* 356, 181-197, who group bond
breakages of a bonded-particle model into events): the breakages are taken in time order; a
breakage joins an event when both

* **space**: its midpoint lies within ``d`` of the midpoint of a breakage already in the event,
  ``d = distance`` if given, else ``size_factor * max(L_new, L_member)`` (the local element
  size ``L`` plays the particle diameter; ``size_factor = 3`` by default), and
* **time**: it occurs no later than ``t_last + T`` after the event's latest breakage, with
  ``T = window`` if given, else ``T = R / c_s``: the time a shear wave (``c_s = sqrt(mu/rho)``)
  takes to cross the event's radius ``R``, the largest distance of a member from the event's
  centroid, at least ``d`` (so that a one-crack event stays open for ``d / c_s``).

A breakage that satisfies both rules for several open events merges them into one.

Magnitudes (formulas in :func:`seismic_moment` and :func:`moment_magnitude`): the 2D
(per metre) energy is made a 3D source by an out-of-plane length equal to the event's source
size; ``M0 = 2 mu E_3D / delta_sigma``; ``Mw = (2/3) log10(M0) - 6.07`` (Hanks & Kanamori 1979).

How M0 is obtained here, against the moment-tensor route. This code takes the fracture energy
the crack elements of an event dissipated (``E_2D`` [J/m], softening work, friction excluded),
makes it a square patch of side ``L_s`` (``E_3D = E_2D L_s``) and converts energy to moment by
the stress drop, ``M0 = 2 mu E_3D / delta_sigma`` with ``delta_sigma`` the mean tensile
strength of the property sets (:class:`fdem.results.report.RunReport`). The bonded-particle
models the Muliashi paper follows (Hazzard & Young 2000, 2002) instead sum, for each broken
bond of an event, the change of the contact forces ``delta F_i`` at the bond's contacts times
their arm ``R_j`` into a moment tensor ``M_ij = sum (delta F_i R_j)``, take its largest value
while the event lasts, and ``M0 = sqrt(sum_j m_j^2 / 2)`` of its eigenvalues ``m_j``. Both
measure the same thing, the size of the force release, but: (1) the tensor route needs no
assumed stress drop or out-of-plane length, the energy route moves by ``-(2/3) log10`` of the
stress drop and ``+(2/3) log10 L_s``; (2) a PFC bond is millimetres to centimetres wide, a crack
element here 0.5-1 m, so one breakage releases the force over a patch ~10-100 times wider:
with ``M0 ~ delta_sigma L^3`` a tenfold size is two magnitude units per breakage before
clustering (here ``E_2D = G L`` with the size rule's ``G_I = 404 h`` J/m^2 makes
``M0 = 2 mu G L^2 / delta_sigma`` grow as ``h^3`` too); (3) the tensor route sees the force change around the break (including the
neighbours' unloading), the energy route only the softening work of the broken elements.
Magnitudes of this code therefore fall with element size; they are compared with a PFC
catalogue by shape (:func:`fdem.results.meso.normality`) more than by place.
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
import numpy as np
from fdem.io.pictures import finish, new_figure
from scipy.spatial.distance import pdist

__all__ = ["CATALOGUE_DTYPE", "MULIASHI", "MW_CONSTANT", "NO_EVENTS", "EventCatalogue", "seismic_moment",
           "moment_magnitude", "cluster_events", "write_catalogue_csv", "magnitude_statistics", "b_value",
           "max_curvature_mc", "magnitude_frequency", "compare_with_reference", "magnitude_plot"]


CATALOGUE_DTYPE = np.dtype([
    ("event", np.int64), ("t_start", np.float64), ("duration", np.float64), ("x", np.float64), ("y", np.float64),
    ("n_cracks", np.int64), ("n_I", np.int64), ("n_II", np.int64), ("n_mixed", np.int64),
    ("energy", np.float64), ("source_size", np.float64), ("energy_3d", np.float64),
    ("moment", np.float64), ("magnitude", np.float64),
])
"""One micro-seismic event: id, start time [s], duration (last minus first breakage) [s],
energy-weighted centroid [m], number of breakages (all, mode I, mode II, mixed), released
energy [J/m], source size ``L_s`` [m], 3D-equivalent energy ``E_3D = E L_s`` [J], seismic moment
[N m], moment magnitude."""


MULIASHI = {"count": 238, "min": -4.91, "max": -2.05, "mean": -3.07, "std": 0.495}
"""Micro-seismic catalogue of the Muliashi slope model (bonded-particle PFC2D; ``/work/shared
cases.md`` case B): 238 events, magnitudes -4.91 to -2.05, mean -3.07, standard deviation 0.495."""


MW_CONSTANT = 6.07
"""``Mw = (2/3) log10(M0 [N m]) - 6.07`` (Hanks & Kanamori 1979 with Kanamori's 9.1: 2/3 * 9.1)."""


NO_EVENTS = "no events: the run recorded no crack breakage (or none passed the filters)"


@dataclass
class EventCatalogue:
    """Events found by :func:`cluster_events`.

    ``events``: structured array of :data:`CATALOGUE_DTYPE`, by start time; ``members``: for each
    event the rows of the input breakage array that form it (time order); ``rule``: the
    parameters used (distance, window or shear-wave speed, shear modulus, stress drop).
    """

    events: np.ndarray
    members: list[np.ndarray] = field(default_factory=list)
    rule: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.events.size)

    @property
    def empty(self) -> bool:
        return self.events.size == 0

    @property
    def magnitudes(self) -> np.ndarray:
        return self.events["magnitude"]

    def summary(self) -> str:
        """One line: the count and the magnitude range, or :data:`NO_EVENTS`."""
        if self.empty:
            return NO_EVENTS
        m = self.magnitudes
        return f"{m.size} events, Mw {m.min():.2f} to {m.max():.2f}, mean {m.mean():.2f}"


def seismic_moment(energy_2d, source_size, shear_modulus: float, stress_drop: float) -> np.ndarray:
    """Seismic moment [N m] of an event that released ``energy_2d`` [J/m] over ``source_size`` [m].

    The plane-strain energy per metre is made a 3D source by an out-of-plane length equal to the
    in-plane source size, ``E_3D = E_2D L_s`` [J] (a square rupture patch ``A = L_s^2``). On that
    patch the cohesive stress drops by ``delta_sigma`` over the slip ``u``; with linear softening
    the work is ``E_3D = delta_sigma u A / 2``, so ``u = 2 E_3D / (delta_sigma A)`` and
    ``M0 = mu A u = 2 mu E_3D / delta_sigma`` (Aki 1966 for ``M0 = mu A u``; the same relation
    as Kanamori 1977's ``E = delta_sigma M0 / (2 mu)``). ``shear_modulus`` ``mu`` [Pa],
    ``stress_drop`` ``delta_sigma`` [Pa], e.g. the tensile strength or cohesion of the bonds.
    """
    if shear_modulus <= 0 or stress_drop <= 0:
        raise ValueError(f"shear modulus and stress drop must be > 0 Pa, got {shear_modulus}, {stress_drop}")
    return 2.0 * shear_modulus * np.asarray(energy_2d, float) * np.asarray(source_size, float) / stress_drop


def moment_magnitude(moment) -> np.ndarray:
    """Moment magnitude ``Mw = (2/3) log10(M0) - 6.07``, ``M0`` in N m (Hanks & Kanamori 1979,
    *J. Geophys. Res.* 84, 2348-2350). ``-inf`` for ``M0 = 0``."""
    with np.errstate(divide="ignore"):
        return (2.0 / 3.0) * np.log10(np.asarray(moment, float)) - MW_CONSTANT


def _check_breakages(breakages) -> np.ndarray:
    b = np.asarray(breakages)
    need = ("time", "x", "y", "length", "energy")
    if b.dtype.names is None:
        raise ValueError(f"breakages must be a structured array with fields {need} (CrackSet.events)")
    missing = [n for n in need if n not in b.dtype.names]
    if missing:
        raise ValueError(f"breakages lack field(s) {missing}; need {need} (see fdem.physics.cracks.EVENT_DTYPE)")
    if b.ndim != 1:
        raise ValueError(f"breakages must be 1-D, got shape {b.shape}")
    return b


def _source_size(px: np.ndarray, py: np.ndarray, length: np.ndarray) -> float:
    """``L_s = D + mean(L)``: the largest distance between two member midpoints plus the mean
    crack length (the rupture length of a straight chain of cracks; one crack's length for a
    single crack). Beyond 4000 members ``D`` is the diagonal of their bounding box."""
    n = px.size
    if n == 1:
        return float(length[0])
    if n <= 4000:
        d = float(pdist(np.column_stack([px, py])).max())
    else:
        d = float(math.hypot(np.ptp(px), np.ptp(py)))
    return d + float(length.mean())


def cluster_events(breakages, shear_modulus: float, stress_drop: float, density: float | None = None,
                   window: float | None = None, distance: float | None = None,
                   size_factor: float = 3.0) -> EventCatalogue:
    """Group crack breakages into micro-seismic events (rule in the module docstring).

    Parameters
    ----------
    breakages : structured array with ``time``, ``x``, ``y``, ``length``, ``energy`` (and ``mode``)
    shear_modulus : ``mu`` of the rock [Pa] (moment, and shear-wave speed)
    stress_drop : ``delta_sigma`` [Pa] for :func:`seismic_moment`
    density : rock density [kg/m^3], for ``c_s = sqrt(mu / rho)``; needed unless ``window`` is given
    window : fixed time window [s] instead of the shear-wave rule
    distance : fixed join distance [m] instead of ``size_factor * element length``

    Returns an :class:`EventCatalogue`; no breakages give an empty one whose
    :meth:`~EventCatalogue.summary` says "no events".
    """
    b = _check_breakages(breakages)
    if window is None and (density is None or density <= 0):
        raise ValueError("give the rock density [kg/m^3] (shear-wave time window) or a fixed window [s]")
    if window is not None and window < 0:
        raise ValueError(f"time window must be >= 0 s, got {window}")
    if distance is not None and distance <= 0:
        raise ValueError(f"join distance must be > 0 m, got {distance}")
    c_s = math.sqrt(shear_modulus / density) if window is None else None
    rule = {"shear_modulus_Pa": shear_modulus, "stress_drop_Pa": stress_drop, "window_s": window,
            "shear_wave_speed_m_s": c_s, "distance_m": distance, "size_factor": size_factor}
    if b.size == 0:
        return EventCatalogue(np.zeros(0, CATALOGUE_DTYPE), [], rule)

    order = np.argsort(b["time"], kind="stable")
    t, px, py = b["time"][order], b["x"][order], b["y"][order]
    length = b["length"][order].astype(float)
    energy = b["energy"][order].astype(float)

    # Breakages of open events (indices into the time-sorted arrays) and their event labels;
    # an event's members are all open while it is, so a merge relabels only open entries.
    label = np.empty(t.size, dtype=np.int64)
    end = np.empty(t.size)  # time each event stays open until, by label
    open_idx = np.zeros(0, dtype=np.int64)
    open_ev = np.zeros(0, dtype=np.int64)
    n_ev = 0
    for i in range(t.size):
        if open_idx.size:
            alive = end[open_ev] >= t[i]
            if not alive.all():
                open_idx, open_ev = open_idx[alive], open_ev[alive]
        if open_idx.size:
            d = distance if distance is not None else size_factor * np.maximum(length[open_idx], length[i])
            near = np.hypot(px[open_idx] - px[i], py[open_idx] - py[i]) <= d
        else:
            near = np.zeros(0, bool)
        if near.any():
            hits = np.unique(open_ev[near])
            e = int(hits[0])
            if hits.size > 1:
                merged = np.isin(open_ev, hits)
                open_ev[merged] = e
                label[open_idx[merged]] = e
        else:
            e = n_ev
            n_ev += 1
        label[i] = e
        open_idx = np.append(open_idx, i)
        open_ev = np.append(open_ev, e)
        if window is not None:
            end[e] = t[i] + window
        else:
            m = open_idx[open_ev == e]
            r = np.hypot(px[m] - px[m].mean(), py[m] - py[m].mean()).max()
            d_own = distance if distance is not None else size_factor * float(length[m].max())
            end[e] = t[i] + max(r, d_own) / c_s

    # Number the events by their first breakage (labels were given in that order, merges keep
    # the older label), then per-event sums by bincount.
    _, ev = np.unique(label, return_inverse=True)
    k = int(ev.max()) + 1
    by_event = np.argsort(ev, kind="stable")
    groups = np.split(by_event, np.flatnonzero(np.diff(ev[by_event])) + 1)
    count = np.bincount(ev, minlength=k)
    e2 = np.bincount(ev, weights=energy, minlength=k)
    zero = e2[ev] <= 0  # events without energy: plain centroid
    w = np.where(zero, 1.0, energy)
    wsum = np.bincount(ev, weights=w, minlength=k)
    size = np.zeros(k)
    for n_, m in enumerate(groups):
        size[n_] = _source_size(px[m], py[m], length[m])
    cat = np.zeros(k, CATALOGUE_DTYPE)
    cat["event"] = np.arange(k)
    first = np.full(k, np.inf)
    last = np.full(k, -np.inf)
    np.minimum.at(first, ev, t)
    np.maximum.at(last, ev, t)
    cat["t_start"], cat["duration"] = first, last - first
    cat["x"] = np.bincount(ev, weights=w * px, minlength=k) / wsum
    cat["y"] = np.bincount(ev, weights=w * py, minlength=k) / wsum
    cat["n_cracks"] = count
    if "mode" in b.dtype.names:
        modes = b["mode"][order]
        for name, key in (("I", "n_I"), ("II", "n_II"), ("mixed", "n_mixed")):
            cat[key] = np.bincount(ev, weights=(modes == name).astype(float), minlength=k).astype(np.int64)
    cat["energy"], cat["source_size"], cat["energy_3d"] = e2, size, e2 * size
    cat["moment"] = seismic_moment(e2, size, shear_modulus, stress_drop)
    cat["magnitude"] = moment_magnitude(cat["moment"])
    return EventCatalogue(cat, [order[m] for m in groups], rule)


def write_catalogue_csv(path: str | os.PathLike, catalogue: EventCatalogue | np.ndarray) -> Path:
    """Write the event catalogue as CSV, one row per event, columns of :data:`CATALOGUE_DTYPE`
    (SI units: s, m, J/m, m, J, N m). An empty catalogue writes the header and the comment line
    ``# no events: ...`` so an empty file is never silent."""
    ev = catalogue.events if isinstance(catalogue, EventCatalogue) else np.asarray(catalogue)
    if ev.dtype.names is None:
        raise ValueError("catalogue must be an EventCatalogue or a structured array of CATALOGUE_DTYPE")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(ev.dtype.names)
        for row in ev:
            w.writerow([f"{v:.10g}" if isinstance(v, (float, np.floating)) else v for v in row.tolist()])
        if ev.size == 0:
            fh.write(f"# {NO_EVENTS}\n")
    return path


def _magnitudes(m) -> np.ndarray:
    if isinstance(m, EventCatalogue):
        m = m.magnitudes
    m = np.asarray(m, dtype=np.float64).ravel()
    return m[np.isfinite(m)]


def magnitude_statistics(magnitudes) -> dict:
    """``count``, ``min``, ``max``, ``mean`` and ``std`` (sample standard deviation, ``ddof = 1``)
    of the finite magnitudes; with no events, ``count = 0``, NaN statistics and ``message``
    :data:`NO_EVENTS`."""
    m = _magnitudes(magnitudes)
    if m.size == 0:
        nan = float("nan")
        return {"count": 0, "min": nan, "max": nan, "mean": nan, "std": nan, "message": NO_EVENTS}
    return {"count": int(m.size), "min": float(m.min()), "max": float(m.max()), "mean": float(m.mean()),
            "std": float(m.std(ddof=1)) if m.size > 1 else 0.0, "message": ""}


def b_value(magnitudes, mc: float | None = None, dm: float = 0.0) -> dict:
    """Gutenberg-Richter ``log10 N(>= M) = a - b M``: maximum-likelihood b-value (Aki 1965,
    *Bull. Earthq. Res. Inst.* 43, 237-239), ``b = log10(e) / (mean(M) - (M_c - dm/2))`` over the
    events with ``M >= M_c`` (``dm`` the magnitude bin width, Utsu's correction; 0 for
    unbinned magnitudes). ``mc`` defaults to the smallest magnitude. Returns ``b``, its standard
    error ``b / sqrt(n)`` (Aki 1965), ``a = log10 n + b M_c``, ``mc`` and ``n``. Raises
    ``ValueError`` with fewer than two events above ``M_c``."""
    m = _magnitudes(magnitudes)
    if m.size == 0:
        raise ValueError(f"cannot fit a b-value: {NO_EVENTS}")
    mc = float(m.min()) if mc is None else float(mc)
    m = m[m >= mc]
    if m.size < 2:
        raise ValueError(f"cannot fit a b-value: {m.size} event(s) with M >= Mc = {mc:.3g}; need at least 2")
    excess = m.mean() - (mc - dm / 2.0)
    if excess <= 0:
        raise ValueError("cannot fit a b-value: all magnitudes equal Mc")
    b = math.log10(math.e) / excess
    return {"b": b, "b_error": b / math.sqrt(m.size), "a": math.log10(m.size) + b * mc, "mc": mc, "n": int(m.size)}


def max_curvature_mc(magnitudes, dm: float = 0.1) -> float:
    """Magnitude of completeness by maximum curvature (Wiemer & Wyss 2000, *Bull. Seismol. Soc.
    Am.* 90, 859-869): the lower edge of the ``dm`` bin holding the most events."""
    mf = magnitude_frequency(magnitudes, dm)
    if mf["counts"].size == 0:
        raise ValueError(f"cannot find Mc: {NO_EVENTS}")
    return float(mf["edges"][int(np.argmax(mf["counts"]))])


def magnitude_frequency(magnitudes, dm: float = 0.1) -> dict[str, np.ndarray]:
    """Magnitude-frequency table in bins of width ``dm``: ``edges`` (lower edges, multiples of
    ``dm``, plus the last upper edge), ``counts`` (events per bin) and ``cumulative`` (events with
    ``M >=`` each lower edge, the Gutenberg-Richter ``N(>= M)``). Empty arrays with no events."""
    m = _magnitudes(magnitudes)
    if dm <= 0:
        raise ValueError(f"bin width dm must be > 0, got {dm}")
    if m.size == 0:
        return {"edges": np.zeros(0), "counts": np.zeros(0, int), "cumulative": np.zeros(0, int)}
    lo, hi = math.floor(m.min() / dm + 1e-9), math.floor(m.max() / dm + 1e-9) + 1
    edges = np.arange(lo, hi + 1) * dm
    counts, _ = np.histogram(m, bins=edges)
    return {"edges": edges, "counts": counts, "cumulative": counts[::-1].cumsum()[::-1]}


def compare_with_reference(magnitudes, reference: dict | None = None) -> dict:
    """Compare magnitude statistics with a reference catalogue (default :data:`MULIASHI`).

    Returns, per quantity (``count``, ``min``, ``max``, ``mean``, ``std``), ``{"fdem": ...,
    "reference": ..., "difference": fdem - reference}``, plus ``mean_difference_in_std`` (the
    mean difference in units of the reference standard deviation) and ``message`` (empty, or
    "no events")."""
    ref = MULIASHI if reference is None else reference
    ours = magnitude_statistics(magnitudes)
    out = {q: {"fdem": ours[q], "reference": ref[q], "difference": ours[q] - ref[q]}
           for q in ("count", "min", "max", "mean", "std")}
    out["mean_difference_in_std"] = (ours["mean"] - ref["mean"]) / ref["std"]
    out["message"] = ours["message"]
    return out


def magnitude_plot(path: str | os.PathLike | None, magnitudes: np.ndarray, dm: float = 0.1, mc: float | None = None,
                   reference: dict | None = None, title: str = "", dpi: int = 130) -> Path:
    """Left: histogram of event moment magnitudes (bins ``dm``), with the normal density of a
    reference catalogue's mean and standard deviation (e.g. :data:`fdem.results.events.MULIASHI`) scaled
    to the count. Right: ``N(>= M)`` on a log axis with the Gutenberg-Richter line
    ``log10 N = a - b M`` fitted by maximum likelihood above ``mc`` (default: maximum
    curvature, :func:`fdem.results.events.max_curvature_mc`).
    With no events the picture says so. Returns the path, or the Figure when ``path`` is None."""
    m = np.asarray(magnitudes, float).ravel()
    m = m[np.isfinite(m)]
    fig = new_figure((10.0, 4.2))
    ax1, ax2 = fig.add_subplot(121), fig.add_subplot(122)
    if m.size == 0:
        for ax in (ax1, ax2):
            ax.text(0.5, 0.5, "no events", ha="center", va="center", transform=ax.transAxes, fontsize=14)
    else:
        mf = magnitude_frequency(m, dm)
        e = mf["edges"]
        ax1.bar(e[:-1], mf["counts"], width=dm, align="edge", color="C0", edgecolor="k", lw=0.4,
                label=f"fdem: {m.size} events")
        if reference is not None:
            s = np.linspace(min(e[0], reference["mean"] - 4 * reference["std"]),
                            max(e[-1], reference["mean"] + 4 * reference["std"]), 200)
            pdf = np.exp(-0.5 * ((s - reference["mean"]) / reference["std"]) ** 2) / (reference["std"] * np.sqrt(2 * np.pi))
            ax1.plot(s, pdf * m.size * dm, color="C3", lw=1.4,
                     label=f"reference N({reference['mean']:.2f}, {reference['std']:.3g})")
        ax1.legend(fontsize=8)
        ax2.semilogy(e[:-1], mf["cumulative"], "o", color="C0", ms=4, label="N(>= M)")
        mc = max_curvature_mc(m, dm) if mc is None else mc
        if (m >= mc).sum() >= 2 and np.ptp(m[m >= mc]) > 0:
            fit = b_value(m, mc=mc, dm=0.0)
            s = np.linspace(fit["mc"], m.max(), 50)
            ax2.semilogy(s, 10 ** (fit["a"] - fit["b"] * s), color="C3",
                         label=f"b = {fit['b']:.2f} +- {fit['b_error']:.2f} (Mc = {fit['mc']:.2f})")
        ax2.legend(fontsize=8)
    ax1.set_xlabel("moment magnitude Mw [-]")
    ax1.set_ylabel("events per bin [-]")
    ax2.set_xlabel("moment magnitude Mw [-]")
    ax2.set_ylabel("N(>= Mw) [-]")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.suptitle(title or "micro-seismic events")
    fig.tight_layout()
    return finish(fig, path, dpi)
