"""Newmark sliding block: a block on an incline under a base acceleration history (verification.md).

The plane is inclined by tilting gravity, ``g = 9.81 (sin theta, -cos theta)``, so "down the
slope" is ``+x``. A deformable block rests on a base body with friction ``phi > theta`` (it
sticks under gravity alone). After a settling interval ``t_settle`` the base moves along the
plane with the velocity of a one-cycle sine acceleration pulse ``a_b(t) = -A sin(2 pi t / T)``
(up the slope first, the base ends at rest), prescribed on every base node
(:func:`fdem.physics.shaking.shake_base`). The block slips down the slope relative to the base while
``-a_b`` exceeds the yield acceleration ``a_y = g (cos theta tan phi - sin theta)``.

Exact answer: Newmark's (1965) rigid block, integrated exactly for the same piecewise-linear
history (:func:`fdem.reference.newmark.newmark_response`). Compared: the block's permanent displacement
relative to the base (mean over the block's nodes minus the base's, from the start of shaking).

    fdem run newmark-block --out docs/verification           # three mesh sizes: docs/verification/newmark.json
    python cases/newmark_block.py --size 0.5 --no-pictures
"""
from __future__ import annotations

import argparse
import math
import time

from fdem.io.jsonable import write_json
from pathlib import Path

import numpy as np

from fdem.cases.block_on_incline import CONTACT_PENALTY, G, YOUNG, check_scene, incline_model, unbreakable
from fdem.cases.common import check_common, finish_run, prepare_run, set_threads
from fdem.physics.cracks import CrackSet
from fdem.physics.contact import ContactSet
from fdem.solve.model import DEFAULT_ELEMENT_DAMPING
from fdem.physics.shaking import AccelerationHistory, shake_base
from fdem.reference.newmark import newmark_response, yield_acceleration
from fdem.solve.simulation import Simulation

__all__ = ["AMPLITUDE_RATIO", "PERIOD", "T_SETTLE", "SIZES", "pulse", "check_shaking", "build", "run", "plot",
           "parse_args", "main", "THETA", "PHI"]

THETA, PHI = 20.0, 30.0       # deg: a_y = 1.967 m/s^2
AMPLITUDE_RATIO = 2.0         # A / a_y
PERIOD = 1.0                  # s
T_SETTLE = 0.2                # s of gravity alone before the shaking
SIZES = (0.5, 0.25, 0.125)


def pulse(theta_deg: float = THETA, phi_deg: float = PHI, ratio: float = AMPLITUDE_RATIO, period: float = PERIOD,
          start: float = T_SETTLE) -> AccelerationHistory:
    """Base acceleration along the plane (x): ``-ratio a_y sin(2 pi (t - start) / period)``, one cycle."""
    a_y, _ = yield_acceleration(theta_deg, phi_deg, G)
    return AccelerationHistory.sine_pulse(-ratio * a_y, period, start=start)


def check_shaking(size: float = 0.5, theta_deg: float = THETA, phi_deg: float = PHI, ratio: float = AMPLITUDE_RATIO,
                  period: float = PERIOD, t_after: float = 0.5, element_damping: float = DEFAULT_ELEMENT_DAMPING,
                  n_samples: int = 200, penalty: float = CONTACT_PENALTY) -> None:
    """A ``ValueError`` naming the first setting the test cannot honour, before any meshing:
    the incline's (:func:`fdem.cases.block_on_incline.check_scene`, 1 m block), and ``phi > theta``
    (the block must stick under gravity alone: yield acceleration ``a_y > 0``), ``ratio > 1``
    (``A / a_y``: at or below 1 the block never slips and the relative error divides by a zero
    Newmark displacement), ``period`` > 0 [s], ``t_after`` >= 0 [s], ``n_samples`` >= 1,
    ``penalty`` > 0 [Pa]."""
    check_scene(theta_deg, phi_deg, 1.0, 1.0, 1.0, size, element_damping)
    if not phi_deg > theta_deg:
        raise ValueError(f"newmark block: phi ({phi_deg} deg) must exceed theta ({theta_deg} deg) so that the block "
                         f"sticks under gravity alone (yield acceleration > 0)")
    for name, value in (("ratio (A / a_y)", ratio), ("period", period), ("penalty", penalty)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"newmark block: {name} must be a positive number, got {value}")
    if not ratio > 1:
        raise ValueError(f"newmark block: ratio (A / a_y) must exceed 1, got {ratio}: below the yield acceleration "
                         f"the block never slips and there is no displacement to compare")
    if not (math.isfinite(t_after) and t_after >= 0):
        raise ValueError(f"newmark block: t_after must be a non-negative time [s], got {t_after}")
    if not (isinstance(n_samples, int) and n_samples >= 1):
        raise ValueError(f"newmark block: n_samples must be a positive integer, got {n_samples!r}")


def build(history: AccelerationHistory, theta_deg: float = THETA, phi_deg: float = PHI, size: float = 0.5,
          element_damping: float = DEFAULT_ELEMENT_DAMPING, base_length: float = 8.0,
          penalty: float = CONTACT_PENALTY):
    """Model, providers, block node ids and base node ids; the base shaken by ``history`` along x.
    ``penalty`` [Pa]: contact penalty."""
    model, base_nodes, block_nodes = incline_model(theta_deg, 0.5 * base_length - 0.5, 1.0, 1.0, size, base_length,
                                                   element_damping)
    shake_base(model, base_nodes, history, components="xy")  # x: the history; y: held (a_y = 0)
    cracks = CrackSet(model.topology, {0: unbreakable(YOUNG)})
    contact = ContactSet(model.topology, penalty, friction_angle=phi_deg, mass=model.node_mass(), cracks=cracks)
    return model, [cracks, contact], block_nodes, base_nodes


def run(size: float = 0.5, theta_deg: float = THETA, phi_deg: float = PHI, ratio: float = AMPLITUDE_RATIO,
        period: float = PERIOD, t_after: float = 0.5, element_damping: float = DEFAULT_ELEMENT_DAMPING,
        n_samples: int = 200, penalty: float = CONTACT_PENALTY, max_time: float | None = None) -> dict:
    """Shake the block; return its slip relative to the base against Newmark's, in time and at the end.

    The run lasts until ``t_after`` [s] past the Newmark block's stopping time, or ``max_time``
    [s] of simulated time if that is shorter (a smoke run: ``time_capped`` is then true and the
    error compares an unfinished slip). ``n_samples`` slip samples are recorded along the way.
    Settings the test cannot honour raise a ``ValueError`` before meshing (:func:`check_shaking`).
    """
    check_shaking(size, theta_deg, phi_deg, ratio, period, t_after, element_damping, n_samples, penalty)
    history = pulse(theta_deg, phi_deg, ratio, period)
    t_nm, d_nm, _ = newmark_response(history.t, history.along((1, 0)), theta_deg, phi_deg, G)
    t_end = float(t_nm[-1]) + t_after
    capped = max_time is not None and max_time < t_end
    if capped:
        t_end = max_time
    model, providers, block, base = build(history, theta_deg, phi_deg, size, element_damping, penalty=penalty)
    sim = Simulation(model, providers=providers, progress=False)
    wall = time.perf_counter()
    sim.run(t_end=min(T_SETTLE, t_end), history_every=10**9, energy_tolerance=0.05, stage="settle")

    def rel(s):  # mean down-slope displacement of the block minus the base's [m]
        u = s.state.x[:, 0] - s.x0[:, 0]
        return float(u[block].mean() - u[base].mean())

    r0 = rel(sim)
    times, slips = [sim.state.time], [0.0]
    chunk = max(1, int(round((t_end - T_SETTLE) / n_samples / sim.dt)))
    while sim.state.time < t_end:
        sim.run(n_steps=chunk, history_every=chunk, stage="shake", energy_tolerance=0.05, final_output=False)
        times.append(sim.state.time)
        slips.append(rel(sim) - r0)
    wall = time.perf_counter() - wall
    times, slips = np.array(times), np.array(slips)
    d_exact = float(d_nm[-1])
    _, d_curve, _ = newmark_response(history.t, history.along((1, 0)), theta_deg, phi_deg, G, t_eval=times)
    row = sim.history[-1]
    return {"size_m": size, "theta_deg": theta_deg, "phi_deg": phi_deg,
            "a_y_m_s2": yield_acceleration(theta_deg, phi_deg, G)[0], "amplitude_m_s2": ratio * yield_acceleration(
                theta_deg, phi_deg, G)[0], "period_s": period, "t_settle_s": T_SETTLE,
            "slip_m": float(slips[-1]), "newmark_m": d_exact, "error": float(slips[-1] / d_exact - 1.0),
            "balance_error_relative": float(row["balance_error_relative"]),
            "boundary_work_J_per_m": float(row["boundary_work"]), "friction_J_per_m": float(row.get("friction", 0.0)),
            "n_block_triangles": int(len(block) // 3), "dt_s": sim.dt, "steps": sim.state.step, "wall_s": wall,
            "element_damping": element_damping, "contact_penalty_Pa": penalty, "time_capped": capped,
            "t_s": times.tolist(), "slip_curve_m": slips.tolist(), "newmark_curve_m": d_curve.tolist()}


def plot(rows: list[dict], png: Path) -> None:
    """Slip relative to the base against time for each mesh size, with Newmark's rigid block (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    r0 = rows[0]
    t = np.array(r0["t_s"]) - r0["t_settle_s"]
    ax.plot(t, 100 * np.array(r0["newmark_curve_m"]), "k-", lw=2.5, label="Newmark (1965) rigid block")
    for r in rows:
        ax.plot(np.array(r["t_s"]) - r["t_settle_s"], 100 * np.array(r["slip_curve_m"]), "--", lw=1.4,
                label=f"FDEM, h = {r['size_m']:g} m ({r['n_block_triangles']} block triangles): "
                      f"{100 * r['error']:+.2f} %")
    ax.set_xlabel("time since the start of shaking [s]")
    ax.set_ylabel("block slip relative to the base [cm]")
    ax.set_title(f"theta {r0['theta_deg']:g} deg, phi {r0['phi_deg']:g} deg, sine pulse "
                 f"{r0['amplitude_m_s2']:.3g} m/s^2, T = {r0['period_s']:g} s", fontsize=9)
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def parse_args(argv=None) -> argparse.Namespace:
    """The command line's options, checked before anything is meshed (``parser.error``, exit
    status 2): at least one ``--size``, each positive and at most the 1 m block's side."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--overwrite", action="store_true", help="replace the earlier run in --out")
    parser.add_argument("--out", type=Path, default=Path("runs/newmark"),
                        help="folder for newmark.json and newmark.png (default runs/newmark; the committed figures: --out docs/verification)")
    parser.add_argument("--size", type=float, nargs="*", default=list(SIZES), help="element sizes [m]")
    parser.add_argument("--no-pictures", action="store_true", help="skip the PNG")
    parser.add_argument("--quiet", action="store_true", help="only warnings and the result")
    parser.add_argument("--threads", type=int, default=None, help="Numba threads (default: all cores)")
    parser.add_argument("--max-time", type=float, default=None, metavar="SECONDS",
                        help="cap on each run's simulated time [s] (a smoke run; default: until the block stops)")
    args = parser.parse_args(argv)
    from fdem.io.messages import configure

    configure(quiet=args.quiet)
    check_common(parser, args)
    if not args.size:
        parser.error("--size needs at least one element size [m]")
    for size in args.size:
        try:
            check_shaking(size)
        except ValueError as err:
            parser.error(str(err).replace("block on incline: ", "").replace("newmark block: ", ""))
    return args


def main(argv=None):
    args = parse_args(argv)
    args = prepare_run(None, args, argv, "newmark-block")
    set_threads(args.threads)
    rows = []
    args.out.mkdir(parents=True, exist_ok=True)
    for size in args.size:
        r = run(size, max_time=args.max_time)
        rows.append(r)
        print(f"h = {size:g} m: slip {100 * r['slip_m']:.3f} cm, Newmark {100 * r['newmark_m']:.3f} cm, "
              f"error {100 * r['error']:+.2f} %, ledger {r['balance_error_relative']:.2e}, "
              f"{r['steps']} steps, {r['wall_s']:.1f} s"
              + (f" (SMOKE RUN: stopped at --max-time {args.max_time:g} s, before the block came to rest: the error "
                 f"compares an unfinished slip)" if r["time_capped"] else ""), flush=True)
        write_json(args.out / "newmark.json",
                   {"description": "Newmark sliding block: slip relative to the base vs the rigid-block solution",
                    "runs": rows}, indent=1)
    if not args.no_pictures:
        plot(rows, args.out / "newmark.png")
    finish_run(args.out, {"outcome": "finished"})
    return {"runs": rows}


if __name__ == "__main__":
    main()
