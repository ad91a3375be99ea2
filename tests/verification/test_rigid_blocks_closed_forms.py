"""Rigid blocks against closed forms: Hoek-Bray planar sliding, the pseudo-static yield
acceleration of a block, Goodman-Bray's sliding and toppling regimes, a block sliding and
sticking on an incline (hard and soft contacts), the initial angular acceleration of a toppling
block, and Newmark's sliding block (docs/rigid_blocks.md)."""
import math

import numpy as np
import pytest

from fdem.blocks.assembly import CONTACT, block_system
from fdem.blocks.dynamics import BlockDynamics
from fdem.blocks.limit import check_equilibrium, factor_of_safety, statics, yield_acceleration
from fdem.blocks.newmark import mechanism_newmark, one_way_slip
from fdem.blocks.strength import Strength, strengths_from
from fdem.geometry.polygons import rectangle
from fdem.geometry.section import Geometry
from fdem.reference.newmark import newmark_response, rectangular_pulse_displacement
from fdem.reference.newmark import yield_acceleration as newmark_yield

G = 9.81
RHO = 2650.0


def incline(theta_deg: float, width: float = 1.0, height: float = 1.0):
    """A block on a base; the plane's dip is put into gravity: g = 9.81 (sin theta, -cos theta)."""
    geo = Geometry([rectangle(0, 0, 8, 1, "base"), rectangle(2, 1, width, height, "block")])
    th = math.radians(theta_deg)
    return block_system(geo), np.array([math.sin(th), -math.cos(th)])


@pytest.mark.parametrize("name", ["no_crack", "tension_crack", "flat_plane"])
def test_planar_slopes_against_hoek_bray(name):
    from fdem.cases.planar_failure import GEOMETRIES, HEIGHT, UNIT_WEIGHT, analytic, planar_slope_geometry, property_sets

    g = GEOMETRIES[name]
    bs = block_system(planar_slope_geometry(HEIGHT, **g))
    r = factor_of_safety(statics(bs, UNIT_WEIGHT), strengths_from(property_sets()), rtol=1e-4)
    hb = analytic(**g).fos
    assert r.fos == pytest.approx(hb, rel=2e-4)          # the FDEM path meets it to 1 %
    assert r.mechanism.n_moving == 1 and r.mechanism.kind() == "sliding"
    v = r.mechanism.velocity[r.mechanism.moving][0]
    # associated flow: the wedge leaves the plane at the reduced friction angle
    phi_F = math.degrees(math.atan(math.tan(math.radians(30.0)) / r.fos))
    assert math.degrees(math.atan2(-v[1], -v[0])) == pytest.approx(g["plane_angle"] - phi_F, abs=0.05)


@pytest.mark.parametrize("theta, phi", [(20.0, 35.0), (10.0, 30.0)])
def test_pseudo_static_yield_acceleration_of_a_block(theta, phi):
    bs, g_hat = incline(theta)
    st = statics(bs, RHO * G, g_hat)
    S = {CONTACT: Strength(0.0, phi, 0.0)}
    th = math.radians(theta)
    # along the plane, down the slope: Newmark's a_y = g (cos theta tan phi - sin theta)
    y = yield_acceleration(st, S, direction=(1.0, 0.0))
    assert y.acceleration == pytest.approx(newmark_yield(theta, phi)[0], rel=1e-6)
    # horizontal (in the frame of the true ground surface): k_y = tan(phi - theta)
    horiz = (math.cos(th), math.sin(th))
    y = yield_acceleration(st, S, direction=horiz)
    assert y.k_y == pytest.approx(math.tan(math.radians(phi - theta)), rel=1e-6)
    assert y.mechanism.kind() == "sliding"


@pytest.mark.parametrize("theta, phi, b_over_h, regime", [
    (20.0, 30.0, 0.6, "stable"),         # psi < phi, b/h > tan psi = 0.36
    (35.0, 30.0, 1.0, "sliding"),        # psi > phi, b/h > tan psi = 0.70
    (25.0, 38.0, 0.35, "toppling"),      # psi < phi, b/h < tan psi = 0.47
    (30.0, 40.0, 0.5, "toppling"),       # tan psi = 0.577
    (16.0, 40.0, 0.3, "stable"),         # b/h > tan psi = 0.287
    (40.0, 30.0, 0.5, "slide+topple"),   # psi > phi, b/h < tan psi = 0.84
])
def test_goodman_bray_regimes(theta, phi, b_over_h, regime):
    bs, g_hat = incline(theta, width=b_over_h, height=1.0)
    r = check_equilibrium(statics(bs, RHO * G, g_hat), {CONTACT: Strength(0.0, phi, 0.0)})
    if regime == "stable":
        assert r.stable
        return
    assert not r.stable
    kind = r.mechanism.kind()
    # sliding and toppling are both mechanisms of the slide+topple regime: the solver gives one
    assert kind in ({"sliding", "toppling"} if regime == "slide+topple" else {regime})


@pytest.mark.parametrize("contact", ["hard", "soft"])
@pytest.mark.parametrize("theta, phi", [(30.0, 20.0), (20.0, 30.0)])
def test_block_on_incline_slides_and_sticks(contact, theta, phi):
    bs, g_hat = incline(theta)
    dyn = BlockDynamics(bs, RHO, {CONTACT: Strength(0.0, phi, 0.0)}, gravity=G * g_hat, contact=contact,
                        k_n=1e11, k_t=1e11)
    T, dt = 0.4, 2e-3
    h = dyn.run(T, dt, every=200)
    i = bs.free[0]
    slide = h.x[-1][i, 0] - h.x[0][i, 0]
    th = math.radians(theta)
    a = G * (math.sin(th) - math.cos(th) * math.tan(math.radians(phi)))
    n = round(T / dt)
    exact = max(a, 0.0) * T * T / 2
    # implicit Euler: s_n = a dt^2 n (n + 1) / 2, first order in dt
    assert slide == pytest.approx(exact * (1 + 1 / n), rel=1e-3, abs=1e-6)
    assert abs(h.x[-1][i, 1] - h.x[0][i, 1]) < 1e-5        # no dilation: Coulomb, not associated
    assert abs(h.theta[-1][i]) < 1e-5
    assert h.unconverged == 0


@pytest.mark.parametrize("contact", ["hard", "soft"])
def test_toppling_block_starts_with_the_closed_form_angular_acceleration(contact):
    # b/h < tan(theta) < tan(phi): the block turns about its down-slope corner:
    # alpha_0 = g (h/2 sin theta - b/2 cos theta) / ((b^2 + h^2) / 3)
    theta, phi, b, hgt = 30.0, 40.0, 0.4, 1.0
    bs, g_hat = incline(theta, b, hgt)
    dyn = BlockDynamics(bs, RHO, {CONTACT: Strength(0.0, phi, 0.0)}, gravity=G * g_hat, contact=contact,
                        k_n=1e12, k_t=1e12)
    dt, T = 1e-3, 0.1
    h = dyn.run(T, dt)
    th = math.radians(theta)
    alpha = G * (hgt / 2 * math.sin(th) - b / 2 * math.cos(th)) / ((b * b + hgt * hgt) / 3)
    i = bs.free[0]
    rot = -(h.theta[-1][i] - h.theta[0][i])               # clockwise, towards +x (down the slope)
    assert rot == pytest.approx(alpha * T * T / 2, rel=0.03)
    # the pivot, the down-slope corner (2 + b, 1), stays put
    pivot = np.array([2.0 + b, 1.0])
    c, s = math.cos(h.theta[-1][i]), math.sin(h.theta[-1][i])
    r0 = pivot - bs.centroid[i]
    corner = h.x[-1][i] + np.array([c * r0[0] - s * r0[1], s * r0[0] + c * r0[1]])
    assert np.linalg.norm(corner - pivot) < 1e-4


def test_one_way_slip_against_the_rectangular_pulse():
    a_p, t_p, a_y = 3.0, 0.5, 1.2
    t = np.array([0.0, 1e-9, t_p, t_p + 1e-9, 5.0])
    a = np.array([0.0, a_p, a_p, 0.0, 0.0])
    s, _ = one_way_slip(t, a, a_y)
    assert s[-1] == pytest.approx(rectangular_pulse_displacement(a_p, t_p, a_y), rel=1e-6)


def test_rigid_block_newmark_matches_the_closed_form_sliding_block():
    theta, phi = 20.0, 35.0
    a_y, _ = newmark_yield(theta, phi)
    t = np.linspace(0.0, 1.0, 201)
    a_base = -6.0 * np.sin(2 * math.pi * t) * (t < 0.5)       # base accelerates up-slope: the block slides down
    # closed form (piecewise exact) against the same record through the yield coefficient
    te, d_ref, _ = newmark_response(t, a_base, theta, phi)
    s, _ = one_way_slip(t, -a_base, a_y)
    assert s[-1] == pytest.approx(d_ref[-1], rel=1e-6)
    # the pseudo-static analysis of the block finds the same yield and the same displacement
    bs, g_hat = incline(theta)
    S = {CONTACT: Strength(0.0, phi, 0.0)}
    d, y = mechanism_newmark(statics(bs, RHO * G, g_hat), S, t, np.column_stack([a_base, 0 * t]), direction=(1, 0))
    assert y.acceleration == pytest.approx(a_y, rel=1e-6)
    assert d == pytest.approx(d_ref[-1], rel=1e-5)
    # and the hard-block dynamics under the base acceleration record
    dyn = BlockDynamics(bs, RHO, S, gravity=G * g_hat,
                        base_acceleration=lambda tt: (float(np.interp(tt, t, a_base, right=0.0)), 0.0))
    h = dyn.run(1.2, 1e-3, every=100)
    i = bs.free[0]
    assert h.x[-1][i, 0] - h.x[0][i, 0] == pytest.approx(d_ref[-1], rel=0.02)
