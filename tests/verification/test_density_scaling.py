"""Density-scaled quasi-static stages (:mod:`fdem.solve.density_scaling`): a larger step, the same answers.

The scene is the planar-failure slope of ``cases/planar_failure.py`` (a block on a joint that
daylights in the face, static geostatic start), as in ``test_stages.py``.
"""
from __future__ import annotations

import numpy as np
import pytest

from fdem.solve import density_scaling as ds
from fdem.solve.checkpoint import load_checkpoint, save_checkpoint
from fdem.solve.simulation import InstabilityError
from fdem.workflow.fos import GravityIncrease, factor_of_safety, fundamental_damping
from fdem.workflow.slope import SlopeWorkflow, run_slope_workflow
from fdem.workflow.stages import Convergence, Stage, response_time, run_stage

from conftest import planar_slope_scene


def test_scaled_step_spends_exactly_the_budget():
    """Brute force: the added mass ``sum max(0, S dt^2/4 - m)`` at the returned step is the
    budget, and a step 0.1 % longer exceeds it; a zero budget gives the unscaled nodal bound."""
    rng = np.random.default_rng(3)
    m = rng.uniform(0.5, 2.0, 5000)
    s = m * rng.lognormal(0.0, 1.0, 5000) * 1e8
    s[::7] = 0.0   # nodes without stiffness need no mass
    assert ds.scaled_critical_step(m, s, 0.0) == pytest.approx(float(np.min(2.0 * np.sqrt(m[s > 0] / s[s > 0]))))
    for budget in (1e-4, 0.01, 0.2):
        dt = ds.scaled_critical_step(m, s, budget)
        added = lambda d: float(np.maximum(0.0, s * d * d / 4.0 - m).sum())
        assert added(dt) == pytest.approx(budget * m.sum(), rel=1e-9)
        assert added(1.001 * dt) > budget * m.sum()
        scaled = ds.inertial_masses(m, s, dt)
        assert np.all(scaled >= m) and np.all(scaled >= s * dt * dt / 4.0 * (1 - 1e-12))
    with pytest.raises(ValueError, match="budget"):
        ds.scaled_critical_step(m, s, -0.1)


def test_scaled_masses_are_stable_at_their_critical_step():
    """Irons' bound in practice: every node kicked with a random velocity, the scaled model
    runs undamped at the full critical step it was scaled for (time-step factor 1) without
    growing: the ledger stays closed over 3,000 steps (an unstable mode would multiply its
    energy many times over within a few hundred)."""
    sim = planar_slope_scene().sim
    unscaled_critical, _ = sim.critical_dt()
    sim.set_density_scaling(True)
    critical, _ = sim.critical_dt()
    assert critical > 1.25 * unscaled_critical  # 1.36x on this coarse mesh, about 3x at 180k triangles
    rng = np.random.default_rng(0)
    sim.state.v[:] = 1e-3 * rng.standard_normal(sim.state.v.shape)
    r = run_stage(sim, Stage("kicked", duration=3000 * critical, density_scaling=True, dt_fraction=1.0),
                  frames=False)
    assert r.dt == pytest.approx(critical) and 1.0 < r.period_stretch <= np.sqrt(1.01)
    assert r.steps >= 3000
    errors = np.array([abs(row["balance_error_relative"]) for row in sim.history])
    assert errors.max() < 1e-3, errors.max()


def test_a_step_past_the_scaled_bound_blows_up():
    """The control of the test above: the same kick with a step 1.5 times the one the masses
    were scaled for (``omega dt`` 1.5 times the bound) grows without bound, so 3,000 quiet steps
    do say the bound holds (it is at most 1.5 times conservative in frequency here)."""
    sim = planar_slope_scene().sim
    sim.set_density_scaling(True)
    sim._scaled_dt *= 1.5   # the step the masses were scaled for, overstated: omega dt = 1.5 x the bound
    sim.dt_fraction = 1.0
    rng = np.random.default_rng(0)
    sim.state.v[:] = 1e-3 * rng.standard_normal(sim.state.v.shape)
    grown = False
    try:
        sim.run(n_steps=3000, energy_tolerance=None, progress=False)
        grown = float(np.abs(sim.state.v).max()) > 1.0
    except InstabilityError:  # the guard: an inverted triangle or a non-finite state
        grown = True
    assert grown


def _scene(scaled: bool, geometry: str = "no_crack", size: float | None = None):
    s = planar_slope_scene(geometry) if size is None else planar_slope_scene(geometry, size)
    if not scaled:
        s.sim.density_scaling = None
    return s


def test_planar_factor_of_safety_is_the_same_with_and_without_scaling():
    """Hoek-Bray's planar slope by strength reduction (the verification search of
    ``test_planar_failure.py``): the same trials settle and fail with scaled masses, so the
    bracket is the same, and its trials take fewer steps."""
    import planar_failure as pf

    runs = {}
    for scaled in (False, True):
        sim = _scene(scaled, size=1.5).sim
        runs[scaled] = factor_of_safety(sim, 1.0, 1.8, tol=0.03, trial=pf.trial_stage(sim))
    plain, scaled = runs[False], runs[True]
    assert scaled.bracket == plain.bracket
    assert [(t.factor, t.stable) for t in scaled.trials] == [(t.factor, t.stable) for t in plain.trials]
    steps = lambda r: sum(t.result.steps for t in r.trials)
    assert steps(scaled) < 0.8 * steps(plain)


def test_gravity_increase_factor_is_the_same_with_and_without_scaling():
    """The gravity-increase search of ``test_stages.py`` finds the same bracket on scaled masses
    (gravity acts on the real masses: the loads are the same)."""
    brackets = []
    for scaled in (False, True):
        sim = _scene(scaled).sim
        brackets.append(factor_of_safety(sim, lower=1.0, upper=5.0, tol=0.1, trigger=GravityIncrease()).bracket)
    assert brackets[0] == brackets[1]


def test_workflow_reaches_the_same_failure_with_a_closed_ledger_and_fewer_steps():
    """Damped reduction steps (scaled) until the block fails, then the undamped runout (real
    masses): the same stages settle and fail as without scaling, the ledger stays closed to
    1 % of the energy scale across the switches of the masses (booked as mass_change_work), the
    quasi-static stages take fewer steps and the runout runs at the unscaled step."""
    summaries, sims = {}, {}
    for scaled in (False, True):
        s = _scene(scaled, "tension_crack")
        T = response_time(s.sim.model)
        wf = SlopeWorkflow(factors=(1.2, 1.6, 2.2, 3.0), step_time=8 * T, fail_displacement=0.02, runout_time=0.3)
        summaries[scaled], sims[scaled] = run_slope_workflow(s.sim, wf), s.sim
    plain, scaled = summaries[False], summaries[True]
    assert [(st["name"], st["reason"]) for st in scaled["stages"]] == [(st["name"], st["reason"]) for st in plain["stages"]]
    assert scaled["failed_at_factor"] == plain["failed_at_factor"] is not None
    quasi = [(a, b) for a, b in zip(plain["stages"], scaled["stages"]) if a["name"] != "runout"]
    assert all(b["period_stretch"] > 1.0 and b["dt"] > 1.25 * a["dt"] for a, b in quasi)
    assert sum(b["steps"] for _, b in quasi) < 0.8 * sum(a["steps"] for a, _ in quasi)
    runout = scaled["stages"][-1]
    assert runout["name"] == "runout" and runout["period_stretch"] == 1.0
    assert runout["dt"] == pytest.approx(plain["stages"][-1]["dt"])
    for sim in sims.values():
        errors = np.array([abs(row["balance_error_relative"]) for row in sim.history])
        assert errors.max() < 0.01, f"ledger error {errors.max():.3g} of the energy scale"
    assert sims[True].history[-1]["mass_change_work"] != 0.0


def test_a_checkpoint_taken_while_scaled_continues_bit_for_bit(tmp_path):
    """A checkpoint in the middle of a scaled stage restores the scaled masses and the step:
    the restored run and the uninterrupted one agree to the last bit."""
    a = _scene(True).sim
    stage = Stage("settle", max_time=0.2 * response_time(a.model), converge=Convergence(unbalanced_ratio=1e-9),
                  damping=fundamental_damping(a))
    run_stage(a, stage, frames=False)
    assert a.density_scaled
    path = save_checkpoint(a, tmp_path / "scaled.npz")
    b = _scene(True).sim
    load_checkpoint(b, path)
    assert b.density_scaled and b.dt == a.dt and np.array_equal(b.inertia, a.inertia)
    damping = fundamental_damping(a)
    for sim in (a, b):
        sim.run(n_steps=200, damping=damping, history_every=50, progress=False)
    assert np.array_equal(a.state.x, b.state.x) and np.array_equal(a.state.v, b.state.v)
