"""Memory order (:mod:`fdem.mesh.order`): a mesh renumbered along a Hilbert curve is the same mesh,
its crack elements come out in a local order, each colour of the crack pass sweeps memory
forward, and a renumbered scene gives the same physics as the one in Gmsh's order (the planar
slope's factor-of-safety bracket against Hoek-Bray, a block sliding on an incline, a two-body
impact, the energy ledger), equal to round-off."""
from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest

from fdem.geometry.polygons import rectangle
from fdem.geometry.section import Geometry
from fdem.mesh.mesh import Mesh, jittered_rectangle
from fdem.mesh.order import ORDERS, hilbert_key, morton_key, renumber
from fdem.mesh.topology import build_topology
from fdem.mesh.triangulate import mesh_geometry
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet, _legacy_colour_major_order

from test_mesh_topology import small_slope_model


@pytest.fixture(scope="module")
def meshes():
    """The jointed slope of the topology tests (brick and intermittent joint sets, ~1,000
    triangles) in Gmsh's numbering and renumbered along the Hilbert curve."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geometry = small_slope_model()
        return mesh_geometry(geometry, 0.4, order=None), mesh_geometry(geometry, 0.4)


def grid_points(bits: int) -> np.ndarray:
    """Centres of the ``2^bits`` x ``2^bits`` unit cells, plus the two corners that fix the box."""
    n = 1 << bits
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    centres = np.column_stack([i.ravel(), j.ravel()]) + 0.5
    return np.vstack([centres, [[0.0, 0.0], [n, n]]])


def rows(a: np.ndarray, decimals: int = 9) -> set:
    """The rows of ``a`` as a set of rounded tuples (order-free comparison)."""
    return set(map(tuple, np.round(np.asarray(a, dtype=np.float64), decimals)))


# ----------------------------------------------------------------------------- the curves


def test_hilbert_key_visits_every_cell_once_stepping_to_an_edge_neighbour():
    bits = 4
    pts = grid_points(bits)
    key = hilbert_key(pts, bits)[:-2]
    assert np.array_equal(np.sort(key), np.arange(1 << 2 * bits))
    walk = np.floor(pts[:-2][np.argsort(key)])
    # Continuity of the curve: each step moves to a cell sharing an edge (Manhattan distance 1).
    assert np.all(np.abs(np.diff(walk, axis=0)).sum(axis=1) == 1)


def test_morton_key_interleaves_the_bits_of_the_cell_coordinates():
    bits = 3
    pts = grid_points(bits)
    key = morton_key(pts, bits)[:-2]
    i, j = np.floor(pts[:-2]).astype(np.int64).T
    expected = sum((((i >> b) & 1) << 2 * b) | (((j >> b) & 1) << (2 * b + 1)) for b in range(bits))
    assert np.array_equal(key, expected)
    assert np.array_equal(np.sort(key), np.arange(1 << 2 * bits))


# ----------------------------------------------------------------------------- the mesh


def triangle_rows(mesh: Mesh) -> np.ndarray:
    """Each triangle as its corners (counter-clockwise, starting at its first corner), body and area."""
    from fdem.mesh.triangles import triangle_areas

    p = mesh.points[mesh.triangles].reshape(-1, 6)
    return np.column_stack([p, mesh.triangle_body, triangle_areas(mesh.points, mesh.triangles)])


def group_edges(mesh: Mesh, name: str) -> set:
    """The line elements of a physical group as unordered pairs of end points."""
    g = mesh.group_names.index(name)
    ends = mesh.points[mesh.lines[mesh.line_group == g]]
    return {frozenset(map(tuple, np.round(e, 9))) for e in ends}


def test_renumbered_mesh_is_the_same_mesh(meshes):
    gmsh_order, hilbert = meshes
    assert hilbert.n_triangles == gmsh_order.n_triangles and len(hilbert.points) == len(gmsh_order.points)
    # Same triangles, each with the same corners in the same counter-clockwise order, body and area.
    assert rows(triangle_rows(hilbert)) == rows(triangle_rows(gmsh_order))
    assert hilbert.area() == pytest.approx(gmsh_order.area(), rel=1e-14)
    assert rows(hilbert.points) == rows(gmsh_order.points)
    # Same physical groups, the same curves in each, the same joint edges with their set ids.
    assert hilbert.group_names == gmsh_order.group_names
    for name in hilbert.group_names:
        assert group_edges(hilbert, name) == group_edges(gmsh_order, name)
        assert rows(hilbert.points[hilbert.group_nodes(name)]) == rows(gmsh_order.points[gmsh_order.group_nodes(name)])
    joints = []
    for m in (hilbert, gmsh_order):
        keys, sets = m.joint_edge_keys()
        a, b = np.divmod(keys, len(m.points))
        joints.append({(frozenset(map(tuple, np.round(m.points[[i, j]], 9))), s) for i, j, s in zip(a, b, sets)})
    assert joints[0] == joints[1] and len(joints[0]) > 50


def test_renumbering_orders_triangles_along_the_curve_and_points_by_first_use(meshes):
    _, hilbert = meshes
    centroids = hilbert.points[hilbert.triangles].mean(axis=1)
    assert np.all(np.diff(hilbert_key(centroids)) >= 0)
    first = np.unique(hilbert.triangles.ravel(), return_index=True)[1]
    assert np.all(np.diff(first) > 0)    # point i is first used before point i+1


def test_a_given_mesh_keeps_its_numbering_unless_renumbering_is_asked_for(tmp_path):
    mesh = jittered_rectangle(7, 5, 3.5, 2.5, seed=3)
    assert renumber(mesh, None) is mesh
    path = tmp_path / "user.msh"
    mesh.save(path)
    again = Mesh.load(path)
    assert np.array_equal(again.triangles, mesh.triangles) and np.array_equal(again.points, mesh.points)
    # Asked for, it is the same mesh renumbered: same triangles, every boundary group intact.
    for order in ORDERS:
        r = renumber(again, order)
        assert not np.array_equal(r.triangles, mesh.triangles)
        assert rows(triangle_rows(r)) == rows(triangle_rows(mesh))
        for name in mesh.group_names:
            assert group_edges(r, name) == group_edges(mesh, name)


def test_two_bodies_stay_apart_after_renumbering():
    geometry = Geometry([rectangle(0.0, 0.0, 4.0, 0.5, "base"), rectangle(1.0, 0.5, 1.0, 1.0, "block")])
    mesh = mesh_geometry(geometry, 0.25)
    shared = np.intersect1d(mesh.triangles[mesh.triangle_body == 0], mesh.triangles[mesh.triangle_body == 1])
    assert shared.size == 0
    assert rows(triangle_rows(mesh)) == rows(triangle_rows(mesh_geometry(geometry, 0.25, order=None)))


def test_mesh_geometry_refuses_an_unknown_order():
    with pytest.raises(ValueError, match="unknown mesh order 'peano'"):
        mesh_geometry(Geometry([rectangle(0.0, 0.0, 1.0, 1.0)]), 0.25, order="peano")


# ----------------------------------------------------------------------------- topology and crack pass


def crack_rows(topo) -> np.ndarray:
    """Each crack element as its edge (unordered end points), joint-set tag and length."""
    ends = np.sort(np.round(topo.x0[topo.crack_nodes[:, :2]], 9).reshape(-1, 4), axis=1)
    return np.column_stack([ends, topo.crack_tag, topo.crack_length0])


def test_topology_has_the_same_crack_elements_in_a_local_order(meshes):
    a, b = (build_topology(m) for m in meshes)
    assert rows(crack_rows(a)) == rows(crack_rows(b))
    assert a.n_cracks == b.n_cracks and len(a.boundary_edges) == len(b.boundary_edges)
    # Memory distance between the two triangles of a crack element (their nodes are 3t..3t+2).
    gap_gmsh = np.median(np.abs(np.diff(a.crack_triangles, axis=1)))
    gap_hilbert = np.median(np.abs(np.diff(b.crack_triangles, axis=1)))
    assert gap_hilbert * 20 < gap_gmsh and gap_hilbert <= 4
    # Topology order (by the edge's smaller point id) follows the triangles: consecutive crack
    # elements sit a few triangles apart.
    first = b.crack_triangles.min(axis=1)
    assert np.median(np.abs(np.diff(first))) <= 4


def rock(young: float = 1e9) -> CrackProperties:
    return CrackProperties(f_t=1e5, c=2e5, phi=30.0, G_I=5.0, G_II=20.0, p_n=10 * young)


def test_each_colour_sweeps_its_triangles_forward(meshes):
    topo = build_topology(meshes[1])
    cracks = CrackSet(topo, {t: rock() for t in np.unique(topo.crack_tag)}, parallel_min=0)
    tri = np.sort(topo.crack_triangles[cracks._perm], axis=1)
    ptr = cracks._colour_ptr
    for c in range(cracks.n_colours):
        lo, hi = ptr[c], ptr[c + 1]
        assert np.all(np.diff(tri[lo:hi, 0]) >= 0)
        nodes = cracks._nodes[lo:hi].ravel()
        assert np.unique(nodes).size == nodes.size       # still race-free: no node twice in a colour
    # Public arrays stay in topology order.
    assert np.array_equal(np.sort(cracks.active), np.arange(topo.n_cracks))
    assert np.array_equal(cracks.nodes, topo.crack_nodes) and np.array_equal(cracks.tag, topo.crack_tag)


def damaged_crack_set(topo, rng):
    """A crack set pushed into softening by random nodal displacements of 2 peak openings."""
    cracks = CrackSet(topo, {t: rock() for t in np.unique(topo.crack_tag)}, parallel_min=0)
    x = topo.x0 + 2e-4 * rng.standard_normal(topo.x0.shape)
    f = np.zeros_like(x)
    cracks.add_forces(x, np.zeros_like(x), f, 1e-6, 0)
    return cracks, x


def test_colour_forces_equal_gather_forces_in_the_new_order(meshes):
    topo = build_topology(meshes[1])
    x = topo.x0 + 2e-4 * np.random.default_rng(1).standard_normal(topo.x0.shape)
    forces = {}
    for scheme in ("colour", "gather"):
        cracks = CrackSet(topo, {t: rock() for t in np.unique(topo.crack_tag)}, scheme=scheme, parallel_min=0)
        f = np.zeros_like(x)
        cracks.add_forces(x, np.zeros_like(x), f, 1e-6, 0)
        forces[scheme] = (f, cracks.damage_ip, cracks.broken)
        assert 0 < cracks.broken.sum() < topo.n_cracks and cracks.n_inelastic() > cracks.broken.sum()
    # A node is an end of at most two crack elements: the sum is the same whichever adds first.
    for a, b in zip(forces["colour"], forces["gather"]):
        assert np.array_equal(a, b)


def test_a_state_saved_in_the_old_internal_order_loads_into_the_new_one(meshes):
    topo = build_topology(meshes[1])
    cracks, x = damaged_crack_set(topo, np.random.default_rng(2))
    state = cracks.state_dict()
    colour = np.empty(topo.n_cracks, np.int32)
    colour[cracks._perm] = cracks._colour
    legacy = _legacy_colour_major_order(colour)
    assert not np.array_equal(legacy, cracks._perm)
    # What an older crack set wrote: the same rows in its own order, and no "order" entry.
    to_legacy = cracks._inv[legacy]
    old = {k: v for k, v in state.items() if k != "order"}
    for k in ("const", "status", "state", "diss", "offset", "dilation", "broke_flag"):
        old[k] = state[k][to_legacy]
    old["active"] = np.sort(np.argsort(to_legacy)[state["active"]])
    fresh = CrackSet(topo, {t: rock() for t in np.unique(topo.crack_tag)}, parallel_min=0)
    fresh.load_state_dict(old)
    assert np.array_equal(fresh.damage_ip, cracks.damage_ip) and np.array_equal(fresh.active, cracks.active)
    assert np.array_equal(fresh.dissipated, cracks.dissipated)
    x1 = x + 1e-4 * np.random.default_rng(3).standard_normal(x.shape)
    f_a, f_b = np.zeros_like(x), np.zeros_like(x)
    cracks.add_forces(x1, np.zeros_like(x), f_a, 1e-6, 1)
    fresh.add_forces(x1, np.zeros_like(x), f_b, 1e-6, 1)
    assert np.array_equal(f_a, f_b) and np.array_equal(fresh.damage_ip, cracks.damage_ip)


# ----------------------------------------------------------------------------- same physics


def with_gmsh_order(monkeypatch, module):
    """Make ``module`` mesh in Gmsh's own numbering (the cases call ``mesh_geometry`` by name)."""
    monkeypatch.setattr(module, "mesh_geometry", functools.partial(mesh_geometry, order=None))


def test_planar_slope_fos_bracket_is_the_same_renumbered(monkeypatch):
    """Strength reduction on the no-crack planar slope (236 triangles), bisected on [1.2, 1.6]:
    the same trials, verdicts and bracket, around the Hoek-Bray factor 1.396."""
    import fdem.cases.planar_failure as pf

    hilbert = pf.run_case("no_crack", size=2.0, lower=1.2, upper=1.6, tol=0.1)
    with_gmsh_order(monkeypatch, pf)
    gmsh_order = pf.run_case("no_crack", size=2.0, lower=1.2, upper=1.6, tol=0.1)
    assert hilbert["bracket"] == gmsh_order["bracket"]
    lo, hi = hilbert["bracket"]
    assert lo <= hilbert["analytic_fos"] <= hi
    assert hilbert["failure_surface_tags"] == gmsh_order["failure_surface_tags"] == {1: 9}
    for a, b in zip(hilbert["trials"], gmsh_order["trials"]):
        assert a["factor"] == b["factor"] and a["stable"] == b["stable"] and a["steps"] == b["steps"]
        assert a["max_displacement"] == pytest.approx(b["max_displacement"], rel=1e-6)


def test_block_on_incline_slides_the_same_renumbered(monkeypatch):
    """theta = 30, phi = 20 deg for 0.3 s: the same slide (and the rigid-block answer), rotation,
    friction work and a closed energy ledger, renumbered or not."""
    import fdem.cases.block_on_incline as inc

    hilbert = inc.run(30.0, 20.0, t_end=0.3)
    with_gmsh_order(monkeypatch, inc)
    gmsh_order = inc.run(30.0, 20.0, t_end=0.3)
    assert hilbert["steps"] == gmsh_order["steps"]
    assert hilbert["slide_m"] == pytest.approx(gmsh_order["slide_m"], rel=1e-6)
    assert hilbert["slide_m"] == pytest.approx(hilbert["exact_m"], rel=0.02)
    assert abs(hilbert["rotation_deg"] - gmsh_order["rotation_deg"]) < 1e-6
    assert hilbert["friction_work_J_per_m"] == pytest.approx(gmsh_order["friction_work_J_per_m"], rel=1e-6)
    for r in (hilbert, gmsh_order):
        assert abs(r["balance_error_relative"]) < 1e-4
    assert hilbert["balance_error_relative"] == pytest.approx(gmsh_order["balance_error_relative"], abs=1e-6)


def impact(order):
    """The two-body frictionless impact of the verification tests (penalty 10 E)."""
    from fdem.physics.contact import ContactSet
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    E = 1e9
    left, right = rectangle(0.0, 0.0, 1.0, 0.5, "left"), rectangle(1.0, 0.1, 1.0, 0.5, "right")
    topo = build_topology(mesh_geometry(Geometry([left, right]), 0.25, order=order))
    model = Model(topo, ElasticMaterial(young=E, poisson=0.25, density=2500.0))
    body = np.repeat(topo.triangle_body, 3)
    model.set_initial_velocity(vx=2.0, where=np.flatnonzero(body == 0))
    model.set_initial_velocity(vx=-1.0, where=np.flatnonzero(body == 1))
    glue = CrackProperties(f_t=1e12, c=1e12, phi=30.0, G_I=1e15, G_II=1e15, p_n=10 * E)
    cracks = CrackSet(topo, {0: glue})
    contact = ContactSet(topo, 10 * E, friction_angle=0.0, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=False, dt_fraction=0.4)
    sim.run(t_end=3.0 / np.sqrt(E / 2500.0), history_every=50, energy_tolerance=None)
    return sim, topo


def by_reference(topo, a: np.ndarray) -> np.ndarray:
    """Per-node rows of ``a`` in an order-free sequence: by reference position, then by the
    centroid of the node's triangle (coincident nodes of neighbouring triangles)."""
    c = np.repeat(topo.x0[topo.triangles].mean(axis=1), 3, axis=0)
    key = np.round(np.column_stack([topo.x0, c]), 9)
    return a[np.lexsort(key.T[::-1])]


def test_impact_gives_the_same_motion_and_energies_renumbered():
    (sim_h, topo_h), (sim_g, topo_g) = impact("hilbert"), impact(None)
    assert sim_h.state.step == sim_g.state.step and sim_h.dt == sim_g.dt
    scale = np.abs(sim_g.state.x - sim_g.x0).max()
    dx = by_reference(topo_h, sim_h.state.x) - by_reference(topo_g, sim_g.state.x)
    assert np.abs(dx).max() <= 1e-9 * scale
    dv = by_reference(topo_h, sim_h.state.v) - by_reference(topo_g, sim_g.state.v)
    assert np.abs(dv).max() <= 1e-9 * np.abs(sim_g.state.v).max()
    for a, b in zip(sim_h.history, sim_g.history):
        for k in ("kinetic", "strain", "contact_elastic", "crack_elastic"):
            assert a[k] == pytest.approx(b[k], rel=1e-9, abs=1e-12 * (b["kinetic"] + b["strain"]))
        assert abs(a["balance_error_relative"]) < 0.01
