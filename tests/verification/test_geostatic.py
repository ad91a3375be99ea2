"""Geostatic start: static CST solve, crack preloads, unbalanced-force ratio (fdem.geostatic).

Physical facts checked: the uniaxial-strain column (sigma_yy = -rho g (H - y), sigma_xx =
nu/(1-nu) sigma_yy), global equilibrium of the support reactions, nodal equilibrium of every
free exploded node to round-off, the exactness of the traction prior for a uniform stress,
the unbalanced-force ratio of a body released under gravity, and an undamped slope that
stays at rest from the static start while the K0 start jolts.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from fdem.physics.cracks import CrackSet
from fdem.cases.four_slopes import four_slope_property_sets
from fdem.physics.contact import ContactSet
from fdem.solve.geostatic import (conforming_static_stress, crack_preload_forces, crack_strength_check, geostatic_start, preload_residual, unbalanced_force_ratio)
from fdem.physics.elastic import ElasticMaterial
from fdem.mesh.mesh import structured_rectangle
from fdem.solve.model import FIX_Y, Model, geostatic_stress
from fdem.solve.simulation import Simulation

E, NU, RHO, G = 0.59e9, 0.29, 2680.0, 9.81
H_COL, W_COL = 10.0, 2.0


def column(exploded: bool, nx: int = 4, ny: int = 40) -> Model:
    """Gravity column: rollers on the sides, fixed base, plane strain."""
    model = Model.from_mesh(structured_rectangle(nx, ny, W_COL, H_COL), ElasticMaterial(E, NU, RHO),
                            exploded=exploded)
    model.set_gravity(0.0, -G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    return model


@pytest.mark.parametrize("exploded", [False, True])
def test_column_matches_uniaxial_strain(exploded):
    model = column(exploded)
    sol = conforming_static_stress(model)
    c = model.centroids0
    for y in (2.0, 5.0, 8.0):
        band = np.abs(c[:, 1] - y) < 0.5 * H_COL / 40 + 1e-9
        syy = sol.stress[band, 1].mean()
        assert syy == pytest.approx(-RHO * G * (H_COL - y), rel=0.01)
    # laterally confined: sigma_xx = nu/(1-nu) sigma_yy in every triangle
    np.testing.assert_allclose(sol.stress[:, 0], NU / (1 - NU) * sol.stress[:, 1], rtol=1e-9, atol=1e-6)
    # the supports carry the weight of the column: reaction = rho g H W upwards
    assert sol.reaction[1] == pytest.approx(RHO * G * H_COL * W_COL, rel=1e-12)
    assert abs(sol.reaction[0]) < 1e-9 * RHO * G * H_COL * W_COL
    assert sol.residual < 1e-10


def test_exploded_and_conforming_give_the_same_stress():
    a = conforming_static_stress(column(False)).stress
    b = conforming_static_stress(column(True)).stress
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-6)


def test_unsupported_body_and_moving_support_are_refused():
    model = Model.from_mesh(structured_rectangle(2, 2, 1.0, 1.0), ElasticMaterial(E, NU, RHO))
    model.set_gravity(0.0, -G)
    with pytest.raises(ValueError, match="body 0.*no support"):
        conforming_static_stress(model)
    model.roller("bottom", "y")  # vertical support only: sliding in x stays free
    with pytest.raises(ValueError, match="body 0.*1 rigid-body mode"):
        conforming_static_stress(model)
    model.prescribe_velocity("left", vx=1e-3)
    with pytest.raises(ValueError, match=r"node \d+ at \(0, .*prescribed x velocity 0.001"):
        conforming_static_stress(model)


def test_uniform_stress_prior_is_exact():
    """With a uniform stress, no gravity and the boundary held, the traction prior
    F = sigma.n L0/2 already balances every interior node: the correction vanishes."""
    model = Model.from_mesh(structured_rectangle(5, 4, 5.0, 4.0), ElasticMaterial(E, NU, RHO))
    for side in ("bottom", "top", "left", "right"):
        model.fix(side)
    s = np.array([-2.0e5, -5.0e5, 0.7e5])
    stress = np.tile(s, (model.n_triangles, 1))
    F = crack_preload_forces(model, stress)
    topo = model.topology
    cn = topo.crack_nodes
    m = 0.5 * (topo.x0[cn[:, 1]] + topo.x0[cn[:, 2]] - topo.x0[cn[:, 0]] - topo.x0[cn[:, 3]])
    t = m / np.linalg.norm(m, axis=1, keepdims=True)
    n = np.column_stack([t[:, 1], -t[:, 0]])
    sig = np.array([[s[0], s[2]], [s[2], s[1]]])
    expect = 0.5 * topo.crack_length0[:, None] * (n @ sig)
    np.testing.assert_allclose(F[:, 0], expect, atol=1e-9 * np.abs(expect).max())
    np.testing.assert_allclose(F[:, 1], expect, atol=1e-9 * np.abs(expect).max())


@pytest.fixture(scope="module")
def slope_topology():
    from fdem.mesh.triangulate import mesh_geometry
    from fdem.cases.four_slopes import four_slope_geometry
    from fdem.mesh.topology import build_topology

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = mesh_geometry(four_slope_geometry("low", "coarse"), size=2.5)
    return build_topology(mesh)


def slope_model(topo) -> Model:
    model = Model(topo, ElasticMaterial(E, NU, RHO))
    model.set_gravity(0.0, -G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    return model


def test_preload_holds_every_free_node_of_a_jointed_slope(slope_topology):
    model = slope_model(slope_topology)
    sol = conforming_static_stress(model)
    F = crack_preload_forces(model, sol.stress)
    assert F.shape == (slope_topology.n_cracks, 2, 2)
    assert preload_residual(model, sol.stress, F) < 1e-8
    # the base carries the weight: sum of the y reactions = total weight
    weight = RHO * G * float(slope_topology.triangle_area0.sum())
    assert sol.reaction[1] == pytest.approx(weight, rel=1e-10)


def run_slope(topo, start: str, elastic: bool, periods: float = 1.0):
    """Undamped run of the jointed slope with crack elements and contact; returns the maximum
    node speed [m/s] over ``periods`` slope periods 4 H / c_s, the UFR after one step and the
    crack set."""
    model = slope_model(topo)
    cracks = CrackSet(topo, four_slope_property_sets(), contact_penalty=10 * E)
    if start == "static":
        report = geostatic_start(model, cracks)
    else:
        import cases.four_slopes as fs
        from fdem.cases.four_slopes import four_slope_geometry

        surface = fs.ground_surface(four_slope_geometry("low", "coarse").bodies[0])
        model.set_initial_stress(geostatic_stress(RHO, G, surface=surface, poisson=NU))
        report = None
    if elastic:
        cracks.hold_elastic()
    contact = ContactSet(topo, 10 * E, friction_angle=30.0, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=False)
    sim.monitors.clear()
    c_s = np.sqrt(E / (2 * (1 + NU)) / RHO)
    n_steps = int(np.ceil(periods * 4 * 15.0 / c_s / sim.dt))
    sim.step()
    ufr1 = unbalanced_force_ratio(sim)
    vmax = 0.0
    for k in range(n_steps):
        sim.step()
        if k % 20 == 0:
            vmax = max(vmax, float(np.abs(sim.state.v).max()))
    return vmax, ufr1, cracks, report


def test_static_start_stays_at_rest_and_k0_start_jolts(slope_topology):
    v_static, ufr_static, _, report = run_slope(slope_topology, "static", elastic=True)
    v_k0, ufr_k0, _, _ = run_slope(slope_topology, "k0", elastic=True)
    print(f"max speed over one slope period: static start {v_static:.3g} m/s (UFR {ufr_static:.3g}), "
          f"K0 start {v_k0:.3g} m/s (UFR {ufr_k0:.3g})")
    assert report.preload_residual < 1e-8
    assert ufr_static < 1e-8
    assert v_static < 1e-3
    assert v_k0 > 0.05


def test_over_strength_elements_are_those_that_yield_first(slope_topology):
    """At strength factor 1 the crack elements whose static traction exceeds Mohr-Coulomb
    (crack_strength_check) are exactly the ones the law makes slide at the first update."""
    model = slope_model(slope_topology)
    cracks = CrackSet(slope_topology, four_slope_property_sets(), contact_penalty=10 * E)
    report = geostatic_start(model, cracks)
    over = report.over_strength
    flagged = np.union1d(over["tensile"], over["shear"])
    x = slope_topology.x0.copy()
    cracks.add_forces(x, np.zeros_like(x), np.zeros_like(x), 1e-6, 0)
    np.testing.assert_array_equal(cracks.inelastic(), flagged)
    assert set(over["by_tag"]) <= {0, 1}
    assert crack_strength_check(cracks, report.preload)["max_ratio"] == over["max_ratio"]


def test_unbalanced_force_ratio_of_a_released_column():
    """Unstressed column under gravity at rest: every node not held vertically is unbalanced by
    m g, so R = (total mass - mass of the vertically fixed nodes) / total mass."""
    ratios = []
    for exploded in (False, True):
        model = column(exploded, nx=2, ny=6)
        sim = Simulation(model, progress=False)
        m = sim.state.mass
        held = (model.flags & FIX_Y) != 0
        expect = m[~held].sum() / m.sum()
        r = unbalanced_force_ratio(sim)
        assert r == pytest.approx(expect, rel=1e-12)
        ratios.append(r)
    assert ratios[0] == pytest.approx(ratios[1], rel=1e-12)


def test_geostatic_start_refuses_to_overwrite_initial_stress():
    model = column(False, nx=2, ny=4)
    model.set_initial_stress((-1.0, -1.0, 0.0))
    with pytest.raises(ValueError, match="replace=True"):
        geostatic_start(model)
    report = geostatic_start(model, replace=True)
    np.testing.assert_array_equal(model.initial_stress, report.solution.stress)
    # the static start of the (conforming) column is in equilibrium: R at round-off
    sim = Simulation(model, progress=False)
    assert unbalanced_force_ratio(sim) < 1e-10
    sim.step()
    assert unbalanced_force_ratio(sim) < 1e-10


def test_slip_depth_is_where_mohr_coulomb_is_met_under_level_ground():
    """The closed form z* of fdem.reference.level_ground: at z* the plane's shear traction equals
    c + sigma_n tan(phi) in the uniaxial-strain state, above it the plane holds, below it not;
    a plane whose friction carries the stress ratio (or a horizontal one) holds at every depth."""
    from fdem.reference.level_ground import k0_uniaxial_strain, plane_tractions_per_depth, slip_depth

    k0, gamma = k0_uniaxial_strain(NU), RHO * G
    assert k0 == pytest.approx(NU / (1 - NU))
    for c, phi, dip in [(15e3, 3.34, 15.0), (15e3, 3.34, 115.0), (30e3, 9.83, 60.0)]:
        z = slip_depth(c, phi, dip, gamma, k0)
        # the plane's tractions from the stress tensor itself (compression positive): its unit
        # normal n at dip theta from the vertical, t = S n, sigma_n = n.t, tau = |t - sigma_n n|
        th = np.radians(dip)
        n = np.array([np.sin(th), np.cos(th)])
        S = np.diag([k0, 1.0])   # (sigma_h, sigma_v) / (gamma z)
        t = S @ n
        sn, tau = float(n @ t), float(np.linalg.norm(t - (n @ t) * n))
        assert (sn, tau) == pytest.approx(plane_tractions_per_depth(dip, k0), rel=1e-12)
        margin = lambda depth: tau * gamma * depth - (c + sn * gamma * depth * np.tan(np.radians(phi)))  # noqa: E731
        assert margin(z) == pytest.approx(0.0, abs=1e-6 * c)
        assert margin(0.99 * z) < 0 < margin(1.01 * z)
    assert slip_depth(50e3, 11.0, 15.0, gamma, k0) == np.inf   # the paper's joints at full strength, dip 15 deg
    assert slip_depth(0.0, 30.0, 0.0, gamma, k0) == np.inf      # no shear on a horizontal plane


def test_the_papers_schedule_end_puts_level_ground_beyond_strength():
    """The four-slope paper reduces c and tan(phi) of every crack element to 30 % (F = 3.33,
    f_t kept). Its static start under the level ground is the uniaxial-strain state, so at that
    factor the persistent joints (dip 15 deg) are over strength below z* = 6.2 m of cover and the
    cross joints (dip 75 deg the other way) below 4.7 m (fdem.reference.level_ground), before any
    step: start_against_strength must flag every joint element of the level ground whose
    shallower end lies more than an element size below z* and none whose deeper end lies more
    than that above it, and report the shallowest flagged joint within that of z*. An end's
    traction comes from the constant stress of the triangles beside it, which is off by up to a
    triangle's depth of stress gradient (measured at 1 m: the worst flagged ends lie 0.84 m
    (persistent) and 0.68 m (cross) above z*, both within 10 m of the right-hand roller). At 1 m
    that tolerance still tells K0 = nu / (1 - nu) from K0 = nu, whose z* for the persistent
    joints lies 1.5 m higher. At F = 1 no persistent joint there is over strength (z* infinite)."""
    from fdem.cases import four_slopes as fs
    from fdem.geometry.polygons import ground_surface, slope_crest, slope_toe
    from fdem.reference.level_ground import k0_uniaxial_strain, slip_depth
    from fdem.solve.geostatic import crack_strength_check
    from fdem.workflow.slope import SlopeWorkflow, final_factor, start_against_strength

    size = 1.0
    extents = fs.resolve_extents("low", {k: None for k in fs.EXTENTS_BEFORE_PINNING}, None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geometry, _, topo = fs.build("low", "coarse", size, None, None, extents=extents)
    _, cracks = fs.simulation(geometry, topo, None, pictures=False, progress=False)
    cracks.interfaces.reduce_tensile = False                     # the paper's f_t, untouched
    F = final_factor(SlopeWorkflow(reduction="rate"))
    assert F == pytest.approx(1 / 0.3)
    slope = geometry.bodies[0]
    check = start_against_strength(cracks, slope, F)
    over = crack_strength_check(cracks, cracks.preload_forces, reduction=F)
    flagged = np.zeros(topo.n_cracks, bool)
    flagged[np.union1d(over["tensile"], over["shear"])] = True
    assert check["over"] == flagged.sum() and check["level_ground"]["over"] > 0

    x0, cn = np.asarray(topo.x0), np.asarray(topo.crack_nodes)
    mid = x0[cn].mean(axis=1)
    d = x0[cn[:, 1]] - x0[cn[:, 0]]
    strike = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180.0
    (tx, ty), (cx, cy) = slope_toe(slope), slope_crest(slope)
    level = (mid[:, 0] < tx - (cy - ty)) | (mid[:, 0] > cx + (cy - ty))
    surface = ground_surface(slope)
    end_cover = np.column_stack([surface(x0[cn[:, k], 0]) - x0[cn[:, k], 1] for k in (0, 1)])
    top, bottom = end_cover.min(axis=1), end_cover.max(axis=1)   # the covers of the element's two ends
    whole = np.asarray(topo.crack_length0) > size / 2            # no sliver: its end tractions are noise
    joint = (np.asarray(topo.crack_tag) > 0) & level & whole
    persistent = joint & (np.abs(strike - 15.0) < 5.0)
    cross = joint & ~persistent
    k0, gamma = k0_uniaxial_strain(fs.POISSON), fs.DENSITY * fs.GRAVITY
    c, phi = 50e3 / F, np.degrees(np.arctan(np.tan(np.radians(11.0)) / F))
    tol = size
    depths = {}
    for kind, dip in ((persistent, 15.0), (cross, -75.0)):
        z = depths[dip] = slip_depth(c, phi, dip, gamma, k0)
        shallow, deep = kind & (bottom < z - tol), kind & (top > z + tol)
        assert shallow.sum() >= 10 and deep.sum() >= 10
        assert not flagged[shallow].any(), (dip, z, bottom[shallow & flagged])
        assert flagged[deep].all(), (dip, z, top[deep & ~flagged])
    reported = check["level_ground"]["joints_shallowest_cover_m"]
    assert min(depths.values()) - tol <= reported <= min(depths.values()) + tol, (reported, depths)
    assert check["level_ground"]["joints_over"] == int((flagged & level & (np.asarray(topo.crack_tag) > 0)).sum())
    at_one = start_against_strength(cracks, slope, 1.0)
    ids = np.union1d(*(crack_strength_check(cracks, cracks.preload_forces, reduction=1.0)[k] for k in ("tensile", "shear")))
    assert not persistent[ids].any() and at_one["factor"] == 1.0


def test_elastic_side_bands_carry_the_rollers_load_and_never_yield():
    """``--elastic-band``: the intact crack elements within the band of either side (and only
    they: the bands hold no joints) get strengths no stress reaches and the rock's penalties.
    The static start is then the same to the last bit (the band is as stiff as the rock), yet at
    the paper's F = 3.33 with f_t kept, where the start is beyond strength in rock bands of the
    high-angle slope, no element of an elastic band is, and none leaves its elastic range in 400
    undamped steps, while those of the rock band do. The model's own tags (pictures, summaries)
    keep the bands intact rock."""
    from fdem.cases import four_slopes as fs
    from fdem.physics.side_bands import with_elastic_side_bands
    from fdem.solve.damping import NO_DAMPING
    from fdem.workflow.stages import Stage, run_stage

    extents = fs.resolve_extents("high", {k: None for k in fs.EXTENTS_BEFORE_PINNING}, None)
    band = extents["boundary_band"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geometry, _, topo = fs.build("high", "coarse", 1.5, None, None, extents=extents)
    x0, cn = np.asarray(topo.x0), np.asarray(topo.crack_nodes)
    mid_x = x0[cn[:, :2], 0].mean(axis=1)
    in_band = (mid_x < x0[:, 0].min() + band) | (mid_x > x0[:, 0].max() - band)
    assert not (in_band & (topo.crack_tag > 0)).any()              # BandedSet: no joint in a band
    tags, sets, tag = with_elastic_side_bands(topo, fs.four_slope_property_sets(), band)
    assert tag == 2 and sets[tag].p_n == sets[0].p_n and sets[tag].k_t == sets[0].k_t
    np.testing.assert_array_equal(tags == tag, in_band)
    np.testing.assert_array_equal(tags[~in_band], topo.crack_tag[~in_band])
    F = 1.0 / 0.3
    found = {}
    for law in ("rock", "elastic"):
        sim, cracks = fs.simulation(geometry, topo, None, pictures=False, progress=False,
                                    elastic_band=band if law == "elastic" else None)
        assert cracks.topology is topo and (cracks.tag == tag).sum() == (in_band.sum() if law == "elastic" else 0)
        cracks.interfaces.reduce_tensile = False
        over = crack_strength_check(cracks, cracks.preload_forces, reduction=F)
        over = np.union1d(over["tensile"], over["shear"])
        preload = cracks.preload_forces.copy()
        run_stage(sim, Stage("reduced", duration=400 * sim.dt, reduction=F, damping=NO_DAMPING))
        found[law] = (preload, in_band[over].sum(), in_band[cracks.inelastic()].sum(), len(over))
    np.testing.assert_array_equal(found["rock"][0], found["elastic"][0])
    assert found["rock"][1] > 0 and found["rock"][2] > 0, found["rock"][1:]
    assert found["elastic"][1] == 0 and found["elastic"][2] == 0, found["elastic"][1:]
    assert found["elastic"][3] == found["rock"][3] - found["rock"][1]   # the rest over strength as before
    # The events' stress drop is the breakable sets' mean f_t, as without the bands; the band's
    # set passes the snap-back check wherever the rock's own does (f_t divided by F as well)
    from fdem.results.report import RunReport

    sim, cracks = fs.simulation(geometry, topo, None, pictures=False, progress=False, elastic_band=band)
    assert RunReport(sim, toe_x=45.0).stress_drop == pytest.approx(np.mean([10e3, 50e3]))
    cracks.interfaces.reduce_tensile = True
    for factor in (0.5, 1.0, 1e3):
        cracks.interfaces.set_reduction(factor)
    with pytest.raises(ValueError, match="hold no intact crack element"):
        with_elastic_side_bands(topo, fs.four_slope_property_sets(), 0.02)
