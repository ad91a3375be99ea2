"""Contact: broad phase against brute force, the distributed-potential pair law, impact, friction.

Every test asserts a physical or algorithmic fact with the tolerance it should meet; the small
integrators below (leapfrog over a conforming St Venant-Kirchhoff mesh, or a rigid translating
block) stand in for the solver.
"""
from __future__ import annotations

import numba
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from fdem.physics.contact import ContactSet, brute_force_candidate_pairs, candidate_pairs, pair_energy_force
from fdem.kernels import contact_pairs as fcontact_kernels
from fdem.mesh.mesh import Mesh, structured_rectangle
from fdem.mesh.topology import build_topology

RNG = np.random.default_rng(20240605)


# ----------------------------------------------------------------------------- helpers
def _ccw(p):
    a = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[1, 1] - p[0, 1]) * (p[2, 0] - p[0, 0])
    return p if a > 0 else p[::-1].copy()


def _random_triangle(rng, centre, size, min_quality=0.15):
    while True:
        p = centre + size * rng.normal(size=(3, 2))
        a = 0.5 * abs((p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[1, 1] - p[0, 1]) * (p[2, 0] - p[0, 0]))
        if a > min_quality * size * size:
            return _ccw(p)


def _join(*meshes):
    """One Mesh of several bodies (body id = position in the argument list)."""
    pts, tris, body, off = [], [], [], 0
    for b, m in enumerate(meshes):
        pts.append(m.points)
        tris.append(m.triangles + off)
        body.append(np.full(m.n_triangles, b, np.int32))
        off += len(m.points)
    return Mesh(points=np.vstack(pts), triangles=np.vstack(tris), triangle_body=np.concatenate(body))


def _energy(xc, xt, p):
    return pair_energy_force(xc, xt, p)[0]


def _svk_forces(x, X_tri_inv, area0, tris, lam, mu):
    """Internal forces (on nodes) and strain energy of St Venant-Kirchhoff CST triangles."""
    p0, p1, p2 = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    Dx = np.stack([p1 - p0, p2 - p0], axis=2)            # (n, 2, 2) columns x1-x0, x2-x0
    F = Dx @ X_tri_inv
    E = 0.5 * (np.swapaxes(F, 1, 2) @ F - np.eye(2))
    trE = E[:, 0, 0] + E[:, 1, 1]
    S = lam * trE[:, None, None] * np.eye(2) + 2.0 * mu * E
    W = (0.5 * lam * trE**2 + mu * np.einsum("nij,nij->n", E, E)) * area0
    P = F @ S
    # f_internal on nodes 1, 2 = A0 P X^-T; node 0 = -(sum)
    G = area0[:, None, None] * (P @ np.swapaxes(X_tri_inv, 1, 2))   # (n, 2, 2): columns for nodes 1, 2
    f = np.zeros_like(x)
    np.add.at(f, tris[:, 1], -G[:, :, 0])
    np.add.at(f, tris[:, 2], -G[:, :, 1])
    np.add.at(f, tris[:, 0], G[:, :, 0] + G[:, :, 1])
    return f, W.sum()


# ----------------------------------------------------------------------------- broad phase
@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 40), spread=st.floats(0.5, 6.0), cell=st.floats(0.03, 8.0),
       skin=st.floats(0.0, 0.6), seed=st.integers(0, 2**31 - 1), bond_frac=st.floats(0.0, 0.5))
def test_grid_search_equals_brute_force(n, spread, cell, skin, seed, bond_frac):
    rng = np.random.default_rng(seed)
    x = np.vstack([_random_triangle(rng, rng.uniform(0, spread, 2), rng.uniform(0.05, 0.8))
                   for _ in range(n)])
    n_tri = n + 2
    x = np.vstack([x, np.zeros((6, 2))])         # two trailing non-contactor triangles
    active = np.sort(rng.choice(n, size=max(2, int(rng.integers(2, n + 1))), replace=False))
    bond = np.full((n_tri, 3), -1, np.int64)
    for _ in range(int(bond_frac * n)):
        i, j = rng.choice(n, 2, replace=False)
        si, sj = np.flatnonzero(bond[i] < 0), np.flatnonzero(bond[j] < 0)
        if si.size and sj.size and j not in bond[i]:
            bond[i, si[0]], bond[j, sj[0]] = j, i
    grid = candidate_pairs(x, active, bond, skin, cell)
    brute = brute_force_candidate_pairs(x, active, bond, skin)
    np.testing.assert_array_equal(grid, brute)
    assert np.all(grid[:, 0] < grid[:, 1])
    assert not any(j in bond[i] for i, j in grid)


def test_grid_search_linear_scaling_and_pairs_of_fragmented_block():
    """Fully fragmented block: each triangle pairs with its neighbours only (O(n) pairs)."""
    topo = build_topology(structured_rectangle(30, 30, 3.0, 3.0))
    cs = ContactSet(topo, penalty=1.0, skin=0.01)
    cs.activate_cracks(np.arange(topo.n_cracks))
    assert cs.active.size == topo.n_triangles
    pairs = candidate_pairs(topo.x0, cs.active, cs._bond, cs.skin)
    brute = brute_force_candidate_pairs(topo.x0, cs.active, cs._bond, cs.skin)
    np.testing.assert_array_equal(pairs, brute)
    assert len(pairs) < 12 * topo.n_triangles


# ----------------------------------------------------------------------------- pair law
def test_pair_zero_when_apart_or_touching():
    a = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    b = np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])       # shares the hypotenuse
    for shift in (0.0, 1e-9, 0.3, 5.0):
        e, fc, ft, area = pair_energy_force(a, b + shift, 1e9)
        assert e == 0.0 and area == 0.0
        assert not fc.any() and not ft.any()
    for _ in range(200):
        xc = _random_triangle(RNG, np.zeros(2), 1.0)
        xt = _random_triangle(RNG, np.zeros(2), 1.0)
        # separate along a random direction by more than both sizes
        d = RNG.normal(size=2)
        xt = xt + 20.0 * d / np.linalg.norm(d)
        e, fc, ft, area = pair_energy_force(xc, xt, 1.0)
        assert e == 0.0 and not fc.any() and not ft.any()


def _penetrating_pairs(n):
    out = []
    while len(out) < n:
        xc = _random_triangle(RNG, np.zeros(2), 1.0)
        xt = _random_triangle(RNG, RNG.normal(size=2) * 0.8, RNG.uniform(0.3, 1.5))
        if pair_energy_force(xc, xt, 1.0)[3] > 1e-3:
            out.append((xc, xt))
    return out


def test_pair_forces_equal_opposite_and_torque_free():
    for xc, xt in _penetrating_pairs(100):
        e, fc, ft, _ = pair_energy_force(xc, xt, 3e10)
        F = np.vstack([fc, ft])
        X = np.vstack([xc, xt])
        scale = np.abs(F).max()
        assert e > 0.0 and scale > 0.0
        assert np.abs(F.sum(axis=0)).max() <= 1e-13 * scale * 12
        torque = np.sum(X[:, 0] * F[:, 1] - X[:, 1] * F[:, 0])
        assert abs(torque) <= 1e-13 * scale * np.abs(X).max() * 12
        # the pair pushes apart: relative resultant points from t to c on average
        assert np.dot(fc.sum(axis=0), xc.mean(axis=0) - xt.mean(axis=0)) > -1e-12 * scale


def test_pair_force_is_minus_energy_gradient():
    """Central finite differences of E over all 12 corner coordinates."""
    h = 1e-6
    for xc, xt in _penetrating_pairs(40):
        _, fc, ft, _ = pair_energy_force(xc, xt, 1.0)
        F = np.vstack([fc, ft])
        X = np.vstack([xc, xt])
        G = np.zeros_like(X)
        for n in range(6):
            for d in range(2):
                Xp, Xm = X.copy(), X.copy()
                Xp[n, d] += h
                Xm[n, d] -= h
                G[n, d] = (_energy(Xp[:3], Xp[3:], 1.0) - _energy(Xm[:3], Xm[3:], 1.0)) / (2 * h)
        np.testing.assert_allclose(F, -G, atol=1e-7 * np.abs(F).max())


def test_pair_energy_matches_quadrature_and_munjiza_resultant():
    """E = p int_D (phi_c + phi_t) dA and f_c = p int_D grad(phi_c - phi_t) dA, by brute quadrature."""
    xc = np.array([[0.0, 0.0], [1.0, 0.0], [0.2, 0.9]])
    xt = np.array([[0.5, 0.3], [1.4, 0.6], [0.3, 1.2]])
    e, fc, _, area = pair_energy_force(xc, xt, 1.0)

    def phi(P, X):
        x0, x1, x2 = P
        a2 = (x1[0] - x0[0]) * (x2[1] - x0[1]) - (x1[1] - x0[1]) * (x2[0] - x0[0])

        def cr(a, b):
            return (a[0] - X[..., 0]) * (b[1] - X[..., 1]) - (a[1] - X[..., 1]) * (b[0] - X[..., 0])
        m = np.minimum(np.minimum(cr(x1, x2), cr(x2, x0)), cr(x0, x1)) / a2
        return np.where(m > 0, 3 * m, 0.0), m > 0

    g = np.linspace(-0.2, 1.6, 2401)
    dx = g[1] - g[0]
    X = np.stack(np.meshgrid(g, g), -1)
    pc, ic = phi(xc, X)
    pt, it = phi(xt, X)
    D = ic & it
    assert area == pytest.approx(D.sum() * dx * dx, rel=2e-3)
    assert e == pytest.approx(((pc + pt) * D).sum() * dx * dx, rel=2e-3)
    gy, gx = np.gradient(pc - pt, dx)
    res = np.array([(gx * D).sum(), (gy * D).sum()]) * dx * dx
    np.testing.assert_allclose(fc.sum(axis=0), res, rtol=5e-3)


def test_flat_penetration_matches_closed_form():
    """Edge pushed a depth d into a facing edge: E = 3 p L d^2 (1/h_c + 1/h_t) / 2 + O(d^3)."""
    L, hc, ht, p = 1.0, 0.8, 0.5, 2.0
    xc = np.array([[0.0, 0.0], [L, 0.0], [0.4, hc]])          # c above y = 0
    for d in (1e-4, 1e-3):
        xt = np.array([[L, d], [0.0, d], [0.6, d - ht]])      # t below y = d
        e, fc, ft, area = pair_energy_force(xc, xt, p)
        assert area == pytest.approx(L * d, rel=5 * d)
        assert e == pytest.approx(1.5 * p * L * d**2 * (1 / hc + 1 / ht), rel=5 * d)
        assert fc.sum(axis=0)[1] == pytest.approx(3 * p * L * d * (1 / hc + 1 / ht), rel=5 * d)


# ----------------------------------------------------------------------------- ContactSet
def test_bad_input_is_rejected_with_clear_messages():
    topo = build_topology(_join(structured_rectangle(2, 2, 1.0, 1.0),
                                structured_rectangle(2, 2, 1.0, 1.0, origin=(1.0, 0.0))))
    for p in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="penalty"):
            ContactSet(topo, penalty=p)
    for phi in (-1.0, 90.0, 120.0, np.nan):
        with pytest.raises(ValueError, match=r"friction angle must lie in \[0, 90\)"):
            ContactSet(topo, penalty=1e9, friction_angle=phi)
    phis = np.full(topo.n_triangles, 30.0)
    phis[5] = 95.0
    with pytest.raises(ValueError, match="triangle 5 has 95"):
        ContactSet(topo, penalty=1e9, friction_angle=phis)
    with pytest.raises(ValueError, match="mass"):
        ContactSet(topo, penalty=1e9, damping_ratio=0.1)
    # touching bodies are fine; overlapping ones are named
    ContactSet(topo, penalty=1e9, friction_angle=30.0)
    over = build_topology(_join(structured_rectangle(2, 2, 1.0, 1.0),
                                structured_rectangle(2, 2, 1.0, 1.0, origin=(0.8, 0.3))))
    with pytest.raises(ValueError, match=r"bodies 0 and 1 overlap in the reference state: triangle \d+ "
                                         r"\(body 0, centroid"):
        ContactSet(over, penalty=1e9)


def test_intact_cracks_exclude_and_broken_cracks_activate_pairs():
    # body 0: 2x1 cells (4 triangles, cracks between); body 1 far away so contact is live
    topo = build_topology(_join(structured_rectangle(2, 1, 2.0, 1.0),
                                structured_rectangle(1, 1, 1.0, 1.0, origin=(10.0, 0.0))))
    cs = ContactSet(topo, penalty=1.0, skin=0.05)
    x = topo.x0.copy()
    cs.search(x)
    ct = topo.crack_triangles
    bonded = {tuple(sorted(t)) for t in ct.tolist()}
    assert not bonded & {tuple(p) for p in cs.pairs.tolist()}
    # push triangle A of crack 0 into B: no force while the crack element is intact
    a, b = ct[0]
    shift = 0.05 * (x[3 * b:3 * b + 3].mean(0) - x[3 * a:3 * a + 3].mean(0))
    x[3 * a:3 * a + 3] += shift
    f = np.zeros_like(x)
    cs.add_forces(x, np.zeros_like(x), f, 1e-3, 0)
    assert not f.any()
    cs.activate_cracks([0])
    f[:] = 0.0
    cs.add_forces(x, np.zeros_like(x), f, 1e-3, 1)
    assert (min(a, b), max(a, b)) in {tuple(p) for p in cs.pairs.tolist()}
    fa = f[3 * a:3 * a + 3].sum(0)
    fb = f[3 * b:3 * b + 3].sum(0)
    assert np.dot(fa, shift) < 0.0                       # A is pushed back out of B
    np.testing.assert_allclose(fa + fb, 0.0, atol=1e-14 * np.abs(fa).max())
    assert cs.energy_terms()["contact_elastic"] > 0.0


def test_broken_joint_friction_belongs_to_the_interface_and_is_reduced():
    """A pair across a broken crack element uses that element's friction; activating another
    element never raises it; the reduction factor F divides every friction, whenever it broke."""
    topo = build_topology(_join(structured_rectangle(2, 1, 2.0, 1.0),
                                structured_rectangle(1, 1, 1.0, 1.0, origin=(10.0, 0.0))))
    cs = ContactSet(topo, penalty=1.0, friction_angle=40.0)
    a, b = topo.crack_triangles[1]
    with pytest.raises(ValueError, match="crack 0 has 95"):
        cs.activate_cracks([1], friction_angle=[95.0])
    cs.activate_cracks([1], friction_angle=[25.0])
    cs.search(topo.x0)
    pair_index = lambda: {tuple(p): k for k, p in enumerate(cs.pairs.tolist())}
    q = pair_index()[(min(a, b), max(a, b))]
    t25, t35, t40 = (np.tan(np.radians(d)) for d in (25.0, 35.0, 40.0))
    assert cs._mu_base_pair[q] == pytest.approx(t25)  # the broken element's own, whatever faces touch
    # a later breakage with higher friction does not overwrite it
    cs.activate_cracks([0], friction_angle=[35.0])
    cs.search(topo.x0)
    idx = pair_index()
    assert cs._mu_base_pair[idx[(min(a, b), max(a, b))]] == pytest.approx(t25)
    c, d = topo.crack_triangles[0]
    assert cs._mu_base_pair[idx[(min(c, d), max(c, d))]] == pytest.approx(t35)
    # other pairs take it from the faces in touch: only the broken elements' faces were lowered
    assert (cs._mu_base_pair[[k for p, k in idx.items() if p not in ((min(a, b), max(a, b)), (min(c, d), max(c, d)))]]
            == fcontact_kernels.FROM_FACES).all()
    cn = topo.crack_nodes[1]
    assert cs.face_friction[a, cn[0] % 3] == pytest.approx(t25) and cs.face_friction[b, cn[2] % 3] == pytest.approx(t25)
    lowered = np.argwhere(cs.face_friction < t40 - 1e-12)
    assert len(lowered) == 4 and cs.face_mu == pytest.approx(t40)  # two faces each of the two broken elements
    # one face set: the others keep theirs; a broken face has the lower of its element's and this
    cs.set_friction(friction_angle=[30.0, 10.0], triangles=[a, a], faces=[cn[0] % 3, (cn[0] + 1) % 3])
    assert cs.face_friction[a, cn[0] % 3] == pytest.approx(t25)
    assert cs.face_friction[a, (cn[0] + 1) % 3] == pytest.approx(np.tan(np.radians(10.0)))
    assert cs.face_friction[a, (cn[0] + 2) % 3] == pytest.approx(t40)
    with pytest.raises(ValueError, match="faces must give one face"):
        cs.set_friction(friction_angle=10.0, triangles=[a], faces=[3])
    with pytest.raises(ValueError, match="triangles must be ids"):
        cs.set_friction(friction_angle=10.0, triangles=[topo.n_triangles])
    with pytest.raises(ValueError, match="mu"):
        cs.activate_cracks([0], mu=-0.1)
    with pytest.raises(ValueError, match="positive"):
        cs.interfaces.set_reduction(0.0)


def test_single_intact_body_is_dormant():
    topo = build_topology(structured_rectangle(3, 3, 1.0, 1.0))
    cs = ContactSet(topo, penalty=1.0)
    assert cs.dormant
    f = np.zeros_like(topo.x0)
    cs.add_forces(topo.x0, np.zeros_like(topo.x0), f, 1e-3, 0)
    assert cs.n_searches == 0 and not f.any()
    cs.activate_cracks([0])
    assert not cs.dormant


def test_research_only_after_half_skin_and_pairs_stay_complete():
    topo = build_topology(_join(structured_rectangle(3, 3, 1.0, 1.0),
                                structured_rectangle(3, 3, 1.0, 1.0, origin=(1.5, 0.1))))
    cs = ContactSet(topo, penalty=1.0, skin=0.1)
    x = topo.x0.copy()
    body1 = np.repeat(topo.triangle_body == 1, 3)
    f = np.zeros_like(x)
    step_len = 0.01
    for step in range(60):                           # body 1 moves 0.6 m to the left
        cs.add_forces(x, np.zeros_like(x), f, 1e-3, step)
        # every pair whose boxes (grown by the skin) touch now is in the list
        now = brute_force_candidate_pairs(x, cs.active, cs._bond, 0.0)
        listed = {tuple(p) for p in cs.pairs.tolist()}
        assert {tuple(p) for p in now.tolist()} <= listed
        x[body1, 0] -= step_len
    # searches happen every skin/2 = 5 steps of motion, not every step
    assert 60 / 6 <= cs.n_searches <= 60 / 5 + 2


def test_forces_independent_of_thread_count():
    """Pairs are stored and gathered per triangle in a fixed order: same bits on any thread count
    (the mesh is large enough for the parallel kernels)."""
    topo = build_topology(structured_rectangle(40, 40, 4.0, 4.0))
    x = topo.x0 + 0.002 * RNG.normal(size=topo.x0.shape)
    results = []
    saved = numba.get_num_threads()
    try:
        for threads in (1, numba.config.NUMBA_NUM_THREADS):
            numba.set_num_threads(threads)
            cs = ContactSet(topo, penalty=1.0, friction_angle=30.0, skin=0.02, check_overlap=False)
            cs.activate_cracks(np.arange(topo.n_cracks))
            f = np.zeros_like(x)
            cs.add_forces(x, np.ones_like(x), f, 1e-3, 0)
            assert len(cs.pairs) >= fcontact_kernels.PARALLEL_MIN_PAIRS
            results.append((f, cs.energy_terms()))
    finally:
        numba.set_num_threads(saved)
    assert np.abs(results[0][0]).max() > 0
    np.testing.assert_array_equal(results[0][0], results[1][0])
    for k in results[0][1]:
        assert results[0][1][k] == pytest.approx(results[1][1][k], rel=0.0, abs=0.0)


def test_stable_dt_bounds_the_contact_frequency():
    """stable_dt(mass) <= 2 / omega_max of the linearised pair (FD Hessian of the pair forces),
    for face-to-face and random deep overlaps, and not more than 10x below it."""
    rho, p = 2500.0, 1e10
    cases = [(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
              np.array([[1.0, 0.01], [0.0, 0.01], [1.0, -0.99]]))]
    cases += _penetrating_pairs(8)
    worst = np.inf
    for xc, xt in cases:
        mesh = Mesh(points=np.vstack([xc, xt]), triangles=np.array([[0, 1, 2], [3, 4, 5]]),
                    triangle_body=np.array([0, 1], np.int32))
        topo = build_topology(mesh)
        area = np.abs(topo.triangle_area0)
        mass = np.repeat(rho * area / 3.0, 3)
        cs = ContactSet(topo, penalty=p, friction_angle=0.0, check_overlap=False)
        X = np.vstack([xc, xt])

        def force(Xv):
            _, fc, ft, _ = pair_energy_force(Xv[:3], Xv[3:], p)
            return np.vstack([fc, ft]).ravel()

        h = 1e-7
        K = np.zeros((12, 12))
        for a in range(12):
            Xp, Xm = X.ravel().copy(), X.ravel().copy()
            Xp[a] += h
            Xm[a] -= h
            K[:, a] = -(force(Xp.reshape(6, 2)) - force(Xm.reshape(6, 2))) / (2 * h)
        K = 0.5 * (K + K.T)
        minv = 1.0 / np.sqrt(np.repeat(mass, 2))
        omega = np.sqrt(max(np.linalg.eigvalsh(minv[:, None] * K * minv[None, :]).max(), 0.0))
        dt_exact = 2.0 / omega
        dt = cs.stable_dt(mass)
        assert dt <= dt_exact
        worst = min(worst, dt_exact / dt)
    assert worst < 10.0


# ----------------------------------------------------------------------------- two-body impact
def _impact_run(alpha, damping_ratio=0.0, dt_fraction=0.2, t_end=4.0):
    """Two 2x2-cell elastic blocks (St Venant-Kirchhoff, conforming, lumped masses) thrown at each
    other off-centre, integrated by leapfrog (velocity Verlet). Returns a dict of histories."""
    E_mod, nu, rho = 1.0, 0.25, 1.0
    lam = E_mod * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E_mod / (2 * (1 + nu))
    mesh = _join(structured_rectangle(2, 2, 1.0, 1.0),
                 structured_rectangle(2, 2, 1.0, 1.0, origin=(1.05, 0.3)))
    topo = build_topology(mesh)
    tris = mesh.triangles
    X = mesh.points
    Dx0 = np.stack([X[tris[:, 1]] - X[tris[:, 0]], X[tris[:, 2]] - X[tris[:, 0]]], axis=2)
    Xinv = np.linalg.inv(Dx0)
    area0 = 0.5 * np.abs(np.linalg.det(Dx0))
    m_node = np.zeros(len(X))
    np.add.at(m_node, tris.ravel(), np.repeat(rho * area0 / 3.0, 3))
    m_exp = np.repeat(rho * area0 / 3.0, 3)

    cs = ContactSet(topo, penalty=alpha * E_mod, friction_angle=0.0, damping_ratio=damping_ratio, mass=m_exp)
    c_p = np.sqrt((lam + 2 * mu) / rho)
    dt_el = 0.5 * np.sqrt(2 * area0.min()) / c_p
    dt = dt_fraction * min(cs.stable_dt(m_exp), dt_el)

    x = X.copy()
    v = np.zeros_like(x)
    b0 = np.unique(mesh.triangles[mesh.triangle_body == 0])
    b1 = np.unique(mesh.triangles[mesh.triangle_body == 1])
    v[b0] = [0.02, 0.0]
    v[b1] = [-0.02, 0.0]
    idx = topo.mesh_node

    def forces(x, v_half, step):
        f_int, W = _svk_forces(x, Xinv, area0, tris, lam, mu)
        fe = np.zeros((topo.n_nodes, 2))
        cs.add_forces(x[idx], v_half[idx], fe, dt, step)
        np.add.at(f_int, idx, fe)
        return f_int, W + cs.energy_terms()["contact_elastic"]

    P0 = (m_node[:, None] * v).sum(0)
    f, U = forces(x, v, 0)
    E0 = 0.5 * np.sum(m_node[:, None] * v**2) + U
    v_half = v + 0.5 * dt * f / m_node[:, None]
    max_err, max_contact = 0.0, 0.0
    for step in range(1, int(t_end / dt)):
        x = x + dt * v_half
        f, U = forces(x, v_half, step)
        v_full = v_half + 0.5 * dt * f / m_node[:, None]
        v_half = v_full + 0.5 * dt * f / m_node[:, None]
        en = cs.energy_terms()
        Etot = 0.5 * np.sum(m_node[:, None] * v_full**2) + U + en["contact_damping"] + en["friction"]
        max_err = max(max_err, abs(Etot - E0))
        max_contact = max(max_contact, en["contact_elastic"])
    return dict(E0=E0, max_err=max_err, max_contact=max_contact, P0=P0,
                P=(m_node[:, None] * v_full).sum(0), p_scale=np.abs(m_node[:, None] * v).sum(),
                v_rel=v_full[b0, 0].mean() - v_full[b1, 0].mean(), ledger=cs.energy_terms(),
                ke=0.5 * np.sum(m_node[:, None] * v_full**2))


@pytest.mark.parametrize("alpha", [10.0, 100.0, 1000.0])
def test_frictionless_two_body_impact_conserves_momentum_and_energy(alpha):
    """Penalty 10 E to 1000 E, dt = 0.2 x the stable step: momentum to 1e-10, energy to 1 %."""
    r = _impact_run(alpha)
    assert r["max_contact"] > 0.05 * r["E0"]                 # the bodies did collide
    assert np.abs(r["P"] - r["P0"]).max() <= 1e-10 * r["p_scale"]
    assert r["max_err"] <= 0.01 * r["E0"]
    assert r["v_rel"] < 0.0                                   # they bounced apart
    assert r["ledger"]["friction"] == 0.0 and r["ledger"]["contact_damping"] == 0.0


def test_contact_damping_dissipates_and_balances_the_ledger():
    """Normal damping: momentum still exact, the rebound is slower, and the work it dissipates
    closes the energy balance (kinetic + strain + contact + dissipated = initial, 1 %)."""
    free = _impact_run(100.0)
    damped = _impact_run(100.0, damping_ratio=0.5)
    assert np.abs(damped["P"] - damped["P0"]).max() <= 1e-10 * damped["p_scale"]
    assert damped["ledger"]["contact_damping"] > 0.05 * damped["E0"]
    assert damped["max_err"] <= 0.01 * damped["E0"]
    assert 0.0 > damped["v_rel"] > free["v_rel"]


# ----------------------------------------------------------------------------- friction
def _incline_run(phi_deg, theta_deg, t_end=1.0, damping_ratio=0.5, research_at=None, t_settle=0.05):
    """Rigid translating block (1 x 0.5 m, 2x1 cells) on a fixed base, gravity tilted by theta.

    The block first settles for ``t_settle`` under the normal component of gravity (the contact
    damping takes out the landing bounce), then the tangential component is switched on and the
    block is released at rest. Returns (slip along the plane after ``t_end`` [m], ContactSet,
    (potential energy lost, kinetic energy, ledger increments) over the release phase).
    """
    rho, g, p = 2000.0, 9.81, 1e8
    base = structured_rectangle(20, 2, 10.0, 1.0, origin=(0.0, -1.0))
    block = structured_rectangle(2, 1, 1.0, 0.5, origin=(1.0, 0.0))
    topo = build_topology(_join(base, block))
    area = np.abs(topo.triangle_area0)
    mass = np.repeat(rho * area / 3.0, 3)
    on_block = np.repeat(topo.triangle_body == 1, 3)
    M = mass[on_block].sum()
    cs = ContactSet(topo, penalty=p, friction_angle=phi_deg, damping_ratio=damping_ratio, mass=mass)
    th = np.radians(theta_deg)
    dt = 0.5 * cs.stable_dt(mass)
    n_settle = int(round(t_settle / dt))
    n = int(round(t_end / dt))
    dt = t_end / n
    x = topo.x0.copy()
    V = np.zeros(2)
    f = np.zeros_like(x)
    springs_checked = False
    for step in range(n_settle + n):
        if step < n_settle:
            grav = g * np.array([0.0, -np.cos(th)])
        elif step == n_settle:
            grav = g * np.array([np.sin(th), -np.cos(th)])
            V[:] = 0.0
            x_release = x[on_block].mean(0)
            ledger0 = cs.energy_terms()
        f[:] = 0.0
        vel = np.zeros_like(x)
        vel[on_block] = V
        cs.add_forces(x, vel, f, dt, step)
        V = V + dt * (f[on_block].sum(0) / M + grav)
        x[on_block] += dt * V
        if research_at is not None and step == n_settle + research_at:
            before = dict(zip(cs._keys.tolist(), map(tuple, cs._history.tolist())))
            cs.search(x)
            after = dict(zip(cs._keys.tolist(), map(tuple, cs._history.tolist())))
            carried = [k for k in before if any(before[k]) and k in after]
            assert carried and all(before[k] == after[k] for k in carried)
            springs_checked = True
    disp = x[on_block].mean(0) - x_release
    pe_lost = M * np.dot(grav, disp)
    ke = 0.5 * M * V @ V
    ledger = {k: v - ledger0[k] for k, v in cs.energy_terms().items()}
    assert research_at is None or springs_checked
    return disp[0], cs, (pe_lost, ke, ledger)


def test_block_slides_at_coulomb_rate_and_dissipates_friction_work():
    phi, theta, g = 20.0, 30.0, 9.81
    s, cs, (pe_lost, ke, en) = _incline_run(phi, theta)
    th, mu = np.radians(theta), np.tan(np.radians(phi))
    exact = 0.5 * g * (np.sin(th) - mu * np.cos(th))
    assert s == pytest.approx(exact, rel=0.02)
    assert en["friction"] > 0.0
    # energy ledger: potential energy lost = kinetic + friction + damping + stored contact
    assert pe_lost == pytest.approx(ke + en["friction"] + en["contact_damping"] + en["contact_elastic"],
                                    rel=0.02)


def test_block_sticks_below_friction_angle_across_researches():
    phi, theta, g = 40.0, 20.0, 9.81
    s, cs, _ = _incline_run(phi, theta, research_at=1000)
    free = 0.5 * g * np.sin(np.radians(theta))
    assert abs(s) <= 0.01 * free
    assert cs.n_searches >= 2


def test_frictionless_block_slides_freely_with_no_friction_work():
    theta, g = 10.0, 9.81
    s, cs, _ = _incline_run(0.0, theta)
    assert s == pytest.approx(0.5 * g * np.sin(np.radians(theta)), rel=0.02)
    assert cs.energy_terms()["friction"] == 0.0
    assert not cs._history[:, :2].any()              # no tangential history either
