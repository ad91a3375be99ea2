"""The equilibrium stage's damping and end rule (docs/benchmarks.md, "Equilibrium stage at scale").

Physical facts checked:

* Rayleigh's estimate of a laterally confined column's fundamental frequency from its static
  deflection is ``sqrt(5/2) c_p / H`` (parabolic shape; the exact value is ``pi/2 c_p / H``);
* a column released under gravity, damped critically for that frequency, settles to the static
  solution, in a number of steps proportional to the elements across it, and in fewer steps
  than under the shear-beam damping ``4 pi / T``;
* the unbalanced-force ratio of a model at rest sits at its round-off floor
  (:func:`fdem.solve.geostatic.unbalanced_ratio_floor`), and does not depend on the origin:
  moved 4096 m away, a jointed column settles the same, in the same steps, under the bare
  limit 1e-4 (its crack elements read displacements, not positions); a limit under the floor is
  raised to it.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from fdem.cases.four_slopes import four_slope_property_sets
from fdem.mesh.mesh import structured_rectangle
from fdem.mesh.topology import build_topology
from fdem.physics.cracks import CrackSet
from fdem.physics.elastic import ElasticMaterial
from fdem.solve.damping import Damping
from fdem.solve.geostatic import (conforming_static_stress, rayleigh_frequency,
                                  unbalanced_force_ratio, unbalanced_forces, unbalanced_ratio_floor)
from fdem.solve.model import Model
from fdem.solve.simulation import Simulation
from fdem.workflow.fos import fundamental_damping
from fdem.workflow.stages import Convergence, Stage, response_time, run_stage

E, NU, RHO, G = 0.59e9, 0.29, 2680.0, 9.81
H, W = 10.0, 2.0


def column(ny: int, exploded: bool = False, origin=(0.0, 0.0)) -> Model:
    """Laterally confined gravity column (rollers on the sides, fixed base), square cells of
    ``H / ny``."""
    mesh = structured_rectangle(max(1, ny // 5), ny, W, H, origin=origin)
    model = (Model(build_topology(mesh), ElasticMaterial(E, NU, RHO)) if exploded
             else Model.from_mesh(mesh, ElasticMaterial(E, NU, RHO), exploded=False))
    model.set_gravity(0.0, -G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    return model


def p_wave_speed(model) -> float:
    lam, mu = model.lame_arrays()
    return float(np.sqrt((lam[0] + 2 * mu[0]) / RHO))


def test_rayleigh_frequency_of_a_confined_column():
    # u(y) ~ 2 xi - xi^2 (xi = y / H): omega^2 = (c_p / H)^2 int (2 - 2 xi)^2 / int (2 xi - xi^2)^2 = 5/2 (c_p / H)^2
    model = column(40)
    c_p = p_wave_speed(model)
    omega = rayleigh_frequency(model)
    assert omega == pytest.approx(np.sqrt(2.5) * c_p / H, rel=0.01)
    assert omega > np.pi / 2 * c_p / H * 0.995   # above the exact fundamental, as Rayleigh's quotient is
    # the same from a solution already at hand
    assert rayleigh_frequency(model, conforming_static_stress(model)) == omega
    weightless = column(10)
    weightless.set_gravity(0.0, 0.0)
    with pytest.raises(ValueError, match="do no work"):
        rayleigh_frequency(weightless)
    with pytest.raises(ValueError, match="angular frequency"):
        Damping.critical(0.0)


def settle(ny: int, damping_of) -> tuple[int, float, float]:
    """A column released from rest, unstressed, under gravity: steps to ratio 1e-4, the top
    displacement reached and the static one [m]."""
    model = column(ny)
    static = conforming_static_stress(model).displacement[:, 1]
    sim = Simulation(model, progress=False)
    sim.monitors.clear()
    T = response_time(model)
    r = run_stage(sim, Stage("settle", max_time=10 * T, damping=damping_of(sim), check_interval=T / 400,
                             converge=Convergence(unbalanced_ratio=1e-4)), frames=False)
    assert r.reason == "converged", r.detail
    top = np.flatnonzero(np.isclose(model.topology.x0[:, 1], H))
    u = sim.state.x[:, 1] - model.topology.x0[:, 1]
    return r.steps, float(u[top].mean()), float(static[model.topology.mesh_node[top]].mean())


def test_critically_damped_column_settles_to_the_static_solution_in_steps_proportional_to_its_size():
    critical = lambda sim: Damping.critical(rayleigh_frequency(sim.model))   # noqa: E731
    steps = {}
    for ny in (10, 20, 40):
        steps[ny], top, static = settle(ny, critical)
        assert top == pytest.approx(static, rel=2e-3)
        # the static top settlement of a confined column: rho g H^2 / (2 M)
        assert static == pytest.approx(-RHO * G * H ** 2 / (2 * RHO * p_wave_speed(column(ny)) ** 2), rel=0.01)
    # the settling time is a number of periods of the column, the step is proportional to the
    # element size: the steps double with the elements across
    assert 1.7 < steps[20] / steps[10] < 2.3, steps
    assert 1.7 < steps[40] / steps[20] < 2.3, steps
    # the shear-beam damping 4 pi / T is 0.54 of the critical one for this mode (c_p / c_s = 1.84,
    # omega_R = 1.58 c_p / H): the ratio falls to 1e-4 at omega t = 17 (envelope exp(-0.54 omega t))
    # instead of 11.9 ((1 + omega t) exp(-omega t)), 1.45 times the steps (1.39 measured)
    slow, _, _ = settle(20, fundamental_damping)
    assert slow > 1.3 * steps[20], (slow, steps[20])


def jointed_column(origin):
    """The column exploded, with the four-slope crack elements held elastic, released unstressed
    under gravity (it settles 1.7 mm: its nodes leave their reference positions)."""
    model = column(10, exploded=True, origin=origin)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # the DFN property set has no element in a column without joints
        cracks = CrackSet(model.topology, four_slope_property_sets(), contact_penalty=10 * E)
    cracks.hold_elastic()
    sim = Simulation(model, providers=[cracks], progress=False)
    sim.monitors.clear()
    return sim


def position_read_floor(sim) -> float:
    """The floor the column would have if its crack elements read positions instead of
    displacements: every stiffness times the spacing of float64 numbers at the positions."""
    from fdem.solve.density_scaling import nodal_stiffness

    eps = np.spacing(np.abs(sim.state.x)).max(axis=1)
    s = nodal_stiffness(sim.model, sim.providers, sim.state.mass)
    return float(s @ eps) / float(sim.state.mass.sum() * G)


def test_the_ratio_at_rest_does_not_depend_on_the_origin_and_sits_at_its_round_off_floor():
    near = jointed_column((0.0, 0.0))
    far = jointed_column((4096.0, 4096.0))
    T = response_time(far.model)
    damping = Damping.critical(rayleigh_frequency(far.model))
    settled, steps = {}, {}
    for name, sim in (("near", near), ("far", far)):
        # the bare limit 1e-4, no allowance for round-off
        r = run_stage(sim, Stage("bare", max_time=3.0 * T, damping=damping,
                                 converge=Convergence(unbalanced_ratio=1e-4, roundoff_factor=None)), frames=False)
        assert r.reason == "converged", (name, r)
        steps[name] = r.steps
        top = np.flatnonzero(np.isclose(sim.model.topology.x0[:, 1], H + sim.model.topology.x0[:, 1].min()))
        settled[name] = sim.state.u[top, 1].mean()
        # on: the ratio at rest is the round-off floor's (0.7 to 0.9 of it here)
        run_stage(sim, Stage("rest", max_time=3.0 * T, damping=damping,
                             converge=Convergence(unbalanced_ratio=1e-30, roundoff_factor=None)), frames=False)
        floor = unbalanced_ratio_floor(sim)
        assert 0.3 * floor <= unbalanced_force_ratio(sim) <= 3.0 * floor, name
        # positions and displacements are rounded apart by at most half a spacing a step
        spacing = np.spacing(np.abs(sim.state.x).max())
        assert np.abs(sim.state.x - sim.x0 - sim.state.u).max() <= 0.5 * sim.state.step * spacing, name
    # the same column 4096 m from the origin settles the same, in the same steps: the crack
    # elements read the displacements kept apart from the positions (State.u), so their stiff
    # springs turn no coordinate round-off into force
    assert steps["far"] == steps["near"]
    assert settled["far"] == pytest.approx(settled["near"], rel=1e-5)
    # far from the origin the floor is the triangles' (2.6e-7 here); read from the positions,
    # the crack penalties would have held the ratio above the bare limit (the stall of the 180k
    # four-slope run, in 160 triangles)
    assert unbalanced_ratio_floor(far) < 1e-6 < 1e-4 < position_read_floor(far)
    # the residual is spread over the whole column, not held by a few nodes
    f = np.linalg.norm(unbalanced_forces(far), axis=1)
    assert np.sort(f)[::-1][: len(f) // 10].sum() < 0.5 * f.sum()
    assert f.sum() / (RHO * G * H * W) == pytest.approx(unbalanced_force_ratio(far), rel=1e-6)


def test_a_limit_under_the_floor_is_raised_to_it_and_the_stage_ends_there():
    """Where the floor times ``roundoff_factor`` exceeds the bare limit, the stage applies the
    raised limit, ends sooner and says why."""
    T = response_time(jointed_column((0.0, 0.0)).model)
    far = jointed_column((4096.0, 4096.0))
    damping = Damping.critical(rayleigh_frequency(far.model))
    bare = run_stage(far, Stage("bare", max_time=3.0 * T, damping=damping,
                                converge=Convergence(unbalanced_ratio=1e-6, roundoff_factor=None)), frames=False)
    again = jointed_column((4096.0, 4096.0))
    # 1e3 times the floor at the start (the triangles' 2.6e-7 at the reference positions) is above 1e-6
    r = run_stage(again, Stage("floor", max_time=3.0 * T, damping=damping,
                               converge=Convergence(unbalanced_ratio=1e-6, roundoff_factor=1e3)), frames=False)
    assert r.reason == "converged" and "round-off floor" in r.detail and r.steps < bare.steps
    with pytest.raises(ValueError, match="roundoff_factor"):
        Convergence(roundoff_factor=0.0)


def test_the_crack_elements_act_on_the_displacements_of_the_one_simulation_that_steps_them():
    """Positions written by hand without their displacements are refused at the next history
    row (the crack elements would act on the old ones); :meth:`Simulation.set_positions` keeps
    both, and the elements carry the tractions the move gives (the same as from ``x - x0``, to
    its round-off). A crack set handed to a second simulation reads that
    one's displacements: the first refuses to step."""
    sim = jointed_column((4096.0, 4096.0))
    top = np.flatnonzero(np.isclose(sim.x0[:, 1], sim.x0[:, 1].max()))
    sim.state.x[top, 1] += 1e-4
    with pytest.raises(ValueError, match="set_positions"):
        sim.step(ledger=True)
    sim.state.x[:] = sim.x0
    du = np.zeros_like(sim.x0)
    node = int(sim.cracks.nodes[0, 3])       # one side of one crack element moved 1e-4 m
    du[node] = [1e-4, 1e-4]
    sim.set_positions(displace=du)
    normal, shear = sim.cracks.tractions()   # from the kept displacements
    ref_normal, ref_shear = sim.cracks.tractions(sim.state.x.copy())   # from x - x0, a copy
    moved = np.flatnonzero((sim.cracks.nodes == node).any(axis=1))
    assert np.abs(normal[moved]).max() + np.abs(shear[moved]).max() > 0.0
    np.testing.assert_allclose(normal, ref_normal, rtol=1e-6, atol=1e-6 * np.abs(ref_normal).max())
    np.testing.assert_allclose(shear, ref_shear, rtol=1e-6, atol=1e-6 * np.abs(ref_shear).max())
    sim.step(ledger=True)                    # the check passes
    from fdem.solve.simulation import Simulation

    other = Simulation(sim.model, providers=sim.providers, progress=False)
    with pytest.raises(RuntimeError, match="handed to another Simulation"):
        sim.step()
    other.step()
