"""Planar slope failure (verification.md): the factor of safety of a slope with one persistent
joint daylighting in the face, by strength reduction with the full solver, against the
Hoek-Bray limit-equilibrium value (:func:`fdem.reference.hoek_bray.planar_fos`).

The scene (:func:`planar_failure_simulation`) is built so that the limit-equilibrium
assumptions hold: a rigid block on a perfectly plastic plane.

* Rock triangles are elastic; intact crack elements (tag 0) are so strong that the rock mass
  never yields, even at the largest reduction tried: failure can only follow the joints.
* The sliding plane (tag 1) has the Mohr-Coulomb strength ``c + sigma_n tan(phi)`` of the
  limit-equilibrium plane and fracture energies so large that its cohesion softens over a
  slip (``G_II / (c Zbar)``, tens of metres) far beyond the slip at which a trial is judged to
  fail: the strength stays at its peak along the whole plane while the block slides, so the
  progressive failure of a brittle joint (which would give a lower factor of safety) is ruled
  out and the plane behaves perfectly plastic, as limit equilibrium assumes.
* The tension crack (tag 2) has no cohesion and a near-zero tensile strength, so it carries
  no force once the block moves away from it (Hoek and Bray's dry crack).
* Penalties ``p_n = p_t = 5 E`` (the tangential penalty tied to the normal one): the elastic
  slip before the peak, ``c L / p_t``, is about a micrometre, far below any slip that decides
  a trial, and the stable step is twice what ``10 E`` allows. Contact (same penalty, below
  Munjiza's ``alpha = 10..100``) carries nothing here: the joints never break and the block
  slides out into air.
* Supports: bottom fixed, sides on rollers; a geostatic start (:func:`fdem.solve.geostatic.geostatic_start`)
  puts the slope in static equilibrium before any reduction.
* Each strength-reduction trial (:func:`trial_stage`) is damped by mass-proportional damping
  critical for the slope's fundamental mode and judged by convergence of the unbalanced-force
  ratio within a few response times (see there).

    python cases/planar_failure.py --out runs/planar --size 0.7
"""
from __future__ import annotations

from fdem.io.messages import say

import argparse
from fdem.io.jsonable import write_json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fdem.cases.common import check_common, finish_run, prepare_run, set_threads
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.contact import ContactSet
from fdem.solve.geostatic import geostatic_start
from fdem.reference.hoek_bray import planar_fos
from fdem.physics.elastic import ElasticMaterial
from fdem.mesh.triangulate import mesh_geometry
from fdem.solve.model import Model
from fdem.solve.damping import Damping
from fdem.solve.simulation import Simulation
from fdem.workflow.stages import Convergence, Failure, Stage, response_time
from fdem.workflow.fos import DEFAULT_MAX_TRIALS, MIN_RELATIVE_TOL, BracketError, factor_of_safety
from fdem.mesh.topology import build_topology

from fdem.geometry.joint_sets import SegmentSet
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import simple_slope

__all__ = ["planar_slope_geometry", "G", "UNIT_WEIGHT", "PENALTY", "HEIGHT", "GEOMETRIES", "PlanarScene",
           "property_sets", "analytic", "planar_failure_simulation", "block_nodes", "trial_stage", "run_case",
           "plot", "parse_args", "check_search", "main", "YOUNG", "POISSON", "DENSITY", "JOINT_COHESION", "JOINT_FRICTION"]


def planar_slope_geometry(height: float, face_angle: float, plane_angle: float, crest_length: float | None = None,
                       toe_length: float | None = None, base_depth: float | None = None,
                       tension_crack_offset: float | None = None, toe_step: float | None = None) -> Geometry:
    """A slope with one persistent joint daylighting in the face: the planar-failure verification
    problem (Hoek & Bray 1981, ch. 7; Wyllie & Mah 2004, ch. 6; :mod:`fdem.reference.hoek_bray`).

    ``height`` H [m] is the face above the daylight point ``D`` of the plane, ``face_angle``
    psi_f and ``plane_angle`` psi_p [deg] (``psi_p < psi_f``). Joint set 1 is the sliding plane,
    from ``D`` up at psi_p to the horizontal upper surface, or, with ``tension_crack_offset`` b
    [m], to the foot of a vertical tension crack b behind the crest: joint set 2, of depth
    ``z = H - (H cot psi_f + b) tan psi_p``.

    ``toe_step`` [m] (default ``H/5``) continues the face below ``D`` down to the toe floor. The
    down-dip direction from ``D`` points into air only there: with the plane daylighting at the
    very toe of a horizontal floor (``toe_step=0``) the block's tip is driven into the floor
    rock, which then holds the block over a finite slip; limit equilibrium assumes it free to
    slide out.

    Assumed extents, compact since the block's equilibrium does not depend on them: toe floor
    ``toe_length`` (default 0.3 H) left of the toe, base ``base_depth`` (default 0.3 H) below
    it, and a crest plateau reaching ``crest_length`` (default H/2 beyond the point where the
    plane or the crack meets the upper surface) behind the crest. ``D`` lies at
    ``(toe_length + toe_step cot psi_f, base_depth + toe_step)``.
    """
    H, pf, pp = float(height), float(face_angle), float(plane_angle)
    if not H > 0:
        raise ValueError(f"planar slope: height must be positive, got {height} m")
    if not 0 < pp < pf <= 90:
        raise ValueError(f"planar slope: need 0 < plane angle < face angle <= 90 deg for the plane to daylight "
                         f"in the face, got plane {plane_angle} deg, face {face_angle} deg")
    step = 0.2 * H if toe_step is None else float(toe_step)
    if step < 0:
        raise ValueError(f"planar slope: toe_step must be >= 0, got {toe_step} m")
    cot_f = 0.0 if pf == 90 else 1.0 / math.tan(math.radians(pf))
    cot_p, tan_p = 1.0 / math.tan(math.radians(pp)), math.tan(math.radians(pp))
    run_above = H * cot_f                      # face run from D to the crest
    if tension_crack_offset is None:
        reach = H * cot_p                      # plane meets the upper surface this far from D
    else:
        b = float(tension_crack_offset)
        reach = run_above + b
        if b <= 0 or reach * tan_p >= H:
            raise ValueError(f"planar slope: the tension crack must stand behind the crest (b > 0) and reach the "
                             f"plane below the surface (b < {H * cot_p - run_above:.6g} m), got b = {b} m")
    toe_length = 0.3 * H if toe_length is None else float(toe_length)
    base_depth = 0.3 * H if base_depth is None else float(base_depth)
    crest_length = (reach - run_above) + 0.5 * H if crest_length is None else float(crest_length)
    if crest_length <= reach - run_above:
        raise ValueError(f"planar slope: crest_length {crest_length} m must exceed "
                         f"{reach - run_above:.6g} m, where the joints meet the upper surface")
    if step > 0:
        slope = simple_slope(H + step, pf, crest_length=crest_length, toe_length=toe_length,
                             base_depth=base_depth, name="slope")
        dx, dy = toe_length + step * cot_f, base_depth + step
    else:
        slope = simple_slope(H, pf, crest_length=crest_length, toe_length=toe_length, base_depth=base_depth,
                             name="slope")
        dx, dy = toe_length, base_depth
    end = (dx + reach, dy + reach * tan_p)
    sets = [SegmentSet([[dx, dy, end[0], end[1]]], name="sliding plane")]
    if tension_crack_offset is not None:
        sets.append(SegmentSet([[end[0], end[1], end[0], dy + H]], name="tension crack"))
    return Geometry([slope], sets)


G = 9.81
UNIT_WEIGHT = 25e3                              # gamma [N/m^3]
YOUNG, POISSON, DENSITY = 5e9, 0.25, UNIT_WEIGHT / G
PENALTY = 5 * YOUNG                             # p_n = p_t = contact penalty [Pa], alpha = 5
HEIGHT = 10.0                                   # H above the daylight point [m]
JOINT_COHESION, JOINT_FRICTION = 20e3, 30.0     # c [Pa], phi [deg] of the sliding plane

GEOMETRIES = {
    "no_crack": dict(face_angle=60.0, plane_angle=35.0, tension_crack_offset=None),
    "tension_crack": dict(face_angle=60.0, plane_angle=35.0, tension_crack_offset=2.0),
    "flat_plane": dict(face_angle=50.0, plane_angle=30.0, tension_crack_offset=None),
}
"""The verification geometries, all H = 10 m, c = 20 kPa, phi = 30 deg, gamma = 25 kN/m^3."""


@dataclass(frozen=True)
class PlanarScene:
    """What :func:`planar_failure_simulation` built."""

    sim: Simulation
    cracks: CrackSet
    contact: ContactSet
    block_nodes: np.ndarray       # exploded nodes of the sliding block
    geostatic: object             # fdem.solve.geostatic.GeostaticReport
    n_triangles: int


def property_sets(cohesion: float = JOINT_COHESION, friction_angle: float = JOINT_FRICTION,
                  penalty: float = PENALTY, slip_to_soften: float = 50.0) -> dict[int, CrackProperties]:
    """Crack-element properties: tag 0 intact rock (never yields), tag 1 the sliding plane, tag 2
    the tension crack.

    Plane: ``f_t = c / 10`` (a tension cut-off; the plane is in compression wherever the block
    rests on it), ``G_II = c Zbar d`` with ``Zbar = 0.386`` the area under the Munjiza softening
    curve, so the cohesion is spent only after a slip ``d = slip_to_soften`` [m]: perfectly
    plastic over the centimetres a failing trial slides. Intact rock: ``f_t = c = 100 MPa``,
    two orders above the largest geostatic stress (``gamma H_total`` about 0.4 MPa) even when
    divided by a reduction factor of 10. Tension crack: ``c = 0``, ``f_t = 100 Pa``.
    """
    zbar = 0.38631
    common = dict(p_n=penalty, p_t=penalty)
    strong = 100e6
    return {
        0: CrackProperties(f_t=strong, c=strong, phi=45.0, G_I=1e8, G_II=1e8, name="intact rock", **common),
        1: CrackProperties(f_t=cohesion / 10, c=cohesion, phi=friction_angle,
                           G_I=cohesion / 10 * zbar * slip_to_soften, G_II=cohesion * zbar * slip_to_soften,
                           name="sliding plane", **common),
        2: CrackProperties(f_t=100.0, c=0.0, phi=friction_angle, G_I=1.0, G_II=0.0, name="tension crack",
                           **common),
    }


def analytic(face_angle: float, plane_angle: float, tension_crack_offset: float | None = None,
             height: float = HEIGHT, cohesion: float = JOINT_COHESION, friction_angle: float = JOINT_FRICTION):
    """The Hoek-Bray factor of safety of the scene (dry)."""
    return planar_fos(height, face_angle, plane_angle, cohesion, friction_angle, UNIT_WEIGHT,
                      tension_crack_offset=tension_crack_offset)


def planar_failure_simulation(geometry, size: float, cohesion: float = JOINT_COHESION,
                              friction_angle: float = JOINT_FRICTION, penalty: float = PENALTY,
                              out_dir: Path | None = None, pictures: bool = False,
                              progress: bool = False) -> PlanarScene:
    """Mesh ``geometry`` (a :func:`fdem.cases.planar_failure.planar_slope_geometry`) at ``size`` [m] and build the
    simulation: elastic rock, crack elements (:func:`property_sets`), contact with the joint's
    friction, bottom fixed, sides on rollers, gravity, and a static geostatic start."""
    topo = build_topology(mesh_geometry(geometry, size))
    model = Model(topo, ElasticMaterial(young=YOUNG, poisson=POISSON, density=DENSITY))
    model.set_gravity(0.0, -G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    # Element damping (0.1 of each triangle's critical value, docs/damping.md): without it the
    # tension-crack slope rang at the crack-element frequencies, which the fundamental-mode
    # damping of the trials does not reach, and stable trials near the limit failed to converge
    # (F = 1.25 on the 0.5 m mesh: unbalanced-force ratio 0.27 after 5 T; with it: converged in 1 T).
    model.set_element_damping()
    # the property sets of the joint sets this geometry has (no tension crack in the no-crack
    # geometries); a set whose joints all fell below the geometry's min_joint_length (cross
    # joints of an ensemble's DFN at a coarse size) draws a warning, not an error
    joint_tags = range(1, len(geometry.joint_sets) + 1)
    sets = {t: p for t, p in property_sets(cohesion, friction_angle, penalty).items() if t == 0 or t in joint_tags}
    cracks = CrackSet(topo, sets, contact_penalty=penalty, absent_ok=joint_tags)
    report = geostatic_start(model, cracks)
    contact = ContactSet(topo, penalty, friction_angle=friction_angle, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], out_dir=out_dir, name="planar", pictures=pictures,
                     progress=progress)
    return PlanarScene(sim, cracks, contact, block_nodes(topo), report, topo.n_triangles)


def block_nodes(topo) -> np.ndarray:
    """Exploded nodes of the sliding block: the triangles joined to the face above the daylight
    point through intact crack elements only (the joints cut the block off)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    keep = topo.crack_tag == 0
    a, b = topo.crack_triangles[keep].T
    n = topo.n_triangles
    _, label = connected_components(coo_matrix((np.ones(a.size), (a, b)), shape=(n, n)), directed=False)
    on_plane = np.flatnonzero(topo.crack_tag == 1)
    ends = topo.x0[topo.crack_nodes[on_plane, :2]].reshape(-1, 2)
    d = ends[np.argmin(ends[:, 1])]
    tangent = ends[np.argmax(ends[:, 1])] - d
    normal = np.array([-tangent[1], tangent[0]])          # up-slope normal: into the block
    pair = topo.crack_triangles[on_plane[0]]
    centroid = topo.x0[topo.triangles[pair]].mean(axis=1)
    t = int(pair[np.argmax((centroid - d) @ normal)])
    return np.flatnonzero(np.repeat(label == label[t], 3))


def trial_stage(sim: Simulation, periods: float = 5.0, unbalanced_ratio: float = 1e-4) -> Stage:
    """The damped trial of the strength-reduction search for this scene.

    Damping: mass-proportional, ``alpha = 2 omega_1 = 4 pi / T`` [1/s], critical for the
    fundamental mode of period ``T = 4 H / c_s`` (:func:`fdem.workflow.stages.response_time`). It
    vanishes at rest, so a converged state is the static equilibrium whatever its value, and
    it brings a stable slope to ``R < 1e-4`` within about 1.5 T; Cundall's local damping
    (0.8) needs over 10 T here, and its force ``0.8 |f|`` on every node of a sliding block,
    scaled by the large internal forces, holds a failing block to a creep that looks settled.

    Rule: stable when the unbalanced-force ratio ``R = sum |f_net| / sum |m g|`` falls below
    ``unbalanced_ratio`` within ``periods`` T; failing otherwise (non-convergence, Dawson, Roth
    & Drescher 1999) or when a node moves 1 % of the model height. A failing block creeps at
    ``v = a_net / alpha`` while ``R`` stays near the net driving force over the weight of the
    model, above the limit: measured 5e-4 at F only 0.3 % above the Hoek-Bray value (no-crack
    geometry, 364 triangles), 2e-2 at 30 % above.
    """
    T = response_time(sim.model)
    return Stage("trial", max_time=periods * T, converge=Convergence(unbalanced_ratio=unbalanced_ratio),
                 fail=Failure(), damping=Damping(mass_proportional=4.0 * math.pi / T))


def run_case(name: str, size: float, lower: float = 0.8, upper: float = 2.0, tol: float = 0.01,
             out_dir: Path | None = None, pictures: bool = False, max_time: float | None = None,
             **fos_options) -> dict:
    """Factor of safety of geometry ``name`` (:data:`GEOMETRIES`) at mesh ``size`` [m] by
    strength reduction (:func:`fdem.workflow.fos.factor_of_safety`), with the analytic value.
    ``max_time`` [s]: cap on each trial's simulated time (a smoke run: capped trials count as
    failing, so its factor of safety means nothing). When the cap stops the lower end's trial
    before it converges, the search cannot start: the row then has ``fos = None`` and says why
    (``fos_undefined``). Every other error of the search (a bracket the slope contradicts
    without a cap, bad settings) is raised, never reported as a smoke run."""
    from fdem.cases.common import cap_simulated_time

    g = GEOMETRIES[name]
    le = analytic(**g)
    t0 = time.perf_counter()
    scene = planar_failure_simulation(planar_slope_geometry(HEIGHT, **g), size, out_dir=out_dir, pictures=pictures)
    cap_simulated_time(scene.sim, max_time)
    t1 = time.perf_counter()
    try:
        result = factor_of_safety(scene.sim, lower, upper, tol=tol, trial=trial_stage(scene.sim), **fos_options)
    except BracketError as err:
        if not err.trial.time_capped:
            raise
        # the --max-time cap stopped the trial before its rule could decide: not a verdict
        return {"geometry": name, "size_m": size, "n_triangles": scene.n_triangles, "dt_s": scene.sim.dt,
                "analytic_fos": le.fos, "fos": None, "bracket": None, "time_capped": True,
                "fos_undefined": f"the trial at F = {err.trial.factor:g} stopped at the --max-time cap of "
                                 f"{max_time:g} s before it converged or failed: the factor of safety is undefined "
                                 f"(smoke run)",
                "capped_trial": str(err), "steps": int(scene.sim.state.step),
                "seconds_build": t1 - t0, "seconds_fos": time.perf_counter() - t1}
    t2 = time.perf_counter()
    fos = float(result.fos)
    return {
        "geometry": name, **{k: v for k, v in g.items()}, "height_m": HEIGHT,
        "cohesion_Pa": JOINT_COHESION, "friction_deg": JOINT_FRICTION, "unit_weight_N_m3": UNIT_WEIGHT,
        "size_m": size, "n_triangles": scene.n_triangles, "dt_s": scene.sim.dt,
        "analytic_fos": le.fos, "analytic": le.as_dict(),
        "fos": fos, "bracket": [float(b) for b in result.bracket],
        "error_relative": fos / le.fos - 1.0,
        "n_trials": len(result.trials), "search_ended_by": result.ended_by,
        "capped_trials": sum(t.time_capped for t in result.trials),
        "trials": [{k: t.as_dict()[k] for k in ("factor", "stable", "reason", "t_end", "t_start", "steps",
                                                 "unbalanced_ratio", "max_displacement", "wall_seconds")}
                   for t in result.trials],
        "failure_surface_tags": {int(k): int(v) for k, v in zip(*np.unique(scene.cracks.tag[result.failure_surface],
                                                                             return_counts=True))},
        "n_broken_first_failure": int(result.failure_broken.size),
        "seconds_build": t1 - t0, "seconds_fos": t2 - t1, "time_capped": max_time is not None,
    }


def plot(rows: list, path: Path) -> Path:
    """FoS from strength reduction (bracket as error bar) against triangles, per geometry, with
    the Hoek-Bray value and its +-10 % band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted({r["geometry"] for r in rows}, key=list(GEOMETRIES).index)
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 3.6), squeeze=False)
    for ax, name in zip(axes[0], names):
        mine = sorted((r for r in rows if r["geometry"] == name), key=lambda r: r["n_triangles"])
        n = [r["n_triangles"] for r in mine]
        f = np.array([r["fos"] for r in mine])
        lo = f - np.array([r["bracket"][0] for r in mine])
        hi = np.array([r["bracket"][1] for r in mine]) - f
        F = mine[0]["analytic_fos"]
        ax.axhspan(0.9 * F, 1.1 * F, color="0.9", label="Hoek-Bray +-10 %")
        ax.axhline(F, color="k", lw=1, label=f"Hoek-Bray F = {F:.3f}")
        ax.errorbar(n, f, yerr=[lo, hi], fmt="o-", capsize=3, label="strength reduction")
        ax.set_xscale("log")
        ax.set_xlabel("triangles")
        ax.set_ylabel("factor of safety")
        g = GEOMETRIES[name]
        crack = "" if g["tension_crack_offset"] is None else f", crack b = {g['tension_crack_offset']:g} m"
        ax.set_title(f"psi_f {g['face_angle']:g}, psi_p {g['plane_angle']:g}{crack}", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return path


def parse_args(argv=None) -> argparse.Namespace:
    """The command line's options, checked (``parser.error``, exit status 2, on a bad one)
    before anything is meshed."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--overwrite", action="store_true", help="replace the earlier run in --out")
    parser.add_argument("--out", type=Path, default=Path("runs/planar_failure"))
    parser.add_argument("--size", type=float, nargs="+", default=[1.0, 0.7, 0.5],
                        help="element sizes [m], one run per size and geometry")
    parser.add_argument("--geometry", nargs="+", choices=list(GEOMETRIES), default=["no_crack", "tension_crack"])
    parser.add_argument("--threads", type=int, default=None, help="Numba threads (default: all cores)")
    parser.add_argument("--lower", type=float, default=0.8, help="reduction factor known to be stable")
    parser.add_argument("--upper", type=float, default=2.0, help="reduction factor known to fail")
    parser.add_argument("--tol", type=float, default=0.01, help="bracket width at which the search stops")
    parser.add_argument("--no-pictures", action="store_true", help="skip the FoS-against-mesh figure")
    parser.add_argument("--quiet", action="store_true", help="only warnings and the result")
    parser.add_argument("--max-time", type=float, default=None, metavar="SECONDS",
                        help="cap on each trial's simulated time [s] (a smoke run: its FoS means nothing)")
    parser.add_argument("--max-trials", type=int, default=DEFAULT_MAX_TRIALS,
                        help=f"cap on the trials of each search, the two ends included (default {DEFAULT_MAX_TRIALS}); "
                             "the search ends at --tol or at this cap, and the output says which")
    parser.add_argument("--rigid-blocks", action="store_true",
                        help="first print the rigid-block factor of safety and mechanism of the same joints "
                             "(seconds; docs/rigid_blocks.md)")
    args = parser.parse_args(argv)
    from fdem.io.messages import configure

    configure(quiet=args.quiet)
    check_common(parser, args)
    check_search(parser, args)
    return args


def check_search(parser: argparse.ArgumentParser, args) -> None:
    """Refuse a search that cannot run or cannot end: ``--lower`` and ``--upper`` positive and
    finite with lower < upper, ``--tol`` positive, finite and at least ``MIN_RELATIVE_TOL`` of
    ``--upper`` (below it the bisection cannot move), ``--max-trials`` >= 2."""
    for option, value in (("--lower", args.lower), ("--upper", args.upper)):
        if not (math.isfinite(value) and value > 0):
            parser.error(f"{option} must be a positive finite reduction factor, got {value}")
    if not args.upper > args.lower:
        parser.error(f"--upper ({args.upper}) must exceed --lower ({args.lower}): the bracket is [stable, failing]")
    if not (math.isfinite(args.tol) and args.tol > 0):
        parser.error(f"--tol must be a positive bracket width, got {args.tol}")
    if args.tol < MIN_RELATIVE_TOL * args.upper:
        parser.error(f"--tol {args.tol:g} is below the resolution of the search, {MIN_RELATIVE_TOL:g} of --upper "
                     f"({MIN_RELATIVE_TOL * args.upper:.3g})")
    if args.max_trials < 2:
        parser.error(f"--max-trials must be at least 2 (the two ends of the bracket), got {args.max_trials}")


def main(argv=None) -> list:
    args = parse_args(argv)
    args = prepare_run(None, args, argv, "planar-failure")
    set_threads(args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.geometry:
        if args.rigid_blocks:  # seconds, beside the FDEM factor of safety that follows
            from fdem.blocks.slope import print_rigid_blocks
            print_rigid_blocks(planar_slope_geometry(HEIGHT, **GEOMETRIES[name]), property_sets(),
                               UNIT_WEIGHT, args.out / name)
        for size in args.size:
            r = run_case(name, size, args.lower, args.upper, args.tol, max_time=args.max_time,
                         max_trials=args.max_trials)
            rows.append(r)
            write_json(args.out / "planar_failure.json", rows, indent=1)
            if r["fos"] is None:
                print(f"{name:14s} size {size:4.2f} m: {r['n_triangles']:6d} triangles: {r['fos_undefined']}",
                      flush=True)
                continue
            print(f"{name:14s} size {size:4.2f} m: {r['n_triangles']:6d} triangles, FoS {r['fos']:.3f} "
                  f"in [{r['bracket'][0]:.3f}, {r['bracket'][1]:.3f}] against Hoek-Bray {r['analytic_fos']:.3f} "
                  f"({100 * r['error_relative']:+.1f} %), {r['seconds_fos']:.0f} s"
                  + (f"; the search hit --max-trials {args.max_trials} before --tol" if r["search_ended_by"] ==
                     "max_trials" else "")
                  + (f"; {r['capped_trials']} trial(s) stopped at --max-time, counted as failing: smoke run"
                     if r["capped_trials"] else ""), flush=True)
    say(f"wrote {args.out / 'planar_failure.json'}")
    if not args.no_pictures and any(r["fos"] is not None for r in rows):
        say(f"wrote {plot([r for r in rows if r['fos'] is not None], args.out / 'planar_failure.png')}")
    finish_run(args.out, {"outcome": "finished"})
    return rows


if __name__ == "__main__":
    main()
