"""Base shaking and quiet boundaries: acceleration histories (checks, exact integration,
baseline correction), Newmark's rigid block against its closed form, plane P and S pulses
leaving through Lysmer-Kuhlemeyer dashpots, the energy ledger through shaking, and the FDEM
block on an incline against Newmark (verification.md)."""
import math

import numpy as np
import pytest

from fdem.physics.boundaries import QuietBoundary
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.elastic import ElasticMaterial
from fdem.mesh.mesh import structured_rectangle
from fdem.solve.model import Model
from fdem.physics.shaking import AccelerationHistory, shake_base
from fdem.reference.newmark import (newmark_displacement, newmark_response, rectangular_pulse_displacement, yield_acceleration)
from fdem.solve.simulation import Simulation
from fdem.mesh.topology import build_topology

from conftest import load_case

E, NU, RHO = 1e9, 0.25, 2700.0


# ----------------------------------------------------------------------------- histories
def test_history_rejects_bad_input_naming_the_row(tmp_path):
    with pytest.raises(ValueError, match="row 2"):
        AccelerationHistory([0.0, 0.1, 0.1, 0.3], [0, 1, 2, 3])
    with pytest.raises(ValueError, match="a_x is not finite in row 1"):
        AccelerationHistory([0.0, 0.1, 0.2], [0, np.nan, 2])
    with pytest.raises(ValueError, match="at least two samples"):
        AccelerationHistory([0.0], [1.0])
    csv = tmp_path / "record.csv"
    csv.write_text("t,ax,ay\n0,0,0\n0.1,1,0\n0.2,oops,0\n")
    with pytest.raises(ValueError, match="line 4"):
        AccelerationHistory.from_csv(csv)
    csv.write_text("t,ax,ay\n0,0,0\n0.1,1,0.5\n0.2,0,0\n")
    h = AccelerationHistory.from_csv(csv)
    assert h.a.shape == (3, 2) and h.a[1, 1] == 0.5


def test_velocity_is_the_exact_integral_of_the_piecewise_linear_record():
    # one sine cycle: v = A T (1 - cos(2 pi t / T)) / (2 pi), back to rest at T; d(T) = A T^2 / (2 pi)
    A, T = 3.0, 0.8
    h = AccelerationHistory.sine_pulse(A, T, samples_per_cycle=2000)
    t = np.linspace(0, T, 7)
    v_exact = A * T * (1 - np.cos(2 * np.pi * t / T)) / (2 * np.pi)
    assert np.allclose(h.velocity(t)[:, 0], v_exact, atol=1e-5 * A * T)
    assert h.displacement(T)[0] == pytest.approx(A * T * T / (2 * np.pi), rel=1e-5)
    # trapezoid at the samples, quadratic between: the velocity a solver samples mid-step is exact
    r = AccelerationHistory([0.0, 1.0, 3.0], [0.0, 2.0, 0.0])
    assert r.velocity(0.5)[0] == pytest.approx(0.25)          # int_0^0.5 2 s ds
    assert r.velocity(3.0)[0] == pytest.approx(3.0)           # trapezoid: 1 + 2
    assert r.velocity(10.0)[0] == pytest.approx(3.0)          # held after the record
    assert r.velocity_component(0)(2.0) == pytest.approx(1 + 2 * 1 - 1 / 2)
    assert r.displacement(4.0)[0] == pytest.approx(1 / 3 + (1 * 2 + 2 * 2 - 8 / 6) + 3.0)
    box = AccelerationHistory.rectangular_pulse(2.0, 0.5, direction=(0.6, 0.8), start=1.0)
    assert np.allclose(box.velocity(5.0), [0.6, 0.8]) and np.allclose(box.acceleration(0.9), 0.0)


def test_linear_baseline_brings_the_base_to_rest():
    t = np.linspace(0, 2, 201)
    h = AccelerationHistory(t, 1.0 + np.sin(3 * t), baseline="linear")
    assert abs(h.velocity(2.0)[0]) < 1e-12
    raw = AccelerationHistory(t, 1.0 + np.sin(3 * t))
    # the correction subtracts the line v_end (t - t0) / (tN - t0) from the velocity
    assert np.allclose(h.velocity(t)[:, 0], raw.velocity(t)[:, 0] - raw.velocity(2.0)[0] * t / 2.0)


# ----------------------------------------------------------------------------- Newmark
@pytest.mark.parametrize("ratio", [1.5, 3.0])
def test_newmark_rectangular_pulse_matches_closed_form(ratio):
    theta, phi, tp = 20.0, 30.0, 0.3
    ay, _ = yield_acceleration(theta, phi)
    assert ay == pytest.approx(9.81 * (math.cos(math.radians(20)) * math.tan(math.radians(30))
                                       - math.sin(math.radians(20))))
    ap = ratio * ay
    # base accelerates up the slope (a_b < 0): drive -a_b = a_p for 0 <= t <= t_p
    d = newmark_displacement([0.0, tp], [-ap, -ap], theta, phi)
    assert d == pytest.approx(rectangular_pulse_displacement(ap, tp, ay), rel=1e-12)
    assert d == pytest.approx(ap * tp ** 2 * (ap - ay) / (2 * ay), rel=1e-12)
    # it stops at t = a_p t_p / a_y
    t, dd, v = newmark_response([0.0, tp], [-ap, -ap], theta, phi)
    assert t[-1] == pytest.approx(ap * tp / ay, rel=1e-12) and v[-1] == 0.0


def test_newmark_block_sticks_below_the_yield_acceleration():
    h = AccelerationHistory.sine_pulse(-0.99 * yield_acceleration(20.0, 30.0)[0], 1.0)
    assert newmark_displacement(h.t, h.a[:, 0], 20.0, 30.0) == 0.0
    # the same record split at extra evaluation times gives the same answer
    h = AccelerationHistory.sine_pulse(-2.0 * yield_acceleration(20.0, 30.0)[0], 1.0)
    d = newmark_displacement(h.t, h.a[:, 0], 20.0, 30.0)
    _, dd, _ = newmark_response(h.t, h.a[:, 0], 20.0, 30.0, t_eval=np.linspace(-0.5, 3, 357))
    assert dd[-1] == pytest.approx(d, rel=1e-12) and dd[0] == 0.0


# ----------------------------------------------------------------------------- quiet boundaries
def _pulse_in_a_bar(kind: str, end: str, length=20.0, nx=200, xc=6.0, w=2.0):
    """A right-going plane P (or S) pulse in a bar held to 1D motion; the right end quiet or fixed.

    Returns ``(energy left in the bar / pulse energy, absorbed / pulse energy, ledger error)``
    once the pulse has had time to reach the end and come 6 m back."""
    mesh = structured_rectangle(nx, 2, length, 2 * length / nx)
    mat = ElasticMaterial(young=E, poisson=NU, density=RHO)
    model = Model.from_mesh(mesh, mat, exploded=False)
    comp = 0 if kind == "P" else 1
    c = mat.p_wave_speed if kind == "P" else mat.s_wave_speed
    model.fix(lambda x, y: np.ones_like(x, bool), x=comp == 1, y=comp == 0)  # plane wave, 1D motion
    providers = []
    if end == "quiet":
        providers.append(QuietBoundary(model, "right"))
    else:
        model.fix("right", x=comp == 0, y=comp == 1)
    sim = Simulation(model, providers=providers, progress=False)
    X = sim.x0[:, 0]
    U = 1e-4

    def f(xi):
        return np.where(np.abs(xi) < 1, np.cos(np.pi * xi / 2) ** 2, 0.0)

    def fp(xi):
        return np.where(np.abs(xi) < 1, -np.pi / 2 * np.sin(np.pi * xi), 0.0)

    # u = U f((X - xc - c t) / w): right-going; leapfrog velocities live at t = -dt/2
    sim.state.x[:, comp] += U * f((X - xc) / w)
    sim.state.v[:, comp] = -c * U / w * fp((X - xc + 0.5 * c * sim.dt) / w)
    sim.run(t_end=(length - xc + w + 6.0) / c, history_every=50, energy_tolerance=None)
    h0, h1 = sim.history[0], sim.history[-1]
    e0 = h0["kinetic"] + h0["strain"]
    return ((h1["kinetic"] + h1["strain"]) / e0, h1.get("quiet_boundary", 0.0) / e0,
            max(abs(r["balance_error_relative"]) for r in sim.history))


@pytest.mark.parametrize("kind", ["P", "S"])
def test_plane_pulse_leaves_through_a_quiet_boundary(kind):
    left, absorbed, ledger = _pulse_in_a_bar(kind, "quiet")
    assert left < 0.05            # measured: 0.05 % (P), 0.02 % (S)
    assert absorbed == pytest.approx(1.0 - left, abs=1e-6)
    assert ledger < 1e-6
    left_fixed, _, _ = _pulse_in_a_bar(kind, "fixed")
    assert left_fixed > 0.99      # a fixed end sends it all back


def test_compliant_base_input_sends_the_free_field_wave_in():
    # Traction 2 rho c v_in through the dashpot of the left end: an S pulse of particle velocity
    # v_in enters the bar with that velocity and the energy flux rho c int v_in^2 dt per area.
    L, nx, H = 20.0, 200, 0.2
    mat = ElasticMaterial(young=E, poisson=NU, density=RHO)
    model = Model.from_mesh(structured_rectangle(nx, 2, L, H), mat, exploded=False)
    model.fix(lambda x, y: np.ones_like(x, bool), x=True, y=False)
    c = mat.s_wave_speed
    V, T = 0.01, 4.0 / c

    def v_in(t):
        return 0.0, (V * np.sin(np.pi * t / T) ** 2 if 0.0 <= t <= T else 0.0)

    sim = Simulation(model, providers=[QuietBoundary(model, "left", input_velocity=v_in),
                                       QuietBoundary(model, "right")], progress=False)
    mid = np.flatnonzero(np.isclose(sim.x0[:, 0], 0.5 * L))
    peak = 0.0
    for k in range(int(np.ceil((0.5 * L / c + T) / sim.dt))):
        sim.step(ledger=k % 50 == 0)
        peak = max(peak, sim.state.v[mid, 1].max())
    row = sim.history[-1]
    flux = RHO * c * V ** 2 * (3 * T / 8) * H        # int_0^T sin^4(pi t / T) dt = 3 T / 8
    assert peak == pytest.approx(V, rel=0.01)        # measured 0.9998 V
    assert row["kinetic"] + row["strain"] == pytest.approx(flux, rel=0.01)
    assert abs(row["balance_error_relative"]) < 1e-6


def test_quiet_boundary_dashpots_and_stable_step():
    mesh = structured_rectangle(4, 2, 4.0, 2.0)
    mat = ElasticMaterial(young=E, poisson=NU, density=RHO)
    model = Model(build_topology(mesh), mat)
    qb = QuietBoundary(model, ["left", "right", "bottom"])
    # tributary lengths: the dashpots of all nodes add up to rho c L over each side
    total = qb.damping.sum(axis=0)
    zp, zs = RHO * mat.p_wave_speed, RHO * mat.s_wave_speed
    assert np.allclose(total, [[zp * 4.0 + zs * 4.0, 0], [0, zs * 4.0 + zp * 4.0]], rtol=1e-12)
    m = model.node_mass()
    c_max = np.linalg.eigvalsh(qb.damping)[:, -1]
    assert qb.stable_dt(m) == pytest.approx(np.min(math.sqrt(2) * m[qb.nodes] / c_max))
    with pytest.raises(ValueError, match="matches no external edge"):
        QuietBoundary(model, lambda x, y: x > 100)


# ----------------------------------------------------------------------------- ledger through shaking
def test_ledger_closes_through_base_shaking_with_quiet_sides():
    topo = build_topology(structured_rectangle(16, 8, 8.0, 4.0))
    model = Model(topo, ElasticMaterial(young=E, poisson=NU, density=RHO))
    model.set_element_damping(0.1)
    model.set_gravity(0.0, -9.81)
    shake_base(model, "bottom", AccelerationHistory.sine_pulse(3.0, 0.04, cycles=2))
    qb = QuietBoundary(model, ["left", "right"])
    cracks = CrackSet(topo, {0: CrackProperties(f_t=1e12, c=1e12, phi=45.0, G_I=1e15, G_II=1e15, p_n=10 * E)})
    sim = Simulation(model, providers=[cracks, qb], progress=False)
    sim.run(t_end=0.15, history_every=20)
    last = sim.history[-1]
    assert last["boundary_work"] > 0 and last["quiet_boundary"] > 0
    assert max(abs(r["balance_error_relative"]) for r in sim.history) < 0.01   # measured ~1e-10


# ----------------------------------------------------------------------------- FDEM against Newmark
def test_block_on_shaken_incline_slips_as_newmark():
    case = load_case("newmark_block")
    r = case.run(size=0.5, t_after=0.2, n_samples=20)
    assert r["newmark_m"] > 0.1
    assert r["slip_m"] == pytest.approx(r["newmark_m"], rel=0.05)   # measured +0.3 %
    assert abs(r["balance_error_relative"]) < 0.01
