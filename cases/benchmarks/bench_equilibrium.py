"""The slope workflow's equilibrium stage at F = 1, from the static start, at several mesh sizes.

Scene: the low-angle fine four-slope scene (``fdem run four-slopes --angle low --spacing fine``),
built as the case builds it (:func:`fdem.cases.four_slopes.build` and ``simulation``: static
start, crack elements, contact, density scaling within 1 % added mass). The stage is driven with
:func:`fdem.workflow.stages.run_stage` exactly as :func:`fdem.workflow.slope.run_slope_workflow`
does (F = 1, fail at 1 % of the height, capped at 5 response times), in two settings:

* ``before``: shear-beam damping ``4 pi / T`` (:func:`fdem.workflow.fos.fundamental_damping`) and
  the bare ratio limit 1e-4 (``Convergence(roundoff_factor=None)``), the stage as it was;
* ``after``: damping critical for the Rayleigh frequency of the static deflection
  (:func:`fdem.workflow.slope.equilibrium_damping`) and the limit raised to 10 times the
  round-off floor where that is above 1e-4 (``Convergence()``), the stage as it is.

Figures are load-independent: steps, simulated time, response times ``t / T``; the wall time is
printed for orientation only (the machine is shared). Per size and setting it records the steps
to converge, the ratio reached, the round-off floor
(:func:`fdem.solve.geostatic.unbalanced_ratio_floor`), the crack elements inelastic at the start
and at the end and the fracture energy booked, and prints the ratio's trajectory. A longer
``--tail`` after the stage measures the ratio at rest (the floor actually reached).

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_equilibrium.py                  # 1.0, 0.5, 0.35
    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_equilibrium.py --sizes 1.0 --settings after
    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_equilibrium.py --sizes 0.18 \
        --checkpoint runs/paper_low_fine/checkpoint.npz --name equilibrium_residual_180k   # where the residual sits

Writes docs/benchmarks/equilibrium.json (or ``--name``).
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from records import record, save  # noqa: E402

from fdem.cases.four_slopes import build, simulation  # noqa: E402
from fdem.solve.damping import Damping  # noqa: E402
from fdem.solve.geostatic import rayleigh_frequency, unbalanced_force_ratio, unbalanced_ratio_floor  # noqa: E402
from fdem.workflow.fos import fundamental_damping  # noqa: E402
from fdem.workflow.slope import equilibrium_damping  # noqa: E402
from fdem.workflow.stages import Convergence, Failure, Stage, response_time, run_stage  # noqa: E402


def run_one(size: float, setting: str, tail: float) -> list[dict]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # short joint segments dropped, thin triangles: the case's own warnings
        geometry, _, topo = build("low", "fine", size)
    sim, cracks = simulation(geometry, topo, None, pictures=False, progress=False)
    sim.add_monitor("unbalanced_ratio", unbalanced_force_ratio)
    sim.add_monitor("inelastic", lambda s: float(cracks.n_inelastic()))
    T = response_time(sim.model)
    height = float(np.ptp(topo.x0[:, 1]))
    cracks.hold_elastic(False)
    if setting == "before":
        damping, conv = fundamental_damping(sim), Convergence(unbalanced_ratio=1e-4, roundoff_factor=None)
    else:
        damping, conv = equilibrium_damping(sim), Convergence(unbalanced_ratio=1e-4)
    omega_r = rayleigh_frequency(sim.model)
    inelastic0 = int(cracks.n_inelastic())
    floor = unbalanced_ratio_floor(sim)
    stage = Stage("equilibrium", max_time=5.0 * T, reduction=1.0, damping=damping, converge=conv,
                  fail=Failure(displacement=0.01 * height))
    result = run_stage(sim, stage, frames=False)
    rows = list(sim.history)
    print(f"\nsize {size} ({topo.n_triangles} triangles), {setting}: {result.reason} in {result.steps} steps "
          f"of {result.dt:.4g} s, t = {result.t_end:.4g} s = {result.t_end / T:.3g} T; ratio {result.unbalanced_ratio:.3g}"
          f" (floor {floor:.3g}); alpha {damping.mass_proportional:.4g} 1/s; wall {result.wall_seconds:.0f} s")
    for row in rows[:: max(1, len(rows) // 12)] + rows[-1:]:
        print(f"   step {row['step']:>7d}  t {row['time']:.4f} s  R {row['unbalanced_ratio']:.3e}  "
              f"kinetic {row['kinetic']:.3e} J/m  fracture {row['fracture']:.4g} J/m  inelastic {row['inelastic']:.0f}")
    common = dict(mesh_size=int(topo.n_triangles), threads=numba.get_num_threads(), setting=setting, element_size_m=size)
    recs = [
        record("equilibrium stage steps", float(result.steps), "steps", reason=result.reason, **common),
        record("equilibrium stage simulated time", float(result.t_end - result.t_start), "s", **common),
        record("equilibrium stage response times", float((result.t_end - result.t_start) / T), "T", **common),
        record("equilibrium stage time step", float(result.dt), "s", **common),
        record("equilibrium stage damping alpha", float(damping.mass_proportional), "1/s", **common),
        record("unbalanced ratio at the end", float(result.unbalanced_ratio), "-", **common),
        record("unbalanced ratio round-off floor (estimate)", float(floor), "-", **common),
        record("Rayleigh frequency of the static deflection", float(omega_r), "rad/s",
               shear_beam_rad_s=float(2 * np.pi / T), **common),
        record("inelastic crack elements at the start", float(inelastic0), "elements", **common),
        record("inelastic crack elements at the end", float(rows[-1]["inelastic"]), "elements", **common),
        record("fracture energy booked", float(rows[-1]["fracture"]), "J/m", **common),
        record("equilibrium stage wall time (shared machine)", float(result.wall_seconds), "s", **common),
    ]
    if tail > 0:  # the ratio at rest: keep the stage's damping on, far past convergence
        sim.run(t_end=sim.state.time + tail * T, damping=damping, history_every=max(1, int(round(T / 40 / sim.dt))), output_every=2 ** 62, final_output=False, stage="tail")
        at_rest = float(np.median([r["unbalanced_ratio"] for r in sim.history[-10:]]))
        print(f"   at rest after {tail:g} T more: ratio {at_rest:.3g} = {at_rest / floor:.2g} times the floor estimate")
        recs.append(record("unbalanced ratio at rest", at_rest, "-", floor_multiple=at_rest / floor, **common))
    return recs


def residual_map(size: float, checkpoint: str, steps: int) -> list[dict]:
    """Where the unbalanced force of a saved state sits: the scene at ``size`` with the state of
    ``checkpoint``, its ratio, its round-off floor estimate, and the share of the summed nodal
    residual that each kind of node carries against its share of the nodes; then ``steps`` more
    steps under the equilibrium damping, to see whether the ratio still moves."""
    from fdem.solve.checkpoint import load_checkpoint
    from fdem.solve.geostatic import unbalanced_forces

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geometry, _, topo = build("low", "fine", size)
    sim, cracks = simulation(geometry, topo, None, pictures=False, progress=False)
    load_checkpoint(sim, checkpoint)
    common = dict(mesh_size=int(topo.n_triangles), threads=numba.get_num_threads(), element_size_m=size, checkpoint=str(checkpoint),
                  step=int(sim.state.step))
    ratio, floor = unbalanced_force_ratio(sim), unbalanced_ratio_floor(sim)
    f = np.linalg.norm(unbalanced_forces(sim), axis=1)
    n, total = len(f), float(f.sum())
    print(f"{checkpoint}: step {sim.state.step}, t {sim.state.time:.4g} s, ratio {ratio:.4g}, floor estimate {floor:.3g}")
    recs = [record("unbalanced ratio of the saved state", ratio, "-", **common),
            record("unbalanced ratio round-off floor (estimate)", floor, "-", **common)]
    ranked = np.sort(f)[::-1]
    groups = {f"top {q:g} % of nodes by residual": np.arange(max(1, int(n * q / 100))) for q in (0.1, 1.0, 10.0)}
    cn = topo.crack_nodes
    groups["nodes of inelastic crack elements"] = np.unique(cn[cracks.inelastic()].ravel())
    groups["nodes of joint crack elements"] = np.unique(cn[topo.crack_tag > 0].ravel())
    if sim.inertia is not None:
        groups["density-scaled nodes"] = np.flatnonzero(sim.inertia > 1.0001 * sim.state.mass)
    near_support = np.unique(np.flatnonzero(sim.flags != 0) // 3)
    groups["nodes of triangles with a supported node"] = (3 * near_support[:, None] + np.arange(3)).ravel()
    if sim.contact is not None and len(sim.contact.active):
        watched = np.asarray(sim.contact.active)
        groups["nodes of triangles contact watches"] = (3 * watched[:, None] + np.arange(3)).ravel()
    for name, idx in groups.items():
        share = float((ranked[idx] if name.startswith("top") else f[idx]).sum() / total)
        print(f"   {name}: {idx.size / n:.2%} of the nodes carry {share:.2%} of the summed residual")
        recs.append(record(f"share of the summed nodal residual: {name}", share, "-", node_share=idx.size / n,
                           **common))
    if steps > 0:
        sim.add_monitor("unbalanced_ratio", unbalanced_force_ratio)
        sim.run(n_steps=steps, damping=equilibrium_damping(sim), history_every=max(1, steps // 6),
                output_every=2 ** 62, final_output=False, stage="probe")
        later = [r["unbalanced_ratio"] for r in sim.history[-7:]]
        print(f"   {steps} more steps: ratio {min(later):.4g} .. {max(later):.4g}, kinetic "
              f"{sim.history[-1]['kinetic']:.3g} J/m")
        recs.append(record(f"unbalanced ratio over {steps} more steps (max)", float(max(later)), "-", **common))
    return recs


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=float, nargs="+", default=[1.0, 0.5, 0.35], help="element sizes [m]")
    parser.add_argument("--settings", nargs="+", choices=["before", "after"], default=["before", "after"])
    parser.add_argument("--tail", type=float, default=0.0,
                        help="response times to run on after the stage, to measure the ratio at rest")
    parser.add_argument("--name", default="equilibrium", help="record file name under docs/benchmarks/")
    parser.add_argument("--checkpoint", default=None,
                        help="map the residual of this saved state (of the scene at the one --sizes value) instead")
    parser.add_argument("--probe-steps", type=int, default=600, help="steps run on from --checkpoint")
    args = parser.parse_args(argv)
    records = []
    t0 = time.perf_counter()
    if args.checkpoint is not None:
        if len(args.sizes) != 1:
            parser.error("--checkpoint needs exactly one --sizes value: the element size the checkpoint was run at")
        records = residual_map(args.sizes[0], args.checkpoint, args.probe_steps)
        save(args.name, records, checkpoint=args.checkpoint, wall_seconds=time.perf_counter() - t0)
        return
    for size in args.sizes:
        for setting in args.settings:
            records += run_one(size, setting, args.tail)
    save(args.name, records, sizes=args.sizes, settings=args.settings, wall_seconds=time.perf_counter() - t0)


if __name__ == "__main__":
    main()
