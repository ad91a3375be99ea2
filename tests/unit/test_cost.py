"""The cost estimate (:mod:`fdem.solve.cost`): the step it reports is the simulation's, the
memory it reports is the arrays the simulation holds, and a mesh too large for the machine is
refused before anything is meshed."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fdem.mesh.mesh import structured_rectangle
from fdem.mesh.topology import build_topology
from fdem.physics.contact import ContactSet
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.elastic import ElasticMaterial
from fdem.solve import cost
from fdem.solve.model import Model
from fdem.solve.simulation import Simulation

YOUNG = 1e9


def scene(penalty_ratio: float = 10.0, contact: bool = True) -> Simulation:
    """A 6 x 4 block of 48 triangles, fixed at its base, under gravity: crack elements with
    penalty ``penalty_ratio * E``, and contact."""
    topo = build_topology(structured_rectangle(6, 4, 0.6, 0.4))
    model = Model(topo, ElasticMaterial(young=YOUNG, poisson=0.25, density=2500.0))
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    rock = CrackProperties(f_t=2e5, c=4e5, phi=30.0, G_I=50.0, G_II=200.0, p_n=penalty_ratio * YOUNG)
    cracks = CrackSet(topo, {0: rock})
    providers = [cracks]
    if contact:
        providers.append(ContactSet(topo, 10 * YOUNG, friction_angle=30.0, mass=model.node_mass(), cracks=cracks))
    return Simulation(model, providers=providers, progress=False)


def test_the_step_is_the_critical_step_times_the_fraction():
    sim = scene()
    est = cost.estimate_cost(sim, simulated_seconds=0.01)
    crit, limits = sim.critical_dt()
    assert est.dt == pytest.approx(sim.dt_fraction * crit, rel=1e-12)
    assert est.steps_per_simulated_second == pytest.approx(1.0 / est.dt, rel=1e-12)
    assert set(est.dt_limits) == {"triangles", "cracks", "contact"}
    assert sorted(est.dt_limits.values()) == pytest.approx(sorted(limits.values()))
    assert est.dt_limits[est.governing] == min(est.dt_limits.values())
    assert est.steps == math.ceil(0.01 / est.dt - 1e-9)
    assert est.wall_seconds == pytest.approx(est.steps * est.seconds_per_step)
    assert est.seconds_per_step_source == "benchmark"
    assert est.seconds_per_step == pytest.approx(cost.SECONDS_PER_STEP_OVERHEAD + cost.SECONDS_PER_TRIANGLE_STEP * 48)
    assert (est.n_triangles, est.n_nodes, est.n_cracks) == (48, 144, sim.model.topology.n_cracks)
    d = est.as_dict()
    assert d["governing"] == est.governing and d["dt_limits"] == est.dt_limits
    lines = est.describe().splitlines()
    assert len(lines) == 2 and "48 triangles" in lines[0] and "steps for 0.01 s" in lines[1]


def test_the_memory_is_the_arrays_the_simulation_holds():
    sim = scene()
    est = cost.estimate_cost(sim)
    arrays = {}
    owners = [sim, sim.state, sim.model, sim.model.topology, *sim.providers]
    for owner in owners:
        for value in vars(owner).values():
            if isinstance(value, np.ndarray):
                arrays[id(value)] = value.nbytes
    direct = sum(arrays.values())
    assert direct / 2 <= est.memory_bytes <= 2 * direct
    assert est.peak_memory_bytes == pytest.approx(cost.mesh_memory_bytes(48))


def test_a_measured_step_leaves_the_simulation_as_it_was():
    sim = scene()
    sim.run(n_steps=5, energy_tolerance=None, output_every=10**9)
    x, v, step, time = sim.state.x.copy(), sim.state.v.copy(), sim.state.step, sim.state.time
    est = cost.estimate_cost(sim, simulated_seconds=1e-4, measure_steps=20)
    assert est.seconds_per_step_source == "measured" and 0 < est.seconds_per_step < 1.0
    assert (sim.state.step, sim.state.time) == (step, time)
    assert np.array_equal(sim.state.x, x) and np.array_equal(sim.state.v, v)
    given = cost.estimate_cost(sim, simulated_seconds=1.0, steps_per_second_measured=1e4)
    assert given.seconds_per_step == pytest.approx(1e-4) and given.wall_seconds == pytest.approx(given.steps * 1e-4)


def test_a_stiff_penalty_draws_a_warning():
    assert cost.dt_warning(cost.estimate_cost(scene(contact=False))) is None
    stiff = cost.estimate_cost(scene(penalty_ratio=1e6, contact=False))
    assert stiff.governing == "cracks"
    ratio = stiff.dt_limits["triangles"] / stiff.dt_limits["cracks"]
    assert ratio > cost.DT_WARNING_RATIO
    text = cost.dt_warning(stiff)
    assert text is not None and "cracks" in text and f"{ratio:,.0f}x" in text


def test_triangles_of_an_area():
    h = 0.5
    assert cost.estimate_triangles(1000 * math.sqrt(3) / 4 * h * h, h) == 1000
    for bad in ((0.0, 1.0), (1.0, 0.0), (-1.0, 1.0), (1.0, math.nan), (math.inf, 1.0)):
        with pytest.raises(ValueError):
            cost.estimate_triangles(*bad)


def test_the_mesh_budget_refuses_an_absurd_size_before_meshing(monkeypatch):
    n = cost.estimate_triangles(1e4, 1e-3)                       # 1 ha at 1 mm: 2.3e10 triangles
    with pytest.raises(ValueError, match=r"at most about [\d,]+ triangles fit; use a larger element size"):
        cost.check_mesh_budget(n, memory_available=8e9)
    assert cost.check_mesh_budget(1000, memory_available=8e9) == pytest.approx(cost.mesh_memory_bytes(1000))
    monkeypatch.setattr(cost, "available_memory", lambda: None)  # nothing to compare against: passes
    assert cost.check_mesh_budget(n) == pytest.approx(cost.mesh_memory_bytes(n))


def test_the_brazilian_disc_refuses_a_mesh_too_fine_for_the_memory(monkeypatch):
    import fdem.cases.brazilian_disc as bd

    def no_meshing(*args, **kwargs):
        raise AssertionError("meshed before the budget check")

    monkeypatch.setattr(bd, "disc_mesh", no_meshing)
    monkeypatch.setattr(cost, "available_memory", lambda: int(4e9))
    with pytest.raises(SystemExit) as exit_:
        bd.parse_args(["--size", "1e-5"])
    assert exit_.value.code == 2


def test_peak_memory_follows_the_measured_peaks():
    measured = {7_761: 236.7e6, 29_348: 313.0e6, 59_979: 429.4e6, 123_403: 709.5e6, 238_227: 1277.6e6,
                490_381: 2667.3e6}
    for n, peak in measured.items():
        above = peak - cost.BASE_PEAK_BYTES
        assert cost.mesh_memory_bytes(n) - cost.BASE_PEAK_BYTES == pytest.approx(above, rel=0.1)


def test_a_search_alone_is_priced_at_its_own_trial_cap(capsys):
    """``reduction = "none"``: the equilibrium at F = 1 (twice the stage cap, and never under
    twice 5 response times) and the search's most trials, each at the workflow's ``step_time``
    when it gives one, 5 response times when not, at the cap rule (no follow): the simulated
    seconds the estimate prices are those the run may take."""
    import argparse
    from types import SimpleNamespace

    from fdem.cases.common import report_runout_cost
    from fdem.workflow.fos import most_trials
    from fdem.workflow.slope import SlopeWorkflow
    from fdem.workflow.stages import response_time

    sim = scene()
    T = response_time(sim.model)
    args = SimpleNamespace(yes=True, threads=1)
    assert 3.7 > 5.0 * T  # so that the longer trials lengthen the equilibrium too
    for step_time, cap, equilibrium in ((None, 5.0 * T, 10.0 * T), (3.7, 3.7, 7.4), (2.0 * T, 2.0 * T, 10.0 * T)):
        wf = SlopeWorkflow(reduction="none", fos=(1.0, 1.6, 0.04), step_time=step_time, trial_end="cap")
        est = report_runout_cost(argparse.ArgumentParser(), sim, args, wf)
        n = most_trials(1.0, 1.6, 0.04)
        assert est["simulated_seconds"] == pytest.approx(equilibrium + n * cap, rel=1e-12), est
        assert f"trials of up to {cap:.3g} s" in capsys.readouterr().out


def test_a_search_followed_to_rest_is_priced_with_each_trial_s_follow(capsys):
    """``trial_end = "rest"``: every trial may go on, undamped, for the runout's cap after its
    own, and the estimate prices that at its most (the follow is the runout stage)."""
    import argparse
    from types import SimpleNamespace

    import numpy as np

    from fdem.cases.common import report_runout_cost
    from fdem.workflow.fos import most_trials
    from fdem.workflow.slope import SlopeWorkflow, runout_stage
    from fdem.workflow.stages import response_time

    sim = scene()
    T = response_time(sim.model)
    wf = SlopeWorkflow(reduction="none", fos=(1.0, 1.6, 0.04), step_time=3.7, trial_end="rest", runout_time=9.0)
    follow = runout_stage(wf, T, float(np.ptp(sim.model.topology.x0[:, 1])), 9.81).max_time
    assert follow == 9.0
    est = report_runout_cost(argparse.ArgumentParser(), sim, SimpleNamespace(yes=True, threads=1), wf)
    assert est["simulated_seconds"] == pytest.approx(2.0 * 3.7 + most_trials(1.0, 1.6, 0.04) * (3.7 + 9.0), rel=1e-12)
    assert "each followed to rest for up to 9 s more" in capsys.readouterr().out
