"""The quasi-static stages of the four-slope model with and without density scaling: steps, step, wall time.

Builds the four-slope scene (``fdem/cases/four_slopes.py``: static geostatic start, crack
elements, contact) at ``--size`` and runs the workflow's own quasi-static stages on it: the
``F = 1`` equilibrium stage (fundamental-mode damping, unbalanced-force ratio 1e-4, capped at 5
response times) and, with ``--reductions``, damped 10 % reduction steps ``F = 1/0.9, 1/0.8, ...``
until one fails (the factor-of-safety bracket of the default workflow). Each ``--budget`` is
one run from a fresh scene: 0 runs on the real masses, 0.01 is the default density scaling
(:mod:`fdem.solve.density_scaling`).

Prints and saves (``docs/benchmarks/quasi_static_<label>.json``) for every stage its outcome,
steps, time step, simulated time, wall time and unbalanced-force ratio, with the build time,
peak resident memory, thread count, machine and load average.

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_quasi_static.py --size 0.5 --budget 0 0.01
    NUMBA_NUM_THREADS=2 python cases/benchmarks/bench_quasi_static.py --size 0.18 --budget 0.01 --reductions
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
sys.path.insert(0, str(Path(__file__).resolve().parent))

from records import record, save  # noqa: E402


def run(size: float, budget: float, angle: str, spacing: str, reductions: bool, threads: int) -> dict:
    import numpy as np

    from fdem.cases import four_slopes as fs
    from fdem.workflow.fos import fundamental_damping
    from fdem.workflow.slope import SlopeWorkflow
    from fdem.workflow.stages import Convergence, Failure, Stage, response_time, run_stage

    t0 = time.perf_counter()
    geometry, _, topo = fs.build(angle, spacing, size)
    sim, cracks = fs.simulation(geometry, topo, None, pictures=False, progress=True)
    sim.density_scaling = budget or None
    build_s = time.perf_counter() - t0
    T = response_time(sim.model)
    height = float(np.ptp(topo.x0[:, 1]))
    wf = SlopeWorkflow()
    stage_time = wf.step_time or 5.0 * T
    fail = Failure(displacement=wf.fail_displacement or 0.01 * height)
    damped = fundamental_damping(sim)
    plan = [("equilibrium", 1.0)] + ([(f"reduction_F{F:.3f}", F) for F in wf.factors] if reductions else [])
    stages = []
    for name, F in plan:
        r = run_stage(sim, Stage(name, max_time=stage_time, reduction=F, damping=damped, fail=fail,
                                 converge=Convergence(unbalanced_ratio=wf.equilibrium_ratio)), frames=False)
        stages.append({"stage": name, "reduction": F, "reason": r.reason, "steps": r.steps, "dt_s": r.dt,
                       "simulated_s": r.t_end - r.t_start, "wall_s": r.wall_seconds,
                       "ms_per_step": 1e3 * r.wall_seconds / max(r.steps, 1), "unbalanced_ratio": r.unbalanced_ratio,
                       "period_stretch": r.period_stretch, "n_broken": r.n_broken,
                       "inelastic": int(cracks.n_inelastic())})
        print(f"  {name}: {r.reason} in {r.steps} steps of {r.dt:.3g} s, {r.wall_seconds:.1f} s wall "
              f"({1e3 * r.wall_seconds / max(r.steps, 1):.2f} ms/step), ratio {r.unbalanced_ratio:.2g}", flush=True)
        if r.reason != "converged":
            break
    return {"size": size, "budget": budget, "n_triangles": topo.n_triangles, "n_cracks": topo.n_cracks,
            "threads": threads, "build_s": build_s, "response_time_s": T, "stages": stages,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "load_average": os.getloadavg()}


def step_limits(size: float, angle: str, spacing: str) -> list[dict]:
    """The critical step the solver combines on the real masses, and the density-scaled critical
    step at several added-mass budgets (no stepping: the scene is only built)."""
    from fdem.cases import four_slopes as fs
    from fdem.solve import density_scaling as ds

    geometry, _, topo = fs.build(angle, spacing, size)
    sim, _ = fs.simulation(geometry, topo, None, pictures=False, progress=False)
    combined, limits = sim.critical_dt()
    mass = sim.state.mass
    stiffness = ds.nodal_stiffness(sim.model, sim.providers, mass)
    print(f"{topo.n_triangles} triangles; combined global bound {combined * 1e6:.3f} us "
          f"({', '.join(f'{k} {v * 1e6:.3g} us' for k, v in limits.items())})")
    rows = []
    for budget in (0.0, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05):
        dt = ds.scaled_critical_step(mass, stiffness, budget)
        rows.append(record(f"density-scaled critical step, budget {budget}", dt * 1e6, "us",
                           mesh_size=topo.n_triangles, budget=budget, gain=dt / combined,
                           combined_bound_us=combined * 1e6))
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=float, default=0.5, help="element size [m] (0.18: 179,205 triangles)")
    parser.add_argument("--budget", type=float, nargs="+", default=[0.0, 0.01],
                        help="added-mass budgets to compare (0: real masses)")
    parser.add_argument("--angle", default="low", choices=["low", "high"])
    parser.add_argument("--spacing", default="fine")
    parser.add_argument("--reductions", action="store_true", help="also the damped 10 %% reduction steps")
    parser.add_argument("--label", default=None)
    parser.add_argument("--limits-only", action="store_true",
                        help="only the critical steps at several budgets (builds the scene, no stepping)")
    args = parser.parse_args(argv)
    if args.limits_only:
        label = args.label or f"{args.angle}_{args.spacing}_{args.size:g}"
        save(f"step_limits_{label}", step_limits(args.size, args.angle, args.spacing),
             command=" ".join(["python", *sys.argv]))
        return
    import numba

    threads = numba.get_num_threads()
    runs = []
    for budget in args.budget:
        print(f"size {args.size}, density-scaling budget {budget}, {threads} thread(s), load {os.getloadavg()}")
        runs.append(run(args.size, budget, args.angle, args.spacing, args.reductions, threads))
    records = []
    for r in runs:
        for st in r["stages"]:
            records.append(record(f"{st['stage']} ({st['reason']}), budget {r['budget']}", st["wall_s"], "s",
                                  mesh_size=r["n_triangles"], threads=r["threads"], **st))
    label = args.label or f"{args.angle}_{args.spacing}_{args.size:g}"
    save(f"quasi_static_{label}", records, runs=runs, command=" ".join(["python", *sys.argv]))


if __name__ == "__main__":
    main()
