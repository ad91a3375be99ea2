"""Pictures (valid PNGs of real content, clear errors on mismatched arrays) and compact VTU output
(compressed files read back bit for bit through meshio and pyvista; field selection)."""
import numpy as np
import pytest

from fdem.results.events import MULIASHI
from fdem.mesh.mesh import structured_rectangle
from fdem.io.vtk import PvdSeries, read_pvd, write_vtu
from fdem.io.pictures import (crack_count_plot, failure_frame, fragment_size_plot, kinetic_energy_plot)
from fdem.results.events import magnitude_plot
from fdem.mesh.topology import build_topology

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
TOPO = build_topology(structured_rectangle(20, 10, 20.0, 10.0))


def png_size(path):
    """(width, height) from the IHDR chunk, after checking the PNG signature."""
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and data[12:16] == b"IHDR"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def scene():
    x = TOPO.x0.copy()
    c0 = x[TOPO.triangles].mean(axis=1)
    wedge = c0[:, 1] > c0[:, 0] - 5.0
    x[TOPO.triangles[wedge].ravel()] += [-1.5, -1.0]
    u = np.linalg.norm(x[TOPO.triangles].mean(axis=1) - c0, axis=1)
    a, b = TOPO.crack_triangles.T
    broken = wedge[a] != wedge[b]
    mode = np.where(broken, 1 + np.arange(TOPO.n_cracks) % 3, 0)
    cn = TOPO.crack_nodes
    segs = np.stack([0.5 * (x[cn[:, 0]] + x[cn[:, 3]]), 0.5 * (x[cn[:, 1]] + x[cn[:, 2]])], axis=1)
    return x, u, segs, broken, mode


def test_failure_frame_is_a_png_with_content(tmp_path):
    x, u, segs, broken, mode = scene()
    p = failure_frame(tmp_path / "f.png", x, TOPO, u, segs, broken, mode, title="wedge")
    w, h = png_size(p)
    assert w > 800 and h > 300 and p.stat().st_size > 20_000
    # per-node displacement, (2n, 2) crack points and string modes are accepted as well
    names = np.array(["", "I", "II", "mixed"])[mode]
    names[~broken] = "I"
    p2 = failure_frame(tmp_path / "g.png", x, TOPO.triangles, np.linalg.norm(x - TOPO.x0, axis=1),
                       segs.reshape(-1, 2), broken, names)
    assert png_size(p2)[0] > 800


def test_failure_frame_refuses_mismatched_shapes(tmp_path):
    x, u, segs, broken, mode = scene()
    with pytest.raises(ValueError, match="displacement must have one value per triangle"):
        failure_frame(tmp_path / "f.png", x, TOPO, u[:-1], segs, broken, mode)
    with pytest.raises(ValueError, match="failure_mode must have shape"):
        failure_frame(tmp_path / "f.png", x, TOPO, u, segs, broken, mode[:-1])
    with pytest.raises(ValueError, match="broken must have shape"):
        failure_frame(tmp_path / "f.png", x, TOPO, u, segs, broken[:3], mode)
    with pytest.raises(ValueError, match="crack_segments must have shape"):
        failure_frame(tmp_path / "f.png", x, TOPO, u, segs[:, :, :1], broken, mode)
    with pytest.raises(ValueError, match="unknown failure mode"):
        failure_frame(tmp_path / "f.png", x, TOPO, u, segs, broken, np.full(TOPO.n_cracks, "III"))
    assert not (tmp_path / "f.png").exists()


def test_time_plots_are_pngs_and_refuse_mismatched_lengths(tmp_path):
    t = np.linspace(0, 2.0, 200)
    ke = 1e3 * np.exp(-((t - 1.0) / 0.2) ** 2)
    stage = np.where(t < 0.5, "geostatic", "runout")
    assert png_size(kinetic_energy_plot(tmp_path / "ke.png", t, ke, stage))[0] > 500
    with pytest.raises(ValueError, match="time: 200, kinetic: 199"):
        kinetic_energy_plot(tmp_path / "bad.png", t, ke[:-1])
    rng = np.random.default_rng(0)
    tc = np.sort(rng.random(300))
    modes = rng.choice(["I", "II", "mixed"], 300)
    assert png_size(crack_count_plot(tmp_path / "cracks.png", tc, modes, t_end=1.2))[0] > 500
    with pytest.raises(ValueError, match="same length"):
        crack_count_plot(tmp_path / "bad.png", tc, modes[:10])
    m = -4.0 + rng.exponential(1 / np.log(10), 500)
    p = magnitude_plot(tmp_path / "mag.png", m, reference=MULIASHI)
    assert png_size(p)[0] > 800 and p.stat().st_size > 20_000
    assert png_size(magnitude_plot(tmp_path / "none.png", np.zeros(0)))[0] > 800  # says "no events"
    assert png_size(fragment_size_plot(tmp_path / "frag.png", 10 ** rng.uniform(-2, 2, 400)))[0] > 500
    with pytest.raises(ValueError, match="positive"):
        fragment_size_plot(tmp_path / "bad.png", np.array([1.0, 0.0]))


def frame_arrays(n_tri=3000, seed=0):
    rng = np.random.default_rng(seed)
    topo = build_topology(structured_rectangle(50, n_tri // 100, 10.0, 5.0))
    x = topo.x0 + 1e-3 * rng.standard_normal(topo.x0.shape)
    point = {"displacement": x - topo.x0, "velocity": rng.standard_normal(x.shape)}
    cell = {"stress_yy": rng.standard_normal(topo.n_triangles) * 1e5,
            "property": np.zeros(topo.n_triangles, np.int32), "broken": rng.random(topo.n_triangles) < 0.5}
    return topo, x, point, cell


@pytest.mark.parametrize("compression", ["zlib", "lzma"])
def test_compressed_vtu_reads_back_exactly_through_meshio_and_pyvista(tmp_path, compression):
    import meshio
    import pyvista as pv

    import fdem.io.vtk as out

    topo, x, point, cell = frame_arrays()
    raw = write_vtu(tmp_path / "raw.vtu", x, topo.triangles, point_data=point, cell_data=cell)
    old = out.BLOCK_SIZE
    out.BLOCK_SIZE = 4096  # several blocks per array, and a partial last block
    try:
        p = write_vtu(tmp_path / "c.vtu", x, topo.triangles, point_data=point, cell_data=cell, compression=compression)
    finally:
        out.BLOCK_SIZE = old
    assert f'compressor="vtk{"ZLib" if compression == "zlib" else "LZMA"}DataCompressor"' in p.read_bytes()[:300].decode()
    assert p.stat().st_size < raw.stat().st_size
    m = meshio.read(p)
    np.testing.assert_array_equal(m.points[:, :2], x)
    np.testing.assert_array_equal(m.cells_dict["triangle"], topo.triangles)
    np.testing.assert_array_equal(m.point_data["displacement"][:, :2], point["displacement"])
    np.testing.assert_array_equal(m.point_data["velocity"][:, :2], point["velocity"])
    np.testing.assert_array_equal(m.cell_data["stress_yy"][0], cell["stress_yy"])
    np.testing.assert_array_equal(m.cell_data["broken"][0], cell["broken"].astype(np.uint8))
    g = pv.read(str(p))
    np.testing.assert_array_equal(np.asarray(g.cell_data["stress_yy"]), cell["stress_yy"])
    np.testing.assert_array_equal(np.asarray(g.points)[:, :2], x)


def test_field_selection_writes_only_the_named_arrays(tmp_path):
    import meshio

    topo, x, point, cell = frame_arrays()
    p = write_vtu(tmp_path / "s.vtu", x, topo.triangles, point_data=point, cell_data=cell,
                  compression="zlib", fields=["displacement", "stress_yy"])
    m = meshio.read(p)
    assert set(m.point_data) == {"displacement"} and set(m.cell_data) == {"stress_yy"}
    with pytest.raises(ValueError, match=r"fields \['stres_yy'\] are not among"):
        write_vtu(tmp_path / "t.vtu", x, topo.triangles, point_data=point, cell_data=cell, fields=["stres_yy"])
    with pytest.raises(ValueError, match="compression must be None or one of"):
        write_vtu(tmp_path / "t.vtu", x, topo.triangles, compression="gzip")


def test_compressed_pvd_series_reads_back(tmp_path):
    import meshio

    topo, x, point, cell = frame_arrays()
    series = PvdSeries(tmp_path, "slope", compression="zlib", fields=["displacement"])
    for k in range(3):
        series.write(0.1 * k, x + k, topo.triangles, point_data=point, cell_data=cell)
    frames = read_pvd(series.pvd_path)
    assert [t for t, _ in frames] == [0.0, 0.1, 0.2]
    last = meshio.read(frames[-1][1])
    np.testing.assert_array_equal(last.points[:, :2], x + 2)
    assert set(last.point_data) == {"displacement"} and not last.cell_data
