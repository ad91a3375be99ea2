"""Element damping (docs/damping.md): the critical viscosity of a constant-strain triangle's
highest mode, what it does to the stable step and the energy ledger, and the block on an
incline with the default damping against the rigid-block answer."""
import numpy as np
import pytest

from conftest import load_case

from fdem.physics.elastic import ElasticMaterial, elasticity_matrix, plane_lame_constants
from fdem.physics.stability import critical_viscosity, critical_viscosity_equilateral, triangle_critical_dt
from fdem.mesh.triangles import smallest_altitude, triangle_shape_gradients
from fdem.mesh.mesh import structured_rectangle
from fdem.solve.model import DEFAULT_ELEMENT_DAMPING, Model
from fdem.mesh.topology import ConformingTopology
from fdem.solve.simulation import Simulation

incline = load_case("block_on_incline")

RHO = 2700.0
EQUILATERAL = np.array([[0.0, 0.0], [2.0 / np.sqrt(3.0), 0.0], [1.0 / np.sqrt(3.0), 1.0]])  # altitude 1 m
RIGHT = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
ONE = np.array([[0, 1, 2]])


def state_matrix(x0, lam, mu, eta):
    """12 x 12 first-order matrix of one free triangle: ``M u'' + C u' + K u = 0`` with lumped
    ``M = rho A / 3``, ``K = A B^T D_e B``, ``C = A B^T D_v B``, ``D_v = eta diag(1, 1, 1/2)``."""
    inv, area = triangle_shape_gradients(x0, ONE)
    g = np.array([-(inv[0, 0] + inv[0, 1]), inv[0, 0], inv[0, 1]])
    B = np.zeros((3, 6))
    for a in range(3):
        B[0, 2 * a], B[1, 2 * a + 1] = g[a]
        B[2, 2 * a], B[2, 2 * a + 1] = g[a, 1], g[a, 0]
    m = RHO * area[0] / 3.0
    K = area[0] * B.T @ elasticity_matrix(lam, mu) @ B / m
    C = area[0] * B.T @ np.diag([eta, eta, eta / 2]) @ B / m
    return np.block([[np.zeros((6, 6)), np.eye(6)], [-K, -C]]), np.sqrt(np.linalg.eigvalsh(K).max())


def highest_mode_critical_fraction(x0, poisson, step=0.002):
    """Fraction of :func:`critical_viscosity` at which the highest mode stops oscillating, found by
    following its eigenvalue from ``i omega_max`` (no damping) until it reaches the real axis."""
    lam, mu = plane_lame_constants(1e9, poisson)
    eta_c = critical_viscosity(x0, ONE, lam, mu, RHO)[0]
    s_now = 1j * state_matrix(x0, lam, mu, 0.0)[1]
    for f in np.arange(step, 3.0, step):
        s = np.linalg.eigvals(state_matrix(x0, lam, mu, f * eta_c)[0])
        s_now = s[np.argmin(np.abs(s - s_now))]
        if abs(s_now.imag) < 1e-3 * abs(s_now):
            return f
    return np.inf


def test_equilateral_critical_viscosity_closed_form():
    # eta_crit = (4/3) h sqrt(rho (lambda + mu)); plane strain, nu = 0.25: 1.193 h sqrt(E rho)
    lam, mu = plane_lame_constants(1e9, 0.25)
    eta = critical_viscosity(EQUILATERAL, ONE, lam, mu, RHO)[0]
    assert eta == pytest.approx(critical_viscosity_equilateral(1.0, lam, mu, RHO), rel=1e-12)
    assert eta == pytest.approx(4 / 3 * np.sqrt(0.8) * np.sqrt(1e9 * RHO), rel=1e-12)
    # it scales with the element size
    assert critical_viscosity(0.1 * EQUILATERAL, ONE, lam, mu, RHO)[0] == pytest.approx(0.1 * eta, rel=1e-12)


def test_fraction_one_critically_damps_the_equilateral_highest_mode():
    # Exact: the uniform dilatation is a mode of both stiffness and damping. Within 1 %:
    # at 0.99 of critical the highest mode still oscillates, at 1.01 it no longer does.
    for poisson in (0.1, 0.25, 0.4):
        assert highest_mode_critical_fraction(EQUILATERAL, poisson, step=0.01) == pytest.approx(1.0, abs=0.011)


def test_fraction_one_nearly_critically_damps_a_right_triangle():
    # Structured-mesh shape: damping couples the modes a little; critical within 10 %.
    assert highest_mode_critical_fraction(RIGHT, 0.25) == pytest.approx(1.0, abs=0.10)


def test_damping_shortens_the_stable_step_as_central_differences_predict():
    # dt = (2 / omega_max)(sqrt(1 + xi^2) - xi) (Belytschko et al. 2014, eq. 6.3.22); at fraction
    # 1 the equilateral's xi of the highest mode is 1: dt shrinks by sqrt(2) - 1.
    lam, mu = plane_lame_constants(1e9, 0.25)
    eta_c = critical_viscosity(EQUILATERAL, ONE, lam, mu, RHO)[0]
    dt0 = triangle_critical_dt(EQUILATERAL, ONE, lam, mu, RHO)[0]
    for f in (0.1, 1.0):
        dt = triangle_critical_dt(EQUILATERAL, ONE, lam, mu, RHO, f * eta_c)[0]
        assert dt / dt0 == pytest.approx(np.sqrt(1 + f * f) - f, rel=1e-9)


def test_model_sets_element_damping_per_triangle_and_the_solver_uses_it():
    mesh = structured_rectangle(4, 2, 2.0, 1.0)
    model = Model(ConformingTopology.from_mesh(mesh), ElasticMaterial(young=1e9, poisson=0.25, density=RHO))
    dt0 = model.triangle_critical_dt().min()
    assert Simulation(model, progress=False).use_viscous is False
    left = model.set_element_damping(where=lambda x, y: x < 1.0)
    assert model.element_damping_fraction()[model.centroids0[:, 0] < 1.0] == pytest.approx(DEFAULT_ELEMENT_DAMPING)
    assert not model.viscosity_array()[model.centroids0[:, 0] > 1.0].any()
    # about (4/3) h sqrt(rho (lambda + mu)) = 1.19 h sqrt(E rho), h the smallest altitude
    h = smallest_altitude(mesh.points, mesh.triangles)[model.centroids0[:, 0] < 1.0]
    ratio = left / DEFAULT_ELEMENT_DAMPING / (h * np.sqrt(1e9 * RHO))
    assert np.all((ratio > 0.9) & (ratio < 1.5))
    sim = Simulation(model, progress=False)
    assert sim.use_viscous
    assert sim.tc[:, 6] == pytest.approx(model.viscosity_array() * np.abs(model.topology.triangle_area0))
    assert model.triangle_critical_dt().min() < dt0


def test_ledger_closes_and_books_the_viscous_work_of_a_ringing_block():
    # A free block released with a straining velocity field rings; element damping turns its
    # kinetic + strain energy into viscous dissipation, and the ledger balances.
    mesh = structured_rectangle(4, 4, 1.0, 1.0)
    model = Model(ConformingTopology.from_mesh(mesh), ElasticMaterial(young=1e9, poisson=0.25, density=RHO))
    model.set_element_damping(0.2)
    x = model.topology.x0
    model.initial_velocity[:] = np.column_stack([x[:, 0] - 0.5, -(x[:, 1] - 0.5)]) * 0.1  # pure shear rate
    sim = Simulation(model, progress=False)
    e0 = 0.5 * (sim.state.mass[:, None] * sim.state.v ** 2).sum()
    sim.run(n_steps=3000, history_every=100)
    last = sim.history[-1]
    assert last["kinetic"] + last["strain"] < 0.05 * e0
    assert last["viscous_dissipation"] == pytest.approx(e0, rel=0.05)
    assert abs(last["balance_error_relative"]) < 1e-6


@pytest.fixture(scope="module")
def slides():
    # theta 30 deg, phi 20 deg, default damping, two mesh sizes (16 and 40 block triangles)
    return {size: incline.run(30.0, 20.0, t_end=1.0, size=size) for size in (0.5, 0.25)}


def test_default_damping_slide_within_two_percent_of_the_rigid_block(slides):
    for r in slides.values():
        assert r["element_damping"] == DEFAULT_ELEMENT_DAMPING
        assert r["slide_m"] == pytest.approx(r["exact_m"], rel=0.02)
        assert r["viscous_dissipation_J_per_m"] > 0.0
        assert abs(r["balance_error_relative"]) < 1e-3


def test_default_damping_error_does_not_grow_with_refinement(slides):
    coarse, fine = (abs(slides[s]["slide_m"] / slides[s]["exact_m"] - 1.0) for s in (0.5, 0.25))
    assert fine <= coarse + 0.002
