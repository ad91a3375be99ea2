"""Does the runout's time-step factor bias the runout distance beyond its chaotic spread?

The demo slope's runout (the workflow's runout stage: undamped, to rest or its cap) is run
from the same failed state (``runs/bench_sleeping/demo_None/runout_start.npz``, made by
``bench_sleeping.py``) at time-step factors 0.4 and 0.8, each from velocities nudged by
``--kick`` m/s (normal, seeded). The nudge measures the spread a chaotic runout has anyway:
1e-6 m/s barely diverges within a runout and understated it (``docs/benchmarks.md``, region
sleeping), 1e-3 m/s is the size of the perturbations a change of step makes. A factor whose
mean lies outside the other's spread (difference of the means against its standard error)
biases the answer; one inside it gives the same answer for half the steps.

Prints and saves ``docs/benchmarks/runout_step.json`` (distance, broken elements, peak kinetic
energy, steps, wall time, ledger balance per run; machine, threads, load).

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_runout_step.py --seeds 6
    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_runout_step.py --scene four-slopes --size 1.0 --max-time 2 --seeds 4 \
        --runs-file docs/benchmarks/runout_step_four_slopes_runs.jsonl
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_sleeping import build, failed_state  # noqa: E402
from records import record, save  # noqa: E402


def runout(scene: str, size: float | None, start: Path, fraction: float, seed: int, kick: float,
           max_time: float | None = None) -> dict:
    from fdem.results.analysis import runout as runout_figures
    from fdem.solve.checkpoint import read_checkpoint
    from fdem.workflow.slope import SlopeWorkflow, runout_stage
    from fdem.workflow.stages import response_time, run_stage

    sim, toe_x = build(scene, size)
    # not load_checkpoint: the failed state was saved at F > 1, whose reduced contact friction
    # the model fingerprint would read as another model
    sim.load_state_dict(read_checkpoint(start)["state"])
    sim.state.v += kick * np.random.default_rng(seed).standard_normal(sim.state.v.shape)
    topo = sim.model.topology
    broken0, step0, n_hist = int(sim.cracks.broken.sum()), sim.state.step, len(sim.history)
    stage = runout_stage(SlopeWorkflow(runout_dt_fraction=fraction, runout_time=max_time), response_time(sim.model),
                         float(np.ptp(topo.x0[:, 1])), float(np.linalg.norm(sim.gravity)))
    load = os.getloadavg()[0]
    wall = time.perf_counter()
    res = run_stage(sim, stage, frames=False)
    wall = time.perf_counter() - wall
    rows = sim.history[n_hist:]
    fig = runout_figures(topo, sim.state.x, toe_x)
    out = {"dt_fraction": fraction, "seed": seed, "kick_m_s": kick, "reason": res.reason,
           "steps": sim.state.step - step0, "wall_s": wall, "runout_distance_m": fig["runout_distance_m"],
           "broken_in_runout": int(sim.cracks.broken.sum()) - broken0,
           "kinetic_peak_J_m": max(float(r["kinetic_peak"]) for r in rows),
           "balance_error_relative": float(rows[-1]["balance_error_relative"]), "n_triangles": topo.n_triangles,
           "load_start": load, "load_end": os.getloadavg()[0]}
    sim.close()
    return out


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--kick", type=float, default=1e-3, help="nudge [m/s] (default 1e-3)")
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.4, 0.8])
    parser.add_argument("--scene", choices=("demo", "four-slopes"), default="demo")
    parser.add_argument("--size", type=float, default=None, help="element size [m] (default: the scene's)")
    parser.add_argument("--max-time", type=float, default=None, help="cap on the runout [s] (default the stage's)")
    parser.add_argument("--runs-file", type=Path, default=None,
                        help="JSON-lines file: each run is appended as it ends, and runs already there "
                             "(same scene, size, cap, fraction, seed and nudge) are read back, not rerun")
    args = parser.parse_args(argv)
    threads = int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1))
    start, meta = failed_state(args.scene, args.size)
    runs = []
    done = {}
    key = lambda r: (r["scene"], r["size"], r["max_time"], r["dt_fraction"], r["seed"], r["kick_m_s"])  # noqa: E731
    if args.runs_file is not None and args.runs_file.exists():
        for line in args.runs_file.read_text().splitlines():
            r = json.loads(line)
            done[key(r)] = r
    for seed in range(args.seeds):  # interleaved, so that a change of load falls on both
        for f in args.fractions:
            tag = {"scene": args.scene, "size": args.size, "max_time": args.max_time}
            r = done.get(key({**tag, "dt_fraction": f, "seed": seed, "kick_m_s": args.kick}))
            if r is None:
                r = {**tag, **runout(args.scene, args.size, start, f, seed, args.kick, args.max_time)}
                if args.runs_file is not None:  # an hours-long comparison keeps every finished run
                    with args.runs_file.open("a") as fh:
                        fh.write(json.dumps(r) + "\n")
            runs.append(r)
            print(f"dt_fraction {f}: seed {seed}: {r['runout_distance_m']:.2f} m, {r['broken_in_runout']} broken, "
                  f"{r['steps']} steps, {r['wall_s']:.0f} s ({r['reason']})", flush=True)
    summary = {}
    for f in args.fractions:
        d = np.array([r["runout_distance_m"] for r in runs if r["dt_fraction"] == f])
        summary[f] = {"mean": float(d.mean()), "std": float(d.std(ddof=1)) if d.size > 1 else None,
                      "min": float(d.min()), "max": float(d.max()), "n": int(d.size)}
        print(f"dt_fraction {f}: runout {d.mean():.2f} +- {summary[f]['std'] or 0:.2f} m "
              f"({d.min():.2f}-{d.max():.2f}, {d.size} runs)")
    if len(args.fractions) == 2 and args.seeds > 1:
        a, b = (summary[f] for f in args.fractions)
        se = float(np.hypot(a["std"], b["std"]) / np.sqrt(args.seeds))
        summary["difference_over_standard_error"] = (b["mean"] - a["mean"]) / se
        print(f"difference of the means {b['mean'] - a['mean']:+.2f} m = "
              f"{summary['difference_over_standard_error']:.2f} standard errors")
    records = [record(f"{args.scene} runout at dt_fraction {f}: mean distance", s["mean"], "m", runs[0]["n_triangles"],
                      threads) for f, s in summary.items() if isinstance(s, dict)]
    label = "runout_step" if args.scene == "demo" else f"runout_step_{args.scene}_{args.size}"
    save(label, records, scene=args.scene, size=args.size, max_time=args.max_time, runs=runs, summary={str(k): v for k, v in summary.items()}, threads=threads,
         kick_m_s=args.kick, **meta)
    return summary


if __name__ == "__main__":
    main()
