"""The meso-scale readings of fdem.results.meso on small arrays with known answers."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from fdem.results import meso


def test_initiation_order_is_time_order_and_measures_the_climb():
    # breaks at y = 0, 1, 2, 3 m happening in the order y = 0, 1, 2, 3 but listed shuffled
    t = np.array([0.3, 0.1, 0.4, 0.2])
    y = np.array([2.0, 0.0, 3.0, 1.0])
    x = np.array([5.0, 7.0, 6.0, 8.0])
    r = meso.initiation_order(t, x, y)
    assert list(r["order"]) == [1, 3, 0, 2]
    assert r["first"] == (7.0, 0.0)
    assert r["climb_m_per_break"] == pytest.approx(1.0)  # one metre higher per break
    assert list(meso.initiation_order(t, x, y, n=2)["order"]) == [1, 3]
    with pytest.raises(ValueError, match="same length"):
        meso.initiation_order(t, x[:3], y)


def _chain(n_tri: int):
    """Triangles 0..n-1 in a row, crack element k between triangles k and k+1."""
    pairs = np.array([[k, k + 1] for k in range(n_tri - 1)])
    return SimpleNamespace(n_triangles=n_tri, n_cracks=n_tri - 1, crack_triangles=pairs)


def test_fragments_at_splits_a_chain_when_its_middle_element_breaks():
    topo = _chain(4)  # cracks (0,1), (1,2), (2,3)
    bt = np.array([np.nan, 0.5, np.nan])
    n, label = meso.fragments_at(topo, bt, 0.4)
    assert n == 1
    n, label = meso.fragments_at(topo, bt, 0.5)  # broken at its break time
    assert n == 2 and label[0] == label[1] != label[2] == label[3]


def test_assemblies_drop_single_triangle_debris_and_rank_by_area():
    # fragments: {0, 1} area 2, {2} area 5 (one triangle: debris), {3, 4, 5} area 3
    label = np.array([0, 0, 1, 2, 2, 2])
    area = np.array([1.0, 1.0, 5.0, 1.0, 1.0, 1.0])
    a = meso.assemblies(label, area, min_triangles=2)
    assert list(a) == [1, 1, -1, 0, 0, 0]
    table = meso.assembly_table(a, area, np.array([0.0, 2.0, 9.0, 1.0, 1.0, 4.0]))
    assert table["area"] == pytest.approx([3.0, 2.0])
    assert table["y"] == pytest.approx([2.0, 1.0])


def test_principal_directions_of_a_rotated_uniaxial_compression():
    # uniaxial compression of 2 MPa along 65 deg: s = -2 n n^T
    th = math.radians(65.0)
    n = np.array([math.cos(th), math.sin(th)])
    s = -2e6 * np.outer(n, n)
    pd = meso.principal_directions(s[0, 0], s[1, 1], s[0, 1])
    assert float(pd["s2"]) == pytest.approx(-2e6)
    assert float(pd["s1"]) == pytest.approx(0.0, abs=1e-6)
    assert float(pd["theta2"]) == pytest.approx(th)
    assert meso.direction_share(np.array([th, th - math.pi, 0.0, th + 0.1]), th, math.radians(10)) == 0.75


def test_force_segments_join_centroids_and_drop_zero_forces():
    c = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    segs, mag = meso.force_segments(c, np.array([[0, 1], [1, 2]]), np.array([3.0, 0.0]))
    assert segs.tolist() == [[0.0, 0.0, 1.0, 0.0]] and mag.tolist() == [3.0]
    with pytest.raises(ValueError, match="outside"):
        meso.force_segments(c, np.array([[0, 3]]), np.array([1.0]))


def test_normality_accepts_a_normal_sample_and_rejects_a_skewed_one():
    rng = np.random.default_rng(7)
    normal = rng.normal(-3.07, 0.495, 238)  # the paper's catalogue size and law
    r = meso.normality(normal, -3.07, 0.495)
    # p-values of a sample from the tested law are uniform: 1e-3 fails one seed in a thousand
    assert r["normal_at_5pct"] and r["shapiro_p"] > 1e-3 and r["ks_p"] > 1e-3
    # the same sample shifted by one magnitude unit keeps its shape but leaves the paper's law
    assert meso.normality(normal + 1.0, -3.07, 0.495)["ks_p"] < 1e-6
    skewed = -3.0 + rng.exponential(0.5, 238)
    assert not meso.normality(skewed)["normal_at_5pct"]
    with pytest.raises(ValueError, match="at least 3"):
        meso.normality([1.0, np.nan])


def test_muliashi_slide_model_divides_strengths_by_k_and_fracture_energies_by_k_squared():
    """The slide's 1 g model of the slope at gravity factor k: forces scale by 1/k, so the crack
    laws must be the same curves in (u/k, f/k): strengths / k, energies / k^2, friction and
    penalties kept; the snap-back margin G f_t^-2 is then unchanged."""
    from fdem.cases.muliashi import property_sets

    base, weak = property_sets(1.0), property_sets(1.0, strength_factor=4.0)
    for tag in (0, 1):
        b, w = base[tag], weak[tag]
        assert (w.f_t, w.c) == pytest.approx((b.f_t / 4, b.c / 4))
        assert (w.G_I, w.G_II) == pytest.approx((b.G_I / 16, b.G_II / 16))
        assert (w.phi, w.p_n, w.p_t) == (b.phi, b.p_n, b.p_t)
        assert w.G_I / w.f_t ** 2 == pytest.approx(b.G_I / b.f_t ** 2)
    with pytest.raises(ValueError, match="strength_factor"):
        property_sets(1.0, strength_factor=0.0)


def test_fragment_statistics_leaves_out_excluded_triangles_and_their_bonds():
    """A strip of five 1 m cells whose middle cell is excluded (a fixed support): intact, the
    strip is two rock fragments of 2 m^2 each; the support's own bonds do not join them."""
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology
    from fdem.results.analysis import fragment_statistics

    topo = build_topology(structured_rectangle(5, 1, 5.0, 1.0))
    xc = topo.x0[topo.triangles].mean(axis=1)[:, 0]
    support = (xc > 2.0) & (xc < 3.0)
    intact = np.zeros(topo.n_cracks, bool)
    assert fragment_statistics(topo, intact)["n_fragments"] == 1  # everything counted: one body
    s = fragment_statistics(topo, intact, exclude=support)
    assert s["n_fragments"] == 2 and s["n_blocks"] == 2 and s["n_single_triangles"] == 0
    assert s["areas"] == pytest.approx([2.0, 2.0]) and s["largest_share"] == pytest.approx(0.5)
    assert np.all(s["label"][support] == -1) and set(s["label"][~support]) == {0, 1}
    assert s["hist_counts"].sum() == 2
    every = fragment_statistics(topo, np.ones(topo.n_cracks, bool), exclude=support)
    assert every["n_fragments"] == every["n_single_triangles"] == 8  # 10 triangles less the support's 2
    with pytest.raises(ValueError, match=r"exclude must have shape \(10,\)"):
        fragment_statistics(topo, intact, exclude=support[:3])


@pytest.fixture(scope="module")
def slide_model():
    """The Muliashi slide model at 2 m elements, strengths / 20, with its wall (15 s to build)."""
    from fdem.cases.muliashi import build

    _, sim, cracks, _ = build(2.0, wall=True, progress=False, pictures=False, strength_factor=20.0)
    yield sim, cracks
    sim.close()


def test_muliashi_fixed_wall_is_no_fragment(slide_model):
    """The slide model's left wall (a body fixed in x and y at every node) is a support: the
    run's fragment count is the slope alone, intact one fragment, fully broken one per triangle."""
    from fdem.results.analysis import fragment_statistics
    from fdem.results.report import RunReport, fixed_body_triangles

    sim, cracks = slide_model
    topo = sim.model.topology
    wall = topo.triangle_body == 1
    assert wall.any() and np.array_equal(fixed_body_triangles(sim.model), wall)
    assert fragment_statistics(topo, cracks.broken)["n_fragments"] == 2  # the slope and the wall
    frag = RunReport(sim, toe_x=10.0).summary()["fragments"]
    assert frag["n_fragments"] == frag["n_blocks"] == 1 and frag["largest_share"] == 1.0
    every = fragment_statistics(topo, np.ones(topo.n_cracks, bool), exclude=wall)
    assert every["n_fragments"] == every["n_single_triangles"] == int((~wall).sum())


def test_muliashi_slide_model_keeps_the_ground_below_the_toe_at_full_strength(slide_model):
    """Strengths / k are the slope's limit state; the ground below the toe's elevation takes no
    part in that failure and keeps the unreduced set (same heterogeneity draws), while the
    model's own tags (what the pictures show as joints) stay the geometry's."""
    from fdem.cases.muliashi import GROUND_TAG_OFFSET, property_sets

    sim, cracks = slide_model
    topo = sim.model.topology
    mid_y = topo.x0[topo.crack_nodes[:, :2], 1].mean(axis=1)
    ground = (mid_y < 7.5) & (topo.triangle_body[topo.crack_triangles[:, 0]] == 0)  # toe at y = 7.5 m
    assert ground.any() and (~ground).any()
    assert np.array_equal(cracks.tag[ground], topo.crack_tag[ground] + GROUND_TAG_OFFSET)
    assert np.array_equal(cracks.tag[~ground], topo.crack_tag[~ground])
    assert set(np.unique(topo.crack_tag)) <= {0, 1}
    full, weak = property_sets(2.0), property_sets(2.0, strength_factor=20.0)
    g = cracks.property_sets[GROUND_TAG_OFFSET]
    assert (g.f_t, g.c, g.G_I, g.G_II) == (full[0].f_t, full[0].c, full[0].G_I, full[0].G_II)
    assert (cracks.property_sets[0].f_t, cracks.property_sets[0].G_I) == (weak[0].f_t, weak[0].G_I)
    h = cracks.strength_multiplier[ground & (topo.crack_tag == 0)]
    assert 0.05 < h.std() < 0.15  # the bridges' cov 0.1 reaches the ground too


def test_floor_cracking_counts_broken_elements_below_the_toe_by_place_and_depth():
    # toe at (10, 7.5), the slope facing -x: the floor is x < 10 below y = 7.5
    mid = np.array([[5.0, 7.0], [5.0, 4.0], [15.0, 1.0], [15.0, 9.0], [5.0, 2.0], [12.0, 7.4]])
    broken = np.array([True, True, True, True, False, True])
    r = meso.floor_cracking(mid, broken, (10.0, 7.5))
    assert (r["broken"], r["below_toe"], r["in_floor"], r["under_slope"]) == (5, 4, 2, 2)
    assert r["deepest_m"] == pytest.approx(6.5)  # the element at y = 1 under the slope
    assert r["by_depth_m"] == {"0-1": 2, "1-2": 0, "2-4": 1, "4-8": 1, ">8": 0}
    none = meso.floor_cracking(mid, np.zeros(6, bool), (10.0, 7.5))
    assert none["below_toe"] == 0 and none["deepest_m"] == 0.0
    with pytest.raises(ValueError, match="midpoints must be"):
        meso.floor_cracking(mid, broken[:3], (10.0, 7.5))
