"""Gmsh meshing conforming to the DFN, quality report, .msh round trip, and the exploded topology."""
import re
import warnings
from collections import Counter

import numpy as np
import pytest

from fdem.geometry.joint_sets import BrickSet, IntermittentSet, SegmentSet
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import rectangle, simple_slope
from fdem.mesh.mesh import Mesh, structured_rectangle
from fdem.mesh.triangulate import mesh_geometry
from fdem.mesh.quality import quality_report
from fdem.mesh.topology import build_topology
from fdem.mesh.triangles import check_triangles

from conftest import ROOT

MESHES = ROOT / "meshes"


def small_slope_model():
    slope = simple_slope(height=6, face_angle=45, crest_length=6, toe_length=6, base_depth=3)
    return Geometry([slope], [BrickSet(dip=15, spacing=1.5), IntermittentSet(dip=115, trace_length=2,
                                                                           bridge_length=1, row_spacing=2.5,
                                                                           stagger=1.0)],
                 min_joint_length=0.05)


@pytest.fixture(scope="module")
def slope_model():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = small_slope_model()
        model.dfn()
    return model


@pytest.fixture(scope="module")
def slope_mesh(slope_model):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return mesh_geometry(slope_model, 0.4)


@pytest.fixture(scope="module")
def slope_topology(slope_mesh):
    return build_topology(slope_mesh)


def test_crack_count_equals_interior_edges(slope_mesh, slope_topology):
    count = Counter()
    for tri in slope_mesh.triangles:
        for k in range(3):
            a, b = tri[k], tri[(k + 1) % 3]
            count[(min(a, b), max(a, b))] += 1
    interior = sum(1 for c in count.values() if c == 2)
    exterior = sum(1 for c in count.values() if c == 1)
    assert slope_topology.n_cracks == interior
    assert len(slope_topology.boundary_edges) == exterior
    # Euler: 3 T = 2 E_int + E_ext.
    assert 3 * slope_topology.n_triangles == 2 * interior + exterior


def test_crack_node_pairs_coincide_and_normal_points_from_a_to_b(slope_topology):
    x, c = slope_topology.x0, slope_topology.crack_nodes
    assert np.array_equal(x[c[:, 0]], x[c[:, 3]])
    assert np.array_equal(x[c[:, 1]], x[c[:, 2]])
    t = x[c[:, 1]] - x[c[:, 0]]
    n = np.column_stack([t[:, 1], -t[:, 0]])
    tri = slope_topology.triangles
    centroid_b = x[tri[slope_topology.crack_triangles[:, 1]]].mean(axis=1)
    centroid_a = x[tri[slope_topology.crack_triangles[:, 0]]].mean(axis=1)
    assert np.all(((centroid_b - x[c[:, 0]]) * n).sum(axis=1) > 0)
    assert np.all(((centroid_a - x[c[:, 0]]) * n).sum(axis=1) < 0)
    assert np.allclose(slope_topology.crack_length0, np.linalg.norm(t, axis=1))


def _distance_to_segments(p, segs):
    a, b = segs[:, 0], segs[:, 1]
    ab = b - a
    s = np.clip(((p[:, None] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1)[None], 0, 1)
    return np.linalg.norm(p[:, None] - (a[None] + s[..., None] * ab[None]), axis=-1)


def test_joint_edges_lie_on_joints_and_cover_them(slope_model, slope_topology):
    dfn = slope_model.dfn()
    tol = 1e-9 * slope_model.size
    x, c, tag = slope_topology.x0, slope_topology.crack_nodes, slope_topology.crack_tag
    assert set(np.unique(tag)) == {0, 1, 2}
    for j in (1, 2):
        segs = dfn.segments[dfn.set_id == j]
        on = tag == j
        p, q = x[c[on, 0]], x[c[on, 1]]
        dp, dq = _distance_to_segments(p, segs), _distance_to_segments(q, segs)
        # Both ends of each tagged edge on one and the same segment of its set.
        same = (dp <= tol) & (dq <= tol)
        assert same.any(axis=1).all(), f"joint set {j}: tagged edge off its joints"
        covered = np.zeros(len(segs))
        owner = np.argmax(same, axis=1)
        np.add.at(covered, owner, slope_topology.crack_length0[on])
        lengths = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
        assert np.allclose(covered, lengths, rtol=1e-9, atol=tol), f"joint set {j}: segment not fully covered"
    # No intact edge lies along a joint: its midpoint is off every joint (or it crosses one).
    intact = tag == 0
    mid = 0.5 * (x[c[intact, 0]] + x[c[intact, 1]])
    d = _distance_to_segments(mid, dfn.segments).min(axis=1)
    assert np.all(d > tol)


def test_areas_positive_and_sum_to_domain(slope_model, slope_topology):
    a = slope_topology.triangle_area0
    assert np.all(a > 0)
    assert a.sum() == pytest.approx(slope_model.area, rel=1e-12)


def test_boundary_groups_and_node_selection(slope_model, slope_topology):
    x0, y0, x1, y1 = slope_model.bounds
    bottom = slope_topology.nodes_in_group("bottom")
    assert np.allclose(slope_topology.x0[bottom, 1], y0)
    by_predicate = slope_topology.nodes_where(lambda x, y: np.isclose(y, y0))
    assert np.array_equal(bottom, by_predicate)
    assert np.allclose(slope_topology.x0[slope_topology.nodes_in_group("left"), 0], x0)
    assert np.allclose(slope_topology.x0[slope_topology.nodes_in_group("right"), 0], x1)
    surface = slope_topology.x0[slope_topology.nodes_in_group("surface")]
    assert surface[:, 1].max() == pytest.approx(y1)
    with pytest.raises(KeyError, match="no physical group named 'top'"):
        slope_topology.nodes_in_group("top")


def test_same_input_same_mesh(slope_model, slope_mesh):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = mesh_geometry(slope_model, 0.4)
    assert np.array_equal(again.points, slope_mesh.points)
    assert np.array_equal(again.triangles, slope_mesh.triangles)
    assert np.array_equal(again.lines, slope_mesh.lines)


def test_msh_round_trip(tmp_path, slope_mesh):
    path = tmp_path / "slope.msh"
    slope_mesh.save(path)
    back = Mesh.load(path)
    assert np.allclose(back.points, slope_mesh.points, rtol=0, atol=1e-12)
    assert np.array_equal(back.triangles, slope_mesh.triangles)
    assert back.group_names == slope_mesh.group_names
    assert np.array_equal(back.lines, slope_mesh.lines)
    assert np.array_equal(back.line_group, slope_mesh.line_group)


def test_stored_small_meshes_are_valid():
    files = sorted(MESHES.glob("*.msh"))
    assert files, "meshes/ should hold the small meshes the tests and quick cases use"
    for f in files:
        mesh = Mesh.load(f)
        topo = build_topology(mesh)
        assert np.all(topo.triangle_area0 > 0)
        assert 3 * topo.n_triangles == 2 * topo.n_cracks + len(topo.boundary_edges)


def test_quality_report(slope_mesh):
    r = quality_report(slope_mesh, worst=3)
    assert r.n_triangles == slope_mesh.n_triangles
    assert 0 < r.min_angle_deg <= r.mean_min_angle_deg <= 60
    assert r.edge_min <= r.edge_mean <= r.edge_max
    assert len(r.worst) == 3 and r.worst[0][1] == pytest.approx(r.min_angle_deg)
    d = r.as_dict()
    assert d["n_triangles"] == r.n_triangles and "worst" in d


def test_refinement_near_joints_makes_smaller_edges_there():
    model = Geometry([rectangle(0, 0, 10, 5)], [SegmentSet([[2, 2.5, 8, 2.5]])])
    coarse = build_topology(mesh_geometry(model, 0.5))
    fine = build_topology(mesh_geometry(model, 0.5, refine_near_joints=0.25, refine_distance=1.0))
    on_joint = lambda t: t.crack_length0[t.crack_tag == 1]
    assert on_joint(fine).mean() < 0.5 * on_joint(coarse).mean()
    assert fine.n_triangles > coarse.n_triangles


def test_two_bodies_share_no_nodes_and_no_crack_elements():
    base = rectangle(0, 0, 6, 1, "incline")
    block = rectangle(2, 1, 1, 1, "block")
    mesh = mesh_geometry(Geometry([base, block]), 0.25)
    topo = build_topology(mesh)
    assert set(np.unique(mesh.triangle_body)) == {0, 1}
    used = [set(mesh.triangles[mesh.triangle_body == b].ravel()) for b in (0, 1)]
    assert not used[0] & used[1]
    body_a = topo.triangle_body[topo.crack_triangles[:, 0]]
    body_b = topo.triangle_body[topo.crack_triangles[:, 1]]
    assert np.array_equal(body_a, body_b)
    areas = topo.triangle_area0
    assert areas[topo.triangle_body == 1].sum() == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("size", [0.0, -0.1, float("nan")])
def test_non_positive_mesh_size(size):
    with pytest.raises(ValueError, match="mesh size must be positive"):
        mesh_geometry(Geometry([rectangle(0, 0, 1, 1)]), size)


def test_degenerate_and_inverted_triangles_are_named():
    pts = np.array([[0, 0], [1, 0], [0, 1], [2, 0], [1.5, 0.0]], dtype=float)
    inverted = Mesh(points=pts, triangles=np.array([[0, 1, 2], [0, 2, 1]]), triangle_body=np.zeros(2, np.int32))
    with pytest.raises(ValueError, match=r"triangle 1 is inverted .* corners \(0, 0\), \(0, 1\), \(1, 0\)"):
        build_topology(inverted)
    degenerate = Mesh(points=pts, triangles=np.array([[0, 1, 2], [1, 3, 4]]), triangle_body=np.zeros(2, np.int32))
    with pytest.raises(ValueError, match=r"triangle 1 is degenerate"):
        check_triangles(degenerate.points, degenerate.triangles)


def test_small_angle_warning_names_count_and_worst_angle():
    model = Geometry([rectangle(0, 0, 10, 10)], [SegmentSet([[1, 5, 9, 5], [1, 4.5, 9, 5.3]])])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mesh_geometry(model, 1.0)
    messages = [str(w.message) for w in caught]
    assert any("1 joint crossing(s) sharper than 15 deg (worst 5.71 deg)" in m for m in messages), messages
    assert any(re.search(r"\d+ triangle\(s\) have an angle below 10 deg \(worst \d+\.\d+ deg", m)
               for m in messages), messages


def test_structured_rectangle_topology_counts():
    topo = build_topology(structured_rectangle(4, 3, 4.0, 3.0))
    assert topo.n_triangles == 24
    # Interior edges: horizontal 4*2 + vertical 3*3 + diagonals 12.
    assert topo.n_cracks == 8 + 9 + 12
    assert topo.triangle_area0.sum() == pytest.approx(12.0)


def test_jittered_rectangle_keeps_area_and_boundary():
    from fdem.mesh.mesh import jittered_rectangle

    mesh = jittered_rectangle(6, 5, 3.0, 2.0, amount=0.3, seed=4)
    topo = build_topology(mesh)
    assert np.all(topo.triangle_area0 > 0)
    assert topo.triangle_area0.sum() == pytest.approx(6.0, rel=1e-12)
    assert not np.allclose(mesh.points, structured_rectangle(6, 5, 3.0, 2.0).points)
    with pytest.raises(ValueError, match="amount must lie in"):
        jittered_rectangle(2, 2, 1.0, 1.0, amount=0.5)
