"""Pictures of a slope run, off-screen (matplotlib Agg): the failure frame, the maps and the time plots.

Every function takes plain arrays and a ``path``: it writes a PNG and returns the path, or, with
``path=None``, returns the matplotlib Figure unsaved (so a test can walk its axes). Arrays of
mismatched shape are refused with the names and shapes involved. Every axis is labelled with its
unit in brackets (``[-]`` for a pure number).

* :func:`failure_frame`: displacement magnitude on the deformed mesh (flat-shaded triangles,
  perceptual colour map, colour bar in m), the pre-failure outline dashed beneath it, the intact
  joint elements thin, the broken crack elements on top coloured by failure mode (I tensile,
  II shear, mixed), and optionally displacement or velocity arrows (subsampled).
* :func:`mechanism_frames`: the failure mechanism as the four-slope paper draws it (its Fig. 3):
  displacement with the activated (slipping, unbroken) and broken crack elements in black, one
  panel per moment (mid-failure, at rest), the locked part of the failed mass outlined.
* :func:`geostatic_stress_map`: sigma_yy [kPa] and its ratio to the lithostatic ``rho g d``.
* :func:`crack_time_map`: the broken crack elements coloured by their time of breakage.
* :func:`kinetic_energy_plot`: kinetic energy [J/m] against time, stages shaded and labelled.
* :func:`crack_count_plot`: cumulative broken crack elements by mode against time.
* :func:`fragment_size_plot`: number of fragments per log-spaced area bin.
* :func:`trial_histories_plot`: a factor-of-safety search's trials, each one's unbalanced-force
  ratio and displacement against its own time, beside the ratio limit: which trials settled
  and which crept.

The magnitude-frequency picture needs the event statistics and lives with them
(:func:`fdem.results.events.magnitude_plot`); the animation of a run's frames is
:mod:`fdem.io.animation`. What each picture shows: ``docs/pictures.md``.
"""
from __future__ import annotations

import os
from pathlib import Path
import numpy as np

__all__ = ["MODE_COLOURS", "MODE_LABELS", "new_figure", "save_figure", "finish", "mode_codes", "as_segments",
           "boundary_segments", "arrow_sample", "draw_failure", "failure_frame", "crack_segments_at", "mechanism_frames", "geostatic_stress_map",
           "crack_time_map", "stage_spans", "group_label", "group_stages", "stage_label_rows", "mark_stages", "kinetic_energy_plot",
           "crack_count_plot", "fragment_size_plot", "trial_histories_plot"]


MODE_COLOURS = {1: "#e8112d", 2: "#ffffff", 3: "#ff9e1b"}
"""Crack colours by failure mode (1 = I tensile: red, 2 = II shear: white, 3 = mixed: orange),
each drawn over a black outline so it reads on every colour of the displacement map."""


MODE_LABELS = {1: "mode I (tensile)", 2: "mode II (shear)", 3: "mixed mode"}


_MODE_CODE = {"I": 1, "II": 2, "mixed": 3}


def new_figure(figsize=(8.0, 5.0)):
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path, dpi) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def finish(fig, path, dpi):
    """The figure itself when ``path`` is None (to inspect it), else the PNG written at ``path``."""
    return fig if path is None else save_figure(fig, path, dpi)


def _same_length(**arrays) -> int:
    sizes = {k: len(v) for k, v in arrays.items()}
    if len(set(sizes.values())) > 1:
        raise ValueError("arrays must have the same length, got " + ", ".join(f"{k}: {n}" for k, n in sizes.items()))
    return next(iter(sizes.values()))


def mode_codes(mode) -> np.ndarray:
    """Failure modes as integers 0 (none), 1 (I), 2 (II), 3 (mixed), from those integers or from
    the strings ``"I"``, ``"II"``, ``"mixed"`` of :data:`fdem.physics.cracks.EVENT_DTYPE`."""
    mode = np.asarray(mode)
    if mode.dtype.kind in "US":
        bad = sorted(set(mode.tolist()) - set(_MODE_CODE))
        if bad:
            raise ValueError(f"unknown failure mode(s) {bad}; expected 'I', 'II' or 'mixed'")
        return np.array([_MODE_CODE[m] for m in mode.tolist()], dtype=np.int8)
    return mode.astype(np.int8)


def as_segments(segments, name: str = "crack_segments") -> np.ndarray:
    """``(n, 2, 2)`` end points [m] from ``(n, 2, 2)`` or the ``(2 n, 2)`` points of line cells
    (``Simulation.crack_geometry()["points"]``)."""
    segs = np.asarray(segments, dtype=np.float64)
    if segs.ndim == 2 and segs.shape[1] == 2 and len(segs) % 2 == 0:
        segs = segs.reshape(-1, 2, 2)
    if segs.ndim != 3 or segs.shape[1:] != (2, 2):
        raise ValueError(f"{name} must have shape (n, 2, 2) or (2 n, 2), got {segs.shape}")
    return segs


def boundary_segments(x0: np.ndarray, boundary_edges: np.ndarray) -> np.ndarray:
    """``(n_boundary, 2, 2)`` end points [m] of the external edges (``Topology.boundary_edges``,
    node ids) at the positions ``x0``: the slope's outline in the reference configuration."""
    e = np.asarray(boundary_edges, dtype=np.int64).reshape(-1, 2)
    return np.asarray(x0, dtype=np.float64)[e]


def arrow_sample(points: np.ndarray, max_arrows: int) -> np.ndarray:
    """Indices of at most ``max_arrows`` of ``points`` (n, 2), one per cell of a square grid over
    their bounding box (the point nearest each occupied cell's centre), so arrows spread evenly
    and stay readable whatever the mesh size. Deterministic."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n <= max_arrows:
        return np.arange(n)
    lo, span = pts.min(axis=0), np.maximum(np.ptp(pts, axis=0), 1e-300)
    # a cell area that leaves about max_arrows cells occupied on a filled bounding box; shrink
    # it until the occupied cells (a slope fills part of its box) come near the target
    h = np.sqrt(span[0] * span[1] / max_arrows)
    for _ in range(12):
        ij = np.floor((pts - lo) / h).astype(np.int64)
        key = ij[:, 0] * (int(span[1] / h) + 2) + ij[:, 1]
        centre = lo + (ij + 0.5) * h
        d = ((pts - centre) ** 2).sum(1)
        order = np.lexsort((d, key))
        first = order[np.r_[True, key[order][1:] != key[order][:-1]]]
        if len(first) > max_arrows:
            h *= 1.15
            continue
        if len(first) >= 0.6 * max_arrows:
            break
        h /= 1.15
    if len(first) > max_arrows:  # even spacing could not land under the cap: keep every k-th
        first = first[:: int(np.ceil(len(first) / max_arrows))]
    return np.sort(first)


def _check_mesh(x, triangles) -> tuple[np.ndarray, np.ndarray]:
    tri = np.asarray(getattr(triangles, "triangles", triangles), dtype=np.int64)
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 2:
        raise ValueError(f"x must have shape (n_nodes, 2), got {x.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"triangles must have shape (n_tri, 3), got {tri.shape}")
    if tri.size and (tri.min() < 0 or tri.max() >= len(x)):
        raise ValueError(f"triangles refer to nodes outside x (0..{len(x) - 1})")
    return x, tri


def _per_triangle(values, x, tri, name: str) -> np.ndarray:
    u = np.asarray(values, dtype=np.float64)
    if u.shape[:1] == (len(x),) and len(x) != len(tri):
        u = u[tri].mean(axis=1)
    if u.shape[:1] != (len(tri),):
        raise ValueError(f"{name} must have one value per triangle ({len(tri)},) or per node ({len(x)},), "
                         f"got {u.shape}")
    return u


def _figsize(x: np.ndarray, width: float = 11.0, rows: int = 1) -> tuple[float, float]:
    span = np.ptp(x, axis=0) if len(x) else np.ones(2)
    panel = 0.82 * width * span[1] / max(span[0], 1e-300)
    return width, float(np.clip(rows * (panel + 1.0) + 0.4, 3.0, 9.0 * rows))


def draw_failure(fig, ax, x, tri, u, segs=None, show=None, mode=None, outline=None, joint=None,
                 vectors=None, vector_name: str = "displacement", vector_unit: str = "m",
                 max_arrows: int = 250, vmax: float | None = None, cmap: str = "viridis",
                 legend: bool = True) -> None:
    """Draw a failure frame on ``ax`` (arrays already checked; see :func:`failure_frame`)."""
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.tri import Triangulation
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    if outline is not None and len(outline):
        # under the deposit: where the slope stood before it failed
        ax.add_collection(LineCollection(outline, colors="0.25", linewidths=0.9, linestyles=(0, (4, 2)),
                                         zorder=1, gid="outline"))
    pc = ax.tripcolor(Triangulation(x[:, 0], x[:, 1], tri), facecolors=u, cmap=cmap, shading="flat",
                      vmin=0.0, vmax=vmax if vmax is not None else (float(u.max()) if u.size and u.max() > 0 else 1.0),
                      edgecolors="face", linewidth=0.0, antialiased=False, rasterized=True, zorder=2)
    cax = make_axes_locatable(ax).append_axes("right", size="2%", pad=0.1)  # as tall as the mesh
    fig.colorbar(pc, cax=cax, label="displacement magnitude [m]")
    handles = []
    if segs is not None and joint is not None:
        intact = joint & ~show
        if intact.any():  # thin: the joints that still hold
            ax.add_collection(LineCollection(segs[intact], colors="0.85", linewidths=0.35, zorder=3, gid="intact"))
            handles.append(Line2D([], [], color="0.85", lw=1.0, label=f"intact joint: {int(intact.sum())}"))
    if segs is not None and show.any():
        lw = 0.9 if show.sum() < 20000 else 0.5
        ax.add_collection(LineCollection(segs[show], colors="k", linewidths=lw + (1.0 if lw > 0.5 else 0.6),
                                         zorder=4))
        for code in (2, 3, 1):  # tensile on top: the cracks that open
            sel = show & (mode == code)
            if sel.any():
                ax.add_collection(LineCollection(segs[sel], colors=MODE_COLOURS[code], linewidths=lw, zorder=5,
                                                 gid=f"broken-{code}"))
                handles.append(Line2D([], [], color=MODE_COLOURS[code], lw=2.5,
                                      label=f"{MODE_LABELS[code]}: {int(sel.sum())}"))
    if vectors is not None:
        c = x[tri].mean(axis=1)
        pick = arrow_sample(c, max_arrows)
        span = np.ptp(c, axis=0)
        cell = np.sqrt(max(span[0] * span[1], 1e-300) / max(len(pick), 1))
        size = np.linalg.norm(vectors[pick], axis=1)
        top = float(size.max()) if size.size else 0.0
        pick = pick[size >= 0.03 * top]  # arrows under 3 % of the longest would be dots on rock at rest
        vec = vectors[pick]
        if top > 0:
            # arrows scaled so the longest spans about two grid cells: a runout of metres and a
            # creep of millimetres both read; the key gives the true length
            q = ax.quiver(c[pick, 0], c[pick, 1], vec[:, 0], vec[:, 1], angles="xy", scale_units="xy",
                          scale=top / (2.0 * cell), width=0.0022, color="k", zorder=6, gid="arrows")
            ax.quiverkey(q, 0.9, 1.02, top, f"{vector_name} {top:.3g} {vector_unit}", labelpos="E",
                         coordinates="axes", fontproperties={"size": 8})
    if handles and legend:
        leg = ax.legend(handles=handles[::-1], loc="upper left", fontsize=8, title="crack elements",
                        title_fontsize=8, facecolor="0.35", labelcolor="w", framealpha=0.9)
        leg.get_title().set_color("w")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def failure_frame(path: str | os.PathLike | None, x: np.ndarray, triangles, displacement: np.ndarray,
                  crack_segments: np.ndarray | None = None, broken: np.ndarray | None = None,
                  failure_mode: np.ndarray | None = None, title: str = "", cmap: str = "viridis",
                  vmax: float | None = None, dpi: int = 150, figsize=None, outline: np.ndarray | None = None,
                  joint: np.ndarray | None = None, vectors: np.ndarray | None = None,
                  vector_name: str = "displacement", vector_unit: str = "m", max_arrows: int = 250):
    """Displacement magnitude on the deformed mesh with broken crack elements by failure mode.

    Parameters
    ----------
    x : (n_nodes, 2) current node positions [m]
    triangles : (n_tri, 3) node ids, or a :class:`fdem.mesh.topology.Topology` (its ``triangles``)
    displacement : (n_tri,) per triangle or (n_nodes,) per node displacement magnitude [m]
        (per node values are averaged over each triangle: flat shading)
    crack_segments : (n_crack, 2, 2) end points of every crack element [m], or the
        (2 n_crack, 2) ``points`` of ``Simulation.crack_geometry()``
    broken : (n_crack,) bool, which crack elements to draw (default: those with a mode > 0)
    failure_mode : (n_crack,) 0 intact, 1 I, 2 II, 3 mixed (``CrackSet.failure_mode``) or the
        strings ``"I"``, ``"II"``, ``"mixed"``
    vmax : top of the colour scale [m] (default: the largest displacement)
    figsize : inches (default: 11 wide, height from the deformed mesh's aspect ratio)
    outline : (n, 2, 2) or (2 n, 2) segments [m] drawn dashed under the mesh: the slope's
        boundary in the reference configuration (:func:`boundary_segments`)
    joint : (n_crack,) bool, the crack elements on joints (``Topology.crack_tag > 0``): those
        not broken are drawn thin and light (intact rock bridges are not drawn)
    vectors : (n_nodes, 2) or (n_tri, 2) displacement [m] or velocity [m/s] drawn as arrows at
        about ``max_arrows`` evenly spread triangle centroids (:func:`arrow_sample`), scaled so
        the longest spans two spacings, those under 3 % of the longest left out (rock at rest);
        ``vector_name`` and ``vector_unit`` label the key

    Flat-shaded triangles go through one ``tripcolor`` (a single PolyCollection) and the cracks
    through one LineCollection per mode, so a 180k-triangle frame renders in seconds
    (``docs/outputs.md``). Returns the path, or the Figure when ``path`` is None.
    """
    x, tri = _check_mesh(x, triangles)
    u = _per_triangle(displacement, x, tri, "displacement")
    if u.ndim != 1:
        raise ValueError(f"displacement must be a magnitude per triangle or node, got shape {u.shape}")
    segs = show = mode = jt = None
    if crack_segments is not None:
        segs = as_segments(crack_segments, "crack_segments")
        n_crack = len(segs)
        mode = np.full(n_crack, 3, np.int8) if failure_mode is None else mode_codes(failure_mode)
        if mode.shape != (n_crack,):
            raise ValueError(f"failure_mode must have shape ({n_crack},) like crack_segments, got {mode.shape}")
        show = mode > 0 if broken is None else np.asarray(broken, dtype=bool)
        if show.shape != (n_crack,):
            raise ValueError(f"broken must have shape ({n_crack},) like crack_segments, got {show.shape}")
        if joint is not None:
            jt = np.asarray(joint, dtype=bool)
            if jt.shape != (n_crack,):
                raise ValueError(f"joint must have shape ({n_crack},) like crack_segments, got {jt.shape}")
    out = None if outline is None else as_segments(outline, "outline")
    vec = None
    if vectors is not None:
        vec = _per_triangle(vectors, x, tri, "vectors")
        if vec.shape != (len(tri), 2):
            raise ValueError(f"vectors must have shape (n_nodes, 2) or (n_tri, 2), got {np.shape(vectors)}")
    fig = new_figure(figsize or _figsize(x))
    ax = fig.add_subplot(111)
    draw_failure(fig, ax, x, tri, u, segs, show, mode, out, jt, vec, vector_name, vector_unit, max_arrows,
                 vmax, cmap)
    if title:
        ax.set_title(title, pad=14 if vec is not None else 6)
    fig.tight_layout()
    return finish(fig, path, dpi)


def crack_segments_at(x: np.ndarray, crack_nodes: np.ndarray) -> np.ndarray:
    """(n_crack, 2, 2) mid-line of every crack element at positions ``x`` [m]: from the midpoint
    of its nodes 0 and 3 to that of 1 and 2 (``Simulation.crack_geometry``'s points)."""
    cn = np.asarray(crack_nodes, dtype=np.int64)
    x = np.asarray(x, dtype=np.float64)
    return np.stack([0.5 * (x[cn[:, 0]] + x[cn[:, 3]]), 0.5 * (x[cn[:, 1]] + x[cn[:, 2]])], axis=1)


def mechanism_frames(path: str | os.PathLike | None, triangles, crack_nodes, panels: list[dict],
                     joint: np.ndarray | None = None, outline: np.ndarray | None = None,
                     locked: np.ndarray | None = None, crack_triangles: np.ndarray | None = None,
                     cmap: str = "viridis", dpi: int = 150):
    """The failure mechanism, one panel per moment, as the four-slope paper's Fig. 3 draws it.

    Each panel is a dict with ``x`` (n_nodes, 2) positions [m], ``displacement`` (n_tri,) or
    (n_nodes,) magnitude [m], ``status`` (n_crack,) 0 intact, 1 activated (past its elastic range,
    and slipped or opened by more than 1 mm, unbroken), 2 broken (:func:`fdem.results.motion.crack_status`) and a
    ``title``. Activated crack elements are drawn thin black, broken ones thick black, intact
    joints (``joint``, (n_crack,) bool) thin light grey; the colour scale is shared by all panels
    (up to the largest displacement). ``locked`` (n_tri,) bool with ``crack_triangles`` (n_crack,
    2) outlines the locked part of the failed mass (magenta: the crack elements with exactly one
    locked side) in every panel. ``outline`` as in :func:`failure_frame`. Returns the path, or the
    Figure when ``path`` is None.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.tri import Triangulation
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    if not panels:
        raise ValueError("mechanism_frames needs at least one panel")
    cn = np.asarray(crack_nodes, dtype=np.int64)
    n_crack = len(cn)
    jt = None if joint is None else np.asarray(joint, dtype=bool)
    if jt is not None and jt.shape != (n_crack,):
        raise ValueError(f"joint must have shape ({n_crack},) like crack_nodes, got {jt.shape}")
    rim = None
    if locked is not None:
        lk = np.asarray(locked, dtype=bool)
        if crack_triangles is None:
            raise ValueError("locked needs crack_triangles to find the locked part's outline")
        ct = np.asarray(crack_triangles, dtype=np.int64)
        rim = lk[ct[:, 0]] != lk[ct[:, 1]]
    checked = []
    for k, p in enumerate(panels):
        x, tri = _check_mesh(p["x"], triangles)
        u = _per_triangle(p["displacement"], x, tri, f"panels[{k}].displacement")
        st = np.asarray(p["status"])
        if st.shape != (n_crack,):
            raise ValueError(f"panels[{k}].status must have shape ({n_crack},) like crack_nodes, got {st.shape}")
        checked.append((x, tri, u, st, str(p.get("title", ""))))
    vmax = max(float(c[2].max()) if c[2].size else 0.0 for c in checked) or 1.0
    width = 11.0
    fig = new_figure((width, sum(_figsize(c[0], width)[1] for c in checked)))
    out = None if outline is None else as_segments(outline, "outline")
    for k, (x, tri, u, st, title) in enumerate(checked):
        ax = fig.add_subplot(len(checked), 1, k + 1)
        if out is not None and len(out):
            ax.add_collection(LineCollection(out, colors="0.25", linewidths=0.9, linestyles=(0, (4, 2)), zorder=1))
        pc = ax.tripcolor(Triangulation(x[:, 0], x[:, 1], tri), facecolors=u, cmap=cmap, shading="flat",
                          vmin=0.0, vmax=vmax, edgecolors="face", linewidth=0.0, antialiased=False,
                          rasterized=True, zorder=2)
        cax = make_axes_locatable(ax).append_axes("right", size="2%", pad=0.1)
        fig.colorbar(pc, cax=cax, label="displacement magnitude [m]")
        segs = crack_segments_at(x, cn)
        handles = []
        if jt is not None:
            quiet = jt & (st == 0)
            ax.add_collection(LineCollection(segs[quiet], colors="0.85", linewidths=0.3, zorder=3))
            handles.append(Line2D([], [], color="0.85", lw=1.0, label=f"joint, elastic: {int(quiet.sum())}"))
        for code, lw, label in ((1, 0.6, "activated (slipping, unbroken)"), (2, 1.6, "broken")):
            sel = st == code
            ax.add_collection(LineCollection(segs[sel], colors="k", linewidths=lw, zorder=4 + code,
                                             gid=f"status-{code}"))
            handles.append(Line2D([], [], color="k", lw=lw + 0.6, label=f"{label}: {int(sel.sum())}"))
        if rim is not None and rim.any():
            ax.add_collection(LineCollection(segs[rim], colors="#d61fd6", linewidths=1.4, zorder=7, gid="locked"))
            handles.append(Line2D([], [], color="#d61fd6", lw=2.0, label="outline of the locked part"))
        leg = ax.legend(handles=handles, loc="upper left", fontsize=7, title="crack elements", title_fontsize=7,
                        facecolor="0.35", labelcolor="w", framealpha=0.9)
        leg.get_title().set_color("w")
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        if title:
            ax.set_title(title)
    fig.tight_layout()
    return finish(fig, path, dpi)


def geostatic_stress_map(path: str | os.PathLike | None, x: np.ndarray, triangles, sigma_yy: np.ndarray,
                         ratio: np.ndarray, title: str = "", outline: np.ndarray | None = None,
                         ratio_range: float = 0.5, dpi: int = 140):
    """Two maps of the geostatic state: the vertical stress ``sigma_yy`` [kPa] (tension
    positive) and its ratio to the lithostatic stress, ``-sigma_yy / (rho g d)`` [-] with ``d`` the
    depth below the surface above each triangle (:func:`fdem.results.overburden.lithostatic_ratio`).
    A ratio of 1 is the weight of the column above; below 1 the slope's face or a stiffer
    neighbour carries part of it (arching), above 1 a concentration (the toe). The ratio's
    colour scale spans ``1 +- ratio_range``; triangles with no ratio (nan: no rock above) are grey.

    Parameters: ``x`` (n_nodes, 2) [m], ``triangles`` (n_tri, 3), ``sigma_yy`` and ``ratio``
    (n_tri,) [Pa] and [-], ``outline`` as in :func:`failure_frame`.
    """
    x, tri = _check_mesh(x, triangles)
    syy = np.asarray(sigma_yy, dtype=np.float64)
    r = np.asarray(ratio, dtype=np.float64)
    _same_length(triangles=tri, sigma_yy=syy, ratio=r)
    from matplotlib.collections import LineCollection
    from matplotlib.tri import Triangulation
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    fig = new_figure(_figsize(x, 10.0, rows=2))
    tr = Triangulation(x[:, 0], x[:, 1], tri)
    panels = ((syy / 1e3, "vertical stress $\\sigma_{yy}$ [kPa]", "cividis", None, None),
              (r, "$-\\sigma_{yy} / (\\rho g d)$ [-]", "RdBu_r", 1.0 - ratio_range, 1.0 + ratio_range))
    for k, (val, label, cmap, lo, hi) in enumerate(panels):
        ax = fig.add_subplot(2, 1, k + 1)
        import matplotlib

        cm = matplotlib.colormaps[cmap].with_extremes(bad="0.7")
        pc = ax.tripcolor(tr, facecolors=np.ma.masked_invalid(val), cmap=cm, shading="flat", vmin=lo, vmax=hi,
                          edgecolors="face", linewidth=0.0, antialiased=False, rasterized=True)
        if outline is not None:
            ax.add_collection(LineCollection(as_segments(outline, "outline"), colors="k", linewidths=0.6))
        cax = make_axes_locatable(ax).append_axes("right", size="2%", pad=0.1)
        fig.colorbar(pc, cax=cax, label=label, extend="both" if lo is not None else "neither")
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        if k == 0:
            ax.set_title(title or "geostatic state: vertical stress and its ratio to the overburden weight")
        else:
            inner = r[np.isfinite(r)]
            if inner.size:
                ax.set_title(f"ratio to $\\rho g d$: median {np.median(inner):.3f}, 5-95 % "
                             f"[{np.quantile(inner, 0.05):.3f}, {np.quantile(inner, 0.95):.3f}]", fontsize=9)
    fig.tight_layout()
    return finish(fig, path, dpi)


def crack_time_map(path: str | os.PathLike | None, x: np.ndarray, triangles, crack_segments: np.ndarray,
                   element: np.ndarray, time: np.ndarray, title: str = "", outline: np.ndarray | None = None,
                   cmap: str = "plasma", dpi: int = 150):
    """The broken crack elements coloured by the time they broke [s], over the mesh in grey.

    ``crack_segments`` (n_crack, 2, 2) or (2 n_crack, 2) [m] (at the positions to draw: the
    reference ones show where each crack started); ``element`` and ``time`` (n_events,) from
    ``CrackSet.events`` (an element that appears twice keeps its first time). Drawn in order of
    time, so the last cracks lie on top. The LineCollection (gid ``"break-time"``) holds the
    elements' times as its colour array, in the order of :func:`numpy.unique` of the elements
    sorted by time.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.tri import Triangulation
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    x, tri = _check_mesh(x, triangles)
    segs = as_segments(crack_segments, "crack_segments")
    el = np.asarray(element, dtype=np.int64)
    t = np.asarray(time, dtype=np.float64)
    _same_length(element=el, time=t)
    if el.size and (el.min() < 0 or el.max() >= len(segs)):
        raise ValueError(f"element ids must lie in 0..{len(segs) - 1} (one per crack segment), got "
                         f"{el.min()}..{el.max()}")
    first = np.full(len(segs), np.inf)
    np.minimum.at(first, el, t)
    hit = np.flatnonzero(np.isfinite(first))
    hit = hit[np.argsort(first[hit], kind="stable")]
    fig = new_figure(_figsize(x))
    ax = fig.add_subplot(111)
    ax.tripcolor(Triangulation(x[:, 0], x[:, 1], tri), facecolors=np.zeros(len(tri)), cmap="Greys", vmin=-1.0,
                 vmax=3.0, shading="flat", edgecolors="face", linewidth=0.0, antialiased=False, rasterized=True)
    if outline is not None:
        ax.add_collection(LineCollection(as_segments(outline, "outline"), colors="0.3", linewidths=0.7))
    lc = LineCollection(segs[hit], cmap=cmap, linewidths=1.6, gid="break-time")
    lc.set_array(first[hit])
    if hit.size:
        lc.set_clim(float(first[hit].min()), float(first[hit].max()) + (0.0 if np.ptp(first[hit]) > 0 else 1e-9))
    ax.add_collection(lc)
    cax = make_axes_locatable(ax).append_axes("right", size="2%", pad=0.1)
    fig.colorbar(lc, cax=cax, label="time of breakage [s]")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or f"{hit.size} broken crack elements by time of breakage")
    fig.tight_layout()
    return finish(fig, path, dpi)


# ----------------------------------------------------------------------------- stage marks
def stage_spans(time: np.ndarray, stage) -> list[tuple[str, float, float]]:
    """``(name, t_start, t_end)`` of each run of equal ``stage`` values in a history's time
    order (a stage's rows are contiguous); a stage starts where the previous one ends."""
    time = np.asarray(time, dtype=np.float64)
    stage = np.asarray(stage)
    _same_length(time=time, stage=stage)
    if time.size == 0:
        return []
    change = np.flatnonzero(stage[1:] != stage[:-1]) + 1
    starts = np.r_[0, change]
    ends = np.r_[change, len(time)]
    out = []
    for a, b in zip(starts, ends):
        t0 = float(time[a - 1]) if a > 0 else float(time[0])
        out.append((str(stage[a]), t0, float(time[b - 1])))
    return out


def stage_label_rows(centres, widths, left: float, right: float, gap: float = 4.0) -> np.ndarray:
    """Place one label per stage: ``(n, 3)`` boxes ``[x0, x1, row]`` (x in the units of the
    arguments, e.g. pixels) such that no two boxes of a row overlap or come closer than ``gap``.

    Each label is centred on its stage (``centres``), shifted inside ``[left, right]`` and put on
    the lowest row where it fits (first fit, in the given order); so the labels of long stages
    stay on row 0 beside their stage and many short stages stack on rows 1, 2, ... instead of
    printing over each other.
    """
    c = np.asarray(centres, dtype=np.float64)
    w = np.asarray(widths, dtype=np.float64)
    _same_length(centres=c, widths=w)
    rows: list[list[tuple[float, float]]] = []
    boxes = np.zeros((len(c), 3))
    for k in range(len(c)):
        x0 = min(max(c[k] - 0.5 * w[k], left), max(right - w[k], left))
        x1 = x0 + w[k]
        for r, placed in enumerate(rows):
            if all(x1 + gap <= a or x0 >= b + gap for a, b in placed):
                placed.append((x0, x1))
                break
        else:
            r = len(rows)
            rows.append([(x0, x1)])
        boxes[k] = (x0, x1, r)
    return boxes


def group_label(names, i: int, j: int) -> str:
    """The label of stages ``i..j``: the name when ``i == j``, else ``"first ... last (n stages)"``
    with the last name's part shared with the first (up to a ``_`` or space) left out."""
    if i == j:
        return str(names[i])
    a, b = str(names[i]), str(names[j])
    k = 0
    while k < min(len(a), len(b)) and a[k] == b[k]:
        k += 1
    cut = max(a.rfind("_", 0, k), a.rfind(" ", 0, k)) + 1
    return f"{a} ... {b[cut:]} ({j - i + 1} stages)"


def group_stages(starts, ends, names, measure, gap: float = 0.0) -> list[tuple[int, int, str]]:
    """Stages ``(i, j, label)`` to label together: a stage whose span ``ends - starts`` (e.g. in
    pixels) is shorter than its label (``measure(text)``, same units, plus ``gap``) joins the
    short stages after it until their span holds their common label (:func:`group_label`); a
    stage long enough for its own label is labelled alone. Dozens of reduction steps of a
    factor-of-safety search then read as a few ranges instead of a stack of names."""
    n = len(names)
    short = [ends[k] - starts[k] < measure(str(names[k])) + gap for k in range(n)]
    out, i = [], 0
    while i < n:
        j = i
        if short[i]:
            while j + 1 < n and short[j + 1] and ends[j] - starts[i] < measure(group_label(names, i, j)) + gap:
                j += 1
        out.append((i, j, group_label(names, i, j)))
        i = j + 1
    return out


def mark_stages(fig, ax, time: np.ndarray, stage, fontsize: float = 7.0) -> list:
    """Shade every other stage of ``ax`` and name each stage once above the axes: alone when its
    span holds its name, else in a range with its short neighbours (:func:`group_stages`), on rows
    from :func:`stage_label_rows` so that labels never overlap. Call it after ``tight_layout``
    (it keeps the axes' width and lowers its top to make room). Returns the label Texts (gid
    ``"stage-label"``)."""
    from matplotlib.transforms import offset_copy

    spans = stage_spans(time, stage)
    if not spans:
        return []
    for k, (_, t0, t1) in enumerate(spans):
        if k % 2:
            ax.axvspan(t0, t1, color="0.5", alpha=0.12, lw=0, zorder=0)
        if k:
            ax.axvline(t0, color="0.5", lw=0.6, ls="--", zorder=0)
    renderer = fig.canvas.get_renderer()
    probe = ax.text(0.0, 0.0, "", fontsize=fontsize)

    def measure(text: str) -> float:
        probe.set_text(text)
        return probe.get_window_extent(renderer).width

    line = probe.get_window_extent(renderer).height
    names = [name for name, _, _ in spans]
    px = ax.transData.transform(np.array([[t0, 0.0] for _, t0, _ in spans] + [[spans[-1][2], 0.0]]))[:, 0]
    gap = 0.6 * fontsize
    groups = group_stages(px[:-1], px[1:], names, measure, gap)
    probe.set_text("Mg")
    line = probe.get_window_extent(renderer).height + 1.0
    probe.remove()
    texts = [ax.text(0.0, 1.0, label, transform=ax.transAxes, fontsize=fontsize, color="0.25", gid="stage-label",
                     ha="left", va="bottom") for _, _, label in groups]
    widths = np.array([t.get_window_extent(renderer).width for t in texts])
    bbox = ax.get_window_extent(renderer)
    centres = np.array([0.5 * (px[i] + px[j + 1]) for i, j, _ in groups])
    boxes = stage_label_rows(centres, widths, bbox.x0, bbox.x1, gap=gap)
    pt = 72.0 / fig.dpi  # points per pixel
    n_rows = int(boxes[:, 2].max()) + 1
    for t, (x0, _, r) in zip(texts, boxes):
        t.set_x((x0 - bbox.x0) / bbox.width)
        t.set_transform(offset_copy(ax.transAxes, fig=fig, y=(2.0 + r * line) * pt, units="points"))
    # the title moves above the label rows; the axes lose that height at the top (not width:
    # the label positions in x stay right)
    extra = n_rows * line
    ax.set_title(ax.get_title(), pad=6.0 + extra * pt)
    pos = fig.subplotpars
    fig.subplots_adjust(top=pos.top - extra / (fig.get_figheight() * fig.dpi))
    return texts


# ----------------------------------------------------------------------------- time plots
def kinetic_energy_plot(path: str | os.PathLike | None, time: np.ndarray, kinetic: np.ndarray, stage=None,
                        log: bool = False, title: str = "", dpi: int = 130):
    """Kinetic energy [J per metre of thickness] against time [s] (history columns ``time``,
    ``kinetic``); ``stage`` (same length) shades and names the stages (:func:`mark_stages`);
    ``log`` for a logarithmic energy axis."""
    time, kinetic = np.asarray(time, float), np.asarray(kinetic, float)
    _same_length(time=time, kinetic=kinetic, **({} if stage is None else {"stage": stage}))
    fig = new_figure((8.0, 4.2))
    ax = fig.add_subplot(111)
    ax.plot(time, kinetic, color="C0", lw=1.2)
    if log:
        ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("kinetic energy [J/m]")
    ax.set_title(title or f"kinetic energy, peak {kinetic.max() if kinetic.size else 0.0:.3g} J/m")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    if stage is not None:
        mark_stages(fig, ax, time, stage)
    return finish(fig, path, dpi)


def crack_count_plot(path: str | os.PathLike | None, time: np.ndarray, mode, t_end: float | None = None,
                     title: str = "", dpi: int = 130):
    """Cumulative number of broken crack elements by failure mode against time: one step curve
    per mode and the total. ``time`` [s] and ``mode`` of each breakage (``CrackSet.events``
    fields ``time`` and ``mode``, strings or codes 1/2/3); ``t_end`` extends the curves."""
    time = np.asarray(time, float)
    codes = mode_codes(mode)
    _same_length(time=time, mode=codes)
    order = np.argsort(time, kind="stable")
    time, codes = time[order], codes[order]
    fig = new_figure((8.0, 4.0))
    ax = fig.add_subplot(111)
    colours = {1: "#d62728", 2: "#1f77b4", 3: "#ff7f0e"}
    end = max(float(time.max()) if time.size else 0.0, t_end or 0.0)
    for code, label in ((0, "all"), (1, "mode I (tensile)"), (2, "mode II (shear)"), (3, "mixed mode")):
        t = time if code == 0 else time[codes == code]
        n = np.arange(1, t.size + 1)
        ax.step(np.r_[0.0, t, end], np.r_[0, n, t.size], where="post", label=f"{label}: {t.size}",
                color="k" if code == 0 else colours[code], lw=1.6 if code == 0 else 1.2)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("cumulative broken crack elements [-]")
    ax.set_title(title or "crack breakage by failure mode")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return finish(fig, path, dpi)


def fragment_size_plot(path: str | os.PathLike | None, areas: np.ndarray, bins_per_decade: int = 4,
                       title: str = "", dpi: int = 130, time: np.ndarray | None = None,
                       count: np.ndarray | None = None, stage=None):
    """Number of fragments per log-spaced area bin (``bins_per_decade`` per factor of 10) of the
    fragment areas [m^2 per metre] (``fragment_statistics(...)["areas"]``), log-log axes; with
    ``time`` [s] and ``count`` (the ``fragments`` monitor of the history), a left panel shows
    the number of fragments against time, with the stages shaded and named."""
    a = np.asarray(areas, float).ravel()
    if a.size == 0 or np.any(a <= 0):
        raise ValueError("fragment areas must be a non-empty array of positive values [m^2]")
    lo = np.floor(np.log10(a.min()) * bins_per_decade)
    hi = np.ceil(np.log10(a.max()) * bins_per_decade)
    edges = 10.0 ** (np.arange(lo, max(hi, lo + 1) + 1) / bins_per_decade)
    counts, _ = np.histogram(a, bins=edges)
    over_time = time is not None and count is not None and len(time) > 1
    fig = new_figure((12.0, 4.4) if over_time else (7.0, 4.2))
    ax0 = None
    if over_time:
        n = _same_length(time=np.asarray(time), count=np.asarray(count))
        ax0 = fig.add_subplot(121)
        ax0.step(np.asarray(time, float)[:n], np.asarray(count, float)[:n], where="post", color="C2")
        ax0.set_xlabel("time [s]")
        ax0.set_ylabel("number of fragments [-]")
        ax0.set_title("fragments over time")
        ax0.grid(alpha=0.3)
        ax = fig.add_subplot(122)
    else:
        ax = fig.add_subplot(111)
    ax.bar(edges[:-1], counts, width=np.diff(edges), align="edge", color="C2", edgecolor="k", lw=0.4)
    ax.set_xscale("log")
    if counts.max() > 10:
        ax.set_yscale("log")
    ax.set_xlabel("fragment area [m$^2$ per m]")
    ax.set_ylabel("number of fragments [-]")
    ax.set_title(title or f"{a.size} fragments, largest {a.max():.3g} m$^2$ ({a.max() / a.sum():.0%} of the area)")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    if ax0 is not None and stage is not None:
        mark_stages(fig, ax0, np.asarray(time, float)[:n], np.asarray(stage)[:n])
    return finish(fig, path, dpi)


def trial_histories_plot(path: str | os.PathLike | None, trials: list[dict], limit: float | None = None,
                         hold: float = 0.0, trigger: str = "F", title: str = "", dpi: int = 130):
    """The trials of a factor-of-safety search against each trial's own time [s]: above, the
    unbalanced-force ratio [-] (log axis) with the ``limit`` a trial must keep below for ``hold``
    seconds to count as stable; below, the growth of the largest displacement [m] since the
    trial's first history row. One curve per trial, blue for stable, red for failing, darker for
    a larger factor, labelled with it. A trial that settles falls through the limit and stays
    there; one that creeps hovers near it while its displacement keeps growing.
    ``trials``: dicts with ``factor``, ``stable``, and arrays ``time`` [s] (since the trial's start),
    ``ratio`` and ``displacement`` [m] of equal length; optionally ``limit``, the trial's own limit
    (drawn dotted in its colour) where the trials' limits differ, and ``settling``: a trial that
    reached its cap still settling (:func:`fdem.workflow.fos.settling_at_cap`), drawn dashed and
    labelled so, whose verdict leans on the cap; ``follow_from`` [s]: a trial followed undamped
    from its cap (:func:`fdem.workflow.fos.factor_of_safety` ``follow``), the follow drawn dash-dotted."""
    from matplotlib import colormaps

    fig = new_figure((8.0, 6.0))
    top, bottom = fig.add_subplot(211), fig.add_subplot(212)
    shades = {True: colormaps["Blues"], False: colormaps["Reds"]}
    for stable in (True, False):
        group = sorted((t for t in trials if bool(t["stable"]) == stable), key=lambda t: t["factor"])
        for k, t in enumerate(group):
            time, ratio, disp = (np.asarray(t[key], float) for key in ("time", "ratio", "displacement"))
            _same_length(time=time, ratio=ratio, displacement=disp)
            colour = shades[stable](0.45 + 0.5 * (k + 1) / len(group))
            settling = bool(t.get("settling"))
            follow_from = t.get("follow_from")
            label = f"{trigger} = {t['factor']:.4g} {'stable' if stable else 'failing'}" + (
                " (capped, settling)" if settling else "") + (" (followed from its cap)" if follow_from is not None else "")
            style = "--" if settling else "-"
            cut = time.size if follow_from is None else int(np.searchsorted(time, follow_from, side="right"))
            top.plot(time[:cut], ratio[:cut], color=colour, lw=1.1, ls=style, label=label)
            bottom.plot(time[:cut], disp[:cut], color=colour, lw=1.1, ls=style)
            if cut < time.size:   # the undamped follow, from the trial's last row on
                top.plot(time[max(cut - 1, 0):], ratio[max(cut - 1, 0):], color=colour, lw=1.1, ls="-.")
                bottom.plot(time[max(cut - 1, 0):], disp[max(cut - 1, 0):], color=colour, lw=1.1, ls="-.")
            if t.get("limit") is not None:   # a trial's own limit, where the trials' differ
                top.axhline(t["limit"], color=colour, ls=":", lw=0.8)
    if limit is not None:
        top.axhline(limit, color="k", ls="--", lw=0.9,
                    label=f"limit {limit:.3g}" + (f", held {hold:.3g} s" if hold else ""))
    top.set_yscale("log")
    top.set_ylabel("unbalanced-force ratio [-]")
    top.set_title(title or f"factor-of-safety trials: {len(trials)}")
    top.legend(fontsize=7, ncol=2)
    bottom.set_yscale("log")   # creep (a line still rising) and rest (flat) read alike at mm and m
    bottom.set_ylabel("largest displacement, growth [m]")
    for ax in (top, bottom):
        ax.set_xlabel("time since the trial's start [s]")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return finish(fig, path, dpi)
