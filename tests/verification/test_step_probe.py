"""The measured critical step (:mod:`fdem.solve.step_probe`) against exact references: the
per-element limit of free triangles (exact for the system when nothing couples them), the
largest eigenvalue of the whole ``M^-1 K`` assembled column by column on a small glued,
supported block under gravity, and the step past which the explicit run goes unstable. The
probe leaves the run as it found it."""
from __future__ import annotations

import numpy as np
import pytest

from fdem.mesh.mesh import jittered_rectangle
from fdem.mesh.topology import build_topology
from fdem.physics.contact import ContactSet
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.elastic import ElasticMaterial
from fdem.solve.model import FIX_X, FIX_Y, Model
from fdem.solve.simulation import Simulation
from fdem.solve.step_probe import measured_critical_dt

E, NU, RHO = 1e9, 0.25, 2500.0


def glued_block(seed=3):
    """A jittered 3 x 3 block of exploded triangles glued by crack elements (penalty 50 E),
    fixed at its base, with contact and gravity, settled for a few steps so that the state is
    not the reference one."""
    topo = build_topology(jittered_rectangle(3, 3, 1.0, 1.0, 0.25, seed))
    model = Model(topo, ElasticMaterial(E, NU, RHO))
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    glue = CrackProperties(f_t=1e11, c=1e11, phi=45.0, G_I=1e15, G_II=1e15, p_n=50 * E)
    cracks = CrackSet(topo, {0: glue})
    contact = ContactSet(topo, 10 * E, friction_angle=30.0, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=False)
    sim.run(n_steps=50, history_every=10, output_every=10**9)
    return sim


def dense_omega_max(sim, eps=1e-8):
    """Brute force: ``M^-1 K`` of the free degrees of freedom assembled one column at a time by
    the same finite difference of one step, and its largest eigenvalue."""
    saved = sim.state_dict()

    def accel(du):
        sim.load_state_dict(saved)
        sim.set_positions(displace=du)
        sim.state.v[:] = 0.0
        sim.step()
        return (sim.state.v / sim.dt).ravel().copy()

    n = sim.state.x.size
    held = np.column_stack([sim.flags & FIX_X, sim.flags & FIX_Y]).ravel() != 0
    idx = np.flatnonzero(~held)
    a0 = accel(np.zeros_like(sim.state.x))
    cols = []
    for k in idx:
        du = np.zeros(n)
        du[k] = eps
        cols.append(-(accel(du.reshape(-1, 2)) - a0)[idx] / eps)
    sim.load_state_dict(saved)
    A = np.array(cols).T
    return float(np.sqrt(np.max(np.linalg.eigvals(A).real)))


def test_free_triangles_give_the_exact_per_element_limit():
    """Exploded triangles with nothing between them: the system's limit is the stiffest
    triangle's exact element limit (the bound the solver uses), so the probe must return it."""
    topo = build_topology(jittered_rectangle(3, 2, 1.5, 1.0, 0.25, 0))
    sim = Simulation(Model(topo, ElasticMaterial(E, NU, RHO)), progress=False)
    sim.state.v[:] = 1e-3 * np.random.default_rng(0).standard_normal(sim.state.v.shape)
    probe = measured_critical_dt(sim, rtol=1e-8)
    assert probe.converged
    assert abs(probe.critical_dt / sim.triangle_dt - 1.0) < 1e-4
    assert abs(probe.margin - 1.0) < 1e-4


def test_glued_block_matches_the_assembled_eigenvalue_and_the_bound_is_safe():
    """Cracks, contact, supports and gravity: the Lanczos ``omega_max`` is the largest
    eigenvalue of the assembled ``M^-1 K`` to 1e-4, and the solver's combined bound lies below
    the measured limit (a safe step), here by more than a third."""
    sim = glued_block()
    probe = measured_critical_dt(sim, rtol=1e-8)
    assert probe.converged
    omega = dense_omega_max(sim)
    assert abs(probe.omega_max / omega - 1.0) < 1e-4
    assert probe.margin > 1.0
    assert probe.step_share == sim.dt / probe.critical_dt


def test_the_probe_changes_nothing_in_the_run():
    """A run probed midway goes on bit for bit as the same run not probed."""
    a, b = glued_block(), glued_block()
    measured_critical_dt(a)
    a.run(n_steps=200, history_every=20, output_every=10**9)
    b.run(n_steps=200, history_every=20, output_every=10**9)
    assert np.array_equal(a.state.x, b.state.x) and np.array_equal(a.state.v, b.state.v)
    assert [r["kinetic"] for r in a.history] == [r["kinetic"] for r in b.history]


def test_the_run_goes_unstable_just_past_the_measured_step():
    """Central differences are stable up to ``2 / omega_max``: the glued block, kicked, runs
    20,000 steps at 0.99 of the measured critical step with its energy ledger within 1 % (the
    highest modes, excited by the kick, are measured with the step's period error), and at 1.01
    of it the highest mode runs away and the guard stops the run within 200 steps. The
    solver's own step lies well below both."""
    from fdem.solve.simulation import InstabilityError

    sim = glued_block()
    sim.state.v[:] += 1e-4 * np.random.default_rng(1).standard_normal(sim.state.v.shape)
    probe = measured_critical_dt(sim, rtol=1e-8)
    saved = sim.state_dict()
    sim._choose_dt = lambda: 0.99 * probe.critical_dt  # past the solver's own step on purpose
    sim.run(n_steps=20000, history_every=500, output_every=10**9)
    assert max(abs(r["balance_error_relative"]) for r in sim.history) < 1e-2
    sim.load_state_dict(saved)
    sim._choose_dt = lambda: 1.01 * probe.critical_dt
    with pytest.raises(InstabilityError) as err:
        sim.run(n_steps=20000, history_every=500, output_every=10**9)
    assert err.value.step - saved["step"] < 200
    assert probe.step_dt < 0.8 * probe.critical_dt
