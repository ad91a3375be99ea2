"""Planar slope failure (verification.md): the Hoek-Bray limit-equilibrium factor of safety,
the slope with its persistent joint and tension crack, and the factor of safety that strength
reduction finds for it with the full solver."""
import math

import numpy as np
import pytest

from fdem.reference.hoek_bray import (critical_tension_crack, crack_depth_from_offset, crack_offset_from_depth, planar_fos)
from fdem.mesh.triangulate import mesh_geometry
from fdem.cases.planar_failure import planar_slope_geometry
from fdem.mesh.topology import build_topology

# ----------------------------------------------------------------------------- limit equilibrium


def test_dry_slope_without_crack_matches_hand_calculation():
    # H = 10 m, psi_f = 60 deg, psi_p = 35 deg, c = 20 kPa, phi = 30 deg, gamma = 25 kN/m^3, dry.
    # cot 35 = 1.428148, cot 60 = 0.577350
    # W = gamma H^2 / 2 (cot psi_p - cot psi_f) = 1.25e6 * 0.850798      = 1,063,497 N/m
    # A = H / sin psi_p = 10 / 0.573576                                   = 17.43447 m
    # resisting = c A + W cos psi_p tan phi = 348,689 + 1,063,497 * 0.819152 * 0.577350 = 851,657 N/m
    # driving = W sin psi_p = 1,063,497 * 0.573576                        = 609,997 N/m
    # F = 851,657 / 609,997                                               = 1.39617
    r = planar_fos(10.0, 60.0, 35.0, cohesion=20e3, friction_angle=30.0, unit_weight=25e3)
    assert r.W == pytest.approx(1_063_497, rel=1e-5)
    assert r.A == pytest.approx(17.43447, rel=1e-5)
    assert r.U == 0.0 and r.V == 0.0 and r.crack_depth == 0.0
    assert r.resisting == pytest.approx(851_657, rel=1e-5)
    assert r.driving == pytest.approx(609_997, rel=1e-5)
    assert r.fos == pytest.approx(1.39617, rel=1e-5)


def test_crack_half_full_of_water_matches_hand_calculation():
    # As above with a tension crack z = 4 m deep, water standing z_w = 2 m in it, gamma_w = 9.81 kN/m^3.
    # b = (H - z) cot psi_p - H cot psi_f = 6 * 1.428148 - 5.773503            = 2.795385 m
    # W = gamma H^2/2 [(1 - (z/H)^2) cot psi_p - cot psi_f] = 1.25e6 * 0.622294 = 777,867 N/m
    # A = (H - z) / sin psi_p = 6 / 0.573576                                     = 10.46067 m
    # U = gamma_w z_w A / 2 = 9810 * 10.46067                                    = 102,619 N/m
    # V = gamma_w z_w^2 / 2 = 9810 * 2                                           = 19,620 N/m
    # resisting = c A + (W cos psi_p - U - V sin psi_p) tan phi
    #           = 209,213 + (637,188 - 102,619 - 11,254) * 0.577350              = 511,349 N/m
    # driving = W sin psi_p + V cos psi_p = 446,166 + 16,072                     = 462,238 N/m
    # F = 511,349 / 462,238                                                      = 1.10625
    r = planar_fos(10.0, 60.0, 35.0, 20e3, 30.0, 25e3, tension_crack_depth=4.0, water_depth=2.0)
    assert r.crack_offset == pytest.approx(2.795385, rel=1e-5)
    assert r.W == pytest.approx(777_867, rel=1e-5)
    assert r.A == pytest.approx(10.46067, rel=1e-5)
    assert r.U == pytest.approx(102_619, rel=1e-5)
    assert r.V == pytest.approx(19_620, rel=1e-9)
    assert r.resisting == pytest.approx(511_349, rel=1e-5)
    assert r.driving == pytest.approx(462_238, rel=1e-5)
    assert r.fos == pytest.approx(1.10625, rel=1e-4)
    # The same crack given by its offset behind the crest gives the same answer.
    same = planar_fos(10.0, 60.0, 35.0, 20e3, 30.0, 25e3, tension_crack_offset=r.crack_offset, water_depth=2.0)
    assert same.fos == pytest.approx(r.fos, rel=1e-12)


@pytest.mark.parametrize("plane, crack", [(35.0, None), (35.0, 2.0), (25.0, None), (25.0, 1.0)])
def test_cohesionless_dry_plane_gives_friction_ratio(plane, crack):
    # c = 0, dry: the weight cancels, F = tan(phi) / tan(psi_p) whatever the block's shape.
    r = planar_fos(10.0, 60.0, plane, 0.0, 30.0, 25e3, tension_crack_offset=crack)
    assert r.fos == pytest.approx(math.tan(math.radians(30)) / math.tan(math.radians(plane)), rel=1e-12)


def test_weight_is_the_area_of_the_block_polygon():
    # W = gamma * (shoelace area of daylight, crack foot, crack top, crest).
    H, pf, pp, b = 12.0, 55.0, 30.0, 1.5
    r = planar_fos(H, pf, pp, 10e3, 35.0, 26e3, tension_crack_offset=b)
    xc = H / math.tan(math.radians(pf))
    z = r.crack_depth
    assert z == pytest.approx(crack_depth_from_offset(H, pf, pp, b))
    assert crack_offset_from_depth(H, pf, pp, z) == pytest.approx(b)
    x = np.array([0.0, xc + b, xc + b, xc])
    y = np.array([0.0, H - z, H, H])
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    assert r.W == pytest.approx(26e3 * area, rel=1e-12)


def test_critical_crack_depth_minimises_dry_factor_of_safety():
    H, pf, pp = 10.0, 60.0, 35.0
    zc, bc = critical_tension_crack(H, pf, pp)
    assert crack_depth_from_offset(H, pf, pp, bc) == pytest.approx(zc, rel=1e-12)
    zs = np.linspace(0.0, crack_depth_from_offset(H, pf, pp, 0.0), 2001)
    F = np.array([planar_fos(H, pf, pp, 20e3, 30.0, 25e3, tension_crack_depth=z).fos for z in zs])
    assert zs[np.argmin(F)] == pytest.approx(zc, abs=zs[1] - zs[0])
    # Water in the crack only lowers F (V pushes, U lifts).
    wet = planar_fos(H, pf, pp, 20e3, 30.0, 25e3, tension_crack_depth=zc, water_depth=zc)
    assert wet.fos < F.min()


def test_planar_fos_refuses_a_plane_that_cannot_daylight():
    with pytest.raises(ValueError, match="daylight"):
        planar_fos(10.0, 40.0, 45.0, 0.0, 30.0, 25e3)
    with pytest.raises(ValueError, match="water"):
        planar_fos(10.0, 60.0, 35.0, 0.0, 30.0, 25e3, water_depth=1.0)
    with pytest.raises(ValueError, match="disagree"):
        planar_fos(10.0, 60.0, 35.0, 0.0, 30.0, 25e3, tension_crack_depth=3.0, tension_crack_offset=3.0)


# ----------------------------------------------------------------------------- geometry and mesh


def _joint_edges(topo, tag):
    """(k, 2, 2) reference end points of the crack elements on joint set ``tag``."""
    sel = np.flatnonzero(topo.crack_tag == tag)
    return topo.x0[topo.crack_nodes[sel, :2]]


@pytest.mark.parametrize("crack", [None, 2.0])
def test_joint_daylights_in_the_face_and_reaches_the_surface_or_the_crack(crack):
    H, pf, pp = 10.0, 60.0, 35.0
    geometry = planar_slope_geometry(H, pf, pp, tension_crack_offset=crack)
    mesh = mesh_geometry(geometry, 1.0)
    topo = build_topology(mesh)
    expected = {"bottom", "left", "right", "surface", "joint_set_1"} | ({"joint_set_2"} if crack else set())
    assert set(mesh.group_names) == expected
    top = geometry.bounds[3]
    # The daylight point: lowest end of the joint, on the face, H below the crest.
    plane = _joint_edges(topo, 1).reshape(-1, 2)
    d = plane[np.argmin(plane[:, 1])]
    face_nodes = mesh.points[mesh.group_nodes("surface")]
    assert np.min(np.linalg.norm(face_nodes - d, axis=1)) < 1e-9
    assert top - d[1] == pytest.approx(H, rel=1e-12)
    # Every joint element lies on the line at psi_p through the daylight point.
    t = np.array([math.cos(math.radians(pp)), math.sin(math.radians(pp))])
    rel = plane - d
    assert np.abs(rel[:, 0] * t[1] - rel[:, 1] * t[0]).max() < 1e-9
    length = np.linalg.norm(np.diff(_joint_edges(topo, 1), axis=1), axis=2).sum()
    le = planar_fos(H, pf, pp, 0.0, 30.0, 25e3, tension_crack_offset=crack)
    assert length == pytest.approx(le.A, rel=1e-9)          # the plane is the LE plane, length A
    if crack is None:
        assert plane[:, 1].max() == pytest.approx(top)      # up to the upper surface
    else:
        vertical = _joint_edges(topo, 2).reshape(-1, 2)
        assert np.ptp(vertical[:, 0]) < 1e-9                 # a vertical crack
        crest_x = d[0] + H / math.tan(math.radians(pf))
        assert vertical[0, 0] - crest_x == pytest.approx(crack)
        assert vertical[:, 1].max() == pytest.approx(top)
        assert top - vertical[:, 1].min() == pytest.approx(le.crack_depth, rel=1e-9)
        assert plane[:, 1].max() == pytest.approx(vertical[:, 1].min())   # the plane ends at its foot
    # The block above the plane is its own region: removing the joint's crack elements (and the
    # tension crack's) cuts the mesh into two pieces, the sliding block and the stable rock.
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    keep = topo.crack_tag == 0
    a, b = topo.crack_triangles[keep].T
    n = topo.n_triangles
    n_parts, label = connected_components(coo_matrix((np.ones(a.size), (a, b)), shape=(n, n)), directed=False)
    assert n_parts == 2
    c = topo.x0[topo.triangles].mean(axis=1)
    block = label == label[np.argmin(np.linalg.norm(c - (d + [0.5, 1.0]), axis=1))]
    area = topo.triangle_area0[block].sum()
    assert area * 25e3 == pytest.approx(le.W, rel=1e-9)      # its weight is the LE weight W


# ----------------------------------------------------------------------------- strength reduction


def _case():
    from conftest import load_case

    # registered in sys.modules: its dataclasses look their module up there
    return load_case("planar_failure", "planar_failure_case", register=True)


@pytest.fixture(scope="module")
def fos_runs():
    """Strength-reduction FoS of two geometries on coarse meshes (a few hundred triangles),
    bisected on [1.0, 1.8] to a bracket 0.025 wide."""
    case = _case()
    return {name: case.run_case(name, size=1.5, lower=1.0, upper=1.8, tol=0.03)
            for name in ("no_crack", "tension_crack")}


@pytest.mark.parametrize("name", ["no_crack", "tension_crack"])
def test_strength_reduction_fos_matches_hoek_bray(fos_runs, name):
    r = fos_runs[name]
    lo, hi = r["bracket"]
    assert hi - lo <= 0.03 and lo <= r["fos"] <= hi
    # verification.md: within 10 % of the limit-equilibrium value.
    assert r["fos"] == pytest.approx(r["analytic_fos"], rel=0.10)
    # Every trial below the bracket settled, every trial above it did not.
    for t in r["trials"]:
        assert t["stable"] == (t["factor"] <= lo)
    # The slope failed along its joints: no intact-rock element (tag 0) yielded, none broke.
    assert set(r["failure_surface_tags"]) <= {1, 2} and 1 in r["failure_surface_tags"]
    assert r["n_broken_first_failure"] == 0


def test_tension_crack_lowers_the_fos_as_limit_equilibrium_says(fos_runs):
    # Hoek-Bray: 1.396 without a crack, 1.302 with the crack 2 m behind the crest.
    a, b = fos_runs["no_crack"], fos_runs["tension_crack"]
    assert b["analytic_fos"] < a["analytic_fos"]
    assert b["bracket"][1] <= a["bracket"][0]
