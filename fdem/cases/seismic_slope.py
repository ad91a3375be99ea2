"""Seismic slope: the demo's jointed slope shaken through its base; critical amplitude against rigid blocks.

The quick-start slope (10 m high, 60 deg face, joints dipping 30 deg out of the face in a brick
pattern; :mod:`fdem.cases.quick_start`), its base shaken horizontally by a sine record of
``--frequency`` and ``--cycles`` (default 2 Hz, 2 cycles: the inertial drive points towards the
face first). The base moves rigidly with the record (:class:`fdem.workflow.seismic.BaseShaking`);
the two sides move with it horizontally and are free vertically (rollers riding on the base),
so the model is a laterally rigid box: instead of free-field columns, the box is made wide and
the run shows the sides do not matter (the permanent displacement at the same amplitude with the
crest plateau ``--widths`` long: the critical amplitudes of both models).

1. FDEM: the critical amplitude ``a_c`` [g] by bisection (:func:`fdem.workflow.fos.factor_of_safety`
   with the base-shaking trigger): each trial restarts from static equilibrium, shakes the base
   with the record at the trial amplitude and runs the record plus ``--settle`` seconds
   dynamically (no stage damping: the model's element damping, 0.1 of critical at each
   triangle's own frequency, and the contact damping are all there is); it fails when a node's
   permanent displacement relative to the base exceeds ``--threshold`` times the slope height.
2. Rigid blocks of the same joints (:func:`fdem.blocks.slope.analyse`): the pseudo-static yield
   acceleration ``k_y`` [g] towards the face and its mechanism.
3. Newmark (1965) displacement of that mechanism under the same record
   (:func:`fdem.blocks.newmark.one_way_slip`) at ``--amplitudes`` (multiples of ``k_y``), and the
   FDEM permanent displacement at the same amplitudes.

``--max-time`` caps every trial's simulated time (a smoke run: the search then cannot find a
failing end, says so and writes ``time_capped``).

Writes ``summary.json`` (k_y, a_c, the displacements, the width check) and ``seismic.png``
(permanent displacement against amplitude: FDEM and Newmark, ``a_c`` and ``k_y`` marked).

    fdem run seismic-slope --out runs/seismic              # about 4 minutes on one shared core
    python cases/seismic_slope.py --out runs/seismic

The FDEM joints are brittle (their cohesion and tensile strength soften once they slip, and
the residual friction, 28 deg, is below the joints' 30 deg dip) while the rigid blocks keep the
peak strength, so a slope that slips past its peak keeps going in the FDEM and stops in Newmark's
model: compare ``a_c`` with ``k_y`` and the displacements below ``a_c``, not the runout above it.
"""
from __future__ import annotations

from fdem.io.messages import say, warn

import math
import time
import warnings
from pathlib import Path

import numpy as np

from fdem.cases.common import (cap_simulated_time, case_parser, check_common, finish_run, prepare_run, set_threads,
                               threads_for_mesh)
from fdem.cases.quick_start import (BASE_DEPTH, CONTACT_DAMPING, DENSITY, ELEMENT_DAMPING, FACE_ANGLE, GRAVITY,
                                    HEIGHT, JOINT_DIP, JOINT_SPACING, MIN_JOINT_LENGTH, PENALTY, POISSON,
                                    TOE_LENGTH, YOUNG, property_sets)
from fdem.io.jsonable import write_json

__all__ = ["NAME", "SIZE", "FREQUENCY", "CYCLES", "SETTLE", "THRESHOLD", "BRACKET", "AMPLITUDES", "WIDTHS",
           "geometry", "build", "shake", "rigid_blocks", "newmark_curve", "newmark_critical", "plot", "parse_args",
           "main"]

NAME = "seismic-slope"
SIZE = 1.0                      # element size [m]
FREQUENCY, CYCLES = 2.0, 2.0    # the sine record [Hz, -]
SETTLE = 0.5                    # s after the record before a trial is judged
THRESHOLD = 0.01                # failure: permanent displacement > this fraction of the slope height
BRACKET = (0.1, 0.8, 0.025)     # (stable, failing, tolerance) of the amplitude search [g]
AMPLITUDES = (1.25, 1.5, 2.0)   # FDEM and Newmark displacements at these multiples of k_y
WIDTHS = (24.0, 40.0)           # crest lengths [m] of the width check (the first is the run's model)


def geometry(crest_length: float = WIDTHS[0]):
    """The quick-start slope and joints with a crest plateau ``crest_length`` [m] long (the toe
    side and the joints' pattern unchanged: the plateau grows away from the face)."""
    from fdem.geometry.joint_sets import BrickSet
    from fdem.geometry.polygons import simple_slope
    from fdem.geometry.section import Geometry

    slope = simple_slope(HEIGHT, FACE_ANGLE, crest_length=crest_length, toe_length=TOE_LENGTH,
                         base_depth=BASE_DEPTH, name="slope")
    a = math.radians(JOINT_DIP)
    offset = -math.sin(a) * TOE_LENGTH + math.cos(a) * BASE_DEPTH
    fabric = BrickSet(dip=JOINT_DIP, spacing=JOINT_SPACING, offset=offset, name="bedding + cross joints")
    return Geometry([slope], [fabric], min_joint_length=MIN_JOINT_LENGTH)


def build(size: float = SIZE, crest_length: float = WIDTHS[0], frequency: float = FREQUENCY,
          cycles: float = CYCLES, settle: float = SETTLE, threshold: float = THRESHOLD):
    """The shaken slope in static equilibrium: ``(sim, shaking)``. The base follows the record in
    x and y (y: at rest), the sides in x (free in y)."""
    from fdem.mesh.topology import build_topology
    from fdem.mesh.triangulate import mesh_geometry
    from fdem.physics.contact import ContactSet
    from fdem.physics.cracks import CrackSet
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.geostatic import geostatic_start
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation
    from fdem.workflow.seismic import BaseShaking

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="dropped .* joint segment", category=UserWarning)
        topo = build_topology(mesh_geometry(geometry(crest_length), size))
    model = Model(topo, ElasticMaterial(young=YOUNG, poisson=POISSON, density=DENSITY))
    model.set_element_damping(ELEMENT_DAMPING)
    model.set_gravity(0.0, -GRAVITY)
    # base accelerating away from the face first: the inertial drive points at the face (-x)
    shaking = BaseShaking.sine(frequency, cycles, direction=(1.0, 0.0), settle=settle,
                               threshold=threshold * HEIGHT, g=GRAVITY)
    model.fix("bottom")                 # the static start needs zero prescribed velocities ...
    model.roller("left", "x")
    model.roller("right", "x")
    cracks = CrackSet(topo, property_sets(), contact_penalty=PENALTY)
    geostatic_start(model, cracks)
    shaking.attach(model, "bottom", "xy")   # ... then the same supports follow the record (zero until a trial)
    shaking.attach(model, "left", "x")
    shaking.attach(model, "right", "x")
    contact = ContactSet(topo, PENALTY, friction_angle=28.0, mass=model.node_mass(), cracks=cracks,
                         damping_ratio=CONTACT_DAMPING)
    sim = Simulation(model, providers=[cracks, contact], progress=False)
    return sim, shaking


def shake(sim, shaking, amplitude: float) -> dict:
    """One trial at ``amplitude`` [g] from the current state, which is restored afterwards:
    the permanent displacement relative to the base [m], the verdict and the crack elements broken."""
    from fdem.solve.checkpoint import restore, snapshot
    from fdem.workflow.stages import run_stage

    start = snapshot(sim)
    broken0 = int(sim.cracks.broken.sum())
    try:
        shaking.apply(sim, amplitude)
        result = run_stage(sim, shaking.trial_stage(sim, name=f"shake_{amplitude:.4f}g"), frames=False)
        stable = shaking.judge(sim, result)
        out = {"amplitude_g": amplitude, "permanent_displacement_m": shaking.permanent_displacement(sim),
               "stable": stable, "broken": int(sim.cracks.broken.sum()) - broken0, "steps": result.steps,
               "wall_seconds": result.wall_seconds}
    finally:
        restore(sim, start)
        shaking.reset(sim, 0.0)
    return out


def rigid_blocks(crest_length: float = WIDTHS[0]) -> dict:
    """The rigid-block factor of safety, yield acceleration towards the face and its mechanism."""
    from fdem.blocks.slope import analyse

    t = np.array([0.0, 1.0])
    r = analyse(geometry(crest_length), property_sets(), DENSITY * GRAVITY, record=(t, np.zeros(2)))
    if r.get("yield") is None:
        raise RuntimeError(f"rigid blocks: no yield acceleration ({r.get('yield_error', 'the slope fails statically')})")
    return r


def newmark_curve(shaking, a_y: float, amplitudes) -> np.ndarray:
    """Newmark displacement [m] of the rigid mechanism (yield acceleration ``a_y`` [m/s^2],
    horizontal towards the face) under the record at each amplitude [g]."""
    from fdem.blocks.newmark import one_way_slip

    return np.array([one_way_slip(shaking.t, shaking.drive(a, (-1.0, 0.0)), a_y)[0][-1] for a in amplitudes])


def newmark_critical(shaking, a_y: float, threshold: float, upper: float = 10.0, tol: float = 1e-5) -> float | None:
    """Amplitude [g] at which the rigid mechanism's Newmark displacement reaches ``threshold``
    [m] under the record (bisection; the displacement grows with the amplitude); ``None`` above ``upper``."""
    lo, hi = a_y / shaking.g, upper
    if newmark_curve(shaking, a_y, [hi])[0] < threshold:
        return None
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if newmark_curve(shaking, a_y, [mid])[0] < threshold else (lo, mid)
    return 0.5 * (lo + hi)


def plot(summary: dict, shaking, a_y: float, png: Path) -> Path:
    """Permanent displacement against amplitude: FDEM trials and Newmark's mechanism; a_c, k_y marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ky, ac = summary["k_y"], summary["a_c_g"]
    pts = summary["fdem_points"]
    a_max = max([p["amplitude_g"] for p in pts] + [2.2 * ky])
    grid = np.linspace(ky, a_max, 200)[1:]
    d_nm = newmark_curve(shaking, a_y, grid)
    fig, ax = plt.subplots(figsize=(6.6, 4.4))
    ax.plot(grid, 100 * d_nm, "k-", lw=2, label="Newmark, rigid-block mechanism")
    for stable, mark, label in ((True, "o", "FDEM, stable"), (False, "x", "FDEM, failing")):
        sel = [p for p in pts if p["stable"] == stable]
        if sel:
            ax.plot([p["amplitude_g"] for p in sel], [max(100 * p["permanent_displacement_m"], 1e-3) for p in sel],
                    mark, ms=7, mew=2, label=label)
    ax.axvline(ky, color="tab:gray", ls="--", lw=1, label=f"rigid-block k_y = {ky:.3f} g")
    ax.axvline(ac, color="tab:red", ls="--", lw=1.2, label=f"FDEM a_c = {ac:.3f} g")
    ax.axhline(100 * summary["threshold_m"], color="tab:red", ls=":", lw=1, label="failure threshold")
    if summary.get("newmark_a_c_g") is not None:
        ax.plot([summary["newmark_a_c_g"]], [100 * summary["threshold_m"]], "ks", ms=6,
                label=f"Newmark reaches it at {summary['newmark_a_c_g']:.3f} g")
    ax.set_yscale("log")
    ax.set_xlabel("peak base acceleration [g]")
    ax.set_ylabel("permanent displacement relative to the base [cm]")
    ax.set_title(f"demo slope, sine {summary['frequency_hz']:g} Hz x {summary['cycles']:g} cycles", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def parse_args(argv=None):
    parser = case_parser(__doc__, name=NAME, out="runs/seismic_slope", size=SIZE,
                         size_help=f"element size [m] (default {SIZE})")
    parser.add_argument("--frequency", type=float, default=FREQUENCY, help=f"record frequency [Hz] (default {FREQUENCY})")
    parser.add_argument("--cycles", type=float, default=CYCLES, help=f"record length in cycles (default {CYCLES})")
    parser.add_argument("--settle", type=float, default=SETTLE, help=f"seconds after the record (default {SETTLE})")
    parser.add_argument("--threshold", type=float, default=THRESHOLD,
                        help=f"failure: permanent displacement above this fraction of the slope height (default {THRESHOLD})")
    parser.add_argument("--bracket", type=float, nargs=3, default=list(BRACKET), metavar=("STABLE", "FAILING", "TOL"),
                        help=f"amplitude search [g] (default {' '.join(map(str, BRACKET))})")
    parser.add_argument("--amplitudes", type=float, nargs="*", default=list(AMPLITUDES),
                        help=f"FDEM and Newmark displacements at these multiples of k_y (default {' '.join(map(str, AMPLITUDES))})")
    parser.add_argument("--widths", type=float, nargs="*", default=list(WIDTHS),
                        help="crest lengths [m]: the first is the model, the others repeat the width check "
                             f"(default {' '.join(map(str, WIDTHS))}; one value: no check)")
    parser.add_argument("--max-trials", type=int, default=12, help="cap on the search's trials (default 12)")
    args = parser.parse_args(argv)
    check_common(parser, args)
    for name in ("frequency", "cycles"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0):
            parser.error(f"--{name} must be a positive number, got {v}")
    if not (math.isfinite(args.settle) and args.settle >= 0):
        parser.error(f"--settle must be a number of seconds >= 0, got {args.settle}")
    if not (math.isfinite(args.threshold) and 0 < args.threshold < 1):
        parser.error(f"--threshold must be a fraction of the slope height in (0, 1), got {args.threshold}")
    from fdem.workflow.fos import check_bracket

    try:
        check_bracket(*args.bracket, max_trials=args.max_trials)
    except ValueError as err:
        parser.error(str(err).replace("factor_of_safety: ", "--bracket/--max-trials: "))
    if any(not (math.isfinite(a) and a > 1) for a in args.amplitudes):
        parser.error(f"--amplitudes must be multiples of k_y above 1 (below k_y Newmark's block does not move), "
                     f"got {args.amplitudes}")
    if not args.widths or any(not (math.isfinite(w) and w >= 2) for w in args.widths):
        parser.error(f"--widths must be crest lengths of at least 2 m, got {args.widths}")
    if args.size > HEIGHT / 4:
        parser.error(f"--size {args.size} m is too coarse for a {HEIGHT:g} m slope (at most {HEIGHT / 4:g} m)")
    return parser, args


def main(argv=None) -> dict:
    parser, args = parse_args(argv)
    args = prepare_run(parser, args, argv, NAME)
    set_threads(args.threads)
    from fdem.workflow.fos import BracketError, factor_of_safety

    wall = time.perf_counter()
    out = Path(args.out)
    rb = rigid_blocks(args.widths[0])
    y = rb["yield_result"]
    ky, a_y = y.k_y, y.acceleration
    print(f"rigid blocks: factor of safety {rb['fos']:.3f}, yield acceleration k_y = {ky:.4f} g towards the face, "
          f"mechanism {y.mechanism.n_moving} block(s) {y.mechanism.as_dict()['kind']}")
    sim, shaking = build(args.size, args.widths[0], args.frequency, args.cycles, args.settle, args.threshold)
    cap_simulated_time(sim, args.max_time)   # a smoke run: every trial stops at --max-time (each restarts at t = 0)
    threads = threads_for_mesh(args.threads, sim.model.topology.n_triangles)
    say(f"{sim.model.topology.n_triangles} triangles, time step {sim.dt:.3g} s; each trial "
          f"{shaking.duration + shaking.settle:g} s of shaking and settling")
    lower, upper, tol = args.bracket
    outcome, ending = "finished", None
    try:
        fos = factor_of_safety(sim, lower, upper, tol, trial=shaking.trial_stage(sim), trigger=shaking,
                               judge=shaking.judge, max_trials=args.max_trials)
        a_c, bracket, ended_by = fos.fos, list(fos.bracket), fos.ended_by
    except BracketError as err:
        a_c, bracket, ended_by = None, None, "bracket"
        outcome, ending = "bracket_error", str(err)
        warn(str(err))
    search = list(shaking.log)
    print(f"FDEM critical amplitude a_c = {a_c if a_c is None else round(a_c, 4)} g, bracket {bracket}", flush=True)
    amps = [r * ky for r in args.amplitudes]
    runs = [shake(sim, shaking, a) for a in amps]
    d_nm = newmark_curve(shaking, a_y, amps)
    rows = [{"ratio_to_k_y": r, "amplitude_g": a, "newmark_m": float(d), "fdem_m": run["permanent_displacement_m"],
             "fdem_stable": run["stable"], "fdem_broken": run["broken"]}
            for r, a, d, run in zip(args.amplitudes, amps, d_nm, runs)]
    for row in rows:
        print(f"  {row['amplitude_g']:.3f} g ({row['ratio_to_k_y']:g} k_y): Newmark {100 * row['newmark_m']:.2f} cm, "
              f"FDEM {100 * row['fdem_m']:.2f} cm ({'stable' if row['fdem_stable'] else 'failing'})", flush=True)
    # width check: the same search on wider models (the crest plateau longer, the face and joints unchanged)
    width = []
    if len(args.widths) > 1 and a_c is not None:
        width.append({"crest_length_m": args.widths[0], "model_width_m": float(np.ptp(sim.model.topology.x0[:, 0])),
                      "n_triangles": int(sim.model.topology.n_triangles), "a_c_g": a_c, "a_c_bracket_g": bracket})
        for w in args.widths[1:]:
            wsim, wshake = build(args.size, w, args.frequency, args.cycles, args.settle, args.threshold)
            cap_simulated_time(wsim, args.max_time)
            row = {"crest_length_m": w, "model_width_m": float(np.ptp(wsim.model.topology.x0[:, 0])),
                   "n_triangles": int(wsim.model.topology.n_triangles)}
            try:
                r = factor_of_safety(wsim, lower, upper, tol, trial=wshake.trial_stage(wsim), trigger=wshake,
                                     judge=wshake.judge, max_trials=args.max_trials)
                row.update(a_c_g=r.fos, a_c_bracket_g=list(r.bracket))
            except BracketError as err:
                row.update(a_c_g=None, a_c_bracket_g=None, error=str(err))
            wsim.close()
            width.append(row)
        for r in width:
            r["a_c_difference_g"] = None if r["a_c_g"] is None else r["a_c_g"] - a_c
            say(f"  width check: crest {r['crest_length_m']:g} m (model {r['model_width_m']:.1f} m wide, "
                  f"{r['n_triangles']} triangles): a_c {r['a_c_g'] if r['a_c_g'] is None else round(r['a_c_g'], 4)} g, "
                  f"bracket {r['a_c_bracket_g']}")
    sim.close()
    model_width = float(np.ptp(sim.model.topology.x0[:, 0]))
    summary = {"case": NAME, "outcome": outcome, "ending": ending, "time_capped": args.max_time is not None,
               "size_m": args.size, "threads": threads,
               "n_triangles": int(sim.model.topology.n_triangles), "model_width_m": model_width,
               "height_m": HEIGHT, "frequency_hz": args.frequency, "cycles": args.cycles, "settle_s": shaking.settle,
               "threshold_m": args.threshold * HEIGHT, "k_y": ky, "a_y_m_s2": a_y,
               "rigid_block_fos": rb["fos"], "mechanism": y.mechanism.as_dict(),
               "a_c_g": a_c, "a_c_bracket_g": bracket, "search_ended_by": ended_by,
               "a_c_over_k_y": None if a_c is None else a_c / ky,
               "newmark_a_c_g": newmark_critical(shaking, a_y, args.threshold * HEIGHT),
               "fdem_points": search + [{"amplitude_g": r["amplitude_g"], "permanent_displacement_m": r["fdem_m"],
                                         "stable": r["fdem_stable"]} for r in rows],
               "displacements": rows, "width_check": width, "time_step_s": sim.dt,
               "wall_seconds": time.perf_counter() - wall}
    if not args.no_pictures and a_c is not None:
        summary["picture"] = str(plot(summary, shaking, a_y, out / "seismic.png"))
    write_json(out / "summary.json", summary)
    finish_run(out, summary)
    say(f"wrote {out / 'summary.json'} in {summary['wall_seconds']:.0f} s")
    return summary
