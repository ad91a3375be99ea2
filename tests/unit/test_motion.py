"""When each part of a failed mass moved (fdem.results.motion), crack elements by tag, the
``crept`` outcome, and a monitor's record kept across a checkpoint.

Kinematics with known answers: blocks of an exploded structured mesh moved rigidly, row by row,
one of them stopping early while the other runs on."""
import numpy as np
import pytest

from fdem.mesh.mesh import structured_rectangle
from fdem.mesh.topology import build_topology
from fdem.results.analysis import crack_breakdown
from fdem.results.motion import MotionRecord
from fdem.workflow.slope import _tell_creep, factor_of_safety_figures
from fdem.workflow.stages import StageResult

TOPO = build_topology(structured_rectangle(20, 4, 20.0, 4.0))  # 1 m cells, 160 triangles of 0.5 m^2
C0 = TOPO.x0[TOPO.triangles].mean(axis=1)
JAMMED = C0[:, 0] < 4.0  # 16 m^2: moves 0.5 m, then stops
RUNNER = C0[:, 0] > 4.0  # 64 m^2, beside the jammed block: runs 8 m
FAR_RUNNER = C0[:, 0] > 12.0  # 32 m^2, unmoved rock between it and the jammed block


class Rows:
    """A stand-in simulation: positions set row by row, the stage named per row."""

    def __init__(self):
        self.state = type("S", (), {})()
        self.state.x, self.state.time, self.state.step = TOPO.x0.copy(), 0.0, 0
        self.stage = "runout"

    def move(self, which, dx, t):
        self.state.x[TOPO.triangles[which].ravel()] += [dx, 0.0]
        self.state.time, self.state.step = t, self.state.step + 100


def run_rows(record, sim=None, runner=RUNNER):
    sim = sim or Rows()
    record(sim)  # the first row anchors
    for k in range(1, 5):  # 0.125 m per row for both: the jammed block stops at 0.5 m (t = 0.4 s)
        sim.move(JAMMED | runner, 0.125, 0.1 * k)
        record(sim)
    for k in range(5, 20):  # the runner alone, 0.5 m per row, to 8 m
        sim.move(runner, 0.5, 0.1 * k)
        record(sim)
    return sim


def test_a_block_that_stops_while_the_mass_runs_on_is_locked_and_one_that_runs_is_not():
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = run_rows(rec)
    got = rec.locked(sim.state.x)
    assert np.array_equal(got["mask"], JAMMED)
    assert got["area_m2"] == pytest.approx(16.0)
    assert got["share_of_failed"] == pytest.approx(16.0 / 80.0)
    assert got["mean_displacement_m"] == pytest.approx(0.5)
    assert got["stopped_s"] == pytest.approx([0.4, 0.4])  # the row it last travelled 2.5 cm
    assert got["d90_m"] == pytest.approx(8.0)
    assert got["stopped_apart_m2"] == 0.0


def test_a_slab_that_stopped_apart_from_the_running_mass_is_not_locked():
    # the same motion, with 8 m of unmoved rock between the block that stopped and the runner:
    # a slab slipping and stopping beside a roller, not a block jammed in the failing mass
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = run_rows(rec, runner=FAR_RUNNER)
    got = rec.locked(sim.state.x)
    assert got["n_triangles"] == 0 and got["area_m2"] == 0.0
    assert got["stopped_apart_m2"] == pytest.approx(16.0) and got["stopped_apart_triangles"] == int(JAMMED.sum())
    assert got["failed_area_m2"] == pytest.approx(48.0)


def test_ground_dragged_by_the_mass_without_moving_with_it_is_not_locked():
    # the block beside the runner moves 0.25 m in two rows while the runner moves 2 m, then
    # stops: ground settling behind a collapsing face (an eighth of the mass's D90 when it
    # stopped), not a block carried by the mass and jammed
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = Rows()
    rec(sim)
    for k in (1, 2):
        sim.move(JAMMED, 0.125, 0.1 * k)
        sim.move(RUNNER, 1.0, 0.1 * k)
        rec(sim)
    for k in range(3, 9):
        sim.move(RUNNER, 1.0, 0.1 * k)
        rec(sim)
    got = rec.locked(sim.state.x)
    assert got["d90_m"] == pytest.approx(8.0)
    assert got["n_triangles"] == 0 and got["stopped_apart_m2"] == 0.0
    assert got["dragged_m2"] == pytest.approx(16.0) and got["dragged_triangles"] == int(JAMMED.sum())
    # carried: the same block moving with the runner (1 m per row) for the two rows is locked
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = Rows()
    rec(sim)
    for k in (1, 2):
        sim.move(JAMMED | RUNNER, 1.0, 0.1 * k)
        rec(sim)
    for k in range(3, 10):
        sim.move(RUNNER, 1.0, 0.1 * k)
        rec(sim)
    got = rec.locked(sim.state.x)
    assert np.array_equal(got["mask"], JAMMED) and got["dragged_m2"] == 0.0


def test_a_mass_that_moves_together_has_no_locked_part():
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = Rows()
    rec(sim)
    for k in range(1, 20):
        sim.move(JAMMED | RUNNER, 0.4, 0.1 * k)
        rec(sim)
    assert rec.locked(sim.state.x)["n_triangles"] == 0


def test_ringing_below_the_move_distance_is_no_motion():
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = run_rows(rec)
    for k in range(20, 40):  # the jammed block rings by +-1 cm (under 2.5 cm): still stopped at 0.4 s
        sim.move(JAMMED, 0.01 * (-1) ** k, 0.1 * k)
        rec(sim)
    assert rec.locked(sim.state.x)["stopped_s"] == pytest.approx([0.4, 0.4])


def test_rows_of_trials_book_no_motion():
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = Rows()
    rec(sim)
    sim.stage = "trial_F1.5000"
    sim.move(JAMMED, 3.0, 0.1)
    rec(sim)
    assert np.all(np.isnan(rec.moved_time)) and rec.snapshots == []


def test_mid_failure_is_the_snapshot_nearest_half_the_final_spread():
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = run_rows(rec)
    assert 1 <= len(rec.snapshots) <= 5  # those under a quarter of the present D90 are dropped
    mid = rec.mid_failure(8.0)
    ratios = [s["d90"] / 4.0 for s in rec.snapshots]
    assert abs(np.log(mid["d90"] / 4.0)) == pytest.approx(min(abs(np.log(r)) for r in ratios))
    assert 4.0 / np.sqrt(2) <= mid["d90"] <= 4.0 * np.sqrt(2)
    # the snapshot holds the positions of its row
    d = np.linalg.norm(mid["x"][TOPO.triangles].mean(axis=1) - C0, axis=1)
    assert d[RUNNER].max() == pytest.approx(mid["d90"], rel=1e-6)


def test_mid_failure_is_the_failure_the_run_ended_in_after_the_reduction_carried_on():
    """A block falls 9 m off the face and comes to rest; the reduction carries on, and the mass
    beside it then runs 16 m. The mid-failure snapshot and its D90 are the second failure's,
    measured from the state the reduction carried on from; until the mass moves they are the
    block's (a slope that stands after a local fall keeps its picture); the locked part still
    reads the whole run's displacement."""
    block, mass = C0[:, 0] < 2.0, C0[:, 0] > 4.0  # 8 m^2 and 64 m^2, rock between them
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = Rows()
    rec(sim)
    for k in range(1, 10):  # the block, 1 m a row, to 9 m
        sim.move(block, 1.0, 0.1 * k)
        rec(sim)
    first = [s["d90"] for s in rec.snapshots]
    assert max(first) >= 9.0 / np.sqrt(2)  # the ladder of sqrt(2) levels
    # saved at the runout's end by a version that did not keep the last stage: read from the history
    state = rec.state_dict()
    del state["last_stage"]
    old = MotionRecord(TOPO, threshold=0.1)
    old.load_state_dict(state)
    sim.stage, sim.history = "reduction_F2.000", [{"stage": "runout"}]
    for record in (rec, old):  # carried on from rest: until something moves, the block's fall stays the picture
        record(sim)
        assert record.pending_origin is not None and record.d90(sim.state.x) == pytest.approx(9.0)
        assert record.mid_failure(record.d90(sim.state.x))["time"] < 1.0  # a snapshot of the fall
    sim.stage = "runout_F2.000"
    for k in range(1, 17):  # the mass, 1 m a row, to 16 m
        sim.move(mass, 1.0, 1.0 + 0.1 * k)
        rec(sim)
    final = rec.d90(sim.state.x)
    assert final == pytest.approx(16.0)  # the block has not moved since: not part of it
    mid = rec.mid_failure(final)
    assert 8.0 / np.sqrt(2) <= mid["d90"] <= 8.0 * np.sqrt(2) and mid["time"] > 1.0
    d = np.linalg.norm(mid["x"][TOPO.triangles].mean(axis=1) - C0, axis=1)
    assert d[block].min() == pytest.approx(9.0) and d[mass].max() == pytest.approx(mid["d90"])
    assert rec.locked(sim.state.x)["failed_area_m2"] == pytest.approx(72.0)  # the whole run's
    assert rec.pending_origin is None  # the mass moved: the snapshots are the second failure's
    again = MotionRecord(TOPO, threshold=0.1)  # kept with a checkpoint
    again.load_state_dict(rec.state_dict())
    assert again.d90(sim.state.x) == pytest.approx(16.0) and again.last_stage == "runout_F2.000"


def test_the_record_survives_its_state_dict():
    rec = MotionRecord(TOPO, threshold=0.1)
    sim = run_rows(rec)
    again = MotionRecord(TOPO, threshold=0.1)
    again.load_state_dict(rec.state_dict())
    assert np.array_equal(again.locked(sim.state.x)["mask"], JAMMED)
    assert len(again.snapshots) == len(rec.snapshots)
    with pytest.raises(ValueError, match="triangles"):
        MotionRecord(build_topology(structured_rectangle(2, 2, 2.0, 2.0))).load_state_dict(rec.state_dict())


def test_bad_settings_are_refused():
    for kw in ({"threshold": 0.0}, {"move_distance": -1.0}, {"locked_share": 1.0}, {"with_mass_share": 1.5}):
        with pytest.raises(ValueError):
            MotionRecord(TOPO, **kw)


def test_crack_breakdown_splits_rock_from_joints_and_activated_from_broken():
    tag = np.array([0, 0, 0, 1, 1, 2])
    broken = np.array([1, 0, 0, 1, 0, 0], bool)
    mode = np.array([1, 0, 0, 2, 0, 0])
    out = crack_breakdown(tag, np.array([0, 1, 3, 4]), broken, mode)  # ids: 0 and 3 are broken, 1 and 4 not
    assert out["rock"] == {"n_elements": 3, "activated": 1, "broken": 1, "broken_by_mode": {"I": 1, "II": 0, "mixed": 0}}
    assert out["joints"]["n_elements"] == 3 and out["joints"]["activated"] == 1 and out["joints"]["broken"] == 1
    assert out["joints"]["broken_by_mode"]["II"] == 1
    assert out["by_tag"]["2"]["activated"] == 0
    with pytest.raises(ValueError, match="broken"):
        crack_breakdown(tag, np.zeros(6, bool), broken[:3], mode)


def stage(name, reason, max_displacement, reduction):
    return StageResult(name=name, reason=reason, t_start=0.0, t_end=1.0, steps=10, wall_seconds=0.1, dt=1e-5,
                       reduction=reduction, unbalanced_ratio=0.0, kinetic_energy=0.0, peak_kinetic_energy=0.0,
                       max_speed=0.0, max_displacement=max_displacement, n_broken=0, detail="")


@pytest.mark.parametrize("failing, runout, outcome", [
    (("capped", 0.03), ("converged", 0.006), "crept"),  # 3.6 cm in all, at rest: the high-angle coarse slope
    (("capped", 0.03), ("converged", 0.5), "failed"),  # ran on in the runout
    # still moving when the runout's cap came, 3.6 cm in all: neither a collapse nor a rest
    (("capped", 0.03), ("capped", 0.006), "undecided"),
    (("capped", 0.03), ("capped", 0.5), "failed"),  # ran on past the failure displacement before the cap
    (("failed", 0.3), ("converged", 0.0), "failed"),  # the failing stage itself moved 1 % of the height
])
def test_a_slope_that_crept_and_stopped_is_told_from_one_that_failed(failing, runout, outcome):
    stages = [stage("equilibrium", "converged", 1e-3, 1.0), stage("reduction_F1.667", "converged", 1e-3, 1.667),
              stage("reduction_F2.000", failing[0], failing[1], 2.0)]
    summary = {"stages": [s.as_dict() for s in stages], "fos": None, "failed_at_factor": 2.0, "outcome": "failed"}
    result = stage("runout", runout[0], runout[1], 2.0)
    summary["stages"].append(result.as_dict())
    _tell_creep(summary, result, fail_displacement=0.3)
    assert summary["outcome"] == outcome
    fos = factor_of_safety_figures(summary)
    if outcome == "crept":
        assert summary["crept_at_factor"] == 2.0 and summary["failed_at_factor"] is None
        assert summary["crept_m"] == pytest.approx(0.036)
        assert fos["fos_bracket"] == [2.0, None] and fos["fos"] is None  # it stands at 2.0
    else:
        assert fos["fos_bracket"] == [1.667, 2.0]   # not settled at 2.0: the bracket's upper end
    if outcome == "undecided":
        assert summary["failed_at_factor"] == 2.0 and "undecided" in summary["ending"]
        assert "0.036 m" in summary["ending"] and "longer runout cap" in summary["ending"]


def scripted_workflow(monkeypatch, fake_run_stage, sim, wf, journal=None, step_time=5.0) -> dict:
    """The workflow's reduction steps with ``fake_run_stage`` in place of the solver (its
    equilibrium undamped): the summary of :func:`fdem.workflow.slope._run_stages`."""
    import types

    from fdem.workflow import slope

    monkeypatch.setattr(slope, "run_stage", fake_run_stage)
    monkeypatch.setattr(slope, "equilibrium_damping", lambda sim: slope.NO_DAMPING)
    cracks = types.SimpleNamespace(hold_elastic=lambda held: None)
    summary = {"stages": [], "fos": None, "failed_at_factor": None}

    def record(result):
        summary["stages"].append(result.as_dict())
        return result

    rules = slope.StageRules(T=1.0, height=10.0, g=9.81, step_time=step_time, fail=slope.Failure(displacement=0.3),
                             damped=slope.NO_DAMPING,
                             converge=slope.Convergence(unbalanced_ratio=wf.equilibrium_ratio, hold_for=wf.equilibrium_hold))
    slope._run_stages(sim, wf, summary, record, cracks, rules, None, journal)
    return summary


@pytest.mark.parametrize("step_time, equilibrium_cap", [(2.0, 10.0), (5.0, 10.0), (8.0, 16.0)])
def test_shorter_trials_do_not_shorten_the_equilibrium(monkeypatch, step_time, equilibrium_cap):
    """The equilibrium at F = 1 is capped at twice the stage cap, and never under twice 5
    response times (T = 1 s here): trials of 2.5 T on the high-angle coarse four-slope scene at
    2.0 m capped its equilibrium at 5 T, which it needs 5.3 T to meet, and the run called a slope
    moving at 8e-5 m/s failed at F = 1."""
    import types

    from fdem.workflow import slope

    caps = {}

    def fake_run_stage(sim, st, journal=None):
        caps[st.name] = st.max_time
        return stage(st.name, "converged", 1e-3, st.reduction if st.reduction is not None else 0.0)

    scripted_workflow(monkeypatch, fake_run_stage, types.SimpleNamespace(time_capped=False),
                      slope.SlopeWorkflow(factors=(1.25,)), step_time=step_time)
    assert caps == {"equilibrium": equilibrium_cap, "reduction_F1.250": step_time}


@pytest.mark.parametrize("script, outcome, bracket, names", [
    # creeps at 1.5 and comes to rest; the steps carry on and it fails at 2.0
    ({"reduction_F1.500": ("capped", 0.03), "runout": ("converged", 0.006),
      "reduction_F2.000": ("capped", 0.03), "runout_F2.000": ("converged", 0.5)},
     "failed", [1.5, 2.0], ["equilibrium", "reduction_F1.250", "reduction_F1.500", "runout", "reduction_F2.000",
                            "runout_F2.000"]),
    # creeps at 1.5 and at 2.0 and stands at the end of the schedule
    ({"reduction_F1.500": ("capped", 0.03), "runout": ("converged", 0.006),
      "reduction_F2.000": ("capped", 0.03), "runout_F2.000": ("converged", 0.002)},
     "crept", [2.0, None], ["equilibrium", "reduction_F1.250", "reduction_F1.500", "runout", "reduction_F2.000",
                            "runout_F2.000"]),
    # does not settle at 1.5 and its runout is capped still moving: undecided, no carrying on
    ({"reduction_F1.500": ("capped", 0.03), "runout": ("capped", 0.006)},
     "undecided", [1.25, 1.5], ["equilibrium", "reduction_F1.250", "reduction_F1.500", "runout"]),
    # a node moves the failure displacement at 1.5: the runout follows, no carrying on
    ({"reduction_F1.500": ("failed", 0.3), "runout": ("converged", 0.006)},
     "failed", [1.25, 1.5], ["equilibrium", "reduction_F1.250", "reduction_F1.500", "runout"]),
])
def test_the_reduction_steps_carry_on_after_a_creep(monkeypatch, script, outcome, bracket, names):
    """The workflow's control flow with scripted stage endings (every stage not in ``script``
    converges with 1 mm): a slope that crept and came to rest at one factor is reduced further
    from its resting state, each undamped stage named so that a resumed run replays it."""
    import types

    from fdem.workflow import slope

    def fake_run_stage(sim, st, journal=None):
        reason, moved = script.get(st.name, ("converged", 1e-3))
        return stage(st.name, reason, moved, st.reduction if st.reduction is not None else 0.0)

    summary = scripted_workflow(monkeypatch, fake_run_stage, types.SimpleNamespace(time_capped=False),
                                slope.SlopeWorkflow(factors=(1.25, 1.5, 2.0)))
    assert [st["name"] for st in summary["stages"]] == names
    assert summary["outcome"] == outcome
    assert factor_of_safety_figures(summary)["fos_bracket"] == bracket
    if len(names) > 4:
        assert 1.5 in summary["crept_at_factors"]



@pytest.mark.parametrize("reduction", ["none", "steps"])
@pytest.mark.parametrize("stable_at_upper", [True, False])
def test_a_bracket_its_ends_contradict_is_a_result_not_a_crash(monkeypatch, reduction, stable_at_upper):
    """A search whose upper factor still stands (or whose lower one already fails) ends with the
    side the factor lies beyond and the message, after two trials of perhaps hours: kept in the
    summary, and the schedule after the search runs as it would have."""
    import types

    from fdem.workflow import slope
    from fdem.workflow.fos import BracketError, Trial

    def fake_search(sim, lower, upper, tol, out_dir=None, journal=None, trial=None, follow=None):
        # the search judges its trials by the workflow's rule: its stage cap and failure displacement,
        # a capped trial followed to rest (trial_end unset: "rest" for a strength search), undamped
        # up to the runout's cap (20 T here)
        assert (trial.max_time, trial.fail.displacement, trial.converge.unbalanced_ratio) == (5.0, 0.3, 1e-4)
        assert follow is not None and follow.name == "runout" and follow.max_time == 20.0
        assert follow.damping == slope.NO_DAMPING
        trial = Trial(factor=upper if stable_at_upper else lower, stable=stable_at_upper,
                      result=stage("trial", "converged" if stable_at_upper else "capped", 1e-3, 0.0))
        raise BracketError("factor_of_safety: the slope is still stable at the upper factor F = 2; raise the bracket"
                           if stable_at_upper else "factor_of_safety: the slope already fails at the lower factor "
                                                   "F = 1.5; lower the bracket", trial)

    monkeypatch.setattr(slope, "factor_of_safety", fake_search)

    def fake_run_stage(sim, st, journal=None):
        return stage(st.name, "converged", 1e-3, st.reduction if st.reduction is not None else 0.0)

    wf = slope.SlopeWorkflow(factors=(1.25, 1.5), fos=(1.5, 2.0, 0.1), reduction=reduction)
    summary = scripted_workflow(monkeypatch, fake_run_stage, types.SimpleNamespace(time_capped=False), wf)
    assert summary["fos"]["fos"] is None
    assert summary["fos"]["bracket"] == ([2.0, None] if stable_at_upper else [None, 1.5])
    figures = factor_of_safety_figures(summary)
    if reduction == "none":
        assert summary["outcome"] == "searched" and "bracket" in summary["ending"]
        assert [st["name"] for st in summary["stages"]] == ["equilibrium"]
        assert figures == {"fos": None, "fos_bracket": summary["fos"]["bracket"], "fos_method": "bisection"}
    else:  # the steps went on and stood at both factors: their bracket is the figure
        assert summary["outcome"] == "stable"
        assert [st["name"] for st in summary["stages"]] == ["equilibrium", "reduction_F1.250", "reduction_F1.500"]
        assert figures["fos_method"] == "reduction steps" and figures["fos_bracket"] == [1.5, None]


def test_a_search_alone_runs_no_runout_and_a_capped_trial_gives_no_verdict(monkeypatch):
    """With reduction 'none' a slope that does not settle at F = 1 has no factor above 1 to search
    and gets no runout; a search whose trial the run's --max-time stopped ends time_capped,
    not with a bracket or an error it did not find."""
    import types

    from fdem.workflow import slope
    from fdem.workflow.fos import BracketError, Trial

    wf = slope.SlopeWorkflow(fos=(1.0, 2.0, 0.1), reduction="none")
    summary = scripted_workflow(monkeypatch, lambda sim, st, journal=None: stage(st.name, "failed", 0.5, 1.0),
                                types.SimpleNamespace(time_capped=False), wf)
    assert [st["name"] for st in summary["stages"]] == ["equilibrium"]
    assert summary["outcome"] == "failed" and summary["failed_at_factor"] == 1.0
    assert "no runout" in summary["ending"]

    def converged(sim, st, journal=None):
        return stage(st.name, "converged", 1e-3, st.reduction if st.reduction is not None else 0.0)

    capped = Trial(factor=1.0, stable=False, result=stage("trial", "capped", 1e-3, 0.0), time_capped=True)

    def cut_by_the_cap(sim, lower, upper, tol, out_dir=None, journal=None, trial=None, follow=None):
        raise BracketError("factor_of_safety: the slope already fails at the lower factor F = 1", capped)

    for reduction in ("none", "steps"):
        monkeypatch.setattr(slope, "factor_of_safety", cut_by_the_cap)
        summary = scripted_workflow(monkeypatch, converged, types.SimpleNamespace(time_capped=True),
                                    slope.SlopeWorkflow(factors=(1.25,), fos=(1.0, 2.0, 0.1), reduction=reduction))
        assert summary["outcome"] == "time_capped" and summary["fos"]["time_capped"]
        assert [st["name"] for st in summary["stages"]] == ["equilibrium"]


@pytest.mark.parametrize("falls, area_limit, outcome, bracket, stood", [
    # a block of 0.5 m^2 falls at 1.5 and comes to rest: the steps carry on, the slope stands at 2.0
    ({"runout": (3, 2.0)}, 1.2, "stable", [2.0, None], [1.5]),
    # a second block at 2.0 brings the fallen area to 1.0 m^2, under 1.2: both local
    ({"runout": (3, 2.0), "runout_F2.000": (7, 5.0)}, 1.2, "stable", [2.0, None], [1.5, 2.0]),
    # under a limit of 0.8 m^2 the two blocks together are the slope's failure, at 2.0
    ({"runout": (3, 2.0), "runout_F2.000": (7, 5.0)}, 0.8, "failed", [1.5, 2.0], [1.5]),
    # without a limit any fall ends the reduction (the default)
    ({"runout": (3, 2.0)}, None, "failed", [1.25, 1.5], []),
])
def test_the_reduction_steps_carry_on_after_a_local_fall(monkeypatch, falls, area_limit, outcome, bracket, stood):
    """A runout that came to rest with less than ``local_fall_area`` moved the failure
    displacement (every fall so far together) lost a block off the face, not the slope: the
    reduction carries on from its resting state and the bracket counts the factor as standing.
    Each failing stage moves a node 0.3 m; its runout moves one 0.5 m^2 triangle by the metres
    given (``falls``: stage -> (triangle, metres))."""
    import types

    from fdem.workflow import slope

    from fdem.workflow.journal import RunJournal

    x = TOPO.x0.copy()

    def fake_run_stage(sim, st, journal=None):
        kind, saved = journal.next_stage(st.name) if journal is not None else ("fresh", None)
        if kind == "done":  # a replay: the state is the checkpoint's, the result the recorded one
            return StageResult(**saved)
        if st.name in falls:
            tri, metres = falls[st.name]
            x[TOPO.triangles[tri]] += [-metres, 0.0]
        if st.name.startswith("reduction") and f"runout{'' if st.reduction == 1.5 else f'_F{st.reduction:.3f}'}" in falls:
            result = stage(st.name, "failed", 0.3, st.reduction)
        elif st.name in falls:
            result = stage(st.name, "converged", falls[st.name][1], 0.0)
        else:
            result = stage(st.name, "converged", 1e-3, st.reduction if st.reduction is not None else 0.0)
        if journal is not None:
            journal.stage_finished(sim, result.as_dict())
        return result

    sim = types.SimpleNamespace(time_capped=False, model=types.SimpleNamespace(topology=TOPO),
                                state=types.SimpleNamespace(x=x))
    wf = slope.SlopeWorkflow(factors=(1.25, 1.5, 2.0), local_fall_area=area_limit)

    def run(journal):
        return scripted_workflow(monkeypatch, fake_run_stage, sim, wf, journal)

    journal = RunJournal()
    summary = run(journal)
    # resumed from the end state (every stage replayed, the state the last one's): the same
    # verdicts and figures, each fall's area the one measured when its runout came to rest
    again = RunJournal()
    again.done, again.marks = list(journal.done), dict(journal.marks)
    replayed = run(again)
    assert (replayed["outcome"], replayed.get("local_falls")) == (summary["outcome"], summary.get("local_falls"))
    if stood:  # a journal that holds no measure (written before it was kept) still carries on past a fall
        blind = RunJournal()
        blind.done = list(journal.done)
        assert run(blind)["outcome"] == outcome
    assert summary["outcome"] == outcome
    assert factor_of_safety_figures(summary)["fos_bracket"] == bracket
    assert [fall["factor"] for fall in summary.get("local_falls", [])] == stood
    if stood:
        assert summary["local_falls"][0]["area_m2"] == pytest.approx(0.5)
        assert summary["local_falls"][0]["max_displacement_m"] == pytest.approx(2.0)   # the runout's own
    if outcome == "stable":
        assert "a local fall at F = " in summary["ending"] and "stood at every factor to F = 2" in summary["ending"]
    with pytest.raises(ValueError, match="local_fall_area"):
        slope.SlopeWorkflow(local_fall_area=-1.0)
    with pytest.raises(ValueError, match="local_fall_area carries the reduction steps on"):
        slope.SlopeWorkflow(reduction="rate", local_fall_area=10.0)
    # the run's printed line, an area unrecorded by an older journal included
    from fdem.cases.four_slopes import local_fall_line

    for fall in summary.get("local_falls", []) + [{"factor": 1.5, "area_m2": None, "max_displacement_m": 2.0,
                                                   "at_rest_s": 1.0}]:
        line = local_fall_line(fall)
        assert line.startswith(f"local fall at F = {fall['factor']:.3f}: ")
        assert ("an unrecorded area" in line) == (fall["area_m2"] is None)


def thrown_block(out_dir=None):
    """The checkpoint tests' 6 x 6 block thrown sideways, with a motion record of millimetres."""
    from fdem.mesh.topology import build_topology as topology
    from fdem.physics.crack_properties import CrackProperties
    from fdem.physics.cracks import CrackSet
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    topo = topology(structured_rectangle(6, 6, 0.6, 0.6))
    model = Model(topo, ElasticMaterial(young=1e9, poisson=0.25, density=2500.0))
    model.fix("bottom")
    model.set_initial_velocity(vx=3.0, vy=0.0, where=np.flatnonzero(topo.x0[:, 1] > 0.35))
    cracks = CrackSet(topo, {0: CrackProperties(f_t=2e5, c=4e5, phi=30.0, G_I=5.0, G_II=20.0, p_n=1e10)},
                      parallel_min=0)
    sim = Simulation(model, providers=[cracks], progress=False, out_dir=out_dir)
    record = MotionRecord(topo, cracks, threshold=1e-4, move_distance=2e-5)
    sim.add_monitor("failed_d90", record)
    return sim, record


def test_a_monitors_record_is_saved_with_a_checkpoint_and_a_new_monitor_gets_its_history_column(tmp_path):
    from fdem.io.history import read_history
    from fdem.solve.checkpoint import load_checkpoint, save_checkpoint

    sim, record = thrown_block(tmp_path)
    sim.run(n_steps=60, history_every=10, energy_tolerance=None, stage="runout")
    assert np.isfinite(record.moved_time).any() and record.snapshots  # it moved and the ladder took snapshots
    save_checkpoint(sim, tmp_path / "checkpoint.npz")
    at_checkpoint = record.state_dict()
    sim.run(n_steps=40, history_every=10, energy_tolerance=None, stage="runout")
    sim.close()

    again, rec2 = thrown_block(tmp_path)
    again.add_monitor("extra", lambda s: 1.0)  # a monitor the checkpoint's run did not have
    load_checkpoint(again, tmp_path / "checkpoint.npz")
    again.continue_outputs()
    assert np.array_equal(rec2.moved_time, at_checkpoint["moved_time"], equal_nan=True)
    assert np.array_equal(rec2.anchor, at_checkpoint["anchor"])
    again.run(n_steps=40, history_every=10, energy_tolerance=None, stage="runout")
    again.close()
    # the resumed record is the uninterrupted one's
    assert np.array_equal(rec2.moved_time, record.moved_time)
    assert np.array_equal(rec2.moved_d90, record.moved_d90)
    assert [s["step"] for s in rec2.snapshots] == [s["step"] for s in record.snapshots]
    h = read_history(tmp_path / "history.csv")
    assert np.isnan(h["extra"][:7]).all() and np.all(h["extra"][7:] == 1.0)  # rows before the column: empty
    assert np.all(np.diff(h["step"]) > 0)


def test_the_history_file_is_never_truncated_by_a_row_after_close(tmp_path):
    from fdem.io.history import HistoryWriter, read_history

    w = HistoryWriter(tmp_path / "h.csv")
    for k in range(3):
        w.write({"step": k, "time": 0.1 * k})
    w.close()
    for k in range(3, 5):
        w.write({"step": k, "time": 0.1 * k})
    w.close()
    assert list(read_history(tmp_path / "h.csv")["step"]) == [0, 1, 2, 3, 4]


def test_an_element_is_activated_only_once_it_has_slipped_or_opened_a_millimetre():
    """crack_status: broken > activated (inelastic, and its faces 1 mm or more apart along or across
    the element) > intact; an inelastic element that yielded by micrometres stays intact."""
    from fdem.results.motion import ACTIVATED, BROKEN, INTACT, crack_status

    cn = TOPO.crack_nodes
    e, used = [], set()  # five elements of which no two share a triangle, so each is moved alone
    for c in range(TOPO.n_cracks):
        tris = set(TOPO.crack_triangles[c])
        if not tris & used:
            e.append(c)
            used |= tris
        if len(e) == 5:
            break

    class Cracks:
        nodes = cn
        broken = np.zeros(TOPO.n_cracks, bool)

        def inelastic(self):
            return np.array(e[:4])

    cracks = Cracks()
    cracks.broken[e[3]] = True
    x = TOPO.x0.copy()
    t = x[cn[:, 1]] - x[cn[:, 0]]
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    x[cn[e[0], 2:]] += 2e-3 * t[e[0]]                                      # slipped 2 mm
    x[cn[e[1], 2:]] += 2e-3 * np.array([t[e[1], 1], -t[e[1], 0]])          # opened 2 mm
    x[cn[e[2], 2:]] += 2e-6 * t[e[2]]                                      # yielded by micrometres
    x[cn[e[4], 2:]] += 5e-3 * t[e[4]]                                      # moved, but elastic
    assert list(crack_status(cracks, x)[e]) == [ACTIVATED, ACTIVATED, INTACT, BROKEN, INTACT]
    assert list(crack_status(cracks)[e]) == [ACTIVATED, ACTIVATED, ACTIVATED, BROKEN, INTACT]  # no positions


def test_periodic_checkpoint_interval_runs_from_the_end_of_the_last_write(monkeypatch, tmp_path):
    """A write that takes longer than the interval (a large model, a loaded machine) must not make
    every later tick write again: with writes of 2 s (a fake clock), an interval of 1 s and ticks
    0.5 s of stepping apart, a write comes every second tick (1 s of stepping after the last
    write ended), 12 in 24 ticks; timed from the start of the write, every tick after the first
    write would write (23)."""
    import types

    import fdem.solve.checkpoint as checkpoint
    from fdem.workflow import journal as journal_module

    clock = [0.0]
    monkeypatch.setattr(journal_module.time, "monotonic", lambda: clock[0])

    def slow_save(sim, path, context=None):
        clock[0] += 2.0

    monkeypatch.setattr(checkpoint, "save_checkpoint", slow_save)
    j = journal_module.RunJournal(tmp_path / "checkpoint.npz", every_seconds=1.0)
    sim = types.SimpleNamespace(state=types.SimpleNamespace(step=0))
    for _ in range(24):
        clock[0] += 0.5   # half a second of stepping between ticks
        j.tick(sim)
    assert len(j.writes) == 12


def test_a_followed_failing_end_capped_short_of_failure_is_told_of_the_runout_cap(capsys):
    """A search whose failing end was followed to rest and whose follow reached the runout's cap
    short of the failure displacement leans on that cap, not on the trial's: the warning says
    so with the motion in all, and needs no reading of the trial's ratio (an ensemble's trials
    carry none: the reading used to be read all the same, and the realization ended in a
    TypeError with its search lost)."""
    from fdem.workflow.fos import FoSResult, Trial, _tell_leaning_on_cap

    stood = Trial(factor=1.5, stable=True, result=stage("trial_F1.5000", "converged", 0.01, 1.5))
    open_ = Trial(factor=2.0, stable=False, result=stage("trial_F2.0000", "capped", 0.05, 2.0),
                  follow=stage("trial_F2.0000_rest", "capped", 0.1, 2.0), follow_verdict="undecided")
    result = FoSResult(fos=1.75, bracket=(1.5, 2.0), tolerance=0.5, trigger="strength", trials=[stood, open_])
    assert result.leans_on_cap and open_.cap_trend is None
    _tell_leaning_on_cap(None, result)   # the follow's branch needs no model
    out = capsys.readouterr()
    told = out.out + out.err
    assert "F = 2, was followed undamped to the runout's cap" in told and "0.15 m" in told, told
