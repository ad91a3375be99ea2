"""Convergence with refinement: slide error against element size, one line per element damping.

Two scenes of ``docs/verification.md``, both a 1 m x 1 m elastic block on a fixed (or shaken)
base plate, contact penalty 20 E (:mod:`fdem.cases.block_on_incline`):

* block on incline (theta 30, phi 20, the case's defaults): mean slide at 1 s against the
  rigid block ``g t^2 (sin theta - tan phi cos theta) / 2``;
* Newmark block (:mod:`fdem.cases.newmark_block`): permanent slip against Newmark's rigid block.

For every element size and element-damping fraction (of critical, ``Model.set_element_damping``)
it records the error. Incline runs also record what the block's base does while it slides:
sampled every ``SAMPLE`` steps, the fraction of its bottom nodes moving up the slope (reversed
slip) and the block's vibration kinetic energy (kinetic energy less that of its rigid motion),
both averaged over the slide. Two targeted incline runs test the cause at a fixed size:
``settled`` releases the undamped block from rest on its gravity-loaded base (0.2 s with
friction mu = 10 and Cundall's local damping 0.8 first, then friction tan(phi) and no damping),
``penalty x K`` scales the contact penalty (undamped at the fixed size; with the default damping
at 0.5 and 0.25 m, x0.25 and x4).

Each process writes its rows to ``runs/bench_refinement_drift/<part>.json`` (rows already
there are skipped, so parts run side by side and resume); ``--report`` merges the parts, prints
the table, saves ``docs/benchmarks/refinement_drift.json`` (``records.save``) and the plot
``docs/verification/refinement_drift.png``.

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_refinement_drift.py --part incline --scene incline
    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_refinement_drift.py --part nm --scene newmark --sizes 0.5 0.25
    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_refinement_drift.py --part cause --scene cause
    python cases/benchmarks/bench_refinement_drift.py --report
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
sys.path.insert(0, str(Path(__file__).resolve().parent))

from records import record, save  # noqa: E402

RUNS = ROOT / "runs" / "bench_refinement_drift"
PNG = ROOT / "docs" / "verification" / "refinement_drift.png"
SIZES = (1.0, 0.5, 0.25, 0.125)
FRACTIONS = (0.0, 0.1, 0.2, 0.5)
THETA, PHI = 30.0, 20.0
SAMPLE = 13  # steps between samples of the base's velocities (prime: no lock-in with a mode)


def incline(size: float, fraction: float, penalty_factor: float = 1.0, settled: bool = False,
            theta: float = THETA, phi: float = PHI, t_slide: float = 1.0) -> dict:
    """The block-on-incline scene of :func:`fdem.cases.block_on_incline.build` with the contact
    penalty scaled by ``penalty_factor``; slide after ``t_slide`` [s] against the rigid block,
    and the base's reversed-slip fraction and the block's vibration energy averaged over the slide."""
    from fdem.cases.block_on_incline import (CONTACT_PENALTY, YOUNG, incline_model, sliding_distance, unbreakable)
    from fdem.physics.contact import ContactSet
    from fdem.physics.cracks import CrackSet
    from fdem.solve.damping import Damping
    from fdem.solve.simulation import Simulation

    model, base_nodes, block = incline_model(theta, 2.0, 1.0, 1.0, size, 8.0, fraction)
    model.fix(base_nodes)
    cracks = CrackSet(model.topology, {0: unbreakable(YOUNG)})
    contact = ContactSet(model.topology, penalty_factor * CONTACT_PENALTY, friction_angle=phi,
                         mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=False)
    wall = time.perf_counter()
    if settled:  # gravity-loaded and at rest before the release: no ringing from a sudden load
        contact.set_friction(mu=10.0)
        sim.run(t_end=0.2, damping=Damping.quasi_static(0.8), history_every=10**9, energy_tolerance=None,
                final_output=False)
        contact.set_friction(friction_angle=phi)
        sim.state.v[block] = 0.0
    t0 = sim.state.time
    x0 = sim.state.x[block].copy()
    m = sim.state.mass[block] if np.ndim(sim.state.mass) == 1 else np.asarray(model.node_mass())[block]
    bottom = block[np.abs(x0[:, 1] - 0.5) < 1e-9]
    reversed_frac, vib = [], []
    while sim.state.time < t0 + t_slide - 0.5 * sim.dt:
        n = min(SAMPLE, max(1, int(round((t0 + t_slide - sim.state.time) / sim.dt))))
        sim.run(n_steps=n, history_every=10**9, energy_tolerance=None, final_output=False)
        v = sim.state.v
        reversed_frac.append(float(np.mean(v[bottom, 0] < 0.0)))
        vb, xb = v[block], sim.state.x[block]
        c = (m[:, None] * xb).sum(0) / m.sum()
        vc = (m[:, None] * vb).sum(0) / m.sum()
        r, dv = xb - c, vb - vc
        omega = (m * (r[:, 0] * dv[:, 1] - r[:, 1] * dv[:, 0])).sum() / (m * (r * r).sum(1)).sum()
        rigid = vc + omega * np.stack([-r[:, 1], r[:, 0]], axis=1)
        vib.append(0.5 * float((m[:, None] * (vb - rigid) ** 2).sum()))
    wall = time.perf_counter() - wall
    t = sim.state.time - t0
    slide = float((sim.state.x[block, 0] - x0[:, 0]).mean())
    exact = sliding_distance(theta, phi, t)
    weight = float(m.sum()) * 9.81
    return {"scene": "incline", "size_m": size, "element_damping": fraction, "penalty_factor": penalty_factor,
            "settled": settled, "theta_deg": theta, "phi_deg": phi, "t_s": t, "slide_m": slide, "exact_m": exact,
            "error": slide / exact - 1.0, "reversed_slip_fraction": float(np.mean(reversed_frac)),
            "reversed_slip_fraction_first_0.1s": float(np.mean(reversed_frac[:max(1, len(reversed_frac) // 10)])),
            "vibration_J_per_m": float(np.mean(vib)), "vibration_per_weight_m": float(np.mean(vib)) / weight,
            "n_block_triangles": int(len(block) // 3), "n_bottom_nodes": int(len(bottom)), "dt_s": sim.dt,
            "steps": sim.state.step, "wall_s": wall}


def newmark(size: float, fraction: float) -> dict:
    from fdem.cases import newmark_block as nb

    r = nb.run(size, element_damping=fraction)
    keep = {k: v for k, v in r.items() if not isinstance(v, list)}
    return {"scene": "newmark", "penalty_factor": 1.0, "settled": False, **keep}


def key(r: dict) -> tuple:
    return (r["scene"], r["size_m"], r["element_damping"], r.get("penalty_factor", 1.0), r.get("settled", False))


def load_rows() -> list[dict]:
    rows = []
    for p in sorted(RUNS.glob("*.json")):
        rows += json.loads(p.read_text())["runs"]
    return rows


def run_part(part: str, jobs: list[tuple]) -> None:
    path = RUNS / f"{part}.json"
    rows = json.loads(path.read_text())["runs"] if path.exists() else []
    done = {key(r) for r in load_rows()}
    for scene, size, fraction, penalty, settled in jobs:
        if (scene, size, fraction, penalty, settled) in done:
            continue
        r = newmark(size, fraction) if scene == "newmark" else incline(size, fraction, penalty, settled)
        r["load_average"] = os.getloadavg()
        r["threads"] = int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count()))
        rows.append(r)
        print(f"{scene} size {size:g} damping {fraction:g} penalty x{penalty:g}{' settled' if settled else ''}: "
              f"error {100 * r['error']:+.3f} %, wall {r['wall_s']:.0f} s, load {r['load_average'][0]:.1f}", flush=True)
        RUNS.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"runs": rows}, indent=1))


def report() -> None:
    rows = load_rows()
    recs = []
    print("| scene | size [m] | block tris | damping | penalty | settled | error [%] | reversed slip | "
          "vibration [J/m] | steps | wall [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in sorted(rows, key=lambda r: (r["scene"], r.get("penalty_factor", 1.0) != 1.0, r.get("settled", False),
                                         r["element_damping"], -r["size_m"])):
        rev = r.get("reversed_slip_fraction")
        vib = r.get("vibration_J_per_m")
        print(f"| {r['scene']} | {r['size_m']:g} | {r['n_block_triangles']} | {r['element_damping']:g} | "
              f"x{r.get('penalty_factor', 1.0):g} | {'yes' if r.get('settled') else 'no'} | {100 * r['error']:+.3f} | "
              f"{'' if rev is None else f'{rev:.4f}'} | {'' if vib is None else f'{vib:.3g}'} | {r['steps']} | "
              f"{r['wall_s']:.0f} |")
        extra = {k: v for k, v in r.items() if k not in ("error", "size_m", "threads")}
        recs.append(record(f"{r['scene']} error vs rigid block", r["error"], "relative",
                           mesh_size=None, threads=r.get("threads"), size_m=r["size_m"], **extra))
    save("refinement_drift", recs, description="slide error against element size and element damping "
         "(fraction of critical), block on incline 30/20 at 1 s and Newmark block; runs of "
         "cases/benchmarks/bench_refinement_drift.py", load_average_now=os.getloadavg())
    plot(rows, PNG)
    print(f"wrote {PNG}")


def plot(rows: list[dict], png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10.4, 4.2))
    titles = {"incline": f"block on incline, theta {THETA:g}, phi {PHI:g}: slide at 1 s",
              "newmark": "Newmark block: permanent slip"}
    for ax, scene in zip(axes, ("incline", "newmark")):
        mine = [r for r in rows if r["scene"] == scene and r.get("penalty_factor", 1.0) == 1.0
                and not r.get("settled")]
        for fraction in sorted({r["element_damping"] for r in mine}):
            pts = sorted((r["size_m"], 100 * r["error"]) for r in mine if r["element_damping"] == fraction)
            label = "undamped" if fraction == 0 else f"{fraction:g} of critical"
            style = dict(lw=2.5, color="k") if math.isclose(fraction, 0.1) else dict(lw=1.2)
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=label, **style)
        extra = [r for r in rows if r["scene"] == scene and (r.get("penalty_factor", 1.0) != 1.0 or r.get("settled"))]
        labelled = set()
        for r in extra:
            label = ("undamped, settled before release" if r.get("settled") else
                     f"{'undamped' if r['element_damping'] == 0 else r['element_damping']}, "
                     f"penalty x{r['penalty_factor']:g}")
            marker = "s" if r.get("settled") else ("^" if r["penalty_factor"] > 1 else "v")
            color = "C3" if r["element_damping"] == 0 else "0.3"
            ax.plot([r["size_m"]], [100 * r["error"]], marker, ms=7, color=color, mfc="none",
                    label=None if label in labelled else label)
            labelled.add(label)
        tol = 2.0 if scene == "incline" else 5.0
        ax.axhspan(-tol, tol, color="0.92", zorder=0, label=f"tolerance +-{tol:g} %")
        ax.axhline(0, color="0.5", lw=0.8)
        ax.set_yscale("symlog", linthresh=0.1)  # undamped Newmark reaches +140 %, damped runs 0.003-1 %
        ax.set_xscale("log", base=2)
        sizes = sorted({r["size_m"] for r in mine})
        ax.set_xticks(sizes, [f"{s:g}" for s in sizes])
        ax.invert_xaxis()
        ax.set_xlabel("element size [m] (block 1 m x 1 m)")
        ax.set_ylabel("error against the rigid block [%]")
        ax.set_title(titles[scene], fontsize=10)
        ax.legend(fontsize=7)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--part", default="main", help="name of this process's row file under runs/bench_refinement_drift/")
    parser.add_argument("--scene", choices=("incline", "newmark", "cause"), default=None)
    parser.add_argument("--sizes", type=float, nargs="*", default=None)
    parser.add_argument("--fractions", type=float, nargs="*", default=list(FRACTIONS))
    parser.add_argument("--cause-size", type=float, default=0.125, help="element size of the cause runs [m]")
    parser.add_argument("--penalty-factors", type=float, nargs="*", default=[0.25], help="cause runs: penalty scales")
    parser.add_argument("--report", action="store_true", help="merge the parts, print and save the table and plot")
    args = parser.parse_args(argv)
    if args.scene == "incline":
        run_part(args.part, [("incline", s, f, 1.0, False) for s in (args.sizes or SIZES) for f in args.fractions])
    elif args.scene == "newmark":
        run_part(args.part, [("newmark", s, f, 1.0, False) for s in (args.sizes or SIZES) for f in args.fractions])
    elif args.scene == "cause":
        run_part(args.part, [("incline", args.cause_size, 0.0, 1.0, True)]
                 + [("incline", args.cause_size, 0.0, k, False) for k in args.penalty_factors]
                 + [("incline", s, 0.1, k, False) for s in (0.5, 0.25) for k in (0.25, 4.0)])
    if args.report:
        report()


if __name__ == "__main__":
    main()
