"""Contact of softening crack elements through loose vertices (``ContactSet(softening="vertex")``).

The scene: a small block, fixed at its base, whose upper part is thrown sideways and down, so
that crack elements in a band damage and slide (a few break late in the run). The reduced
candidate list (vertex-neighbour pairs around loose vertices, no search while nothing has
broken) is checked against a brute-force search over *every* triangle pair that no intact
crack element bonds, at every step, and the run is compared with the unreduced contact
(``softening="all"``: every triangle of a softening element searched against every other).
"""
from __future__ import annotations

import numpy as np
import pytest

from fdem.physics import contact as fc
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.contact import ContactSet
from fdem.kernels import contact_pairs as kc
from fdem.physics.elastic import ElasticMaterial
from fdem.mesh.mesh import structured_rectangle
from fdem.solve.model import Model
from fdem.solve.simulation import Simulation
from fdem.mesh.topology import build_topology

STEPS = 400


def scene(softening: str, loose_fraction: float = fc.LOOSE_FRACTION):
    topo = build_topology(structured_rectangle(8, 6, 0.8, 0.6))
    model = Model(topo, ElasticMaterial(young=1e9, poisson=0.25, density=2500.0))
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    model.set_initial_velocity(vx=1.0, vy=-0.5, where=np.flatnonzero(topo.x0[:, 1] > 0.35))
    rock = CrackProperties(f_t=2e5, c=4e5, phi=30.0, G_I=50.0, G_II=200.0, p_n=1e10, name="rock")
    cracks = CrackSet(topo, {0: rock}, contact_penalty=1e10)
    contact = ContactSet(topo, 1e10, friction_angle=30.0, mass=model.node_mass(), cracks=cracks,
                         softening=softening, loose_fraction=loose_fraction)
    sim = Simulation(model, providers=[cracks, contact], progress=False)
    return sim, cracks, contact


def overlapping_pairs(topo, x, broken):
    """Brute force: every pair of triangles, no intact crack element between them, whose
    overlap area is positive at ``x``; with the areas."""
    bond = fc._bond_table(topo, ~broken)
    allp = fc.brute_force_candidate_pairs(x, np.arange(topo.n_triangles), bond, 0.0)
    area = kc.overlap_areas(x, np.ascontiguousarray(allp[:, 0]), np.ascontiguousarray(allp[:, 1]))
    return allp[area > 0], area[area > 0]


@pytest.fixture(scope="module")
def reduced_run():
    """Every step of a softening run: the reduced list against the brute-force overlaps."""
    sim, cracks, contact = scene("vertex")
    topo = sim.model.topology
    corners = topo.mesh_node.reshape(-1, 3)
    area0 = np.abs(topo.triangle_area0)
    log = {"missing": [], "skipped_energy": 0.0, "skipped_force": 0.0, "max_rel_area": 0.0, "n_skipped": 0,
           "n_kept_overlaps": 0, "searches_unbroken": None}
    for k in range(STEPS):
        sim.step(ledger=(k % 50 == 0))
        if not cracks.broken.any():
            log["searches_unbroken"] = contact.n_searches
        x = sim.state.x
        pairs, area = overlapping_pairs(topo, x, cracks.broken)
        listed = set() if contact.dormant else set(map(tuple, contact.pairs.tolist()))
        f_scale = np.abs(sim.f_interaction).max()
        for (i, j), a in zip(pairs.tolist(), area):
            if (i, j) in listed:
                log["n_kept_overlaps"] += 1
                continue
            shared = np.intersect1d(corners[i], corners[j])
            if shared.size == 0 or contact._loose[shared].any():
                log["missing"].append((k, i, j))
                continue
            # a vertex neighbour around a vertex no softening element has loosened
            e, fc_, ft_, _ = fc.pair_energy_force(x[3 * i:3 * i + 3], x[3 * j:3 * j + 3], contact.penalty)
            log["n_skipped"] += 1
            log["skipped_energy"] = max(log["skipped_energy"], e / max(cracks.energy_terms()["crack_elastic"], 1e-300))
            if k >= 40:  # once the band carries load
                log["skipped_force"] = max(log["skipped_force"], max(np.abs(fc_).max(), np.abs(ft_).max()) / f_scale)
            log["max_rel_area"] = max(log["max_rel_area"], a / min(area0[i], area0[j]))
    return sim, cracks, contact, log


def test_every_pair_that_can_touch_is_listed(reduced_run):
    sim, cracks, contact, log = reduced_run
    assert cracks.n_inelastic() > 50 and contact.loose_vertices.size > 10    # the scene softens
    assert log["n_kept_overlaps"] > 0                                        # and contact works
    # every overlapping pair of the brute-force search is in the reduced list, unless it is a
    # vertex neighbour around vertices that are all still tight
    assert log["missing"] == []
    # and those carry next to nothing: corner slivers from the elastic compression
    assert log["max_rel_area"] < 1e-6
    assert log["skipped_energy"] < 1e-3      # of the crack elements' elastic energy
    assert log["skipped_force"] < 1e-2       # of the largest crack / contact nodal force


def test_no_search_while_nothing_is_broken(reduced_run):
    sim, cracks, contact, log = reduced_run
    # the fan list is rebuilt only when vertices loosen (every 16 steps at most), never on motion
    assert log["searches_unbroken"] is not None
    assert log["searches_unbroken"] <= STEPS // 16 + 1


def test_fan_pairs_equal_brute_force_vertex_neighbours():
    sim, cracks, contact = scene("vertex", loose_fraction=0.0)
    for _ in range(120):
        sim.step()
    topo = sim.model.topology
    corners = topo.mesh_node.reshape(-1, 3)
    loose = contact._loose
    assert loose.any() and not loose.all()
    bond = fc._bond_table(topo, ~cracks.broken)
    expect = set()
    for i in range(topo.n_triangles):
        for j in range(i + 1, topo.n_triangles):
            shared = np.intersect1d(corners[i], corners[j])
            if shared.size and loose[shared].any() and j not in bond[i]:
                expect.add((i, j))
    assert set(map(tuple, contact.fan_pairs().tolist())) == expect


def test_reduced_and_full_contact_agree():
    """Same run with the unreduced contact: positions and energies agree to a stated tolerance
    (the reduced run leaves out only the corner slivers bounded above)."""
    runs = {}
    for mode in ("vertex", "all"):
        sim, cracks, contact = scene(mode)
        sim.run(n_steps=300, history_every=50, stage="shear", progress=False, final_output=False)
        runs[mode] = (sim, cracks, contact)
    (sa, ca, ka), (sb, cb, kb) = runs["vertex"], runs["all"]
    disp = np.abs(sb.state.x - sb.model.topology.x0).max()
    assert np.abs(sa.state.x - sb.state.x).max() < 0.01 * disp
    ea, eb = ca.energy_terms(), cb.energy_terms()
    for name in ("crack_elastic", "fracture"):
        assert ea[name] == pytest.approx(eb[name], rel=0.02)
    ra, rb = sa.history[-1], sb.history[-1]
    assert ra["kinetic"] == pytest.approx(rb["kinetic"], rel=0.02)
    for row in (ra, rb):
        assert abs(row["balance_error_relative"]) < 1e-3
    # the reduced run keeps fewer contactors, pairs and searches
    assert ka.active.size < kb.active.size and ka.n_searches <= kb.n_searches


def test_loose_vertices_survive_a_restart():
    sim, cracks, contact = scene("vertex")
    for _ in range(200):
        sim.step()
    state = sim.state_dict()
    loose = contact.loose_vertices.copy()
    assert loose.size
    other, _, contact2 = scene("vertex")
    other.load_state_dict(state)
    assert np.array_equal(contact2.loose_vertices, loose)
    assert np.array_equal(contact2.active, contact.active)
    for _ in range(50):
        sim.step()
        other.step()
    assert np.array_equal(sim.state.x, other.state.x)


def test_bad_softening_mode():
    topo = build_topology(structured_rectangle(2, 2, 1.0, 1.0))
    with pytest.raises(ValueError, match="softening"):
        ContactSet(topo, 1e9, softening="some")
    with pytest.raises(ValueError, match="loose_fraction"):
        ContactSet(topo, 1e9, loose_fraction=-1.0)
