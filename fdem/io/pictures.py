"""Pictures of a slope run, off-screen (matplotlib Agg): the failure frame and the time plots.

Every function takes plain arrays and a path, writes a PNG and returns the path; arrays of
mismatched shape are refused with the names and shapes involved.

* :func:`failure_frame`: displacement magnitude on the deformed mesh (flat-shaded triangles,
  perceptual colour map, colour bar in m) with the broken crack elements drawn on top,
  coloured by failure mode (I tensile, II shear, mixed), as in a rock-engineering failure figure.
* :func:`kinetic_energy_plot`: kinetic energy [J/m] against time, stage boundaries marked.
* :func:`crack_count_plot`: cumulative broken crack elements by mode against time.
* :func:`fragment_size_plot`: number of fragments per log-spaced area bin.

The magnitude-frequency picture needs the event statistics and lives with them
(:func:`fdem.results.events.magnitude_plot`).
"""
from __future__ import annotations

import os
from pathlib import Path
import numpy as np

__all__ = ["MODE_COLOURS", "MODE_LABELS", "new_figure", "save_figure", "mode_codes", "failure_frame",
           "kinetic_energy_plot", "crack_count_plot", "fragment_size_plot"]


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


def failure_frame(path: str | os.PathLike, x: np.ndarray, triangles, displacement: np.ndarray,
                  crack_segments: np.ndarray | None = None, broken: np.ndarray | None = None,
                  failure_mode: np.ndarray | None = None, title: str = "", cmap: str = "viridis",
                  vmax: float | None = None, dpi: int = 150, figsize=None) -> Path:
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

    Flat-shaded triangles go through one ``tripcolor`` (a single PolyCollection) and the cracks
    through one LineCollection per mode, so a 180k-triangle frame renders in seconds
    (``docs/outputs.md``).
    """
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.tri import Triangulation

    tri = np.asarray(getattr(triangles, "triangles", triangles), dtype=np.int64)
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 2:
        raise ValueError(f"x must have shape (n_nodes, 2), got {x.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"triangles must have shape (n_tri, 3), got {tri.shape}")
    if tri.size and (tri.min() < 0 or tri.max() >= len(x)):
        raise ValueError(f"triangles refer to nodes outside x (0..{len(x) - 1})")
    u = np.asarray(displacement, dtype=np.float64)
    if u.shape == (len(x),) and len(x) != len(tri):
        u = u[tri].mean(axis=1)
    if u.shape != (len(tri),):
        raise ValueError(f"displacement must have one value per triangle ({len(tri)},) or per node "
                         f"({len(x)},), got {u.shape}")
    segs = None
    if crack_segments is not None:
        segs = np.asarray(crack_segments, dtype=np.float64)
        if segs.ndim == 2 and segs.shape[1] == 2 and len(segs) % 2 == 0:
            segs = segs.reshape(-1, 2, 2)
        if segs.ndim != 3 or segs.shape[1:] != (2, 2):
            raise ValueError(f"crack_segments must have shape (n_crack, 2, 2) or (2 n_crack, 2), got {segs.shape}")
        n_crack = len(segs)
        mode = np.full(n_crack, 3, np.int8) if failure_mode is None else mode_codes(failure_mode)
        if mode.shape != (n_crack,):
            raise ValueError(f"failure_mode must have shape ({n_crack},) like crack_segments, got {mode.shape}")
        show = mode > 0 if broken is None else np.asarray(broken, dtype=bool)
        if show.shape != (n_crack,):
            raise ValueError(f"broken must have shape ({n_crack},) like crack_segments, got {show.shape}")

    if figsize is None:
        span = np.ptp(x, axis=0) if len(x) else np.ones(2)
        figsize = (11.0, float(np.clip(9.0 * span[1] / max(span[0], 1e-300) + 1.4, 3.0, 9.0)))
    fig = new_figure(figsize)
    ax = fig.add_subplot(111)
    pc = ax.tripcolor(Triangulation(x[:, 0], x[:, 1], tri), facecolors=u, cmap=cmap, shading="flat",
                      vmin=0.0, vmax=vmax if vmax is not None else (float(u.max()) if u.size else 1.0),
                      edgecolors="face", linewidth=0.0, antialiased=False, rasterized=True)
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    cax = make_axes_locatable(ax).append_axes("right", size="2%", pad=0.1)  # as tall as the mesh
    fig.colorbar(pc, cax=cax, label="displacement magnitude [m]")
    handles = []
    if segs is not None and show.any():
        lw = 0.9 if show.sum() < 20000 else 0.5
        ax.add_collection(LineCollection(segs[show], colors="k", linewidths=lw + (1.0 if lw > 0.5 else 0.6),
                                         zorder=3))
        for code in (2, 3, 1):  # tensile on top: the cracks that open
            sel = show & (mode == code)
            if sel.any():
                ax.add_collection(LineCollection(segs[sel], colors=MODE_COLOURS[code], linewidths=lw, zorder=4))
                handles.append(Line2D([], [], color=MODE_COLOURS[code], lw=2.5,
                                      label=f"{MODE_LABELS[code]}: {int(sel.sum())}"))
    if handles:
        leg = ax.legend(handles=handles[::-1], loc="upper left", fontsize=8, title="broken crack elements",
                        title_fontsize=8, facecolor="0.35", labelcolor="w", framealpha=0.9)
        leg.get_title().set_color("w")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return save_figure(fig, path, dpi)


def _stage_marks(ax, time: np.ndarray, stage) -> None:
    if stage is None:
        return
    stage = np.asarray(stage)
    change = np.flatnonzero(stage[1:] != stage[:-1]) + 1
    for k in change:
        ax.axvline(time[k], color="0.5", lw=0.8, ls="--")
    starts = np.r_[0, change]
    for k in starts:
        ax.annotate(str(stage[k]), (time[k], 1.0), xycoords=("data", "axes fraction"), xytext=(2, -10),
                    textcoords="offset points", fontsize=7, color="0.3")


def kinetic_energy_plot(path: str | os.PathLike, time: np.ndarray, kinetic: np.ndarray, stage=None,
                        log: bool = False, title: str = "", dpi: int = 130) -> Path:
    """Kinetic energy [J per metre of thickness] against time [s] (history columns ``time``,
    ``kinetic``); ``stage`` (same length) marks stage changes with dashed lines; ``log`` for a
    logarithmic energy axis."""
    time, kinetic = np.asarray(time, float), np.asarray(kinetic, float)
    _same_length(time=time, kinetic=kinetic, **({} if stage is None else {"stage": stage}))
    fig = new_figure((8.0, 4.0))
    ax = fig.add_subplot(111)
    ax.plot(time, kinetic, color="C0", lw=1.2)
    if log:
        ax.set_yscale("log")
    _stage_marks(ax, time, stage)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("kinetic energy [J/m]")
    ax.set_title(title or f"kinetic energy, peak {kinetic.max() if kinetic.size else 0.0:.3g} J/m")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path, dpi)


def crack_count_plot(path: str | os.PathLike, time: np.ndarray, mode, t_end: float | None = None,
                     title: str = "", dpi: int = 130) -> Path:
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
    ax.set_ylabel("cumulative broken crack elements")
    ax.set_title(title or "crack breakage by failure mode")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path, dpi)


def fragment_size_plot(path: str | os.PathLike, areas: np.ndarray, bins_per_decade: int = 4,
                       title: str = "", dpi: int = 130, time: np.ndarray | None = None,
                       count: np.ndarray | None = None, stage=None) -> Path:
    """Number of fragments per log-spaced area bin (``bins_per_decade`` per factor of 10) of the
    fragment areas [m^2 per metre] (``fragment_statistics(...)["areas"]``), log-log axes; with
    ``time`` [s] and ``count`` (the ``fragments`` monitor of the history), a left panel shows
    the number of fragments against time, with the stages marked."""
    a = np.asarray(areas, float).ravel()
    if a.size == 0 or np.any(a <= 0):
        raise ValueError("fragment areas must be a non-empty array of positive values [m^2]")
    lo = np.floor(np.log10(a.min()) * bins_per_decade)
    hi = np.ceil(np.log10(a.max()) * bins_per_decade)
    edges = 10.0 ** (np.arange(lo, max(hi, lo + 1) + 1) / bins_per_decade)
    counts, _ = np.histogram(a, bins=edges)
    over_time = time is not None and count is not None and len(time) > 1
    fig = new_figure((12.0, 4.2) if over_time else (7.0, 4.2))
    if over_time:
        n = _same_length(time=np.asarray(time), count=np.asarray(count))
        ax0 = fig.add_subplot(121)
        ax0.step(np.asarray(time, float)[:n], np.asarray(count, float)[:n], where="post", color="C2")
        if stage is not None:
            _stage_marks(ax0, np.asarray(time, float)[:n], stage)
        ax0.set_xlabel("time [s]")
        ax0.set_ylabel("number of fragments")
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
    ax.set_ylabel("number of fragments")
    ax.set_title(title or f"{a.size} fragments, largest {a.max():.3g} m$^2$ ({a.max() / a.sum():.0%} of the area)")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    return save_figure(fig, path, dpi)
