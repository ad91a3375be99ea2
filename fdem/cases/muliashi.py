"""The Muliashi slope with intermittent bedding joints (cases.md B, seed 001): gravity increase
to failure, step-path failure surface, micro-cracks by mode, fragments, micro-seismic events.

The paper raised the particle density from 2560 to 25,600 kg/m^3 until the slope failed. Here
gravity is multiplied by a factor ``k`` (same statics as a density factor, real mass in the
dynamics) and the critical factor is found by the factor-of-safety search
(:class:`fdem.workflow.fos.GravityIncrease`). The slide then runs on the same slope at 1 g with
its strengths divided by the smallest failing factor ``k`` and its fracture energies by ``k^2``
(:func:`property_sets`, ``strength_factor``: the same failure onset as at ``k g``, then real
gravity; the ground below the toe's elevation, which takes no part in that failure, at full
strength: :func:`build`), from a damped onset to rest; the meso views (:func:`meso_views`) read it.

Crack-element properties (every choice is a keyword of :func:`property_sets`):

* rock triangles: mudstone E = 5.96 GPa, nu = 0.15, rho = 2560 kg/m^3 (paper);
* intact rock bridges (tag 0): calibrated against the numerical compression test
  (``docs/calibration.md``, :mod:`fdem.physics.calibration`): ``f_t = UCS / 10 = 3.45 MPa``,
  phi = 30 deg, the cohesion that gives the paper's UCS = 34.5 MPa on the 8 m x 16 m specimen at
  the element size used (:data:`BRIDGE_COHESION`, 11.8 MPa +- 3 % between sizes), and the
  fracture energies of the size rule (:func:`fdem.physics.calibration.size_scaled_properties`,
  ``G_I = 404.4 h`` J/m^2), which keep every element up to 1.5 h long from snapping back at 1.5
  times the mean strength; strengths normally distributed with a coefficient of variation of
  0.1, as the paper's bond strengths (23 +- 2.3 MPa);
* bedding joints (tag 1): c = 149.33 kPa and phi = 12.35 deg (paper; the direct-shear scene
  returns them exactly); ``f_t = c / 10``; ``G_II = c Zbar d`` with a cohesion softening slip
  ``d`` = 1 mm, ``G_I = f_t Zbar d``; a dilation angle of 5 deg up to 5 mm of slip (the paper's
  smooth joints dilate, its value is lost in the source);
* penalties ``p_n = p_t = 10 E`` (Munjiza's alpha = 10, the tangential tied to the normal).

    python cases/muliashi.py --out runs/muliashi                      # pitch reading, 1.0 m: docs/cases.md B
    python cases/muliashi.py --spacing-rule both --out runs/muliashi_both
"""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from fdem.cases.common import (add_resume_options, cap_simulated_time, case_parser, check_common, finish_run,
                               open_run, prepare_run, set_threads, sign_journal, start_journal, stop_cleanly_on_signals,
                               threads_for_mesh, time_capped, use_density_scaling)

from fdem.geometry.joint_sets import SegmentSet
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import simple_slope
from fdem.io.jsonable import write_json
from fdem.io.messages import say

__all__ = ["NAME", "MULIASHI_SPACING_RULES", "muliashi_geometry", "ZBAR", "BRIDGE_COHESION", "bridge_cohesion",
           "property_sets", "GROUND_TAG_OFFSET", "ground_tags", "build", "meso_views", "build_simulation", "run_one", "main", "YOUNG", "POISSON", "DENSITY", "UCS",
           "JOINT_COHESION", "JOINT_FRICTION", "SEARCH_CHECKPOINT"]


NAME = "muliashi"
MULIASHI_SPACING_RULES = ("pitch", "gap")


def muliashi_geometry(spacing_rule: str = "pitch", above_toe: bool = True, min_joint_length: float = 0.05) -> Geometry:
    """The Muliashi open-pit slope of cases.md B (seed 001): 30 m x 22.5 m, 15 m bench at 65 deg,
    the model ending 7.5 m into the crest plateau; five layers of intermittent bedding joints,
    each joint 3 m long dipping 25 deg, layers 2.14 m apart (perpendicular).

    The paper's "horizontal distance of each joint in the same layer is 3 m" reads two ways:

    * ``spacing_rule="pitch"``: 3 m horizontally from the start of one joint to the start of the
      next, an along-trace period of ``3 / cos 25 = 3.31 m`` and rock bridges of 0.31 m
      (nearly persistent layers);
    * ``spacing_rule="gap"``: a 3 m horizontal gap between one joint's end and the next
      one's start, a period of ``(3 cos 25 + 3) / cos 25 = 6.31 m`` and rock bridges of 3.31 m.

    ``above_toe=True`` (the paper) keeps only the joints that lie wholly above the toe's
    elevation; ``False`` keeps every joint of the five layers, the floor and the ground below
    the toe included. Assumed: the lowest layer half a layer spacing above the bedding plane
    through the toe; joints of a layer start at whole periods from the point of the layer
    nearest the toe (the paper gives no phase).
    """
    if spacing_rule not in MULIASHI_SPACING_RULES:
        raise ValueError(f"spacing_rule must be one of {MULIASHI_SPACING_RULES}, got {spacing_rule!r}")
    width, height, bench, face = 30.0, 22.5, 15.0, 65.0
    crest = 7.5
    run = bench / math.tan(math.radians(face))
    toe_x = width - crest - run
    toe_y = height - bench
    slope = simple_slope(bench, face, crest_length=crest, toe_length=toe_x, base_depth=toe_y, name="slope")
    dip = math.radians(25.0)
    t = np.array([math.cos(dip), math.sin(dip)])
    n = np.array([-t[1], t[0]])
    trace, layer = 3.0, 2.14
    period = 3.0 / t[0] if spacing_rule == "pitch" else (3.0 * t[0] + 3.0) / t[0]
    toe = np.array([toe_x, toe_y])
    segments = []
    reach = math.hypot(width, height)
    for row in range(5):
        origin = toe + (row + 0.5) * layer * n
        for k in range(-int(reach / period) - 2, int(reach / period) + 2):
            a = origin + k * period * t
            b = a + trace * t
            if above_toe and min(a[1], b[1]) < toe_y:
                continue
            if max(a[0], b[0]) < 0 or min(a[0], b[0]) > width or max(a[1], b[1]) < 0 or min(a[1], b[1]) > height:
                continue
            if not slope.contains(np.array([a, b, 0.5 * (a + b)])).any():
                continue
            segments.append([a[0], a[1], b[0], b[1]])
    joints = SegmentSet(np.array(segments), name=f"bedding ({spacing_rule})")
    return Geometry([slope], [joints], min_joint_length=min_joint_length)


YOUNG, POISSON, DENSITY, UCS = 5.96e9, 0.15, 2560.0, 34.5e6
JOINT_COHESION, JOINT_FRICTION = 149.33e3, 12.35
ZBAR = 0.38631  # area under the Munjiza softening curve
G = 9.81  # [m/s^2]
FACE_ANGLE = 65.0  # [deg]
MIN_ASSEMBLY_TRIANGLES = 2  # a fragment of one triangle is debris, not an assembly (cases.md B)
N_FIRST_BREAKS = 60


BRIDGE_COHESION = {1.0: 11.57e6, 0.6: 12.23e6, 0.5: 11.51e6}  # [Pa] docs/calibration.md (UCS = 34.5 MPa)


def bridge_cohesion(size: float) -> float:
    """Rock-bridge cohesion [Pa] calibrated to UCS = 34.5 MPa at element size ``size`` [m]
    (:data:`BRIDGE_COHESION`); other sizes get the mean 11.8 MPa (the table's spread, +-3 %,
    is mesh scatter, not a trend with size)."""
    return BRIDGE_COHESION.get(round(float(size), 3), 11.8e6)


def property_sets(size: float, intact_phi: float = 30.0, penalty_ratio: float = 10.0,
                  joint_softening_slip: float = 1e-3, dilation_angle: float = 5.0, dilation_limit: float = 5e-3,
                  strength_factor: float = 1.0):
    """Crack-element property sets at element size ``size`` [m]: calibrated rock bridges (tag 0)
    and the paper's bedding joints (tag 1); module docstring.

    ``strength_factor`` ``k``: the slope at its critical gravity factor ``k`` seen at 1 g. Strengths
    ``f_t``, ``c`` divided by ``k`` and fracture energies by ``k^2`` (friction, dilation and
    penalties kept): every force of the model then scales by ``1/k`` against gravity ``k g``
    with the full strengths, the crack laws are the same curves in ``(u/k, f/k)``, and the two
    models move alike with displacements ``1/k`` as large at the same times, as long as the
    displacements are small against the geometry. Past that (the slide) the weaker model moves
    at real gravity: a slope at its limit state, not an overloaded one."""
    if not (math.isfinite(strength_factor) and strength_factor > 0):
        raise ValueError(f"property_sets: strength_factor must be a positive number, got {strength_factor!r}")
    k = float(strength_factor)
    from fdem.physics.calibration import size_scaled_properties
    from fdem.physics.crack_properties import CrackProperties

    if not (math.isfinite(size) and size > 0):
        raise ValueError(f"property_sets: element size must be a positive length [m], got {size!r}")
    p = penalty_ratio * YOUNG
    ft_joint = JOINT_COHESION / 10
    sets = {
        0: size_scaled_properties(UCS / 10, bridge_cohesion(size), intact_phi, p, size, p_t=p,
                                  name="mudstone rock bridges"),
        1: CrackProperties(f_t=ft_joint, c=JOINT_COHESION, phi=JOINT_FRICTION,
                           G_I=ft_joint * ZBAR * joint_softening_slip,
                           G_II=JOINT_COHESION * ZBAR * joint_softening_slip, p_n=p, p_t=p,
                           dilation_angle=dilation_angle, dilation_limit=dilation_limit, name="bedding joints"),
    }
    if k == 1.0:
        return sets
    return {t: dataclasses.replace(q, f_t=q.f_t / k, c=q.c / k, G_I=q.G_I / k ** 2, G_II=q.G_II / k ** 2)
            for t, q in sets.items()}


GROUND_TAG_OFFSET = 2  # crack tag t below the toe's elevation -> t + 2 in the slide model's crack set


def ground_tags(topology, toe_y: float) -> np.ndarray:
    """(n_cracks,) crack tags of the slide model: ``topology.crack_tag``, with the elements of
    body 0 whose reference midpoint lies below the toe's elevation ``toe_y`` [m] moved to
    ``tag + GROUND_TAG_OFFSET`` (the ground under the floor and under the slope), so that
    :func:`build` can give them the unreduced strengths."""
    tag = np.asarray(topology.crack_tag, dtype=np.int32).copy()
    mid_y = topology.x0[topology.crack_nodes[:, :2], 1].mean(axis=1)
    body = np.asarray(topology.triangle_body)[topology.crack_triangles[:, 0]]
    ground = (mid_y < toe_y) & (body == 0)
    tag[ground] += GROUND_TAG_OFFSET
    return tag


def build(size: float, spacing_rule: str = "pitch", above_toe: bool = True, out_dir=None, pictures: bool = True,
          heterogeneity_seed: int = 1, progress: bool = True, strength_factor: float = 1.0, wall: bool = False,
          full_strength_ground: bool = True):
    """Geometry, mesh, model in static equilibrium, crack elements, contact and the simulation.

    Supports as the paper: x fixed on the left and right sides, x and y fixed at the bottom.
    ``wall``: a fixed rigid body 1 m thick, 0.1 m left of the model and as high as it, which the
    debris meets as the paper's particles meet its left wall (without it debris past the 15.5 m
    floor falls off the model and never comes to rest).

    ``full_strength_ground`` (with ``strength_factor`` k != 1): the ground below the toe's
    elevation keeps the unreduced strengths (the crack set's tags moved by :func:`ground_tags`;
    the model's own tags, which the pictures read, unchanged). The failure that k measures is the
    slope's, above the toe (the sliding base runs on the lowest joint layer); reduced by k the
    ground is k times too weak for a slide at 1 g: the release of the slope's stress when it
    fails cracked the floor of the slide down to the model's base (docs/cases.md B)."""
    from fdem.physics.cracks import CrackSet
    from fdem.physics.heterogeneity import Heterogeneity
    from fdem.physics.contact import ContactSet
    from fdem.solve.geostatic import geostatic_start
    from fdem.physics.elastic import ElasticMaterial
    from fdem.mesh.triangulate import mesh_geometry
    from fdem.solve.model import Model
    from fdem.cases.muliashi import muliashi_geometry
    from fdem.solve.simulation import Simulation
    from fdem.mesh.topology import build_topology

    geometry = muliashi_geometry(spacing_rule, above_toe)
    if wall:
        from fdem.geometry.polygons import rectangle

        x0, y0, x1, y1 = geometry.bounds
        geometry = Geometry([*geometry.bodies, rectangle(x0 - 1.1, y0, 1.0, y1 - y0, name="wall")],
                            list(geometry.joint_sets), min_joint_length=geometry.min_joint_length)
    topo = build_topology(mesh_geometry(geometry, size))
    model = Model(topo, ElasticMaterial(young=YOUNG, poisson=POISSON, density=DENSITY))
    model.set_gravity(0.0, -9.81)
    if wall:  # the sides by coordinates: the mesh's "left" is now the wall's
        eps = 1e-6
        model.fix(lambda x, y: x < x0 - 0.05)
        model.fix(lambda x, y: (y < y0 + eps) & (x > x0 - 0.05))
        model.roller(lambda x, y: np.abs(x - x0) < eps, "x")
        model.roller(lambda x, y: np.abs(x - x1) < eps, "x")
    else:
        model.fix("bottom")
        model.roller("left", "x")
        model.roller("right", "x")
    model.set_element_damping()
    sets = property_sets(size, strength_factor=strength_factor)
    crack_tags, random_tags = None, (0,)
    if full_strength_ground and strength_factor != 1.0:
        from fdem.geometry.polygons import slope_toe

        tags = ground_tags(topo, slope_toe(geometry.bodies[0])[1])
        full = property_sets(size)
        for t in np.unique(tags[tags >= GROUND_TAG_OFFSET]) - GROUND_TAG_OFFSET:
            sets[int(t) + GROUND_TAG_OFFSET] = dataclasses.replace(full[int(t)], name=f"{full[int(t)].name} below the toe")
        crack_tags = tags
        random_tags = (0, GROUND_TAG_OFFSET)  # the same draws as without: Heterogeneity draws for all elements
    # The crack set reads its properties by ``crack_tags``; the topology it shares with the
    # model keeps the geometry's tags (0 intact, j joint set j): the pictures draw tags > 0 as
    # joints, and the ground is no joint.
    cracks = CrackSet(topo, sets, contact_penalty=sets[0].p_n, tags=crack_tags,
                      heterogeneity=Heterogeneity("normal", cov=0.1, seed=heterogeneity_seed, tags=random_tags))
    report = geostatic_start(model, cracks)
    contact = ContactSet(topo, sets[0].p_n, friction_angle=JOINT_FRICTION, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], out_dir=out_dir, name="muliashi", pictures=pictures,
                     progress=progress)
    return geometry, sim, cracks, report


def meso_views(out: Path, sim, geometry: Geometry, catalogue, recorder, pictures: bool = True,
               min_triangles: int = MIN_ASSEMBLY_TRIANGLES, n_first: int = N_FIRST_BREAKS) -> dict:
    """The meso-scale readings of the slide (:mod:`fdem.results.meso`) and, with ``pictures``,
    ``meso_initiation.png``, ``meso_events.png``, ``meso_magnitudes.png``, ``meso_fragments.png``
    and ``meso_forces.png`` (:mod:`fdem.io.meso_pictures`). Returns the figures for the summary:

    * initiation: the first ``n_first`` breaks, the first one's place, its distance to the
      nearest joint tip and the layer (0 = lowest) of that tip, how far the front climbs;
    * fragments: assemblies of at least ``min_triangles`` triangles (smaller: debris) when 1/3,
      2/3 and all of the breaks have happened: count, the largest besides the ground, the mean
      elevation where they formed;
    * forces: before sliding (the first kept state) the share of the triangles within 2 m of the
      face whose most compressive stress lies within 15 deg of the face (65 deg); during the
      slide (the kept state nearest the kinetic-energy peak) the mean compressive force of
      intact rock-bridge elements within 1 m of a joint tip against the others [N/m];
    * floor: :func:`fdem.results.meso.floor_cracking`, the broken elements below the toe's
      elevation (in front of the toe and under the slope) and how deep;
    * magnitudes: :func:`fdem.results.meso.normality` against the paper's N(-3.07, 0.495).
    """
    from fdem.io import meso_pictures as mp
    from fdem.results import meso
    from fdem.results.events import MULIASHI

    topo, cracks = sim.model.topology, sim.cracks
    tri = topo.triangles
    x_end = sim.state.x
    joints = np.concatenate([np.asarray(j.segments).reshape(-1, 4) for j in geometry.joint_sets]) \
        if geometry.joint_sets else np.zeros((0, 4))
    tips = np.concatenate([joints[:, :2], joints[:, 2:]]) if joints.size else np.zeros((0, 2))
    dip = math.radians(25.0)
    normal = np.array([-math.sin(dip), math.cos(dip)])
    from fdem.geometry.polygons import slope_toe

    toe = np.array(slope_toe(geometry.bodies[0]))
    result: dict = {"min_assembly_triangles": min_triangles, "first_breaks": n_first}
    b = geometry.bounds
    view = (b[0] - 10.0, b[2] + 1.0, b[1] - 1.0, b[3] + 1.0)  # the model and 10 m of runout beyond its edge

    # initiation order
    ev = cracks.events
    x0 = topo.x0
    seg0 = np.column_stack([x0[topo.crack_nodes[:, 0]], x0[topo.crack_nodes[:, 1]]])
    if len(ev):
        init = meso.initiation_order(ev["time"], ev["x"], ev["y"], n_first)
        first = np.array(init["first"])
        if tips.size:
            d = np.linalg.norm(tips - first, axis=1)
            k = int(np.argmin(d))
            layer = int(round(float((tips[k] - toe) @ normal) / 2.14 - 0.5))
        else:
            d, k, layer = np.array([math.nan]), 0, -1
        sel = ev[init["order"]]
        result["initiation"] = {"first_xy_m": init["first"], "first_time_s": float(sel["time"][0]),
                                "first_tag": int(sel["tag"][0]), "first_mode": str(sel["mode"][0]),
                                "distance_to_joint_tip_m": float(d[k]), "joint_tip_layer": layer,
                                "climb_m_per_break": init["climb_m_per_break"],
                                "y_first_10_mean_m": float(np.mean(sel["y"][:10])),
                                "y_last_10_mean_m": float(np.mean(sel["y"][-10:]))}
        if pictures:
            mp.initiation_map(out / "meso_initiation.png", x0, tri, seg0[sel["element"]], init["rank"],
                              time=sel["time"], joints=joints)
    # cracking below the toe: the floor in front of it and the ground under the slope
    mid0 = 0.5 * (seg0[:, :2] + seg0[:, 2:])
    in_slope = topo.triangle_body[topo.crack_triangles[:, 0]] == 0
    result["floor"] = meso.floor_cracking(mid0[in_slope], cracks.broken[in_slope], toe)
    # events
    if not catalogue.empty:
        e = catalogue.events
        if pictures:
            mp.event_map(out / "meso_events.png", x0, tri, e["x"], e["y"], e["magnitude"], t=e["t_start"],
                         joints=joints)
        if e.size >= 3:
            test = meso.normality(e["magnitude"], MULIASHI["mean"], MULIASHI["std"])
            result["magnitudes"] = test
            if pictures:
                mp.magnitude_histogram(out / "meso_magnitudes.png", e["magnitude"],
                                       reference={"mean": MULIASHI["mean"], "std": MULIASHI["std"],
                                                  "count": MULIASHI["count"]}, test=test)
    # fragments at 1/3, 2/3 and all of the breaks
    snaps = recorder.snapshots
    area = np.abs(topo.triangle_area0)
    yc0 = x0[tri][:, :, 1].mean(axis=1)
    slope = topo.triangle_body == 0
    bt = cracks.break_time()
    if len(ev) and snaps:
        times = np.sort(ev["time"])
        frames, rows = [], []
        for share in (1 / 3, 2 / 3, 1.0):
            t_at = float(times[max(0, int(math.ceil(share * times.size)) - 1)])
            snap = next((sn for sn in snaps if sn.time >= t_at), snaps[-1])
            _, label = meso.fragments_at(topo, bt, snap.time)
            asm = np.full(topo.n_triangles, -1, dtype=np.int64)  # the wall (body 1) is no assembly
            asm[slope] = meso.assemblies(label[slope], area[slope], min_triangles)
            table = meso.assembly_table(asm, area, yc0)
            rest = slice(1, None)  # 0 is the largest: the ground
            rows.append({"time_s": snap.time, "broken": int(np.sum(bt <= snap.time)),
                         "assemblies_besides_ground": int(max(table["area"].size - 1, 0)),
                         "largest_besides_ground_m2": float(table["area"][rest].max()) if table["area"].size > 1 else 0.0,
                         "mean_formed_elevation_m": float(np.average(table["y"][rest], weights=table["area"][rest]))
                         if table["area"].size > 1 else math.nan,
                         "debris_triangles": int(np.sum((asm < 0) & slope))})
            frames.append((snap.x, asm, f"t = {snap.time:.3f} s, {rows[-1]['broken']} broken"))
        result["fragments"] = rows
        if pictures:
            mp.fragment_maps(out / "meso_fragments.png", frames, tri, min_triangles, extent=view)
    # force chains and principal directions before and during sliding
    if snaps:
        before = snaps[0]
        during = max(snaps, key=lambda sn: sn.kinetic)
        face = math.radians(FACE_ANGLE)
        fdir = np.array([math.cos(face), math.sin(face)])
        fn = np.array([-fdir[1], fdir[0]])
        c0 = x0[tri].mean(axis=1)
        near_face = (np.abs((c0 - toe) @ fn) < 2.0) & (c0[:, 1] > toe[1]) & (c0[:, 1] < toe[1] + 15.0)
        tip_near = np.zeros(topo.n_cracks, bool)
        for t in tips:
            tip_near |= np.linalg.norm(mid0 - t, axis=1) < 1.0
        bridge = topo.crack_tag == 0
        panels = []
        for name, sn in (("before sliding", before), ("during the slide", during)):
            pd = meso.principal_directions(sn.sxx, sn.syy, sn.sxy)
            cen = sn.x[tri].mean(axis=1)
            with np.errstate(invalid="ignore"):
                intact = ~(bt <= sn.time)
            comp = np.where(intact & (sn.crack_normal < 0), -sn.crack_normal * topo.crack_length0, 0.0)
            cs, cm = meso.force_segments(cen, topo.crack_triangles, comp)
            ks, km = meso.force_segments(cen, sn.contact_pairs, sn.contact_force)
            panels.append({"x": sn.x, "title": f"{name}: t = {sn.time:.3f} s", "crack": (cs, cm), "contact": (ks, km),
                           "centroids": cen, "theta2": pd["theta2"], "s2": pd["s2"]})
            near = comp[bridge & tip_near & intact]
            far = comp[bridge & ~tip_near & intact]
            result[f"forces_{name.split()[0]}"] = {
                "time_s": sn.time,
                "face_parallel_share": meso.direction_share(pd["theta2"][near_face], face, math.radians(15.0)),
                "bridge_force_near_tips_N_per_m": float(near.mean()) if near.size else math.nan,
                "bridge_force_elsewhere_N_per_m": float(far.mean()) if far.size else math.nan,
                "contact_pairs": int(km.size), "contact_force_max_N_per_m": float(km.max()) if km.size else 0.0}
        if pictures:
            mp.force_chain_maps(out / "meso_forces.png", panels, tri, extent=view)
    return result


def build_simulation(size: float, spacing_rule: str = "pitch", above_toe: bool = True):
    """Module-level builder for the parallel factor-of-safety workers."""
    return build(size, spacing_rule, above_toe, progress=False)[1]


SEARCH_CHECKPOINT = "search_checkpoint.npz"
"""The gravity-factor search's own checkpoint in a run's folder (its trials, then its result)."""


def _search_journal(sim, args, out: Path):
    """The search's journal: resumed from ``SEARCH_CHECKPOINT`` (loaded into the search's
    simulation, which is the start state every trial restarts from) when ``--resume`` finds one,
    else a new one writing it."""
    from fdem.workflow.journal import RunJournal

    path = out / SEARCH_CHECKPOINT
    every = getattr(args, "checkpoint_every", None) or None
    if getattr(args, "resume", None) is not None and path.is_file():
        journal = sign_journal(RunJournal.resume_from(sim, path, every), path)
        from fdem.workflow.fos import TRIALS_MARK

        done = "done" if "fos" in journal.marks else f"{len(journal.marks.get(TRIALS_MARK, {}).get('trials', []))} trial(s) done"
        say(f"resumed the gravity-factor search from {path}: {done}")
        return journal
    return sign_journal(RunJournal(path, every))   # its checkpoints name the code that wrote them


def run_one(args, spacing_rule: str, out: Path) -> dict:
    from fdem.geometry.polygons import slope_toe
    from fdem.results.report import RunReport
    from fdem.workflow.stages import response_time, run_stage
    from fdem.workflow.fos import GravityIncrease, factor_of_safety
    from fdem.solve.simulation import InstabilityError
    from fdem.workflow.fos import default_trial_stage
    from fdem.workflow.slope import SlopeWorkflow, runout_stage
    from fdem.results.meso import MesoRecorder

    t0 = time.perf_counter()
    geometry, sim, cracks, geo = build(args.size, spacing_rule, not args.below_toe, out, False, progress=False)
    stop_cleanly_on_signals()  # after meshing: Gmsh installs its own handlers
    cap_simulated_time(sim, args.max_time)
    use_density_scaling(sim, args.density_scaling)
    topo = sim.model.topology
    threads = threads_for_mesh(args.threads, topo.n_triangles)
    print(f"[{spacing_rule}] {topo.n_triangles} triangles, {topo.n_cracks} crack elements "
          f"({int((topo.crack_tag > 0).sum())} on joints), dt {sim.dt:.3g} s, {threads} thread(s), "
          f"{len(geo.over_strength['shear']) + len(geo.over_strength['tensile'])} elements over strength at k = 1")
    toe_x, floor_y = slope_toe(geometry.bodies[0])
    from fdem.results.events import MULIASHI

    T = response_time(sim.model)
    if args.gravity_factor is None:
        # The search has its own journal (SEARCH_CHECKPOINT, on the search's model, which the
        # slide's checkpoint cannot hold): each finished trial is kept, then the result, so a
        # resumed run goes on from its last finished trial, or past a finished search at once.
        search = _search_journal(sim, args, out)
        searched = "fos" in search.marks   # a resume past a finished search: its result is on disk
        if not (out / SEARCH_CHECKPOINT).is_file():
            search.write(sim, "search start")   # so that a stop in the first trial can be resumed too
        try:
            fos_summary = search.once("fos", lambda: factor_of_safety(
                sim, lower=1.0, upper=args.upper, tol=args.tol, trigger=GravityIncrease(), out_dir=out,
                workers=args.workers, build=build_simulation,
                build_args=(args.size, spacing_rule, not args.below_toe), journal=search).as_dict())
        except KeyboardInterrupt as stop:  # between or in a trial: the finished ones are on disk
            sim.close()
            ending = f"interrupted in the gravity-factor search ({stop.args[0] if stop.args else 'Ctrl-C'})"
            summary = {"case": f"muliashi_{spacing_rule}", "outcome": "interrupted", "ending": ending,
                       "size_m": args.size, "search_checkpoint": str(out / SEARCH_CHECKPOINT)}
            write_json(out / "summary.json", summary)
            print(f"[{spacing_rule}] {ending}; resume with: fdem run muliashi --resume {args.out}")
            return summary
        if not searched:
            search.write(sim, "search end")  # the result on disk: a resume skips the search
        k_fail = fos_summary["bracket"][1] * (1.0 + args.overload)
        print(f"[{spacing_rule}] critical gravity factor {fos_summary['fos']:.3f} (bracket "
              f"{fos_summary['bracket'][0]:.3f}-{fos_summary['bracket'][1]:.3f}, {fos_summary['n_trials']} trials, "
              f"{fos_summary['wall_seconds']:.0f} s); the slide at 1 g with strengths / {k_fail:.3f}")
    else:
        k_fail, fos_summary = args.gravity_factor, None
    sim.close()
    # The slide (docs/cases.md B): the failing factor k found by the search, seen at 1 g
    # (property_sets(strength_factor=k): strengths / k, fracture energies / k^2), so that the
    # failure starts as in the failing trial and the slide then runs at real gravity. First the
    # failing trial's damped stage ("onset": fundamental-mode damping, ends when a node has
    # moved 1 % of the model height), then the slope workflow's undamped runout ("slide") to
    # rest: kinetic energy below 1 % of its peak for one response time, capped at
    # --runout-time or max(20 T, 4 sqrt(2 H / g)).
    geometry, sim, cracks, geo = build(args.size, spacing_rule, not args.below_toe, out, not args.no_pictures,
                                       strength_factor=k_fail, wall=True)
    cap_simulated_time(sim, args.max_time)
    use_density_scaling(sim, args.density_scaling)
    print(f"[{spacing_rule}] at strengths / {k_fail:.3f}: {len(geo.over_strength['shear'])} elements over shear "
          f"and {len(geo.over_strength['tensile'])} over tensile strength in the geostatic start")
    # the events' stress drop is the mean tensile strength of the slope's sets (bridges and
    # joints, / k), as RunReport's default would take it without the ground's full-strength
    # sets: those would raise it 14-fold and shift every magnitude by -0.8
    slope_sets = [p for t, p in cracks.property_sets.items() if t < GROUND_TAG_OFFSET]
    report = RunReport(sim, toe_x=toe_x, floor_y=floor_y, reference_events=MULIASHI,
                       stress_drop=float(np.mean([p.f_t for p in slope_sets])))
    recorder = MesoRecorder(interval=T / 4).attach(sim)  # before the history's first row
    journal = start_journal(sim, args, out)
    height = float(geometry.bounds[3] - geometry.bounds[1])
    onset_stage = dataclasses.replace(default_trial_stage(sim), name="onset")
    slide_stage = dataclasses.replace(runout_stage(SlopeWorkflow(runout_time=args.runout_time), T, height, G),
                                      name="slide")
    stages = []
    outcome, ending = "finished", None
    try:
        for stage in (onset_stage, slide_stage):
            stages.append(run_stage(sim, stage, journal=journal))
        failure = stages[-1]
    except KeyboardInterrupt as stop:  # at a whole step: the journal has written its checkpoint
        outcome, ending = "interrupted", f"interrupted ({stop.args[0] if stop.args else 'Ctrl-C'})"
    except InstabilityError as err:  # the journal's checkpoint is the last good state
        outcome, ending = "unstable", str(err)
    finally:
        sim.close()
    if outcome != "finished":
        summary = report.write(out, pictures_on=not args.no_pictures, extra={
            "case": f"muliashi_{spacing_rule}", "outcome": outcome, "ending": ending, "size_m": args.size,
            "critical_gravity_factor": fos_summary, "strength_factor": k_fail})
        print(f"[{spacing_rule}] {ending}; resume with: fdem run muliashi --resume {args.out}")
        return summary
    meso = meso_views(out, sim, geometry, report.catalogue(), recorder, pictures=not args.no_pictures)
    summary = report.write(out, pictures_on=not args.no_pictures, extra={
        "case": f"muliashi_{spacing_rule}", "spacing_rule": spacing_rule, "joints_above_toe_only": not args.below_toe,
        "size_m": args.size, "critical_gravity_factor": fos_summary, "strength_factor": k_fail,
        "stages": [r.as_dict() for r in stages], "meso": meso, "response_time_s": T, "wall_seconds": time.perf_counter() - t0,
        "time_capped": time_capped(sim), "outcome": "finished", "checkpoints": journal.writes,
        "paper": {"density_factor_reached": 10.0, "events": 238, "magnitude_mean": -3.07, "magnitude_std": 0.495,
                  "magnitude_min": -4.91, "magnitude_max": -2.05}})
    print(f"[{spacing_rule}] {failure.reason} after {failure.t_end - failure.t_start:.3g} s: "
          f"{summary['cracks']['broken']} broken ({summary['cracks']['by_mode']}), "
          f"max displacement {summary['displacement']['max_m']:.3g} m; events: {summary['events']}")
    return summary


def main(argv=None) -> dict:
    # defaults: the run of docs/cases.md B. At 0.6 m the slope weakened by its failing factor
    # settles instead of sliding (the search loads from the 1 g state, the slide model starts
    # from a geostatic state at the reduced strength; it slides at --gravity-factor 24.4,
    # 1.25 times the factor, docs/cases.md B), so the default size is 1.0 m; the
    # critical factor is about 20 (pitch) and 39 (gap), so the bracket reaches 80.
    parser = case_parser(__doc__, "runs/muliashi", 1.0, "element size [m] (default 1.0)", name=NAME)
    parser.add_argument("--spacing-rule", choices=["pitch", "gap", "both"], default="pitch",
                        help="read the 3 m joint spacing as start-to-start pitch (default: the paper's figure) "
                             "or as the gap, or both")
    parser.add_argument("--below-toe", action="store_true", help="also build the joints below the toe's elevation")
    parser.add_argument("--upper", type=float, default=80.0,
                        help="upper end of the gravity-factor bracket (default 80; the critical factor is about "
                             "20 for pitch, 39 for gap at 1.0 m)")
    parser.add_argument("--tol", type=float, default=1.25, help="bracket width of the gravity-factor search (default 1.25)")
    parser.add_argument("--overload", type=float, default=0.0,
                        help="the slide runs with strengths / ((1 + overload) k_fail), k_fail the smallest failing factor")
    parser.add_argument("--runout-time", type=float, default=None,
                        help="cap of the slide [s] (default max(20 T, 4 sqrt(2 H / g)))")
    parser.add_argument("--workers", type=int, default=1, help="factor-of-safety trials in parallel")
    parser.add_argument("--gravity-factor", type=float, default=None,
                        help="skip the search: the slide runs with strengths / this factor")
    add_resume_options(parser)
    args = prepare_run(parser, parser.parse_args(argv), argv, NAME, open_now=False)
    check_common(parser, args)
    for name, value, low in (("--upper", args.upper, 1.0), ("--tol", args.tol, 0.0),
                             ("--runout-time", args.runout_time, 0.0), ("--gravity-factor", args.gravity_factor, 0.0)):
        if value is not None and not (math.isfinite(value) and value > low):
            parser.error(f"{name} must be a finite number above {low:g}, got {value}")
    if not (math.isfinite(args.overload) and args.overload >= 0):
        parser.error(f"--overload must be a fraction >= 0, got {args.overload}")
    if args.workers < 1:
        parser.error(f"--workers must be at least 1, got {args.workers}")
    open_run(parser, args, NAME)  # every option checked: now the folder and run.json
    set_threads(args.threads)
    rules = ["pitch", "gap"] if args.spacing_rule == "both" else [args.spacing_rule]
    results = {}
    for rule in rules:
        out = args.out / rule if len(rules) > 1 else args.out
        out.mkdir(parents=True, exist_ok=True)
        results[rule] = run_one(args, rule, out)
        if results[rule].get("outcome") in ("interrupted", "unstable"):
            break
    summary = results[rules[0]] if len(rules) == 1 else {"cases": results}
    if len(rules) > 1:
        ended = [r.get("outcome") for r in results.values()]
        summary["outcome"] = next((o for o in ended if o in ("interrupted", "unstable")), "finished")
        write_json(args.out / "summary.json", summary)
    finish_run(args.out, summary)
    return summary


if __name__ == "__main__":
    main()
