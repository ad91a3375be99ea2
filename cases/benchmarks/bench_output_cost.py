"""What output costs a paper-scale run: frames, history rows and checkpoints against the steps.

Scene: the low-angle fine four-slope scene at ``--size`` (0.18: the paper's 179,205 triangles),
built as ``fdem run four-slopes`` builds it, with the run's report monitors
(:class:`fdem.results.report.RunReport`: cracks by mode, inelastic count, fragments, the motion
record) and the workflow's unbalanced-force monitor, writing into a scratch folder. Timed, best of
``--repeats``: a plain damped step, a step with its history row (ledger, monitors, ``history.csv``),
one output frame (triangles, cracks and contact ``.vtu``), one checkpoint. The share of the wall
time then follows from the workflow's cadence, which is set in simulated time:

* a history row every check, ``T / 40`` of simulated time (``T`` the response time), i.e. every
  ``T / 40 / dt`` steps at the stage's step;
* four frames per stage; a stage of ``n`` steps (the 180k equilibrium stage: 40,021 steps; a
  failing stage capped at 5 T: about 275,000);
* a checkpoint every ``--checkpoint-every`` seconds of wall time (600, the default of the cases),
  plus one per stage end.

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_output_cost.py --size 0.18

Prints the per-item costs and the share for a short and a long stage; writes
``docs/benchmarks/output_cost.json``. The goal of the paper-scale issue: output under 5 % of
the run's wall time.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from records import record, save  # noqa: E402


def best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=float, default=0.18)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--steps", type=int, default=50, help="steps per timing of the plain step")
    parser.add_argument("--checkpoint-every", type=float, default=600.0)
    parser.add_argument("--stage-steps", type=int, nargs="+", default=[40_021, 275_000])
    args = parser.parse_args(argv)

    from fdem.cases import four_slopes
    from fdem.geometry.polygons import slope_toe
    from fdem.results.report import RunReport
    from fdem.solve.checkpoint import save_checkpoint
    from fdem.solve.geostatic import unbalanced_force_ratio
    from fdem.workflow.fos import fundamental_damping
    from fdem.workflow.stages import response_time

    scratch = Path(tempfile.mkdtemp(prefix="fdem_output_cost_"))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            geometry, _, topo = four_slopes.build("low", "fine", args.size)
            sim, cracks = four_slopes.simulation(geometry, topo, scratch, pictures=False, progress=False)
        toe_x, toe_y = slope_toe(geometry.bodies[0])
        RunReport(sim, toe_x=toe_x, floor_y=toe_y)
        sim.add_monitor("unbalanced_ratio", unbalanced_force_ratio)
        damping = fundamental_damping(sim)
        sim.set_density_scaling(True)  # the quasi-static stages' step
        sim.dt = sim._choose_dt()
        T = response_time(sim.model)
        for _ in range(10):  # warm-up
            sim.step(damping)

        def plain():
            for _ in range(args.steps):
                sim.step(damping)

        step_s = best(plain, args.repeats) / args.steps
        # a history row: a step with the ledger books its row (ledger, monitors, history.csv) itself
        row_s = best(lambda: sim.step(damping, ledger=True), args.repeats) - step_s
        frame_s = best(sim.write_output, args.repeats)
        ckpt_s = best(lambda: save_checkpoint(sim, scratch / "checkpoint.npz"), args.repeats)
        steps_per_row = max(1, round(T / 40.0 * sim.period_stretch / sim.dt))
        rows = {}
        for n in args.stage_steps:
            compute = n * step_s
            history = n / steps_per_row * row_s
            frames = 4 * frame_s
            checkpoints = (compute / args.checkpoint_every + 1) * ckpt_s
            total = compute + history + frames + checkpoints
            rows[n] = {"steps": n, "compute_s": compute, "history_s": history, "frames_s": frames,
                       "checkpoints_s": checkpoints, "output_share": (history + frames + checkpoints) / total}
        n_tri = topo.n_triangles
        print(f"{n_tri} triangles, dt {sim.dt:.3g} s (density-scaled), T {T:.3g} s: a row every {steps_per_row} steps")
        print(f"step {1e3 * step_s:.2f} ms; history row {1e3 * row_s:.1f} ms; frame {frame_s:.2f} s; "
              f"checkpoint {ckpt_s:.2f} s ({(scratch / 'checkpoint.npz').stat().st_size / 1e6:.0f} MB)")
        for r in rows.values():
            print(f"stage of {r['steps']} steps: compute {r['compute_s']:.0f} s, history {r['history_s']:.1f} s, "
                  f"frames {r['frames_s']:.1f} s, checkpoints {r['checkpoints_s']:.1f} s: "
                  f"output {100 * r['output_share']:.2f} % of the wall time")
        threads = int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1))
        records = [record("plain damped step", 1e3 * step_s, "ms", n_tri, threads),
                   record("history row (ledger, monitors, csv) beyond its step", 1e3 * row_s, "ms", n_tri, threads),
                   record("output frame (triangles, cracks, contact)", frame_s, "s", n_tri, threads),
                   record("checkpoint", ckpt_s, "s", n_tri, threads)]
        records += [record(f"output share of a stage of {r['steps']} steps", 100 * r["output_share"], "%", n_tri,
                           threads) for r in rows.values()]
        save("output_cost", records, size=args.size, steps_per_row=steps_per_row, dt=sim.dt, response_time=T,
             stages=list(rows.values()), load_end=os.getloadavg()[0])
        sim.close()
        return rows
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
