"""Analysis of a run: runout distance/volume, deposit, displacement percentiles, failure surface,
fragments. Scenes with known answers: a block of an exploded mesh moved rigidly past a toe."""
import numpy as np
import pytest

from fdem.results.analysis import (boundary_motion, deposit_profile, displaced_areas, displacement_statistics, failure_surface, fragment_statistics, history_columns, runout, weighted_percentile)
from fdem.mesh.mesh import structured_rectangle
from fdem.mesh.topology import build_topology

# A 40 m x 10 m body of 1 m cells (2 triangles of 0.5 m^2 each); toe at x = 0, runout toward -x.
TOPO = build_topology(structured_rectangle(40, 10, 40.0, 10.0))
CENTROID0 = TOPO.x0[TOPO.triangles].mean(axis=1)
BLOCK = (CENTROID0[:, 0] < 10.0) & (CENTROID0[:, 1] > 4.0)  # 10 x 6 cells = 60 m^2
SHIFT = np.array([-13.0, -4.0])  # block lands on the floor y = 0, front at x = -13


def moved_block(stray: bool = False) -> np.ndarray:
    x = TOPO.x0.copy()
    x[TOPO.triangles[BLOCK].ravel()] += SHIFT
    if stray:  # one triangle thrown 130 m (0.5 m^2, 0.83 % of the displaced area)
        t = int(np.flatnonzero((CENTROID0[:, 0] > 30) & (CENTROID0[:, 1] < 1))[0])
        x[TOPO.triangles[t]] += [-130.0, 0.0]
    return x


def test_block_geometry_is_what_the_tests_assume():
    assert TOPO.triangle_area0[BLOCK].sum() == pytest.approx(60.0)
    assert np.all(TOPO.triangle_area0 == pytest.approx(0.5))


def test_runout_of_a_rigidly_moved_block_is_its_known_travel_and_area():
    r = runout(TOPO, moved_block(), toe_x=0.0, threshold=0.1)
    assert r["runout_distance_m"] == pytest.approx(13.0)
    assert r["runout_front_max_m"] == pytest.approx(13.0)
    assert r["runout_volume_m2"] == pytest.approx(60.0)
    assert r["passed_toe_area_m2"] == pytest.approx(60.0)
    assert r["n_displaced_triangles"] == 120
    travel = np.hypot(*SHIFT)
    for key in ("max_displacement_m", "p50_displacement_m", "p90_displacement_m", "p99_displacement_m"):
        assert r[key] == pytest.approx(travel)
    assert r["deformed_area_m2"] == pytest.approx(400.0)
    # the body ends at x = 0 (its toe): the block lies wholly beyond it, where no floor holds it
    assert r["off_model_area_m2"] == pytest.approx(60.0)


def test_debris_is_off_the_model_only_beyond_its_initial_extent():
    x = TOPO.x0.copy()
    x[TOPO.triangles[BLOCK].ravel()] += [5.0, 0.0]  # still over the body: nothing off it
    assert runout(TOPO, x, toe_x=0.0)["off_model_area_m2"] == 0.0
    half = BLOCK & (CENTROID0[:, 0] < 5.0)  # 5 x 6 cells moved 6 m left: their centroids at x < 0
    x = TOPO.x0.copy()
    x[TOPO.triangles[half].ravel()] += [-6.0, 0.0]
    assert runout(TOPO, x, toe_x=0.0)["off_model_area_m2"] == pytest.approx(30.0)


def test_one_thrown_triangle_does_not_change_the_runout_distance():
    r = runout(TOPO, moved_block(stray=True), toe_x=0.0)
    assert r["runout_distance_m"] == pytest.approx(13.0)  # 99th percentile by area ignores < 1 % of the mass
    assert r["runout_front_max_m"] == pytest.approx(100.0)  # the plain maximum does not
    assert r["runout_volume_m2"] == pytest.approx(60.5)
    assert r["max_displacement_m"] == pytest.approx(130.0)
    assert r["p99_displacement_m"] == pytest.approx(np.hypot(*SHIFT))


def test_nothing_moved_gives_zero_runout():
    r = runout(TOPO, TOPO.x0.copy(), toe_x=0.0)
    assert r["runout_distance_m"] == 0.0 and r["runout_volume_m2"] == 0.0 and r["n_displaced_triangles"] == 0
    assert r["off_model_area_m2"] == 0.0


def test_deposit_profile_of_a_block_on_the_floor_is_its_height():
    p = deposit_profile(TOPO, moved_block(), floor_y=0.0, bins=np.arange(-15.0, 1.0))
    inside = (p["centres"] > -13) & (p["centres"] < -3)
    np.testing.assert_allclose(p["top"][inside], 6.0)
    np.testing.assert_allclose(p["thickness"][inside], 6.0)
    np.testing.assert_allclose(p["top"][~inside], 0.0)
    assert p["area"].sum() == pytest.approx(60.0)


def test_failure_surface_is_the_failed_boundary_of_the_displaced_block():
    a, b = TOPO.crack_triangles[:, 0], TOPO.crack_triangles[:, 1]
    boundary = np.flatnonzero(BLOCK[a] != BLOCK[b])
    assert boundary.size == 16  # 10 along y = 4 and 6 along x = 10
    broken = np.zeros(TOPO.n_cracks, bool)
    broken[boundary[2:]] = True
    broken[np.flatnonzero(~BLOCK[a] & ~BLOCK[b])[:5]] = True  # cracks elsewhere: not on the surface
    surface = failure_surface(TOPO, moved_block(), broken, slipped=boundary[:2])
    np.testing.assert_array_equal(surface, boundary)
    assert failure_surface(TOPO, moved_block(), broken).size == 14  # without the two slid elements


def test_fragment_count_and_areas_of_a_hand_broken_strip():
    topo = build_topology(structured_rectangle(4, 1, 4.0, 1.0))  # 8 triangles of 0.5 m^2
    mid = 0.5 * (topo.x0[topo.crack_nodes[:, 0]] + topo.x0[topo.crack_nodes[:, 1]])
    broken = np.isclose(mid[:, 0], 2.0)  # the vertical edge at x = 2 splits the strip in halves
    lone = int(np.flatnonzero(topo.x0[topo.triangles].mean(axis=1)[:, 0] > 3.5)[0])
    broken |= np.any(topo.crack_triangles == lone, axis=1)  # free one triangle of the right half
    s = fragment_statistics(topo, broken)
    assert s["n_fragments"] == 3 and s["n_single_triangles"] == 1 and s["n_blocks"] == 2
    np.testing.assert_allclose(np.sort(s["areas"]), [0.5, 1.5, 2.0])
    np.testing.assert_allclose(s["largest"], [2.0, 1.5, 0.5])
    assert s["largest_share"] == pytest.approx(0.5)
    assert s["hist_counts"].sum() == 3
    assert s["hist_edges"][0] <= 0.5 and s["hist_edges"][-1] >= 2.0
    assert sorted(s["n_triangles"]) == [1, 3, 4]
    none = fragment_statistics(topo, np.zeros(topo.n_cracks, bool))
    assert none["n_fragments"] == 1 and none["areas"][0] == pytest.approx(4.0)


def test_weighted_percentile_is_the_inverse_cdf():
    v, w = np.array([1.0, 2.0, 3.0]), np.array([0.5, 0.495, 0.005])
    assert weighted_percentile(v, w, 99.0) == 2.0  # 3.0 carries only 0.5 % of the weight
    assert weighted_percentile(v, w, 50.0) == 1.0
    assert weighted_percentile(v, w, 100.0) == 3.0
    assert np.isnan(weighted_percentile(np.zeros(0), np.zeros(0), 50.0))


def test_bad_shapes_are_refused_with_the_expected_shape():
    with pytest.raises(ValueError, match=r"positions must have shape \(2400, 2\)"):
        runout(TOPO, TOPO.x0[:10], toe_x=0.0)
    with pytest.raises(ValueError, match="broken must have shape"):
        fragment_statistics(TOPO, np.zeros(3, bool))
    with pytest.raises(ValueError, match="mask must have shape"):
        displacement_statistics(TOPO, TOPO.x0, np.zeros(3, bool))


def test_history_columns_from_rows_and_from_csv_dict():
    rows = [{"time": 0.0, "kinetic": 1.0}, {"time": 0.1, "kinetic": 3.0}]
    t, k = history_columns(rows, "time", "kinetic")
    np.testing.assert_array_equal(k, [1.0, 3.0])
    t2, = history_columns({"time": np.array([0.0, 0.1])}, "time")
    np.testing.assert_array_equal(t, t2)
    with pytest.raises(KeyError, match="kinetic"):
        history_columns({"time": t}, "kinetic")


def test_boundary_motion_is_the_slip_of_the_nodes_that_started_on_each_side():
    """The block cut from the left-hand side took its share of that side along (its rigid shift,
    13.6 m, 4 m of it along the side) and left the right-hand side and the base at rest; nodes
    then dragged 0.2 m down the right-hand side (a roller) show that slip and nothing else."""
    x = moved_block()
    still = boundary_motion(TOPO.x0, x)
    assert still["left"]["max_displacement_m"] == pytest.approx(np.hypot(*SHIFT))
    assert still["left"]["max_slip_m"] == pytest.approx(4.0)
    assert still["right"]["max_displacement_m"] == 0.0 and still["base"]["max_displacement_m"] == 0.0
    right = np.isclose(TOPO.x0[:, 0], 40.0) & (TOPO.x0[:, 1] > 5.0)
    x[right] += [0.0, -0.2]
    dragged = boundary_motion(TOPO.x0, x)
    assert dragged["right"]["max_slip_m"] == pytest.approx(0.2)
    assert dragged["right"]["max_displacement_m"] == pytest.approx(0.2)
    assert dragged["base"]["max_displacement_m"] == 0.0 and dragged["left"] == still["left"]
    assert dragged["right"]["n_nodes"] == np.isclose(TOPO.x0[:, 0], 40.0).sum()


def test_displaced_areas_count_each_triangle_above_each_threshold():
    """The block moved 13.6 m (60 m^2) and one strip of 20 cells 0.5 m (20 m^2): 80 m^2 moved
    more than 0.1 m, 60 m^2 more than 1 m and 10 m, none more than 20 m."""
    x = moved_block()
    strip = (CENTROID0[:, 0] > 20.0) & (CENTROID0[:, 1] < 1.0)
    x[TOPO.triangles[strip].ravel()] += [0.0, 0.5]
    assert TOPO.triangle_area0[strip].sum() == pytest.approx(20.0)
    assert displaced_areas(TOPO, x, (0.1, 1.0, 10.0, 20.0)) == pytest.approx({"0.1": 80.0, "1": 60.0, "10": 60.0,
                                                                             "20": 0.0})
