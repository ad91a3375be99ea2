"""Explicit solver: wave speed, gravity column, energy conservation, damping, time step, providers."""

import numpy as np
import pytest

from fdem.physics.elastic import ElasticMaterial, bar_wave_speed, k0_elastic
from fdem.physics.stability import stable_dt_spring
from fdem.mesh.mesh import jittered_rectangle, structured_rectangle
from fdem.solve.model import Model, geostatic_stress
from fdem.solve.damping import Damping
from fdem.solve.simulation import Simulation

E, NU, RHO, G = 1e9, 0.25, 2000.0, 10.0


def jittered_mesh(nx, ny, w, h, amount=0.25, seed=1):
    return jittered_rectangle(nx, ny, w, h, amount, seed)


class PenaltyTies:
    """Test force provider: a linear spring ``k`` [N/m/m] between the coincident node pairs of
    every crack element (an unbreakable elastic bond), with energy and stable step."""

    def __init__(self, topology, stiffness, report_stable_dt=True):
        cn = topology.crack_nodes
        self.a = np.concatenate([cn[:, 0], cn[:, 1]])
        self.b = np.concatenate([cn[:, 3], cn[:, 2]])
        self.k = stiffness
        self.report = report_stable_dt
        self.energy = 0.0
        self.n_cracks = len(cn)
        self.calls = []

    def add_forces(self, x, v, f_interaction, dt, step):
        d = x[self.b] - x[self.a]
        np.add.at(f_interaction, self.a, self.k * d)
        np.add.at(f_interaction, self.b, -self.k * d)
        self.energy = 0.5 * self.k * float((d * d).sum())
        self.calls.append(step)

    def energy_terms(self):
        return {"tie_elastic": self.energy}

    def stable_dt(self, mass):
        if not self.report:
            return np.inf
        count = np.bincount(np.concatenate([self.a, self.b]), minlength=len(mass))
        # Gershgorin on M^-1 K: omega^2 <= 2 k n_i / m_i
        return float(np.min(stable_dt_spring(2.0 * self.k * count[count > 0], mass[count > 0])))

    def crack_fields(self):
        return {"damage": np.zeros(self.n_cracks), "broken": np.zeros(self.n_cracks, np.uint8)}


def arrival_time_error(plane, rollers, nx=400, ny=1, length=10.0, width=0.025, station=6.0):
    """Relative error of the arrival time of a velocity step at ``station`` (half-amplitude crossing)."""
    mat = ElasticMaterial(E, NU, RHO, plane=plane)
    model = Model.from_mesh(structured_rectangle(nx, ny, length, width), mat, exploded=False)
    v0 = 0.01
    model.prescribe_velocity("left", vx=v0)
    if rollers:
        model.roller("bottom", "y")
        model.roller("top", "y")
    sim = Simulation(model, progress=False)
    node = int(np.argmin(np.hypot(model.topology.x0[:, 0] - station, model.topology.x0[:, 1])))
    c = mat.p_wave_speed if rollers else bar_wave_speed(E, RHO)
    times, speeds = [], []
    while sim.state.time < 1.3 * station / c:
        sim.step()
        times.append(sim.state.time - 0.5 * sim.dt)  # v is at the half step
        speeds.append(sim.state.v[node, 0] / v0)
    t, s = np.array(times), np.array(speeds)
    k = int(np.argmax(s >= 0.5))
    assert k > 0 and s[:k].max() < 0.5
    t_arrival = t[k - 1] + (0.5 - s[k - 1]) / (s[k] - s[k - 1]) * (t[k] - t[k - 1])
    return t_arrival / (station / c) - 1.0


def test_p_wave_arrival_plane_strain_with_lateral_rollers():
    # c_p = sqrt(E (1 - nu) / (rho (1 + nu) (1 - 2 nu)))
    assert abs(arrival_time_error("strain", rollers=True)) < 0.02


def test_wave_arrival_plane_stress_with_rollers_and_free_bar():
    # rollers: c = sqrt(E / (rho (1 - nu^2))); free slender bar: c_0 = sqrt(E / rho)
    assert abs(arrival_time_error("stress", rollers=True)) < 0.02
    assert abs(arrival_time_error("stress", rollers=False, ny=2, width=0.05)) < 0.02


def gravity_column(damping, n_steps, nx=3, ny=30, height=10.0, exploded=False):
    mat = ElasticMaterial(E, NU, RHO)
    model = Model.from_mesh(jittered_mesh(nx, ny, 1.0, height, amount=0.2), mat, exploded=exploded)
    model.set_gravity(0.0, -G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    sim = Simulation(model, progress=False)
    sim.run(n_steps=n_steps, damping=damping, history_every=100)
    return model, sim


def column_errors(model, sim, height=10.0):
    s = sim.stresses()
    yc = model.centroids0[:, 1]
    exact_yy = -RHO * G * (height - yc)
    err_yy = np.max(np.abs(s["yy"] - exact_yy)) / (RHO * G * height)
    err_xx = np.max(np.abs(s["xx"] - k0_elastic(NU) * s["yy"])) / (RHO * G * height)
    return err_yy, err_xx


# critical mass-proportional damping of the column's first mode: alpha = 2 omega_1, omega_1 = pi c_p / (2 H)
ALPHA_COLUMN = 2 * np.pi * ElasticMaterial(E, NU, RHO).p_wave_speed / (2 * 10.0)


@pytest.mark.parametrize("damping", [Damping(mass_proportional=ALPHA_COLUMN), Damping(local=0.8)],
                         ids=["mass-proportional", "local"])
def test_gravity_column_converges_to_static_stresses(damping):
    """Rollers on the sides, fixed base, plane strain: sigma_yy = -rho g (H - y),
    sigma_xx = nu/(1-nu) sigma_yy, within 1 % of rho g H, reached by damped loading."""
    model, sim = gravity_column(damping, 1500)
    early = column_errors(model, sim)
    sim.run(n_steps=3500, damping=damping, history_every=500)
    err_yy, err_xx = column_errors(model, sim)
    assert err_yy < 0.01 and err_xx < 0.01
    assert err_yy < early[0] or early[0] < 0.01
    # the damped loading came to rest: kinetic energy is a negligible part of the strain energy
    last = sim.history[-1]
    assert last["kinetic"] < 1e-8 * last["strain"]
    # static balance (Clapeyron): strain energy = half the work of gravity
    assert last["strain"] == pytest.approx(0.5 * -last["gravity_potential"], rel=2e-3)
    # and the ledger closes: damping took the other half
    assert abs(last["balance_error"]) < 1e-7 * last["strain"]  # exact up to the Green-strain nonlinearity


def test_geostatic_initial_stress_is_in_equilibrium():
    """With the K0 initial stress of the column, gravity causes (almost) no motion."""
    mat = ElasticMaterial(E, NU, RHO)
    model = Model.from_mesh(structured_rectangle(3, 30, 1.0, 10.0), mat, exploded=False)
    model.set_gravity(0.0, -G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    model.set_initial_stress(geostatic_stress(RHO, G, surface=10.0, poisson=NU))
    sim = Simulation(model, progress=False)
    sim.run(n_steps=300)
    # compare with the static settlement of the column without initial stress, rho g H^2 / (2 M)
    settlement = RHO * G * 10.0**2 / (2 * mat.p_wave_modulus)
    assert sim.history[-1]["max_displacement"] < 0.05 * settlement
    s = sim.stresses()
    yc = model.centroids0[:, 1]
    assert np.max(np.abs(s["yy"] + RHO * G * (10.0 - yc))) < 0.01 * RHO * G * 10.0


def test_energy_conservation_of_released_elastic_body():
    """No damping, no supports: a body released from a uniform strain keeps its total energy
    to < 0.5 % over 2e4 steps (the ledger's kinetic energy is the leapfrog-consistent one)."""
    mat = ElasticMaterial(E, NU, RHO)
    model = Model.from_mesh(jittered_mesh(6, 6, 2.0, 2.0, seed=7), mat, exploded=False)
    sim = Simulation(model, progress=False)
    H = np.array([[2e-3, 1e-3], [-5e-4, -1e-3]])
    sim.state.x[:] = model.topology.x0 + (model.topology.x0 - 1.0) @ H.T
    sim.run(n_steps=20_000, history_every=500)
    total = np.array([r["total"] for r in sim.history])
    strain0 = sim.history[0]["strain"]
    assert strain0 > 0
    assert np.max(np.abs(total - total[0])) < 0.005 * abs(total[0])
    kinetic = np.array([r["kinetic"] for r in sim.history])
    assert kinetic.max() > 0.3 * strain0  # it really vibrates
    # momentum stays zero (free body, internal forces only)
    p = (sim.state.mass[:, None] * sim.state.v).sum(0)
    assert np.abs(p).max() < 1e-9 * np.sqrt(sim.state.mass.sum() * 2 * strain0)


def test_user_time_step_above_stable_is_refused():
    mat = ElasticMaterial(E, NU, RHO)
    model = Model.from_mesh(structured_rectangle(4, 4, 1.0, 1.0), mat)
    sim = Simulation(model, progress=False)
    critical, limits = sim.critical_dt()
    assert sim.dt == pytest.approx(0.8 * critical)
    with pytest.raises(ValueError) as err:
        Simulation(model, dt=1.5 * critical, progress=False)
    assert f"{critical:.6g}" in str(err.value) and "stable" in str(err.value)
    assert Simulation(model, dt=0.99 * critical, progress=False).dt == 0.99 * critical
    # a provider's stiffness lowers the stable step, combined as 1/dt^2 = sum 1/dt_i^2
    ties = PenaltyTies(model.topology, stiffness=50 * E)
    sim2 = Simulation(model, providers=[ties], progress=False)
    crit2, limits2 = sim2.critical_dt()
    assert crit2 == pytest.approx((limits2["triangles"] ** -2 + limits2["PenaltyTies"] ** -2) ** -0.5)
    with pytest.raises(ValueError, match=f"{crit2:.6g}"):
        Simulation(model, dt=0.99 * critical, providers=[ties], progress=False)


def test_provider_plugs_in_and_its_energy_enters_the_ledger():
    """Exploded mesh tied by a spring provider behaves like an elastic body: energy conserved
    with the provider's term in the balance, and the provider sees every step."""
    mat = ElasticMaterial(E, NU, RHO)
    model = Model.from_mesh(jittered_mesh(4, 4, 1.0, 1.0, seed=3), mat, exploded=True)
    ties = PenaltyTies(model.topology, stiffness=20 * E)
    sim = Simulation(model, providers=[ties], progress=False)
    sim.state.x[:] = model.topology.x0 * [1.001, 0.999]
    sim.run(n_steps=2000, history_every=100)
    assert ties.calls == list(range(2000))
    rows = sim.history
    assert "tie_elastic" in rows[0] and max(r["tie_elastic"] for r in rows) > 0
    scale = max(r["strain"] + r["tie_elastic"] + r["kinetic"] for r in rows)
    assert max(abs(r["balance_error"]) for r in rows) < 1e-6 * scale
    # cross-check: the work done by the provider's forces equals minus its energy change
    for r in rows:
        assert -r["interaction_work"] == pytest.approx(r["tie_elastic"] - rows[0]["tie_elastic"], abs=1e-6 * scale)


def test_ledger_balances_with_damping_viscosity_and_prescribed_velocity():
    mat = ElasticMaterial(E, NU, RHO, viscosity=2e4)
    model = Model.from_mesh(jittered_mesh(5, 4, 2.0, 1.0, seed=5), mat, exploded=False)
    model.set_gravity(0.0, -G)
    model.fix("left")
    model.prescribe_velocity("right", vy=-0.01, history=lambda t: np.sin(2e3 * t))
    model.add_body_force(1e3, 0.0, where=lambda x, y: x > 1.0)
    sim = Simulation(model, progress=False)
    sim.run(n_steps=1500, damping=Damping(mass_proportional=50.0, local=0.3), history_every=50)
    last = sim.history[-1]
    for key in ("damping_dissipation", "viscous_dissipation"):
        assert last[key] > 0
    assert last["boundary_work"] != 0 and last["load_potential"] != 0
    scale = max(abs(r["strain"]) + abs(r["gravity_potential"]) + abs(r["boundary_work"]) for r in sim.history)
    assert max(abs(r["balance_error"]) for r in sim.history) < 1e-6 * scale


def test_supports_and_prescribed_velocity_are_respected():
    mat = ElasticMaterial(E, NU, RHO)
    model = Model.from_mesh(structured_rectangle(4, 4, 1.0, 1.0), mat, exploded=True)
    model.set_gravity(0.0, -G)
    bottom = model.fix("bottom")
    left = model.roller("left", "x")
    top = model.prescribe_velocity("top", vy=0.02)
    sim = Simulation(model, progress=False)
    sim.run(n_steps=200)
    u = sim.state.x - model.topology.x0
    assert np.all(u[bottom] == 0.0)
    assert np.all(u[left, 0] == 0.0) and np.any(u[np.setdiff1d(left, bottom), 1] != 0.0)
    np.testing.assert_allclose(u[top, 1], 0.02 * sim.state.time, rtol=1e-10)  # round-off of 200 additions
    with pytest.raises(ValueError, match="no physical group"):
        model.fix("crest")
    with pytest.raises(ValueError, match="matches no node"):
        model.fix(lambda x, y: x > 5.0)


def test_exploded_and_conforming_single_triangle_agree():
    """Without crack elements an exploded triangle is a conforming one: same trajectory."""
    from fdem.mesh.mesh import Mesh

    mesh = Mesh(points=np.array([[0.0, 0.0], [1.0, 0.1], [0.3, 0.9]]), triangles=np.array([[0, 1, 2]]),
                triangle_body=np.zeros(1, np.int32))
    runs = []
    for exploded in (True, False):
        model = Model.from_mesh(mesh, ElasticMaterial(E, NU, RHO, viscosity=1e3), exploded=exploded)
        model.set_gravity(0.0, -G)
        model.set_initial_velocity(0.0, 0.0)
        sim = Simulation(model, progress=False)
        sim.state.x[1] += [1e-3, 0.0]
        sim.run(n_steps=500, damping=Damping(local=0.2))
        runs.append(sim.state.x.copy())
    np.testing.assert_allclose(runs[0], runs[1], rtol=0, atol=1e-13)


@pytest.mark.parametrize("damping, tol", [(Damping(), 1e-8), (Damping(mass_proportional=30.0), 1e-8),
                                          (Damping(mass_proportional=30.0, local=0.4), 1e-5)],
                         ids=["free", "mass-proportional", "local"])
def test_fast_path_matches_general_kernel(damping, tol):
    """Steps without a ledger row take the lean kernel; it must reproduce the general one."""
    mat = ElasticMaterial(E, NU, RHO)
    finals, ledgers = [], []
    for every in (1, 1000):
        model = Model.from_mesh(jittered_mesh(4, 3, 1.0, 1.0, seed=9), mat, exploded=True)
        model.set_gravity(0.0, -G)
        model.fix("bottom")
        model.prescribe_velocity("top", vx=0.01)
        ties = PenaltyTies(model.topology, stiffness=20 * E)
        sim = Simulation(model, providers=[ties], progress=False)
        sim.run(n_steps=600, damping=damping, history_every=every)
        finals.append(sim.state.x.copy())
        ledgers.append(sim.history[-1])
        u_max = np.abs(sim.state.x - model.topology.x0).max()
    # identical arithmetic up to rounding; local damping's sign(v) can amplify a last-bit difference
    np.testing.assert_allclose(finals[0], finals[1], rtol=0, atol=tol * u_max)
    for key in ("damping_dissipation", "boundary_work", "interaction_work"):
        assert ledgers[0][key] == pytest.approx(ledgers[1][key], rel=tol, abs=1e-12 * abs(ledgers[0]["strain"]))
    for ledger in ledgers:  # round-off level in both
        assert abs(ledger["balance_error"]) < 1e-8 * abs(ledger["strain"])
