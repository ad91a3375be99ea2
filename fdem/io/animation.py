"""An animated GIF of a run's failure, drawn from its ``.pvd`` frames like the failure picture.

:func:`animate_series` reads the triangle frames of a ``<name>.pvd`` series back (and, when
given, the ``<name>_cracks.pvd`` line frames), draws each the way
:func:`fdem.io.pictures.failure_frame` draws the last state (displacement magnitude on the
deformed mesh, the outline before failure, the crack elements broken by that frame's time by
mode) on one colour scale and one view for all frames, and writes them as a looping GIF with
Pillow (which matplotlib depends on; no video encoder needed). :func:`write_gif` assembles
RGB arrays into a GIF.

A frame is read with meshio, not pyvista: meshio is pure Python over numpy, imports in a
fraction of a second, gives ``points``, ``cells`` and point arrays as numpy arrays directly, and
reads any valid VTU (raw, base64 or compressed appended data, float32 or float64), while
pyvista drags in VTK for no gain here. Only ``points``, the triangle ``cells`` and the
``displacement`` point field are read, so the writer may change what else it stores.
"""
from __future__ import annotations

import os
from pathlib import Path
import numpy as np
from fdem.io.pictures import as_segments, draw_failure, mode_codes, new_figure
from fdem.io.vtk import read_pvd

__all__ = ["MAX_FRAMES", "MAX_TRIANGLES_DRAWN", "read_frame", "read_crack_points", "pick_frames", "write_gif",
           "animate_series"]


MAX_FRAMES = 60
"""Frames drawn at most (a GIF of 60 frames at 8 per second plays 7.5 s)."""


MAX_TRIANGLES_DRAWN = 3_000_000
"""Triangles drawn over all frames at most: fewer frames for a large mesh, so drawing the
animation stays near a minute (about 0.5 s per 100k triangles per frame) and its frames in memory
(positions in float32) near 100 MB."""


def read_frame(vtu: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x (n_nodes, 2) [m], triangles (n_tri, 3), displacement (n_nodes, 2) [m])`` of one
    triangle frame. A frame without a ``displacement`` field is refused, naming the file."""
    import meshio

    m = meshio.read(vtu)
    tri = [c.data for c in m.cells if c.type == "triangle"]
    if not tri:
        raise ValueError(f"{vtu}: no triangle cells")
    if "displacement" not in m.point_data:
        raise ValueError(f"{vtu}: no 'displacement' point field (found {sorted(m.point_data)})")
    return (np.asarray(m.points[:, :2], np.float64), np.concatenate(tri).astype(np.int64),
            np.asarray(m.point_data["displacement"][:, :2], np.float64))


def read_crack_points(vtu: str | os.PathLike) -> np.ndarray:
    """``(n_crack, 2, 2)`` end points [m] of the line cells of one crack frame."""
    import meshio

    m = meshio.read(vtu)
    lines = [c.data for c in m.cells if c.type == "line"]
    if not lines:
        return np.zeros((0, 2, 2))
    return np.asarray(m.points[:, :2], np.float64)[np.concatenate(lines)]


def pick_frames(n: int, max_frames: int) -> np.ndarray:
    """At most ``max_frames`` indices of ``n`` frames, evenly spread, first and last included."""
    if n <= max_frames:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, max(max_frames, 2))).astype(np.int64))


def write_gif(path: str | os.PathLike, images, fps: float = 8.0) -> Path:
    """A looping GIF of ``images`` (each (h, w, 3) or (h, w, 4) uint8, all one size), each shown
    ``1/fps`` s. Every frame gets its own adaptive 256-colour palette."""
    from PIL import Image

    frames = [Image.fromarray(np.asarray(im)[..., :3]).quantize(colors=256) for im in images]
    if not frames:
        raise ValueError(f"no frames to write to {path}")
    sizes = {f.size for f in frames}
    if len(sizes) > 1:
        raise ValueError(f"GIF frames must share one size, got {sorted(sizes)}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=int(round(1000.0 / fps)), loop=0,
                   disposal=1)
    return path


def animate_series(path: str | os.PathLike, pvd: str | os.PathLike, crack_pvd: str | os.PathLike | None = None,
                   events=None, outline=None, joint=None, max_frames: int = MAX_FRAMES, width_px: int = 800,
                   fps: float | None = None, title: str = "") -> Path:
    """Draw the frames of the ``pvd`` series into a GIF at ``path``; returns the path.

    Parameters
    ----------
    crack_pvd : the crack series written beside it (``<name>_cracks.pvd``), frame for frame
    events : the breakage catalogue (``CrackSet.events``: fields ``element``, ``time`` [s] and
        ``mode``), so each frame shows the elements broken by its time, by mode
    outline : (n, 2, 2) segments [m] of the reference boundary, dashed under each frame
    joint : (n_crack,) bool, joint elements (drawn thin while intact)
    max_frames : frames drawn at most (evenly spread, first and last kept), fewer for a large
        mesh (:data:`MAX_TRIANGLES_DRAWN`)
    width_px : width of the GIF [pixels]; the height follows the deformed extent
    fps : frames per second (default: the frames drawn over 6 s, between 2 and 12 per second, so
        a run with few output frames is not over in a blink)
    """
    frames = read_pvd(pvd)
    if not frames:
        raise ValueError(f"{pvd}: the series has no frames")
    cracks = read_pvd(crack_pvd) if crack_pvd is not None else None
    if cracks is not None and len(cracks) != len(frames):
        raise ValueError(f"{crack_pvd} has {len(cracks)} frames, {pvd} has {len(frames)}: not one series")
    x, tri, _ = read_frame(frames[-1][1])
    budget = max(2, int(MAX_TRIANGLES_DRAWN // max(len(tri), 1)))
    pick = pick_frames(len(frames), min(max_frames, budget))
    drawn = []
    for k in pick:
        x, tri, d = read_frame(frames[k][1])
        u = np.linalg.norm(d, axis=1)[tri].mean(axis=1)
        drawn.append((frames[k][0], x.astype(np.float32), u.astype(np.float32), k))
    lo = np.min([f[1].min(axis=0) for f in drawn], axis=0)
    hi = np.max([f[1].max(axis=0) for f in drawn], axis=0)
    pad = 0.02 * max(float((hi - lo).max()), 1e-9)
    lo, hi = lo - pad, hi + pad
    vmax = max(float(max(f[2].max() for f in drawn)), 1e-12)
    if events is not None and len(events):
        el = np.asarray(events["element"], np.int64)
        et = np.asarray(events["time"], np.float64)
        em = mode_codes(events["mode"]) if "mode" in events.dtype.names else np.full(len(el), 3, np.int8)
    else:
        el, et, em = np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int8)
    dpi = 100.0
    aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-12)
    figsize = (width_px / dpi, float(np.clip(0.85 * width_px * aspect / dpi + 1.0, 2.5, 8.0)))
    images = []
    for t, xf, u, k in drawn:
        segs = show = mode = jt = None
        if cracks is not None:
            segs = as_segments(read_crack_points(cracks[k][1]))
            mode = np.zeros(len(segs), np.int8)
            now = (et <= t) & (el < len(segs))
            mode[el[now]] = em[now]
            show = mode > 0
            jt = None if joint is None else np.asarray(joint, bool)
            if jt is not None and jt.shape != (len(segs),):
                raise ValueError(f"joint must have shape ({len(segs)},) like the crack frames, got {jt.shape}")
        fig = new_figure(figsize)
        fig.set_dpi(dpi)
        ax = fig.add_subplot(111)
        draw_failure(fig, ax, xf.astype(np.float64), tri, u.astype(np.float64), segs, show, mode,
                     None if outline is None else as_segments(outline, "outline"), jt, vmax=vmax,
                     legend=cracks is not None)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_title(f"{title + ': ' if title else ''}t = {t:.3g} s", fontsize=10)
        fig.tight_layout()
        fig.canvas.draw()
        images.append(np.asarray(fig.canvas.buffer_rgba()).copy())
    return write_gif(path, images, fps if fps is not None else float(np.clip(len(images) / 6.0, 2.0, 12.0)))
