"""Rigid blocks: the blocks a geometry's joints cut out, the equilibrium cone program against an
independent brute-force linear program, and clear errors on bad input (docs/rigid_blocks.md)."""
import math

import numpy as np
import pytest

from fdem.blocks.assembly import BRIDGE, CONTACT, block_system, polygon_properties
from fdem.blocks.cone import ConeProblem, ConeSolverError, solve_cone
from fdem.blocks.limit import BlockSystemError, check_equilibrium, factor_of_safety, statics
from fdem.blocks.strength import Strength, interface_strength
from fdem.geometry.joint_sets import IntermittentSet, SegmentSet
from fdem.geometry.polygons import Polygon, rectangle
from fdem.geometry.section import Geometry
from fdem.reference.hoek_bray import planar_fos


def incline(theta_deg: float, width: float = 1.0, height: float = 1.0):
    """A block on a horizontal base; the plane's dip goes into gravity, g_hat = (sin, -cos)."""
    geo = Geometry([rectangle(0, 0, 8, 1, "base"), rectangle(2, 1, width, height, "block")])
    th = math.radians(theta_deg)
    return block_system(geo), (math.sin(th), -math.cos(th))


def test_planar_slope_blocks_are_the_hoek_bray_wedge():
    from fdem.cases.planar_failure import planar_slope_geometry

    geo = planar_slope_geometry(10.0, 60.0, 35.0, tension_crack_offset=2.0)
    bs = block_system(geo)
    assert bs.n_blocks == 2 and bs.fixed.sum() == 1
    assert bs.area.sum() == pytest.approx(geo.area, rel=1e-12)
    hb = planar_fos(10.0, 60.0, 35.0, 0.0, 30.0, 1.0, tension_crack_offset=2.0)
    wedge = int(np.flatnonzero(~bs.fixed)[0])
    assert bs.area[wedge] == pytest.approx(hb.weight, rel=1e-9)           # W / gamma
    lengths = bs.tag_lengths()
    assert lengths[1] == pytest.approx(hb.plane_length, rel=1e-9)         # A
    assert lengths[2] == pytest.approx(hb.crack_depth, rel=1e-9)          # z
    # normals point into block a, out of block b
    for (a, b), n, e in zip(bs.blocks, bs.normal, bs.ends):
        mid = e.mean(axis=0)
        assert Polygon(bs.polygons[a]).contains(mid + 1e-3 * n)[0]
        assert Polygon(bs.polygons[b]).contains(mid - 1e-3 * n)[0]


def test_rock_bridges_close_a_row_of_intermittent_joints():
    # one row of 2 m joints with 1 m bridges across a 10 m wide box: the row becomes one interface
    # line, joints where the traces are, bridges (tag 0) in between and out to the sides
    box = rectangle(0, 0, 10, 4, "box")
    row = IntermittentSet(dip=0.0, trace_length=2.0, bridge_length=1.0, row_spacing=100.0, offset=2.0, phase=0.5)
    bs = block_system(Geometry([box], [row]), supports=("bottom",))
    assert bs.n_blocks == 2
    L = bs.tag_lengths()
    assert L[1] + L[BRIDGE] == pytest.approx(10.0, rel=1e-9)
    assert L[1] == pytest.approx(3 * 2.0 + 0.5, rel=1e-9)     # traces at 0.5-2.5, 3.5-5.5, 6.5-8.5, 9.5-10
    assert bs.area.sum() == pytest.approx(40.0)


def test_polygon_properties_of_a_rectangle():
    A, c, J = polygon_properties(rectangle(1.0, 2.0, 3.0, 0.5).vertices)
    assert A == pytest.approx(1.5)
    assert c == pytest.approx([2.5, 2.25])
    assert J == pytest.approx(1.5 * (9.0 + 0.25) / 12)


def test_contact_between_bodies_is_found_with_its_overlap():
    bs, _ = incline(0.0, width=1.5)
    assert bs.n_interfaces == 1 and bs.tag[0] == CONTACT
    assert bs.length[0] == pytest.approx(1.5)
    a = bs.blocks[0, 0]
    assert (bs.centroid[a] - bs.ends[0].mean(axis=0)) @ bs.normal[0] > 0


def brute_force_fos(bs, strengths, unit_weight, g_hat, lower=0.1, upper=10.0, rtol=1e-4):
    """Independent check: the same statics written out by hand, point by point, the Coulomb cone
    as its two planes (exact in 2D), feasibility by scipy's HiGHS linear programming."""
    from scipy.optimize import linprog

    free = [i for i in range(bs.n_blocks) if not bs.fixed[i]]
    row = {b: k for k, b in enumerate(free)}
    cols = []   # (interface, end)
    for k in range(bs.n_interfaces):
        a, b = bs.blocks[k]
        if bs.fixed[a] and bs.fixed[b]:
            continue
        cols += [(k, 0), (k, 1)]
    n_var = 2 * len(cols)                     # (n, t) per point

    def feasible(F):
        Aeq = np.zeros((3 * len(free), n_var))
        beq = np.zeros(3 * len(free))
        for i in free:
            W = unit_weight * bs.area[i]
            beq[3 * row[i]:3 * row[i] + 2] = [-W * g_hat[0], -W * g_hat[1]]
        Aub, bub = [], []
        for j, (k, e) in enumerate(cols):
            a, b = bs.blocks[k]
            nu = bs.normal[k]
            tau = np.array([-nu[1], nu[0]])
            p = bs.ends[k, e]
            for blk, sign in ((a, 1.0), (b, -1.0)):
                if bs.fixed[blk]:
                    continue
                r = p - bs.centroid[blk]
                for c, d in ((0, nu), (1, tau)):
                    Aeq[3 * row[blk], 2 * j + c] += sign * d[0]
                    Aeq[3 * row[blk] + 1, 2 * j + c] += sign * d[1]
                    Aeq[3 * row[blk] + 2, 2 * j + c] += sign * (r[0] * d[1] - r[1] * d[0])
            s = strengths[int(bs.tag[k])]
            mu, c0 = math.tan(math.radians(s.phi)) / F, s.c * bs.length[k] / 2 / F
            ft = min(s.f_t, s.c / math.tan(math.radians(s.phi)) if s.phi > 0 else math.inf) * bs.length[k] / 2 / F
            for sign in (1.0, -1.0):           # sign t - mu n <= c L/2
                r_ = np.zeros(n_var)
                r_[2 * j + 1], r_[2 * j] = sign, -mu
                Aub.append(r_)
                bub.append(c0)
            r_ = np.zeros(n_var)
            r_[2 * j] = -1.0                   # -n <= f_t L/2
            Aub.append(r_)
            bub.append(ft)
        res = linprog(np.zeros(n_var), A_ub=np.array(Aub), b_ub=np.array(bub), A_eq=Aeq, b_eq=beq,
                      bounds=[(None, None)] * n_var, method="highs")
        return res.status == 0

    assert feasible(lower) and not feasible(upper)
    lo, hi = lower, upper
    while hi / lo - 1 > rtol:
        m = math.sqrt(lo * hi)
        lo, hi = (m, hi) if feasible(m) else (lo, m)
    return math.sqrt(lo * hi)


def test_cone_program_matches_a_brute_force_linear_program_on_a_small_block_system():
    # three blocks: a column of two blocks and a leaning one on an incline, joints and bridges
    base = rectangle(0, 0, 6, 1, "base")
    stack = Polygon(np.array([[1.0, 1], [2.2, 1], [2.2, 3.0], [1.0, 2.6]]), "stack")
    geo = Geometry([base, stack], [SegmentSet([[1.0, 1.8, 2.2, 2.1]], name="joint", must_lie_inside=True)])
    bs = block_system(geo)
    assert bs.n_blocks == 3 and bs.fixed.sum() == 1
    strengths = {1: Strength(2e3, 25.0, 0.5e3), -1: Strength(1e3, 30.0, 0.0)}
    th = math.radians(28.0)
    g_hat = (math.sin(th), -math.cos(th))
    st = statics(bs, 25e3, g_hat)
    socp = factor_of_safety(st, strengths, 0.1, 10.0, rtol=1e-5)
    lp = brute_force_fos(bs, strengths, 25e3, g_hat)
    assert socp.fos == pytest.approx(lp, rel=2e-4)
    # and the point forces of a stable state satisfy equilibrium and the cones
    eq = check_equilibrium(st, strengths, 0.9 * socp.fos)
    assert eq.stable
    mu, c, ft = interface_strength(bs.tag, strengths, 0.9 * socp.fos)
    half = bs.length / 2
    assert np.all(np.abs(eq.shear) <= (mu * eq.normal.T + c * half).T * (1 + 1e-6) + 1e-6 * 25e3)
    assert np.all(eq.normal >= -(ft * half)[:, None] * (1 + 1e-6) - 1e-6 * 25e3)


def test_interface_strength_reduction_and_tension_cut_off_at_the_apex():
    mu, c, ft = interface_strength(np.array([1, 0]), {1: Strength(10e3, 30.0, 1e6), 0: Strength(0.0, 20.0, 5e3)}, 2.0)
    assert mu == pytest.approx([math.tan(math.radians(30)) / 2, math.tan(math.radians(20)) / 2])
    assert c == pytest.approx([5e3, 0.0])
    assert ft == pytest.approx([10e3 / math.tan(math.radians(30)) / 2, 0.0])   # clamped to c / tan(phi)
    with pytest.raises(ValueError, match=r"no strength given for interface tag\(s\) \[7\]"):
        interface_strength(np.array([7]), {1: Strength(0, 30)})


def test_a_block_touching_nothing_is_refused():
    geo = Geometry([rectangle(0, 0, 8, 1, "base"), rectangle(2, 3, 1, 1, "flying")])
    with pytest.raises(BlockSystemError, match="no support"):
        statics(block_system(geo), 25e3)


def test_a_mechanism_no_strength_resists_is_refused():
    # a block on a frictionless, cohesionless incline: fails at any F
    bs, g = incline(20.0)
    with pytest.raises(BlockSystemError, match="fail already at F"):
        factor_of_safety(statics(bs, 25e3, g), {CONTACT: Strength(0.0, 0.0, 0.0)})


def test_a_system_that_stands_beyond_the_bracket_is_refused():
    bs, g = incline(0.0)
    with pytest.raises(BlockSystemError, match="still stand at F = 20"):
        factor_of_safety(statics(bs, 25e3, g), {CONTACT: Strength(0.0, 30.0, 0.0)})


def test_a_solver_without_an_answer_raises():
    bs, g = incline(10.0)
    st = statics(bs, 25e3, g)
    import scipy.sparse as sp
    A = sp.vstack([st.B, -sp.eye(4, format="csc")], format="csc")
    prob = ConeProblem(A, np.r_[-st.loads(), np.zeros(4)], np.zeros(4), 3, 4, 0)
    with pytest.raises(ConeSolverError, match="status MaxIterations"):
        solve_cone(prob, max_iter=1, what="test")


def test_intact_cells_can_only_lower_the_factor_of_safety():
    # cutting the intact rock into bonded cells adds mechanisms and removes none: any admissible
    # set of cell forces sums to one of the joint blocks, so F(cells) <= F(joints); with
    # intact rock far stronger than the joints the joints' mechanism is kept
    import warnings

    from fdem.cases import quick_start
    from fdem.blocks.strength import strengths_from

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geo = quick_start.geometry()
        joints = block_system(geo)
        cells = block_system(geo, intact_cell_size=2.0)
    assert cells.n_blocks > 3 * joints.n_blocks
    assert cells.area.sum() == pytest.approx(joints.area.sum(), rel=1e-9)
    props = quick_start.property_sets()
    S = strengths_from(props)
    weak = {**S, 0: Strength(2e3, 15.0, 0.5e3)}     # intact rock weaker than the joints
    f_joints = factor_of_safety(statics(joints, 25e3), S).fos
    f_cells = factor_of_safety(statics(cells, 25e3), S).fos
    f_weak = factor_of_safety(statics(cells, 25e3), weak).fos
    assert f_cells == pytest.approx(f_joints, rel=2e-3)
    assert f_weak < 0.9 * f_joints
