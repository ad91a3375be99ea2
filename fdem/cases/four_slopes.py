"""The four jointed slopes of cases.md A (seed 002): brick-pattern DFN, static start, strength reduction, runout.

Meshes a 15 m slope with its brick-pattern DFN, starts it in static equilibrium, reduces the
strength of crack elements, joints and contact until it fails, and follows the failure and
runout to rest (:mod:`fdem.workflow.slope`).

Writes to ``--out``: the mesh (``.msh``, and ``.npz`` for a GPU node without Gmsh: ``fdem run
FILE.toml --mesh low_fine.npz`` with the scene of ``--write-scene``), a PNG and a ``.vtu`` with crack elements as line cells),
``slope.pvd`` and ``slope_cracks.pvd`` (open them in ParaView), ``history.csv`` (energy ledger
and monitors per stage), ``summary.json`` (every stage and why it ended, the factor of safety
when searched, runout distance and volume, displacement percentiles, kinetic energy, cracks by
mode, fragments, events: :class:`fdem.results.report.RunReport`), ``events.csv`` and the pictures
``failure.png``, ``kinetic_energy.png``, ``cracks_by_mode.png`` (plus a PNG per output frame),
and checkpoints ``runout_start.npz`` (the failed state the runout starts from) and
``final_state.npz`` (:func:`fdem.solve.checkpoint.load_checkpoint`).

    fdem run four-slopes --out runs/low_fine                           # the workflow at size 0.5
    fdem run four-slopes --angle high --spacing coarse --size 0.3 --out runs/high_coarse
    fdem run four-slopes --fos 1.0 3.0 0.02 --out runs/fos             # factor of safety first
    fdem run four-slopes --max-steps 0 --out runs/mesh_only            # mesh and pictures only

Paper (seed 002): about 180,000 triangles (``--size 0.18``), geostatic equilibrium over 500,000
steps of 2 us, then 10 % strength reduction per 10,000 steps (``--reduction rate``). Here the
geostatic stage is a static solve with pre-loaded crack elements, and stages end by physics
(convergence, failure, rest), not by step counts.
"""
from __future__ import annotations

from fdem.io.messages import say, warn

import time
import warnings
from pathlib import Path

import numpy as np

from fdem.cases.common import (add_resume_options, add_write_scene_option, cap_simulated_time, case_parser, check_common, check_mesh_size,
                               finish_run, open_run, prepare_run, report_runout_cost, save_final_state,
                               set_threads, start_journal, stop_cleanly_on_signals, threads_for_mesh, time_capped,
                               use_density_scaling, write_case_scene, write_report)

import math
from fdem.mesh.topology import INTACT
from fdem.geometry.joint_sets import BrickSet
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import ground_surface, simple_slope
from fdem.physics.crack_properties import CrackProperties
from fdem.io.jsonable import write_json

__all__ = ["four_slope_property_sets", "RUN_EXTENTS", "EXTENTS_BEFORE_PINNING", "resolve_extents", "keep_settings_of_then", "FOUR_SLOPE_HEIGHT", "FOUR_SLOPE_FACE_ANGLE", "FOUR_SLOPE_JOINT_DIP",
           "FOUR_SLOPE_SPACING", "four_slope_geometry", "NAME", "CONTACT_PENALTY", "GRAVITY", "SIZE", "build",
           "ground_surface", "simulation", "scene", "main", "YOUNG", "POISSON", "DENSITY"]


def four_slope_property_sets() -> dict[int, CrackProperties]:
    """The paper's crack-element table (seed 002, Table 1; ``/shared/cases.md`` section A).

    Tag 0: intact rock bridges; tag 1: DFN fractures. The normal penalty "5.9 GPa.m" is read
    as Munjiza's penalty ``p_n = 5.9 GPa`` (= 10 E; ``k_n = p_n / L0``); the tangential
    "917 GPa/m" as a stiffness per unit area ``k_t = 917 GPa/m`` (see ``docs/cohesive.md``).
    """
    common = dict(p_n=5.9e9, k_t=917e9)
    return {
        INTACT: CrackProperties(f_t=50e3, c=100e3, phi=30.0, G_I=130.0, G_II=1300.0,
                                name="intact rock bridges", **common),
        1: CrackProperties(f_t=10e3, c=50e3, phi=11.0, G_I=13.0, G_II=130.0,
                           name="DFN joints", **common),
    }


FOUR_SLOPE_HEIGHT = 15.0


FOUR_SLOPE_FACE_ANGLE = 45.0


LOCAL_FALL_AREA = 0.1 * FOUR_SLOPE_HEIGHT ** 2 / (2.0 * math.tan(math.radians(FOUR_SLOPE_FACE_ANGLE)))
"""A tenth of the face wedge above the toe level (the triangle between the toe, the crest edge
and the toe level below it, ``H^2 / (2 tan beta)``): 11.25 m^2. A failure that comes to rest
with less moved than this is a block off the face (the high-angle coarse slope with a joint
through the toe loses a 2.7 m^2 toe block at F = 1.43); the slides of the four slopes move
180-560 m^2 (``docs/cases.md`` A). :class:`fdem.workflow.slope.SlopeWorkflow` ``local_fall_area``."""


FOUR_SLOPE_JOINT_DIP = {"low": 15.0, "high": 115.0}


FOUR_SLOPE_SPACING = {"fine": 1.0, "coarse": 5.0}


def four_slope_geometry(angle: str = "low", spacing: str | float = "fine", toe_length: float | None = None,
                     crest_length: float | None = None, base_depth: float | None = None,
                     min_joint_length: float = 0.05, joint_offset: float | None = None,
                     boundary_band: float | None = None) -> Geometry:
    """The jointed slopes of cases.md A (seed 002): H = 15 m, face 45 deg, brick fabric.

    ``angle`` is ``"low"`` (persistent joints at 15 deg, inclined) or ``"high"`` (115 deg,
    anti-inclined). ``spacing`` is ``"fine"`` (s = 1 m, s:H = 1:15), ``"coarse"`` (s = 5 m, s:H
    = 1:3 as in the paper's text; its figure caption says 1:5, pass ``3.0`` for that) or a
    number [m]. Cross joints are perpendicular at d = 2 s, offset half a block between layers.

    ``joint_offset`` places the persistent joints relative to the toe, as a fraction of the
    spacing measured along the joints' normal: 0 puts one through the toe, 0.5 puts the toe
    midway between two. The paper's text fixes it only through its results: in the fine models
    "a critical persistent joint crosses the slope toe" (0), and the coarse result depends on
    whether "the next persistent joint does not cross the slope toe", the case it reports for
    its thick layers (0.5). Default: 0 for ``"fine"``, 0.5 for ``"coarse"`` and 0 for a number.

    Assumed (the paper gives no extents): toe floor 3 H, crest plateau 2 H, base H below the toe.
    ``boundary_band`` [m]: keep the joints out of bands of intact rock that wide along the left
    and right boundaries (:class:`fdem.geometry.joint_sets.BandedSet`).
    """
    if angle not in FOUR_SLOPE_JOINT_DIP:
        raise ValueError(f"angle must be 'low' or 'high', got {angle!r}")
    s = FOUR_SLOPE_SPACING[spacing] if isinstance(spacing, str) else float(spacing)
    H = FOUR_SLOPE_HEIGHT
    toe_length = 3 * H if toe_length is None else toe_length
    base_depth = H if base_depth is None else base_depth
    slope = simple_slope(H, FOUR_SLOPE_FACE_ANGLE, crest_length=2 * H if crest_length is None else crest_length,
                         toe_length=toe_length, base_depth=base_depth, name="slope")
    # Layers start at the toe, so a persistent joint daylights through the toe as in the paper.
    toe = (toe_length, base_depth)
    dip = FOUR_SLOPE_JOINT_DIP[angle]
    n = (-math.sin(math.radians(dip)), math.cos(math.radians(dip)))
    if joint_offset is None:
        joint_offset = 0.5 if spacing == "coarse" else 0.0
    if not (math.isfinite(joint_offset) and 0.0 <= joint_offset < 1.0):
        raise ValueError(f"joint_offset must be a fraction of the spacing in [0, 1), got {joint_offset!r}")
    offset = toe[0] * n[0] + toe[1] * n[1] + joint_offset * s
    fabric = BrickSet(dip=dip, spacing=s, offset=offset, name=f"{angle}-angle brick fabric")
    if boundary_band is not None:
        from fdem.geometry.joint_sets import BandedSet

        fabric = BandedSet(fabric, boundary_band)
    return Geometry([slope], [fabric], min_joint_length=min_joint_length)


RUN_EXTENTS = {
    "low": {"crest_length": 4 * FOUR_SLOPE_HEIGHT, "toe_length": 6 * FOUR_SLOPE_HEIGHT,
            "base_depth": FOUR_SLOPE_HEIGHT, "boundary_band": None},
    "high": {"crest_length": 4 * FOUR_SLOPE_HEIGHT, "toe_length": 6 * FOUR_SLOPE_HEIGHT,
             "base_depth": FOUR_SLOPE_HEIGHT, "boundary_band": 5.0},
}
"""The extents [m] a run of the case uses unless told (``docs/cases.md`` A, "Boundaries"), chosen
so that the boundaries take no part: a wider model gives the same factor of safety within the
bisection's tolerance. Low angle: the persistent joint through the toe rises at 15 deg and meets
the crest 56 m behind the toe; with a crest of 2 H it met the right-hand roller instead, and the
whole package above it slid off that roller (1.0 m, 2026-11-24), so the crest is 4 H (0.5 m:
1.216 on 4 H, 1.206 on 6 H); the debris ran 44 m and off the end of a 3 H floor, so the floor is
6 H. High angle: joints dipping into the model break beside the right-hand roller already at
F = 1 (23 elements at 1.0 m), and 5 m bands of intact rock along the sides stop it there. The
first failing trial is a creep of the whole jointed ground behind the face, as far back as the
joints reach, so a longer crest holds it better: bisected at 1.0 m with elastic bands, the fine
slope gives 1.680, 1.820 and 1.801 on crests of 2, 4 and 6 H, the coarse slope 1.328, 1.578 and
1.547 (2026-11-29), so the crest is 4 H; the coarse debris reached the end of a 3 H floor (a
45.3 m front), so the floor is 6 H, as the low angle's. Part of the breakage at F = 1 is the
start, not the boundary: in the static start's uniaxial-strain state the high-angle persistent
joints (65 deg) are beyond Mohr-Coulomb at F = 1 below 15 m of cover
(:func:`fdem.reference.level_ground.slip_depth`), so under the crest they slip at F = 1 wherever
they are. The runs begun before 2026-11-29 on the high angle's crest of 2 H and floor of 3 H keep
them (their ``run.json`` names them). :func:`four_slope_geometry` keeps the smaller extents of its
own defaults (the verification tests and benchmarks use them)."""

EXTENTS_BEFORE_PINNING = {"crest_length": 2 * FOUR_SLOPE_HEIGHT, "toe_length": 3 * FOUR_SLOPE_HEIGHT,
                          "base_depth": FOUR_SLOPE_HEIGHT, "boundary_band": None}
"""The extents of runs begun before ``run.json`` named them (a resumed run keeps its mesh)."""

def resolve_extents(angle: str, given: dict, began_with: list[str] | None = None) -> dict:
    """The extents [m] of a run: ``given`` (``None`` where not given; a band of 0 is none), else
    :data:`RUN_EXTENTS` of ``angle``; for a resumed run whose first command line ``began_with``
    does not name an extent, the defaults of then (:data:`EXTENTS_BEFORE_PINNING`), so that it
    rebuilds the mesh its checkpoint belongs to. A bad value is a ``ValueError`` naming its option."""
    extents = {}
    for k, default in RUN_EXTENTS[angle].items():
        flag, v = "--" + k.replace("_", "-"), given.get(k)
        if v is None:
            v = EXTENTS_BEFORE_PINNING[k] if began_with is not None and flag not in began_with else default
        elif not (math.isfinite(v) and (v > 0 or k == "boundary_band" and v == 0)):
            raise ValueError(f"{flag} must be a positive number of metres{' (0: none)' if k == 'boundary_band' else ''},"
                             f" got {v}")
        extents[k] = None if k == "boundary_band" and not v else v
    return extents


NAME = "four-slopes"
# Table 1 of the paper (cases.md A): finite elements
YOUNG, POISSON, DENSITY = 0.59e9, 0.29, 2680.0
CONTACT_PENALTY = 10 * YOUNG  # Pa; Munjiza p = alpha E, alpha = 10 (verification.md guidance)
GRAVITY = 9.81
SIZE = 0.5


def build(angle: str = "low", spacing="fine", size: float = SIZE, refine: float | None = None,
          joint_offset: float | None = None, order: str | None = "hilbert", extents: dict | None = None):
    """Geometry, mesh and topology of one of the four slopes (``joint_offset``: where the
    persistent joints sit relative to the toe, :func:`four_slope_geometry`; ``order``: the mesh's
    memory order, :func:`fdem.mesh.triangulate.mesh_geometry`; ``None`` rebuilds the Gmsh-numbered
    mesh of runs made before renumbering, whose checkpoints belong to it; ``extents``: ``toe_length``,
    ``crest_length``, ``base_depth`` [m] of :func:`four_slope_geometry`)."""
    from fdem.mesh.triangulate import mesh_geometry
    from fdem.cases.four_slopes import four_slope_geometry
    from fdem.mesh.topology import build_topology

    geometry = four_slope_geometry(angle, spacing, joint_offset=joint_offset, **(extents or {}))
    mesh = mesh_geometry(geometry, size, refine_near_joints=refine, order=order)
    return geometry, mesh, build_topology(mesh)


def _tell_start_against_final_strength(cracks, geometry, workflow, tensile: str) -> dict:
    """Before any step: the start's static stress against the strength the schedule ends at
    (:func:`fdem.workflow.slope.start_against_strength`). The paper's rate always reaches its end
    (F = 3.33), and with Table 1's strengths the static stress under the level ground is beyond
    that strength below a few metres of cover: the schedule then fails the ground as well as the
    slope, which a user should know before hours of it (``docs/cases.md`` A)."""
    from fdem.workflow.slope import final_factor, start_against_strength

    check = start_against_strength(cracks, geometry.bodies[0], final_factor(workflow))
    level = check["level_ground"]
    if workflow.reduction == "rate" and level["over"]:
        cover = level["shallowest_cover_m"]
        depth = f" from {cover:.1f} m of cover down" if cover is not None else ""
        warn(f"at the schedule's end (F = {check['factor']:.3g}, f_t {tensile}) the static stress of the start is "
             f"beyond the strength of {check['over']:,} of {check['elements']:,} crack elements "
             f"({check['joints_over']:,} of {check['joints']:,} on joints); under the level ground more than one "
             f"slope height from the face, {level['over']:,} of {level['elements']:,}{depth}: the schedule fails the "
             f"ground as well as the slope (docs/cases.md A, the paper's schedule)")
    return check


def simulation(geometry, topology, out_dir: Path | None, pictures: bool = True, start: str = "static",
               progress: bool = True, elastic_band: float | None = None):
    """The slope model: rock triangles, crack elements (intact + DFN), contact, supports, gravity.

    ``elastic_band`` [m]: the intact crack elements within that distance of the left and right
    sides never soften or break (:func:`fdem.physics.side_bands.with_elastic_side_bands`); the
    geometry's side bands (``boundary_band``) keep the joints out of the same width.

    ``start="static"`` (default) puts it in static equilibrium with pre-loaded crack elements
    (:func:`fdem.solve.geostatic.geostatic_start`); ``"k0"`` gives the triangles the approximate
    laterally confined stress ``sigma_xx = K0 sigma_yy`` of a flat ground instead (not in
    equilibrium under the face: it needs a damped settling stage). Returns ``(sim, cracks)``."""
    from fdem.physics.cracks import CrackSet
    from fdem.cases.four_slopes import four_slope_property_sets
    from fdem.physics.contact import ContactSet
    from fdem.solve.geostatic import geostatic_start
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model, geostatic_stress
    from fdem.solve.simulation import Simulation

    model = Model(topology, ElasticMaterial(young=YOUNG, poisson=POISSON, density=DENSITY))
    model.set_gravity(0.0, -GRAVITY)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    sets, tags = four_slope_property_sets(), None
    if elastic_band:
        from fdem.physics.side_bands import with_elastic_side_bands

        tags, sets, _ = with_elastic_side_bands(topology, sets, elastic_band)
    cracks = CrackSet(topology, sets, contact_penalty=CONTACT_PENALTY, tags=tags)
    if start == "static":
        geostatic_start(model, cracks)
    elif start == "k0":
        model.set_initial_stress(geostatic_stress(DENSITY, GRAVITY, surface=ground_surface(geometry.bodies[0]),
                                                  poisson=POISSON))
    else:
        raise ValueError(f"start must be 'static' or 'k0', got {start!r}")
    contact = ContactSet(topology, CONTACT_PENALTY, friction_angle=30.0, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], out_dir=out_dir, name="slope", pictures=pictures,
                     progress=progress)
    return sim, cracks


def scene(angle: str = "low", spacing="fine", size: float = SIZE, refine: float | None = None,
          joint_offset: float | None = None, workflow=None, extents: dict | None = None,
          tensile: str | None = None, elastic_band: float | None = None) -> dict:
    """One of the four slopes as a scene file's contents (``fdem run four-slopes --write-scene
    FILE``): the outline, brick fabric, rock, the paper's crack table, contact, supports and
    ``workflow`` (a :class:`fdem.workflow.slope.SlopeWorkflow`) of :func:`build` and
    :func:`simulation`, so that ``fdem run FILE`` runs the same model."""
    import dataclasses

    geo = four_slope_geometry(angle, spacing, joint_offset=joint_offset, **(extents or {}))
    fabric = geo.joint_sets[0]
    band = getattr(fabric, "band", None)
    fabric = getattr(fabric, "joints", fabric)  # the brick set inside a BandedSet
    H = FOUR_SLOPE_HEIGHT
    ext = {"crest_length": 2 * H, "toe_length": 3 * H, "base_depth": H}
    ext.update({k: v for k, v in (extents or {}).items() if v is not None and k != "boundary_band"})
    cracks = {str(tag): {k: v for k, v in dataclasses.asdict(p).items() if v is not None}
              for tag, p in four_slope_property_sets().items()}
    wf = {}
    if workflow is not None:
        wf = {"reduction": workflow.reduction, "fos": list(workflow.fos) if workflow.fos else None,
              "runout_time": workflow.runout_time, "runout_dt_fraction": workflow.runout_dt_fraction,
              **({"runout_step": workflow.runout_step} if workflow.runout_step != "bound" else {}),
              **({"equilibrium_ratio": workflow.equilibrium_ratio} if workflow.equilibrium_ratio != 1e-4 else {}),
              **({"equilibrium_hold": workflow.equilibrium_hold} if workflow.equilibrium_hold else {}),
              **({"step_time": workflow.step_time} if workflow.step_time else {}),
              **({"trial_end": workflow.trial_end} if workflow.trial_end is not None else {}),
              **({"local_fall_area": workflow.local_fall_area} if workflow.local_fall_area else {})}
    if tensile is not None:
        wf["reduce_tensile"] = tensile == "reduced"
    return {
        "scene": {"name": f"four-slopes-{angle}-{spacing}", "size": size, "refine_near_joints": refine,
                  "description": f"the {angle}-angle {spacing} slope of the four-slope paper (docs/cases.md A)",
                  "min_joint_length": geo.min_joint_length},
        "slope": {"kind": "simple", "height": H, "face_angle": FOUR_SLOPE_FACE_ANGLE, **ext},
        "joints": [{"kind": "brick", "name": fabric.name, "dip": fabric.dip, "spacing": fabric.spacing,
                    "offset": fabric.offset, **({"side_band": band} if band is not None else {})}],
        "rock": {"young": YOUNG, "poisson": POISSON, "density": DENSITY,
                 **({"elastic_side_bands": elastic_band} if elastic_band else {})},
        "cracks": cracks,
        "contact": {"penalty": CONTACT_PENALTY, "friction_angle": 30.0},
        "supports": {"bottom": "fixed", "left": "fix-x", "right": "fix-x"},
        "gravity": {"g": GRAVITY},
        "workflow": {"kind": "strength-reduction", **wf},
    }


def local_fall_line(fall: dict) -> str:
    """One line on a local fall of ``summary.json`` ``local_falls`` (its area is ``None`` when a
    run resumed from a journal written before the area was kept)."""
    area = "an unrecorded area" if fall.get("area_m2") is None else f"{fall['area_m2']:.3g} m^2"
    return (f"local fall at F = {fall['factor']:.3f}: {area} moved (at most {fall['max_displacement_m']:.3g} m), "
            f"at rest at t = {fall['at_rest_s']:.4g} s; the reduction carried on")


def keep_settings_of_then(args, began_with: list[str] | None) -> None:
    """Give a resumed run the settings it began with where its ``run.json`` does not name them.

    A run's options are pinned into its ``run.json`` when it begins; a run begun before an option
    existed ran with the behaviour of then, and carrying it on with today's default would change
    its physics half-way. ``began_with`` is the recorded argv (``None`` for a new run, which
    takes today's defaults): without ``--tensile`` f_t was divided by F in every mode; without
    ``--runout-dt-fraction`` the runout stepped at 0.4 of the stable step; without
    ``--local-fall-area`` any fall ended the reduction steps (0); without ``--trial-end`` a search's
    capped trial failed (``cap``, the default before 2026-12-08). A new run under the damped
    steps gets :data:`LOCAL_FALL_AREA`.
    """
    if began_with is not None:
        if "--trial-end" not in began_with:
            args.trial_end = "cap"
        if "--tensile" not in began_with:
            args.tensile = "reduced"
        if "--runout-dt-fraction" not in began_with:
            args.runout_dt_fraction = 0.4
    if args.local_fall_area is None and args.reduction == "steps":
        then = began_with is not None and "--local-fall-area" not in began_with
        args.local_fall_area = 0.0 if then else LOCAL_FALL_AREA


def main(argv=None) -> dict:
    parser = case_parser(__doc__, name=NAME, out="runs/four_slopes", size=SIZE,
                         size_help=f"element size [m] (default {SIZE}; 0.18 gives ~180k triangles)")
    parser.add_argument("--angle", choices=["low", "high"], default="low")
    parser.add_argument("--spacing", default="fine", help="'fine' (s = 1 m), 'coarse' (s = 5 m) or metres")
    parser.add_argument("--joint-offset", type=float, default=None, metavar="FRACTION",
                        help="persistent joints relative to the toe, a fraction of the spacing: 0 puts one "
                             "through the toe, 0.5 the toe midway (default: 0 fine, 0.5 coarse)")
    parser.add_argument("--refine", type=float, default=None, help="element size factor on joints, e.g. 0.5")
    low, high = RUN_EXTENTS["low"], RUN_EXTENTS["high"]
    for name, what in (("crest-length", "crest plateau behind the face"), ("toe-length", "floor in front of the toe"),
                       ("base-depth", "rock below the toe")):
        key = name.replace("-", "_")
        parser.add_argument(f"--{name}", type=float, default=None, metavar="METRES",
                            help=f"{what} [m] (default {low[key]:g} low angle, {high[key]:g} high angle: far enough "
                                 f"that the boundaries take no part; larger to show it)")
    parser.add_argument("--boundary-band", type=float, default=None, metavar="METRES",
                        help=f"keep the joints out of bands of intact rock this wide along the left and right "
                             f"boundaries, so that slip at the rollers is not part of the mechanism (default: none "
                             f"low angle, {high['boundary_band']:g} high angle; 0 for none)")
    parser.add_argument("--elastic-band", action="store_true",
                        help="make the side bands elastic: their crack elements never soften or break, a far "
                             "field that carries the rollers' load, instead of intact rock with its strength "
                             "(shows whether the boundaries take part; needs a band)")
    parser.add_argument("--reduction", choices=["steps", "rate", "none"], default="steps",
                        help="strength reduction in damped steps of 10 %% (default), at the paper's rate, or none: "
                             "the --fos search is the whole analysis (a bracket for a convergence or boundary study, "
                             "without the schedule after it)")
    parser.add_argument("--tensile", choices=["reduced", "kept"], default=None,
                        help="whether strength reduction divides the tensile strength f_t by F too (default: "
                             "reduced with --reduction steps, kept with --reduction rate: the paper reduces the "
                             "'cohesive and frictional strength')")
    parser.add_argument("--fos", type=float, nargs=3, metavar=("LOWER", "UPPER", "TOL"), default=None,
                        help="search the factor of safety in [LOWER, UPPER] to TOL first")
    parser.add_argument("--equilibrium-ratio", type=float, default=1e-4, metavar="RATIO",
                        help="unbalanced-force ratio that counts as equilibrium in every damped stage and "
                             "factor-of-safety trial (default 1e-4; each model raises it to 10 times its round-off "
                             "floor, which grows as the mesh refines: give the finest model's limit to judge every "
                             "size of a convergence study by one rule, docs/cases.md A)")
    parser.add_argument("--equilibrium-hold", type=float, default=0.0, metavar="T",
                        help="response times the ratio must keep below its limit before a factor-of-safety trial "
                             "or reduction step counts as converged (default 0: the first check; a slope near its "
                             "factor creeps with its ratio dipping below a raised limit and rising again)")
    parser.add_argument("--step-time", type=float, default=None, metavar="SECONDS",
                        help="cap of every damped stage and factor-of-safety trial [s of simulated time] (default 5 "
                             "response times, printed with the cost estimate); a trial that reaches its cap is "
                             "followed to rest (--trial-end)")
    parser.add_argument("--trial-end", choices=["cap", "rest"], default=None,
                        help="what a factor-of-safety trial that reaches its cap (--step-time) says: 'rest' "
                             "(default) it is followed undamped, as the damped steps follow a stage that did not "
                             "settle, and stands if it comes to rest having moved less than the failure "
                             "displacement: the factor of a slope that creeps and stops, not of the cap; 'cap' it "
                             "fails, quicker and the same for a slope that slides")
    parser.add_argument("--runout-time", type=float, default=None, help="cap on the runout stage [s of simulated time]")
    parser.add_argument("--runout-dt-fraction", type=float, default=0.8, metavar="FACTOR",
                        help="time-step factor of the runout stage (default 0.8; 0.4 takes twice the steps "
                             "for the same runout within its spread, and more accurate impact energies, "
                             "docs/pareto.md)")
    parser.add_argument("--runout-step", choices=["bound", "measured"], default="bound",
                        help="what --runout-dt-fraction multiplies: the solver's bound on the critical step "
                             "(default), or the critical step measured on the model when the runout starts and "
                             "again every response time (1.26-1.63 times the bound here: 1.25-1.4 times fewer runout steps; CPU only; "
                             "docs/benchmarks.md)")
    parser.add_argument("--local-fall-area", type=float, default=None, metavar="M2",
                        help="in the reduction steps, a failure that comes to rest with less than this area "
                             "[m^2] moved 1 %% of the model height (all falls so far together) is a block off "
                             "the face: the reduction carries on (default: a tenth of the face wedge above the "
                             f"toe level, H^2 / (20 tan(face angle)) = {LOCAL_FALL_AREA:g} m^2; 0: any fall ends "
                             "the reduction)")
    parser.add_argument("--max-steps", type=int, default=None, choices=[0],
                        help="0: mesh and pictures only (stages end by physics, not by step counts: "
                             "--max-time caps the simulated time)")
    parser.add_argument("--rigid-blocks", action="store_true",
                        help="first print the rigid-block factor of safety and mechanism of the same joints "
                             "(seconds; docs/rigid_blocks.md)")
    add_resume_options(parser)
    add_write_scene_option(parser)
    args = prepare_run(parser, parser.parse_args(argv), argv, NAME, open_now=False)
    check_common(parser, args)
    if not 0.0 < args.runout_dt_fraction <= 1.0:
        parser.error(f"--runout-dt-fraction must lie in (0, 1], got {args.runout_dt_fraction}")
    if args.runout_time is not None and not (math.isfinite(args.runout_time) and args.runout_time > 0):
        parser.error(f"--runout-time must be a positive number of simulated seconds, got {args.runout_time}")
    if args.refine is not None and not (math.isfinite(args.refine) and 0 < args.refine <= 1):
        parser.error(f"--refine (element size factor on joints) must lie in (0, 1], got {args.refine}")
    if args.joint_offset is not None and not (math.isfinite(args.joint_offset) and 0 <= args.joint_offset < 1):
        parser.error(f"--joint-offset must be a fraction of the spacing in [0, 1), got {args.joint_offset}")
    if args.local_fall_area is not None and not (math.isfinite(args.local_fall_area) and args.local_fall_area >= 0):
        parser.error(f"--local-fall-area must be a number of square metres >= 0 (0: any fall ends the reduction), "
                     f"got {args.local_fall_area}")
    resuming = getattr(args, "resume", None) is not None
    began_with = list(args.run_record.get("argv", [])) + list(args.run_record.get("resumed_with", []))
    if args.local_fall_area is not None and args.reduction != "steps":
        parser.error(f"--local-fall-area carries the reduction steps on after a block falls off the face; "
                     f"--reduction {args.reduction} has no steps: leave it out")
    if args.reduction == "none" and not args.fos:
        parser.error("--reduction none makes the factor-of-safety search the whole analysis: give --fos LOWER UPPER TOL")
    keep_settings_of_then(args, began_with if resuming else None)
    tensile = args.tensile or ("kept" if args.reduction == "rate" else "reduced")
    try:
        extents = resolve_extents(args.angle, {k: getattr(args, k) for k in EXTENTS_BEFORE_PINNING},
                                  began_with if resuming else None)
    except ValueError as err:
        parser.error(str(err))
    if args.elastic_band and extents["boundary_band"] is None:
        parser.error("--elastic-band makes the side bands elastic, and this run has none: give --boundary-band "
                     "METRES (the high angle has 5 m by default)")
    if args.elastic_band and extents["boundary_band"] < args.size:
        parser.error(f"--elastic-band: side bands of {extents['boundary_band']:g} m are narrower than one element "
                     f"(--size {args.size:g} m) and would hold no crack element: widen --boundary-band")
    if not resuming:
        pinned = [("--tensile", tensile), ("--runout-dt-fraction", str(args.runout_dt_fraction)),
                  ("--runout-step", args.runout_step)] + (
            [("--local-fall-area", f"{args.local_fall_area:g}")] if args.local_fall_area is not None else []) + (
            [("--trial-end", args.trial_end or "rest")] if args.fos else []) + [
            ("--" + k.replace("_", "-"), f"{v or 0:g}") for k, v in extents.items()]
        args.run_record["argv"] = list(args.run_record["argv"]) + [
            a for flag, value in pinned if flag not in args.run_record["argv"] for a in (flag, value)]
    from fdem.workflow.slope import SlopeWorkflow

    try:  # the workflow's settings are checked now, not after hours of stages
        workflow = SlopeWorkflow(reduction=args.reduction, fos=tuple(args.fos) if args.fos else None,
                                 runout_time=args.runout_time, runout_dt_fraction=args.runout_dt_fraction,
                                 runout_step=args.runout_step, equilibrium_ratio=args.equilibrium_ratio,
                                 equilibrium_hold=args.equilibrium_hold, step_time=args.step_time,
                                 local_fall_area=args.local_fall_area or None, trial_end=args.trial_end)
    except ValueError as err:
        parser.error(str(err))
    if args.runout_step == "measured" and getattr(args, "backend", "cpu") != "cpu":
        parser.error(f"--runout-step measured probes the model on the host, and --backend {args.backend} steps on "
                     "the GPU: run on the CPU (--backend cpu), or start the run with --runout-step bound")
    set_threads(args.threads)
    try:
        spacing = args.spacing if args.spacing in ("fine", "coarse") else float(args.spacing)
    except ValueError:
        parser.error(f"--spacing must be 'fine', 'coarse' or a number of metres, got {args.spacing!r}")
    if args.write_scene is not None:
        return write_case_scene(parser, NAME, scene(args.angle, spacing, args.size, args.refine, args.joint_offset,
                                                    workflow, extents, tensile,
                                                    elastic_band=extents["boundary_band"] if args.elastic_band
                                                    else None), args.write_scene, argv)

    from fdem.geometry.polygons import slope_toe
    from fdem.mesh.quality import quality_report
    from fdem.mesh.preview import plot_mesh_png, write_mesh_vtu
    from fdem.results.report import RunReport
    from fdem.workflow.slope import factor_of_safety_figures, run_slope_workflow

    try:
        check_mesh_size(parser, four_slope_geometry(args.angle, spacing, joint_offset=args.joint_offset, **extents),
                        args.size)
    except ValueError as err:  # a bad geometry option: say what is wrong, no traceback
        parser.error(str(err))
    open_run(parser, args, NAME)  # every option checked: now the folder and run.json
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            geometry, mesh, topo = build(args.angle, spacing, args.size, args.refine, args.joint_offset,
                                         extents=extents)
        except ValueError as err:  # bad input: say what is wrong, no traceback
            parser.error(str(err))
    for w in caught:
        warn(str(w.message))
    if args.rigid_blocks:  # seconds, beside the FDEM factor of safety that follows
        from fdem.blocks.slope import print_rigid_blocks
        print_rigid_blocks(geometry, four_slope_property_sets(), DENSITY * GRAVITY, args.out)
    elapsed = time.perf_counter() - t0
    threads = threads_for_mesh(args.threads, topo.n_triangles)
    report = quality_report(mesh)
    say(f"meshed and exploded in {elapsed:.2f} s: {topo.n_triangles} triangles, {topo.n_cracks} crack elements "
          f"({int((topo.crack_tag > 0).sum())} on joints); {threads} thread(s)")
    say(report)
    out = args.out
    name = f"{args.angle}_{args.spacing}"
    mesh.save(out / f"{name}.msh")
    mesh.save(out / f"{name}.npz")  # the same mesh for a machine without Gmsh or meshio: --mesh on a scene
    vtu = write_mesh_vtu(topo, out / f"{name}_mesh.vtu")
    written = [vtu]
    if not args.no_pictures:
        written.append(plot_mesh_png(topo, out / f"{name}_mesh.png",
                                     title=f"{args.angle}-angle {args.spacing} slope: {topo.n_triangles} triangles"))
    say("wrote " + ", ".join(map(str, written)))
    joint_offset = args.joint_offset if args.joint_offset is not None else 0.5 if spacing == "coarse" else 0.0
    summary = {"case": NAME, "scene": name, "size_m": args.size, "joint_offset": joint_offset, "tensile": tensile,
               "extents_m": dict(extents),
               "side_bands": None if extents["boundary_band"] is None else "elastic" if args.elastic_band else "rock",
               "n_triangles": topo.n_triangles, "threads": threads, "seconds_mesh_and_topology": elapsed, "n_crack_elements": topo.n_cracks,
               "n_joint_crack_elements": int((topo.crack_tag > 0).sum()), "quality": report.as_dict()}

    if args.max_steps != 0:
        sim, cracks = simulation(geometry, topo, out, pictures=not args.no_pictures, progress=not args.quiet,
                                 elastic_band=extents["boundary_band"] if args.elastic_band else None)
        cracks.interfaces.reduce_tensile = tensile == "reduced"
        summary["start_at_final_factor"] = _tell_start_against_final_strength(cracks, geometry, workflow, tensile)
        stop_cleanly_on_signals()  # after meshing: Gmsh installs its own handlers
        toe_x, toe_y = slope_toe(geometry.bodies[0])
        run_report = RunReport(sim, toe_x=toe_x, floor_y=toe_y)
        cap_simulated_time(sim, args.max_time)
        use_density_scaling(sim, args.density_scaling)
        say(f"time step {sim.dt:.3g} s (critical limits: "
              + ", ".join(f"{k} {v:.3g} s" for k, v in sim.critical_dt()[1].items()) + ")")
        summary["cost_estimate"] = report_runout_cost(parser, sim, args, workflow)
        t1 = time.perf_counter()
        journal = start_journal(sim, args)
        try:
            result = run_slope_workflow(sim, workflow, out_dir=out, journal=journal)
            save_final_state(sim, out, result["outcome"])
        finally:
            sim.close()
        summary.update({"workflow": result, "outcome": result["outcome"], "ending": result.get("ending"),
                        "checkpoints": journal.writes,
                        "failed_at_factor": result["failed_at_factor"], "local_falls": result.get("local_falls", []),
                        **factor_of_safety_figures(result),
                        "toe": [toe_x, toe_y], "time_capped": time_capped(sim),
                        "seconds_simulation": time.perf_counter() - t1})
        summary = write_report(run_report, out, summary, pictures_on=not args.no_pictures)
        if summary["outcome"] == "write_error":
            finish_run(out, summary)
            return summary
        write_json(out / "summary.json", summary)  # before the printing below: nothing printed can lose it
        for st in result["stages"]:
            say(f"  {st['name']:>20s}: {st['reason']:9s} t {st['t_start']:.3f}-{st['t_end']:.3f} s, "
                  f"{st['steps']} steps, {st['wall_seconds']:.1f} s wall, max disp {st['max_displacement']:.3g} m")
        print(f"outcome: {summary['outcome']}"
              + (f" at F = {summary['failed_at_factor']:.3f}" if summary["failed_at_factor"] else "")
              + (f"; factor of safety {summary['fos']:.3f} (between {summary['fos_bracket'][0]:.3f} and "
                 f"{summary['fos_bracket'][1]:.3f}, {summary['fos_method']})" if summary.get("fos") else ""))
        if (result.get("fos") or {}).get("error"):  # the bracket's end contradicted it: which way to move it
            print(f"factor-of-safety search: {result['fos']['error']}")
        for fall in summary["local_falls"]:
            print(local_fall_line(fall))
        print(f"ran {sim.state.step} steps ({sim.state.time:.4g} s) in {summary['seconds_simulation']:.1f} s; "
              f"{summary['cracks']['broken']} crack elements broken; max displacement "
              f"{summary['runout']['max_displacement_m']:.3g} m; see {out / 'slope.pvd'}")
    write_json(out / "summary.json", summary)
    finish_run(out, summary)
    say(f"wrote {out / 'summary.json'}")
    return summary
