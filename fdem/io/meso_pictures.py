"""Pictures of the meso-scale views (cases.md B, seed 001): crack initiation order, event map,
magnitude histogram against a normal law, fragment assemblies at successive times, force chains
with principal-stress directions. Plain arrays in, a PNG out (or the figure when ``path`` is
None); the readings themselves are :mod:`fdem.results.meso`. Axes in metres, forces in N/m
(per metre of thickness), stresses in MPa.
"""
from __future__ import annotations

import math
import os

import numpy as np

from fdem.io.pictures import finish, new_figure

__all__ = ["initiation_map", "event_map", "magnitude_histogram", "fragment_maps", "force_chain_maps"]


def _mesh(ax, x, triangles, facecolor="0.92", edgecolor="none", colours=None, lw=0.0):
    from matplotlib.collections import PolyCollection

    polys = np.asarray(x)[np.asarray(triangles)]
    pc = PolyCollection(polys, facecolors=colours if colours is not None else facecolor, edgecolors=edgecolor,
                        linewidths=lw)
    ax.add_collection(pc)
    ax.set_xlim(polys[..., 0].min() - 0.5, polys[..., 0].max() + 0.5)
    ax.set_ylim(polys[..., 1].min() - 0.5, polys[..., 1].max() + 0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return pc


def _lines(ax, segments, **kw):
    from matplotlib.collections import LineCollection

    segs = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    lc = LineCollection(segs, **kw)
    ax.add_collection(lc)
    return lc


def _slope_axes(x, triangles, joints):
    """A figure with the slope's mesh and, when given, its joints (m, 4) [m] drawn thin black:
    the background of the maps below."""
    fig = new_figure((9.0, 6.5))
    ax = fig.add_subplot(111)
    _mesh(ax, x, triangles)
    if joints is not None and len(joints):
        _lines(ax, joints, colors="k", linewidths=0.6)
    return fig, ax


def initiation_map(path: str | os.PathLike | None, x, triangles, segments, rank, time=None, joints=None,
                   title: str = "", dpi: int = 130):
    """The first breakages as segments (k, 4) [m] coloured by their order ``rank`` (0 = first);
    ``time`` [s] (k,) labels the colour bar's ends; ``joints`` (m, 4) drawn thin black; the first
    break starred."""
    rank = np.asarray(rank, dtype=float)
    segs = np.asarray(segments, dtype=float).reshape(-1, 4)
    if segs.shape[0] != rank.size:
        raise ValueError(f"initiation_map: {segs.shape[0]} segments for {rank.size} ranks")
    fig, ax = _slope_axes(x, triangles, joints)
    if rank.size:
        lc = _lines(ax, segs, array=rank, cmap="plasma_r", linewidths=2.2)
        cb = fig.colorbar(lc, ax=ax, shrink=0.8)
        label = "break order (0 = first)"
        if time is not None and len(time):
            label += f"; t = {np.min(time):.3g} to {np.max(time):.3g} s"
        cb.set_label(label)
        mid = 0.5 * (segs[0, :2] + segs[0, 2:])
        ax.plot(mid[0], mid[1], marker="*", ms=14, mfc="yellow", mec="k", zorder=5, label="first break")
        ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title or f"crack initiation: the first {rank.size} breaks by order")
    fig.tight_layout()
    return finish(fig, path, dpi)


def event_map(path: str | os.PathLike | None, x, triangles, ex, ey, magnitude, t=None, joints=None,
              title: str = "", dpi: int = 130):
    """Events at ``(ex, ey)`` [m], circle area growing with magnitude (smallest 8 pt^2, largest
    300 pt^2, linear in Mw), coloured by time [s] when ``t`` is given."""
    mag = np.asarray(magnitude, dtype=float)
    fig, ax = _slope_axes(x, triangles, joints)
    if mag.size:
        lo, hi = float(mag.min()), float(mag.max())
        size = 8.0 + 292.0 * ((mag - lo) / (hi - lo) if hi > lo else np.full(mag.size, 0.5))
        sc = ax.scatter(ex, ey, s=size, c=t if t is not None else "tab:red", cmap="viridis", alpha=0.6,
                        edgecolors="k", linewidths=0.4, zorder=4)
        if t is not None:
            fig.colorbar(sc, ax=ax, shrink=0.8).set_label("event start time [s]")
        for m in (lo, 0.5 * (lo + hi), hi):
            s = 8.0 + 292.0 * ((m - lo) / (hi - lo) if hi > lo else 0.5)
            ax.scatter([], [], s=s, facecolors="none", edgecolors="k", label=f"Mw {m:.2f}")
        ax.legend(loc="lower right", fontsize=8, title="circle size")
    ax.set_title(title or f"micro-seismic events ({mag.size})")
    fig.tight_layout()
    return finish(fig, path, dpi)


def magnitude_histogram(path: str | os.PathLike | None, magnitudes, reference: dict | None = None,
                        test: dict | None = None, dm: float = 0.2, dpi: int = 130):
    """Histogram of the magnitudes (bins ``dm``), the normal law fitted to them and, when given,
    the reference law ``reference = {"mean", "std", "count"}`` scaled to its own count; ``test``
    (:func:`fdem.results.meso.normality`) is written in the corner."""
    m = np.asarray(magnitudes, dtype=float)
    m = m[np.isfinite(m)]
    fig = new_figure((8.0, 5.0))
    ax = fig.add_subplot(111)
    lo = min(m.min() if m.size else 0.0, reference["mean"] - 4 * reference["std"] if reference else np.inf)
    hi = max(m.max() if m.size else 0.0, reference["mean"] + 4 * reference["std"] if reference else -np.inf)
    edges = np.arange(math.floor(lo / dm) * dm, math.ceil(hi / dm) * dm + dm, dm)
    ax.hist(m, bins=edges, color="tab:blue", alpha=0.6, label=f"this model ({m.size} events)")
    grid = np.linspace(edges[0], edges[-1], 300)

    def pdf(mu, sd):
        return np.exp(-0.5 * ((grid - mu) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))

    if m.size >= 2 and m.std() > 0:
        ax.plot(grid, m.size * dm * pdf(m.mean(), m.std(ddof=1)), "b-",
                label=f"normal fit N({m.mean():.2f}, {m.std(ddof=1):.2f})")
    if reference:
        n = reference.get("count", m.size)
        ax.plot(grid, n * dm * pdf(reference["mean"], reference["std"]), "r--",
                label=f"paper N({reference['mean']:.2f}, {reference['std']:.3f}), {n} events")
    if test:
        txt = (f"Shapiro-Wilk p = {test['shapiro_p']:.3g}\nAnderson-Darling A2 = {test['anderson_statistic']:.2f} "
               f"(5 %: {test['anderson_critical_5pct']:.2f})\nskewness {test['skewness']:.2f}")
        if "ks_p" in test:
            txt += f"\nKS against the paper's law p = {test['ks_p']:.2g}"
        ax.text(0.02, 0.97, txt, transform=ax.transAxes, va="top", fontsize=8,
                bbox=dict(facecolor="white", alpha=0.8, edgecolor="0.7"))
    ax.set_xlabel("moment magnitude Mw [-]")
    ax.set_ylabel(f"events per {dm:g} Mw bin")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return finish(fig, path, dpi)


def _extent(ax, extent):
    if extent is not None:
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])


def fragment_maps(path: str | os.PathLike | None, frames, triangles, min_triangles: int, dpi: int = 120,
                  extent=None):
    """One panel per frame ``(x, assembly, title)``: triangles coloured by assembly
    (``assembly`` (n_tri,) from :func:`fdem.results.meso.assemblies`, -1 for debris below
    ``min_triangles`` triangles, drawn white with a grey edge); the largest assembly (0, the
    ground the slope stands on) light grey. ``extent`` ``(x0, x1, y0, y1)`` [m] fixes the view
    (debris that left the model is then out of the picture)."""
    from matplotlib import colormaps

    frames = list(frames)
    if not frames:
        raise ValueError("fragment_maps needs at least one frame")
    fig = new_figure((5.2 * len(frames), 4.6))
    cmap = colormaps["tab20"]
    for i, (x, assembly, title) in enumerate(frames):
        ax = fig.add_subplot(1, len(frames), i + 1)
        a = np.asarray(assembly)
        colours = np.array([cmap(int(k - 1) % 20) for k in np.maximum(a, 1)])
        colours[a == 0] = (0.85, 0.85, 0.85, 1.0)
        colours[a < 0] = (1.0, 1.0, 1.0, 1.0)
        _mesh(ax, x, triangles, colours=colours, edgecolor="0.6", lw=0.15)
        _extent(ax, extent)
        ax.set_title(f"{title}\n{int(a.max()) if a.size else 0} assemblies besides the ground; "
                     f"debris (< {min_triangles} triangles) white", fontsize=8)
    fig.tight_layout()
    return finish(fig, path, dpi)


def force_chain_maps(path: str | os.PathLike | None, frames, triangles, dpi: int = 120, max_ticks: int = 400,
                     extent=None):
    """One panel per frame, a dict with ``x`` (node positions [m]), ``title``, ``contact``
    ``(segments, magnitude [N/m])``, ``crack`` ``(segments, magnitude [N/m])`` (compressive force
    carried by intact crack elements), ``centroids`` (n_tri, 2), ``theta2`` [rad] and ``s2`` [Pa]
    (most compressive principal stress). Line width grows with the force (the largest of the
    panel 3 pt); black ticks along ``theta2`` on an even sample of triangles, length by ``|s2|``;
    ``extent`` as :func:`fragment_maps`."""
    frames = list(frames)
    if not frames:
        raise ValueError("force_chain_maps needs at least one frame")
    fig = new_figure((6.2 * len(frames), 5.2))
    for i, f in enumerate(frames):
        ax = fig.add_subplot(1, len(frames), i + 1)
        _mesh(ax, f["x"], triangles, facecolor="0.96")
        top = max([float(np.max(m)) for _, m in (f["crack"], f["contact"]) if len(m)] or [1.0])
        for (segs, mag), colour, label in ((f["crack"], "tab:blue", "crack elements"),
                                           (f["contact"], "tab:red", "contacts")):
            if len(mag):
                _lines(ax, segs, colors=colour, linewidths=0.2 + 2.8 * np.asarray(mag) / top, alpha=0.8,
                       label=f"{label} (max {np.max(mag) / 1e6:.2f} MN/m)")
        c, th, s2 = np.asarray(f["centroids"]), np.asarray(f["theta2"]), np.asarray(f["s2"])
        pick = np.linspace(0, c.shape[0] - 1, min(max_ticks, c.shape[0])).astype(int)
        scale = 1.2 / max(float(np.max(np.abs(s2[pick]))), 1.0)  # the largest tick 1.2 m long
        half = (0.5 * np.abs(s2[pick]) * scale)[:, None] * np.column_stack([np.cos(th[pick]), np.sin(th[pick])])
        ticks = np.hstack([c[pick] - half, c[pick] + half])
        _lines(ax, ticks, colors="k", linewidths=0.9,
               label=f"most compressive stress direction (|s2| up to {np.max(np.abs(s2)) / 1e6:.2f} MPa)")
        _extent(ax, extent)
        ax.legend(loc="lower right", fontsize=7)
        ax.set_title(f["title"], fontsize=9)
    fig.tight_layout()
    return finish(fig, path, dpi)
