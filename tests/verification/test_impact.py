"""Two-body frictionless impact through the full solver (triangles + crack elements + contact):
momentum is conserved to round-off and total energy to 1 % (verification.md), across contact
penalties from 10 E to 1000 E."""
import numpy as np
import pytest

from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.contact import ContactSet
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import rectangle
from fdem.physics.elastic import ElasticMaterial
from fdem.mesh.triangulate import mesh_geometry
from fdem.solve.model import Model
from fdem.solve.simulation import Simulation
from fdem.mesh.topology import build_topology

E, NU, RHO = 1e9, 0.25, 2500.0


@pytest.mark.parametrize("alpha", [10.0, 100.0, 1000.0])
def test_frictionless_impact_conserves_momentum_and_energy(alpha):
    left, right = rectangle(0.0, 0.0, 1.0, 0.5, "left"), rectangle(1.0, 0.1, 1.0, 0.5, "right")
    topo = build_topology(mesh_geometry(Geometry([left, right]), 0.25))
    model = Model(topo, ElasticMaterial(young=E, poisson=NU, density=RHO))
    body = np.repeat(topo.triangle_body, 3)
    model.set_initial_velocity(vx=2.0, where=np.flatnonzero(body == 0))
    model.set_initial_velocity(vx=-1.0, where=np.flatnonzero(body == 1))
    glue = CrackProperties(f_t=1e12, c=1e12, phi=30.0, G_I=1e15, G_II=1e15, p_n=10 * E)
    cracks = CrackSet(topo, {0: glue})
    contact = ContactSet(topo, alpha * E, friction_angle=0.0, mass=model.node_mass(), cracks=cracks)
    # Bodies start 0 apart at x = 1 (touching, not overlapping): they collide at once.
    # Half the default dt_fraction factor: the energy error of a violent penalty impact converges
    # at about second order in dt (alpha = 10: 1.3 % at 0.8, 0.21 % at 0.4, 0.036 % at 0.2).
    sim = Simulation(model, providers=[cracks, contact], progress=False, dt_fraction=0.4)
    m = sim.state.mass
    p0 = (m[:, None] * sim.state.v).sum(axis=0)
    t_contact = 3 * 1.0 / np.sqrt(E / RHO)  # a few wave transits: the bodies separate again
    sim.run(t_end=t_contact, history_every=50, energy_tolerance=None)
    p1 = (m[:, None] * sim.state.v).sum(axis=0)
    assert np.all(np.abs(p1 - p0) <= 1e-10 * np.abs(m * np.hypot(*sim.state.v.T)).sum())
    first, last = sim.history[0], sim.history[-1]
    total0 = first["kinetic"] + first["strain"]
    energies = [r["kinetic"] + r["strain"] + r["crack_elastic"] + r["contact_elastic"] for r in sim.history]
    assert max(abs(e - total0) for e in energies) < 0.01 * total0
    # The contact really acted: the left body slowed down.
    v_left = (m[body == 0, None] * sim.state.v[body == 0]).sum(axis=0)[0] / m[body == 0].sum()
    assert v_left < 1.5
    assert last["friction"] == 0.0
