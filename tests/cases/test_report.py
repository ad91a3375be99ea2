"""A slope run through failure and runout to rest writes every output with finite values."""
from __future__ import annotations

import json
import math

import numpy as np

from fdem.geometry.polygons import slope_toe
from fdem.results.report import RunReport
from fdem.workflow.stages import response_time
from fdem.workflow.slope import SlopeWorkflow, run_slope_workflow

from conftest import planar_slope, planar_slope_scene


def _finite(obj) -> bool:
    if isinstance(obj, dict):
        return all(_finite(v) for v in obj.values())
    if isinstance(obj, list):
        return all(_finite(v) for v in obj)
    if isinstance(obj, float):
        return math.isfinite(obj)
    return True  # None marks a figure that is undefined (no displaced material), never NaN


def test_run_report_after_failure_and_runout(tmp_path):
    g = planar_slope("tension_crack")
    s = planar_slope_scene("tension_crack", 1.6, out_dir=tmp_path, pictures=False)
    sim = s.sim
    toe_x, _ = slope_toe(g.bodies[0])
    report = RunReport(sim, toe_x=toe_x)
    T = response_time(sim.model)
    # a short runout (0.4 s) decides "failed" once the block has moved the failure displacement,
    # here 2 cm (by default 1 % of the height, 15 cm: the block has slid 8.6 cm when the cap comes,
    # and the outcome would be "undecided")
    summary = run_slope_workflow(sim, SlopeWorkflow(factors=(1.6, 3.0), step_time=8 * T, runout_time=0.4,
                                                    fail_displacement=0.02))
    sim.close()
    out = report.write(tmp_path, extra={"workflow": summary})
    assert summary["outcome"] == "failed"
    for name in ("summary.json", "events.csv", "kinetic_energy.png", "cracks_by_mode.png", "failure.png",
                 "mechanism.png", "history.csv", "planar.pvd"):
        assert (tmp_path / name).stat().st_size > 0, name
    data = json.loads((tmp_path / "summary.json").read_text())
    assert _finite(data)
    assert data["cracks"]["broken"] == int(s.cracks.broken.sum()) > 0
    assert data["kinetic_energy"]["peak_J_per_m"] >= max(r["kinetic"] for r in sim.history) > 0
    assert data["runout"]["max_displacement_m"] > 0.02
    assert "NaN" not in (tmp_path / "summary.json").read_text()
    # monitors: cumulative cracks by mode on every history row, never decreasing
    broken = np.array([r["broken_I"] + r["broken_II"] + r["broken_mixed"] for r in sim.history])
    assert np.all(np.diff(broken) >= 0) and broken[-1] == data["cracks"]["broken"]
    assert np.all(np.array([r["fragments"] for r in sim.history]) >= 1)
    # crack elements by tag add up to the totals; activated ones are past the elastic range, unbroken
    tags = data["cracks_by_tag"]
    assert tags["rock"]["broken"] + tags["joints"]["broken"] == data["cracks"]["broken"]
    assert sum(g["broken"] for g in tags["by_tag"].values()) == data["cracks"]["broken"]
    # activated: past the elastic range and slipped or opened more than 1 mm, unbroken
    from fdem.results.motion import ACTIVATED, crack_status
    status = crack_status(s.cracks, sim.state.x)
    assert tags["rock"]["activated"] + tags["joints"]["activated"] == int((status == ACTIVATED).sum())
    assert int((status == ACTIVATED).sum()) <= data["cracks"]["inelastic"] - data["cracks"]["broken"]
    for g in (tags["rock"], tags["joints"]):
        assert sum(g["broken_by_mode"].values()) == g["broken"]
    # the failed mass's D90 on every row; the locked part is part of the failed mass
    assert data["locked"]["failed_area_m2"] == data["runout"]["displaced_area_m2"]
    assert 0 <= data["locked"]["area_m2"] <= data["locked"]["failed_area_m2"]
    assert sim.history[-1]["failed_d90"] == data["locked"]["d90_m"]
    # the block slides out of the face, far from the model's sides: they stay put while it moves
    bnd = data["boundaries"]
    assert set(bnd) == {"left", "right", "base"} and all(b["n_nodes"] > 0 for b in bnd.values())
    assert all(b["max_slip_m"] <= b["max_displacement_m"] < 0.01 * data["runout"]["max_displacement_m"]
               for b in bnd.values())
    # what the stages spent on frames, history rows and checkpoints is booked, and is part of their wall time
    cost = data["output_cost"]
    assert cost["seconds"]["frames"] > 0 and cost["seconds"]["history"] > 0
    assert 0 < cost["share"] < 1
    assert cost["wall_seconds"] == sum(st["wall_seconds"] for st in summary["stages"])
