"""The instability guard tells crushing from a time-step problem (:meth:`Simulation._instability_kind`).

A column under 10^4 g is crushed: a four-times smaller step inverts the same triangle at the
same time, and the guard says crushing (a smaller step will not help). A step above the
critical one makes the highest mode grow: the guard says time step and suggests a stable one.
"""
from __future__ import annotations

import pytest

from fdem.geometry.polygons import rectangle
from fdem.geometry.section import Geometry
from fdem.mesh.topology import build_topology
from fdem.mesh.triangulate import mesh_geometry
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.elastic import ElasticMaterial
from fdem.solve.model import Model
from fdem.solve.simulation import InstabilityError, Simulation

E, NU, RHO = 1e9, 0.25, 2500.0


def column(gravity: float, dt_fraction: float = 0.8) -> Simulation:
    """A 1 m x 2 m column of glued triangles on a fixed base under ``gravity`` [m/s^2]."""
    topo = build_topology(mesh_geometry(Geometry([rectangle(0.0, 0.0, 1.0, 2.0, "column")]), 0.25))
    model = Model(topo, ElasticMaterial(E, NU, RHO))
    model.set_gravity(0.0, -gravity)
    model.fix("bottom")
    glue = CrackProperties(f_t=1e11, c=1e11, phi=45.0, G_I=1e15, G_II=1e15, p_n=10 * E)
    return Simulation(model, providers=[CrackSet(topo, {0: glue})], progress=False, dt_fraction=dt_fraction)


def failure(sim: Simulation) -> InstabilityError:
    with pytest.raises(InstabilityError) as err:
        sim.run(t_end=0.05, history_every=10, output_every=10**9)
    return err.value


def test_a_column_crushed_by_ten_thousand_g_is_called_crushing_at_any_step():
    coarse, fine = failure(column(9.81e4)), failure(column(9.81e4, dt_fraction=0.2))
    assert coarse.kind == fine.kind == "crushing"
    assert "a smaller step is unlikely to change" in str(coarse)
    # the evidence holds: the same triangle inverts at the same time with a 4x smaller step
    assert coarse.triangle == fine.triangle
    assert abs(coarse.time - fine.time) < 0.01 * coarse.time


@pytest.mark.parametrize("factor", [1.5, 3.0])
def test_a_step_above_critical_is_called_a_time_step_problem(factor):
    sim = column(9.81)
    critical = sim.critical_dt()[0]
    # past the refusal, as a wrong stable_dt would be (the combined bound is conservative: 1.05x
    # of it stays stable on this column)
    sim._choose_dt = lambda: factor * critical
    sim.state.v[:, 1] = 1e-3 * (-1.0) ** sim.state.v[:, 0].size  # a nudge for every mode
    sim.state.v[::2, 0] = 1e-3
    err = failure(sim)
    assert err.kind == "time step" and "try dt <=" in str(err)
    assert err.suggested_dt < critical
