"""Pictures of a block system and its collapse mechanism (matplotlib, imported here only)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fdem.blocks.assembly import BRIDGE, CONTACT, BlockSystem
from fdem.blocks.limit import Mechanism

__all__ = ["draw_mechanism", "save_mechanism"]


def draw_mechanism(ax, system: BlockSystem, mechanism: Mechanism | None = None, title: str = "",
                   arrows: bool = True) -> None:
    """Blocks on ``ax``: fixed grey, free white, moving ones coloured by the speed of their
    fastest corner (1 = the fastest of the mechanism), arrows for the centroid velocities;
    joints black, rock bridges red, contacts between bodies blue."""
    from matplotlib.collections import LineCollection, PolyCollection

    speed = np.zeros(system.n_blocks)
    if mechanism is not None:
        for i in np.flatnonzero(mechanism.moving):
            r = system.polygons[i] - system.centroid[i]
            v = mechanism.velocity[i]
            speed[i] = np.linalg.norm(v[:2] + v[2] * np.column_stack([-r[:, 1], r[:, 0]]), axis=1).max()
    colours = []
    import matplotlib

    cmap = matplotlib.colormaps["autumn_r"]
    for i in range(system.n_blocks):
        if system.fixed[i]:
            colours.append((0.85, 0.85, 0.85, 1.0))
        elif speed[i] > 1e-3:
            colours.append(cmap(0.25 + 0.75 * speed[i]))
        else:
            colours.append((1.0, 1.0, 1.0, 1.0))
    ax.add_collection(PolyCollection(list(system.polygons), facecolors=colours, edgecolors="none"))
    for tag, colour, lw in ((None, "k", 0.6), (BRIDGE, "r", 1.0), (CONTACT, "b", 1.0)):
        sel = (system.tag >= 1) if tag is None else (system.tag == tag)
        if sel.any():
            ax.add_collection(LineCollection(list(system.ends[sel]), colors=colour, linewidths=lw))
    outline = [np.vstack([p, p[:1]]) for p in system.polygons]
    ax.add_collection(LineCollection(outline, colors="0.4", linewidths=0.3))
    if mechanism is not None and arrows and mechanism.moving.any():
        # at most 25 arrows, on the largest moving blocks, 6 % of the section's width long at speed 1
        m = np.flatnonzero(mechanism.moving)
        m = m[np.argsort(system.area[m])[::-1][:25]]
        c, v = system.centroid[m], mechanism.velocity[m, :2]
        allp = np.vstack(system.polygons)
        scale = 0.06 * float(np.ptp(allp[:, 0]))
        ax.quiver(c[:, 0], c[:, 1], v[:, 0] * scale, v[:, 1] * scale, angles="xy", scale_units="xy", scale=1,
                  width=0.003, color="k")
    allp = np.vstack(system.polygons)
    ax.set_xlim(allp[:, 0].min(), allp[:, 0].max())
    ax.set_ylim(allp[:, 1].min(), allp[:, 1].max())
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def save_mechanism(path: Path, system: BlockSystem, mechanism: Mechanism | None, title: str = "",
                   size=(7.0, 3.6)) -> Path:
    """:func:`draw_mechanism` into a PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size)
    draw_mechanism(ax, system, mechanism, title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
