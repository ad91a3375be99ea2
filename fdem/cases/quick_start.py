"""Quick start: a small jointed slope that stands, fails under strength reduction and runs out.

A 12 m slope with a 60 deg face; a persistent joint set dipping 30 deg out of the face (one
joint through the toe) crossed by perpendicular cross joints in a brick pattern (blocks 2 m x
4 m). The slope starts in static equilibrium (:func:`fdem.solve.geostatic.geostatic_start`), then
:func:`fdem.workflow.slope.run_slope_workflow` checks equilibrium at F = 1, searches the factor of
safety by strength reduction, reduces the strength in steps (1/0.9, 1/0.8, ...) until the slope
fails, and follows the runout at the failing factor until the rock comes to rest.

Writes to ``--out``: ``slope.pvd`` and ``slope_cracks.pvd`` (ParaView series), ``history.csv``,
``summary.json`` (factor of safety, factor at failure, runout distance and volume, displacement
percentiles, kinetic energy, cracks by mode, fragments, events), ``events.csv``, ``fos.json``
and the pictures ``failure.png``, ``kinetic_energy.png``, ``cracks_by_mode.png``,
``fos_failure.png`` (and ``fragments.png``, ``magnitudes.png`` when there are any).

    fdem run quick-start --out runs/demo          # about 1,500 triangles, about a minute
    python cases/quick_start.py --out runs/demo   # the same

Chosen (not from a paper): a soft rock (E = 0.5 GPa) so that the stable step is large, and
penalties tied and soft, ``p_t = p_n = E`` (the contact penalty too), for a larger step (the
crack elements' limit goes as ``sqrt(1/p)``: the Pareto column's combined step is 2.1-2.4x
larger at alpha 1 than at 10). The price is compliance: glued crack elements at ``p = E`` make an
exploded mesh about three times too soft in uniaxial strain (``docs/pareto.md``: the gravity
column settles +210 % at alpha 1, +22 % at 10), so the demo's elastic displacements are not to
be read as such; strength and failure are set by the crack law's strengths, not its penalty
(the planar slope's factor of safety is the same at alpha 5 and 20; alpha 1 was not tried on
it). The stiff literal shear penalty of the four-slope paper would cut the step several-fold. Joints ``c = 20 kPa``, ``phi = 28 deg``:
limit equilibrium of the wedge above the toe joint gives about F = 1.2 (Hoek-Bray, dry).
"""
from __future__ import annotations

from fdem.io.messages import say

from fdem.io.jsonable import write_json
import math
import time
import warnings
from pathlib import Path

import numpy as np

from fdem.cases.common import (add_resume_options, add_write_scene_option, cap_simulated_time, case_parser, check_common, check_mesh_size,
                               finish_run, prepare_run, report_runout_cost, save_final_state,
                               set_threads, start_journal, stop_cleanly_on_signals, threads_for_mesh, time_capped,
                               use_density_scaling, write_case_scene, write_report, failing_factor_words)

__all__ = ["NAME", "PENALTY", "GRAVITY", "ELEMENT_DAMPING", "CONTACT_DAMPING", "SIZE", "MIN_JOINT_LENGTH",
           "FOS_BRACKET", "geometry", "property_sets", "build", "scene", "main", "HEIGHT", "FACE_ANGLE", "TOE_LENGTH", "CREST_LENGTH", "BASE_DEPTH", "JOINT_DIP", "JOINT_SPACING", "YOUNG", "POISSON", "DENSITY"]

NAME = "quick-start"
HEIGHT, FACE_ANGLE = 10.0, 60.0                 # slope height [m], face angle [deg]
TOE_LENGTH, CREST_LENGTH, BASE_DEPTH = 24.0, 8.0, 3.0   # [m]: room for the runout in front of the toe
JOINT_DIP, JOINT_SPACING = 30.0, 2.0            # persistent joints out of the face [deg], [m]
YOUNG, POISSON, DENSITY = 0.5e9, 0.25, 2600.0   # rock [Pa, -, kg/m^3]
PENALTY = 1 * YOUNG                             # p_n = p_t = contact penalty [Pa]
GRAVITY = 9.81
ELEMENT_DAMPING = 0.1                           # of critical, each triangle (docs/damping.md default)
CONTACT_DAMPING = 0.2                           # normal contact damping ratio: impacts lose energy
SIZE = 1.0                                      # default element size [m]: the demo runs in < 2 min cold
MIN_JOINT_LENGTH = 0.3                          # joint pieces shorter than this are dropped [m]
FOS_BRACKET = (1.0, 2.0, 0.05)                  # (stable, failing, tolerance) of the FoS search


def geometry(height: float = HEIGHT, face_angle: float = FACE_ANGLE, joint_dip: float = JOINT_DIP,
             spacing: float = JOINT_SPACING):
    """The slope polygon and its brick-pattern joints, one persistent joint through the toe."""
    from fdem.geometry.joint_sets import BrickSet
    from fdem.geometry.section import Geometry
    from fdem.geometry.polygons import simple_slope

    slope = simple_slope(height, face_angle, crest_length=CREST_LENGTH, toe_length=TOE_LENGTH,
                         base_depth=BASE_DEPTH, name="slope")
    a = math.radians(joint_dip)
    offset = -math.sin(a) * TOE_LENGTH + math.cos(a) * BASE_DEPTH   # n . toe, n the joints' normal
    fabric = BrickSet(dip=joint_dip, spacing=spacing, offset=offset, name="bedding + cross joints")
    return Geometry([slope], [fabric], min_joint_length=MIN_JOINT_LENGTH)


def property_sets(penalty: float = PENALTY) -> dict:
    """Tag 0 intact rock bridges, tag 1 joints; ``p_t = p_n``."""
    from fdem.physics.crack_properties import CrackProperties

    common = dict(p_n=penalty, p_t=penalty)
    return {
        0: CrackProperties(f_t=100e3, c=250e3, phi=35.0, G_I=50.0, G_II=500.0, name="intact rock bridges",
                           **common),
        1: CrackProperties(f_t=5e3, c=20e3, phi=28.0, G_I=5.0, G_II=50.0, name="joints", **common),
    }


def build(size: float = SIZE, out_dir: Path | None = None, pictures: bool = False, progress: bool = True):
    """Geometry, simulation (in static equilibrium) and crack set of the quick-start slope."""
    from fdem.physics.cracks import CrackSet
    from fdem.physics.contact import ContactSet
    from fdem.solve.geostatic import geostatic_start
    from fdem.physics.elastic import ElasticMaterial
    from fdem.mesh.triangulate import mesh_geometry
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation
    from fdem.mesh.topology import build_topology

    geo = geometry()
    with warnings.catch_warnings():
        # slivers shorter than MIN_JOINT_LENGTH are dropped on purpose (they would shrink the step)
        warnings.filterwarnings("ignore", message="dropped .* joint segment", category=UserWarning)
        topo = build_topology(mesh_geometry(geo, size))
    model = Model(topo, ElasticMaterial(young=YOUNG, poisson=POISSON, density=DENSITY))
    model.set_element_damping(ELEMENT_DAMPING)
    model.set_gravity(0.0, -GRAVITY)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    cracks = CrackSet(topo, property_sets(), contact_penalty=PENALTY)
    start = geostatic_start(model, cracks)
    contact = ContactSet(topo, PENALTY, friction_angle=28.0, mass=model.node_mass(), cracks=cracks,
                         damping_ratio=CONTACT_DAMPING)
    sim = Simulation(model, providers=[cracks, contact], out_dir=out_dir, name="slope", pictures=pictures,
                     progress=progress)
    return geo, sim, cracks, start


def scene(size: float = SIZE, fos: bool = False, runout_time: float | None = None) -> dict:
    """This case as a scene file's contents (``fdem run quick-start --write-scene FILE``): the
    same outline, joints, rock, crack elements, contact, supports and workflow as :func:`build`,
    so that ``fdem run FILE`` runs the same model."""
    import dataclasses

    a = math.radians(JOINT_DIP)
    cracks = {str(tag): {k: v for k, v in dataclasses.asdict(p).items() if v is not None}
              for tag, p in property_sets().items()}
    return {
        "scene": {"name": NAME, "description": "the quick-start slope (fdem demo)", "size": size,
                  "min_joint_length": MIN_JOINT_LENGTH},
        "slope": {"kind": "simple", "height": HEIGHT, "face_angle": FACE_ANGLE, "crest_length": CREST_LENGTH,
                  "toe_length": TOE_LENGTH, "base_depth": BASE_DEPTH},
        "joints": [{"kind": "brick", "name": "bedding + cross joints", "dip": JOINT_DIP, "spacing": JOINT_SPACING,
                    "offset": -math.sin(a) * TOE_LENGTH + math.cos(a) * BASE_DEPTH}],
        "rock": {"young": YOUNG, "poisson": POISSON, "density": DENSITY, "damping": ELEMENT_DAMPING},
        "cracks": cracks,
        "contact": {"penalty": PENALTY, "friction_angle": 28.0, "damping_ratio": CONTACT_DAMPING},
        "supports": {"bottom": "fixed", "left": "fix-x", "right": "fix-x"},
        "gravity": {"g": GRAVITY},
        "workflow": {"kind": "strength-reduction", "fos": list(FOS_BRACKET) if fos else None,
                     **({"runout_time": runout_time} if runout_time is not None else {})},
    }


def main(argv=None) -> dict:
    parser = case_parser(__doc__, name=NAME, out="runs/quick_start", size=SIZE, size_help=f"element size [m] (default {SIZE})")
    parser.add_argument("--fos", action="store_true",
                        help=f"search the factor of safety by bisection first (bracket {FOS_BRACKET[:2]}, "
                             f"tolerance {FOS_BRACKET[2]}; about 6 more damped trials)")
    parser.add_argument("--rigid-blocks", action="store_true",
                        help="first print the rigid-block factor of safety and mechanism of the same joints "
                             "(seconds; docs/rigid_blocks.md)")
    parser.add_argument("--runout-time", type=float, default=None, metavar="SECONDS",
                        help="cap on the runout stage [s of simulated time] (default: 20 response times or four "
                             "free falls over the model height); with --resume, carries a capped runout on")
    add_resume_options(parser)
    add_write_scene_option(parser)
    args = parser.parse_args(argv)
    if args.write_scene is not None:
        check_common(parser, args)
        return write_case_scene(parser, NAME, scene(args.size, args.fos, args.runout_time), args.write_scene, argv or [])
    if args.runout_time is not None and not (math.isfinite(args.runout_time) and args.runout_time > 0):
        parser.error(f"--runout-time must be a positive number of simulated seconds, got {args.runout_time}")
    args = prepare_run(parser, args, argv, NAME)
    check_common(parser, args)
    set_threads(args.threads)
    if args.rigid_blocks:  # seconds, beside the FDEM factor of safety that follows
        from fdem.blocks.slope import print_rigid_blocks
        print_rigid_blocks(geometry(), property_sets(), DENSITY * GRAVITY, args.out)

    from fdem.geometry.polygons import slope_toe
    from fdem.results.report import RunReport
    from fdem.workflow.slope import SlopeWorkflow, factor_of_safety_figures, run_slope_workflow

    wall = time.perf_counter()
    out = args.out
    check_mesh_size(parser, geometry(), args.size)
    workflow = SlopeWorkflow(fos=FOS_BRACKET if args.fos else None, runout_time=args.runout_time)
    geo, sim, cracks, start = build(args.size, out, progress=not args.quiet)
    stop_cleanly_on_signals()  # after meshing: Gmsh installs its own handlers
    toe_x, toe_y = slope_toe(geo.bodies[0])
    report = RunReport(sim, toe_x=toe_x, floor_y=toe_y)
    cap_simulated_time(sim, args.max_time)
    use_density_scaling(sim, args.density_scaling)
    threads = threads_for_mesh(args.threads, sim.model.topology.n_triangles)
    say(f"{sim.model.topology.n_triangles} triangles, {sim.model.topology.n_cracks} crack elements, "
          f"time step {sim.dt:.3g} s, {threads} thread(s)")
    cost = report_runout_cost(parser, sim, args, workflow)
    journal = start_journal(sim, args)
    try:
        result = run_slope_workflow(sim, workflow, out_dir=out, journal=journal)
        save_final_state(sim, out, result["outcome"])
    finally:
        sim.close()
    extra = {"case": NAME, "size_m": args.size, "threads": threads, "toe": [toe_x, toe_y], "time_capped": time_capped(sim),
             "geostatic_seconds": start.seconds, "workflow": result,
             "failed_at_factor": result["failed_at_factor"], "outcome": result["outcome"],
             "ending": result.get("ending"), "checkpoints": journal.writes, "cost_estimate": cost,
             **factor_of_safety_figures(result), "wall_seconds": time.perf_counter() - wall}
    summary = write_report(report, out, extra, pictures_on=not args.no_pictures)
    if summary["outcome"] == "write_error":
        finish_run(out, summary)
        return summary
    summary["wall_seconds"] = time.perf_counter() - wall
    write_json(out / "summary.json", summary)
    finish_run(out, summary)
    run = summary["runout"]
    print(f"outcome {summary['outcome']}"
          + (f", factor of safety {summary['fos']:.3f} (between {summary['fos_bracket'][0]:.3f} and "
             f"{summary['fos_bracket'][1]:.3f}, {summary['fos_method']})" if summary["fos"] is not None else "")
          + failing_factor_words(summary)
          + f"; runout {_fmt(run.get('runout_distance_m'))} m beyond the toe, displaced area "
          f"{_fmt(run.get('displaced_area_m2'))} m^2; {summary['cracks']['broken']} crack elements broken; "
          f"{summary['wall_seconds']:.0f} s")
    say(f"wrote {out / 'summary.json'}, {out / 'slope.pvd'}" + ("" if args.no_pictures else f", {out / 'failure.png'}"))
    return summary


def _fmt(v) -> str:
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:.3g}"
