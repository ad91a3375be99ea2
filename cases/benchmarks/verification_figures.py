"""The headline figures of ``docs/verification.md``'s table, computed as the tests compute them.

Each figure calls the package functions and case code that its test in ``tests/verification/``
calls, on the test's scene, mesh size and run length (the tests' own assertion helpers are
repeated here, importing ``fdem`` only), so that one command measures them all on any version
of the package that has these functions. The script imports whichever ``fdem`` comes first on
``sys.path``: with ``PYTHONPATH`` pointing at another checkout it measures that checkout (the
JSON names the package's path and commit; run the script as a file, since ``python -c`` from a
checkout's root puts that checkout first). A figure that cannot run on the measured version (a
function it lacks, a run that raises) is recorded as n/a with the reason.

Figures (test; the value compared is the error against the exact answer, or the quantity
that should be zero):

* 1D wave arrival, plane strain and plane stress with rollers, free bar (``test_solver.py``)
* gravity column sigma_yy and sigma_xx/sigma_yy, mass-proportional and local damping (``test_solver.py``)
* undamped energy drift of a released body over 2e4 steps (``test_solver.py``)
* two-body frictionless impact, full solver, alpha = 10, 100, 1000: energy and momentum (``test_impact.py``)
* block on incline sliding 30/20 and 40/25 at 1 s (``test_incline.py``)
* planar slope FoS by strength reduction, no crack and tension crack, size 1.5 m, bisection
  on [1.0, 1.8] to 0.03, against Hoek-Bray (``test_planar_failure.py``)
* planar block critical gravity factor, and the ledger through gravity increase (``test_stages.py``)
* ledger through the reduction schedule with breakage, contact and runout (``test_stages.py``)
* geostatic start, undamped, elements held elastic: max speed over one slope period (``test_geostatic.py``)
* Newmark block at h = 0.5 m (``test_shaking.py``)
* quiet boundary, P and S pulses: energy left in the bar (``test_shaking.py``)
* deformable block on incline with element damping 0.1 at 0.5 and 0.25 m (``test_damping.py``)

Prints the table and writes ``docs/benchmarks/verification_figures_<label>.json`` (``--out``);
``--compare BEFORE AFTER`` prints the before-and-after table (markdown) of two such files.
A figure counts as the same when its error moved by at most 5 % of the larger of the two, or
when both are below 1e-12 (round-off: the momentum), else better or worse by the size of the
error, however far below its tolerance.

    NUMBA_NUM_THREADS=1 nice -n 5 .venv/bin/python cases/benchmarks/verification_figures.py --label after
    git worktree add /tmp/vf_before 8e4bbaf
    PYTHONPATH=/tmp/vf_before NUMBA_CACHE_DIR=/tmp/vf_before_cache NUMBA_NUM_THREADS=1 nice -n 5 \\
        .venv/bin/python cases/benchmarks/verification_figures.py --label before
    .venv/bin/python cases/benchmarks/verification_figures.py --compare \\
        docs/benchmarks/verification_figures_before.json docs/benchmarks/verification_figures_after.json
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import traceback
import warnings
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
# appended, not prepended: a PYTHONPATH naming another checkout must win
sys.path.append(str(HERE.parents[1]))

from records import machine, record

DOCS = HERE.parents[1] / "docs" / "benchmarks"

FIGURES: list = []


def figure(fn):
    FIGURES.append(fn)
    return fn


def row(key: str, what: str, value, error, tolerance: float, unit: str, mesh_size=None, signed: bool = False,
        **extra) -> dict:
    """One figure: ``value`` as the test reads it (``signed``: an error with its sign), ``error``
    the magnitude held against ``tolerance`` (``None`` when the figure could not be computed)."""
    passes = None if error is None else bool(abs(error) < tolerance)
    return record(what, value, unit, mesh_size=mesh_size, threads=_threads(), key=key, error=error,
                  tolerance=tolerance, passes=passes, signed=signed, **extra)


def na(key: str, what: str, tolerance: float | None, unit: str, reason: str) -> dict:
    return row(key, what, None, None, tolerance, unit, na=reason)


def _threads():
    try:
        import numba

        return numba.get_num_threads()
    except Exception:  # noqa: BLE001
        return None


# ----------------------------------------------------------------------------- test_solver.py
E_S, NU_S, RHO_S, G_S = 1e9, 0.25, 2000.0, 10.0


def arrival_time_error(plane, rollers, nx=400, ny=1, length=10.0, width=0.025, station=6.0):
    """tests/verification/test_solver.py: relative error of the arrival time of a velocity step
    at ``station`` (half-amplitude crossing)."""
    from fdem.mesh.mesh import structured_rectangle
    from fdem.physics.elastic import ElasticMaterial, bar_wave_speed
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    mat = ElasticMaterial(E_S, NU_S, RHO_S, plane=plane)
    model = Model.from_mesh(structured_rectangle(nx, ny, length, width), mat, exploded=False)
    v0 = 0.01
    model.prescribe_velocity("left", vx=v0)
    if rollers:
        model.roller("bottom", "y")
        model.roller("top", "y")
    sim = Simulation(model, progress=False)
    node = int(np.argmin(np.hypot(model.topology.x0[:, 0] - station, model.topology.x0[:, 1])))
    c = mat.p_wave_speed if rollers else bar_wave_speed(E_S, RHO_S)
    times, speeds = [], []
    while sim.state.time < 1.3 * station / c:
        sim.step()
        times.append(sim.state.time - 0.5 * sim.dt)
        speeds.append(sim.state.v[node, 0] / v0)
    t, s = np.array(times), np.array(speeds)
    k = int(np.argmax(s >= 0.5))
    if not (k > 0 and s[:k].max() < 0.5):
        raise RuntimeError("the front arrives before any sample or the signal rises early")
    t_arrival = t[k - 1] + (0.5 - s[k - 1]) / (s[k] - s[k - 1]) * (t[k] - t[k - 1])
    return t_arrival / (station / c) - 1.0, model.n_triangles


@figure
def wave_arrival():
    out = []
    for key, what, args in (("wave_plane_strain", "1D wave arrival, plane strain, rollers", ("strain", True, {})),
                            ("wave_plane_stress", "1D wave arrival, plane stress, rollers", ("stress", True, {})),
                            ("wave_free_bar", "1D wave arrival, free bar", ("stress", False, {"ny": 2, "width": 0.05}))):
        err, n = arrival_time_error(args[0], args[1], **args[2])
        out.append(row(key, what, err, abs(err), 0.02, "relative", mesh_size=n, signed=True))
    return out


def _jittered(nx, ny, w, h, amount=0.25, seed=1):
    from fdem.mesh.mesh import jittered_rectangle

    return jittered_rectangle(nx, ny, w, h, amount, seed)


@figure
def gravity_column():
    """test_gravity_column_converges_to_static_stresses: 1500 + 3500 damped steps."""
    from fdem.physics.elastic import ElasticMaterial, k0_elastic
    from fdem.solve.damping import Damping
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    alpha = 2 * np.pi * ElasticMaterial(E_S, NU_S, RHO_S).p_wave_speed / (2 * 10.0)
    out = []
    for name, damping in (("mass_proportional", Damping(mass_proportional=alpha)), ("local", Damping(local=0.8))):
        model = Model.from_mesh(_jittered(3, 30, 1.0, 10.0, amount=0.2), ElasticMaterial(E_S, NU_S, RHO_S),
                                exploded=False)
        model.set_gravity(0.0, -G_S)
        model.fix("bottom")
        model.roller("left", "x")
        model.roller("right", "x")
        sim = Simulation(model, progress=False)
        sim.run(n_steps=1500, damping=damping, history_every=100)
        sim.run(n_steps=3500, damping=damping, history_every=500)
        s = sim.stresses()
        yc = model.centroids0[:, 1]
        scale = RHO_S * G_S * 10.0
        err_yy = float(np.max(np.abs(s["yy"] - (-RHO_S * G_S * (10.0 - yc)))) / scale)
        err_xx = float(np.max(np.abs(s["xx"] - k0_elastic(NU_S) * s["yy"])) / scale)
        last = sim.history[-1]
        out.append(row(f"column_syy_{name}", f"gravity column sigma_yy, {name.replace('_', '-')} damping", err_yy,
                       err_yy, 0.01, "of rho g H", mesh_size=model.n_triangles,
                       kinetic_over_strain=last["kinetic"] / last["strain"]))
        out.append(row(f"column_sxx_{name}", f"gravity column sigma_xx/sigma_yy, {name.replace('_', '-')} damping",
                       err_xx, err_xx, 0.01, "of rho g H", mesh_size=model.n_triangles))
    return out


@figure
def energy_drift():
    """test_energy_conservation_of_released_elastic_body: 2e4 undamped steps."""
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    model = Model.from_mesh(_jittered(6, 6, 2.0, 2.0, seed=7), ElasticMaterial(E_S, NU_S, RHO_S), exploded=False)
    sim = Simulation(model, progress=False)
    H = np.array([[2e-3, 1e-3], [-5e-4, -1e-3]])
    sim.set_positions(model.topology.x0 + (model.topology.x0 - 1.0) @ H.T)
    sim.run(n_steps=20_000, history_every=500)
    total = np.array([r["total"] for r in sim.history])
    drift = float(np.max(np.abs(total - total[0])) / abs(total[0]))
    return [row("energy_drift", "energy drift, no damping, 2e4 steps", drift, drift, 0.005, "relative",
                mesh_size=model.n_triangles)]


# ----------------------------------------------------------------------------- test_impact.py
@figure
def impact():
    from fdem.geometry.polygons import rectangle
    from fdem.geometry.section import Geometry
    from fdem.mesh.topology import build_topology
    from fdem.mesh.triangulate import mesh_geometry
    from fdem.physics.contact import ContactSet
    from fdem.physics.crack_properties import CrackProperties
    from fdem.physics.cracks import CrackSet
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    E, NU, RHO = 1e9, 0.25, 2500.0
    out = []
    for alpha in (10.0, 100.0, 1000.0):
        left, right = rectangle(0.0, 0.0, 1.0, 0.5, "left"), rectangle(1.0, 0.1, 1.0, 0.5, "right")
        topo = build_topology(mesh_geometry(Geometry([left, right]), 0.25))
        model = Model(topo, ElasticMaterial(young=E, poisson=NU, density=RHO))
        body = np.repeat(topo.triangle_body, 3)
        model.set_initial_velocity(vx=2.0, where=np.flatnonzero(body == 0))
        model.set_initial_velocity(vx=-1.0, where=np.flatnonzero(body == 1))
        glue = CrackProperties(f_t=1e12, c=1e12, phi=30.0, G_I=1e15, G_II=1e15, p_n=10 * E)
        cracks = CrackSet(topo, {0: glue})
        contact = ContactSet(topo, alpha * E, friction_angle=0.0, mass=model.node_mass(), cracks=cracks)
        sim = Simulation(model, providers=[cracks, contact], progress=False, dt_fraction=0.4)
        m = sim.state.mass
        p0 = (m[:, None] * sim.state.v).sum(axis=0)
        sim.run(t_end=3 * 1.0 / np.sqrt(E / RHO), history_every=50, energy_tolerance=None)
        p1 = (m[:, None] * sim.state.v).sum(axis=0)
        p_err = float(np.abs(p1 - p0).max() / np.abs(m * np.hypot(*sim.state.v.T)).sum())
        first = sim.history[0]
        total0 = first["kinetic"] + first["strain"]
        energies = [r["kinetic"] + r["strain"] + r["crack_elastic"] + r["contact_elastic"] for r in sim.history]
        e_err = float(max(abs(e - total0) for e in energies) / total0)
        v_left = float((m[body == 0, None] * sim.state.v[body == 0]).sum(axis=0)[0] / m[body == 0].sum())
        a = int(alpha)
        out.append(row(f"impact_energy_{a}", f"two-body impact energy, alpha {a}", e_err, e_err, 0.01, "relative",
                       mesh_size=topo.n_triangles, v_left=v_left))
        out.append(row(f"impact_momentum_{a}", f"two-body impact momentum, alpha {a}", p_err, p_err, 1e-10,
                       "of sum m|v|", mesh_size=topo.n_triangles))
    return out


# ----------------------------------------------------------------------------- test_incline.py
@figure
def incline_sliding():
    from fdem.cases import block_on_incline as incline

    out = []
    for theta, phi in ((30.0, 20.0), (40.0, 25.0)):
        r = incline.run(theta, phi, t_end=1.0)
        err = r["slide_m"] / r["exact_m"] - 1.0
        out.append(row(f"incline_{int(theta)}_{int(phi)}", f"block on incline sliding {theta:g}/{phi:g}", err,
                       abs(err), 0.02, "relative", mesh_size=r["n_block_triangles"], signed=True,
                       ledger=r["balance_error_relative"], steps=int(r["steps"])))
    return out


# ----------------------------------------------------------------------------- test_planar_failure.py
@figure
def planar_fos():
    """test_strength_reduction_fos_matches_hoek_bray: size 1.5, bisection on [1.0, 1.8] to 0.03."""
    from fdem.cases import planar_failure as pf

    out = []
    for name in ("no_crack", "tension_crack"):
        r = pf.run_case(name, size=1.5, lower=1.0, upper=1.8, tol=0.03)
        err = r["fos"] / r["analytic_fos"] - 1.0
        lo, hi = r["bracket"]
        trials_ok = all(t["stable"] == (t["factor"] <= lo) for t in r["trials"])
        tags = set(r["failure_surface_tags"])
        out.append(row(f"planar_fos_{name}", f"planar slope FoS, {name.replace('_', ' ')}, size 1.5 m", err,
                       abs(err), 0.10, "relative", mesh_size=r["n_triangles"], signed=True, fos=r["fos"],
                       analytic_fos=r["analytic_fos"], bracket=[lo, hi], n_trials=r["n_trials"],
                       trials=[[t["factor"], t["stable"], t["reason"], t["t_end"], t["steps"]] for t in r["trials"]],
                       trials_consistent=trials_ok, joint_failure=tags <= {1, 2} and 1 in tags,
                       n_broken_first_failure=r["n_broken_first_failure"]))
    return out


# ----------------------------------------------------------------------------- test_stages.py
PLANAR_SIZE = 1.6  # tests/conftest.py


def planar_slope_scene(geometry: str = "no_crack", size: float = PLANAR_SIZE):
    """tests/conftest.py's planar_slope_scene."""
    from fdem.cases import planar_failure as pf

    return pf.planar_failure_simulation(pf.planar_slope_geometry(pf.HEIGHT, **pf.GEOMETRIES[geometry]), size)


@figure
def gravity_increase():
    """test_gravity_increase_books_its_work_and_finds_the_critical_gravity_factor."""
    from fdem.cases import planar_failure as pf
    from fdem.workflow.fos import GravityIncrease, factor_of_safety
    from fdem.workflow.stages import Stage, response_time, run_stage

    s = planar_slope_scene()
    sim = s.sim
    le = pf.analytic(**pf.GEOMETRIES["no_crack"])
    psi, phi = np.radians(35.0), np.radians(pf.JOINT_FRICTION)
    k_exact = pf.JOINT_COHESION * le.plane_length / (le.weight * (np.sin(psi) - np.cos(psi) * np.tan(phi)))
    result = factor_of_safety(sim, lower=1.0, upper=5.0, tol=0.1, trigger=GravityIncrease())
    err = result.fos / k_exact - 1.0
    T = response_time(sim.model)
    run_stage(sim, Stage("heavier", duration=2 * T, gravity_factor=2.0), frames=False)
    run_stage(sim, Stage("failing", duration=4 * T, gravity_factor=1.3 * k_exact), frames=False)
    ledger = float(max(abs(r["balance_error_relative"]) for r in sim.history))
    n = s.n_triangles
    return [row("gravity_factor", "planar block critical gravity factor", err, abs(err), 0.10, "relative",
                mesh_size=n, signed=True, fos=result.fos, exact=float(k_exact), bracket=list(map(float, result.bracket)),
                n_trials=len(result.trials)),
            row("ledger_gravity", "ledger through gravity increase", ledger, ledger, 0.01, "of energy scale",
                mesh_size=n)]


@figure
def ledger_reduction():
    """test_ledger_closes_through_a_reduction_schedule_with_breakage_and_contact."""
    from fdem.workflow.slope import SlopeWorkflow, run_slope_workflow
    from fdem.workflow.stages import response_time

    s = planar_slope_scene("tension_crack")
    sim = s.sim
    T = response_time(sim.model)
    wf = SlopeWorkflow(factors=(1.2, 1.6, 2.2, 3.0), step_time=8 * T, fail_displacement=0.02, runout_time=0.6)
    summary = run_slope_workflow(sim, wf)
    ledger = float(max(abs(r["balance_error_relative"]) for r in sim.history))
    return [row("ledger_reduction", "ledger through a reduction schedule with breakage", ledger, ledger, 0.01,
                "of energy scale", mesh_size=s.n_triangles, equilibrium=summary["equilibrium"],
                outcome=summary["outcome"], failed_at_factor=summary.get("failed_at_factor"),
                n_broken=int(s.cracks.broken.sum()), n_touching=int(s.contact.n_touching),
                stages=[[st["name"], st["reason"], st["steps"]] for st in summary["stages"]])]


# ----------------------------------------------------------------------------- test_geostatic.py
@figure
def geostatic():
    """test_static_start_stays_at_rest_and_k0_start_jolts, the static start (the K0 start, the
    test's contrast, is left out)."""
    from fdem.cases.four_slopes import four_slope_geometry, four_slope_property_sets
    from fdem.mesh.topology import build_topology
    from fdem.mesh.triangulate import mesh_geometry
    from fdem.physics.contact import ContactSet
    from fdem.physics.cracks import CrackSet
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.geostatic import geostatic_start, unbalanced_force_ratio
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    E, NU, RHO, G = 0.59e9, 0.29, 2680.0, 9.81
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        topo = build_topology(mesh_geometry(four_slope_geometry("low", "coarse"), size=2.5))
    model = Model(topo, ElasticMaterial(E, NU, RHO))
    model.set_gravity(0.0, -G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    cracks = CrackSet(topo, four_slope_property_sets(), contact_penalty=10 * E)
    report = geostatic_start(model, cracks)
    cracks.hold_elastic()
    contact = ContactSet(topo, 10 * E, friction_angle=30.0, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=False)
    sim.monitors.clear()
    c_s = np.sqrt(E / (2 * (1 + NU)) / RHO)
    n_steps = int(np.ceil(4 * 15.0 / c_s / sim.dt))
    sim.step()
    ufr1 = float(unbalanced_force_ratio(sim))
    vmax = 0.0
    for k in range(n_steps):
        sim.step()
        if k % 20 == 0:
            vmax = max(vmax, float(np.abs(sim.state.v).max()))
    return [row("geostatic_speed", "geostatic start, max speed over one slope period", vmax, vmax, 1e-3, "m/s",
                mesh_size=topo.n_triangles, ufr_first_step=ufr1, preload_residual=float(report.preload_residual),
                steps=n_steps + 1)]


# ----------------------------------------------------------------------------- test_shaking.py
@figure
def newmark():
    from fdem.cases import newmark_block

    r = newmark_block.run(size=0.5, t_after=0.2, n_samples=20)
    err = r["slip_m"] / r["newmark_m"] - 1.0
    return [row("newmark", "Newmark block, h = 0.5 m", err, abs(err), 0.05, "relative",
                mesh_size=r["n_block_triangles"], signed=True, ledger=r["balance_error_relative"], steps=int(r["steps"]))]


def _pulse_in_a_bar(kind: str, length=20.0, nx=200, xc=6.0, w=2.0):
    """test_shaking.py's _pulse_in_a_bar with the quiet end: energy left in the bar and absorbed
    (fractions of the pulse's) and the ledger error."""
    from fdem.mesh.mesh import structured_rectangle
    from fdem.physics.boundaries import QuietBoundary
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    E, NU, RHO = 1e9, 0.25, 2700.0
    mesh = structured_rectangle(nx, 2, length, 2 * length / nx)
    mat = ElasticMaterial(young=E, poisson=NU, density=RHO)
    model = Model.from_mesh(mesh, mat, exploded=False)
    comp = 0 if kind == "P" else 1
    c = mat.p_wave_speed if kind == "P" else mat.s_wave_speed
    model.fix(lambda x, y: np.ones_like(x, bool), x=comp == 1, y=comp == 0)
    sim = Simulation(model, providers=[QuietBoundary(model, "right")], progress=False)
    X = sim.x0[:, 0]
    U = 1e-4

    def f(xi):
        return np.where(np.abs(xi) < 1, np.cos(np.pi * xi / 2) ** 2, 0.0)

    def fp(xi):
        return np.where(np.abs(xi) < 1, -np.pi / 2 * np.sin(np.pi * xi), 0.0)

    sim.state.x[:, comp] += U * f((X - xc) / w)
    sim.state.v[:, comp] = -c * U / w * fp((X - xc + 0.5 * c * sim.dt) / w)
    sim.run(t_end=(length - xc + w + 6.0) / c, history_every=50, energy_tolerance=None)
    h0, h1 = sim.history[0], sim.history[-1]
    e0 = h0["kinetic"] + h0["strain"]
    return ((h1["kinetic"] + h1["strain"]) / e0, h1.get("quiet_boundary", 0.0) / e0,
            max(abs(r["balance_error_relative"]) for r in sim.history), model.n_triangles)


@figure
def quiet_boundary():
    out = []
    for kind in ("P", "S"):
        left, absorbed, ledger, n = _pulse_in_a_bar(kind)
        out.append(row(f"quiet_{kind}", f"quiet boundary, {kind} pulse, energy left", float(left), float(left), 0.05,
                       "of pulse energy", mesh_size=n, absorbed=float(absorbed), ledger=float(ledger)))
    return out


# ----------------------------------------------------------------------------- test_damping.py
@figure
def damped_incline():
    from fdem.cases import block_on_incline as incline

    out = []
    for size in (0.5, 0.25):
        r = incline.run(30.0, 20.0, t_end=1.0, size=size)
        err = r["slide_m"] / r["exact_m"] - 1.0
        out.append(row(f"damped_incline_{size:g}", f"damped incline 30/20 (element damping {r['element_damping']:g}), "
                                                   f"h = {size:g} m", err, abs(err), 0.02, "relative",
                       mesh_size=r["n_block_triangles"], signed=True, ledger=r["balance_error_relative"], steps=int(r["steps"])))
    return out


# ----------------------------------------------------------------------------- bookkeeping
def _source() -> dict:
    import fdem

    root = Path(fdem.__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip()
        dirty = bool(subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--", "fdem"],
                                    check=False, capture_output=True, text=True).stdout.strip())
    except (OSError, subprocess.CalledProcessError):
        commit, dirty = None, None
    return {"fdem": str(Path(fdem.__file__).resolve().parent), "commit": commit, "fdem_modified": dirty}


def fmt(r: dict) -> str:
    if r.get("value") is None:
        return "n/a"
    v = r["error"]
    if r["unit"] in ("relative", "of rho g H", "of energy scale", "of pulse energy") and abs(v) >= 1e-6:
        return f"{100 * r['value']:+.3g} %" if r.get("signed") else f"{100 * v:.3g} %"
    return f"{r['value']:.3g}" + (" m/s" if r["unit"] == "m/s" else "")


def fmt_tol(r: dict) -> str:
    t = r["tolerance"]
    if t is None:
        return "-"
    if r["unit"] == "m/s":
        return f"< {t:g} m/s"
    return f"{100 * t:g} %" if t >= 1e-4 else f"{t:g}"


def verdict(before: dict, after: dict) -> str:
    if before.get("error") is None or after.get("error") is None:
        return "n/a"
    a, b = abs(before["error"]), abs(after["error"])
    if a == b:
        return "same (identical)"
    if abs(a - b) <= 0.05 * max(a, b) or max(a, b) < 1e-12:
        return "same"
    return "better" if b < a else "worse"


def compare(before_path: Path, after_path: Path) -> None:
    before = json.loads(Path(before_path).read_text())
    after = json.loads(Path(after_path).read_text())
    rb = {r["key"]: r for r in before["records"]}
    print(f"| figure | tolerance | before ({str(before.get('commit'))[:7]}) | after ({str(after.get('commit'))[:7]}) "
          "| after against before |")
    print("|---|---|---|---|---|")
    for r in after["records"]:
        b = rb.get(r["key"], {"value": None, "error": None})
        print(f"| {r['what']} | {fmt_tol(r)} | {fmt(b)} | {fmt(r)} | {verdict(b, r)} |")
    for key in rb.keys() - {r["key"] for r in after["records"]}:
        print(f"| {rb[key]['what']} | {fmt_tol(rb[key])} | {fmt(rb[key])} | n/a | n/a |")
    print(f"\nwall: before {before.get('wall_seconds', float('nan')):.0f} s, after "
          f"{after.get('wall_seconds', float('nan')):.0f} s")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--label", default="after", help="name of the run (file name and JSON)")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON file (default docs/benchmarks/verification_figures_<label>.json)")
    parser.add_argument("--only", nargs="*", default=None, help="figure functions to run (default all): "
                        + ", ".join(f.__name__ for f in FIGURES))
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("BEFORE", "AFTER"),
                        help="print the before-and-after table of two JSON files and exit")
    args = parser.parse_args(argv)
    if args.compare:
        compare(*args.compare)
        return 0
    out = args.out or DOCS / f"verification_figures_{args.label}.json"
    source = _source()
    print(f"fdem from {source['fdem']} (commit {source['commit']}), {_threads()} Numba thread(s)", flush=True)
    records, wall0 = [], time.perf_counter()
    for fn in FIGURES:
        if args.only and fn.__name__ not in args.only:
            continue
        t0 = time.perf_counter()
        try:
            rows = fn()
        except Exception as err:  # noqa: BLE001  (an API this version lacks, or a run that broke)
            traceback.print_exc()
            rows = [na(fn.__name__, fn.__name__.replace("_", " "), None, "", f"{type(err).__name__}: {err}")]
        seconds = time.perf_counter() - t0
        for r in rows:
            r["figure_seconds"] = seconds
            value = "n/a (" + r["na"] + ")" if r.get("na") else fmt(r)
            flag = "" if r["passes"] is None else ("  ok" if r["passes"] else "  FAILS its tolerance")
            print(f"{r['what']:62s} {value:>14s}   tolerance {fmt_tol(r):>10s}{flag}", flush=True)
        print(f"  ({fn.__name__}: {seconds:.1f} s)", flush=True)
        records.extend(rows)
    wall = time.perf_counter() - wall0
    doc = {"benchmark": f"verification_figures_{args.label}",
           "date": datetime.now(UTC).isoformat(timespec="seconds"), "machine": machine(),
           "label": args.label, **source, "numba_threads": _threads(), "nice": os.nice(0),
           "load_average": list(os.getloadavg()), "wall_seconds": wall, "records": records}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1, default=_jsonable))
    print(f"wall {wall:.0f} s; wrote {out}")
    return 0


def _jsonable(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, (np.bool_,)):
        return bool(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON: {type(o)}")


if __name__ == "__main__":
    sys.exit(main())
