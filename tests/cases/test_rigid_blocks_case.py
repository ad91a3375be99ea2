"""The rigid-block case runs end to end and meets Hoek-Bray on the planar slope; its slope
option prints beside the FDEM run without touching it."""
import json

import pytest

from fdem.cases import case_module


def test_rigid_blocks_case_runs_and_meets_hoek_bray(tmp_path, capsys):
    summary = case_module("rigid-blocks").main(["--scene", "planar-tension-crack", "demo", "--out", str(tmp_path),
                                                "--no-pictures", "--cycles", "1"])
    planar = summary["scenes"]["planar-tension-crack"]
    assert planar["fos"] == pytest.approx(planar["reference_fos"], rel=1e-3)
    assert planar["residual"]["fos"] == pytest.approx(0.5774 / 0.7002, rel=2e-3)   # tan 30 / tan 35, c = 0
    assert planar["yield"]["k_y"] > 0 and planar["newmark_displacement_m"] >= 0
    demo = summary["scenes"]["demo"]
    assert demo["n_blocks"] > 20 and demo["mechanism"]["n_moving"] >= 1 and demo["fos"] > 1.0
    assert json.loads((tmp_path / "summary.json").read_text())["scenes"]["demo"]["fos"] == demo["fos"]
    assert "factor of safety" in capsys.readouterr().out


def test_rigid_blocks_case_refuses_bad_options(tmp_path):
    with pytest.raises(SystemExit):
        case_module("rigid-blocks").main(["--lower", "2", "--upper", "1", "--out", str(tmp_path)])


def test_slivers_are_glued_but_the_planar_wedge_is_not(tmp_path):
    import warnings

    from fdem.blocks.assembly import block_system
    from fdem.cases.four_slopes import four_slope_geometry
    from fdem.cases.planar_failure import GEOMETRIES, planar_slope_geometry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = four_slope_geometry("low", "coarse")
    raw, glued = block_system(g), block_system(g, merge_below=0.01)
    assert glued.n_blocks < raw.n_blocks and glued.n_glued > 0
    assert glued.area.sum() == pytest.approx(raw.area.sum(), rel=1e-12)
    planar = planar_slope_geometry(10.0, **GEOMETRIES["no_crack"])
    assert block_system(planar, merge_below=0.01).n_blocks == 2
