"""Strength reduction is one consistent definition and keeps the energy books closed.

A change of the reduction factor F (or holding elements elastic and releasing them) on damaged
elements must neither create nor remove stored energy; what it makes fail is booked as
dissipation at fixed positions. Element-level facts here; the ledger of a whole reduction
schedule on a slope is in tests/verification/test_stages.py.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fdem.physics.interfaces import Interfaces
from test_cohesive import KN, KT, Driver, props


def stored_and_spent(dr: Driver) -> tuple[float, float]:
    e = dr.cs.energy_terms()
    return e["crack_elastic"], e["fracture"] + e["crack_friction"]


def damaged_mode_I(p, frac=0.3):
    """An element opened into its softening branch (a fraction of the way to full damage)."""
    dr = Driver(p)
    op = p.f_t / KN
    from fdem.physics.crack_properties import softening_integral

    o_r = op + (p.G_I - p.f_t ** 2 / (2 * KN)) / (p.f_t * softening_integral("munjiza"))
    for o in np.linspace(0.0, op + frac * (o_r - op), 400)[1:]:
        dr.move(o, 0.0)
    return dr, op, o_r


@pytest.mark.parametrize("factor", [0.5, 0.9, 1.5])
def test_strength_change_keeps_the_secant_and_books_what_it_releases(factor):
    p = props()
    dr, op, o_r = damaged_mode_I(p)
    assert 0.0 < dr.cs.damage[0] < 1.0
    sig_before = dr.move(dr.x_prev[dr.cn[3], 1] * -1.0, 0.0)[0]  # same opening, traction now
    e0, d0 = stored_and_spent(dr)
    dr.cs.interfaces.set_reduction(1 / factor)
    e1, d1 = stored_and_spent(dr)
    # Stronger (factor > 1): the state lies inside the new envelope, nothing changes.
    # Weaker: the end softens at fixed opening; the stored energy it loses is dissipated.
    assert e1 + d1 == pytest.approx(e0 + d0, rel=1e-12)
    if factor >= 1.0:
        assert e1 == pytest.approx(e0, rel=1e-12) and d1 == d0
    else:
        assert e1 < e0 and d1 > d0
    # The traction at the same opening never rises (damage never heals).
    o = -dr.x_prev[dr.cn[3], 1]
    sig_after = dr.move(o, 0.0)[0]
    assert sig_after <= sig_before * (1 + 1e-12)


def test_hold_elastic_after_damage_creates_no_energy_and_no_traction_jump():
    p = props()
    dr, op, o_r = damaged_mode_I(p)
    o = -dr.x_prev[dr.cn[3], 1]
    sig0 = dr.move(o, 0.0)[0]
    e0, d0 = stored_and_spent(dr)
    dr.cs.hold_elastic(True)
    assert dr.move(o, 0.0)[0] == pytest.approx(sig0, rel=1e-9)     # was 40 f_t before the fix
    e1, d1 = stored_and_spent(dr)
    assert e1 == pytest.approx(e0, rel=1e-9) and d1 == d0
    dr.cs.hold_elastic(False)
    assert dr.move(o, 0.0)[0] == pytest.approx(sig0, rel=1e-9)
    e2, d2 = stored_and_spent(dr)
    assert e2 + d2 == pytest.approx(e0 + d0, rel=1e-9)


def test_reduction_below_the_traction_of_a_sliding_element_books_the_slip():
    """An element sliding at its shear strength under compression: lowering the strength
    releases the spring energy above the new strength, all of it booked."""
    p = props()
    dr = Driver(p)
    sigma_n = 2e6
    o_c = -sigma_n / KN
    dr.move(o_c, 0.0)
    f_s = p.c + sigma_n * math.tan(math.radians(p.phi))
    for s in np.linspace(0, 1.2 * f_s / KT, 200)[1:]:
        dr.move(o_c, s)
    e0, d0 = stored_and_spent(dr)
    dr.cs.interfaces.set_reduction(1 / 0.5)
    e1, d1 = stored_and_spent(dr)
    assert e1 < e0
    assert e1 + d1 == pytest.approx(e0 + d0, rel=1e-12)
    tau = dr.move(o_c, 1.2 * f_s / KT)[1]
    assert abs(tau) <= 0.5 * f_s * (1 + 1e-6)


def test_interfaces_define_one_factor_for_everything():
    sets = {0: props(name="rock"), 1: props(phi=11.0, c=5e5, name="joint")}
    ifc = Interfaces(sets, surface_friction_angle=30.0)
    ifc.set_reduction(2.0)
    assert ifc.residual_mu(np.array([0, 1])) == pytest.approx(
        [math.tan(math.radians(30.0)) / 2, math.tan(math.radians(11.0)) / 2])
    assert ifc.surface_mu == pytest.approx(math.tan(math.radians(30.0)) / 2)
    assert ifc.tensile_factor == 0.5
    assert Interfaces(sets, reduce_tensile=False).tensile_factor == 1.0
    with pytest.raises(ValueError, match="positive"):
        ifc.set_reduction(float("nan"))
    with pytest.raises(ValueError, match="surface_friction_angle"):
        Interfaces(sets, surface_friction_angle=95.0)
