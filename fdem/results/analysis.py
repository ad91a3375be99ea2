"""Results of a run: fragments, runout distance and volume, deposit, displacements, failure surface.

All functions take plain arrays (positions, topology, broken flags) so they work on a live
simulation or on a saved state. Areas are per metre of thickness (plane strain), so an "area"
[m^2] is also a volume per metre [m^3/m]. Definitions with their reasons: ``docs/outputs.md``.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from fdem.mesh.topology import Topology
from fdem.mesh.triangles import triangle_areas

__all__ = ["fragments", "fragment_areas", "weighted_percentile", "triangle_displacement", "displaced",
           "displacement_statistics", "runout", "deposit_profile", "failure_surface", "fragment_statistics",
           "released_kinetic_energy", "history_columns", "crack_breakdown", "boundary_motion",
           "displaced_areas", "AREA_THRESHOLDS"]


def fragments(topology: Topology, broken: np.ndarray) -> tuple[int, np.ndarray]:
    """Clusters of triangles still bonded by intact crack elements.

    Returns ``(n_fragments, label)`` with ``label`` (n_tri,) the fragment of each triangle
    (connected components of the graph whose edges are the unbroken crack elements).
    """
    intact = ~np.asarray(broken, dtype=bool)
    a, b = topology.crack_triangles[intact, 0], topology.crack_triangles[intact, 1]
    n = topology.n_triangles
    graph = coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)


def fragment_areas(topology: Topology, label: np.ndarray) -> np.ndarray:
    """Area of each fragment [m^2 per metre of thickness], indexed by fragment label."""
    return np.bincount(label, weights=topology.triangle_area0)


def weighted_percentile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """Weighted ``q``-th percentile (``0 <= q <= 100``): the smallest value ``v_i`` (sorted) at which
    the cumulative weight reaches ``q/100`` of the total, ``min{v_i : sum_{v_j <= v_i} w_j >= q/100 W}``.

    An inverse-CDF (no interpolation) definition: a value carried by less than ``1 - q/100`` of
    the weight cannot become the percentile. NaN for empty input.
    """
    values = np.asarray(values, dtype=np.float64).ravel()
    weights = np.asarray(weights, dtype=np.float64).ravel()
    if values.shape != weights.shape:
        raise ValueError(f"values {values.shape} and weights {weights.shape} must have the same shape")
    if not 0.0 <= q <= 100.0:
        raise ValueError(f"percentile q must lie in [0, 100], got {q}")
    if values.size == 0 or weights.sum() <= 0.0:
        return float("nan")
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(weights[order])
    k = int(np.searchsorted(cum, q / 100.0 * cum[-1] * (1.0 - 1e-12), side="left"))
    return float(values[order[min(k, values.size - 1)]])


def triangle_displacement(topology: Topology, x: np.ndarray) -> np.ndarray:
    """(n_tri,) displacement magnitude of each triangle's centroid ``|x_c - X_c|`` [m]."""
    x = _check_positions(topology, x)
    d = x[topology.triangles].mean(axis=1) - topology.x0[topology.triangles].mean(axis=1)
    return np.hypot(d[:, 0], d[:, 1])


def displaced(topology: Topology, x: np.ndarray, threshold: float = 0.1) -> np.ndarray:
    """(n_tri,) bool: triangles whose centroid moved more than ``threshold`` [m]."""
    if threshold < 0:
        raise ValueError(f"displacement threshold must be >= 0 m, got {threshold}")
    return triangle_displacement(topology, x) > threshold


def _check_positions(topology: Topology, x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (topology.n_nodes, 2):
        raise ValueError(f"positions must have shape ({topology.n_nodes}, 2), got {x.shape}")
    return x


def displacement_statistics(topology: Topology, x: np.ndarray, mask: np.ndarray | None = None) -> dict[str, float]:
    """Maximum and area-weighted percentiles of the displacement [m].

    ``max_m``: largest node displacement ``max |x - X|`` over the nodes of the selected
    triangles; ``p50_m``, ``p90_m``, ``p99_m``: :func:`weighted_percentile` of the triangle
    centroid displacements weighted by reference area. ``mask`` (n_tri,) bool selects triangles
    (default all; pass :func:`displaced` for the failed mass). NaN when nothing is selected.
    """
    x = _check_positions(topology, x)
    sel = np.ones(topology.n_triangles, bool) if mask is None else np.asarray(mask, bool)
    if sel.shape != (topology.n_triangles,):
        raise ValueError(f"mask must have shape ({topology.n_triangles},), got {sel.shape}")
    if not sel.any():
        return {"max_m": float("nan"), "p50_m": float("nan"), "p90_m": float("nan"), "p99_m": float("nan")}
    nodes = topology.triangles[sel].ravel()
    u = np.linalg.norm(x[nodes] - topology.x0[nodes], axis=1)
    dc = triangle_displacement(topology, x)[sel]
    a = topology.triangle_area0[sel]
    return {"max_m": float(u.max()), **{f"p{q}_m": weighted_percentile(dc, a, q) for q in (50, 90, 99)}}


def runout(topology: Topology, x: np.ndarray, toe_x: float, threshold: float = 0.1,
           toward: float = -1.0, percentile: float = 99.0) -> dict[str, float]:
    """Runout of the failed mass of a slope whose toe is at ``x = toe_x``.

    Displaced material: triangles whose centroid moved more than ``threshold`` [m]. The reach of a
    displaced triangle is how far its farthest corner lies beyond the toe,
    ``r = max(0, max_k toward (x_k - toe_x))`` [m] (``toward = -1`` with the toe on the left).

    * ``runout_distance_m``: the area-weighted ``percentile`` (default 99th) of ``r`` over the
      displaced material (:func:`weighted_percentile`): the front of the failed mass, beyond
      which lies less than 1 % of its area. A single thrown triangle (or any debris holding less
      than 1 % of the displaced area) does not move it; ``runout_front_max_m`` is the plain
      maximum of ``r`` for comparison.
    * ``runout_volume_m2`` (= ``displaced_area_m2``): reference area of the displaced material
      [m^2 per metre of thickness = m^3/m].
    * ``passed_toe_area_m2``: reference area of displaced triangles whose centroid is beyond the toe.
    * ``max_displacement_m``: largest node displacement anywhere; ``p50/p90/p99_displacement_m``:
      :func:`displacement_statistics` over the displaced material.
    * ``deformed_area_m2``: current area of all triangles (a mass-balance check).
    * ``off_model_area_m2``: reference area of displaced triangles whose centroid lies beyond
      the model's initial x range: debris that ran off the end of the floor, where nothing holds
      it. When it is not zero the runout was cut by the model's extent and ``runout_distance_m``
      is a lower bound (lengthen the floor in front of the toe).
    """
    x = _check_positions(topology, x)
    moved = displaced(topology, x, threshold)
    reach = np.maximum(toward * (x[topology.triangles[moved], 0] - toe_x), 0.0).max(axis=1, initial=0.0) \
        if moved.any() else np.zeros(0)
    area = topology.triangle_area0[moved]
    xc = x[topology.triangles[moved]].mean(axis=1)
    stats = displacement_statistics(topology, x, moved)
    return {
        "displaced_area_m2": float(area.sum()),
        "runout_volume_m2": float(area.sum()),
        "runout_distance_m": weighted_percentile(reach, area, percentile) if reach.size else 0.0,
        "runout_front_max_m": float(reach.max()) if reach.size else 0.0,
        "passed_toe_area_m2": float(area[toward * (xc[:, 0] - toe_x) > 0].sum()),
        "max_displacement_m": float(np.linalg.norm(x - topology.x0, axis=1).max()),
        "p50_displacement_m": stats["p50_m"],
        "p90_displacement_m": stats["p90_m"],
        "p99_displacement_m": stats["p99_m"],
        "n_displaced_triangles": int(moved.sum()),
        "deformed_area_m2": float(triangle_areas(x, topology.triangles).sum()),
        "off_model_area_m2": float(area[(xc[:, 0] < topology.x0[:, 0].min())
                                        | (xc[:, 0] > topology.x0[:, 0].max())].sum()),
    }


AREA_THRESHOLDS = (0.1, 1.0, 10.0)
"""Displacements [m] at which :func:`displaced_areas` measures the displaced area."""


def displaced_areas(topology: Topology, x: np.ndarray, thresholds=AREA_THRESHOLDS) -> dict[str, float]:
    """Reference area [m^2 per metre] of the triangles whose centroid moved more than each
    threshold [m], keyed by the threshold as written (``"0.1"``, ``"1"``, ``"10"``). The failed
    mass at 0.1 m holds what crept and settled behind a slide as well as what ran out; the area
    above 1 m is the part that ran, the one to set beside a runout volume."""
    d = triangle_displacement(topology, x)
    return {f"{t:g}": float(topology.triangle_area0[d > t].sum()) for t in thresholds}


def boundary_motion(x0: np.ndarray, x: np.ndarray, tolerance: float = 1e-6) -> dict[str, dict]:
    """How far the model's own boundaries moved, from the nodes' reference positions ``x0`` and
    positions ``x`` (n, 2) [m]: for each of its ``left``, ``right`` and ``base`` sides, the
    nodes that started on it (``|X - X_side| <= tolerance * extent``), their largest
    displacement ``max |x - X|`` [m] and its component along the side [m] (vertical for the
    sides, horizontal for the base: the slip a roller lets through).

    A boundary that takes no part in a failure stays where it was, to within the elastic
    motion of the rock (millimetres); a failure that reaches it drags its nodes along the
    roller by as much as the mass beside it moves. It does not show a boundary that *holds*:
    a roller met by a joint whose slip it would have to let through keeps that joint shut and
    stays put. That part is shown only by a wider model giving the same bracket and mechanism
    (``docs/cases.md`` A, "Boundaries"); this figure is the one beside it."""
    x0 = np.asarray(x0, dtype=np.float64)[:, :2]
    x = np.asarray(x, dtype=np.float64)[:, :2]
    if x.shape != x0.shape:
        raise ValueError(f"positions must have the reference positions' shape {x0.shape}, got {x.shape}")
    extent = float(max(np.ptp(x0[:, 0]), np.ptp(x0[:, 1]), 1e-300))
    tol = tolerance * extent
    u = x - x0
    sides = {"left": (np.abs(x0[:, 0] - x0[:, 0].min()) <= tol, 1),
             "right": (np.abs(x0[:, 0] - x0[:, 0].max()) <= tol, 1),
             "base": (np.abs(x0[:, 1] - x0[:, 1].min()) <= tol, 0)}
    out = {}
    for name, (on, along) in sides.items():
        out[name] = {"n_nodes": int(on.sum()),
                     "max_displacement_m": float(np.linalg.norm(u[on], axis=1).max()) if on.any() else 0.0,
                     "max_slip_m": float(np.abs(u[on, along]).max()) if on.any() else 0.0}
    return out


def deposit_profile(topology: Topology, x: np.ndarray, floor_y: float, bins, threshold: float = 0.1,
                    mask: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Height of the displaced material over the floor ``y = floor_y`` [m] in x bins.

    Each displaced triangle (centroid moved more than ``threshold`` [m], or ``mask``) is put in
    the bin of its current centroid. Per bin ``[e_i, e_{i+1})``:

    * ``top``: highest corner of its triangles above the floor, ``max y - floor_y`` [m] (0 if empty);
    * ``thickness``: current area of its triangles divided by the bin width [m], the height of
      the deposit packed without voids (equals ``top`` for a solid block resting on the floor).

    ``bins``: bin edges (increasing) or a number of bins over the displaced material's x range.
    Returns ``edges``, ``centres``, ``top``, ``thickness``, ``area`` (per bin, m^2).
    """
    x = _check_positions(topology, x)
    moved = displaced(topology, x, threshold) if mask is None else np.asarray(mask, bool)
    tri = topology.triangles[moved]
    xc = x[tri].mean(axis=1)
    if np.ndim(bins) == 0:
        n = int(bins)
        if n < 1:
            raise ValueError(f"need at least one bin, got {bins}")
        lo, hi = (x[tri, 0].min(), x[tri, 0].max()) if tri.size else (0.0, 1.0)
        edges = np.linspace(lo, hi if hi > lo else lo + 1.0, n + 1)
    else:
        edges = np.asarray(bins, dtype=np.float64)
        if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
            raise ValueError("bin edges must be a strictly increasing 1-D array of at least 2 values")
    k = np.searchsorted(edges, xc[:, 0], side="right") - 1
    inside = (k >= 0) & (k < edges.size - 1)
    k = k[inside]
    area_now = triangle_areas(x, tri)[inside]
    ytop = x[tri[inside], 1].max(axis=1) - floor_y
    top = np.zeros(edges.size - 1)
    np.maximum.at(top, k, ytop)
    area = np.bincount(k, weights=area_now, minlength=edges.size - 1)
    return {"edges": edges, "centres": 0.5 * (edges[1:] + edges[:-1]), "top": top,
            "thickness": area / np.diff(edges), "area": area}


def failure_surface(topology: Topology, x: np.ndarray, broken: np.ndarray, slipped: np.ndarray | None = None,
                    threshold: float = 0.1, mask: np.ndarray | None = None) -> np.ndarray:
    """Crack elements that bound the displaced mass and have failed: sorted element ids.

    An element is on the failure surface when exactly one of its two triangles is displaced
    (centroid moved more than ``threshold`` [m], or ``mask``) and it is broken or has slid
    plastically. ``broken`` (n_crack,) bool; ``slipped`` (n_crack,) bool, or an array of
    element ids (e.g. ``CrackSet.inelastic()``, or ``dissipated[:, 2] > 0`` for frictional
    slip), optional.
    """
    x = _check_positions(topology, x)
    n = topology.n_cracks
    failed = np.asarray(broken, dtype=bool).copy()
    if failed.shape != (n,):
        raise ValueError(f"broken must have shape ({n},), got {failed.shape}")
    if slipped is not None:
        s = np.asarray(slipped)
        if s.dtype == bool:
            if s.shape != (n,):
                raise ValueError(f"slipped mask must have shape ({n},), got {s.shape}")
            failed |= s
        else:
            failed[s.astype(np.int64)] = True
    moved = displaced(topology, x, threshold) if mask is None else np.asarray(mask, bool)
    a, b = moved[topology.crack_triangles[:, 0]], moved[topology.crack_triangles[:, 1]]
    return np.flatnonzero(failed & (a != b))


def crack_breakdown(crack_tag: np.ndarray, inelastic: np.ndarray, broken: np.ndarray,
                    failure_mode: np.ndarray) -> dict:
    """Crack elements split by tag: intact rock (tag 0) against joints (tags > 0), and each tag.

    ``crack_tag`` (n,) int, ``Topology.crack_tag``; ``inelastic`` (n,) bool or the ids of the
    elements past their elastic range (``CrackSet.inelastic()``); ``broken`` (n,) bool;
    ``failure_mode`` (n,) 0 intact, 1 I, 2 II, 3 mixed (``CrackSet.failure_mode``). Each group
    gets ``n_elements``, ``activated`` (past the elastic range, slipping or softening, but not
    broken), ``broken`` and ``broken_by_mode`` (``I``, ``II``, ``mixed``). The paper's figures
    draw activated and broken joints; the split says whether a slope failed through its joints
    or through intact rock bridges.
    """
    tag = np.asarray(crack_tag, dtype=np.int64)
    n = tag.size
    broken = np.asarray(broken, dtype=bool)
    mode = np.asarray(failure_mode)
    ine = np.asarray(inelastic)
    if ine.dtype != bool:
        mask = np.zeros(n, bool)
        mask[ine.astype(np.int64)] = True
        ine = mask
    for name, a in (("inelastic", ine), ("broken", broken), ("failure_mode", mode)):
        if a.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},) like crack_tag, got {a.shape}")

    def group(sel: np.ndarray) -> dict:
        b = sel & broken
        return {"n_elements": int(sel.sum()), "activated": int((sel & ine & ~broken).sum()), "broken": int(b.sum()),
                "broken_by_mode": {m: int((b & (mode == code)).sum()) for m, code in (("I", 1), ("II", 2), ("mixed", 3))}}

    return {"rock": group(tag == 0), "joints": group(tag > 0),
            "by_tag": {str(t): group(tag == t) for t in np.unique(tag)}}


def fragment_statistics(topology: Topology, broken: np.ndarray, bins_per_decade: int = 4,
                        n_largest: int = 10, exclude: np.ndarray | None = None) -> dict:
    """Fragments: connected groups of triangles still bonded by unbroken crack elements.

    ``exclude`` (n_tri,) bool: triangles that are not rock and count as no fragment, e.g. a
    fixed wall the debris meets (``RunReport`` passes the triangles of bodies whose every node
    is fixed). They are cut from the bond graph before the groups are found, so a fixed body
    neither counts itself nor joins two rock groups through its own elements.

    Returns a dict:

    * ``n_fragments``: all groups of rock, single triangles included;
    * ``n_single_triangles``: groups of one triangle (counted apart: at the mesh scale they are
      debris, not blocks); ``n_blocks``: groups of two triangles or more;
    * ``label`` (n_tri,) fragment of each triangle; ``areas`` (n_fragments,) reference area of
      each fragment by label [m^2 per metre] (``label`` -1 for excluded triangles);
      ``n_triangles`` (n_fragments,) triangles per fragment;
    * ``largest``: the ``n_largest`` largest areas, descending; ``largest_share``: the largest
      fragment's share of the total area;
    * ``hist_edges``, ``hist_counts``: number of fragments per log-spaced area bin
      (``bins_per_decade`` bins per factor of 10, edges at ``10^(k / bins_per_decade)`` m^2).
    """
    broken = np.asarray(broken, dtype=bool)
    if broken.shape != (topology.n_cracks,):
        raise ValueError(f"broken must have shape ({topology.n_cracks},), got {broken.shape}")
    rock = np.ones(topology.n_triangles, bool) if exclude is None else ~np.asarray(exclude, dtype=bool)
    if rock.shape != (topology.n_triangles,):
        raise ValueError(f"exclude must have shape ({topology.n_triangles},), got {rock.shape}")
    if not rock.any():
        raise ValueError("fragment_statistics: every triangle is excluded, no rock left to count")
    ct = topology.crack_triangles
    _, label = fragments(topology, broken | ~(rock[ct[:, 0]] & rock[ct[:, 1]]))
    # renumber the groups of rock 0..n-1 (in the order of their old labels); excluded triangles -1
    groups, label_rock = np.unique(label[rock], return_inverse=True)
    n = groups.size
    label = np.full(topology.n_triangles, -1, dtype=np.int64)
    label[rock] = label_rock
    areas = np.bincount(label[rock], weights=topology.triangle_area0[rock], minlength=n)
    counts = np.bincount(label[rock], minlength=n)
    lo = np.floor(np.log10(areas.min()) * bins_per_decade)
    hi = np.ceil(np.log10(areas.max()) * bins_per_decade)
    edges = 10.0 ** (np.arange(lo, max(hi, lo + 1) + 1) / bins_per_decade)
    hist, _ = np.histogram(areas, bins=edges)
    largest = np.sort(areas)[::-1][:n_largest]
    return {
        "n_fragments": int(n), "n_single_triangles": int((counts == 1).sum()),
        "n_blocks": int((counts > 1).sum()), "label": label, "areas": areas, "n_triangles": counts,
        "largest": largest, "largest_share": float(largest[0] / areas.sum()),
        "hist_edges": edges, "hist_counts": hist,
    }


def released_kinetic_energy(history: list[dict]) -> float:
    """Peak kinetic energy reached during the rows of ``history`` [J per metre]."""
    return float(max((row.get("kinetic", 0.0) for row in history), default=0.0))


def history_columns(history, *names: str) -> tuple[np.ndarray, ...]:
    """Columns of a history (a list of row dicts as ``Simulation.history``, or the dict of arrays
    of :func:`fdem.io.history.read_history`) as float arrays, one per name; a missing column is refused."""
    if isinstance(history, dict):
        cols = history
        missing = [n for n in names if n not in cols]
    else:
        missing = [n for n in names if not history or n not in history[0]]
        cols = {n: [row[n] for row in history] for n in names if n not in missing}
    if missing:
        raise KeyError(f"history lacks column(s) {missing}")
    return tuple(np.asarray(cols[n], dtype=np.float64) for n in names)
