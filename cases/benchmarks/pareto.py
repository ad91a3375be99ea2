"""Run time against error for every verification problem (docs/pareto.md).

For each problem: sweep element size ``h``, penalty ``alpha = p / E`` and the time-step factor
``safety`` (fraction of the critical step), record wall time and error, write
``docs/pareto/<problem>.json`` and a log-log plot of error against run time with the Pareto
front (``docs/pareto/<problem>.png``), and a table of every run (``docs/pareto/tables.md``).

    python cases/benchmarks/pareto.py                    # every sweep (full)
    python cases/benchmarks/pareto.py --quick            # reduced sweeps, a few minutes
    python cases/benchmarks/pareto.py --only wave column # a subset
    python cases/benchmarks/pareto.py --tables-only      # re-plot and re-tabulate stored JSON

Problems: wave (P-wave arrival on an exploded mesh with glued crack elements), column
(gravity column: stresses and settlement, i.e. static stiffness), mode1 (one cohesive joint
pulled apart: dissipated energy), brazilian (disc: recovered tensile strength), direction
(Brazilian load direction against the mesh and process-zone size), incline (sliding block),
impact (two-body impact: energy), runout (the demo slope's runout to rest: time step against
the chaotic spread of runout distance), planar (planar slope factor of safety), tangential (the
four-slope tangential penalty, paper against tied), longrun (1e6 steps on a small mesh:
ledger drift).

Runs use one Numba thread (set NUMBA_NUM_THREADS=1 before starting, as the machine is
shared); every record carries ``os.getloadavg()``.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.cases.four_slopes import four_slope_property_sets  # noqa: E402
from fdem.physics.contact import ContactSet  # noqa: E402
from fdem.geometry.section import Geometry
from fdem.geometry.joint_sets import SegmentSet
from fdem.geometry.polygons import rectangle  # noqa: E402
from fdem.physics.elastic import ElasticMaterial  # noqa: E402
from fdem.mesh.mesh import jittered_rectangle, structured_rectangle  # noqa: E402
from fdem.mesh.triangulate import mesh_geometry  # noqa: E402
from fdem.solve.model import Model  # noqa: E402
from fdem.solve.damping import Damping
from fdem.solve.simulation import InstabilityError, Simulation  # noqa: E402
from fdem.mesh.topology import build_topology  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "docs" / "pareto"


def load_case(name: str):
    """Import ``cases/<name>.py`` as a module."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, ROOT / "cases" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def glue(young: float, alpha: float, tangential: float | None = None) -> CrackProperties:
    """Crack elements that never yield, penalty ``p_n = alpha E`` (``p_t`` tied unless given)."""
    return CrackProperties(f_t=1e12, c=1e12, phi=45.0, G_I=1e30, G_II=1e30, p_n=alpha * young,
                           p_t=alpha * young if tangential is None else tangential)


def stamp(row: dict, t0: float, sim: Simulation | None = None) -> dict:
    row["wall_s"] = time.perf_counter() - t0
    row["loadavg"] = list(os.getloadavg())
    if sim is not None:
        crit, limits = sim.critical_dt()
        row.update(dt_s=sim.dt, critical_dt_s=crit, steps=sim.state.step,
                   dt_limits_s={k: float(v) for k, v in limits.items()})
    return row


# ============================================================================ 1. P-wave arrival
WAVE_E, WAVE_NU, WAVE_RHO = 30e9, 0.35, 2500.0  # c_p = 4388.5 m/s


def wave(h: float, alpha: float | None, safety: float, length: float = 10.0, station: float = 6.0) -> dict:
    """Velocity step at the left end of a strip one element high, rollers top and bottom (plane
    strain); arrival (half-amplitude crossing) at ``station``. ``alpha = None``: conforming mesh
    (no crack elements); else exploded mesh with glued crack elements ``p_n = p_t = alpha E``."""
    t0 = time.perf_counter()
    mat = ElasticMaterial(WAVE_E, WAVE_NU, WAVE_RHO)
    nx = int(round(length / h))
    mesh = structured_rectangle(nx, 1, length, h)
    if alpha is None:
        model = Model.from_mesh(mesh, mat, exploded=False)
        providers = []
    else:
        topo = build_topology(mesh)
        model = Model(topo, mat)
        providers = [CrackSet(topo, {0: glue(WAVE_E, alpha)})]
    v0 = 0.01
    model.prescribe_velocity("left", vx=v0)
    model.roller("bottom", "y")
    model.roller("top", "y")
    sim = Simulation(model, providers=providers, progress=False, dt_fraction=safety)
    x0 = model.topology.x0
    nodes = np.flatnonzero(np.abs(x0[:, 0] - station) < 1e-9)
    c = mat.p_wave_speed
    times, speeds = [], []
    while sim.state.time < 3.0 * station / c:
        sim.step()
        times.append(sim.state.time - 0.5 * sim.dt)
        speeds.append(sim.state.v[nodes, 0].mean() / v0)
    t, s = np.array(times), np.array(speeds)
    k = int(np.argmax(s >= 0.5))
    t_arr = t[k - 1] + (0.5 - s[k - 1]) / (s[k] - s[k - 1]) * (t[k] - t[k - 1]) if k > 0 else np.nan
    speed = station / t_arr
    row = {"problem": "wave", "h": h, "alpha": alpha, "safety": safety, "c_exact": c, "c_measured": speed,
           "error": abs(speed / c - 1.0), "error_signed": speed / c - 1.0}
    return stamp(row, t0, sim)


# ============================================================================ 2. gravity column
COL_E, COL_NU, COL_RHO, COL_G, COL_H = 1e9, 0.25, 2000.0, 10.0, 10.0


def column(ny: int, alpha: float | None, safety: float, periods: float = 4.0) -> dict:
    """Gravity column (plane strain, rollers, fixed base) damped to rest with mass-proportional
    damping critical for the first mode. Errors: stresses (max over triangles / rho g H) and the
    top settlement against ``rho g H^2 / (2 M)`` (static stiffness). ``alpha = None``:
    conforming mesh; else exploded with glued crack elements ``p = alpha E``."""
    t0 = time.perf_counter()
    mat = ElasticMaterial(COL_E, COL_NU, COL_RHO)
    nx = max(1, ny // 10)
    mesh = jittered_rectangle(nx, ny, 1.0, COL_H, 0.2, 1)
    if alpha is None:
        model = Model.from_mesh(mesh, mat, exploded=False)
        providers = []
    else:
        topo = build_topology(mesh)
        model = Model(topo, mat)
        providers = [CrackSet(topo, {0: glue(COL_E, alpha)})]
    model.set_gravity(0.0, -COL_G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    sim = Simulation(model, providers=providers, progress=False, dt_fraction=safety)
    c = mat.p_wave_speed
    T = 4 * COL_H / c
    sim.run(t_end=periods * T, damping=Damping(mass_proportional=2 * (2 * math.pi / T)), history_every=10**6,
            output_every=10**9)
    s = sim.stresses()
    yc = model.centroids0[:, 1]
    exact = -COL_RHO * COL_G * (COL_H - yc)
    err_yy = float(np.max(np.abs(s["yy"] - exact)) / (COL_RHO * COL_G * COL_H))
    x0 = model.topology.x0
    top = np.abs(x0[:, 1] - COL_H) < 1e-9
    settle = float(-(sim.state.x[top, 1] - x0[top, 1]).mean())
    exact_settle = COL_RHO * COL_G * COL_H ** 2 / (2 * mat.p_wave_modulus)
    row = {"problem": "column", "h": COL_H / ny, "alpha": alpha, "safety": safety, "error": err_yy,
           "stress_error": err_yy, "settlement_error": settle / exact_settle - 1.0}
    return stamp(row, t0, sim)


# ============================================================================ 3. cohesive mode I
MI_E, MI_NU, MI_RHO = 10e9, 0.2, 2500.0
MI_FT, MI_GI = 1e6, 50.0


def mode1(h: float, alpha: float, safety: float, rate_periods: float = 20.0) -> dict:
    """A 1 m x 0.2 m bar cut by one vertical joint (mode-I strength ``f_t``, energy ``G_I``), all
    other crack elements glued; the ends are pulled apart so that the joint opens to full damage
    over about ``rate_periods`` wave transits. Error: dissipated fracture energy / (G_I H) - 1."""
    t0 = time.perf_counter()
    width, height = 1.0, 0.2
    geo = Geometry([rectangle(0.0, 0.0, width, height)],
                   [SegmentSet([(0.5 * width, -0.1, 0.5 * width, height + 0.1)], must_lie_inside=False)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        topo = build_topology(mesh_geometry(geo, h))
    mat = ElasticMaterial(MI_E, MI_NU, MI_RHO)
    model = Model(topo, mat)
    joint = CrackProperties(f_t=MI_FT, c=10 * MI_FT, phi=30.0, G_I=MI_GI, G_II=100 * MI_GI, p_n=alpha * MI_E,
                            p_t=alpha * MI_E)
    cracks = CrackSet(topo, {0: glue(MI_E, alpha), 1: joint})
    o_r = MI_GI / (MI_FT * 0.3863)
    transit = width / mat.p_wave_speed
    v = o_r / (2 * rate_periods * transit)
    x0 = topo.x0
    model.prescribe_velocity(lambda x, y: x < 1e-9, vx=-v, vy=0.0)
    model.prescribe_velocity(lambda x, y: x > width - 1e-9, vx=v, vy=0.0)
    sim = Simulation(model, providers=[cracks], progress=False, dt_fraction=safety)
    joint_ids = np.flatnonzero(cracks.tag == 1)
    t_end = 2.0 * o_r / (2 * v)
    while sim.state.time < t_end and not cracks.broken[joint_ids].all():
        sim.run(n_steps=50, energy_tolerance=None, output_every=10**9, history_every=10**6)
    e = cracks.energy_terms()
    exact = MI_GI * height
    row = {"problem": "mode1", "h": h, "alpha": alpha, "safety": safety, "fracture_J": e["fracture"],
           "exact_J": exact, "error": abs(e["fracture"] / exact - 1.0), "error_signed": e["fracture"] / exact - 1.0,
           "broken": bool(cracks.broken[joint_ids].all()), "n_nodes": int(len(x0))}
    return stamp(row, t0, sim)


# ============================================================================ 4. Brazilian disc
def brazilian(divisions: int, alpha: float = 10.0, safety: float = 0.8, angle_deg: float = 0.0,
              G_I: float | None = None, v_platen: float = 0.05, check_every: int = 50) -> dict:
    """The Brazilian disc of ``cases/brazilian_disc.py`` with penalty ``alpha``, step factor
    ``safety``, the mesh rotated by ``angle_deg`` against the loaded (vertical) diameter and an
    optional fracture energy. Records the peak-load strength ratio, the process-zone length
    ``l_pz = E G_I / f_t^2`` and how many crack elements were damaged at the peak."""
    b = load_case("brazilian_disc")
    t0 = time.perf_counter()
    G_I = b.G_I if G_I is None else G_I
    R = b.DIAMETER / 2
    mesh = b.disc_mesh(divisions)
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    mesh = dataclasses.replace(mesh, points=np.ascontiguousarray(mesh.points @ rot.T))
    topo = build_topology(mesh)
    model = Model(topo, ElasticMaterial(young=b.YOUNG, poisson=b.POISSON, density=b.DENSITY))
    cracks = CrackSet(topo, {0: CrackProperties(f_t=b.F_T, c=b.COHESION, phi=b.PHI, G_I=G_I, G_II=b.G_II,
                                                p_n=alpha * b.YOUNG)})
    y_arc = R * math.cos(math.radians(6.0)) - 1e-9 * R
    top = model.prescribe_velocity(lambda x, y: y > y_arc, vx=0.0, vy=-v_platen)
    model.prescribe_velocity(lambda x, y: y < -y_arc, vx=0.0, vy=v_platen)
    sim = Simulation(model, providers=[cracks], progress=False, dt_fraction=safety)
    peak, damaged_at_peak, inelastic_at_peak = 0.0, 0, 0
    while True:
        sim.run(n_steps=check_every, energy_tolerance=None, output_every=10**9, history_every=10**6)
        P = float(-sim.reaction_force(top)[1])
        if P > peak:
            peak = P
            damaged_at_peak = int((cracks.damage > 0).sum())
            inelastic_at_peak = int(cracks.n_inelastic())
        if (peak > 0 and P < 0.5 * peak) or sim.state.step > 400_000:
            break
    sigma_t = 2 * peak / (math.pi * b.DIAMETER)
    ratio = sigma_t / b.F_T
    l_pz = b.YOUNG * G_I / b.F_T ** 2
    ev = cracks.events
    first = None if len(ev) == 0 else float(np.hypot(ev["x"][0], ev["y"][0]) / R)
    row = {"problem": "brazilian", "h": b.DIAMETER / divisions, "divisions": divisions, "alpha": alpha,
           "safety": safety, "angle_deg": angle_deg, "G_I": G_I, "l_pz_m": l_pz, "D_over_l_pz": b.DIAMETER / l_pz,
           "l_pz_over_h": l_pz * divisions / b.DIAMETER, "ratio": ratio, "error": abs(ratio - 1.0),
           "damaged_at_peak": damaged_at_peak, "inelastic_at_peak": inelastic_at_peak,
           "n_triangles": topo.n_triangles, "first_crack_r_over_R": first}
    return stamp(row, t0, sim)


# ============================================================================ 5. block on incline
def incline(size: float, alpha: float, safety: float, theta: float = 30.0, phi: float = 20.0) -> dict:
    """The sliding block of ``cases/block_on_incline.py`` (slide at 1 s against the rigid block)
    with contact penalty ``alpha E`` and step factor ``safety``."""
    m = load_case("block_on_incline")
    t0 = time.perf_counter()
    model, cracks, _, block = m.build(theta, phi, size=size)
    contact = ContactSet(model.topology, alpha * m.YOUNG, friction_angle=phi, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=False, dt_fraction=safety)
    x0 = sim.state.x[block].copy()
    sim.run(t_end=1.0, output_every=10**9, history_every=2000)
    slide = float((sim.state.x[block, 0] - x0[:, 0]).mean())
    exact = m.sliding_distance(theta, phi, sim.state.time)
    row = {"problem": "incline", "h": size, "alpha": alpha, "safety": safety, "slide_m": slide, "exact_m": exact,
           "error": abs(slide / exact - 1.0), "error_signed": slide / exact - 1.0,
           "balance_error_relative": sim.history[-1]["balance_error_relative"]}
    return stamp(row, t0, sim)


# ============================================================================ 6. two-body impact
def impact(size: float, alpha: float, safety: float) -> dict:
    """Frictionless impact of two elastic blocks (``tests/verification/test_impact.py``): largest total-energy
    error over the contact, relative to the initial energy."""
    t0 = time.perf_counter()
    E, NU, RHO = 1e9, 0.25, 2500.0
    left, right = rectangle(0.0, 0.0, 1.0, 0.5, "left"), rectangle(1.0, 0.1, 1.0, 0.5, "right")
    topo = build_topology(mesh_geometry(Geometry([left, right]), size))
    model = Model(topo, ElasticMaterial(young=E, poisson=NU, density=RHO))
    body = np.repeat(topo.triangle_body, 3)
    model.set_initial_velocity(vx=2.0, where=np.flatnonzero(body == 0))
    model.set_initial_velocity(vx=-1.0, where=np.flatnonzero(body == 1))
    cracks = CrackSet(topo, {0: glue(E, 10.0)})
    contact = ContactSet(topo, alpha * E, friction_angle=0.0, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=False, dt_fraction=safety)
    sim.run(t_end=3.0 / math.sqrt(E / RHO), history_every=20, energy_tolerance=None, output_every=10**9)
    e = np.array([r["kinetic"] + r["strain"] + r["crack_elastic"] + r["contact_elastic"] for r in sim.history])
    err = float(np.abs(e - e[0]).max() / e[0])
    row = {"problem": "impact", "h": size, "alpha": alpha, "safety": safety, "error": err}
    return stamp(row, t0, sim)


# ============================================================================ 7. planar slope FoS
def planar(size: float, alpha: float, safety: float, tangential_ratio: float = 1.0, geometry: str = "no_crack",
           tol: float = 0.03) -> dict:
    """Factor of safety of ``cases/planar_failure.py`` by strength reduction against Hoek-Bray,
    with penalty ``p_n = alpha E`` (contact too), ``p_t = tangential_ratio p_n`` and step factor
    ``safety``."""
    p = load_case("planar_failure")
    from fdem.cases.planar_failure import planar_slope_geometry
    from fdem.workflow.fos import factor_of_safety

    t0 = time.perf_counter()
    g = p.GEOMETRIES[geometry]
    le = p.analytic(**g)
    original = p.property_sets

    def sets(cohesion, friction_angle, penalty):
        out = original(cohesion, friction_angle, penalty)
        return {k: dataclasses.replace(v, p_t=tangential_ratio * penalty) for k, v in out.items()}

    p.property_sets = sets
    try:
        scene = p.planar_failure_simulation(planar_slope_geometry(p.HEIGHT, **g), size, penalty=alpha * p.YOUNG)
    finally:
        p.property_sets = original
    sim = scene.sim
    sim.dt_fraction = safety
    sim.dt = sim._choose_dt()
    result = factor_of_safety(sim, 1.0, 1.8, tol=tol, trial=p.trial_stage(sim))
    steps = sum(t.result.steps for t in result.trials) if hasattr(result.trials[0].result, "steps") else None
    row = {"problem": "planar", "h": size, "alpha": alpha, "safety": safety, "tangential_ratio": tangential_ratio,
           "fos": float(result.fos), "analytic_fos": le.fos, "bracket": list(result.bracket),
           "error": abs(result.fos / le.fos - 1.0), "error_signed": result.fos / le.fos - 1.0,
           "n_triangles": scene.n_triangles, "trial_steps": steps}
    stamp(row, t0, sim)
    row["steps"] = steps
    return row


# ============================================================================ 8. four-slope tangential penalty
def four_slope_scene(tangential: str, size: float, toe: float = 15.0, crest: float = 15.0, base: float = 7.5,
                     spacing: float = 2.5):
    """A compact low-angle four-slope (H = 15 m, 45 deg, brick fabric of spacing ``spacing``)
    meshed at ``size`` with the four-slope crack properties, ``tangential`` ``"paper"``
    (``k_t = 917 GPa/m``) or ``"tied"`` (``p_t = p_n``)."""
    from fdem.cases.four_slopes import four_slope_geometry

    fs = load_case("four_slopes")
    geo = four_slope_geometry("low", spacing, toe_length=toe, crest_length=crest, base_depth=base)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        topo = build_topology(mesh_geometry(geo, size))
    model = Model(topo, ElasticMaterial(young=fs.YOUNG, poisson=fs.POISSON, density=fs.DENSITY))
    model.set_gravity(0.0, -fs.GRAVITY)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    sets = four_slope_property_sets()
    if tangential == "tied":
        sets = {k: dataclasses.replace(v, k_t=None, p_t=v.p_n) for k, v in sets.items()}
    cracks = CrackSet(topo, sets, contact_penalty=fs.CONTACT_PENALTY)
    return model, cracks, fs


def tangential_study(size: float, with_fos: bool = True) -> list[dict]:
    """Paper (``k_t = 917 GPa/m``) against tied (``p_t = p_n``) tangential penalty on a compact
    four-slope: stable step; elastic displacement under gravity after a damped explicit run
    from rest (crack elements held elastic) against the static solve of the intact mesh;
    joint slip; and the factor of safety by strength reduction."""
    from fdem.solve.geostatic import conforming_static_stress, geostatic_start
    from fdem.workflow.stages import Convergence, Stage, response_time, run_stage
    from fdem.workflow.fos import factor_of_safety, fundamental_damping

    rows = []
    for tangential in ("paper", "tied"):
        t0 = time.perf_counter()
        model, cracks, fs = four_slope_scene(tangential, size)
        static = conforming_static_stress(model)
        u_static = static.displacement  # per mesh point
        contact = ContactSet(model.topology, fs.CONTACT_PENALTY, friction_angle=30.0, mass=model.node_mass(),
                             cracks=cracks)
        sim = Simulation(model, providers=[cracks, contact], progress=False)
        cracks.hold_elastic(True)
        T = response_time(model)
        stage = Stage("settle", max_time=4 * T, converge=Convergence(unbalanced_ratio=1e-5),
                      damping=fundamental_damping(sim))
        res = run_stage(sim, stage, frames=False)
        cracks.hold_elastic(False)
        topo = model.topology
        # explicit displacement of each exploded node against the static one of its mesh point
        point = np.asarray(topo.mesh_node)
        u_exp = sim.state.x - topo.x0
        u_ref = u_static[point]
        scale = float(np.abs(u_ref).max())
        disp_err = float(np.abs(u_exp - u_ref).max() / scale)
        settle_ratio = float(np.linalg.norm(u_exp) / np.linalg.norm(u_ref))
        g = sim.crack_geometry()
        joint = cracks.tag == 1
        slip = np.abs(g["slip"][joint])
        crit, limits = sim.critical_dt()
        row = {"problem": "tangential", "tangential": tangential, "h": size, "n_triangles": topo.n_triangles,
               "dt_s": sim.dt, "critical_dt_s": crit, "dt_limits_s": {k: float(v) for k, v in limits.items()},
               "settle_steps": sim.state.step, "settle_reason": res.reason,
               "displacement_error": disp_err, "displacement_norm_ratio": settle_ratio,
               "max_static_displacement_m": scale, "joint_slip_max_m": float(slip.max()),
               "joint_slip_mean_m": float(slip.mean()), "settle_wall_s": time.perf_counter() - t0}
        if with_fos:
            t1 = time.perf_counter()
            model, cracks, fs = four_slope_scene(tangential, size)
            geostatic_start(model, cracks)
            contact = ContactSet(model.topology, fs.CONTACT_PENALTY, friction_angle=30.0, mass=model.node_mass(),
                                 cracks=cracks)
            sim = Simulation(model, providers=[cracks, contact], progress=False)
            try:
                fos = factor_of_safety(sim, 0.6, 3.0, tol=0.1)
                row.update(fos=float(fos.fos), fos_bracket=list(fos.bracket),
                           fos_steps=int(sum(t.result.steps for t in fos.trials)))
            except ValueError as exc:  # the bracket did not hold
                row.update(fos=None, fos_note=str(exc)[:200])
            row["fos_wall_s"] = time.perf_counter() - t1
        row["loadavg"] = list(os.getloadavg())
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "dt_limits_s"}), flush=True)
    return rows


# ============================================================================ 9. runout of the demo slope
RUNOUT_DIR = ROOT / "runs" / "pareto_runout"


def runout_start() -> Path:
    """The failed state of the quick-start slope (``fdem demo``) that its runout starts from:
    made by running the demo's workflow (``runs/pareto_runout/runout_start.npz``), and made again
    whenever a kernel source has changed since (the digest of ``fdem._kernel_cache`` is kept
    beside it), so that no sweep starts from a state older kernels produced."""
    import fdem
    from fdem.kernels.cache import kernel_sources_digest

    path = RUNOUT_DIR / "runout_start.npz"
    stamp = RUNOUT_DIR / "kernel_sources.sha256"
    digest = kernel_sources_digest(Path(fdem.__file__).resolve().parent)
    if path.exists() and stamp.exists() and stamp.read_text().strip() == digest:
        return path
    from fdem.cases import quick_start
    from fdem.workflow.slope import SlopeWorkflow, run_slope_workflow

    path.unlink(missing_ok=True)
    _, sim, _, _ = quick_start.build(quick_start.SIZE, None, progress=False)
    RUNOUT_DIR.mkdir(parents=True, exist_ok=True)
    # the workflow saves the failed state before its runout; a short cap, since only the state is needed
    result = run_slope_workflow(sim, SlopeWorkflow(runout_time=1e-3), out_dir=RUNOUT_DIR)
    sim.close()
    if not path.exists():
        raise RuntimeError(f"the quick-start slope did not fail (outcome {result['outcome']!r}): "
                           f"no runout state to sweep; see {RUNOUT_DIR}")
    stamp.write_text(digest)
    return path


def runout(safety: float, seed: int | None = None, kick: float = 1e-6) -> dict:
    """The demo slope's runout to rest (the workflow's runout stage) from its failed state, at
    step factor ``safety``; with ``seed``, every node's velocity is first nudged by
    ``kick`` [m/s] (normal, seeded): the spread of such runs is the chaotic noise floor that a
    time-step effect must exceed to matter. Error measures: the ledger's balance error relative
    to the energy moved, and (in the docs) the runout distance against the smallest step."""
    from fdem.results.analysis import runout as runout_figures
    from fdem.geometry.polygons import slope_toe
    from fdem.cases import quick_start
    from fdem.solve.checkpoint import load_checkpoint
    from fdem.workflow.stages import response_time, run_stage
    from fdem.workflow.slope import SlopeWorkflow, runout_stage

    start = runout_start()
    geo, sim, cracks, _ = quick_start.build(quick_start.SIZE, None, progress=False)
    load_checkpoint(sim, start)
    t0 = time.perf_counter()   # the runout alone
    step0 = sim.state.step
    if seed is not None:
        sim.state.v += kick * np.random.default_rng(seed).standard_normal(sim.state.v.shape)
    topo = sim.model.topology
    t_start, broken0 = sim.state.time, int(cracks.broken.sum())
    res = run_stage(sim, runout_stage(SlopeWorkflow(runout_dt_fraction=safety), response_time(sim.model),
                                      float(np.ptp(topo.x0[:, 1])),
                                      float(np.linalg.norm(sim.gravity))), frames=False)
    toe_x, _ = slope_toe(geo.bodies[0])
    fig = runout_figures(topo, sim.state.x, toe_x)
    last = sim.history[-1]
    row = {"problem": "runout", "h": quick_start.SIZE, "alpha": quick_start.PENALTY / quick_start.YOUNG,
           "safety": safety, "seed": seed,
           "kick_m_s": kick if seed is not None else 0.0, "n_triangles": topo.n_triangles, "reason": res.reason,
           "runout_time_s": sim.state.time - t_start, "runout_distance_m": fig["runout_distance_m"],
           "displaced_area_m2": fig["displaced_area_m2"], "broken": int(cracks.broken.sum()),
           "broken_in_runout": int(cracks.broken.sum()) - broken0,
           "balance_error_relative": float(last["balance_error_relative"]),
           "error": abs(float(last["balance_error_relative"]))}
    sim.close()
    row = stamp(row, t0, sim)
    row["steps"] = sim.state.step - step0
    return row


# ============================================================================ 10. long run
def long_run(n_steps: int = 1_000_000) -> dict:
    """1e6 undamped steps of a small elastic block with glued crack elements released from a
    strained state: the ledger's balance error (drift) relative to the energy held."""
    t0 = time.perf_counter()
    E = 1e9
    topo = build_topology(jittered_rectangle(4, 4, 1.0, 1.0, 0.25, 3))
    model = Model(topo, ElasticMaterial(E, 0.25, 2000.0))
    cracks = CrackSet(topo, {0: glue(E, 10.0)})
    sim = Simulation(model, providers=[cracks], progress=False)
    H = np.array([[2e-3, 1e-3], [-5e-4, -1e-3]])
    sim.set_positions(topo.x0 + (topo.x0 - 0.5) @ H.T)
    sim.run(n_steps=n_steps, history_every=n_steps // 100, output_every=10**9)
    tot = np.array([r["total"] for r in sim.history])
    held = max(r["kinetic"] + r["strain"] + r["crack_elastic"] for r in sim.history)
    row = {"problem": "longrun", "n_steps": n_steps, "n_triangles": topo.n_triangles,
           "drift_max_relative": float(np.abs(tot - tot[0]).max() / held),
           "drift_end_relative": float((tot[-1] - tot[0]) / held), "energy_J": held}
    return stamp(row, t0, sim)


# ============================================================================ sweeps
def grid(*axes):
    out = [()]
    for a in axes:
        out = [o + (v,) for o in out for v in a]
    return out


def sweeps(quick: bool) -> dict:
    """(function, list of keyword sets) per problem."""
    q = quick
    return {
        "wave": (wave, [dict(h=h, alpha=a, safety=s) for h, a, s in
                        (grid((0.1, 0.05), (None, 1, 10, 100), (0.8,)) + [(0.05, 10, 0.5), (0.05, 10, 0.99)] if q else
                         grid((0.1, 0.05, 0.025), (None, 1, 10, 100, 1000), (0.8,))
                         + grid((0.05,), (None, 10, 100), (0.5, 0.99)))]),
        "column": (column, [dict(ny=n, alpha=a, safety=s) for n, a, s in
                            (grid((10, 20), (None, 10, 100), (0.8,)) if q else
                             grid((10, 20, 40), (None, 1, 10, 100), (0.8,)) + grid((20,), (None, 10), (0.5, 0.99)))]),
        "mode1": (mode1, [dict(h=h, alpha=a, safety=s) for h, a, s in
                          (grid((0.1, 0.05), (10, 100), (0.8,)) if q else
                           grid((0.1, 0.05, 0.025), (1, 10, 100), (0.8,)) + grid((0.05,), (10,), (0.3, 0.5, 0.99)))]),
        "brazilian": (brazilian, [dict(divisions=d, alpha=a, safety=s) for d, a, s in
                                  (grid((25, 35), (10,), (0.8,)) if q else
                                   grid((25, 40, 60, 80), (10,), (0.8,)) + grid((25,), (30, 100), (0.8,))
                                   + grid((25,), (10,), (0.5, 0.99)))]),
        "direction": (brazilian, [dict(divisions=d, angle_deg=a, G_I=g) for d, a, g in
                                  (grid((25,), (0.0, 30.0, 60.0), (None,)) if q else
                                   grid((25, 40), (0.0, 20.0, 40.0, 60.0), (None,))
                                   + grid((40,), (0.0, 40.0), (5.0, 80.0)))]),
        "incline": (incline, [dict(size=h, alpha=a, safety=s) for h, a, s in
                              (grid((0.5,), (5, 20, 100), (0.8,)) if q else
                               grid((0.5, 0.25), (5, 20, 100), (0.8,)) + grid((0.5,), (20,), (0.5, 0.99)))]),
        "impact": (impact, [dict(size=h, alpha=a, safety=s) for h, a, s in
                            (grid((0.25,), (10, 100), (0.2, 0.4, 0.8)) if q else
                             grid((0.25, 0.125), (10, 100, 1000), (0.2, 0.4, 0.8, 0.99)))]),
        "runout": (runout, [dict(safety=s) for s in ((0.4, 0.8) if q else (0.2, 0.4, 0.6, 0.8, 0.99))]
                   + [dict(safety=s, seed=k) for s in (0.4, 0.8) for k in range(2 if q else 4)]),
        "planar": (planar, [dict(size=1.5, alpha=5, safety=0.8)] if q else
                   [dict(size=h, alpha=a, safety=s) for h, a, s in
                    grid((1.5, 1.0), (5, 20), (0.8,)) + grid((1.5,), (5,), (0.5, 0.99))]
                   + [dict(size=1.5, alpha=5, safety=0.8, tangential_ratio=30.0)]),
    }


def run_problem(name: str, quick: bool) -> list[dict]:
    path = OUT / f"{name}.json"
    if name == "tangential":
        rows = tangential_study(size=1.5 if quick else 1.0, with_fos=not quick)
        for size in (1.0, 0.5):  # what the step costs on finer four-slope meshes (no run)
            for tangential in ("paper", "tied"):
                model, cracks, _ = four_slope_scene(tangential, size)
                crit, limits = Simulation(model, providers=[cracks], progress=False).critical_dt()
                rows.append({"problem": "tangential", "tangential": tangential, "h": size,
                             "n_triangles": model.topology.n_triangles, "critical_dt_s": crit,
                             "dt_limits_s": {k: float(v) for k, v in limits.items()}})
    elif name == "longrun":
        rows = [long_run(100_000 if quick else 1_000_000)]
        print(json.dumps(rows[0]), flush=True)
    else:
        fn, kwargs = sweeps(quick)[name]
        kwargs = [k if isinstance(k, dict) else k for k in kwargs]
        rows = []
        try:  # warm-up: compile the kernels this problem uses outside the timings
            fn(**kwargs[0])
        except InstabilityError:
            pass
        for kw in kwargs:
            try:
                r = fn(**kw)
            except InstabilityError as exc:
                r = {"problem": name, **kw, "error": float("nan"), "unstable": str(exc)[:200],
                     "loadavg": list(os.getloadavg())}
            rows.append(r)
            show = {k: (round(v, 5) if isinstance(v, float) else v) for k, v in r.items()
                    if k in ("h", "alpha", "safety", "angle_deg", "G_I", "tangential_ratio", "error", "wall_s",
                             "steps", "ratio", "settlement_error", "error_signed", "damaged_at_peak",
                             "seed", "runout_distance_m", "broken_in_runout", "reason")}
            print(name, show, flush=True)
            path.write_text(json.dumps({"quick": quick, "rows": rows}, indent=1))
    path.write_text(json.dumps({"quick": quick, "rows": rows}, indent=1))
    return rows


# ============================================================================ plots and tables
def pareto_front(points):
    """Indices of the points not dominated in (time, error), sorted by time."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def label(r: dict) -> str:
    a = "conf" if r.get("alpha") is None else f"a{r['alpha']:g}"
    parts = [f"h{r['h']:.3g}", a, f"s{r['safety']:g}"]
    if r.get("angle_deg") is not None:
        parts.append(f"{r['angle_deg']:g}deg")
    if r.get("tangential_ratio", 1.0) != 1.0:
        parts.append(f"pt{r['tangential_ratio']:g}pn")
    return " ".join(parts)


def plot(name: str, rows: list[dict]) -> Path | None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if "wall_s" in r and np.isfinite(r.get("error", np.nan))]
    if not ok:
        return None
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    alphas = sorted({r.get("alpha") for r in ok}, key=lambda a: -1 if a is None else a)
    markers = dict(zip(sorted({r["h"] for r in ok}), "osD^v<>"))
    cmap = plt.get_cmap("viridis")
    for i, a in enumerate(alphas):
        mine = [r for r in ok if r.get("alpha") == a]
        for r in mine:
            edge = "k" if r["safety"] == 0.8 else ("r" if r["safety"] > 0.9 else "b")
            ax.scatter(r["wall_s"], max(r["error"], 1e-7), marker=markers[r["h"]],
                       color=cmap(i / max(1, len(alphas) - 1)), edgecolors=edge, s=45, zorder=3)
        ax.scatter([], [], marker="s", color=cmap(i / max(1, len(alphas) - 1)),
                   label="conforming (no cracks)" if a is None else f"alpha = p/E = {a:g}")
    for h, m in markers.items():
        ax.scatter([], [], marker=m, color="0.5", label=f"h = {h:.3g} m")
    ax.scatter([], [], marker="o", facecolors="none", edgecolors="b", label="safety < 0.8")
    ax.scatter([], [], marker="o", facecolors="none", edgecolors="r", label="safety 0.99")
    pts = [(r["wall_s"], max(r["error"], 1e-7)) for r in ok]
    front = pareto_front(pts)
    ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "k--", lw=1, label="Pareto front")
    for i in front:
        ax.annotate(label(ok[i]), pts[i], fontsize=6, xytext=(3, 3), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s] (one thread)")
    ax.set_ylabel("relative error")
    ax.set_title(TITLES.get(name, name), fontsize=9)
    ax.legend(fontsize=6, loc="best")
    fig.tight_layout()
    path = OUT / f"{name}.png"
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


TITLES = {
    "wave": "P-wave arrival, exploded mesh with glued crack elements (error in wave speed)",
    "column": "gravity column: max stress error / rho g H",
    "mode1": "cohesive mode I: dissipated energy / G_I L - 1",
    "brazilian": "Brazilian disc: |sigma_t / f_t - 1|",
    "direction": "Brazilian disc: load direction and process zone",
    "incline": "block on incline: slide at 1 s",
    "impact": "two-body impact: max total-energy error",
    "planar": "planar slope: |FoS / Hoek-Bray - 1|",
    "runout": "demo slope runout to rest: |ledger balance error|",
}

COLUMNS = ["h", "alpha", "safety", "angle_deg", "G_I", "tangential_ratio", "seed", "error", "error_signed", "ratio",
           "settlement_error", "damaged_at_peak", "fos", "runout_distance_m", "displaced_area_m2", "broken_in_runout",
           "runout_time_s", "reason", "dt_s", "steps", "wall_s", "loadavg"]


def fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, list):
        return f"{v[0]:.1f}"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def tables(names) -> Path:
    lines = ["# Run time against error: every run", "",
             "Generated by `cases/benchmarks/pareto.py`; `loadavg` is the 1-min load average when the run ended.",
             ""]
    for name in names:
        path = OUT / f"{name}.json"
        if not path.exists():
            continue
        data = json.loads(path.read_text())
        rows = data["rows"]
        cols = [c for c in COLUMNS if any(c in r for r in rows)] if name not in ("tangential", "longrun") else \
            sorted({k for r in rows for k in r if k not in ("dt_limits_s", "problem", "fos_bracket")})
        lines += [f"## {name}{' (quick)' if data.get('quick') else ''}", "",
                  "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        for r in rows:
            lines.append("| " + " | ".join(fmt(r.get(c)) for c in cols) + " |")
        lines.append("")
    out = OUT / "tables.md"
    out.write_text("\n".join(lines))
    return out


ALL = ["wave", "column", "mode1", "brazilian", "direction", "incline", "impact", "runout", "planar", "tangential",
       "longrun"]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="+", choices=ALL, default=ALL)
    parser.add_argument("--quick", action="store_true", help="reduced sweeps (a few minutes)")
    parser.add_argument("--tables-only", action="store_true", help="re-plot and re-tabulate the stored JSON")
    args = parser.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for name in args.only:
        if not args.tables_only:
            t = time.perf_counter()
            run_problem(name, args.quick)
            print(f"== {name}: {time.perf_counter() - t:.0f} s, load {os.getloadavg()}", flush=True)
        path = OUT / f"{name}.json"
        if path.exists() and name not in ("tangential", "longrun"):
            plot(name, json.loads(path.read_text())["rows"])
    print(f"wrote {tables(ALL)}; total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
