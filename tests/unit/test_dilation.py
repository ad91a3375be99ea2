"""Joint dilation of crack elements: single-element closed forms and the energy ledger.

An end that slides plastically separates its faces by ``d = tan(psi) min(kappa, u_lim)``; the
law sees the effective opening ``o - d`` (docs/cohesive.md, "Joint dilation"). The element is
driven by prescribed separations (``Driver`` of tests/test_cohesive.py), which integrates the
work done on it by the trapezoidal rule, as the solver's ledger does.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fdem.physics.crack_properties import CrackProperties
from fdem.kernels.cracks import CD_TANPSI, CS_DIL0, CW_FRICTION, N_STATE_V1
from fdem.physics.cracks import CrackSet
from test_cohesive import KN, KT, Driver, props, two_triangles

PSI = 10.0  # dilation angle [deg]
U_LIM = 2.0e-5  # slip at which dilation stops [m]
SIGMA_N0 = 2.0e6  # initial confinement [Pa]


def dilatant(**kw) -> CrackProperties:
    base = dict(softening="linear", dilation_angle=PSI, dilation_limit=U_LIM)
    base.update(kw)
    return props(**base)


def ledger(dr: Driver) -> float:
    """Stored + dissipated energy of the element [J/m]."""
    e = dr.cs.energy_terms()
    return e["crack_elastic"] + e["fracture"] + e["crack_friction"] + e["crack_released"]


@pytest.mark.parametrize("c", [0.0, 2.0e6])
def test_constant_stiffness_confinement_closed_form(c):
    """Sliding at fixed opening o = -sigma_n0/Kc: sigma = -(sigma_n0 + Kc tan(psi) kappa) while
    kappa < u_lim, constant beyond; tau = c z(D) + sigma_n tan(phi) with that sigma_n."""
    p = dilatant(c=c, G_II=300.0 if c > 0 else 0.0)
    dr = Driver(p)
    o = -SIGMA_N0 / KN  # Kc = Kn (no contact penalty given)
    dr.move(o, 0.0)
    tanphi, tanpsi = math.tan(math.radians(p.phi)), math.tan(math.radians(PSI))
    kappa_r = p.G_II / (0.5 * c) if c > 0 else math.inf
    s_peak = (c + SIGMA_N0 * tanphi) / KT
    path = np.r_[np.linspace(0.0, s_peak, 50)[1:], np.linspace(s_peak, s_peak + 3 * U_LIM, 3000)[1:]]
    kap_prev, seen_before, seen_after = 0.0, 0, 0
    for s in path:
        sig, tau, sig1, tau1 = dr.move(o, s)
        assert sig1 == pytest.approx(sig, rel=1e-8) and tau1 == pytest.approx(tau, rel=1e-8)  # both ends
        kappa = s - tau / KT  # plastic slip of a monotonic path
        if kappa < 1e-12:
            assert sig == pytest.approx(-SIGMA_N0, rel=1e-12)
            continue
        sig_n = SIGMA_N0 + KN * tanpsi * min(kappa, U_LIM)
        assert sig == pytest.approx(-sig_n, rel=1e-9)
        # z from the damage of the previous plastic slip (the law's one-step lag).
        z = 1.0 - kap_prev / kappa_r
        assert tau == pytest.approx(c * z + sig_n * tanphi, rel=1e-9 if c == 0 else 1e-6)
        kap_prev = kappa
        seen_before += kappa < U_LIM
        seen_after += kappa > U_LIM
    assert seen_before > 100 and seen_after > 100
    # Beyond u_lim the dilation has stopped: the confinement stays at its last value.
    sig_end = SIGMA_N0 + KN * tanpsi * U_LIM
    assert sig == pytest.approx(-sig_end, rel=1e-9)
    assert not dr.cs.broken[0]
    # The faces are now separated by d = tan(psi) u_lim: at that opening the joint carries no
    # normal traction (free faces stand open), and it opens no further under more slip.
    d = tanpsi * U_LIM
    sig, tau, _, _ = dr.move(d, s)
    assert abs(sig) < 1e-9 * SIGMA_N0


def test_energy_ledger_closes_on_a_dilating_path():
    """Work done on the element = stored + fracture + friction, at every step, to 1e-6 of the
    work: confined sliding through u_lim, changing confinement while sliding, reversal, and
    opening into tension while sliding (the dilation closes the gap)."""
    p = dilatant(dilation_limit=4e-5)
    dr = Driver(p)
    o_c = -SIGMA_N0 / KN
    tanphi = math.tan(math.radians(p.phi))
    s_peak = (p.c + SIGMA_N0 * tanphi) / KT
    segs = [
        (np.linspace(0, o_c, 20), np.zeros(20)),                                        # close
        (np.full(1500, o_c), np.linspace(0, s_peak + 2.5e-5, 1500)),                    # slide, dilate
        (o_c * (1 + 0.5 * np.sin(np.linspace(0, 3 * np.pi, 1500))),                     # vary confinement
         s_peak + 2.5e-5 + np.linspace(0, 3e-5, 1500)),
        (np.full(2000, o_c * 1.2), s_peak + 5.5e-5 - np.linspace(0, 2 * s_peak + 4e-5, 2000)),  # reverse
        (np.linspace(o_c * 1.2, 3e-5, 1500), -s_peak - 1.5e-5 - np.linspace(0, 1e-5, 1500)),    # open, slide
    ]
    worst, w_max = 0.0, 0.0
    for os_, ss in segs:
        for o, s in zip(os_, ss):
            dr.move(o, s)
            w_max = max(w_max, abs(dr.work))
            worst = max(worst, abs(dr.work - ledger(dr)))
    e = dr.cs.energy_terms()
    assert not dr.cs.broken[0] and e["fracture"] > 0 and e["crack_friction"] > 0
    assert worst <= 1e-6 * w_max, (worst, w_max)


def test_sliding_open_joint_dilates_shut_then_confines_itself():
    """At a fixed small opening o > 0 (tension, shear strength c z alone) the slip dilates the
    faces shut: sigma = sec(D) (o - d) while d < o, then Kc (o - d) < 0 and friction appears,
    d = tan(psi) kappa; the ledger closes to 1e-6 through the change of regime."""
    p = dilatant(dilation_limit=1e-4)
    dr = Driver(p)
    o = 0.5 * p.f_t / KN
    tanphi, tanpsi = math.tan(math.radians(p.phi)), math.tan(math.radians(PSI))
    dr.move(o, 0.0)
    worst, w_max, regimes = 0.0, 0.0, set()
    for s in np.linspace(0, p.c / KT + 4 * o / tanpsi, 4000)[1:]:
        sig, tau, _, _ = dr.move(o, s)
        kappa = s - tau / KT
        w_max = max(w_max, abs(dr.work))
        worst = max(worst, abs(dr.work - ledger(dr)))
        oe = o - tanpsi * kappa
        if oe < 0:
            regimes.add("closed")
            assert sig == pytest.approx(KN * oe, rel=1e-9)
            assert abs(tau) == pytest.approx(p.c * (1 - dr.cs.damage[0]) - sig * tanphi, rel=1e-3)
        elif kappa > 0:
            regimes.add("open")
            assert 0.0 <= sig <= KN * oe * (1 + 1e-12)
    assert regimes == {"open", "closed"}
    assert worst <= 1e-6 * w_max, (worst, w_max)


def test_dilation_stores_shear_work_under_confinement():
    """At fixed opening, the shear work of a dilating slip splits into stored normal energy
    sigma_n tan(psi) dkappa and dissipation (c z + sigma_n (tan(phi) - tan(psi))) dkappa."""
    res = {}
    for psi in (0.0, PSI):
        p = props(softening="linear", c=0.0, G_II=0.0, dilation_angle=psi, dilation_limit=U_LIM)
        dr = Driver(p)
        o = -SIGMA_N0 / KN
        dr.move(o, 0.0)
        for s in np.linspace(0, 0.5 * U_LIM, 2000)[1:]:
            dr.move(o, s)
        e = dr.cs.energy_terms()
        res[psi] = (dr.work, e["crack_elastic"], e["crack_friction"])
    tanphi, tanpsi = math.tan(math.radians(30.0)), math.tan(math.radians(PSI))
    s_end = 0.5 * U_LIM
    # c = 0, constant stiffness Kc = Kn: kappa solves s - kappa = (sigma_n0 + Kn tanpsi kappa) tanphi / Kt.
    kappa = (s_end - SIGMA_N0 * tanphi / KT) / (1 + KN * tanpsi * tanphi / KT)
    sig_n = SIGMA_N0 + KN * tanpsi * kappa
    L = 0.5
    friction = (SIGMA_N0 * kappa + 0.5 * KN * tanpsi * kappa ** 2) * (tanphi - tanpsi) * L
    assert res[PSI][2] == pytest.approx(friction, rel=1e-3)
    normal_stored = 0.5 * (sig_n ** 2 - SIGMA_N0 ** 2) / KN * L
    shear_stored = 0.5 * (sig_n * tanphi) ** 2 / KT * L
    assert res[PSI][1] == pytest.approx(0.5 * SIGMA_N0 ** 2 / KN * L + normal_stored + shear_stored, rel=1e-6)
    assert res[PSI][2] < res[0.0][2]


def test_psi_zero_is_the_law_without_dilation():
    """psi = 0 reproduces the law of the project before dilation (values recorded from it,
    commit c436cc0; bit-identity of forces, state and dissipation on mixed-mode, sliding and
    strength-reduction paths was checked against it), and dilation never acts without slip."""
    dr = Driver(props(softening="linear"))
    tr = []
    for k, s in enumerate(np.linspace(0, 4e-5, 400)):
        o = -2e-6 + 1e-6 * math.sin(k / 20)
        tr.append(dr.move(o, s, 0.7 * o, 0.9 * s))
    dr.cs.interfaces.set_reduction(1 / 0.7)
    for k, s in enumerate(np.linspace(4e-5, -1e-5, 300)):
        tr.append(dr.move(1e-6 * math.sin(k / 10), s))
    tr = np.array(tr)
    e = dr.cs.energy_terms()
    d = dr.cs.dissipated[0]
    recorded = {
        "work": 83.4360068829577, "diss": (0.0008163642388180529, 61.35180447444715, 20.33926010039789),
        "elastic": 1.4303455198659338,
        "tractions": [-1401528.9096767907, 2506265.958803042, -981070.4475299278, 2255639.303975685,
                      -1108603.798406303, 2406334.3327198173, -776025.1352013937, 2238626.9487767983,
                      -132351.75009777304, -1211717.8494103893, -132351.75009777304, -1211879.188776195],
    }
    rel = 1e-12  # bitwise on this machine; round-off latitude for other CPUs (fastmath)
    assert dr.work == pytest.approx(recorded["work"], rel=rel)
    assert tuple(d) == pytest.approx(recorded["diss"], rel=rel)
    assert e["crack_elastic"] == pytest.approx(recorded["elastic"], rel=rel)
    assert tr[[50, 399, 650]].ravel() == pytest.approx(recorded["tractions"], rel=rel)
    # Pure mode I (no plastic slip): a dilatant joint is bit for bit the same as a plain one.
    out = []
    for p in (props(), props(dilation_angle=PSI, dilation_limit=U_LIM)):
        dr = Driver(p)
        out.append([dr.move(o, 0.0) for o in np.linspace(0, 3e-6, 300)] + [tuple(dr.cs.dissipated[0]) + (dr.work,)])
    assert np.array_equal(np.array(out[0]), np.array(out[1]))


def test_strength_reduction_keeps_dilation_and_the_books():
    """A reduction keeps tan(psi) (geometry) while tan(phi)/F >= tan(psi), caps it at
    tan(phi)/F below; it neither creates nor removes stored energy (the dilatant opening is
    state), and what it makes slide is booked."""
    p = dilatant(dilation_limit=1e-4)
    dr = Driver(p)
    o = -SIGMA_N0 / KN
    dr.move(o, 0.0)
    tanphi, tanpsi = math.tan(math.radians(p.phi)), math.tan(math.radians(PSI))
    s = (p.c + SIGMA_N0 * tanphi) / KT + 1e-5
    for si in np.linspace(0, s, 1000)[1:]:
        dr.move(o, si)
    before = ledger(dr)
    dr.cs.interfaces.set_reduction(1 / 0.8)
    assert ledger(dr) == pytest.approx(before, rel=1e-12)
    assert dr.cs._dil[0, CD_TANPSI] == tanpsi
    # Further slip: the confinement still grows at Kc tan(psi) per unit plastic slip.
    sig_a, tau_a, _, _ = dr.move(o, s + 1e-6)
    sig_b, tau_b, _, _ = dr.move(o, s + 2e-6)
    dkap = 1e-6 - (tau_b - tau_a) / KT
    assert (sig_a - sig_b) / dkap == pytest.approx(KN * tanpsi, rel=1e-9)
    # F = 4: tan(phi)/F = 0.144 < tan(psi) = 0.176: capped, the sliding dissipation stays >= 0.
    dr.cs.interfaces.set_reduction(1 / 0.25)
    assert dr.cs._dil[0, CD_TANPSI] == pytest.approx(0.25 * tanphi, rel=1e-12)
    fr = dr.cs.dissipated[0, CW_FRICTION]
    for si in np.linspace(s + 2e-6, s + 2e-5, 200)[1:]:
        dr.move(o, si)
        assert dr.cs.dissipated[0, CW_FRICTION] >= fr
        fr = dr.cs.dissipated[0, CW_FRICTION]
    dr.cs.interfaces.set_reduction(1 / 1.0)
    assert dr.cs._dil[0, CD_TANPSI] == tanpsi


def test_checkpoint_round_trip_keeps_the_dilation():
    p = dilatant()
    a, b = Driver(p), Driver(p)
    o = -SIGMA_N0 / KN
    for s in np.linspace(0, 3e-5, 300):
        a.move(o, s)
    a.cs.interfaces.set_reduction(1 / 0.25)
    b.cs.load_state_dict(a.cs.state_dict())
    b.step = a.step
    assert np.array_equal(b.cs._dil, a.cs._dil)
    for s in np.linspace(3e-5, 5e-5, 50):
        assert a.move(o, s) == b.move(o, s)
    # A state saved before dilation existed (N_STATE_V1 = 8 columns) loads with d = 0.
    st = a.cs.state_dict()
    st["state"] = st["state"][:, :N_STATE_V1]
    del st["dilation"]
    b.cs.load_state_dict(st)
    assert np.all(b.cs._state[:, CS_DIL0:] == 0.0) and np.array_equal(b.cs._dil, a.cs._dil)


def test_bad_dilation_input_is_rejected():
    with pytest.raises(ValueError, match=r"dilation_angle psi must be in \[0, 90\)"):
        props(phi=30.0, dilation_angle=-1.0, dilation_limit=1e-3)
    with pytest.raises(ValueError, match="exceeds the friction angle"):
        props(phi=30.0, dilation_angle=35.0, dilation_limit=1e-3)
    with pytest.raises(ValueError, match="needs a dilation_limit"):
        props(dilation_angle=5.0)
    with pytest.raises(ValueError, match="dilation_limit u_lim must not be negative"):
        props(dilation_limit=-1.0)
    with pytest.raises(ValueError, match="dilation_limit must be a finite number"):
        props(dilation_angle=5.0, dilation_limit=math.inf)
    CrackSet(two_triangles(), {0: props(dilation_angle=30.0, dilation_limit=1e-3)})  # psi = phi is allowed
