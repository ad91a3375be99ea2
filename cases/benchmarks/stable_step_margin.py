"""How far below the model's true critical step does the solver step?

The solver's critical step combines bounds (the triangles' exact element limit, a Gershgorin
bound on the crack springs, a face-to-face bound on contact) and takes ``dt_fraction`` of it.
This script measures the true limit, ``2 / omega_max`` of the linearized model, at the states a
four-slope run passes through (:func:`fdem.solve.step_probe.measured_critical_dt`):

- ``--scene ANGLE:SPACING --size S``: the scene at its start (static equilibrium, every crack
  element intact, nothing in contact);
- ``--run DIR``: a four-slope run's checkpoint (its model rebuilt from ``run.json``), e.g. a
  failure in progress or a debris pile at rest.

``--runout-check SECONDS`` (with ``--run``) then runs the workflow's runout stage from the run's
``runout_start.npz`` for that long at ``--measured-fraction`` (0.8) of the critical step measured
there, held fixed (an experiment: the solver does not step so), and sets its energy ledger,
kinetic energy, breakage and displacement beside the run's own history over the same span
(``--with-control`` reruns that at the solver's step too, with the code of now).

``--at-rest RUN RUN ...`` reads runs already made to rest (a run's folder, or a summary published
in ``docs/cases/rest/``), one stepping its runout from the measured step beside others at the
bound, and sets their figures at rest side by side: the runout's steps and step, and what the
slope did.

``--tangential`` measures once more with the contact's tangential springs in, which the probe
leaves out (they load on slip increments: ``v = u / dt`` as well as ``x + u``, contact damping
off, no other force on velocities in a four-slope runout; power iteration, as the response is
one-sided where a contact slides at its friction cap), for the size of what it leaves out.

Prints and saves ``docs/benchmarks/stable_step_margin.json`` (records merged by label):

    NUMBA_NUM_THREADS=1 python cases/benchmarks/stable_step_margin.py --scene low:coarse --size 0.5 --joint-offset 0 \\
        --crest-length 60 --toe-length 90 --label low_coarse_0.5_offset0_start
    NUMBA_NUM_THREADS=1 python cases/benchmarks/stable_step_margin.py --run runs/s40/high_coarse_1.0_offset0_local \\
        --label high_coarse_1.0_offset0_at_rest --tangential
    python cases/benchmarks/stable_step_margin.py --label low_coarse_1.0_offset0_to_rest --at-rest \\
        runs/s44/twin_measured runs/s44/twin_bound \\
        docs/cases/rest/low_coarse_1.0_crest60_toe90_offset0.json
"""
from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from records import DOCS, machine  # noqa: E402

NAME = "stable_step_margin"


def scene_options(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The four-slope run options that fix the model (the rest of a run's argv is ignored)."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--angle", default="low")
    p.add_argument("--spacing", default="fine")
    p.add_argument("--size", type=float, default=1.0)
    p.add_argument("--joint-offset", type=float, default=None)
    p.add_argument("--refine", type=float, default=None)
    p.add_argument("--crest-length", type=float, default=None)
    p.add_argument("--toe-length", type=float, default=None)
    p.add_argument("--base-depth", type=float, default=None)
    p.add_argument("--boundary-band", type=float, default=None)
    p.add_argument("--elastic-band", action="store_true")
    return p


def build_model(opts):
    """The four-slope simulation of ``opts`` at its static start (as ``fdem run four-slopes`` builds it)."""
    from fdem.cases.four_slopes import RUN_EXTENTS, build, simulation

    spacing = opts.spacing if opts.spacing in ("fine", "coarse") else float(opts.spacing)
    ext = dict(RUN_EXTENTS[opts.angle])
    for k in ext:
        given = getattr(opts, k)
        if given is not None:
            ext[k] = given
    band = ext.get("boundary_band") or None
    ext["boundary_band"] = band
    geometry, _, topo = build(opts.angle, spacing, opts.size, opts.refine, opts.joint_offset, extents=ext)
    sim, cracks = simulation(geometry, topo, None, pictures=False, progress=False,
                             elastic_band=band if opts.elastic_band else None)
    return sim, cracks


def omega_with_tangential_springs(sim, iterations: int = 400, rtol: float = 1e-6) -> float:
    """``omega_max`` [rad/s] with the contact's tangential springs: power iteration on the step's
    response to ``x + u`` with ``v = u / dt`` (the slip increment ``v dt = u`` loads the springs),
    contact damping off; ``u`` scaled so that the node that moves most moves ``1e-10`` of the
    element size (:func:`fdem.solve.step_probe.measured_critical_dt`'s choice). The Rayleigh
    quotient ``u.M w / u.M u`` once it changes by less than ``rtol``."""
    from fdem.physics.contact import ContactSet
    from fdem.solve.model import FIX_X, FIX_Y
    from fdem.solve.step_probe import element_size

    if sim.use_viscous:
        raise ValueError("viscous triangles read velocities too: the tangential measurement needs a model without")
    contact = next(p for p in sim.providers if isinstance(p, ContactSet))
    damping = contact.damping_ratio
    contact.damping_ratio = 0.0
    contact.search(sim.state.x)
    contact._damp_pair[:] = 0.0
    saved = sim.state_dict()
    free = np.column_stack([(sim.flags & FIX_X) == 0, (sim.flags & FIX_Y) == 0])
    mass = sim.state.mass[:, None] * np.ones((1, 2))
    eps = 1e-10 * element_size(saved["x"], sim.triangles)

    def response(u):
        sim.load_state_dict(saved)
        v = np.zeros_like(saved["x"]) if u is None else u / sim.dt
        if u is not None:
            sim.set_positions(displace=u)
        sim.state.v[:] = v
        sim.step()
        return (sim.state.v - v) / sim.dt

    try:
        a0 = response(None).copy()
        u = np.random.default_rng(0).standard_normal(saved["x"].shape) * free
        lam = 0.0
        for _ in range(iterations):
            u /= np.abs(u).max()
            w = -(response(eps * u) - a0) / eps * free
            new = float(np.sum(mass * u * w) / np.sum(mass * u * u))
            u, done, lam = w, abs(new - lam) < rtol * abs(new), new
            if done:
                break
    finally:
        contact.damping_ratio = damping
        sim.load_state_dict(saved)
    return float(np.sqrt(lam))


def history_figures(rows: list[dict], t0: float, t1: float) -> dict:
    """The runout's figures from its history rows between ``t0`` and ``t1`` [s]: kinetic energy
    peak and at the end [J/m], crack elements broken, the largest displacement at the end [m],
    the ledger's largest relative error."""
    rows = [r for r in rows if t0 - 1e-9 <= float(r["time"]) <= t1 + 1e-9 and r["stage"].startswith("runout")]
    broken = lambda r: sum(int(float(r[k])) for k in ("broken_I", "broken_II", "broken_mixed"))  # noqa: E731
    return {"rows": len(rows), "t_end_s": float(rows[-1]["time"]),
            "kinetic_peak_J_m": max(float(r["kinetic"]) for r in rows), "kinetic_end_J_m": float(rows[-1]["kinetic"]),
            "broken_in_runout": broken(rows[-1]) - broken(rows[0]),
            "max_displacement_end_m": float(rows[-1]["max_displacement"]),
            "balance_error_relative_max": max(abs(float(r["balance_error_relative"])) for r in rows)}


def reference_figures(run: Path, t0: float, seconds: float) -> dict:
    """The same figures from the run's own ``history.csv`` (the solver's step, the code the run
    was made with) over the same span of its runout."""
    import csv

    with (run / "history.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    return history_figures(rows, t0, t0 + seconds)


def runout_check(opts, start: Path, seconds: float, fraction_of_measured: float | None) -> dict:
    """The runout stage from ``start`` for ``seconds`` at the solver's step (``None``) or at
    ``fraction_of_measured`` of the critical step measured at ``start``; its figures."""
    from fdem.solve.checkpoint import read_checkpoint
    from fdem.solve.simulation import InstabilityError
    from fdem.solve.step_probe import measured_critical_dt
    from fdem.workflow.slope import SlopeWorkflow, runout_stage
    from fdem.workflow.stages import response_time, run_stage

    sim, cracks = build_model(opts)
    sim.load_state_dict(read_checkpoint(start)["state"])
    sim.set_density_scaling(False)  # the runout's own masses (the state before it may be density-scaled)
    topo = sim.model.topology
    out = {"fraction_of_measured": fraction_of_measured}
    if fraction_of_measured is not None:
        sim.providers[1].search(sim.state.x)
        probe = measured_critical_dt(sim)
        fixed = fraction_of_measured * probe.critical_dt
        sim._choose_dt = lambda: fixed  # the experiment: bypass the solver's bound
        out["measured_critical_dt_s"] = probe.critical_dt
    for mode, name in ((1, "broken_I"), (2, "broken_II"), (3, "broken_mixed")):  # the history columns of a run
        sim.add_monitor(name, lambda s, m=mode: float(np.count_nonzero(cracks.failure_mode == m)))
    step0, n_hist, t0 = sim.state.step, len(sim.history), sim.state.time
    stage = runout_stage(SlopeWorkflow(runout_dt_fraction=0.8, runout_time=seconds), response_time(sim.model),
                         float(np.ptp(topo.x0[:, 1])), float(np.linalg.norm(sim.gravity)))
    wall = time.perf_counter()
    try:
        res = run_stage(sim, stage, frames=False)
        out["reason"] = res.reason
    except InstabilityError as e:
        out["reason"] = f"unstable: {e}"
    out["wall_s"] = time.perf_counter() - wall
    out.update({"dt_s": float(sim.dt), "steps": sim.state.step - step0, "t0_s": t0,
                **history_figures(sim.history[n_hist - 1:], t0, t0 + seconds)})
    sim.close()
    return out


def figures_at_rest(where: Path) -> dict:
    """What a run to rest did and what its runout cost, from its ``summary.json`` (``where`` a
    run's folder) or a published summary (``where`` a ``.json``), with the commit it ran at."""
    summary_path = where if where.suffix == ".json" else where / "summary.json"
    record_path = where.with_name(where.stem + "_run.json") if where.suffix == ".json" else where / "run.json"
    s = json.loads(summary_path.read_text())
    record = json.loads(record_path.read_text()) if record_path.is_file() else {}
    stages = (s.get("workflow") or {}).get("stages") or []
    runout = [st for st in stages if st["name"].startswith("runout")][-1]
    run, ke, tags = s.get("runout") or {}, s.get("kinetic_energy") or {}, s.get("cracks_by_tag") or {}
    return {"run": str(where), "commit": ((record.get("source") or {}).get("commit") or "")[:7],
            "step_from": "measured" if runout.get("measured_critical_dt") else "bound",
            "runout_steps": runout["steps"], "runout_dt_s": runout["dt"], "runout_wall_s": runout["wall_seconds"],
            "runout_reason": runout["reason"], "runout_t_s": runout["t_end"] - runout["t_start"],
            "runout_detail": runout.get("detail", ""),
            "max_displacement_m": run.get("max_displacement_m"), "runout_distance_m": run.get("runout_distance_m"),
            "front_m": run.get("runout_front_max_m"), "displaced_area_m2": run.get("displaced_area_m2"),
            "kinetic_peak_J_m": ke.get("peak_J_per_m"), "released_gravity_J_m": ke.get("released_gravity_J_per_m"),
            "broken_rock": (tags.get("rock") or {}).get("broken"), "broken_joints": (tags.get("joints") or {}).get("broken"),
            "ledger_error_relative": s.get("ledger_error_relative")}


def print_at_rest(rows: list[dict]) -> None:
    keys = [("step_from", "{}"), ("commit", "{}"), ("runout_steps", "{:,}"), ("runout_dt_s", "{:.4g}"),
            ("runout_wall_s", "{:,.0f}"), ("runout_reason", "{}"), ("runout_t_s", "{:.3g}"),
            ("max_displacement_m", "{:.3g}"), ("runout_distance_m", "{:.3g}"), ("front_m", "{:.3g}"),
            ("displaced_area_m2", "{:.4g}"), ("kinetic_peak_J_m", "{:.4g}"), ("released_gravity_J_m", "{:.4g}"),
            ("broken_rock", "{:,}"), ("broken_joints", "{:,}"), ("ledger_error_relative", "{:.2g}")]
    print("| | " + " | ".join(Path(r["run"]).name for r in rows) + " |")
    print("|---|" + "---|" * len(rows))
    for k, fmt in keys:
        print(f"| {k} | " + " | ".join("-" if r.get(k) is None else fmt.format(r[k]) for r in rows) + " |")


def describe(r: dict) -> str:
    return (f"KE peak {r['kinetic_peak_J_m']:.4g} J/m, at the end {r['kinetic_end_J_m']:.4g}; {r['broken_in_runout']} "
            f"broken; max displacement at the end {r['max_displacement_end_m']:.3g} m; ledger error at most "
            f"{r['balance_error_relative_max']:.2e}")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], parents=[scene_options()])
    ap.add_argument("--scene", default=None, metavar="ANGLE:SPACING", help="probe this scene at its start")
    ap.add_argument("--run", type=Path, default=None, help="probe this four-slope run's checkpoint")
    ap.add_argument("--label", required=True, help="the record's name in the JSON file")
    ap.add_argument("--tangential", action="store_true",
                    help="measure again with the contact's tangential springs (their share of the limit)")
    ap.add_argument("--rtol", type=float, default=1e-6)
    ap.add_argument("--runout-check", type=float, default=None, metavar="SECONDS",
                    help="with --run: run the runout from runout_start.npz this long at both steps")
    ap.add_argument("--measured-fraction", type=float, default=0.8, help="of the measured critical step (0.8)")
    ap.add_argument("--with-control", action="store_true",
                    help="also rerun the runout at the solver's step (else the run's own history is the reference)")
    ap.add_argument("--at-rest", type=Path, nargs="+", default=None, metavar="RUN",
                    help="runs made to rest (folders, or summaries in docs/cases/rest): their figures side by side")
    args = ap.parse_args(argv)
    if args.at_rest is not None:
        missing = [str(w) for w in args.at_rest if not (w if w.suffix == ".json" else w / "summary.json").is_file()]
        if missing:
            ap.error(f"--at-rest: no summary in {', '.join(missing)} (a run that has not ended has none)")
        rec = {"label": args.label, "at_rest": [figures_at_rest(w) for w in args.at_rest],
               "command": "python cases/benchmarks/stable_step_margin.py " + shlex.join(argv if argv is not None else sys.argv[1:])}
        print_at_rest(rec["at_rest"])
        return save_record(rec)
    if (args.scene is None) == (args.run is None):
        ap.error("give one of --scene ANGLE:SPACING or --run DIR")
    if args.runout_check is not None and (args.run is None or not (args.run / "runout_start.npz").is_file()):
        ap.error("--runout-check needs --run DIR with a runout_start.npz")
    from fdem.solve.checkpoint import read_checkpoint
    from fdem.solve.step_probe import measured_critical_dt

    t0 = time.perf_counter()
    if args.run is not None:
        record_file = args.run / "run.json"
        if not (args.run / "checkpoint.npz").is_file() or not record_file.is_file():
            ap.error(f"{args.run} holds no checkpoint.npz and run.json of a four-slope run")
        run_argv = json.loads(record_file.read_text())["argv"]
        opts, _ = scene_options().parse_known_args(run_argv)
        sim, cracks = build_model(opts)
        # not load_checkpoint: a state saved at F > 1 has reduced contact friction, which the
        # model fingerprint would read as another model
        sim.load_state_dict(read_checkpoint(args.run / "checkpoint.npz")["state"])
        where = f"checkpoint of {args.run} at t = {sim.state.time:.4g} s, F = {cracks.interfaces.reduction:.4g}"
        command_of_state = "fdem run four-slopes " + shlex.join(run_argv)
    else:
        angle, spacing = args.scene.split(":")
        args.angle, args.spacing = angle, spacing
        sim, cracks = build_model(args)
        where = "static start"
        command_of_state = None
    built = time.perf_counter() - t0
    contact = sim.providers[1]
    contact.search(sim.state.x)
    t1 = time.perf_counter()
    probe = measured_critical_dt(sim, rtol=args.rtol)
    probe_s = time.perf_counter() - t1
    rec = {"label": args.label, "state": where, "triangles": int(sim.model.n_triangles),
           "contact_pairs": int(len(contact.pairs)), "touching_pairs": int(np.sum(contact._touching)) if len(contact.pairs) else 0,
           "broken_cracks": int(cracks.broken.sum()), "threads": int(os.environ.get("NUMBA_NUM_THREADS", "0") or 0),
           **probe.as_dict(), "probe_wall_s": probe_s, "build_wall_s": built, "run_command": command_of_state,
           "command": "python cases/benchmarks/stable_step_margin.py " + shlex.join(argv if argv is not None else sys.argv[1:])}
    print(f"{args.label}: {rec['triangles']:,} triangles, {where}; {rec['touching_pairs']:,} touching of "
          f"{rec['contact_pairs']:,} pairs, {rec['broken_cracks']:,} broken")
    print("  bounds: " + ", ".join(f"{k} {v:.4g} s" for k, v in probe.limits.items()) + f"; combined {probe.bound_dt:.4g} s")
    print(f"  measured critical step {probe.critical_dt:.4g} s ({probe.steps} steps, converged {probe.converged}, "
          f"{probe_s:.0f} s): {probe.margin:.3f} x the bound; the run's step {probe.step_dt:.4g} s is "
          f"{probe.step_share:.3f} of it")
    if args.tangential:
        with_springs = 2.0 / omega_with_tangential_springs(sim)
        rec["critical_dt_with_tangential_s"] = with_springs
        rec["tangential_effect"] = with_springs / probe.critical_dt - 1.0
        print(f"  with the tangential springs: {with_springs:.4g} s ({100 * rec['tangential_effect']:+.2f} %)")
    if args.runout_check is not None:
        rec["runout_check"] = []
        fractions = [args.measured_fraction] + ([None] if args.with_control else [])
        for frac in fractions:
            r = runout_check(opts, args.run / "runout_start.npz", args.runout_check, frac)
            rec["runout_check"].append(r)
            which = "the solver's step" if frac is None else f"{frac:g} of the measured critical step"
            print(f"  runout {args.runout_check:g} s at {which} ({r['dt_s']:.4g} s): {r['reason']}; {r['steps']:,} "
                  f"steps, {r['wall_s']:.0f} s; " + describe(r), flush=True)
        ref = reference_figures(args.run, rec["runout_check"][0]["t0_s"], args.runout_check)
        rec["runout_check_reference"] = ref
        print(f"  the run itself over the same {args.runout_check:g} s (its history.csv): " + describe(ref))
    return save_record(rec)


def save_record(rec: dict) -> dict:
    """Merge ``rec`` into ``docs/benchmarks/stable_step_margin.json`` by its label."""
    DOCS.mkdir(parents=True, exist_ok=True)
    path = DOCS / f"{NAME}.json"
    doc = json.loads(path.read_text()) if path.is_file() else {"benchmark": NAME, "records": []}
    doc["machine"] = machine()
    doc["records"] = [r for r in doc["records"] if r.get("label") != rec["label"]] + [rec]
    path.write_text(json.dumps(doc, indent=2))
    print(f"wrote {path}")
    return rec


if __name__ == "__main__":
    main()
