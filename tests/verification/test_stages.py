"""Stages, the slope workflow and the energy ledger through a whole reduction schedule.

The scene is the planar-failure slope of ``cases/planar_failure.py`` at a coarse size: a block on
a joint that daylights in the face, static geostatic start.
"""
from __future__ import annotations

import numpy as np
import pytest

from fdem.solve.damping import Damping, NO_DAMPING
from fdem.workflow.stages import Convergence, Failure, Stage, response_time, run_stage
from fdem.workflow.fos import fundamental_damping
from fdem.workflow.slope import SlopeWorkflow, reduction_steps, run_slope_workflow, runout_stage

from conftest import PLANAR_SIZE, planar_slope_scene

import planar_failure as pf  # cases/planar_failure.py (tests/conftest.py puts cases/ on sys.path)


def test_stage_rules_are_checked_before_anything_runs():
    with pytest.raises(ValueError, match="can never end"):
        Stage("forever")
    with pytest.raises(ValueError, match="max_time"):
        Stage("x", max_time=float("nan"), converge=Convergence())
    with pytest.raises(ValueError, match="at least one"):
        Convergence(unbalanced_ratio=None)
    with pytest.raises(ValueError, match="damping"):
        Stage("x", duration=1.0, damping=0.8)
    assert reduction_steps(0.3) == pytest.approx([1 / 0.9, 1 / 0.8, 1 / 0.7, 1 / 0.6, 1 / 0.5, 1 / 0.4, 1 / 0.3])
    with pytest.raises(ValueError, match="time-step factor"):
        Stage("x", duration=1.0, dt_fraction=1.5)


def test_a_stage_runs_at_its_own_time_step_factor_and_gives_it_back():
    s = planar_slope_scene()
    crit, _ = s.sim.critical_dt()
    T = response_time(s.sim.model)
    # on the real masses (a damped stage is density-scaled by default: tests/verification/test_density_scaling.py)
    r = run_stage(s.sim, Stage("fine", duration=0.05 * T, dt_fraction=0.4, damping=fundamental_damping(s.sim),
                               density_scaling=False), frames=False)
    assert r.dt == pytest.approx(0.4 * crit) and s.sim.dt_fraction == 0.8
    assert r.steps == pytest.approx(0.05 * T / (0.4 * crit), abs=1)
    r = run_stage(s.sim, Stage("default", duration=0.05 * T, damping=fundamental_damping(s.sim),
                               density_scaling=False), frames=False)
    assert r.dt == pytest.approx(0.8 * crit)
    # the workflow's runout stage runs at the workflow's factor
    assert runout_stage(SlopeWorkflow(runout_dt_fraction=0.4), T, 10.0, 9.81).dt_fraction == 0.4
    # its frames every half free-fall time over the height, whatever the cap (a 60 s cap gave a
    # collapse at rest after 11 s no frame); a short cap keeps four
    free_fall = np.sqrt(2.0 * 30.0 / 9.81)
    assert runout_stage(SlopeWorkflow(runout_time=60.0), T, 30.0, 9.81).output_interval == pytest.approx(0.5 * free_fall)
    assert runout_stage(SlopeWorkflow(runout_time=0.6), T, 30.0, 9.81).output_interval == pytest.approx(0.15)
    # a user step above the critical one is refused, and the simulation keeps its own factor
    s.sim.user_dt = 2.0 * crit
    with pytest.raises(ValueError, match="exceeds the stable time step"):
        run_stage(s.sim, Stage("too_big", duration=0.05 * T, dt_fraction=0.4), frames=False)
    assert s.sim.dt_fraction == 0.8
    s.sim.user_dt = None


def test_a_stage_ends_when_material_leaves_the_model():
    """A body thrown sideways at 3 m/s crosses its initial x range plus a 1 cm margin after
    (0.01 m) / (3 m/s) = 3.3 ms: a stage with ``domain_margin`` ends ``left_model`` then
    (at its next check), one without runs to its cap."""
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    def thrown():
        topo = build_topology(structured_rectangle(3, 3, 0.3, 0.3))
        model = Model(topo, ElasticMaterial(young=1e8, poisson=0.25, density=2500.0))
        model.set_gravity(0.0, -9.81)  # free: it falls 1 cm in 45 ms, after it has left sideways
        model.set_initial_velocity(vx=3.0, vy=0.0)
        return Simulation(model, progress=False)

    sim = thrown()
    r = run_stage(sim, Stage("runout", max_time=0.02, converge=Convergence(unbalanced_ratio=None, speed=1e-6),
                             check_interval=5e-4, domain_margin=0.01), frames=False)
    assert r.reason == "left_model" and "beyond the model's initial extent" in r.detail
    assert 0.01 / 3.0 <= r.t_end <= 0.01 / 3.0 + 5e-4 + 2 * r.dt
    sim = thrown()
    r = run_stage(sim, Stage("runout", max_time=0.02, converge=Convergence(unbalanced_ratio=None, speed=1e-6),
                             check_interval=5e-4), frames=False)
    assert r.reason == "capped"
    with pytest.raises(ValueError, match="domain_margin"):
        Stage("x", duration=1.0, domain_margin=-1.0)
    assert runout_stage(SlopeWorkflow(), 0.3, 30.0, 9.81).domain_margin == pytest.approx(0.3)


def test_fly_rock_is_held_beyond_the_model_and_the_runout_goes_on():
    """Eight free triangles (no crack elements: each its own fragment, 0.5 m^2) of a 4 m x 1 m
    strip: one thrown along +x at 2 m/s, the other seven drifting up at 4 m/s (displaced more
    than 0.1 m after 25 ms). The thrown one crosses the strip's end plus the 0.1 m margin after
    50 ms. With an escape share of 0.2 (0.8 m^2 of the 4 m^2 displaced) it is held there: the
    stage runs to its end, the held triangle's nodes stand still from then on, and its kinetic
    energy (0.5 m v^2 of 2 m/s) leaves as boundary work, the ledger balanced. With a
    share of 0.05 (0.2 m^2) the same triangle is the mass running off: ``left_model``. (Gravity
    1e-6 m/s^2 along x: the stage's closing unbalanced-force ratio needs a load to divide by.)"""
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation
    from fdem.workflow.stages import HELD

    def strip():
        topo = build_topology(structured_rectangle(4, 1, 4.0, 1.0))
        model = Model(topo, ElasticMaterial(young=1e8, poisson=0.25, density=2500.0))
        model.set_gravity(1e-6, 0.0)  # next to none (the stage's last ratio divides by it)
        sim = Simulation(model, progress=False)
        tri = np.asarray(topo.triangles)
        thrown = int(np.argmax(topo.x0[tri].mean(axis=1)[:, 0]))  # the triangle nearest the +x end
        sim.state.v[:, 1] = 4.0
        sim.state.v[tri[thrown]] = (2.0, 0.0)
        return sim, tri, thrown

    sim, tri, thrown = strip()
    area = float(sim.model.topology.triangle_area0[thrown])
    kinetic = 0.5 * float(sim.state.mass[tri[thrown]].sum()) * 4.0
    stage = Stage("runout", duration=1.0, check_interval=0.01, domain_margin=0.1, escape_share=0.2)
    r = run_stage(sim, stage, frames=False)
    assert r.reason == "completed" and "1 triangle(s) of fragments that left the model" in r.detail
    assert np.all(sim.flags[tri[thrown]] == HELD) and np.all(sim.state.v[tri[thrown]] == 0.0)
    assert 4.1 < sim.state.x[tri[thrown], 0].max() < 4.1 + 2.0 * 0.011  # held within a check of the margin
    held = sim.fields()["cell"]["held"]  # the frames mark it, so that a view can leave it out
    assert held[thrown] == 1 and held.sum() == 1
    row = sim.history[-1]
    assert row["boundary_work"] == pytest.approx(-kinetic, rel=1e-5)   # its kinetic energy, taken out
    assert row["balance_error_relative"] < 1e-9
    assert area == pytest.approx(0.5)
    sim, tri, thrown = strip()
    r = run_stage(sim, Stage("runout", duration=1.0, check_interval=0.01, domain_margin=0.1, escape_share=0.05),
                  frames=False)
    assert r.reason == "left_model"
    with pytest.raises(ValueError, match="escape_share"):
        Stage("x", duration=1.0, escape_share=0.5)   # no margin to escape past
    assert runout_stage(SlopeWorkflow(), 0.3, 30.0, 9.81).escape_share == pytest.approx(0.01)


def test_a_trial_stage_keeps_its_time_step_factor():
    from fdem.workflow.fos import _trial_stage_at

    trial = Stage("trial", max_time=1.0, converge=Convergence(), dt_fraction=0.4, output_interval=0.1, reduction=2.0)
    at = _trial_stage_at(trial, 1.5)
    assert at.name == "trial_F1.5000" and at.dt_fraction == 0.4 and at.output_interval == 0.1
    assert at.reduction is None   # the trigger sets the factor, not the stage


def test_static_start_converges_and_a_weak_slope_fails():
    """From the static start the slope settles within the cap (a few joint elements at the
    daylight point are above their strength at F = 1 and slide a little); far below its
    strength the block slides and the failure rule fires."""
    s = planar_slope_scene()
    sim = s.sim
    T = response_time(sim.model)
    r = run_stage(sim, Stage("equilibrium", max_time=10 * T, converge=Convergence(unbalanced_ratio=1e-4),
                             damping=Damping.quasi_static()), frames=False)
    assert r.reason == "converged" and r.unbalanced_ratio <= 1e-4
    assert r.max_displacement < 1e-3
    # Far below its strength the block slides, under the damping of the reduction stages
    # (mass-proportional, critical for the fundamental mode): the stage fails, by displacement
    # or by not converging within its cap, and the whole block has moved.
    snap_x = sim.state.x.copy()
    r = run_stage(sim, Stage("weak", max_time=10 * T, reduction=4.0, converge=Convergence(),
                             fail=Failure(displacement=0.02), damping=fundamental_damping(sim)), frames=False)
    assert r.reason in ("failed", "capped") and r.unbalanced_ratio > 1e-4
    moved = np.linalg.norm(sim.state.x - snap_x, axis=1)[s.block_nodes]
    assert moved.min() > 1e-3   # the whole block moves
    r = run_stage(sim, Stage("weak_dynamic", max_time=10 * T, converge=Convergence(),
                             fail=Failure(displacement=0.02)), frames=False)
    assert r.reason == "failed" and r.max_displacement > 0.02


def test_ledger_closes_through_a_reduction_schedule_with_breakage_and_contact():
    """Damped reduction steps until the block fails, then an undamped runout: elements soften,
    break and slide while the factor keeps changing, contact takes the broken faces; the ledger
    stays closed to 1 % of the energy scale."""
    s = planar_slope_scene("tension_crack")   # the crack breaks open when the block moves
    sim = s.sim
    T = response_time(sim.model)
    wf = SlopeWorkflow(factors=(1.2, 1.6, 2.2, 3.0), step_time=8 * T, fail_displacement=0.02,
                       runout_time=0.6)
    summary = run_slope_workflow(sim, wf)
    assert summary["equilibrium"] == "converged"
    assert summary["outcome"] == "failed"
    # every history row carries the unbalanced-force ratio; the equilibrium stage ended on the
    # row whose ratio met the limit
    assert all("unbalanced_ratio" in row for row in sim.history)
    eq_rows = [row for row in sim.history if row["stage"] == "equilibrium"]
    assert eq_rows[-1]["unbalanced_ratio"] == summary["stages"][0]["unbalanced_ratio"] <= 1e-4
    assert s.cracks.broken.sum() > 0 and s.contact.n_touching > 0
    # reduced after breakage: the factor now on every interface is the failing one
    assert s.cracks.interfaces.reduction == summary["failed_at_factor"]
    errors = np.array([abs(row["balance_error_relative"]) for row in sim.history])
    assert errors.max() < 0.01, f"ledger error {errors.max():.3g} of the energy scale"
    assert summary["stages"][-1]["name"] == "runout"


def test_a_search_alone_ends_after_its_bracket_with_the_limit_equilibrium_factor():
    """``reduction = "none"``: the factor-of-safety search is the whole analysis. Its bracket is
    the planar slope's Hoek-Bray factor (1.396) within the verification tolerance of 10 %, and
    nothing runs after it: no reduction stage, no runout, the state the equilibrium at F = 1
    that every trial started from."""
    with pytest.raises(ValueError, match="needs fos"):
        SlopeWorkflow(reduction="none")
    with pytest.raises(ValueError, match="strength trigger"):
        SlopeWorkflow(reduction="none", fos=(1.0, 2.0, 0.1), trigger="gravity")
    s = planar_slope_scene()
    sim = s.sim
    le = pf.analytic(**pf.GEOMETRIES["no_crack"])
    summary = run_slope_workflow(sim, SlopeWorkflow(reduction="none", fos=(1.0, 1.8, 0.1)))
    assert summary["outcome"] == "searched" and summary["failed_at_factor"] is None
    assert [st["name"] for st in summary["stages"]] == ["equilibrium"]
    lo, hi = summary["fos"]["bracket"]
    assert hi - lo <= 0.1 and summary["fos"]["fos"] == pytest.approx(le.fos, rel=0.10), (summary["fos"], le.fos)
    assert f"{summary['fos']['fos']:.4g}" in summary["ending"]
    # the cost estimate's count of trials bounds the search's, rounding of the midpoints included
    from fdem.workflow.fos import most_trials

    assert summary["fos"]["n_trials"] <= most_trials(1.0, 1.8, 0.1) == 6
    assert [most_trials(1.0, 1.3, 0.04), most_trials(1.0, 3.0, 0.04), most_trials(1.0, 1.5, 1.0)] == [5, 8, 2]
    # the trials restore their start state and keep no history rows: every row is the equilibrium's
    assert {row["stage"] for row in sim.history} == {"equilibrium"}
    equilibrium = summary["stages"][0]
    assert sim.state.time == pytest.approx(equilibrium["t_end"])  # back where the trials started
    assert np.abs(sim.state.x - sim.model.topology.x0[sim.model.topology.triangles].reshape(-1, 2)).max() < 1e-3


def test_the_search_judges_its_trials_by_the_rule_of_the_workflow():
    """The workflow's equilibrium ratio, stage cap and failure displacement are its trials' too:
    a slope the default rule fails at F = 1.8 (its factor is 1.4, the test above) is stable there
    when its workflow counts a ratio of 0.5 as equilibrium, so the search stops at its upper end
    with the bracket open above it. Before, the trials kept 1e-4 and 5 T whatever the workflow
    said, and a convergence study could not hold its rule fixed across element sizes."""
    from fdem.workflow.fos import default_trial_stage

    s = planar_slope_scene()
    sim = s.sim
    trial = default_trial_stage(sim, 2e-4, 3.0, Failure(displacement=0.05), hold_for=0.4)
    assert (trial.converge.unbalanced_ratio, trial.max_time, trial.fail.displacement) == (2e-4, 3.0, 0.05)
    assert trial.converge.hold_for == 0.4
    summary = run_slope_workflow(sim, SlopeWorkflow(reduction="none", fos=(1.0, 1.8, 0.1), equilibrium_ratio=0.5))
    assert summary["fos"]["fos"] is None and summary["fos"]["bracket"] == [1.8, None], summary["fos"]
    assert "stable" in summary["fos"]["error"]


def test_a_held_equilibrium_rule_keeps_the_limit_equilibrium_factor(tmp_path):
    """``equilibrium_hold``: a trial counts as stable only once its ratio has kept below the limit
    for that many response times. On the planar slope, which stands or slides with nothing
    between, the held rule finds the Hoek-Bray factor (1.396) within the verification tolerance
    of 10 % as the first-check rule does, and each stable trial ran at least the hold; the
    search's picture of its trials (ratio and displacement against each trial's time) shows
    every stable trial ending under the limit."""
    with pytest.raises(ValueError, match="equilibrium_hold"):
        SlopeWorkflow(equilibrium_hold=-1.0)
    s = planar_slope_scene()
    sim = s.sim
    T = response_time(sim.model)
    with pytest.raises(ValueError, match="do not fit in a stage capped"):  # refused before any step
        run_slope_workflow(sim, SlopeWorkflow(reduction="none", fos=(1.0, 1.8, 0.1), equilibrium_hold=5.0))
    assert sim.state.step == 0
    le = pf.analytic(**pf.GEOMETRIES["no_crack"])
    summary = run_slope_workflow(sim, SlopeWorkflow(reduction="none", fos=(1.0, 1.8, 0.1), equilibrium_hold=1.0),
                                 out_dir=tmp_path)
    assert summary["fos"]["fos"] == pytest.approx(le.fos, rel=0.10), (summary["fos"], le.fos)
    stable = [t for t in summary["fos"]["trials"] if t["stable"] and t["steps"] > 1]
    assert stable and all(t["t_end"] - t["t_start"] >= T * (1 - 1e-9) for t in stable), stable
    assert all(t["unbalanced_ratio"] <= 1e-4 for t in stable)
    assert (tmp_path / "fos_trials.png").stat().st_size > 0


def test_a_bracket_whose_failing_end_was_still_settling_at_its_cap_is_told_so(tmp_path, capsys):
    """The planar slope at F = 1.4, 0.3 % above its Hoek-Bray factor (1.396), slides, but so
    slowly that at a cap of 3 response times the decay of its elastic answer to the change of
    strength still dominates: its displacement grew less in the last response time than in the
    one before, its ratio fell, and the search whose failing end it is says that its factor may
    lean on the cap (``fos.json`` ``leans_on_cap``, a warning naming the trial). Given 5 response
    times the same trial reads as the slide it is (its growth as large as the response time
    before's, to 5 %, its ratio no longer falling) and the search does not lean on its cap; a
    clear slide (F = 1.8) never reads as settling."""
    import json

    from fdem.solve.geostatic import unbalanced_force_ratio
    from fdem.workflow.fos import default_trial_stage, factor_of_safety

    sim = planar_slope_scene().sim
    sim.add_monitor("unbalanced_ratio", unbalanced_force_ratio)   # the trials' rows, as the workflow keeps them
    T = response_time(sim.model)
    le = pf.analytic(**pf.GEOMETRIES["no_crack"]).fos
    short = factor_of_safety(sim, lower=1.0, upper=1.4, tol=0.8, trial=default_trial_stage(sim, 1e-4, 3 * T),
                             out_dir=tmp_path)
    assert short.bracket == (1.0, 1.4) and le < 1.4 < 1.01 * le
    at_cap = short.trials[1]
    assert at_cap.result.reason == "capped" and at_cap.cap_trend["settling"], at_cap.cap_trend
    assert at_cap.cap_trend["share"] < 0.9 and at_cap.cap_trend["ratio_fall"] > 1.0
    assert short.leans_on_cap and json.loads((tmp_path / "fos.json").read_text())["leans_on_cap"] is True
    # the trials picture draws it dashed: its curve says so, and the picture was written
    from fdem.workflow.fos import trial_curves

    assert [c["settling"] for c in trial_curves(short) if c["factor"] == 1.4] == [True]
    assert (tmp_path / "fos_trials.png").stat().st_size > 0
    assert "F = 1.4, reached its cap" in capsys.readouterr().out
    longer = factor_of_safety(sim, lower=1.0, upper=1.4, tol=0.8, trial=default_trial_stage(sim, 1e-4, 5 * T))
    trend = longer.trials[1].cap_trend
    assert not trend["settling"] and trend["share"] == pytest.approx(1.0, abs=0.05) and trend["ratio_fall"] <= 1.0
    assert not longer.leans_on_cap and "reached its cap" not in capsys.readouterr().out
    slide = factor_of_safety(sim, lower=1.0, upper=1.8, tol=0.8, trial=default_trial_stage(sim, 1e-4, 3 * T))
    assert slide.trials[1].result.reason == "capped" and not slide.trials[1].cap_trend["settling"]
    assert not slide.leans_on_cap
    sim.close()
    # the workflow's search alone says so in its ending, with the trials at its step_time and
    # judged at their cap
    summary = run_slope_workflow(planar_slope_scene().sim,
                                 SlopeWorkflow(reduction="none", fos=(1.0, 1.4, 0.8), step_time=3 * T, trial_end="cap"))
    assert summary["fos"]["leans_on_cap"] and "may lean on the cap" in summary["ending"], summary["ending"]


def test_the_same_trials_read_at_half_their_cap_give_the_verdicts_of_trials_that_short(capsys):
    """A trial steps the same whatever its cap until it stops, so a search's trials read at a
    shorter cap (``by_cap``, :func:`fdem.workflow.fos.bracket_by_cap`) must give the verdicts of
    trials run to that cap. On the planar slope near its Hoek-Bray factor (1.396) the block
    settles ever more slowly (at F = 1.397, 0.1 % above it, in 2.24 response times on this mesh):
    a search of 4 T trials is read at 2 and 4 T, every factor it tried is run again capped at
    2 T, and each verdict must match the 2 T reading; the 4 T reading is the search's own
    bracket, within 1 % of Hoek-Bray."""
    from fdem.solve.checkpoint import restore, snapshot
    from fdem.solve.geostatic import unbalanced_force_ratio
    from fdem.workflow.fos import StrengthReduction, _run_trial, default_trial_stage, factor_of_safety

    sim = planar_slope_scene().sim
    sim.add_monitor("unbalanced_ratio", unbalanced_force_ratio)
    T = response_time(sim.model)
    le = pf.analytic(**pf.GEOMETRIES["no_crack"]).fos
    start = snapshot(sim)
    search = factor_of_safety(sim, lower=1.39, upper=1.45, tol=0.005, trial=default_trial_stage(sim, 1e-4, 4 * T))
    half, whole = search.by_cap
    assert half["cap_response_times"] == pytest.approx(2.0) and whole["cap_response_times"] == pytest.approx(4.0)
    assert whole["bracket"] == list(search.bracket) and abs(search.fos - le) < 0.01 * le
    short = default_trial_stage(sim, 1e-4, 2 * T)
    for t in search.trials:
        restore(sim, start)
        again, _ = _run_trial(sim, StrengthReduction(), short, t.factor)
        assert again.stable == (t.factor in half["stable"]), (t.factor, again.result.reason, half)
    # near the limit the slowest stable trials need more than 2 T: the reading moved, and is told
    assert half["bracket"] != whole["bracket"], search.by_cap
    assert "factor of safety against the trials' length" in capsys.readouterr().out
    sim.close()
    # the workflow's search alone, judged at the cap, ends by saying so, its fos.json (in the
    # summary) keeping the readings
    summary = run_slope_workflow(planar_slope_scene().sim,
                                 SlopeWorkflow(reduction="none", fos=(1.39, 1.45, 0.005), step_time=4 * T,
                                               trial_end="cap"))
    assert summary["fos"]["by_cap"] == search.as_dict()["by_cap"]
    assert "the factor moves with the trials' length" in summary["ending"], summary["ending"]


def test_trials_followed_to_rest_give_the_bracket_of_trials_long_enough_to_converge(capsys):
    """A trial that reaches its cap neither stood nor failed. Followed undamped to rest, as the
    damped reduction steps follow a stage that did not settle (``follow``,
    :func:`fdem.workflow.fos.creep_verdict`), it is judged by whether the slope stops: on the
    planar slope with trials of only 2 response times, F = 1.3975 (0.1 % above Hoek-Bray's
    1.396, settling in 2.24 T) is capped and, followed, comes to rest within a millimetre,
    so stands; the factors above slide to the failure displacement. The bracket is the one
    trials of 4 T give by convergence alone (the test above), and within 1 % of Hoek-Bray; the
    cap's own rule at 2 T gives 1.39-1.3975. A search so judged does not lean on its cap and
    does not read its trials at shorter caps."""
    from fdem.solve.geostatic import unbalanced_force_ratio
    from fdem.workflow.fos import default_trial_stage, factor_of_safety

    sim = planar_slope_scene().sim
    sim.add_monitor("unbalanced_ratio", unbalanced_force_ratio)
    T = response_time(sim.model)
    H = float(np.ptp(sim.model.topology.x0[:, 1]))
    le = pf.analytic(**pf.GEOMETRIES["no_crack"]).fos
    follow = runout_stage(SlopeWorkflow(), T, H, 9.81)
    short = default_trial_stage(sim, 1e-4, 2 * T)
    rest = factor_of_safety(sim, lower=1.39, upper=1.41, tol=0.0025, trial=short, follow=follow)
    capped = factor_of_safety(sim, lower=1.39, upper=1.41, tol=0.0025, trial=short)
    longer = factor_of_safety(sim, lower=1.39, upper=1.41, tol=0.0025, trial=default_trial_stage(sim, 1e-4, 4 * T))
    assert rest.bracket == longer.bracket != capped.bracket, (rest.bracket, longer.bracket, capped.bracket)
    assert capped.bracket[1] == rest.bracket[0] and abs(rest.fos - le) < 0.01 * le
    crept = next(t for t in rest.trials if t.factor == rest.bracket[0])
    assert crept.stable and crept.result.reason == "capped" and crept.follow.reason == "converged"
    assert crept.follow_verdict == "crept"
    from fdem.workflow.fos import trial_curves

    curve = next(c for c in trial_curves(rest) if c["factor"] == crept.factor)   # drawn on into its follow
    assert curve["follow_from"] == pytest.approx(2 * T, rel=0.05) and curve["time"][-1] > curve["follow_from"]
    assert not curve["settling"]   # judged by its follow, not by its cap
    assert crept.result.max_displacement + crept.follow.max_displacement < 0.01 * 0.01 * H   # under a millimetre
    for t in rest.trials:
        if not t.stable:   # each slid to the failure displacement (1 % of the height), followed or not
            assert t.follow.reason == "failed" and t.result.max_displacement + t.follow.max_displacement >= 0.01 * H
    assert not rest.leans_on_cap and rest.by_cap == [] and rest.as_dict()["trials"][1]["follow_verdict"] == "failed"
    assert "followed undamped, came to rest" in capsys.readouterr().out
    sim.close()
    # the workflow's search alone so judged says which trials crept and stood
    summary = run_slope_workflow(planar_slope_scene().sim, SlopeWorkflow(reduction="none", fos=(1.39, 1.41, 0.0025),
                                                                        step_time=2 * T, trial_end="rest"))
    assert summary["fos"]["bracket"] == list(rest.bracket)
    # with the creep each stood trial had at rest, trial and follow together (the workflow's own
    # equilibrium is its trials' start: the same verdicts, not the same millimetres)
    stood = next(t for t in summary["fos"]["trials"] if t["factor"] == rest.bracket[0])
    moved = stood["max_displacement"] + stood["follow"]["max_displacement"]
    assert moved < 0.01 * H
    assert f"standing after creeping at F = {rest.bracket[0]:.4g} ({moved:.3g} m in all)" in summary["ending"], \
        summary["ending"]


def test_a_picture_that_cannot_be_drawn_does_not_lose_the_search(tmp_path, monkeypatch):
    """The search's pictures come after its result: one that raises (a full disk, a broken
    plotting library) is told, and the search still returns its bracket with fos.json on disk;
    the bracket ends are Hoek-Bray's sides (stable at 1.0, failing at 1.8 against 1.396)."""
    import json

    from fdem.io import pictures
    from fdem.workflow.fos import factor_of_safety

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pictures, "trial_histories_plot", broken)
    monkeypatch.setattr(pictures, "failure_frame", broken)
    from fdem.solve.geostatic import unbalanced_force_ratio

    sim = planar_slope_scene().sim
    sim.add_monitor("unbalanced_ratio", unbalanced_force_ratio)   # the trials' curves, as the workflow keeps them
    result = factor_of_safety(sim, lower=1.0, upper=1.8, tol=0.8, out_dir=tmp_path)
    assert result.bracket == (1.0, 1.8)
    assert json.loads((tmp_path / "fos.json").read_text())["bracket"] == [1.0, 1.8]
    sim.close()


def test_a_search_judged_by_a_raised_limit_at_its_first_check_is_told_so(monkeypatch, capsys):
    """A strength-reduction search whose ratio limit the model's round-off floor raises, taken at
    its first check, is warned once before its first trial (such a limit passed a creeping trial
    on the low-angle coarse slope at 1.0 m); the limit named is the one its trials apply (the
    floor of the start state, :func:`fdem.workflow.stages.ratio_limit`), and a held rule is not
    warned."""
    import dataclasses

    from fdem.workflow import fos as fos_module
    from fdem.workflow.fos import factor_of_safety
    from fdem.workflow.stages import ratio_limit

    def no_trial(*args, **kwargs):
        raise RuntimeError("no trial needed")

    monkeypatch.setattr(fos_module, "_run_trial", no_trial)
    sim = planar_slope_scene().sim
    rule = Convergence(unbalanced_ratio=1e-4, roundoff_factor=1e6)   # raised on any model
    limit = ratio_limit(sim, rule)
    assert limit > 1e-4
    for hold, told in ((0.0, True), (0.1, False)):
        trial = Stage("trial", max_time=1.0, converge=dataclasses.replace(rule, hold_for=hold), fail=Failure())
        with pytest.raises(RuntimeError, match="no trial needed"):
            factor_of_safety(sim, lower=1.0, upper=1.8, tol=0.4, trial=trial)
        out = capsys.readouterr().out
        assert (f"raised to {limit:.3g}" in out) is told, out
    sim.close()


def test_gravity_increase_books_its_work_and_finds_the_critical_gravity_factor():
    """Planar block, c = 20 kPa, phi = 30 deg on a 35 deg plane: limit equilibrium fails when
    gravity is k times larger with k = c A / (W (sin psi_p - cos psi_p tan phi)) (the
    cohesion does not grow with the weight). The gravity-increase search must find it within
    10 %, and the ledger must stay closed while gravity changes under a moving slope."""
    from fdem.workflow.fos import GravityIncrease, factor_of_safety

    s = planar_slope_scene()
    sim = s.sim
    le = pf.analytic(**pf.GEOMETRIES["no_crack"])
    psi, phi = np.radians(35.0), np.radians(pf.JOINT_FRICTION)
    k_exact = pf.JOINT_COHESION * le.plane_length / (le.weight * (np.sin(psi) - np.cos(psi) * np.tan(phi)))
    result = factor_of_safety(sim, lower=1.0, upper=5.0, tol=0.1, trigger=GravityIncrease())
    assert result.bracket[0] < result.bracket[1] <= result.bracket[0] + 0.1 + 1e-12
    assert result.fos == pytest.approx(k_exact, rel=0.10), (result.fos, k_exact)
    assert np.allclose(sim.gravity, sim.model.gravity)          # back to where it started
    # gravity doubled, then raised past failure while the block moves, undamped
    T = response_time(sim.model)
    run_stage(sim, Stage("heavier", duration=2 * T, gravity_factor=2.0), frames=False)
    run_stage(sim, Stage("failing", duration=4 * T, gravity_factor=1.3 * k_exact), frames=False)
    row = sim.history[-1]
    assert row["gravity_change_work"] != 0.0 and row["kinetic"] > 0.0
    errors = np.array([abs(r["balance_error_relative"]) for r in sim.history])
    assert errors.max() < 0.01, f"ledger error {errors.max():.3g} of the energy scale"


def planar_simulation(geometry: str, size: float):
    """Module-level scene builder: worker processes of the parallel search call it."""
    return planar_slope_scene(geometry, size).sim


def test_parallel_trials_restart_from_a_checkpoint_and_agree_with_limit_equilibrium(tmp_path):
    """Two worker processes, each restarting its trials from a checkpoint of the equilibrium
    state: each round splits the bracket in three; the factor of safety lands within 10 % of
    Hoek and Bray's, like the serial search."""
    from fdem.workflow.fos import factor_of_safety

    sim = planar_slope_scene().sim
    le = pf.analytic(**pf.GEOMETRIES["no_crack"])
    result = factor_of_safety(sim, lower=1.0, upper=2.0, tol=0.05, workers=2, build=planar_simulation,
                              build_args=("no_crack", PLANAR_SIZE), out_dir=tmp_path)
    assert result.bracket[1] - result.bracket[0] <= 0.05
    assert result.fos == pytest.approx(le.fos, rel=0.10), (result.fos, le.fos)
    assert len(result.trials) == 2 + 2 * 3          # the ends, then three rounds of two
    assert (tmp_path / "fos_start.npz").exists() and (tmp_path / "fos.json").exists()
    with pytest.raises(ValueError, match="needs build"):
        factor_of_safety(sim, workers=2)


def _search_killed_in_its_third_trial(tmp_path, monkeypatch, every_seconds=None, wf=None,
                                      counted=lambda stage: stage.startswith("trial"), kill_in: int = 3):
    """The planar slope's workflow (a search over 1.0-2.0 to 0.1, then a step that holds) run whole
    into ``tmp_path/whole``, then again into ``tmp_path/cut`` with a journal (periodic checkpoints
    every ``every_seconds``) and killed on the fifth row of its third trial, as a SIGKILL would
    (no handler runs). Returns ``(wf, whole summary, whole sim, factors of the cut run's trials,
    the cut run's folder, the real _run_trial)``. ``wf``: another workflow; ``counted``: which
    stages' rows count toward the fifth (default: the trial's); ``kill_in``: the trial killed."""
    from fdem.workflow import fos as fos_module
    from fdem.workflow.journal import RunJournal

    # judged at the cap: a trial is one stage here (a followed one has its own test, below), and
    # with a checkpoint at every row the follows would take minutes
    wf = wf or SlopeWorkflow(factors=(1.1,), fos=(1.0, 2.0, 0.1), trial_end="cap")
    whole_sim = planar_slope_scene(out_dir=tmp_path / "whole", pictures=False).sim
    whole = run_slope_workflow(whole_sim, wf)
    whole_sim.close()
    run_trial = fos_module._run_trial
    calls = []

    class Killed(Exception):
        pass

    def killed_in_the_third(sim, *args, **kwargs):
        calls.append(args[2])
        if len(calls) == kill_in:  # partway through its steps
            record_row = sim._record_row

            def dies_on_the_fifth_row(*a, **k):
                if sum(1 for r in sim.history if counted(r["stage"])) >= 5:
                    raise Killed
                return record_row(*a, **k)

            monkeypatch.setattr(sim, "_record_row", dies_on_the_fifth_row)
        return run_trial(sim, *args, **kwargs)

    monkeypatch.setattr(fos_module, "_run_trial", killed_in_the_third)
    out = tmp_path / "cut"
    cut_sim = planar_slope_scene(out_dir=out, pictures=False).sim
    with pytest.raises(Killed):
        run_slope_workflow(cut_sim, wf, journal=RunJournal(out / "checkpoint.npz", every_seconds=every_seconds))
    cut_sim.close()
    return wf, whole, whole_sim, calls, out, run_trial


def _assert_same_search(whole, whole_sim, resumed, sim, whole_dir, resumed_dir):
    """A resumed run ended as the run never cut: the same trials, verdicts, bracket and failure
    surface, the same stages, the same state to the bit (crack elements too), the same history.csv."""
    key = lambda t: (t["factor"], t["stable"], t["steps"], t["reason"], t["max_displacement"])  # noqa: E731
    assert [key(t) for t in resumed["fos"]["trials"]] == [key(t) for t in whole["fos"]["trials"]]
    assert resumed["fos"]["bracket"] == whole["fos"]["bracket"]
    assert resumed["fos"]["failure_broken_elements"] == whole["fos"]["failure_broken_elements"]
    assert [(st["name"], st["reason"], st["steps"]) for st in resumed["stages"]] == \
        [(st["name"], st["reason"], st["steps"]) for st in whole["stages"]]
    a, b = whole_sim.state_dict(), sim.state_dict()
    assert np.array_equal(a["x"], b["x"]) and np.array_equal(a["v"], b["v"])
    assert all(np.array_equal(a["providers"][0][k], b["providers"][0][k]) for k in ("state", "diss", "broken"))
    assert (whole_dir / "history.csv").read_bytes() == (resumed_dir / "history.csv").read_bytes()


def _resumed_counting_trials(monkeypatch, run_trial, out, wf):
    """The cut run in ``out`` resumed (periodic checkpoints at every row) on a fresh simulation,
    counting the trials it runs and the steps each advanced. Returns ``(summary, sim, factors,
    steps)``."""
    from fdem.workflow import fos as fos_module
    from fdem.workflow.journal import RunJournal

    calls, steps = [], []

    def counted(sim, *a, **k):
        calls.append(a[2])
        step = sim.state.step
        outcome = run_trial(sim, *a, **k)
        steps.append(sim.state.step - step)
        return outcome

    monkeypatch.setattr(fos_module, "_run_trial", counted)
    sim = planar_slope_scene(out_dir=out, pictures=False).sim
    journal = RunJournal.resume_from(sim, out / "checkpoint.npz", every_seconds=1e-9)
    sim.continue_outputs()
    summary = run_slope_workflow(sim, wf, journal=journal)
    sim.close()
    return summary, sim, calls, steps


def test_a_search_cut_short_goes_on_from_its_last_finished_trial(tmp_path, monkeypatch):
    """A bisection of hours must not be lost to the end of a session. Killed halfway through its
    third trial (no handler runs: the checkpoint on disk is the one written after the second),
    the run resumes on a freshly built simulation, runs only the trials not yet finished, and
    ends as a search never cut: the same trials, verdicts and bracket, the same final state to
    the bit after the stage that follows, and the same history.csv."""
    from fdem.solve.checkpoint import read_checkpoint
    from fdem.workflow import fos as fos_module
    from fdem.workflow.journal import RunJournal

    wf, whole, whole_sim, calls, out, run_trial = _search_killed_in_its_third_trial(tmp_path, monkeypatch)
    saved = read_checkpoint(out / "checkpoint.npz")["context"]["marks"][fos_module.TRIALS_MARK]["trials"]
    assert [t["factor"] for t in saved] == calls[:2] == [t["factor"] for t in whole["fos"]["trials"][:2]]

    calls.clear()
    monkeypatch.setattr(fos_module, "_run_trial", lambda sim, *a, **k: (calls.append(a[2]), run_trial(sim, *a, **k))[1])
    sim = planar_slope_scene(out_dir=out, pictures=False).sim
    journal = RunJournal.resume_from(sim, out / "checkpoint.npz")
    sim.continue_outputs()
    resumed = run_slope_workflow(sim, wf, journal=journal)
    sim.close()
    assert calls == [t["factor"] for t in whole["fos"]["trials"][2:]]   # only the trials not yet finished
    _assert_same_search(whole, whole_sim, resumed, sim, tmp_path / "whole", out)
    assert fos_module.TRIALS_MARK not in journal.marks  # a finished search leaves only its result behind


def test_a_trial_cut_short_goes_on_from_its_own_checkpoint(tmp_path, monkeypatch):
    """A trial of an hour must not be run again from its start at every session's end. With
    periodic checkpoints at every history row, a run killed on the fifth row of its third trial
    holds that trial in its checkpoint (its runtime and the search's start state kept apart in
    fos_start.npz); resumed, it runs only the rest of that trial, then the trials not yet begun,
    and ends as a search never cut: the same trials and bracket, the same state to the bit after
    the stage that follows, the same history.csv."""
    import shutil

    from fdem.solve.checkpoint import load_checkpoint, read_checkpoint, save_checkpoint
    from fdem.workflow import fos as fos_module
    from fdem.workflow.journal import RunJournal

    wf, whole, whole_sim, calls, out, run_trial = _search_killed_in_its_third_trial(tmp_path, monkeypatch,
                                                                                    every_seconds=1e-9)
    third = whole["fos"]["trials"][2]
    context = read_checkpoint(out / "checkpoint.npz")["context"]
    assert context["stage"]["name"] == f"trial_F{third['factor']:.4f}"   # inside the third trial
    assert context["marks"][fos_module.TRIALS_MARK]["running"] == third["factor"]
    assert (out / fos_module.START_NAME).is_file()
    stopped_at = read_checkpoint(out / "checkpoint.npz")["state"]["step"]
    assert stopped_at > read_checkpoint(out / fos_module.START_NAME)["state"]["step"]
    # the same folder as a stop right after a resume began would leave it: the trial's state,
    # the trial named running, no stage runtime (written outside the time loop)
    early = tmp_path / "stopped_early"
    shutil.copytree(out, early)
    probe = planar_slope_scene(out_dir=None, pictures=False).sim
    context = load_checkpoint(probe, early / "checkpoint.npz")
    save_checkpoint(probe, early / "checkpoint.npz", context={**context, "stage": None})
    probe.close()

    resumed, sim, calls, resumed_steps = _resumed_counting_trials(monkeypatch, run_trial, out, wf)
    assert calls == [t["factor"] for t in whole["fos"]["trials"][2:]]
    assert 0 < resumed_steps[0] < third["steps"]   # the third trial went on, it did not start again
    _assert_same_search(whole, whole_sim, resumed, sim, tmp_path / "whole", out)

    # resumed from that state, the search starts from its own start state (fos_start.npz), not
    # from the trial's: the third trial begins again and the run ends as the uncut one
    calls.clear()
    monkeypatch.setattr(fos_module, "_run_trial", run_trial)
    sim = planar_slope_scene(out_dir=early, pictures=False).sim
    journal = RunJournal.resume_from(sim, early / "checkpoint.npz")
    sim.continue_outputs()
    again = run_slope_workflow(sim, wf, journal=journal)
    sim.close()
    _assert_same_search(whole, whole_sim, again, sim, tmp_path / "whole", early)


def test_a_trial_cut_inside_its_follow_to_rest_goes_on_from_there(tmp_path, monkeypatch):
    """A trial followed to rest (``trial_end = "rest"``) is two stages; killed on the fifth row
    of the follow of its upper end (F = 2.0, capped, then sliding undamped), the run's
    checkpoint holds the follow (its runtime, and the capped trial's result in the search's
    progress), and resumed it runs only the rest of the follow, not the trial again, and ends
    as the run never cut: the same trials, verdicts and follows, the same state to the bit,
    the same history.csv."""
    from fdem.solve.checkpoint import read_checkpoint
    from fdem.workflow import fos as fos_module
    from fdem.workflow.journal import RunJournal

    wf = SlopeWorkflow(factors=(1.1,), fos=(1.0, 2.0, 1.0), trial_end="rest")
    wf, whole, whole_sim, calls, out, run_trial = _search_killed_in_its_third_trial(
        tmp_path, monkeypatch, every_seconds=1e-9, wf=wf, kill_in=2,
        counted=lambda stage: stage.endswith(fos_module.FOLLOW_SUFFIX))
    upper = whole["fos"]["trials"][1]
    assert upper["reason"] == "capped" and upper["follow"]["reason"] == "failed"   # F = 2.0 slides
    context = read_checkpoint(out / "checkpoint.npz")["context"]
    assert context["stage"]["name"] == f"trial_F{upper['factor']:.4f}{fos_module.FOLLOW_SUFFIX}"
    assert context["marks"][fos_module.TRIALS_MARK]["running_capped"]["steps"] == upper["steps"]
    stopped_at = read_checkpoint(out / "checkpoint.npz")["state"]["step"]

    resumed, sim, calls, steps_run = _resumed_counting_trials(monkeypatch, run_trial, out, wf)
    assert calls == [upper["factor"]]   # only the upper end, from inside its follow
    assert 0 < steps_run[0] < upper["follow"]["steps"]   # the rest of the follow, not the trial again
    assert stopped_at > 0 and resumed["fos"]["trials"][1]["follow"]["steps"] == upper["follow"]["steps"]
    _assert_same_search(whole, whole_sim, resumed, sim, tmp_path / "whole", out)


def test_a_checkpoint_inside_a_trial_is_refused_by_a_search_that_cannot_go_on_with_it(tmp_path):
    """A checkpoint holding a trial's runtime, resumed by a search with parallel workers (whose
    trials are not checkpointed inside), is refused before any trial, naming the trial: run on,
    that search would start from the trial's state with the trial's factor applied."""
    from fdem.workflow import fos as fos_module
    from fdem.workflow.fos import default_trial_stage, factor_of_safety
    from fdem.workflow.journal import RunJournal

    sim = planar_slope_scene(out_dir=tmp_path, pictures=False).sim
    journal = RunJournal(tmp_path / "checkpoint.npz")
    trial = default_trial_stage(sim, max_time=1.0)
    search = {"lower": 1.0, "upper": 2.0, "tol": 0.1, "trigger": "strength reduction", "trial": trial.name,
              "max_time": 1.0}   # the same search, but run by two workers
    journal.marks[fos_module.TRIALS_MARK] = {"search": search, "trials": [], "first_fail": None, "running": 1.5}
    journal.resume = {"name": "trial_F1.5000"}
    with pytest.raises(ValueError, match="trial_F1.5000"):
        factor_of_safety(sim, lower=1.0, upper=2.0, tol=0.1, workers=2, build=planar_slope_scene, journal=journal,
                         trial=trial)
    assert sim.state.step == 0   # nothing ran
    sim.close()


def test_a_checkpoint_of_another_search_is_refused_and_kept(tmp_path):
    """A checkpoint whose finished trials belong to another search (other bracket, or another
    trial rule: a raised ratio) is refused before any step, and left as it was: set aside, the
    search's first checkpoint would replace those trials, hours of them on a fine mesh."""
    from fdem.solve.checkpoint import read_checkpoint
    from fdem.workflow import fos as fos_module
    from fdem.workflow.fos import default_trial_stage, factor_of_safety
    from fdem.workflow.journal import RunJournal

    sim = planar_slope_scene(out_dir=tmp_path, pictures=False).sim
    journal = RunJournal(tmp_path / "checkpoint.npz")
    other = {"lower": 1.0, "upper": 2.0, "tol": 0.1, "trigger": "strength reduction", "trial": "trial",
             "max_time": 1.0, "ratio": 2.8e-4}
    journal.marks[fos_module.TRIALS_MARK] = {"search": other, "trials": [{"factor": 1.5}], "first_fail": None}
    journal.write(sim, "a search under another rule")
    written = (tmp_path / "checkpoint.npz").read_bytes()
    trial = default_trial_stage(sim, max_time=1.0)
    with pytest.raises(ValueError, match="another search") as refused:
        factor_of_safety(sim, lower=1.0, upper=2.0, tol=0.1, trial=trial, journal=journal)
    assert "trial_end" not in str(refused.value)   # the same trial rule: no word of it
    # trials judged at their cap, resumed by a search that follows them (the default since
    # 2026-12-08): the refusal names the setting that gives the search of then
    from fdem.workflow.slope import SlopeWorkflow, runout_stage

    follow = runout_stage(SlopeWorkflow(), 0.1, 10.0, 9.81)
    with pytest.raises(ValueError, match="judged by trial_end 'cap' and this search's would not be: set the "
                                         "workflow's trial_end .* to 'cap'"):
        factor_of_safety(sim, lower=1.0, upper=2.0, tol=0.1, trial=trial, journal=journal, follow=follow)
    assert sim.state.step == 0   # nothing ran
    assert (tmp_path / "checkpoint.npz").read_bytes() == written
    assert read_checkpoint(tmp_path / "checkpoint.npz")["context"]["marks"][fos_module.TRIALS_MARK]["search"] == other
    sim.close()


def test_a_stop_before_a_resumed_stage_is_reached_keeps_that_stage_in_progress(tmp_path):
    """A signal that lands after a resume (or a carry-on) began but before the stage in progress
    is reached stops the run between stages; the state is still the checkpoint's, so the
    checkpoint written then names that stage in progress, and the next resume continues it
    instead of starting it afresh. Once the stage has been taken up, a stop between stages
    names none."""
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.checkpoint import read_checkpoint
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation
    from fdem.workflow.journal import RunJournal

    model = Model(build_topology(structured_rectangle(2, 2, 1.0, 1.0)),
                  ElasticMaterial(young=1e8, poisson=0.25, density=2500.0))
    sim = Simulation(model, progress=False)
    journal = RunJournal(tmp_path / "checkpoint.npz")
    journal.done = [{"name": "equilibrium", "reason": "converged"}]
    journal.resume = {"name": "runout", "t0": 0.0, "step0": 0, "n_total": None}
    journal.write(sim, "interrupted")
    assert read_checkpoint(tmp_path / "checkpoint.npz")["context"]["stage"]["name"] == "runout"
    assert journal.next_stage("equilibrium")[0] == "done" and journal.next_stage("runout")[0] == "resume"
    journal.write(sim, "interrupted")
    assert read_checkpoint(tmp_path / "checkpoint.npz")["context"]["stage"] is None


def test_a_slope_at_rest_but_ringing_ends_its_runout_by_the_drift_rule():
    """Undamped, a slope in equilibrium rings elastically for ever at a kinetic energy that no
    small share of its own small peak bounds: the kinetic-energy rule alone runs such a stage to
    its cap, the drift rule ends it once no node has moved 0.1 mm in one window. A block sliding
    off its joint is never at rest by that rule: it fails first."""
    s = planar_slope_scene()
    sim = s.sim
    T = response_time(sim.model)
    r = run_stage(sim, Stage("equilibrium", max_time=10 * T, converge=Convergence(unbalanced_ratio=1e-4),
                             damping=Damping.quasi_static()), frames=False)
    assert r.reason == "converged"
    start = sim.state_dict()
    sim.state.v[:] += 1e-4  # a little ringing, as a creep leaves behind
    ringing = Convergence(unbalanced_ratio=None, kinetic_ratio=1e-9, min_time=T, hold_for=T)
    r = run_stage(sim, Stage("ringing", max_time=4 * T, converge=ringing), frames=False)
    assert r.reason == "capped"
    sim.load_state_dict(start)
    sim.state.v[:] += 1e-4
    still = Convergence(unbalanced_ratio=None, kinetic_ratio=1e-9, min_time=T, hold_for=T, drift=1e-4, drift_window=T)
    r = run_stage(sim, Stage("still", max_time=4 * T, converge=still), frames=False)
    assert r.reason == "converged" and "no node moved more than" in r.detail
    assert 2 * T <= r.t_end - r.t_start < 4 * T  # min_time, then one whole window
    sim.load_state_dict(start)
    sliding = Stage("sliding", max_time=10 * T, reduction=4.0, converge=still, fail=Failure(displacement=0.02))
    r = run_stage(sim, sliding, frames=False)
    assert r.reason == "failed"
    with pytest.raises(ValueError, match="drift_window"):
        Convergence(drift=1e-3)


def undamped_planar_sim(out_dir=None):
    """The planar slope without its element damping (a viscous force a probe at rest cannot
    see, so a measured step is refused with it), on a simulation of its own."""
    from fdem.solve.simulation import Simulation

    s = planar_slope_scene()
    s.sim.model.set_element_damping(0.0)
    return Simulation(s.sim.model, providers=s.sim.providers, out_dir=out_dir, pictures=False, progress=False)


def cut_at_row(stage, rows, folder):
    """Run ``stage`` on the undamped planar slope with a journal in ``folder`` and stop it as a
    signal would when its ``rows``-th history row is due: its checkpoint is then the stage in
    progress, to resume from."""
    from fdem.workflow.journal import RunJournal

    cut = undamped_planar_sim(out_dir=folder)
    record_row = cut._record_row

    def stop(*a, **k):
        if sum(1 for r in cut.history if r["stage"] == stage.name) >= rows:
            raise KeyboardInterrupt
        return record_row(*a, **k)

    cut._record_row = stop
    with pytest.raises(KeyboardInterrupt):
        run_stage(cut, stage, frames=False, journal=RunJournal(folder / "checkpoint.npz"))
    cut.close()


def test_a_stage_steps_from_the_measured_critical_step_and_a_resume_keeps_it(tmp_path, monkeypatch):
    """``step_from="measured"``: the stage's step is its factor of the critical step measured on
    the model when it starts (above the solver's bound), the result says so, and the next stage
    steps from the bound again; a stage cut by a signal and resumed from its checkpoint keeps the
    step it began with (no second probe) and ends bit for bit as the stage never cut. Settings
    that cannot hold are refused before anything runs."""
    from fdem.solve import step_probe
    from fdem.workflow.journal import RunJournal

    with pytest.raises(ValueError, match="step_from"):
        Stage("x", duration=1.0, step_from="guess")
    with pytest.raises(ValueError, match="damped or density-scaled"):
        Stage("x", duration=1.0, damping=Damping(mass_proportional=1.0), step_from="measured")
    with pytest.raises(ValueError, match="damped or density-scaled"):  # damping lowers the critical step
        Stage("x", duration=1.0, damping=Damping(local=0.8), density_scaling=False, step_from="measured")
    with pytest.raises(ValueError, match="runout_step"):
        SlopeWorkflow(runout_step="guess")
    assert runout_stage(SlopeWorkflow(runout_step="measured"), 1.0, 10.0, 9.81).step_from == "measured"

    sim = undamped_planar_sim()
    T = response_time(sim.model)
    probe = step_probe.measured_critical_dt(sim)
    assert probe.critical_dt > probe.bound_dt
    stage = Stage("runout", duration=0.2 * T, dt_fraction=0.8, step_from="measured")
    whole = run_stage(sim, stage, frames=False)
    assert whole.dt == pytest.approx(0.8 * probe.critical_dt, rel=1e-6)
    assert whole.measured_critical_dt == pytest.approx(probe.critical_dt, rel=1e-6)
    assert sim.measured_critical is None
    after = run_stage(sim, Stage("next", duration=0.005 * T), frames=False)
    assert after.dt == pytest.approx(0.8 * probe.bound_dt) and after.measured_critical_dt is None

    cut_at_row(stage, 3, tmp_path)
    uncut = undamped_planar_sim()
    run_stage(uncut, stage, frames=False)
    resumed = undamped_planar_sim()
    journal = RunJournal.resume_from(resumed, tmp_path / "checkpoint.npz")
    calls = []
    monkeypatch.setattr(step_probe, "measured_critical_dt", lambda *a, **k: calls.append(1))
    end = run_stage(resumed, stage, frames=False, journal=journal)
    assert not calls and end.dt == whole.dt and end.measured_critical_dt == whole.measured_critical_dt
    assert np.array_equal(resumed.state.x, uncut.state.x) and np.array_equal(resumed.state.v, uncut.state.v)


def test_a_measured_step_is_refused_where_the_probe_cannot_see_the_limit_and_falls_back_when_it_fails(monkeypatch):
    """Element damping lowers the critical step and a probe at rest does not see it: the
    workflow refuses ``runout_step = 'measured'`` on such a model before any step, and so does a
    stage. A probe that fails in a run leaves the stage on the bounds, said in its detail."""
    from fdem.solve import step_probe

    sim = planar_slope_scene().sim  # the planar case's triangles carry element damping
    assert sim.use_viscous
    with pytest.raises(ValueError, match="viscous triangles"):
        run_slope_workflow(sim, SlopeWorkflow(runout_step="measured"))
    assert sim.state.step == 0
    T = response_time(sim.model)
    with pytest.raises(ValueError, match="viscous triangles"):
        run_stage(sim, Stage("runout", duration=0.01 * T, step_from="measured"), frames=False)
    assert sim.measured_critical is None and sim.dt_fraction == 0.8

    undamped = undamped_planar_sim()

    def fails(*a, **k):
        raise RuntimeError("ARPACK error -9999")

    monkeypatch.setattr(step_probe, "measured_critical_dt", fails)
    bound, _ = undamped.critical_dt()
    r = run_stage(undamped, Stage("runout", duration=0.01 * T, step_from="measured"), frames=False)
    assert r.dt == pytest.approx(0.8 * bound) and r.measured_critical_dt is None
    assert "step probe failed" in r.detail and "ARPACK" in r.detail


def test_the_cost_estimate_of_a_measured_runout_counts_the_measured_step():
    """The estimate printed before a run prices a runout that steps from the measured critical
    step at that step, not at the bound's (1.26-1.63x more steps on the four slopes), and
    leaves the simulation's step as it found it."""
    import argparse
    import math
    from types import SimpleNamespace

    from fdem.cases.common import report_cost
    from fdem.solve import step_probe

    sim = undamped_planar_sim()
    T = response_time(sim.model)
    probe = step_probe.measured_critical_dt(sim)
    bound, _ = sim.critical_dt()
    dt_before = sim.dt
    args = SimpleNamespace(yes=True, resume=None)
    parser = argparse.ArgumentParser()
    on_bound = report_cost(parser, sim, args, 100 * T, "runout", dt_fraction=0.8)
    measured = report_cost(parser, sim, args, 100 * T, "runout", dt_fraction=0.8, step_from="measured")
    assert on_bound["steps"] == math.ceil(100 * T / (0.8 * bound) - 1e-9)
    assert measured["steps"] == math.ceil(100 * T / (0.8 * probe.critical_dt) - 1e-9)
    assert measured["steps"] < on_bound["steps"] and "measured now" in measured["for"]
    assert sim.dt == dt_before and sim.measured_critical is None and sim.state.step == 0


def test_a_stage_renews_its_measured_step_and_a_resume_probes_on_the_same_steps(tmp_path, monkeypatch):
    """``remeasure_every``: the stage measures its critical step again at that interval of
    simulated time and steps at its factor of the latest measurement, up or down (scripted
    probes: the history's step follows them, and the stage still ends at its end time); with
    the real probe, a stage cut by a signal and resumed from its checkpoint probes on the same
    steps as the uncut stage and ends bit for bit as it."""
    from fdem.solve import step_probe
    from fdem.workflow.journal import RunJournal

    with pytest.raises(ValueError, match="remeasure_every"):
        Stage("x", duration=1.0, remeasure_every=0.1)  # a bound step has nothing to renew
    with pytest.raises(ValueError, match="remeasure_every"):
        Stage("x", duration=1.0, step_from="measured", remeasure_every=-1.0)
    assert runout_stage(SlopeWorkflow(runout_step="measured"), 0.5, 10.0, 9.81).remeasure_every == 0.5
    assert runout_stage(SlopeWorkflow(), 0.5, 10.0, 9.81).remeasure_every is None

    from fdem.workflow.stages import _contact_bound

    sim = undamped_planar_sim()
    T = response_time(sim.model)
    real = step_probe.measured_critical_dt(sim).critical_dt
    contact = _contact_bound(sim)
    assert 1.02 * real < contact < 1.1 * real  # this scene: a rise to 1.1 is above the contact's own bound
    script = [real, 0.9 * real, 1.02 * real, 1.1 * real, 0.95 * real]
    monkeypatch.setattr(step_probe, "critical_or_bounds", lambda s: (script.pop(0), "") if script else (None, "no"))
    stage = Stage("runout", duration=0.2 * T, dt_fraction=0.8, step_from="measured", remeasure_every=0.045 * T)
    r = run_stage(sim, stage, frames=False)
    steps_dt = [row["dt"] for row in sim.history if row["stage"] == "runout"]
    seen = list(dict.fromkeys(steps_dt))  # the steps in the order they were taken
    # a fall taken whole, a rise taken whole up to the contact's bound and held to it above
    assert seen == pytest.approx([0.8 * real, 0.72 * real, 0.816 * real, 0.8 * contact, 0.76 * real], rel=1e-12)
    assert abs(r.t_end - (r.t_start + 0.2 * T)) < r.dt and r.reason == "completed"
    assert "measured 5 times" in r.detail and "1 rise(s) held to the contact's bound" in r.detail
    assert r.measured_critical_dt == pytest.approx(0.95 * real) and sim.measured_critical is None
    monkeypatch.undo()

    stage = Stage("runout", duration=0.2 * T, dt_fraction=0.8, step_from="measured", remeasure_every=0.05 * T)
    cut_at_row(stage, 6, tmp_path)
    calls = []
    probe = step_probe.measured_critical_dt

    def counted(s, *a, **k):
        calls.append(s.state.step)
        return probe(s, *a, **k)

    monkeypatch.setattr(step_probe, "measured_critical_dt", counted)
    uncut = undamped_planar_sim()
    whole = run_stage(uncut, stage, frames=False)
    uncut_calls, calls[:] = list(calls), []
    resumed = undamped_planar_sim()
    journal = RunJournal.resume_from(resumed, tmp_path / "checkpoint.npz")
    end = run_stage(resumed, stage, frames=False, journal=journal)
    assert len(uncut_calls) == 4  # at the start and at 0.05, 0.10 and 0.15 T
    assert calls and calls == uncut_calls[-len(calls):]  # the probes after the cut, on the same steps
    assert end.dt == whole.dt and end.detail == whole.detail
    assert np.array_equal(resumed.state.x, uncut.state.x) and np.array_equal(resumed.state.v, uncut.state.v)


def test_renewals_that_find_the_same_step_keep_the_frames_and_the_end(tmp_path, monkeypatch):
    """A stage renewing a measured step that does not move writes the frames the stage holding
    it writes (one due on a segment's last step included) and ends on the same step."""
    from fdem.solve import step_probe

    real = step_probe.measured_critical_dt(undamped_planar_sim()).critical_dt
    monkeypatch.setattr(step_probe, "critical_or_bounds", lambda s: (real, ""))
    ends, frames = [], []
    for k, every in enumerate((None, 0.05)):
        sim = undamped_planar_sim(out_dir=tmp_path / str(k))
        T = response_time(sim.model)
        stage = Stage("runout", duration=0.2 * T, dt_fraction=0.8, step_from="measured", output_interval=0.05 * T,
                      remeasure_every=None if every is None else every * T)
        r = run_stage(sim, stage, frames=True)
        ends.append((r.steps, r.dt))
        frames.append(sorted(f.name for f in (tmp_path / str(k)).glob("*.vtu")))
        sim.close()
    assert ends[0] == ends[1] and frames[0] == frames[1] and len(frames[0]) >= 5


def test_a_capped_stage_renewing_its_measured_step_is_carried_on_to_the_rows_of_one_never_capped(tmp_path):
    """A stage capped while renewing a measured step, carried on to a longer cap
    (:meth:`fdem.workflow.journal.RunJournal.carry_on`), ends with the rows and the state of the
    stage given the longer cap at once: the row the cap added is dropped by what the stage
    recorded of it, not guessed from the spacing of the last rows, which a renewal's own row
    (a segment's end) upsets (here rows on steps 210, 212 and the cap's 229)."""
    from fdem.workflow.journal import RunJournal

    T = response_time(undamped_planar_sim().model)

    def stage(cap: float) -> Stage:  # a rule that never holds: the stage runs to its cap
        return Stage("runout", max_time=cap * T, converge=Convergence(speed=1e-300), dt_fraction=0.8,
                     step_from="measured", remeasure_every=0.05 * T)

    capped = undamped_planar_sim(out_dir=tmp_path)
    first = run_stage(capped, stage(0.162), frames=False, journal=RunJournal(tmp_path / "checkpoint.npz"))
    cap_rows = [int(r["step"]) for r in capped.history if r["stage"] == "runout"]
    assert first.reason == "capped" and "measured 4 times" in first.detail  # at the start, 0.05, 0.10, 0.15 T
    assert cap_rows[-3:] == [210, 212, 229]  # a row on the history steps, a renewal's, the cap's
    carried = undamped_planar_sim()
    journal = RunJournal.resume_from(carried, tmp_path / "checkpoint.npz")
    journal.carry_on(carried, "runout", lambda: None)
    end = run_stage(carried, stage(0.2), frames=False, journal=journal)
    whole_sim = undamped_planar_sim()
    whole = run_stage(whole_sim, stage(0.2), frames=False)
    rows = lambda s: [(int(r["step"]), r["dt"], r["kinetic"]) for r in s.history if r["stage"] == "runout"]  # noqa: E731
    assert rows(carried) == rows(whole_sim) and 229 not in [r[0] for r in rows(whole_sim)]
    assert end.steps == whole.steps and end.dt == whole.dt and end.detail == whole.detail
    assert np.array_equal(carried.state.x, whole_sim.state.x) and np.array_equal(carried.state.v, whole_sim.state.v)


@pytest.mark.parametrize("damping", [NO_DAMPING, Damping(mass_proportional=5.0, local=0.1)])
def test_a_step_that_books_the_ledger_moves_the_nodes_as_one_that_does_not(damping):
    """The fast step (no state energies) and the step of a history row are two loops over the
    same node update: they add the element, interaction and gravity forces in one order, so a
    run's state does not depend on where its history rows fall, to the last bit (a runout
    carried on past its cap, or resumed with other history steps, ends as the run that was not)."""
    sims = [undamped_planar_sim(), undamped_planar_sim()]
    for n in range(40):
        for booked, sim in zip((True, n % 7 == 0), sims):
            sim.step(damping, ledger=booked)
    a, b = sims
    assert np.abs(a.state.v).max() > 0 and np.any(a.f_interaction != 0.0)  # moving, the crack elements loaded
    assert np.array_equal(a.state.x, b.state.x) and np.array_equal(a.state.v, b.state.v)
