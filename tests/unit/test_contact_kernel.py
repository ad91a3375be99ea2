"""The pair law of the contact kernel evaluated from the overlap's edges (``pair_normal_edges``)
against its evaluation by clipping the overlap polygon (``pair_normal``, the pair loop's) on random
triangle pairs and on the degenerate pairs of a compressed structured block."""
from __future__ import annotations

import numpy as np

from fdem.kernels import contact_pairs as kc

import contact_oracle  # tests/unit/contact_oracle.py, next to this file
from fdem.mesh.mesh import structured_rectangle
from fdem.mesh.topology import build_topology


def _ccw_triangle(rng, centre, size):
    while True:
        p = centre + size * rng.normal(size=(3, 2))
        a = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[1, 1] - p[0, 1]) * (p[2, 0] - p[0, 0])
        if abs(a) > 0.1 * size * size:
            return p if a > 0 else p[::-1].copy()


def _both(x, i, j, penalty):
    iw = np.empty(kc.N_IWORK, np.int64)
    pool = np.empty((kc.MAX_VERT, kc.N_COL))
    w_new = np.zeros(kc.N_WORK)
    w_old = np.zeros(kc.N_WORK)
    new = np.array(contact_oracle.pair_normal_edges(x, i, j, penalty, w_new, iw, pool))
    old = np.array(kc.pair_normal(x, i, j, penalty, w_old, iw, pool))
    return new, w_new, old, w_old


def _assert_same(x, i, j, penalty):
    """Same overlap verdict; forces, energy, area and the friction point agree to round-off:
    ``|dF| <= 1e-9 max|F| + 1e-13 p L`` (``L`` the larger coordinate extent of the pair, the
    scale of the round-off in the corner positions)."""
    new, w_new, old, w_old = _both(x, i, j, penalty)
    assert (new[1] > 0.0) == (old[1] > 0.0)
    if not old[1] > 0.0:
        assert new[0] == 0.0
        return False
    pts = np.vstack([x[3 * i:3 * i + 3], x[3 * j:3 * j + 3]])
    L = np.ptp(pts, axis=0).max()
    f_scale = np.abs(w_old[:12]).max()
    assert np.abs(w_new[:12] - w_old[:12]).max() <= 1e-9 * f_scale + 1e-13 * penalty * L
    # energy, area; the overlap centroid (first moment / area: its round-off grows as the area
    # shrinks); t's centroid and the barycentric gradients
    assert abs(new[0] - old[0]) <= 1e-9 * old[0] + 1e-13 * penalty * L * L
    assert abs(new[1] - old[1]) <= 1e-9 * old[1] + 1e-13 * L * L
    np.testing.assert_allclose(new[2:4], old[2:4], rtol=0.0, atol=1e-13 * L ** 3 / old[1])
    np.testing.assert_allclose(new[4:], old[4:], rtol=1e-12, atol=1e-14 * L)
    return True


def test_edge_evaluation_matches_clipping_on_random_pairs():
    rng = np.random.default_rng(7)
    n_overlap = 0
    for _ in range(1500):
        size = rng.uniform(0.2, 1.5)
        x = np.ascontiguousarray(np.vstack([_ccw_triangle(rng, np.zeros(2), 1.0),
                                            _ccw_triangle(rng, 0.8 * rng.normal(size=2), size)]))
        n_overlap += _assert_same(x, 0, 1, 3e10)
        n_overlap += _assert_same(x, 1, 0, 3e10)
    assert n_overlap > 900


def test_edge_evaluation_matches_clipping_on_shallow_and_containing_pairs():
    """Slivers (a corner or an edge pushed 1e-9 to 1e-3 of the size into the other triangle),
    and one triangle inside the other."""
    rng = np.random.default_rng(11)
    for _ in range(1000):
        xc = _ccw_triangle(rng, np.zeros(2), 1.0)
        # t: the mirror image of c across its edge 0 line, pushed back by a small depth
        p1, p2 = xc[1], xc[2]
        e = (p2 - p1) / np.linalg.norm(p2 - p1)
        n = np.array([e[1], -e[0]])                      # outward normal of c's edge 0
        depth = 10.0 ** rng.uniform(-9, -3)
        xt = xc - 2.0 * np.outer((xc - p1) @ n, n) - depth * n + 0.3 * rng.normal() * e
        xt = xt[::-1].copy()                             # the mirror reverses the orientation
        x = np.ascontiguousarray(np.vstack([xc, xt]))
        _assert_same(x, 0, 1, 1e10)
        _assert_same(x, 1, 0, 1e10)
        inner = xc.mean(axis=0) + 0.2 * (xc - xc.mean(axis=0)) @ np.array([[0.0, -1.0], [1.0, 0.0]])
        x = np.ascontiguousarray(np.vstack([xc, inner]))
        assert _assert_same(x, 0, 1, 1e10) and _assert_same(x, 1, 0, 1e10)


def test_edge_evaluation_matches_clipping_in_a_compressed_block():
    """Every triangle of a structured block inflated by 1 %: edge neighbours overlap in thin
    strips, corner neighbours in small triangles whose edges lie on one line to round-off
    (the case that falls back to clipping)."""
    topo = build_topology(structured_rectangle(12, 12, 12.0, 12.0))
    x = topo.x0.reshape(-1, 3, 2)
    g = x.mean(axis=1, keepdims=True)
    x = np.ascontiguousarray((g + 1.01 * (x - g)).reshape(-1, 2))
    n = topo.n_triangles
    centroids = x.reshape(-1, 3, 2).mean(axis=1)
    near = np.linalg.norm(centroids[:, None] - centroids[None], axis=2) < 1.6
    i, j = np.nonzero(np.triu(near, 1))
    n_overlap = sum(_assert_same(x, a, b, 1e11) for a, b in zip(i, j))
    assert n_overlap > 3 * n


def test_separating_axis_witness_agrees_with_the_full_test():
    """``_apart_on(axis)`` says apart only when the full separating-axis test does, and always
    for the axis the full test names (same strict arithmetic): random pairs, corners on the
    other's edges (exact zeros) and round-off slivers."""
    rng = np.random.default_rng(5)
    named = 0
    for k in range(3000):
        xc = _ccw_triangle(rng, np.zeros(2), 1.0)
        if k % 3 == 0:   # t shares c's edge 0 (a settled neighbour), nudged by 0 or round-off
            p1, p2 = xc[1], xc[2]
            e = p2 - p1
            xt = np.array([p2, p1, p1 + 0.5 * e + np.array([e[1], -e[0]])])
            xt += rng.choice([0.0, 1e-17, -1e-15, 1e-9], size=(3, 2))
        else:
            xt = _ccw_triangle(rng, 1.2 * rng.normal(size=2), rng.uniform(0.3, 1.5))
        args = (*xc.ravel(), *xt.ravel())
        axis = kc._sat_axis(*args)[0]
        hit = kc._sat(*args)[0]
        assert hit == (axis == 0)
        for a in range(1, 7):
            if kc._apart_on(a, *args):
                assert not hit
        if axis:
            named += 1
            assert kc._apart_on(axis, *args)
    assert named > 1000


def test_pair_loop_with_a_carried_witness_equals_a_fresh_one():
    """Forces, energies and history of a sheared, compressed block, stepped 60 times: the pair
    loop carrying its witnesses gives bit for bit what it gives with the cache zeroed."""
    topo = build_topology(structured_rectangle(10, 10, 10.0, 10.0))
    g0 = topo.x0.reshape(-1, 3, 2).mean(axis=1, keepdims=True)
    x = np.ascontiguousarray((g0 + 1.002 * (topo.x0.reshape(-1, 3, 2) - g0)).reshape(-1, 2))
    v = np.zeros_like(x)
    v[:, 0] = 0.3 * np.sin(2.0 * x[:, 1])
    centroids = x.reshape(-1, 3, 2).mean(axis=1)
    near = np.linalg.norm(centroids[:, None] - centroids[None], axis=2) < 1.6
    pi, pj = (np.ascontiguousarray(a, dtype=np.int64) for a in np.nonzero(np.triu(near, 1)))
    n = len(pi)
    bounds = kc.chunk_bounds(pi, 8)
    mu, kt, damp = np.full(n, kc.FROM_FACES), np.full(n, 1e9), np.full(n, 0.1)
    face_mu = np.full((len(x) // 3, 3), 0.5)
    face_mu[::2, 1] = 0.2  # faces of two frictions: the face picking runs
    state = {name: (np.zeros((n, kc.N_HIST)), np.zeros((n, 6)), np.zeros(n, np.uint8)) for name in ("carry", "fresh")}
    witness = np.zeros(n, np.uint8)
    for step in range(60):
        xs = x + step * 2e-3 * v
        out = {}
        for name, (hist, f_t, touching) in state.items():
            f = np.zeros_like(x)
            w = witness if name == "carry" else np.zeros(n, np.uint8)
            e = kc.pair_forces(xs, v, pi, pj, bounds, 1e10, mu, face_mu, 1.0, kt, damp, 1e-4, hist, f_t, touching, w, f)
            out[name] = (e, f)
        assert out["carry"][0] == out["fresh"][0]
        assert np.array_equal(out["carry"][1], out["fresh"][1])
    for a, b in zip(state["carry"], state["fresh"]):
        assert np.array_equal(a, b)
    assert (witness > 0).sum() > 100 and (witness == 0).sum() > 100   # both paths taken
