"""Slope profiles, joint sets and DFN processing (no meshing)."""
import math
import warnings

import numpy as np
import pytest

from fdem.geometry.joint_sets import BrickSet, IntermittentSet, PersistentSet, SegmentSet, StochasticSet
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import Polygon, benched_slope, ground_surface, rectangle, simple_slope
from fdem.geometry.dfn import merge_collinear, split_at_crossings


def test_simple_slope_shape_and_area():
    H, alpha = 15.0, 45.0
    s = simple_slope(H, alpha, crest_length=30, toe_length=45, base_depth=15)
    x0, y0, x1, y1 = s.bounds
    assert (x1 - x0, y1 - y0) == pytest.approx((45 + H / math.tan(math.radians(alpha)) + 30, 30))
    # Rectangle minus the triangle above the face and the block above the toe floor.
    expected = 90 * 30 - 45 * 15 - 0.5 * 15 * 15
    assert s.area == pytest.approx(expected, rel=1e-14)


def test_ground_surface_is_the_top_of_the_profile_wherever_the_base_lies():
    """y_s(x) of a 15 m, 45 deg slope (toe at x = 45 m, 15 m above the base, crest from x = 60 m):
    the floor, the face and the crest, linearly; the same profile moved 100 m down (a base below
    y = 0, as a scene file may place it) gives the same surface moved 100 m down."""
    s = simple_slope(15.0, 45.0, crest_length=30, toe_length=45, base_depth=15)
    x = np.array([0.0, 20.0, 45.0, 52.5, 60.0, 75.0, 90.0])
    top = np.array([15.0, 15.0, 15.0, 22.5, 30.0, 30.0, 30.0])
    np.testing.assert_allclose(ground_surface(s)(x), top, atol=1e-12)
    lowered = Polygon(s.vertices - np.array([0.0, 100.0]), "lowered")
    np.testing.assert_allclose(ground_surface(lowered)(x), top - 100.0, atol=1e-12)


def test_benched_slope_area():
    s = benched_slope([(10, 90, 5), (10, 45, 0)], crest_length=10, toe_length=10, base_depth=5)
    # Width 10 + 0 + 5 + 10 + 10 = 35; the profile is easy to integrate by pieces.
    expected = 35 * 5 + 10 * (5 + 10 + 10) + 10 * 10 + 0.5 * 10 * 10
    assert s.area == pytest.approx(expected, rel=1e-14)


def test_polygon_is_made_counter_clockwise():
    p = Polygon(np.array([[0, 0], [0, 1], [1, 1], [1, 0]]))
    assert p.area == pytest.approx(1.0)


def test_self_intersecting_profile_is_refused():
    with pytest.raises(ValueError, match="self-intersecting"):
        Polygon(np.array([[0, 0], [1, 1], [1, 0], [0, 1]]), name="bowtie")


@pytest.mark.parametrize("dip", [-1.0, 180.0, 200.0])
def test_dip_out_of_range(dip):
    with pytest.raises(ValueError, match="dip must be in"):
        PersistentSet(dip=dip, spacing=1.0)


@pytest.mark.parametrize("spacing", [0.0, -1.0, float("nan")])
def test_non_positive_spacing(spacing):
    with pytest.raises(ValueError, match="spacing must be positive"):
        PersistentSet(dip=10, spacing=spacing)
    with pytest.raises(ValueError, match="spacing must be positive"):
        BrickSet(dip=10, spacing=spacing)
    with pytest.raises(ValueError, match="row_spacing must be positive"):
        IntermittentSet(dip=10, trace_length=1, bridge_length=1, row_spacing=spacing)


def test_joint_outside_domain_is_refused():
    box = rectangle(0, 0, 10, 5)
    js = SegmentSet([[1, 1, 4, 2], [20, 20, 25, 21]], name="mapped")
    with pytest.raises(ValueError, match=r"segment 1 .* lies outside the domain"):
        Geometry([box], [js]).dfn()


def test_persistent_set_is_clipped_and_spaced():
    box = rectangle(0, 0, 10, 10)
    dfn = Geometry([box], [PersistentSet(dip=30, spacing=1.5, offset=0.2)]).dfn()
    n = np.array([-math.sin(math.radians(30)), math.cos(math.radians(30))])
    c = np.sort(dfn.segments[:, 0] @ n)
    assert np.allclose(np.diff(c), 1.5, atol=1e-9)
    assert np.allclose((c - 0.2) / 1.5, np.round((c - 0.2) / 1.5), atol=1e-9)
    # Every segment runs wall to wall: both ends on the box boundary.
    ends = dfn.segments.reshape(-1, 2)
    on_edge = np.isclose(ends, 0, atol=1e-9) | np.isclose(ends, 10, atol=1e-9)
    assert on_edge.any(axis=1).all()


def test_brick_fabric_spacings_and_half_block_offset():
    s, dip = 1.0, 15.0
    box = rectangle(0, 0, 20, 12)
    dfn = Geometry([box], [BrickSet(dip=dip, spacing=s)]).dfn()
    t = np.array([math.cos(math.radians(dip)), math.sin(math.radians(dip))])
    n = np.array([-t[1], t[0]])
    seg = dfn.segments
    d = seg[:, 1] - seg[:, 0]
    along_persistent = np.abs(d @ n) < 1e-9 * np.linalg.norm(d, axis=1)
    # Persistent joints: normal offsets are multiples of s.
    c = np.unique(np.round(seg[along_persistent, 0] @ n, 9))
    assert np.allclose(np.diff(c), s, atol=1e-9)
    # Cross joints are perpendicular, span exactly one layer, and sit d = 2s apart along it.
    cross = seg[~along_persistent]
    interior = []
    for a, b in cross:
        lo, hi = sorted((a @ n, b @ n))
        k = round(lo / s)
        if abs(lo - k * s) < 1e-9 and abs(hi - (k + 1) * s) < 1e-9:  # whole cross joint, not clipped
            interior.append((k, a @ t))
            assert abs((b - a) @ t) < 1e-9
    interior = np.array(interior)
    assert len(interior) > 20
    positions = {}
    for k, x in interior:
        positions.setdefault(int(k), []).append(x)
    layer_phase = {}
    for k, xs in positions.items():
        xs = np.sort(xs)
        if len(xs) > 1:
            assert np.allclose(np.diff(xs), 2 * s, atol=1e-9)
        layer_phase[k] = np.mod(xs[0], 2 * s)
    ks = sorted(layer_phase)
    for k0, k1 in zip(ks[:-1], ks[1:]):
        if k1 == k0 + 1:
            shift = np.mod(layer_phase[k1] - layer_phase[k0], 2 * s)
            assert shift == pytest.approx(s, abs=1e-9)  # half a block d/2 = s


def test_intermittent_set_traces_bridges_and_stagger():
    box = rectangle(-50, -50, 100, 100)
    js = IntermittentSet(dip=25, trace_length=3.0, bridge_length=3.0 / math.cos(math.radians(25)) - 3.0,
                         row_spacing=2.14, stagger=0.7)
    dfn = Geometry([box], [js]).dfn()
    L = np.linalg.norm(dfn.segments[:, 1] - dfn.segments[:, 0], axis=1)
    whole = np.isclose(L, 3.0, atol=1e-9)
    assert whole.mean() > 0.9
    t = np.array([math.cos(math.radians(25)), math.sin(math.radians(25))])
    n = np.array([-t[1], t[0]])
    starts = dfn.segments[whole]
    start_along = np.minimum(starts[:, 0] @ t, starts[:, 1] @ t)
    rows = np.round(starts[:, 0] @ n / 2.14).astype(int)
    period = js.trace_length + js.bridge_length
    for r in np.unique(rows)[:5]:
        x = np.sort(start_along[rows == r])
        assert np.allclose(np.diff(x), period, atol=1e-9)
        assert np.mod(x[0] - r * 0.7, period) == pytest.approx(0, abs=1e-9) or \
            np.mod(x[0] - r * 0.7, period) == pytest.approx(period, abs=1e-9)


def test_stochastic_set_same_seed_same_network():
    box = rectangle(0, 0, 30, 20)
    make = lambda seed: Geometry([box], [StochasticSet(count=40, length=("lognormal", 3, 1), dip=("normal", 60, 10),
                                                    seed=seed)]).dfn().segments
    a, b, c = make(7), make(7), make(8)
    assert np.array_equal(a, b)
    assert a.shape != c.shape or not np.allclose(a, c)


def test_crossing_segments_are_split_and_collinear_overlaps_merged():
    segs = np.array([[[0, 0], [4, 0]], [[2, 0], [6, 0]], [[3, -1], [3, 1]]], dtype=float)
    merged, ids = merge_collinear(segs, np.array([2, 1, 1], np.int32), 1e-9)
    assert len(merged) == 2
    horizontal = merged[np.abs(merged[:, 1, 1] - merged[:, 0, 1]) < 1e-12][0]
    assert sorted(horizontal[:, 0]) == pytest.approx([0, 6])
    assert ids.min() == 1
    pieces, src, angles = split_at_crossings(merged, 1e-9)
    assert len(pieces) == 4
    assert angles == pytest.approx([90.0])
    assert np.linalg.norm(pieces[:, 1] - pieces[:, 0], axis=1).sum() == pytest.approx(8.0)


def test_short_segments_dropped_with_count_and_sharp_crossings_warned():
    box = rectangle(0, 0, 10, 10)
    js = SegmentSet([[1, 1, 9, 1], [5, 1.02, 5, 0.5], [2, 0.8, 8, 1.3]])
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        dfn = Geometry([box], [js], min_joint_length=0.05).dfn()
    messages = " ".join(str(x.message) for x in w)
    assert "dropped 1 joint segment" in messages
    assert "sharper than 15 deg" in messages and "worst 4.76 deg" in messages
    assert dfn.n_dropped_short == 1


def test_overlapping_bodies_are_refused():
    with pytest.raises(ValueError, match="overlap"):
        Geometry([rectangle(0, 0, 2, 2, "a"), rectangle(1, 1, 2, 2, "b")])


def test_touching_bodies_are_allowed():
    m = Geometry([rectangle(0, 0, 4, 1, "base"), rectangle(1, 1, 1, 1, "block")])
    assert m.area == pytest.approx(5.0)


def test_vertices_near_the_boundary_are_snapped_onto_it():
    box = rectangle(0, 0, 10, 10)
    # A junction 4 mm above the floor: the 4 mm stub is dropped and the junction moves to the floor.
    js = SegmentSet([[1, 0.004, 9, 0.004 + 8 * math.tan(math.radians(20))], [1.0, 0.0, 1.0, 3.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dfn = Geometry([box], [js], min_joint_length=0.05).dfn()
    ends = dfn.segments.reshape(-1, 2)
    off_boundary = (ends[:, 1] > 0) & (ends[:, 1] < 10) & (ends[:, 0] > 0) & (ends[:, 0] < 10)
    # Every vertex is either on the boundary or at least min_joint_length away from it.
    gap = np.minimum.reduce([ends[:, 0], ends[:, 1], 10 - ends[:, 0], 10 - ends[:, 1]])
    assert np.all(gap[off_boundary] >= 0.05)
    assert np.linalg.norm(dfn.segments[:, 1] - dfn.segments[:, 0], axis=1).min() >= 0.05


def test_four_slope_joint_offset_places_the_persistent_joints_relative_to_the_toe():
    """Offset 0 puts a persistent joint through the toe (the fine models, and the coarse ones on
    request); the coarse default 0.5 puts the toe midway between two persistent joints."""
    from fdem.cases.four_slopes import four_slope_geometry

    toe = np.array([45.0, 15.0])
    dip = np.radians(15.0)
    normal = np.array([-np.sin(dip), np.cos(dip)])
    for spacing, offset, expect in (("coarse", 0.0, 0.0), ("fine", None, 0.0), ("coarse", None, 2.5)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dfn = four_slope_geometry("low", spacing, joint_offset=offset).dfn()
        seg = dfn.segments
        d = seg[:, 1] - seg[:, 0]
        u = d / np.linalg.norm(d, axis=1, keepdims=True)
        persistent = np.abs(u[:, 0] * np.sin(dip) - u[:, 1] * np.cos(dip)) < 1e-6   # parallel to the dip
        dist = np.abs((seg[persistent, 0] - toe) @ normal)   # distance of each persistent line to the toe
        assert dist.min() == pytest.approx(expect, abs=1e-6), (spacing, offset)
    with pytest.raises(ValueError, match="joint_offset"):
        four_slope_geometry("low", "fine", joint_offset=1.5)


def test_muliashi_scene_has_five_rows_of_three_metre_joints():
    from fdem.cases.muliashi import muliashi_geometry

    dfn = muliashi_geometry().dfn()
    t = np.array([math.cos(math.radians(25)), math.sin(math.radians(25))])
    n = np.array([-t[1], t[0]])
    rows = np.unique(np.round(dfn.segments[:, 0] @ n, 6))
    assert len(rows) == 5 and np.allclose(np.diff(rows), 2.14)
    L = np.linalg.norm(dfn.segments[:, 1] - dfn.segments[:, 0], axis=1)
    assert np.isclose(L, 3.0).sum() >= 10


def test_disc_area():
    from fdem.geometry.polygons import disc

    d = disc((0, 0), 0.5, n_sides=64)
    assert d.area == pytest.approx(32 * 0.25 * math.sin(2 * math.pi / 64), rel=1e-14)
    with pytest.raises(ValueError, match="radius must be positive"):
        disc((0, 0), 0.0)


def test_a_banded_joint_set_keeps_its_joints_out_of_the_side_bands():
    """clip_to_x cuts segments at the band's edges exactly; a BandedSet's joints (and so the
    mesh's) lie only between the bands, each piece on its parent joint."""
    from fdem.geometry.joint_sets import BandedSet, BrickSet, clip_to_x

    seg = np.array([[[-1.0, 0.0], [3.0, 4.0]], [[5.0, 0.0], [6.0, 1.0]], [[1.0, -1.0], [1.0, 1.0]]])
    out = clip_to_x(seg, 0.0, 2.0)
    np.testing.assert_allclose(out, [[[0.0, 1.0], [2.0, 3.0]], [[1.0, -1.0], [1.0, 1.0]]])
    np.testing.assert_allclose(clip_to_x(seg[:1, ::-1], 0.0, 2.0), [[[2.0, 3.0], [0.0, 1.0]]])  # either direction
    fabric = BrickSet(dip=115.0, spacing=1.0)
    banded = BandedSet(fabric, 5.0)
    bounds = (0.0, 0.0, 40.0, 20.0)
    pieces = banded.raw_segments(bounds)
    assert pieces[:, :, 0].min() >= 5.0 - 1e-12 and pieces[:, :, 0].max() <= 35.0 + 1e-12
    assert len(pieces) > 0
    with pytest.raises(ValueError, match="band must be a positive"):
        BandedSet(fabric, 0.0)
    with pytest.raises(ValueError, match="leave no room"):
        BandedSet(fabric, 25.0).raw_segments(bounds)
