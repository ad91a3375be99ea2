"""The seismic-slope case: options refused at parse time, and a coarse run's summary.

The physics (critical amplitude of a block against Newmark's rigid block above k_y) is checked in
``tests/verification/test_seismic_block.py``; here the case's plumbing: a coarse, short run writes
k_y, a_c, the Newmark and FDEM displacements and the picture.
"""
from __future__ import annotations

import json

import pytest

from fdem.cases import CASES
from fdem.cases import seismic_slope


@pytest.mark.parametrize("argv", [["--frequency", "0"], ["--cycles", "-1"], ["--settle", "nan"],
                                  ["--threshold", "1.5"], ["--bracket", "0.5", "0.2", "0.01"],
                                  ["--amplitudes", "0.9"], ["--widths", "1"], ["--size", "4"],
                                  ["--max-trials", "1"]])
def test_bad_options_exit_2_before_any_work(argv, tmp_path):
    with pytest.raises(SystemExit) as err:
        seismic_slope.main(argv + ["--out", str(tmp_path / "run")])
    assert err.value.code == 2
    assert not (tmp_path / "run").exists()


def test_coarse_run_summary_holds_k_y_a_c_and_displacements(tmp_path):
    assert CASES["seismic-slope"] == "fdem.cases.seismic_slope"
    out = tmp_path / "run"
    seismic_slope.main(["--out", str(out), "--size", "2.0", "--widths", "24", "--amplitudes", "1.5",
                        "--bracket", "0.05", "0.8", "0.3", "--frequency", "4", "--cycles", "1", "--settle", "0.1"])
    s = json.loads((out / "summary.json").read_text())
    assert 0 < s["k_y"] < 1 and s["a_y_m_s2"] == pytest.approx(9.81 * s["k_y"])
    lo, hi = s["a_c_bracket_g"]
    assert 0.05 <= lo < s["a_c_g"] < hi <= 0.8
    assert s["mechanism"]["n_moving"] >= 1
    row, = s["displacements"]
    assert row["amplitude_g"] == pytest.approx(1.5 * s["k_y"])
    assert row["newmark_m"] > 0 and row["fdem_m"] >= 0
    # the search's own trials: the stable ones below the threshold, the failing ones above it
    for p in s["fdem_points"]:
        assert (p["permanent_displacement_m"] < s["threshold_m"]) == p["stable"]
    assert (out / "seismic.png").stat().st_size > 0
