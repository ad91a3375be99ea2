"""Output: VTU/PVD series readable by meshio and pyvista, history.csv, PNG, instability guard."""
import numpy as np
import pytest

from fdem.physics.elastic import ElasticMaterial
from fdem.physics.stability import stable_dt_spring
from fdem.mesh.mesh import structured_rectangle
from fdem.solve.model import Model
from fdem.io.npz import load_state
from fdem.io.history import read_history
from fdem.io.vtk import read_pvd, write_vtu
from fdem.solve.damping import Damping
from fdem.solve.simulation import InstabilityError, Simulation

E, NU, RHO = 1e9, 0.25, 2000.0


class Ties:
    """Springs between the coincident node pairs of every crack element (see test_solver)."""

    def __init__(self, topology, stiffness, report_stable_dt=True):
        cn = topology.crack_nodes
        self.a = np.concatenate([cn[:, 0], cn[:, 1]])
        self.b = np.concatenate([cn[:, 3], cn[:, 2]])
        self.k, self.report, self.energy, self.n = stiffness, report_stable_dt, 0.0, len(cn)

    def add_forces(self, x, v, f_interaction, dt, step):
        d = x[self.b] - x[self.a]
        np.add.at(f_interaction, self.a, self.k * d)
        np.add.at(f_interaction, self.b, -self.k * d)
        self.energy = 0.5 * self.k * float((d * d).sum())

    def energy_terms(self):
        return {"tie_elastic": self.energy}

    def stable_dt(self, mass):
        if not self.report:
            return np.inf  # a provider that forgets its stiffness: the run will blow up
        count = np.bincount(np.concatenate([self.a, self.b]), minlength=len(mass))
        return float(np.min(stable_dt_spring(2.0 * self.k * count[count > 0], mass[count > 0])))

    def crack_fields(self):
        return {"damage": np.linspace(0, 1, self.n), "broken": (np.arange(self.n) % 2).astype(np.uint8)}


def small_model():
    model = Model.from_mesh(structured_rectangle(4, 3, 2.0, 1.5), ElasticMaterial(E, NU, RHO), exploded=True)
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    return model


def test_vtu_pvd_series_readable_with_expected_arrays(tmp_path):
    import meshio
    import pyvista as pv

    model = small_model()
    ties = Ties(model.topology, 10 * E)
    sim = Simulation(model, providers=[ties], out_dir=tmp_path, name="block", progress=False, pictures=True)
    sim.run(n_steps=40, output_every=10, damping=Damping(local=0.5))
    frames = read_pvd(tmp_path / "block.pvd")
    assert len(frames) == 5  # initial + 4
    assert [t for t, _ in frames] == sorted(t for t, _ in frames)
    last = frames[-1][1]
    m = meshio.read(last)
    assert m.points.shape == (model.n_nodes, 3)
    np.testing.assert_allclose(m.points[:, :2], sim.state.x)
    np.testing.assert_allclose(m.point_data["displacement"][:, :2], sim.state.x - model.topology.x0)
    np.testing.assert_allclose(m.point_data["velocity"][:, :2], sim.state.v)
    tri = m.cells_dict["triangle"]
    np.testing.assert_array_equal(tri, model.topology.triangles)
    s = sim.stresses()
    # the stress components live in the 6-component tensor [xx, yy, zz, xy, yz, xz] (one array
    # ParaView colours by component and draws tensor glyphs from), written as float32
    for name in ("stress", "stress_principal_1", "stress_principal_2", "stress_von_mises", "property", "body"):
        assert name in m.cell_data, name
    np.testing.assert_array_equal(m.cell_data["stress"][0][:, 1], s["yy"].astype(np.float32))
    assert np.all(m.cell_data["stress_principal_1"][0] >= m.cell_data["stress_principal_2"][0])
    grid = pv.read(str(last))
    assert grid.n_cells == model.n_triangles and "stress_von_mises" in grid.cell_data
    # the crack series: one line cell per crack element with its tag and the provider's arrays
    crack_frames = read_pvd(tmp_path / "block_cracks.pvd")
    assert len(crack_frames) == 5
    c = meshio.read(crack_frames[-1][1])
    assert c.cells_dict["line"].shape == (model.topology.n_cracks, 2)
    for name in ("crack_tag", "damage", "broken", "opening", "slip"):
        assert name in c.cell_data, name
    np.testing.assert_allclose(c.cell_data["damage"][0], np.linspace(0, 1, model.topology.n_cracks))
    assert pv.read(str(crack_frames[-1][1])).n_cells == model.topology.n_cracks
    assert len(list(tmp_path.glob("block_*.png"))) == 5


def test_history_csv_has_ledger_and_monitor_columns(tmp_path):
    model = small_model()
    sim = Simulation(model, providers=[Ties(model.topology, 10 * E)], out_dir=tmp_path, progress=False)
    sim.add_monitor("top_uy", lambda s: float((s.state.x - s.x0)[s.model.select_nodes("top"), 1].mean()))
    sim.run(n_steps=30, history_every=10, stage="settle", damping=Damping(local=0.8))
    sim.run(n_steps=20, history_every=10, stage="dynamic")
    sim.close()
    h = read_history(tmp_path / "history.csv")
    for col in ("stage", "step", "time", "dt", "kinetic", "strain", "gravity_potential", "load_potential",
                "damping_dissipation", "viscous_dissipation", "boundary_work", "interaction_work",
                "tie_elastic", "total", "balance_error", "balance_error_relative", "max_speed",
                "max_displacement", "top_uy"):
        assert col in h, col
    assert list(h["stage"]) == ["settle"] * 4 + ["dynamic"] * 3
    assert np.all(np.diff(h["step"]) > 0)
    assert np.all(h["top_uy"][1:] < 0)
    np.testing.assert_allclose(h["balance_error"], 0.0, atol=1e-6 * np.abs(h["gravity_potential"]).max())


def test_write_vtu_large_mesh_round_trips_exactly(tmp_path):
    import meshio

    n = 100_000
    pts = np.random.default_rng(0).random((3 * n, 2))
    cells = np.arange(3 * n).reshape(n, 3)
    s = np.random.default_rng(1).random(n)
    write_vtu(tmp_path / "big.vtu", pts, cells, point_data={"u": pts}, cell_data={"s": s})
    back = meshio.read(tmp_path / "big.vtu")
    np.testing.assert_array_equal(back.points[:, :2], pts)
    np.testing.assert_array_equal(back.cells_dict["triangle"], cells)
    np.testing.assert_array_equal(back.point_data["u"][:, :2], pts)
    np.testing.assert_array_equal(back.cell_data["s"][0], s)


def test_instability_guard_stops_with_message_and_last_good_state(tmp_path):
    model = small_model()
    liar = Ties(model.topology, 1e4 * E, report_stable_dt=False)  # stiffness hidden from the step control
    sim = Simulation(model, providers=[liar], out_dir=tmp_path, progress=False)
    with pytest.raises(InstabilityError) as err:
        sim.run(n_steps=5000, checkpoint_every=10)
    e = err.value
    msg = str(e)
    assert f"step {e.step}" in msg and "t = " in msg and "triangle" in msg and "try dt <=" in msg
    assert e.suggested_dt < sim.dt
    assert 0 < e.step < 5000
    state = load_state(tmp_path / "last_good_state.npz")
    assert np.all(np.isfinite(state["x"])) and np.all(np.isfinite(state["v"]))
    assert int(state["step"]) <= e.step and int(state["step"]) % 10 == 0
    assert (tmp_path / "last_good_state.vtu").exists()
    import meshio

    assert np.all(np.isfinite(meshio.read(tmp_path / "last_good_state.vtu").points))
    # a correct stable step makes the same model run
    honest = Ties(model.topology, 1e4 * E)
    Simulation(model, providers=[honest], progress=False).run(n_steps=200)


def test_keyboard_interrupt_writes_state(tmp_path):
    model = small_model()
    sim = Simulation(model, out_dir=tmp_path, progress=False)

    def interrupt(s):
        if s.state.step >= 25:
            raise KeyboardInterrupt
        return 0.0

    sim.add_monitor("interrupt", interrupt)
    with pytest.raises(KeyboardInterrupt):
        sim.run(n_steps=100, history_every=5)
    # a full checkpoint (the user guide restarts from it), with a .vtu to look at
    from fdem.solve.checkpoint import load_checkpoint, read_checkpoint

    state = read_checkpoint(tmp_path / "interrupted_state.npz")["state"]
    assert int(state["step"]) == sim.state.step
    np.testing.assert_array_equal(state["x"], sim.state.x)
    assert (tmp_path / "interrupted_state.vtu").exists()
    again = Simulation(small_model(), progress=False)
    load_checkpoint(again, tmp_path / "interrupted_state.npz")
    np.testing.assert_array_equal(again.state.v, sim.state.v)


def test_simulation_writes_compressed_frames_with_only_the_fields_asked_for(tmp_path):
    import meshio

    model = small_model()
    sim = Simulation(model, providers=[Ties(model.topology, 10 * E)], out_dir=tmp_path, name="small",
                     progress=False, output_fields=["displacement", "stress_von_mises"], compression="zlib")
    sim.run(n_steps=20, output_every=10)
    m = meshio.read(read_pvd(tmp_path / "small.pvd")[-1][1])
    assert set(m.point_data) == {"displacement"} and set(m.cell_data) == {"stress_von_mises"}
    # frames are float32 by default: the read-back is the float64 field rounded to float32
    np.testing.assert_array_equal(m.point_data["displacement"][:, :2],
                                  (sim.state.x - model.topology.x0).astype(np.float32))
    assert 'compressor="vtkZLibDataCompressor"' in open(read_pvd(tmp_path / "small.pvd")[-1][1], "rb").read(2000).decode(
        "latin-1")
    with pytest.raises(ValueError, match="compression"):
        Simulation(model, out_dir=tmp_path / "x", compression="gzip")
