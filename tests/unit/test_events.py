"""Micro-seismic events: clustering of hand-made breakages with known events, moments and
magnitudes; Aki's b-value on a seeded Gutenberg-Richter sample; the empty catalogue."""
import csv
import math

import numpy as np
import pytest

from fdem.physics.cracks import EVENT_DTYPE
from fdem.results.events import (MULIASHI, b_value, cluster_events, compare_with_reference, magnitude_frequency, magnitude_statistics, max_curvature_mc, moment_magnitude, seismic_moment, write_catalogue_csv)

MU, RHO, DSIGMA = 1.0e9, 2500.0, 1.0e5  # c_s = 632 m/s


def breakages(rows):
    """rows of (element, time, x, y, mode, length, energy)."""
    out = np.zeros(len(rows), EVENT_DTYPE)
    for k, (el, t, x, y, mode, L, e) in enumerate(rows):
        out[k] = (el, k, t, x, y, mode, 0, L, e, e if mode == "I" else 0.0, 0.0 if mode == "I" else e)
    return out


# Burst A: three 0.3 m cracks in a row at y = 0 within 20 us; burst B: two cracks 11 m away 1 ms later.
# Listed out of time order on purpose.
TWO_BURSTS = breakages([
    (7, 1.0e-3, 10.0, 5.0, "II", 0.3, 5.0),
    (1, 0.0, 0.0, 0.0, "I", 0.3, 10.0),
    (2, 1.0e-5, 0.3, 0.0, "I", 0.3, 20.0),
    (8, 1.1e-3, 10.3, 5.0, "mixed", 0.3, 5.0),
    (3, 2.0e-5, 0.6, 0.0, "II", 0.3, 30.0),
])


def test_two_separated_bursts_give_two_events_with_known_members_energy_moment_magnitude():
    cat = cluster_events(TWO_BURSTS, shear_modulus=MU, stress_drop=DSIGMA, density=RHO)
    assert len(cat) == 2
    assert [sorted(TWO_BURSTS["element"][m]) for m in cat.members] == [[1, 2, 3], [7, 8]]
    a, b = cat.events
    # A: energy 60 J/m, centroid weighted by energy x = (0*10 + 0.3*20 + 0.6*30)/60 = 0.4;
    # source size = 0.6 m (farthest midpoints) + 0.3 m (crack length) = 0.9 m; E_3D = 54 J
    assert a["energy"] == pytest.approx(60.0) and a["x"] == pytest.approx(0.4) and a["y"] == pytest.approx(0.0)
    assert a["t_start"] == 0.0 and a["duration"] == pytest.approx(2.0e-5) and a["n_cracks"] == 3
    assert (a["n_I"], a["n_II"], a["n_mixed"]) == (2, 1, 0)
    assert a["source_size"] == pytest.approx(0.9) and a["energy_3d"] == pytest.approx(54.0)
    assert a["moment"] == pytest.approx(2 * MU * 54.0 / DSIGMA)  # 1.08e6 N m
    assert a["magnitude"] == pytest.approx(2 / 3 * math.log10(1.08e6) - 6.07)  # -2.0477
    # B: energy 10 J/m, x = 10.15, source 0.6 m, E_3D = 6 J, M0 = 1.2e5 N m
    assert b["energy"] == pytest.approx(10.0) and b["x"] == pytest.approx(10.15) and b["y"] == pytest.approx(5.0)
    assert b["t_start"] == pytest.approx(1.0e-3) and b["duration"] == pytest.approx(1.0e-4)
    assert b["moment"] == pytest.approx(1.2e5)
    assert b["magnitude"] == pytest.approx(2 / 3 * math.log10(1.2e5) - 6.07)
    assert (b["n_I"], b["n_II"], b["n_mixed"]) == (0, 1, 1)


def test_time_rule_splits_a_late_crack_at_the_same_place():
    late = breakages([(1, 0.0, 0.0, 0.0, "I", 0.3, 1.0), (2, 1.0e-5, 0.3, 0.0, "I", 0.3, 1.0),
                      (3, 1.0, 0.3, 0.0, "I", 0.3, 1.0)])  # 1 s later: far beyond 0.9 m / 632 m/s
    cat = cluster_events(late, MU, DSIGMA, density=RHO)
    assert [sorted(late["element"][m]) for m in cat.members] == [[1, 2], [3]]
    # a user window long enough joins it again; a user distance below the 0.3 m spacing splits
    # crack 1 off, while 3 (same place as 2) stays with 2
    assert len(cluster_events(late, MU, DSIGMA, window=2.0)) == 1
    cat = cluster_events(late, MU, DSIGMA, window=2.0, distance=0.1)
    assert [sorted(late["element"][m]) for m in cat.members] == [[1], [2, 3]]


def test_a_crack_near_two_open_events_merges_them():
    rows = breakages([(1, 0.0, 0.0, 0.0, "I", 0.3, 1.0), (2, 0.0, 1.5, 0.0, "I", 0.3, 1.0),
                      (3, 1.0e-6, 0.75, 0.0, "I", 0.3, 1.0)])  # 0.75 m from both, join distance 0.9 m
    cat = cluster_events(rows, MU, DSIGMA, density=RHO)
    assert len(cat) == 1 and cat.events["n_cracks"][0] == 3


def test_moment_and_magnitude_formulas():
    assert seismic_moment(10.0, 2.0, 3e10, 1e6) == pytest.approx(2 * 3e10 * 20.0 / 1e6)
    assert moment_magnitude(10 ** 9.105) == pytest.approx(2 / 3 * 9.105 - 6.07)
    assert moment_magnitude(1.0) == pytest.approx(-6.07)
    with pytest.raises(ValueError, match="stress drop"):
        seismic_moment(1.0, 1.0, 3e10, 0.0)


def test_b_value_recovers_the_gutenberg_richter_slope_of_a_seeded_sample():
    rng = np.random.default_rng(2024)
    for b_true in (0.8, 1.0, 1.5):
        m = -4.0 + rng.exponential(1.0 / (b_true * math.log(10.0)), size=5000)
        fit = b_value(m, mc=-4.0)
        assert fit["b"] == pytest.approx(b_true, rel=0.04)
        assert fit["b_error"] == pytest.approx(fit["b"] / math.sqrt(5000))
        assert abs(fit["b"] - b_true) < 3 * fit["b_error"]
    # magnitudes binned to 0.1 (lowest bin centred on Mc = -4.0) with Utsu's half-bin correction
    mb = np.round((-4.05 + rng.exponential(1.0 / math.log(10.0), size=5000)) / 0.1) * 0.1
    assert b_value(mb, mc=-4.0, dm=0.1)["b"] == pytest.approx(1.0, rel=0.05)


def test_max_curvature_mc_is_the_fullest_bin():
    assert max_curvature_mc([-3.25, -3.15, -3.12, -3.11, -2.5], dm=0.1) == pytest.approx(-3.2)


def test_magnitude_frequency_counts_and_cumulative():
    mf = magnitude_frequency([-3.05, -3.0, -2.95, -2.5], dm=0.1)
    assert mf["counts"].sum() == 4
    assert mf["cumulative"][0] == 4 and mf["cumulative"][-1] == 1
    np.testing.assert_array_equal(mf["cumulative"], mf["counts"][::-1].cumsum()[::-1])


def test_statistics_and_comparison_with_the_muliashi_catalogue():
    m = np.array([-4.0, -3.0, -2.0])
    s = magnitude_statistics(m)
    assert (s["count"], s["min"], s["max"], s["mean"], s["std"]) == (3, -4.0, -2.0, -3.0, 1.0)
    c = compare_with_reference(m)
    assert c["count"]["reference"] == 238 and c["mean"]["difference"] == pytest.approx(0.07)
    assert c["std"]["difference"] == pytest.approx(1.0 - 0.495)
    assert c["mean_difference_in_std"] == pytest.approx(0.07 / 0.495)
    assert MULIASHI == {"count": 238, "min": -4.91, "max": -2.05, "mean": -3.07, "std": 0.495}


def test_no_breakages_give_a_clear_no_events_result(tmp_path):
    cat = cluster_events(np.zeros(0, EVENT_DTYPE), MU, DSIGMA, density=RHO)
    assert cat.empty and len(cat) == 0 and "no events" in cat.summary()
    path = write_catalogue_csv(tmp_path / "events.csv", cat)
    lines = path.read_text().splitlines()
    assert lines[0].split(",")[:3] == ["event", "t_start", "duration"] and lines[1].startswith("# no events")
    assert magnitude_statistics(cat)["count"] == 0 and "no events" in magnitude_statistics(cat)["message"]
    with pytest.raises(ValueError, match="no events"):
        b_value(cat)
    assert "no events" in compare_with_reference(cat)["message"]


def test_catalogue_csv_round_trips(tmp_path):
    cat = cluster_events(TWO_BURSTS, MU, DSIGMA, density=RHO)
    path = write_catalogue_csv(tmp_path / "events.csv", cat)
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2
    np.testing.assert_allclose([float(r["magnitude"]) for r in rows], cat.magnitudes, rtol=1e-9)
    assert [int(r["n_cracks"]) for r in rows] == [3, 2]


def test_bad_input_is_refused_by_name():
    with pytest.raises(ValueError, match="energy"):
        cluster_events(np.zeros(2, [("time", float), ("x", float), ("y", float), ("length", float)]),
                       MU, DSIGMA, density=RHO)
    with pytest.raises(ValueError, match="density"):
        cluster_events(TWO_BURSTS, MU, DSIGMA)
    with pytest.raises(ValueError, match="structured"):
        cluster_events(np.zeros(3), MU, DSIGMA, density=RHO)
