"""Pictures of point monitors: displacement and velocity of watched points against time.

A point monitor (:meth:`fdem.solve.simulation.Simulation.add_point_monitor`) writes the columns
``<name>_ux``, ``<name>_uy`` [m], ``<name>_vx``, ``<name>_vy`` [m/s] (and stresses) into every
history row; :func:`monitor_plot` draws them from ``Simulation.history`` (a list of rows) or
from ``read_history("history.csv")`` (a dict of columns, :mod:`fdem.io.history`).
"""
from __future__ import annotations

import os
from pathlib import Path
import numpy as np

__all__ = ["monitor_plot", "monitor_figure"]


def _columns(history, names: list[str]) -> dict[str, np.ndarray]:
    """``time`` and each monitor's four kinematic columns as float arrays; a missing column is
    a ``ValueError`` naming it and the monitors the history has."""
    if isinstance(history, dict):
        cols = history
        have = set(history)
    else:
        rows = list(history)
        have = set(rows[0]) if rows else set()
        cols = {k: [r.get(k, np.nan) for r in rows] for k in have}
    needed = ["time"] + [f"{n}_{q}" for n in names for q in ("ux", "uy", "vx", "vy")]
    missing = [c for c in needed if c not in have]
    if missing:
        monitors = sorted({c[:-3] for c in have if c.endswith("_ux")})
        raise ValueError(f"monitor_plot: the history has no column(s) {missing}; its point monitors are {monitors}")
    return {c: np.asarray(cols[c], dtype=float) for c in needed}


def monitor_figure(history, names):
    """The matplotlib figure of :func:`monitor_plot` (two panels sharing the time axis)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [names] if isinstance(names, str) else list(names)
    if not names:
        raise ValueError("monitor_plot: give at least one point monitor name")
    c = _columns(history, names)
    t = c["time"]
    fig, (ax_u, ax_v) = plt.subplots(2, 1, figsize=(7.0, 5.5), sharex=True, constrained_layout=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, n in enumerate(names):
        col = colours[k % len(colours)]
        ax_u.plot(t, c[f"{n}_ux"], color=col, label=f"{n} u_x")
        ax_u.plot(t, c[f"{n}_uy"], color=col, ls="--", label=f"{n} u_y")
        ax_v.plot(t, c[f"{n}_vx"], color=col, label=f"{n} v_x")
        ax_v.plot(t, c[f"{n}_vy"], color=col, ls="--", label=f"{n} v_y")
    ax_u.set_ylabel("displacement [m]")
    ax_v.set_ylabel("velocity [m/s]")
    ax_v.set_xlabel("time [s]")
    ax_u.set_title("point monitors")
    for ax in (ax_u, ax_v):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="small", ncol=2)
    return fig


def monitor_plot(path: str | os.PathLike, history, names) -> Path:
    """PNG at ``path`` of the displacement ``u_x, u_y`` [m] and velocity ``v_x, v_y`` [m/s] of
    the point monitors ``names`` (one name or a list) against time [s]; returns the path.

    ``history``: ``Simulation.history`` (rows) or ``read_history("history.csv")`` (columns). A
    monitor missing from the history is a ``ValueError`` naming it."""
    import matplotlib.pyplot as plt

    fig = monitor_figure(history, names)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
