"""Checks before work and honest endings (issue 25): every bad option found by an adversarial
tester is refused before any meshing, with a message that names it, and no error is reported
as a smoke run. One test per finding, then property-based fuzzing of the dataclasses'
validation and of the cases' option parsers (parse and check only: nothing is meshed)."""
from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fdem.cases.block_on_incline as incline
import fdem.cases.brazilian_disc as brazilian
import fdem.cases.ensemble as ensemble
import fdem.cases.newmark_block as newmark
import fdem.cases.planar_failure as planar
from fdem.mesh.mesh import structured_rectangle
from fdem.mesh.topology import build_topology
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.workflow.fos import BracketError, check_bracket, factor_of_safety
from fdem.workflow.slope import SlopeWorkflow
from fdem.workflow.stages import Convergence, Failure, Stage


def refused(main, argv, capsys, *needles) -> str:
    """Run a case's ``main(argv)``, expect a parser error (exit status 2) whose message holds
    every one of ``needles``; returns the message."""
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    for needle in needles:
        assert needle in err, err
    return err


@pytest.fixture
def no_meshing(monkeypatch):
    """Any meshing while options are checked fails the test."""
    import fdem.mesh.triangulate as tri

    def fail(*args, **kwargs):
        raise AssertionError("meshed before the options were checked")

    for module in (tri, incline, brazilian, planar):
        if hasattr(module, "mesh_geometry"):
            monkeypatch.setattr(module, "mesh_geometry", fail)
    monkeypatch.setattr(brazilian, "disc_mesh", fail)


# ----------------------------------------------------------------------------- brazilian disc
@pytest.mark.parametrize("speed", ["0", "-1", "nan", "1e3"])
def test_brazilian_refuses_a_platen_speed_that_never_loads_or_is_an_impact(speed, capsys, no_meshing):
    refused(brazilian.main, ["--v-platen", speed, "--out", "unused"], capsys, "--v-platen", "positive speed")


def test_brazilian_refuses_a_disc_too_coarse_and_says_the_largest_size(capsys, no_meshing):
    largest = brazilian.largest_size()
    assert largest == pytest.approx(0.01)   # D/10
    refused(brazilian.main, ["--size", "1.0"], capsys, "--size 1 m is coarser than the largest allowed",
            f"{largest:.4g} m")
    refused(brazilian.main, ["--sizes", "5", "25"], capsys, "D/5", "coarser than the largest allowed")
    assert brazilian.parse_args(["--size", "0.01"]).divisions == [10]   # D/10: allowed, not clamped
    with pytest.raises(ValueError, match="coarser than the largest allowed"):
        brazilian.run(2)


# ----------------------------------------------------------------------------- factor of safety
@pytest.mark.parametrize("argv, needle", [
    (["--tol", "1e-20"], "below the resolution of the search"),
    (["--lower", "2", "--upper", "1"], "--upper (1.0) must exceed --lower (2.0)"),
    (["--tol", "0"], "--tol must be a positive"),
    (["--tol", "-1"], "--tol must be a positive"),
    (["--lower", "-1"], "--lower must be a positive"),
    (["--upper", "inf"], "--upper must be a positive finite"),
    (["--max-trials", "1"], "--max-trials must be at least 2"),
])
def test_planar_failure_checks_the_search_at_parse_time(argv, needle, capsys, no_meshing):
    refused(planar.main, argv + ["--max-time", "0.01", "--size", "2"], capsys, needle)


def test_the_search_refuses_a_tolerance_below_its_resolution_before_any_trial():
    # sim=None: the check comes before anything touches the simulation
    with pytest.raises(ValueError, match=r"tol = 1e-20 is below the resolution"):
        factor_of_safety(None, 1.0, 2.0, tol=1e-20)
    with pytest.raises(ValueError, match="max_trials must be an integer >= 2"):
        factor_of_safety(None, 1.0, 2.0, tol=0.01, max_trials=1)
    check_bracket(1.0, 2.0, 2e-6)


def test_the_search_ends_by_its_trial_cap_and_says_so():
    row = planar.run_case("no_crack", 2.0, lower=0.8, upper=2.0, tol=1e-5, max_trials=4)
    assert row["search_ended_by"] == "max_trials" and row["n_trials"] == 4
    assert row["bracket"][1] - row["bracket"][0] > 1e-5


def test_only_the_time_cap_makes_a_smoke_run():
    row = planar.run_case("no_crack", 2.0, max_time=0.01)
    assert row["fos"] is None and row["time_capped"]
    assert "--max-time cap" in row["fos_undefined"] and "undefined" in row["fos_undefined"]
    # a bracket the slope contradicts is an error, with or without the cap
    with pytest.raises(BracketError, match="still stable at the upper factor") as err:
        planar.run_case("no_crack", 2.0, lower=0.3, upper=0.5)
    assert not err.value.trial.time_capped


# ----------------------------------------------------------------------------- block on incline, newmark, ensemble
@pytest.mark.parametrize("argv, needle", [
    (["--theta", "95"], "--theta (the incline) must lie in (0, 90) deg"),
    (["--theta", "200"], "--theta (the incline) must lie in (0, 90) deg"),
    (["--theta", "0"], "--theta"),
    (["--element-damping", "-0.5"], "--element-damping (a fraction of critical) must lie in [0, 1]"),
    (["--element-damping", "3"], "--element-damping"),
    (["--phi", "-10"], "--phi"),
    (["--phi", "90"], "--phi"),
    (["--t-end", "-1"], "--t-end"),
    (["--width", "-1"], "--width"),
    (["--size", "2"], "--size"),
])
def test_block_on_incline_refuses_physics_it_cannot_honour(argv, needle, capsys, no_meshing):
    refused(incline.main, argv, capsys, needle)


def test_block_on_incline_checks_before_meshing_from_python_too(no_meshing):
    with pytest.raises(ValueError, match="theta"):
        incline.run(95.0, 20.0)
    with pytest.raises(ValueError, match="element_damping"):
        incline.build(30.0, 20.0, element_damping=-0.5)


@pytest.mark.parametrize("argv, needle", [
    (["--size"], "--size needs at least one element size"),
    (["--size", "-1"], "--size must be a positive"),
    (["--size", "0.5", "3"], "at most the block's smaller side"),
    (["--max-time", "0"], "--max-time"),
])
def test_newmark_block_checks_its_options(argv, needle, capsys):
    refused(newmark.main, argv, capsys, needle)


def test_newmark_block_refuses_a_pulse_that_never_slips(no_meshing):
    with pytest.raises(ValueError, match="ratio"):
        newmark.run(0.5, ratio=0.8)
    with pytest.raises(ValueError, match="phi .* must exceed theta"):
        newmark.run(0.5, theta_deg=30.0, phi_deg=20.0)


@pytest.mark.parametrize("argv, needle", [
    (["--workers", "0"], "--workers"), (["--timeout", "-1"], "--timeout"), (["--n", "0"], "n must be"),
    (["--seed", "-1"], "seed"), (["--size", "-2"], "--size"), (["--max-time", "-1"], "max_time"),
])
def test_ensemble_checks_its_options(argv, needle, capsys):
    refused(ensemble.main, argv, capsys, needle)


# ----------------------------------------------------------------------------- crack property sets
def jointed(tags=(1,)):
    """A 4 x 2 structured block whose first crack elements carry the joint-set ``tags``."""
    topo = build_topology(structured_rectangle(4, 2, 1.0, 0.5))
    tag = np.zeros(topo.n_cracks, np.int32)
    tag[: len(tags)] = tags
    return dataclasses.replace(topo, crack_tag=tag)


def rock(**kw):
    return CrackProperties(**{**dict(f_t=1e5, c=2e5, phi=30.0, G_I=50.0, G_II=500.0, p_n=1e10), **kw})


def test_a_property_set_for_a_tag_the_mesh_lacks_is_an_error_naming_it():
    with pytest.raises(ValueError, match=r"tag\(s\) \[3\] \(joints typo\) match no crack element: "
                                         r"the mesh has tags \[0, 1\]"):
        CrackSet(jointed(), {0: rock(), 1: rock(), 3: rock(name="joints typo")})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        CrackSet(jointed(), {0: rock(), 1: rock()})          # every set used: silent


def test_a_joint_set_that_may_mesh_to_nothing_is_a_warning():
    with pytest.warns(UserWarning, match=r"joint set\(s\) \[2\] \(cross joints\) have no crack element"):
        CrackSet(jointed(), {0: rock(), 1: rock(), 2: rock(name="cross joints")}, absent_ok=(2,))
    # a mesh without any joint given a scene's whole table (the benchmarks do): a warning
    plain = build_topology(structured_rectangle(2, 2, 1.0, 1.0))
    with pytest.warns(UserWarning, match=r"joint set\(s\) \[1\]"):
        CrackSet(plain, {0: rock(), 1: rock()})


def test_the_planar_scene_passes_only_the_sets_of_its_geometry():
    from fdem.cases.planar_failure import GEOMETRIES, HEIGHT, planar_failure_simulation, planar_slope_geometry

    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        scene = planar_failure_simulation(planar_slope_geometry(HEIGHT, **GEOMETRIES["no_crack"]), 2.0)
    assert sorted(scene.cracks.property_sets) == [0, 1]


def test_the_snap_back_error_says_how_much_finer_to_mesh():
    """G_II too small for k_t = p / L0: the message gives the refinement factor need / G_II,
    and the mesh refined by it builds; it names no command-line option."""
    props = rock(c=2e6, G_II=100.0)
    with pytest.raises(ValueError) as err:
        CrackSet(build_topology(structured_rectangle(2, 2, 1.0, 1.0)), {0: props})
    text = str(err.value)
    assert "--" not in text and "refine the mesh by at least a factor" in text and "raise G_II" in text
    factor = float(text.split("refine the mesh by at least a factor ")[1].split(" ")[0])
    n = math.ceil(2 * factor * 1.01)
    CrackSet(build_topology(structured_rectangle(n, n, 1.0, 1.0)), {0: props})


# ----------------------------------------------------------------------------- slope workflow
@pytest.mark.parametrize("field, value", [
    ("runout_time", -1.0), ("step_time", -0.5), ("fail_displacement", -0.01), ("step_time", math.nan),
    ("fos", (2.0, 1.0, 0.1)), ("fos", (1.0, 2.0, 0.0)), ("fos", (1.0, 2.0, -0.1)), ("fos", (1.0, 2.0, 1e-20)),
    ("fos", (1.0, 2.0)), ("factors", ()), ("factors", (1.5, 1.2)), ("final_strength", 1.5),
    ("equilibrium_ratio", 2.0), ("rest_kinetic_ratio", 0.0), ("reduction_rate", -5.0), ("runout_dt_fraction", 1.5),
    ("trial_end", "forever"), ("trial_end", "rest"),   # "rest" with no search to judge (fos = None)
])
def test_the_slope_workflow_names_the_bad_field(field, value):
    with pytest.raises(ValueError, match=f"SlopeWorkflow.{field}"):
        SlopeWorkflow(**{field: value})


def test_a_strength_search_follows_its_capped_trials_unless_told_not_to():
    """``trial_end`` unset judges a strength search's capped trials by the damped steps' rule
    (``"rest"``) and a gravity search's at their cap, whose trials are not followed; given, it is
    what it says, and ``"rest"`` where no trial can be followed is refused naming the field."""
    assert SlopeWorkflow().trial_rule == "rest" and SlopeWorkflow(fos=(1.0, 2.0, 0.1)).trial_rule == "rest"
    assert SlopeWorkflow(fos=(1.0, 2.0, 0.1), trial_end="cap").trial_rule == "cap"
    gravity = SlopeWorkflow(trigger="gravity", fos=(1.0, 2.0, 0.1))
    assert gravity.trial_end is None and gravity.trial_rule == "cap"
    with pytest.raises(ValueError, match="SlopeWorkflow.trial_end = 'rest' follows the trials of a strength"):
        SlopeWorkflow(trigger="gravity", fos=(1.0, 2.0, 0.1), trial_end="rest")


# ----------------------------------------------------------------------------- fuzzing
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
anything = st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10, 10)
maybe = st.none() | anything


def constructs_in_range_or_refuses(build, check):
    """``build()`` either raises ``ValueError`` or returns an object that ``check`` accepts;
    any other exception fails the test."""
    try:
        obj = build()
    except ValueError:
        return
    check(obj)


def positive(v):
    return v is None or (math.isfinite(v) and v > 0)


@FUZZ
@given(unbalanced=maybe, kinetic=maybe, speed=maybe, min_time=anything, hold_for=anything)
def test_fuzz_convergence(unbalanced, kinetic, speed, min_time, hold_for):
    def check(c):
        assert all(positive(v) for v in (c.unbalanced_ratio, c.kinetic_ratio, c.speed))
        assert math.isfinite(c.min_time) and c.min_time >= 0 and math.isfinite(c.hold_for) and c.hold_for >= 0

    constructs_in_range_or_refuses(lambda: Convergence(unbalanced, kinetic, speed, min_time, hold_for), check)


@FUZZ
@given(displacement=maybe, speed=maybe)
def test_fuzz_failure(displacement, speed):
    constructs_in_range_or_refuses(lambda: Failure(displacement, speed),
                                   lambda f: positive(f.displacement) and positive(f.speed) or pytest.fail(str(f)))


@FUZZ
@given(duration=maybe, max_time=maybe, reduction=maybe, gravity=maybe, check_interval=maybe, dt_fraction=maybe)
def test_fuzz_stage(duration, max_time, reduction, gravity, check_interval, dt_fraction):
    def check(s):
        assert all(positive(v) for v in (s.duration, s.max_time, s.reduction, s.check_interval))
        assert s.gravity_factor is None or (math.isfinite(s.gravity_factor) and s.gravity_factor >= 0)
        assert s.dt_fraction is None or 0 < s.dt_fraction <= 1

    constructs_in_range_or_refuses(lambda: Stage("fuzz", duration=duration, max_time=max_time, reduction=reduction,
                                                 gravity_factor=gravity, check_interval=check_interval,
                                                 dt_fraction=dt_fraction, converge=Convergence()), check)


@FUZZ
@given(rate=anything, final=anything, ratio=anything, step_time=maybe, fail=maybe, runout=maybe, rest=anything,
       dt_fraction=maybe, fos=st.none() | st.tuples(anything, anything, anything),
       factors=st.lists(anything, max_size=4))
def test_fuzz_slope_workflow(rate, final, ratio, step_time, fail, runout, rest, dt_fraction, fos, factors):
    def check(w):
        assert w.factors and all(math.isfinite(f) and f > 0 for f in w.factors)
        assert all(b > a for a, b in zip(w.factors, w.factors[1:]))
        assert math.isfinite(w.reduction_rate) and w.reduction_rate > 0
        assert all(0 < v < 1 for v in (w.final_strength, w.equilibrium_ratio, w.rest_kinetic_ratio))
        assert all(positive(v) for v in (w.step_time, w.fail_displacement, w.runout_time))
        assert w.runout_dt_fraction is None or 0 < w.runout_dt_fraction <= 1
        if w.fos is not None:
            lower, upper, tol = w.fos
            assert 0 < lower < upper and math.isfinite(upper) and 1e-6 * upper <= tol and math.isfinite(tol)

    constructs_in_range_or_refuses(lambda: SlopeWorkflow(
        factors=tuple(factors), reduction_rate=rate, final_strength=final, equilibrium_ratio=ratio,
        step_time=step_time, fail_displacement=fail, runout_time=runout, rest_kinetic_ratio=rest,
        runout_dt_fraction=dt_fraction, fos=fos), check)


@FUZZ
@given(f_t=anything, c=anything, phi=anything, G_I=anything, G_II=anything, p_n=maybe, k_n=maybe)
def test_fuzz_crack_properties(f_t, c, phi, G_I, G_II, p_n, k_n):
    def check(p):
        assert p.f_t > 0 and p.c >= 0 and 0 <= p.phi < 90 and p.G_I > 0 and p.G_II >= 0
        assert (p.p_n is None) != (p.k_n is None)
        assert all(positive(v) for v in (p.p_n, p.k_n))

    constructs_in_range_or_refuses(lambda: CrackProperties(f_t=f_t, c=c, phi=phi, G_I=G_I, G_II=G_II, p_n=p_n,
                                                           k_n=k_n), check)


number = st.floats(allow_nan=True, allow_infinity=True).map(repr) | st.integers(-5, 200).map(str)


def parses_in_range_or_exits_2(parse, argv, check):
    """A parser accepts ``argv`` with values ``check`` accepts, or exits with status 2."""
    try:
        args = parse(argv)
    except SystemExit as exit_:
        assert exit_.code == 2
        return
    check(args)


@FUZZ
@given(theta=number, phi=number, t_end=number, damping=number, size=number)
def test_fuzz_block_on_incline_options(theta, phi, t_end, damping, size, no_meshing_module):
    def check(a):
        incline.check_scene(a.theta, a.phi, a.t_end, a.width, a.height, a.size, a.element_damping)
        assert 0 < a.theta < 90 and 0 <= a.phi < 90 and 0 <= a.element_damping <= 1 and a.t_end > 0

    parses_in_range_or_exits_2(incline.parse_args, ["--theta", theta, "--phi", phi, "--t-end", t_end,
                                                    "--element-damping", damping, "--size", size], check)


@FUZZ
@given(lower=number, upper=number, tol=number, trials=st.integers(-3, 50).map(str))
def test_fuzz_planar_failure_options(lower, upper, tol, trials, no_meshing_module):
    def check(a):
        check_bracket(a.lower, a.upper, a.tol, a.max_trials)

    parses_in_range_or_exits_2(planar.parse_args, ["--lower", lower, "--upper", upper, "--tol", tol,
                                                   "--max-trials", trials], check)


@FUZZ
@given(size=number, speed=number)
def test_fuzz_brazilian_options(size, speed, no_meshing_module):
    def check(a):
        for n in a.divisions:
            brazilian.check_loading(n, a.v_platen)

    parses_in_range_or_exits_2(brazilian.parse_args, ["--size", size, "--v-platen", speed], check)


@pytest.fixture(scope="module")
def no_meshing_module():
    """:func:`no_meshing` for the fuzz tests (hypothesis runs many examples per test call)."""
    mp = pytest.MonkeyPatch()
    import fdem.mesh.triangulate as tri

    def fail(*args, **kwargs):
        raise AssertionError("meshed while parsing options")

    mp.setattr(tri, "mesh_geometry", fail)
    mp.setattr(brazilian, "disc_mesh", fail)
    for module in (incline, planar):
        mp.setattr(module, "mesh_geometry", fail)
    yield
    mp.undo()


# ----------------------------------------------------------------------------- four slopes
@pytest.mark.parametrize("argv, needle", [
    (["--angle", "low", "--elastic-band"], "this run has none: give --boundary-band"),
    (["--angle", "high", "--boundary-band", "0", "--elastic-band"], "this run has none: give --boundary-band"),
    (["--angle", "high", "--boundary-band", "0.5", "--size", "1", "--elastic-band"], "narrower than one element"),
])
def test_four_slopes_refuses_an_elastic_band_it_cannot_build(argv, needle, capsys, no_meshing, tmp_path):
    from fdem.cases import four_slopes

    refused(four_slopes.main, argv + ["--out", str(tmp_path / "run")], capsys, needle)
    assert not (tmp_path / "run").exists()
