"""Region sleeping (:mod:`fdem.solve.sleeping`) against none: a slope's runout to rest both ways.

For each scene, the workflow is run once (sleeping off) to its failed state, which it saves
before the runout (``runs/bench_sleeping/<scene>/runout_start.npz``); the runout stage of the
workflow (:func:`fdem.workflow.slope.runout_stage`: undamped, time-step factor 0.4, to rest or
its cap) is then run from that state in a freshly built simulation with sleeping off and with
the default :class:`~fdem.solve.sleeping.SleepPolicy` (or the one of the options), and with ``--seeds`` runs without sleeping
whose velocities are first nudged by ``--kick`` (default 1e-6 m/s; the chaotic spread, as ``docs/pareto.md``).
``--whole`` also runs the whole workflow (equilibrium, reduction steps, runout) with sleeping on
from the start.

Prints and saves (``docs/benchmarks/sleeping_<scene>.json``) for every run: steps, simulated
time, wall time, ms per step, triangle-steps taken against all, the fraction asleep at each
history row (time series), the runout distance, broken elements, the ledger's balance error
and the energy sleeping removed; with thread count, machine and load average.

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_sleeping.py --scene demo
    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_sleeping.py --scene four-slopes --size 1.0 --max-time 2
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
sys.path.insert(0, str(Path(__file__).resolve().parent))

from records import record, save  # noqa: E402

RUNS = ROOT / "runs" / "bench_sleeping"


def build(scene: str, size: float | None):
    """``(sim, toe_x)`` of a freshly built scene, in static equilibrium, sleeping off."""
    from fdem.geometry.polygons import slope_toe

    if scene == "demo":
        from fdem.cases import quick_start

        geo, sim, _, _ = quick_start.build(size or quick_start.SIZE, None, progress=False)
        return sim, slope_toe(geo.bodies[0])[0]
    from fdem.cases import four_slopes as fs

    geometry, _, topo = fs.build("low", "fine", size or 1.0)
    sim, _ = fs.simulation(geometry, topo, None, pictures=False, progress=False)
    return sim, slope_toe(geometry.bodies[0])[0]


def failed_state(scene: str, size: float | None) -> tuple[Path, dict]:
    """The failed state the runout starts from (made once per scene and size) and the workflow's figures."""
    from fdem.workflow.slope import SlopeWorkflow, run_slope_workflow

    out = RUNS / f"{scene}_{size}"
    path = out / "runout_start.npz"
    if path.exists():
        return path, {}
    out.mkdir(parents=True, exist_ok=True)
    sim, _ = build(scene, size)
    t0 = time.perf_counter()
    result = run_slope_workflow(sim, SlopeWorkflow(runout_time=1e-3), out_dir=out)
    sim.close()
    if not path.exists():
        raise RuntimeError(f"{scene} did not fail (outcome {result['outcome']!r}): no runout to compare")
    return path, {"workflow_to_failure_s": time.perf_counter() - t0, "outcome": result["outcome"]}


def runout(scene: str, size: float | None, start: Path, sleeping, seed: int | None,
           max_time: float | None, kick: float = 1e-6) -> dict:
    """The workflow's runout stage from ``start``, sleeping off (``None``) or with the policy
    ``sleeping``; its figures."""
    from fdem.results.analysis import runout as runout_figures
    from fdem.solve.checkpoint import mesh_fingerprint, read_checkpoint
    from fdem.workflow.slope import SlopeWorkflow, runout_stage
    from fdem.workflow.stages import response_time, run_stage

    sim, toe_x = build(scene, size)
    saved = read_checkpoint(start)
    if saved.get("mesh") != mesh_fingerprint(sim):
        raise ValueError(f"{start} belongs to another mesh: delete it to make it again")
    # not load_checkpoint: its model fingerprint takes the failed state's reduced contact
    # friction for another model (the failed state was saved at F > 1)
    sim.load_state_dict(saved["state"])
    sim.set_sleeping(sleeping)
    if seed is not None:
        sim.state.v += kick * np.random.default_rng(seed).standard_normal(sim.state.v.shape)
    topo = sim.model.topology
    broken0 = int(sim.cracks.broken.sum())
    step0, t_start, n_hist = sim.state.step, sim.state.time, len(sim.history)
    stage = runout_stage(SlopeWorkflow(runout_time=max_time), response_time(sim.model),
                         float(np.ptp(topo.x0[:, 1])), float(np.linalg.norm(sim.gravity)))
    load = os.getloadavg()[0]
    wall = time.perf_counter()
    res = run_stage(sim, stage, frames=False)
    wall = time.perf_counter() - wall
    steps = sim.state.step - step0
    rows = sim.history[n_hist:]
    fig = runout_figures(topo, sim.state.x, toe_x)
    stepped = sim.sleeping.stepped if sim.sleeping is not None else steps * topo.n_triangles
    out = {"scene": scene, "size": size, "sleeping": sleeping is not None,
           "policy": None if sleeping is None else {k: getattr(sleeping, k) for k in sleeping.__dataclass_fields__},
           "quiet_time_s": None if sim.sleeping is None else sim.sleeping.quiet_time,
           "delta_m": None if sim.sleeping is None else sim.sleeping.delta, "seed": seed, "kick_m_s": kick if seed is not None else 0.0, "reason": res.reason,
           "n_triangles": topo.n_triangles, "steps": steps, "simulated_s": sim.state.time - t_start,
           "wall_s": wall, "ms_per_step": 1e3 * wall / max(steps, 1),
           "stepped_fraction": stepped / max(steps * topo.n_triangles, 1),
           "runout_distance_m": fig["runout_distance_m"], "displaced_area_m2": fig["displaced_area_m2"],
           "broken_in_runout": int(sim.cracks.broken.sum()) - broken0,
           "balance_error_relative": float(rows[-1]["balance_error_relative"]),
           "max_abs_balance_error_relative": max(abs(float(r["balance_error_relative"])) for r in rows),
           "sleep_dissipation_J_m": float(rows[-1].get("sleep_dissipation", 0.0)),
           "kinetic_peak_J_m": max(float(r["kinetic_peak"]) for r in rows),
           "asleep_fraction": [[round(float(r["time"]) - t_start, 5), round(float(r.get("asleep_fraction", 0.0)), 4)]
                               for r in rows],
           "load_start": load, "load_end": os.getloadavg()[0]}
    sim.close()
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", choices=("demo", "four-slopes"), default="demo")
    parser.add_argument("--size", type=float, default=None, help="element size [m] (default: the scene's)")
    parser.add_argument("--seeds", type=int, default=0, help="runs without sleeping, velocities nudged by 1e-6 m/s: the chaotic spread")
    parser.add_argument("--kick", type=float, default=1e-6, help="nudge of the --seeds runs [m/s] (default 1e-6)")
    parser.add_argument("--max-time", type=float, default=None, help="cap on the runout's simulated time [s]")
    parser.add_argument("--acceleration-ratio", type=float, default=None,
                        help="SleepPolicy.acceleration_ratio (default the policy's)")
    parser.add_argument("--wake-ratio", type=float, default=None,
                        help="SleepPolicy.wake_ratio (default the policy's)")
    parser.add_argument("--quiet-periods", type=float, default=None,
                        help="SleepPolicy.quiet_time in response times T (default the policy's, 1)")
    parser.add_argument("--label", default=None)
    args = parser.parse_args(argv)
    threads = int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1))
    from fdem.solve.sleeping import SleepPolicy
    from fdem.workflow.stages import response_time

    start, meta = failed_state(args.scene, args.size)
    policy = {}
    if args.acceleration_ratio is not None:
        policy["acceleration_ratio"] = args.acceleration_ratio
    if args.wake_ratio is not None:
        policy["wake_ratio"] = args.wake_ratio
    if args.quiet_periods is not None:
        policy["quiet_time"] = args.quiet_periods * response_time(build(args.scene, args.size)[0].model)
    policy = SleepPolicy(**policy)
    runs = [runout(args.scene, args.size, start, None, None, args.max_time),
            runout(args.scene, args.size, start, policy, None, args.max_time)]
    runs += [runout(args.scene, args.size, start, None, k, args.max_time, args.kick) for k in range(args.seeds)]
    records = []
    for r in runs:
        tag = f"{args.scene} runout, sleeping {'on' if r['sleeping'] else 'off'}" + (
            f", seed {r['seed']}" if r["seed"] is not None else "")
        n = r["n_triangles"]
        records += [record(f"{tag}: steps", r["steps"], "steps", n, threads),
                    record(f"{tag}: wall time", r["wall_s"], "s", n, threads, load=[r["load_start"], r["load_end"]]),
                    record(f"{tag}: ms per step", r["ms_per_step"], "ms", n, threads),
                    record(f"{tag}: triangle-steps taken / all", r["stepped_fraction"], "-", n, threads),
                    record(f"{tag}: runout distance", r["runout_distance_m"], "m", n, threads),
                    record(f"{tag}: broken in runout", r["broken_in_runout"], "elements", n, threads),
                    record(f"{tag}: ledger balance error (end)", r["balance_error_relative"], "-", n, threads),
                    record(f"{tag}: energy removed by sleeping", r["sleep_dissipation_J_m"], "J/m", n, threads)]
    save(f"sleeping_{args.label or args.scene}", records, runs=runs, threads=threads, **meta)


if __name__ == "__main__":
    main()
