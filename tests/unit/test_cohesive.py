"""Cohesive crack elements: single-element physics, property sets, heterogeneity, kernels.

Single-element tests drive the four nodes of one crack element by prescribed displacements
(quasi-statically, many small increments), read the nodal forces, and integrate the work
``W = int T . d(delta)`` done on the element over the whole separation history. Tolerances
are those of docs/verification.md (peak 0.5 %, energy 1 %).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fdem.physics.crack_properties import CrackProperties, softening_integral, softening_max_slope
from fdem.physics.cracks import CrackSet
from fdem.physics.heterogeneity import Heterogeneity
from fdem.cases.four_slopes import four_slope_property_sets
from fdem.kernels import cracks as K
from fdem.mesh.mesh import Mesh, structured_rectangle
from fdem.mesh.topology import build_topology

L = 0.5  # crack element length [m]
KN = 1.0e12  # normal stiffness per unit area [Pa/m]
KT = 5.0e11  # tangential stiffness [Pa/m]


def props(**kw) -> CrackProperties:
    base = dict(f_t=1.0e6, c=2.0e6, phi=30.0, G_I=100.0, G_II=300.0, k_n=KN, k_t=KT, name="rock")
    base.update(kw)
    return CrackProperties(**base)


def two_triangles(length=L, tag=0):
    """Triangle A above, B below the edge (0,0)-(length,0): one crack element, t = +x, n = -y."""
    pts = np.array([[0.0, 0.0], [length, 0.0], [length / 2, 1.0], [length / 2, -1.0]])
    tris = np.array([[0, 1, 2], [1, 0, 3]])
    if tag:
        mesh = Mesh(points=pts, triangles=tris, triangle_body=np.zeros(2, np.int32),
                    lines=np.array([[0, 1]]), line_group=np.array([0], np.int32),
                    group_names=(f"joint_set_{tag}",))
    else:
        mesh = Mesh(points=pts, triangles=tris, triangle_body=np.zeros(2, np.int32))
    return build_topology(mesh)


class Driver:
    """Prescribe the separation (opening o, slip s) of both ends of one crack element."""

    def __init__(self, p: CrackProperties, tag=0, scheme="colour", length=L, **kw):
        self.topo = two_triangles(length, tag)
        self.cs = CrackSet(self.topo, {tag: p}, scheme=scheme, **kw)
        self.cn = self.topo.crack_nodes[0]
        assert np.allclose(self.topo.x0[self.cn[1]] - self.topo.x0[self.cn[0]], [length, 0.0])
        self.n = np.array([0.0, -1.0])
        self.t = np.array([1.0, 0.0])
        self.w = 0.5 * length
        self.step = 0
        self.work = 0.0
        self.x_prev = self.topo.x0.copy()
        self.f_prev = np.zeros_like(self.x_prev)

    def move(self, o0, s0, o1=None, s1=None):
        """Set the separations; return tractions (sigma, tau) [Pa] at ends 0 and 1 (B side)."""
        o1 = o0 if o1 is None else o1
        s1 = s0 if s1 is None else s1
        x = self.topo.x0.copy()
        x[self.cn[3]] += o0 * self.n + s0 * self.t
        x[self.cn[2]] += o1 * self.n + s1 * self.t
        f = np.zeros_like(x)
        self.cs.add_forces(x, None, f, 1e-3, self.step)
        self.step += 1
        # Work done on the element by the agent that holds the nodes: -f . dx (trapezoid).
        dx = x - self.x_prev
        self.work += float(np.sum(-0.5 * (f + self.f_prev) * dx))
        self.x_prev, self.f_prev = x, f
        fb3, fb2 = f[self.cn[3]], f[self.cn[2]]
        assert np.allclose(f.sum(axis=0), 0.0, atol=1e-9 * (1 + np.abs(f).max()))
        return (-fb3 @ self.n / self.w, -fb3 @ self.t / self.w, -fb2 @ self.n / self.w, -fb2 @ self.t / self.w)


def geometric(a, b, n):
    return np.geomspace(a, b, n)


# ----------------------------------------------------------------------------- the shape
def test_softening_curve_shape():
    d = np.linspace(0, 1, 1001)
    for kind in (K.MUNJIZA, K.LINEAR):
        z = np.array([K.softening(v, kind) for v in d])
        assert z[0] == pytest.approx(1.0, abs=1e-14) and z[-1] == pytest.approx(0.0, abs=1e-14)
        assert np.all(np.diff(z) <= 1e-15)
    assert softening_integral("munjiza") == pytest.approx(0.386307, rel=1e-5)
    assert softening_integral("linear") == 0.5
    assert softening_max_slope("munjiza") == pytest.approx(2.0402, rel=1e-3)
    # Munjiza's curve leaves the peak with zero slope.
    assert (1.0 - K.softening(1e-4, K.MUNJIZA)) < 1e-6


# ----------------------------------------------------------------------------- mode I
@pytest.mark.parametrize("softening", ["munjiza", "linear"])
def test_mode_I_peak_and_fracture_energy(softening):
    p = props(softening=softening)
    dr = Driver(p)
    op = p.f_t / KN
    o_r = op + (p.G_I - p.f_t ** 2 / (2 * KN)) / (p.f_t * softening_integral(softening))
    path = np.r_[np.linspace(0, op, 50)[1:], np.linspace(op, 1.02 * o_r, 4000)[1:]]
    peak, o_break = 0.0, None
    for o in path:
        sig, tau, sig1, tau1 = dr.move(o, 0.0)
        assert sig == pytest.approx(sig1) and abs(tau) < 1e-6 * p.f_t
        peak = max(peak, sig)
        if dr.cs.broken[0]:
            o_break = o
            break
    assert o_break is not None and o_break == pytest.approx(o_r, rel=2e-3)
    assert peak == pytest.approx(p.f_t, rel=5e-3)
    assert dr.work == pytest.approx(p.G_I * L, rel=1e-2)
    # The element's own ledger agrees with the external work; the event records it.
    e = dr.cs.energy_terms()
    assert e["fracture"] == pytest.approx(p.G_I * L, rel=1e-2)
    assert e["crack_elastic"] == 0.0 and e["crack_friction"] == 0.0
    ev = dr.cs.events
    assert len(ev) == 1 and ev["mode"][0] == "I" and ev["element"][0] == 0
    assert ev["energy"][0] == pytest.approx(p.G_I * L, rel=1e-2)
    assert ev["length"][0] == L and ev["x"][0] == pytest.approx(L / 2, abs=1e-3)
    assert dr.cs.damage[0] == 1.0 and dr.cs.n_active == 0
    # From now on the faces belong to contact: the element adds no force, whatever the motion.
    assert dr.move(2 * o_r, 0.0) == (0.0, 0.0, 0.0, 0.0)
    assert dr.move(-o_r, 0.5 * o_r) == (0.0, 0.0, 0.0, 0.0)


def test_compression_is_resisted_by_the_normal_penalty():
    dr = Driver(props())
    for o in np.linspace(0, -1e-5, 20)[1:]:
        sig, tau, _, _ = dr.move(o, 0.0)
        assert sig == pytest.approx(KN * o, rel=1e-12)
    assert dr.cs.damage[0] == 0.0


def test_a_picometre_opening_is_resolved_however_far_the_element_lies_from_the_origin():
    """The crack kernels read displacements, not positions: 10 km from the origin, where
    positions are stored to 1.8e-12 m, an opening of 1e-13 m gives ``KN o`` to round-off as it
    does at the origin once the element is bound to the state's displacements; read from the
    positions (no binding) it is lost to their spacing."""
    o = -1.0e-13
    sig = {}
    for far, bound in ((0.0, True), (1.0e4, True), (1.0e4, False)):
        topo = dataclasses.replace(two_triangles(), x0=two_triangles().x0 + far)
        cs = CrackSet(topo, {0: props()})
        cn = topo.crack_nodes[0]
        u = np.zeros_like(topo.x0)
        u[cn[3]] = [0.0, -o]   # n = -y: an opening o moves B_p by o n
        u[cn[2]] = [0.0, -o]
        x = topo.x0 + u
        if bound:
            cs.bind_displacement(x, u)
        f = np.zeros_like(x)
        cs.add_forces(x, None, f, 1e-3, 0)
        sig[(far, bound)] = -f[cn[3]] @ np.array([0.0, -1.0]) / (0.5 * L)
    assert sig[(0.0, True)] == pytest.approx(KN * o, rel=1e-12)
    assert sig[(1.0e4, True)] == pytest.approx(KN * o, rel=1e-12)
    assert abs(sig[(1.0e4, False)] - KN * o) > 0.5 * abs(KN * o)   # x + 1e-13 rounds to x: no opening seen


# ----------------------------------------------------------------------------- mode II
@pytest.mark.parametrize("softening", ["munjiza", "linear"])
@pytest.mark.parametrize("sigma_n", [0.0, 1.0e6, 4.0e6])
def test_mode_II_peak_and_fracture_energy(sigma_n, softening):
    """Peak c + sigma_n tan(phi); the cohesive part dissipates G_II L, friction the rest.

    Convention: G_II is the work of the cohesive part of the shear strength. Under a normal
    stress the traction softens from c + sigma_n tan(phi) to the residual sigma_n tan(phi);
    the frictional work sigma_n tan(phi) x (plastic slip) is friction, not fracture.
    """
    p = props(softening=softening)
    dr = Driver(p)
    o_c = -sigma_n / KN
    for o in np.linspace(0.0, o_c, 20)[1:]:
        dr.move(o, 0.0)
    w_normal = dr.work  # elastic energy of the closure, stored
    assert w_normal == pytest.approx(0.5 * sigma_n ** 2 / KN * L, rel=1e-9, abs=1e-12)
    tanphi = math.tan(math.radians(p.phi))
    f_s = p.c + sigma_n * tanphi
    s_p = f_s / KT
    kappa_r = p.G_II / (p.c * softening_integral(softening))
    path = np.r_[np.linspace(0, s_p, 50)[1:], np.linspace(s_p, s_p + 1.05 * kappa_r, 5000)[1:]]
    peak, last = 0.0, None
    for s in path:
        w_before = dr.work
        sig, tau, sig1, tau1 = dr.move(o_c, s)
        if dr.cs.broken[0]:
            dr.work = w_before  # the broken element hands the faces to contact
            break
        assert sig == pytest.approx(-sigma_n, rel=1e-9, abs=1e-6)
        peak = max(peak, tau)
        last = (s, tau)
    assert dr.cs.broken[0]
    assert peak == pytest.approx(f_s, rel=5e-3)
    s_end, tau_end = last
    assert tau_end == pytest.approx(sigma_n * tanphi, rel=2e-3, abs=1e-3 * p.c)
    w_shear = dr.work - w_normal
    elastic_end = 0.5 * tau_end ** 2 / KT * L
    plastic_slip = s_end - tau_end / KT
    friction = sigma_n * tanphi * plastic_slip * L
    cohesive = w_shear - elastic_end - friction
    assert cohesive == pytest.approx(p.G_II * L, rel=1e-2)
    e = dr.cs.energy_terms()
    assert e["crack_friction"] == pytest.approx(friction, rel=1e-2, abs=1e-9)
    assert dr.cs.events["mode"][0] == "II"
    assert dr.cs.crack_fields()["failure_mode"][dr.cs.events["element"][0]] == 2
    assert dr.cs.events["energy_II"][0] == pytest.approx(p.G_II * L, rel=1e-2)


def test_tension_cuts_off_friction():
    """In tension the shear strength is the cohesion alone (no negative friction)."""
    p = props()
    dr = Driver(p)
    o = 0.5 * p.f_t / KN
    dr.move(o, 0.0)
    peak = 0.0
    for s in np.linspace(0, 1.5 * p.c / KT, 300)[1:]:
        peak = max(peak, dr.move(o, s)[1])
    assert peak == pytest.approx(p.c, rel=5e-3)


# ----------------------------------------------------------------------------- mixed mode
def test_mixed_mode_path():
    """Proportional opening + slip: strengths are never exceeded, the elliptical damage breaks
    the element earlier than either pure mode, the ledger balances the external work."""
    p = props()
    dr = Driver(p)
    zb = softening_integral("munjiza")
    o_r = p.f_t / KN + (p.G_I - p.f_t ** 2 / (2 * KN)) / (p.f_t * zb)
    kappa_r = p.G_II / (p.c * zb)
    ratio = o_r / kappa_r  # opening per unit slip: equal normalised softening displacements
    s_max = 2 * kappa_r
    D_prev = 0.0
    for s in np.linspace(0, s_max, 6000)[1:]:
        sig, tau, _, _ = dr.move(ratio * s, s)
        assert sig <= p.f_t * (1 + 1e-9) and tau <= p.c * (1 + 1e-9)
        D = dr.cs.damage[0]
        assert D >= D_prev
        D_prev = D
        if dr.cs.broken[0]:
            break
    assert dr.cs.broken[0]
    ev = dr.cs.events[0]
    assert ev["mode"] == "mixed"
    assert s < kappa_r and ratio * s < o_r  # earlier than pure mode II and pure mode I
    assert 0 < ev["energy_I"] < p.G_I * L and 0 < ev["energy_II"] < p.G_II * L
    e = dr.cs.energy_terms()
    assert dr.work == pytest.approx(e["fracture"] + e["crack_friction"] + e["crack_released"], rel=1e-2)


# ----------------------------------------------------------------------------- unloading
def test_unloading_and_reloading_follow_the_damaged_stiffness():
    p = props()
    dr = Driver(p)
    op = p.f_t / KN
    zb = softening_integral("munjiza")
    dO = (p.G_I - p.f_t ** 2 / (2 * KN)) / (p.f_t * zb)
    o_u = op + 0.3 * dO
    for o in np.r_[np.linspace(0, op, 30)[1:], np.linspace(op, o_u, 600)[1:]]:
        sig_u = dr.move(o, 0.0)[0]
    D_u = dr.cs.damage[0]
    assert D_u == pytest.approx(0.3, rel=1e-6)
    assert sig_u == pytest.approx(p.f_t * K.softening(0.3, K.MUNJIZA), rel=1e-6)
    k_dam = sig_u / o_u
    assert k_dam < 1e-2 * KN  # the secant of the damaged element, far below the penalty
    w_at_unload = dr.work
    # Unload to zero and reload to the same opening: linear with the damaged (secant) stiffness.
    for o in np.r_[np.linspace(o_u, 0, 100)[1:], np.linspace(0, o_u, 100)[1:]]:
        sig = dr.move(o, 0.0)[0]
        assert sig == pytest.approx(k_dam * o, rel=1e-9, abs=1e-9 * p.f_t)
        assert dr.cs.damage[0] == D_u  # no damage growth inside the envelope, no healing
    assert dr.work == pytest.approx(w_at_unload, rel=1e-9)  # the loop dissipates nothing
    # Closing the crack: the full normal penalty is back in compression.
    assert dr.move(-1e-7, 0.0)[0] == pytest.approx(-KN * 1e-7, rel=1e-9)
    dr.move(0.0, 0.0)
    # Beyond the unloading point the softening resumes on the original envelope.
    for o in np.linspace(0, o_u + 0.1 * dO, 400)[1:]:
        sig = dr.move(o, 0.0)[0]
    assert dr.cs.damage[0] == pytest.approx(0.4, rel=1e-6)
    assert sig == pytest.approx(p.f_t * K.softening(0.4, K.MUNJIZA), rel=1e-6)


def test_shear_unloading_keeps_the_damaged_strength():
    """After partial shear softening: unloading is elastic (plastic slip stays), reloading
    yields at the damaged strength z(D) c + sigma_n tan(phi)."""
    p = props(softening="linear")
    dr = Driver(p)
    sigma_n = 1e6
    o_c = -sigma_n / KN
    dr.move(o_c, 0.0)
    tanphi = math.tan(math.radians(p.phi))
    kappa_r = p.G_II / (p.c * 0.5)
    s_u = (p.c + sigma_n * tanphi) / KT + 0.4 * kappa_r
    for s in np.linspace(0, s_u, 2000)[1:]:
        tau_u = dr.move(o_c, s)[1]
    D = dr.cs.damage[0]
    s_pl = s_u - tau_u / KT  # plastic slip: beyond 0.4 kappa_r by the elastic slip released
    assert D == pytest.approx(s_pl / kappa_r, rel=1e-3) and D > 0.4
    assert tau_u == pytest.approx((1 - D) * p.c + sigma_n * tanphi, rel=1e-3)
    for s in np.linspace(s_u, s_pl, 50)[1:]:
        tau = dr.move(o_c, s)[1]
        assert tau == pytest.approx(KT * (s - s_pl), rel=1e-6, abs=1e-6 * p.c)
    peak = 0.0
    for s in np.linspace(s_pl, s_u + 1e-3 * kappa_r, 200)[1:]:
        peak = max(peak, dr.move(o_c, s)[1])
    assert peak == pytest.approx((1 - D) * p.c + sigma_n * tanphi, rel=2e-3)


# ----------------------------------------------------------------------------- property sets
def test_dfn_elements_fail_before_intact_ones():
    sets = four_slope_property_sets()
    drivers = {tag: Driver(sets[tag], tag=tag, length=0.3) for tag in (0, 1)}
    assert drivers[1].topo.crack_tag[0] == 1 and drivers[0].topo.crack_tag[0] == 0
    for mode in ("I", "II"):
        drivers = {tag: Driver(sets[tag], tag=tag, length=0.3) for tag in (0, 1)}
        broke_at = {}
        for k, u in enumerate(np.geomspace(1e-8, 0.1, 4000)):
            for tag, dr in drivers.items():
                if tag in broke_at:
                    continue
                dr.move(u, 0.0) if mode == "I" else dr.move(-1e-6, u)
                if dr.cs.broken[0]:
                    broke_at[tag] = k
        assert broke_at[1] < broke_at[0], mode


def test_paper_penalty_mapping():
    sets = four_slope_property_sets()
    kn, kt = sets[0].stiffness(np.array([0.5, 1.0]))
    assert np.allclose(kn, 5.9e9 / np.array([0.5, 1.0]))
    assert np.allclose(kt, 917e9)


def test_bad_input_is_rejected_with_clear_errors():
    with pytest.raises(ValueError, match="c must not be negative"):
        props(c=-1.0)
    with pytest.raises(ValueError, match="G_I must not be negative"):
        props(G_I=-5.0)
    with pytest.raises(ValueError, match="tensile strength"):
        props(f_t=0.0)
    with pytest.raises(ValueError, match="exactly one of p_n"):
        CrackProperties(f_t=1e6, c=1e6, phi=30, G_I=10, G_II=10)
    topo = two_triangles()
    # Snap-back: G_I must exceed f_t^2 / (2 k_n) = 0.5 J/m^2 here.
    with pytest.raises(ValueError, match=r"property set 0 \(rock\).*smallest admissible G_I is 0\.5 J/m\^2"):
        CrackSet(topo, {0: props(G_I=0.4)})
    # Mode II (plastic slip, Munjiza shape): G_II > Zbar max|z'| c^2 / k_t.
    need = softening_integral() * softening_max_slope() * (2e6) ** 2 / KT
    with pytest.raises(ValueError, match=f"smallest admissible G_II is {need:.6g}"):
        CrackSet(topo, {0: props(G_II=0.9 * need)})
    CrackSet(topo, {0: props(G_II=1.1 * need)})
    # A joint-set tag in the topology without a property set.
    with pytest.raises(ValueError, match=r"tag\(s\) \[2\] have no property set.*DFN joint set 2"):
        CrackSet(two_triangles(tag=2), {0: props(), 1: props()})
    with pytest.raises(ValueError, match="distribution"):
        Heterogeneity(distribution="lognormal")
    cs = CrackSet(topo, {0: props()})
    with pytest.raises(ValueError, match="must be positive and finite"):
        cs.interfaces.set_reduction(-1.0)
    with pytest.raises(ValueError, match="smallest admissible G_I"):
        cs.interfaces.set_reduction(1e-3)  # a stronger rock (F = 1e-3) would snap back with this G_I


def test_tags_give_elements_properties_other_than_the_geometry_s():
    """``tags=`` reads an element's properties from another set (an elastic side band, ground at
    full strength) while the topology shared with the outputs keeps the geometry's tag: the
    peak traction of an intact element (tag 0) given tag 5 is set 5's f_t, not set 0's."""
    strong = props()
    dr = Driver(strong)
    dr.cs = CrackSet(dr.topo, {0: props(f_t=0.25 * strong.f_t), 5: strong}, tags=np.array([5]))
    assert dr.cs.tag.tolist() == [5] and dr.topo.crack_tag.tolist() == [0] and dr.cs.topology is dr.topo
    peak = max(dr.move(o, 0.0)[0] for o in np.linspace(0, 2 * strong.f_t / KN, 400)[1:])
    assert peak == pytest.approx(strong.f_t, rel=5e-3)
    with pytest.raises(ValueError, match=r"one tag per crack element \(1\), got shape \(2,\)"):
        CrackSet(dr.topo, {0: strong}, tags=np.array([0, 0]))


# ----------------------------------------------------------------------------- run-time strength
def test_strength_reduction_scales_f_t_c_and_tan_phi():
    p = props()
    factor = 0.6
    dr = Driver(p)
    dr.cs.interfaces.set_reduction(1 / factor)
    assert dr.cs.strength_factor == factor
    peak = max(dr.move(o, 0.0)[0] for o in np.linspace(0, 2 * p.f_t / KN, 400)[1:])
    assert peak == pytest.approx(factor * p.f_t, rel=5e-3)
    dr = Driver(p)
    dr.cs.interfaces.set_reduction(1 / factor)
    sigma_n = 2e6
    o_c = -sigma_n / KN
    dr.move(o_c, 0.0)
    f_s = factor * (p.c + sigma_n * math.tan(math.radians(p.phi)))
    peak = max(dr.move(o_c, s)[1] for s in np.linspace(0, 2 * f_s / KT, 400)[1:])
    assert peak == pytest.approx(f_s, rel=5e-3)
    assert dr.cs.residual_friction[0] == pytest.approx(factor * math.tan(math.radians(p.phi)))


# ----------------------------------------------------------------------------- heterogeneity
def test_heterogeneity_normal_and_weibull():
    tag = np.zeros(200_000, np.int32)
    tag[::2] = 1
    h = Heterogeneity("normal", cov=0.1, seed=3).draw(tag)
    assert h.mean() == pytest.approx(1.0, abs=2e-3) and h.std() == pytest.approx(0.1, rel=2e-2)
    assert np.array_equal(h, Heterogeneity("normal", cov=0.1, seed=3).draw(tag))
    assert not np.array_equal(h, Heterogeneity("normal", cov=0.1, seed=4).draw(tag))
    hw = Heterogeneity("weibull", weibull_modulus=5.0, seed=1).draw(tag)
    m = 5.0
    cov = math.sqrt(math.gamma(1 + 2 / m) / math.gamma(1 + 1 / m) ** 2 - 1)
    assert hw.mean() == pytest.approx(1.0, abs=3e-3) and hw.std() == pytest.approx(cov, rel=2e-2)
    only1 = Heterogeneity("normal", cov=0.3, seed=0, tags=(1,)).draw(tag)
    assert np.all(only1[tag == 0] == 1.0) and only1[tag == 1].std() > 0.25
    assert only1.min() >= 0.05


def test_heterogeneous_element_peaks_follow_their_multiplier():
    p = props()
    dr = Driver(p, heterogeneity=Heterogeneity("weibull", weibull_modulus=3.0, seed=7))
    h = dr.cs.strength_multiplier[0]
    assert h != 1.0
    peak = max(dr.move(o, 0.0)[0] for o in np.linspace(0, 2 * h * p.f_t / KN, 400)[1:])
    assert peak == pytest.approx(h * p.f_t, rel=5e-3)


# ----------------------------------------------------------------------------- kernels
def test_rigid_motion_gives_no_force():
    topo = build_topology(structured_rectangle(4, 3, 2.0, 1.5))
    cs = CrackSet(topo, {0: props()})
    th = math.radians(120.0)
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    x = topo.x0 @ R.T + np.array([3.0, -1.0])
    f = np.zeros_like(x)
    cs.add_forces(x, None, f, 1e-4, 0)
    assert np.abs(f).max() < 1e-6 * 1e6 * L
    assert cs.energy_terms()["crack_elastic"] < 1e-20


def random_cracked_state(scheme, steps=6, seed=0, parallel_min=0):
    topo = build_topology(structured_rectangle(12, 9, 1.2, 0.9))
    cs = CrackSet(topo, {0: props(G_I=2.0, G_II=40.0)}, scheme=scheme, parallel_min=parallel_min,
                  heterogeneity=Heterogeneity("normal", cov=0.2, seed=1))
    rng = np.random.default_rng(seed)
    v = rng.standard_normal(topo.x0.shape) * 2e-6
    fs = []
    for k in range(steps):
        x = topo.x0 + (k + 1) * v
        f = np.zeros_like(x)
        cs.add_forces(x, None, f, 1e-5, k)
        fs.append(f)
    return cs, fs


def test_colour_gather_and_serial_loops_agree():
    a, fa = random_cracked_state("colour")
    b, fb = random_cracked_state("gather")
    c, fc = random_cracked_state("colour", parallel_min=10**9)
    assert 0 < a.broken.sum() < a.n_cracks and a.damage.max() == 1.0
    for x, y, z in zip(fa, fb, fc):
        assert np.allclose(x, y, rtol=1e-12, atol=1e-9) and np.allclose(x, z, rtol=1e-12, atol=1e-9)
    for other in (b, c):
        assert np.array_equal(a.broken, other.broken) and np.allclose(a.damage, other.damage)
        assert np.array_equal(a.events["element"], other.events["element"])
    assert a.n_colours <= 5
    # Colour classes really are node-disjoint.
    col = K.colour_elements(a.topology.crack_triangles, a.topology.n_triangles)
    for k in range(col.max() + 1):
        nodes = a.topology.crack_nodes[col == k].ravel()
        assert np.unique(nodes).size == nodes.size


def test_broken_elements_leave_the_active_list():
    cs, fs = random_cracked_state("colour")
    broken = np.flatnonzero(cs.broken)
    assert cs.n_active == cs.n_cracks - broken.size
    assert not np.isin(broken, cs.active).any()
    ev = cs.events
    assert np.array_equal(np.sort(ev["element"]), broken)
    assert set(ev["mode"]) <= {"I", "II", "mixed"} and np.all(ev["energy"] > 0)
    assert np.all(np.diff(ev["step"]) >= 0) and np.all(ev["time"] >= 0)
    fields = cs.crack_fields()
    assert all(v.shape == (cs.n_cracks,) for v in fields.values())
    assert np.array_equal(fields["broken"].astype(bool), cs.broken)
    assert fields["fracture_energy"].sum() == pytest.approx(cs.energy_terms()["fracture"])
    e = cs.energy_terms()
    assert set(e) == {"crack_elastic", "fracture", "crack_friction", "crack_released"}
    assert e["fracture"] > 0


def test_elastic_energy_and_stable_dt():
    p = props()
    dr = Driver(p)
    o, s = 0.3 * p.f_t / KN, 0.2 * p.c / KT
    dr.move(o, s)
    assert dr.cs.energy_terms()["crack_elastic"] == pytest.approx(0.5 * (KN * o * o + KT * s * s) * L, rel=1e-9)
    mass = np.full(dr.topo.n_nodes, 2.0)
    k_end = max(KN, KT) * L / 2
    # Each node carries one element end here: omega^2 = k/m_a + k/m_b.
    assert dr.cs.stable_dt(mass) == pytest.approx(2 / math.sqrt(2 * k_end / 2.0), rel=1e-12)
    # An explicit two-mass oscillator at 0.95 dt stays bounded; at 1.05 dt it blows up.
    for frac, bounded in ((0.95, True), (1.05, False)):
        dt = frac * dr.cs.stable_dt(mass)
        u, v = 1e-9, 0.0
        for _ in range(400):
            v += -(2 * k_end / 2.0) * u * dt
            u += v * dt
        assert (abs(u) < 1e-8) == bounded


def test_held_elastic_elements_neither_damage_nor_break():
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology

    topo = build_topology(structured_rectangle(1, 1, 1.0, 1.0, diagonal="right"))
    p = CrackProperties(f_t=1e6, c=2e6, phi=30, G_I=100.0, G_II=1000.0, p_n=1e10)
    cs = CrackSet(topo, {0: p})
    cn = topo.crack_nodes[0]
    t = topo.x0[cn[1]] - topo.x0[cn[0]]
    t /= np.linalg.norm(t)
    n = np.array([t[1], -t[0]])
    kn = p.p_n / topo.crack_length0[0]
    opening = 3 * p.f_t / kn  # three times the peak opening
    x = topo.x0.copy()
    x[topo.triangles[topo.crack_triangles[0, 1]]] += opening * n
    cs.hold_elastic()
    f = np.zeros_like(x)
    cs.add_forces(x, np.zeros_like(x), f, 1e-7, 0)
    # Traction k_n o on the element's length: the elastic penalty, three times f_t.
    pull = -(f[topo.triangles[topo.crack_triangles[0, 1]]] @ n).sum()
    assert pull == pytest.approx(kn * opening * topo.crack_length0[0], rel=1e-12)
    assert cs.damage.max() == 0.0 and not cs.broken.any()
    cs.hold_elastic(False)
    cs.add_forces(x, np.zeros_like(x), np.zeros_like(x), 1e-7, 1)
    assert cs.damage.max() > 0.0


def test_compression_matched_to_contact_hands_over_the_same_force():
    """With ``contact_penalty`` set, a compressed element pushes back as contact would after it
    breaks: same normal force for the same flat penetration (no jump at breakage)."""
    from fdem.physics.contact import pair_energy_force
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology

    topo = build_topology(structured_rectangle(1, 1, 1.0, 1.0, diagonal="right"))
    p_contact = 5e9
    props = {0: CrackProperties(f_t=1e6, c=2e6, phi=30, G_I=100.0, G_II=1000.0, p_n=1e10)}
    cs = CrackSet(topo, props, contact_penalty=p_contact)
    cn = topo.crack_nodes[0]
    t = topo.x0[cn[1]] - topo.x0[cn[0]]
    t /= np.linalg.norm(t)
    n = np.array([t[1], -t[0]])
    depth = 1e-5  # B pushed into A, << element size
    x = topo.x0.copy()
    a, b = topo.triangles[topo.crack_triangles[0]]
    x[b] -= depth * n
    f = np.zeros_like(x)
    cs.add_forces(x, np.zeros_like(x), f, 1e-7, 0)
    crack_push_on_b = f[b].sum(axis=0) @ n
    _, f_a, f_b, _ = pair_energy_force(x[a], x[b], p_contact)
    contact_push_on_b = f_b.sum(axis=0) @ n
    assert crack_push_on_b > 0 and contact_push_on_b > 0
    assert crack_push_on_b == pytest.approx(contact_push_on_b, rel=0.01)
    # Stored energy agrees as well: 0.5 k_c d^2 L against the pair's potential energy.
    e_contact, _, _, _ = pair_energy_force(x[a], x[b], p_contact)
    assert cs.energy_terms()["crack_elastic"] == pytest.approx(e_contact, rel=0.01)


def test_an_element_folded_open_about_its_intact_end_breaks():
    """Triangle B swung open about end 1 (held together: intact there) like a book: end 0
    opens far beyond the critical opening, end 1 stays at zero separation. The element's
    mid-line frame degenerates as the faces fold towards 180 degrees (|m| -> 0), which once
    turned a free opening into a huge closure and blew up a runout. The element must break
    once its faces have turned more than 90 degrees apart, and hold no energy on the way."""
    topo = two_triangles()
    cs = CrackSet(topo, {0: props()})
    cn = topo.crack_nodes[0]
    b_nodes = np.arange(3, 6)                    # triangle B's exploded nodes
    hinge = topo.x0[cn[2]]
    energy, alive_at = [], []
    for step, deg in enumerate(np.linspace(0.0, 179.0, 180)):
        th = math.radians(deg)
        R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        x = topo.x0.copy()
        x[b_nodes] = (topo.x0[b_nodes] - hinge) @ R.T + hinge
        f = np.zeros_like(x)
        cs.add_forces(x, None, f, 1e-4, step)
        energy.append(cs.energy_terms()["crack_elastic"])
        alive_at.append(deg if cs.n_active else None)
    last_alive = max(d for d in alive_at if d is not None)
    assert 85.0 <= last_alive <= 91.0
    assert cs.broken[0] and len(cs.events) == 1
    assert max(energy) < 1e-9 * props().f_t ** 2 / KN * L
