"""Constant-strain triangle: the law alone, patch test, rigid rotation, element critical step."""

import numpy as np
import pytest

from fdem.kernels.triangles import (TC_MASS, assemble_triangle_forces, deformation_gradients, svk_piola, triangle_constants, triangle_stress_state, viscous_piola)
from fdem.physics.elastic import (ElasticMaterial, bar_wave_speed, lame_constants, p_wave_speed, plane_lame_constants)
from fdem.physics.stability import combine_stable_dt, stable_dt_altitude, stable_dt_penalty, triangle_critical_dt
from fdem.mesh.triangles import smallest_altitude
from fdem.mesh.mesh import jittered_rectangle
from fdem.mesh.topology import ConformingTopology
from fdem.solve.model import Model
from fdem.mesh.topology import build_topology

E, NU, RHO = 10e9, 0.27, 2600.0


def jittered_mesh(nx=6, ny=5, w=3.0, h=2.0, amount=0.3, seed=1):
    return jittered_rectangle(nx, ny, w, h, amount, seed)


def svk_reference(F, lam, mu, S0=np.zeros((2, 2))):
    Eg = 0.5 * (F.T @ F - np.eye(2))
    S = S0 + lam * np.trace(Eg) * np.eye(2) + 2 * mu * Eg
    W = np.sum(S0 * Eg) + 0.5 * lam * np.trace(Eg) ** 2 + mu * np.sum(Eg * Eg)
    return F @ S, S, Eg, W


def test_svk_law_matches_reference():
    lam, mu = lame_constants(E, NU)
    rng = np.random.default_rng(0)
    for _ in range(20):
        F = np.eye(2) + 0.05 * rng.standard_normal((2, 2))
        S0 = 1e6 * rng.standard_normal((2, 2))
        S0 = S0 + S0.T
        P, _, _, W = svk_reference(F, lam, mu, S0)
        got = svk_piola(F[0, 0], F[0, 1], F[1, 0], F[1, 1], lam, mu, S0[0, 0], S0[1, 1], S0[0, 1])
        np.testing.assert_allclose(np.array(got[:4]).reshape(2, 2), P, rtol=1e-12, atol=1e-12 * np.abs(P).max())
        assert got[4] == pytest.approx(W, rel=1e-12)


def test_viscous_term_vanishes_for_rigid_spin_and_damps_stretching():
    theta = 0.7
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    Wskew = np.array([[0.0, -3.0], [3.0, 0.0]])
    Fd = Wskew @ R  # spin: dF/dt = W F
    q = viscous_piola(*R.ravel(), *Fd.ravel(), 1e6)
    assert np.max(np.abs(q)) < 1e-9
    Fd = np.array([[1.0, 0.0], [0.0, 0.0]])  # stretching along x
    q = viscous_piola(1.0, 0.0, 0.0, 1.0, *Fd.ravel(), 2.0)
    np.testing.assert_allclose(q, [2.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("exploded", [True, False])
@pytest.mark.parametrize("H", [np.array([[1e-3, 4e-4], [-2e-4, -6e-4]]), np.array([[0.05, 0.02], [0.03, -0.04]])])
def test_patch_test_uniform_strain_on_irregular_mesh(exploded, H):
    """x = (I + H) X on an irregular mesh: every element has F = I + H and S = C : E exactly,
    its Cauchy stress is F (C:E) F^T / J, and interior nodes are in equilibrium."""
    mesh = jittered_mesh()
    model = Model.from_mesh(mesh, ElasticMaterial(E, NU, RHO), exploded=exploded)
    topo = model.topology
    tc = model.triangle_constants()
    F_exact = np.eye(2) + H
    x = topo.x0 @ F_exact.T
    v = np.zeros_like(x)
    F = np.empty((topo.n_triangles, 4))
    deformation_gradients(x, topo.triangles, tc, F)
    np.testing.assert_allclose(F, np.broadcast_to(F_exact.ravel(), F.shape), rtol=0, atol=1e-13)

    lam, mu = plane_lame_constants(E, NU)
    _, S, Eg, W = svk_reference(F_exact, lam, mu)
    sigma_exact = F_exact @ S @ F_exact.T / np.linalg.det(F_exact)
    s = np.empty((topo.n_triangles, 6))
    triangle_stress_state(x, v, topo.triangles, tc, s)
    for got, want in ((s[:, 0], sigma_exact[0, 0]), (s[:, 1], sigma_exact[1, 1]), (s[:, 2], sigma_exact[0, 1])):
        assert np.max(np.abs(got - want)) <= 1e-8 * np.abs(sigma_exact).max()
    assert np.max(np.abs(s[:, 5] - W)) <= 1e-8 * W

    # equilibrium: the forces of all corners at an interior mesh node cancel
    f = np.zeros((3 * topo.n_triangles, 2))
    assemble_triangle_forces(x, v, topo.triangles, tc, f)
    per_node = np.zeros((mesh.points.shape[0], 2))
    np.add.at(per_node, topo.mesh_node[topo.triangles.ravel()], f)
    p = mesh.points
    interior = (p[:, 0] > 1e-9) & (p[:, 0] < 3 - 1e-9) & (p[:, 1] > 1e-9) & (p[:, 1] < 2 - 1e-9)
    assert np.max(np.abs(per_node[interior])) <= 1e-10 * np.abs(f).max()
    assert np.abs(per_node.sum(0)).max() <= 1e-10 * np.abs(f).max()


def test_patch_test_small_strain_matches_linear_elasticity():
    """For small strain the Cauchy stress tends to C : eps (difference is second order in eps)."""
    mesh = jittered_mesh(seed=3)
    model = Model.from_mesh(mesh, ElasticMaterial(E, NU, RHO), exploded=True)
    tc = model.triangle_constants()
    lam, mu = lame_constants(E, NU)
    errors = []
    for scale in (1e-4, 1e-5):
        eps = scale * np.array([[1.0, 0.3], [0.3, -0.5]])
        x = model.topology.x0 @ (np.eye(2) + eps).T
        s = np.empty((model.n_triangles, 6))
        triangle_stress_state(x, np.zeros_like(x), model.topology.triangles, tc, s)
        sig = lam * np.trace(eps) * np.eye(2) + 2 * mu * eps
        errors.append(np.max(np.abs(s[:, [0, 1, 2]] - [sig[0, 0], sig[1, 1], sig[0, 1]])) / np.abs(sig).max())
    assert errors[0] < 5e-4 and errors[1] < 5e-5
    assert errors[0] / errors[1] == pytest.approx(10.0, rel=0.05)  # first-order relative error


@pytest.mark.parametrize("degrees", [90.0, 180.0, 270.0, 123.0, 405.0])
def test_rigid_rotation_gives_zero_stress_and_energy(degrees):
    mesh = jittered_mesh(seed=2)
    model = Model.from_mesh(mesh, ElasticMaterial(E, NU, RHO))
    tc = model.triangle_constants()
    th = np.radians(degrees)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    x = (model.topology.x0 - [1.0, 0.5]) @ R.T + [7.0, -3.0]
    s = np.empty((model.n_triangles, 6))
    triangle_stress_state(x, np.zeros_like(x), model.topology.triangles, tc, s)
    assert np.max(np.abs(s[:, :3])) / E < 1e-10
    assert np.max(np.abs(s[:, 5])) / E < 1e-20
    f = np.zeros_like(x)
    energy = assemble_triangle_forces(x, np.zeros_like(x), model.topology.triangles, tc, f)
    assert abs(energy) / (E * 6.0) < 1e-20
    assert np.max(np.abs(f)) / (E * 0.5) < 1e-10  # E times a cell size


def test_prestressed_triangle_rotates_its_stress():
    """With an initial stress S0, a rigid rotation R gives the Cauchy stress R S0 R^T (objectivity)."""
    model = Model.from_mesh(jittered_mesh(seed=4), ElasticMaterial(E, NU, RHO))
    S0 = np.array([[-2e6, 5e5], [5e5, -1e6]])
    model.set_initial_stress([S0[0, 0], S0[1, 1], S0[0, 1]])
    tc = model.triangle_constants()
    th = np.radians(123.0)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    x = model.topology.x0 @ R.T
    s = np.empty((model.n_triangles, 6))
    triangle_stress_state(x, np.zeros_like(x), model.topology.triangles, tc, s)
    want = R @ S0 @ R.T
    np.testing.assert_allclose(s[:, :3], np.broadcast_to([want[0, 0], want[1, 1], want[0, 1]], (len(s), 3)),
                               rtol=0, atol=1e-9 * 2e6)


def _element_omega_max(X, lam, mu, rho):
    Dm = np.array([X[1] - X[0], X[2] - X[0]]).T
    B = np.linalg.inv(Dm)
    A = 0.5 * np.linalg.det(Dm)
    g = np.array([-(B[0] + B[1]), B[0], B[1]])
    Bv = np.zeros((3, 6))
    for a in range(3):
        Bv[0, 2 * a], Bv[1, 2 * a + 1] = g[a]
        Bv[2, 2 * a], Bv[2, 2 * a + 1] = g[a, 1], g[a, 0]
    C = np.array([[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]])
    K = A * Bv.T @ C @ Bv
    return np.sqrt(np.linalg.eigvalsh(K / (rho * A / 3)).max())


def test_element_critical_step_is_exact_and_altitude_rule_is_not_a_bound():
    lam, mu = lame_constants(E, NU)
    rng = np.random.default_rng(5)
    tris = []
    while len(tris) < 50:
        X = rng.random((3, 2))
        a = 0.5 * ((X[1, 0] - X[0, 0]) * (X[2, 1] - X[0, 1]) - (X[1, 1] - X[0, 1]) * (X[2, 0] - X[0, 0]))
        if abs(a) > 0.02:
            tris.append(X if a > 0 else X[[0, 2, 1]])
    x0 = np.concatenate(tris)
    triangles = np.arange(len(x0)).reshape(-1, 3)
    dt = triangle_critical_dt(x0, triangles, lam, mu, RHO)
    want = np.array([2.0 / _element_omega_max(X, lam, mu, RHO) for X in tris])
    np.testing.assert_allclose(dt, want, rtol=1e-10)
    # h_min / c_p overestimates the critical step of a lumped-mass triangle by up to ~1.5x
    ratio = dt / stable_dt_altitude(smallest_altitude(x0, triangles), p_wave_speed(E, NU, RHO))
    assert ratio.min() > 0.6 and ratio.max() < 1.0
    # viscosity lowers it
    dt_visc = triangle_critical_dt(x0, triangles, lam, mu, RHO, viscosity=1e4)
    assert np.all(dt_visc < dt)


def test_elastic_formulas():
    lam, mu = lame_constants(E, NU)
    assert mu == pytest.approx(E / (2 * (1 + NU)))
    assert lam + 2 * mu == pytest.approx(E * (1 - NU) / ((1 + NU) * (1 - 2 * NU)))
    lam_ps, _ = plane_lame_constants(E, NU, "stress")
    assert lam_ps + 2 * mu == pytest.approx(E / (1 - NU**2))
    assert p_wave_speed(E, NU, RHO) == pytest.approx(np.sqrt(E * (1 - NU) / (RHO * (1 + NU) * (1 - 2 * NU))))
    assert bar_wave_speed(E, RHO) == pytest.approx(np.sqrt(E / RHO))
    assert stable_dt_penalty(0.1, 100 * E, RHO) == pytest.approx(0.1 * np.sqrt(RHO / (100 * E)))
    assert combine_stable_dt(3.0, 4.0) == pytest.approx(2.4)
    assert combine_stable_dt(2.0, np.inf) == 2.0
    with pytest.raises(ValueError, match="Poisson"):
        ElasticMaterial(E, 0.5, RHO)
    with pytest.raises(ValueError, match="plane"):
        ElasticMaterial(E, NU, RHO, plane="axisymmetric")


def test_lumped_masses_sum_to_body_mass():
    mesh = jittered_mesh()
    for exploded in (True, False):
        model = Model.from_mesh(mesh, ElasticMaterial(E, NU, RHO), exploded=exploded)
        assert model.node_mass().sum() == pytest.approx(RHO * 3.0 * 2.0, rel=1e-12)
    tc = triangle_constants(build_topology(mesh).x0, build_topology(mesh).triangles, 1.0, 1.0, 0.0, RHO)
    assert 3 * tc[:, TC_MASS].sum() == pytest.approx(RHO * 6.0, rel=1e-12)
    conforming = ConformingTopology.from_mesh(mesh)
    assert conforming.n_nodes == mesh.points.shape[0]
