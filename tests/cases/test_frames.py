"""Output frames a rock engineer reads: the fields on triangles, crack elements and contact pairs
read back through pyvista and meshio with the values the solver holds, light (zlib, float32)
frames that round-trip to float32, and point monitors against the gravity column's closed form."""
import numpy as np
import pytest

from fdem.io.history import read_history
from fdem.io.vtk import read_pvd
from fdem.kernels.cracks import MUNJIZA, softening
from fdem.mesh.mesh import Mesh, structured_rectangle
from fdem.physics.contact import ContactSet
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.elastic import ElasticMaterial
from fdem.solve.damping import Damping
from fdem.solve.model import Model
from fdem.solve.simulation import Simulation

E, NU, RHO = 1e9, 0.25, 2000.0
KN, KT = 1.0e12, 5.0e11  # crack stiffness per unit area [Pa/m]
FT, C, GI = 1.0e6, 2.0e6, 100.0


def two_triangle_model():
    """Triangle A above, B below the edge (0, 0)-(0.5, 0): one crack element."""
    pts = np.array([[0.0, 0.0], [0.5, 0.0], [0.25, 1.0], [0.25, -1.0]])
    mesh = Mesh(points=pts, triangles=np.array([[0, 1, 2], [1, 0, 3]]), triangle_body=np.zeros(2, np.int32))
    return Model.from_mesh(mesh, ElasticMaterial(E, NU, RHO), exploded=True)


def crack_sim(tmp_path):
    model = two_triangle_model()
    cs = CrackSet(model.topology, {0: CrackProperties(f_t=FT, c=C, phi=30.0, G_I=GI, G_II=300.0, k_n=KN, k_t=KT)})
    sim = Simulation(model, providers=[cs], out_dir=tmp_path, name="pair", progress=False)
    cn = model.topology.crack_nodes[0]
    x0 = model.topology.x0
    t = (x0[cn[1]] - x0[cn[0]]) / np.linalg.norm(x0[cn[1]] - x0[cn[0]])
    n = np.array([t[1], -t[0]])  # the law's normal, from face A into face B
    b_side = model.topology.triangles[model.topology.crack_triangles[0, 1]]
    assert set(cn[2:]) <= set(b_side)

    def separate(o, s):
        """Translate triangle B: both ends open by ``o`` and slip by ``s`` [m]."""
        x = x0.copy()
        x[b_side] += o * n + s * t
        sim.set_positions(x)

    return sim, cs, separate


def last_frame(tmp_path, series):
    import meshio
    import pyvista as pv

    path = read_pvd(tmp_path / f"{series}.pvd")[-1][1]
    return meshio.read(path), pv.read(str(path)), path


def test_crack_tractions_and_break_time_read_back_with_the_laws_values(tmp_path):
    sim, cs, separate = crack_sim(tmp_path)
    op = FT / KN
    # elastic: sigma = k_n o, tau = k_t s (below the peak and inside Mohr-Coulomb)
    o, s = 0.4 * op, 1.0e-6
    separate(o, s)
    sim.write_output()
    m, g, path = last_frame(tmp_path, "pair_cracks")
    for frame in (m.cell_data["normal_traction"][0], np.asarray(g.cell_data["normal_traction"])):
        np.testing.assert_allclose(frame, [KN * o], rtol=1e-6)
    np.testing.assert_allclose(m.cell_data["shear_traction"][0], [KT * s], rtol=1e-6)
    assert np.isnan(m.cell_data["break_time"][0][0]) and np.isnan(np.asarray(g.cell_data["break_time"])[0])
    # softening in mode I at fixed opening: on the envelope, sigma = f_t z(D), D = (o - o_p)/(o_r - o_p)
    o = op + 0.3e-4
    separate(o, 0.0)
    cs.add_forces(sim.state.x, None, np.zeros_like(sim.state.x), 1e-3, 1)
    D = float(cs.damage[0])
    o_r = op + (o - op) / D
    assert 0.0 < D < 1.0 and o_r > o
    sim.write_output()
    m, g, _ = last_frame(tmp_path, "pair_cracks")
    np.testing.assert_allclose(m.cell_data["normal_traction"][0], [FT * softening(D, MUNJIZA)], rtol=1e-6)
    np.testing.assert_allclose(m.cell_data["damage"][0], [D], rtol=1e-6)
    # far beyond o_r it breaks at step 7: the frame's break time is the event's, its tractions 0
    separate(10 * o_r, 0.0)
    cs.add_forces(sim.state.x, None, np.zeros_like(sim.state.x), 1e-3, 7)
    assert cs.broken[0] and len(cs.events) == 1
    sim.write_output()
    m, g, _ = last_frame(tmp_path, "pair_cracks")
    np.testing.assert_allclose(m.cell_data["break_time"][0], cs.events["time"], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(g.cell_data["break_time"]), [7e-3], rtol=1e-6)
    assert m.cell_data["normal_traction"][0][0] == 0.0 and m.cell_data["broken"][0][0] == 1


def test_triangle_frame_holds_stress_tensor_principal_directions_and_strain(tmp_path):
    sim, cs, separate = crack_sim(tmp_path)
    rng = np.random.default_rng(3)
    sim.set_positions(sim.x0 + 1e-4 * rng.standard_normal(sim.x0.shape))
    sim.state.v[:] = rng.standard_normal(sim.x0.shape)
    sim.write_output()
    m, g, path = last_frame(tmp_path, "pair")
    head = path.read_bytes()[:3000].decode("latin-1")
    assert 'compressor="vtkZLibDataCompressor"' in head and 'type="Float64"' not in head
    s = sim.stresses()
    f32 = np.float32
    tensor = np.column_stack([s["xx"], s["yy"], s["zz"], s["xy"], 0 * s["xx"], 0 * s["xx"]]).astype(f32)
    np.testing.assert_array_equal(m.cell_data["stress"][0], tensor)
    np.testing.assert_array_equal(np.asarray(g.cell_data["stress"]), tensor)
    # the compressed float32 frame is the float64 state rounded once to float32, field by field
    fields = sim.fields()
    for name, value in fields["cell"].items():
        np.testing.assert_array_equal(m.cell_data[name][0], np.asarray(value).astype(m.cell_data[name][0].dtype))
    for name, value in fields["point"].items():
        np.testing.assert_array_equal(m.point_data[name][:, :2], value.astype(f32))
        assert not m.point_data[name][:, 2].any()  # padded: VTK draws 3-component vectors only
    np.testing.assert_array_equal(m.points[:, :2], sim.state.x.astype(f32))
    # principal directions: sigma d1 = s1 d1 and sigma d2 = s2 d2 (rotation of the tensor)
    for k in range(sim.model.n_triangles):
        sig = np.array([[s["xx"][k], s["xy"][k]], [s["xy"][k], s["yy"][k]]])
        for d, lam in (("stress_direction_1", "principal_1"), ("stress_direction_2", "principal_2")):
            vec = m.cell_data[d][0][k, :2].astype(float)
            np.testing.assert_allclose(sig @ vec, s[lam][k] * vec, atol=1e-6 * np.abs(sig).max())
    # strain of a uniform stretch: E_xx = ((1 + e)^2 - 1)/2 in every triangle
    e = 1e-3
    sim.set_positions(sim.x0 * [1 + e, 1.0])
    sim.write_output()
    m, _, _ = last_frame(tmp_path, "pair")
    np.testing.assert_allclose(m.cell_data["strain"][0][:, 0], 0.5 * ((1 + e) ** 2 - 1), rtol=1e-5)
    np.testing.assert_allclose(m.cell_data["strain"][0][:, 1:], 0.0, atol=1e-9)


def column(nx=2, ny=8, width=1.0, height=4.0):
    # cells all cut the same way: the lumped gravity loads are the same along each row, so every
    # triangle of a row carries the row's stress (the alternating cut spreads it by +-2 %)
    model = Model.from_mesh(structured_rectangle(nx, ny, width, height, diagonal="right"),
                            ElasticMaterial(E, NU, RHO), exploded=False)
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    return model


def test_point_monitor_on_a_gravity_column_matches_the_closed_form(tmp_path):
    """Uniaxial strain under gravity (rollers on the sides, fixed base), plane strain,
    M = lambda + 2 mu: sigma_yy = -rho g (H - y), sigma_xx = lambda / M sigma_yy,
    u_y = -(rho g / M)(H y - y^2 / 2). Linear triangles give the nodal u_y exactly for this
    one-dimensional field and each row of triangles the stress at its mid-height; inside a row
    the interpolated u_y departs from the parabola by at most (rho g / M) h^2 / 8."""
    H, h, g = 4.0, 0.5, 9.81
    model = column()
    sim = Simulation(model, out_dir=tmp_path, progress=False)
    x, y = 0.3, 1.3
    mon = sim.add_point_monitor("crest", x, y)
    sim.run(t_end=0.5, history_every=200, damping=Damping(local=0.8))
    sim.close()
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    M = lam + 2 * E / (2 * (1 + NU))
    uy = -(RHO * g / M) * (H * y - y * y / 2)
    y_mid = (np.floor(y / h) + 0.5) * h
    syy = -RHO * g * (H - y_mid)
    hist = read_history(tmp_path / "history.csv")
    row = {q: hist[f"crest_{q}"][-1] for q in ("ux", "uy", "vx", "vy", "sxx", "syy", "sxy")}
    interpolation = (RHO * g / M) * h * h / 8
    assert abs(row["uy"] - uy) <= interpolation + 1e-3 * abs(uy)
    assert abs(row["ux"]) <= 1e-3 * abs(uy)
    np.testing.assert_allclose(row["syy"], syy, rtol=1e-3)
    np.testing.assert_allclose(row["sxx"], lam / M * syy, rtol=1e-3)
    assert abs(row["sxy"]) <= 1e-3 * abs(syy)
    assert abs(row["vx"]) + abs(row["vy"]) < 1e-4 * abs(uy) / sim.dt  # settled
    # the monitor is the simulation's own field at the point: the triangle's stress, its nodes
    # interpolated with the point's barycentric weights
    nodes = sim.triangles[mon.triangle]
    np.testing.assert_allclose(row["uy"], mon.weights @ (sim.state.x - sim.x0)[nodes, 1], rtol=1e-9)
    np.testing.assert_allclose(row["syy"], sim.stresses()["yy"][mon.triangle], rtol=1e-9)
    np.testing.assert_allclose(mon.weights @ sim.x0[nodes], [x, y], atol=1e-12)


def test_point_monitor_outside_the_mesh_is_refused_naming_the_point(tmp_path):
    sim = Simulation(column(), out_dir=tmp_path, progress=False)
    with pytest.raises(ValueError, match=r"'toe'.*\(1\.5, 2\) m lies outside the mesh"):
        sim.add_point_monitor("toe", 1.5, 2.0)
    sim.add_point_monitor("edge", 1.0, 2.0)  # on the boundary: inside
    with pytest.raises(ValueError, match="already exists"):
        sim.add_point_monitor("edge", 0.5, 2.0)
    assert "toe_ux" not in sim.monitors and "edge_ux" in sim.monitors


def test_point_monitors_survive_a_checkpoint_and_old_checkpoints_still_load(tmp_path):
    from fdem.solve.checkpoint import load_checkpoint, save_checkpoint

    sim = Simulation(column(), progress=False)
    sim.add_point_monitor("mid", 0.5, 2.0)
    sim.run(n_steps=40, history_every=10, damping=Damping(local=0.8))
    save_checkpoint(sim, tmp_path / "c.npz")
    again = Simulation(column(), progress=False)  # built without the monitor: the checkpoint brings it
    load_checkpoint(again, tmp_path / "c.npz")
    assert again.point_monitors["mid"].triangle == sim.point_monitors["mid"].triangle
    sim.run(n_steps=20, history_every=10, damping=Damping(local=0.8))
    again.run(n_steps=20, history_every=10, damping=Damping(local=0.8))
    assert again.history[-1]["mid_uy"] == sim.history[-1]["mid_uy"] != 0.0
    # one of the same name watching another point is refused
    other = Simulation(column(), progress=False)
    other.add_point_monitor("mid", 0.2, 1.0)
    with pytest.raises(ValueError, match="'mid' watches"):
        load_checkpoint(other, tmp_path / "c.npz")
    # a state saved before point monitors existed (no key) loads as before
    d = sim.state_dict()
    del d["point_monitors"]
    plain = Simulation(column(), progress=False)
    plain.load_state_dict(d)
    assert not plain.point_monitors


def test_monitor_plot_draws_displacement_and_velocity_with_units(tmp_path):
    from fdem.io.monitor_plots import monitor_figure, monitor_plot

    sim = Simulation(column(), out_dir=tmp_path, progress=False)
    sim.add_point_monitor("a", 0.5, 3.9)
    sim.run(n_steps=30, history_every=10)
    sim.close()
    fig = monitor_figure(read_history(tmp_path / "history.csv"), ["a"])
    labels = [ax.get_ylabel() for ax in fig.axes] + [fig.axes[-1].get_xlabel()]
    assert labels == ["displacement [m]", "velocity [m/s]", "time [s]"]
    line = fig.axes[0].get_lines()[1]  # a u_y
    np.testing.assert_allclose(line.get_ydata(), [r["a_uy"] for r in sim.history])
    p = monitor_plot(tmp_path / "mon.png", sim.history, "a")
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match=r"no column\(s\) \['b_ux'"):
        monitor_plot(tmp_path / "x.png", sim.history, ["b"])


def test_contact_frame_lines_carry_the_pair_forces(tmp_path):
    """Two blocks, the upper one pushed 1 mm into the lower: one line per touching pair between
    the triangles' centroids, normal and shear force magnitudes equal to the pair law's force
    (the sum of the contact forces on the first triangle's nodes); a frame without touching
    pairs has no cells."""
    lower = structured_rectangle(2, 1, 1.0, 0.5)
    upper = structured_rectangle(2, 1, 1.0, 0.5, origin=(0.2, 0.5))
    mesh = Mesh(points=np.vstack([lower.points, upper.points]),
                triangles=np.vstack([lower.triangles, upper.triangles + len(lower.points)]),
                triangle_body=np.repeat(np.arange(2, dtype=np.int32), len(lower.triangles)))
    model = Model.from_mesh(mesh, ElasticMaterial(E, NU, RHO), exploded=True)
    contact = ContactSet(model.topology, penalty=1e10, friction_angle=30.0, mass=model.node_mass())
    sim = Simulation(model, providers=[contact], out_dir=tmp_path, name="blocks", progress=False)
    upper_nodes = model.topology.triangles[model.topology.triangle_body == 1].ravel()
    sim.state.x[upper_nodes, 1] -= 1e-3
    f = np.zeros_like(sim.state.x)
    contact.add_forces(sim.state.x, sim.state.v, f, sim.dt, 0)
    sim.write_output()
    m, g, _ = last_frame(tmp_path, "blocks_contacts")
    pf = contact.pair_forces()
    k = len(pf["pairs"])
    assert k > 0 and m.cells_dict["line"].shape == (k, 2) and g.n_cells == k
    for q, (i, j) in enumerate(pf["pairs"]):
        np.testing.assert_allclose(m.points[2 * q, :2], sim.state.x[3 * i:3 * i + 3].mean(0), rtol=1e-6)
        np.testing.assert_allclose(m.points[2 * q + 1, :2], sim.state.x[3 * j:3 * j + 3].mean(0), rtol=1e-6)
    f_first = np.array([f[3 * i:3 * i + 3].sum(0) for i in np.unique(pf["pairs"][:, 0])])
    total = np.array([pf["force"][pf["pairs"][:, 0] == i].sum(0) for i in np.unique(pf["pairs"][:, 0])])
    np.testing.assert_allclose(total, f_first, rtol=1e-9, atol=1e-9 * np.abs(f).max())
    np.testing.assert_allclose(m.cell_data["normal_force"][0], pf["normal"], rtol=1e-6)
    np.testing.assert_allclose(m.cell_data["normal_force"][0], np.linalg.norm(pf["force"], axis=1), rtol=1e-6)
    assert np.all(m.cell_data["shear_force"][0] == 0.0)  # no slip yet: no tangential spring force
    # lift the upper block clear: the next frame has no contact lines
    sim.state.x[upper_nodes, 1] += 0.1
    contact.add_forces(sim.state.x, sim.state.v, np.zeros_like(f), sim.dt, 1)
    sim.write_output()
    import pyvista as pv  # (meshio 5.3 cannot read a grid without cells)

    frames = read_pvd(tmp_path / "blocks_contacts.pvd")
    assert len(frames) == 2 and pv.read(str(frames[-1][1])).n_cells == 0


def test_vtk_warps_the_frame_back_to_the_reference_by_its_displacement(tmp_path):
    """The displacement is a 3-component vector VTK takes as such: ParaView's Warp By Vector
    (``vtkWarpVector``) with scale -1 puts the frame's current points back on the reference
    positions (to float32 precision). VTK takes only 3-component arrays as vectors
    (``docs/outputs.md``), hence the zero third component."""
    import pyvista as pv
    import vtk

    sim, cs, separate = crack_sim(tmp_path)
    sim.set_positions(sim.x0 + 1e-3 * np.random.default_rng(5).standard_normal(sim.x0.shape))
    sim.write_output()
    _, grid, _ = last_frame(tmp_path, "pair")
    warp = vtk.vtkWarpVector()
    warp.SetInputData(grid)
    warp.SetInputArrayToProcess(0, 0, 0, 0, "displacement")
    warp.SetScaleFactor(-1.0)
    warp.Update()
    back = np.asarray(pv.wrap(warp.GetOutput()).points)
    np.testing.assert_allclose(back[:, :2], sim.x0, atol=1e-6)
    assert grid.point_data["displacement"].shape[1] == 3
