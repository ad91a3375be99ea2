"""Benchmark: bytes per triangle per frame and write time of the ParaView frames, before and after.

A frame is the pair a run writes at every output time: the triangle file (``<name>_NNNNN.vtu``)
and the crack file (``<name>_cracks_NNNNN.vtu``, one line cell per crack element, about 1.5 per
triangle). The four-slope low-angle fine slope meshed at 0.6 m and 0.18 m (about 2e4 and 1.8e5
triangles; 0.18 m is ``runs/paper_low_fine``), ``--steps`` damped steps from its K0 stress, so
the fields carry a run's noise in their low digits (what decides how well they compress).
Written as

* ``before``: the fields and format of the frames until this change (float64, raw; displacement,
  velocity, seven stress scalars, property, body; on the cracks tag, opening, slip, damage,
  broken, failure mode, fracture energy, strength multiplier); the index arrays are counted as
  Int64, as that writer wrote them;
* ``hand zlib f32`` (the new default of ``Simulation``): today's fields (stress and strain
  tensors, principal stresses and directions, crack tractions and break times) as float32,
  zlib level 1, by :func:`fdem.io.vtk.write_vtu`;
* ``hand raw f32``, ``hand lzma f32``, ``hand zlib f64``: the same without compression, with
  lzma (preset 1), or in float64;
* ``vtk zlib f32``: the same arrays through VTK's own ``vtkXMLUnstructuredGridWriter`` (appended
  raw, zlib level 1), the time including building the ``vtkUnstructuredGrid`` from the arrays.

``hand zlib f32, 2 compression threads`` is the new default with its blocks compressed on two
threads (what a run with ``NUMBA_NUM_THREADS`` unset does on this 2-core machine). Also the
bytes per triangle of the topology alone (connectivity, offsets, types) in the zlib
frame: what writing the topology once (a shared-topology format) could save at most. Times are
the best of ``--repeats`` writes, the variants interleaved; the pyvista read time is one read. Prints and writes ``docs/benchmarks/frames.json``.

    python cases/benchmarks/bench_frames.py [--sizes 0.6 0.18] [--repeats 3] [--steps 200]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parents[1]))  # run from a checkout without installing
from records import record, save  # noqa: E402

from fdem.cases import four_slopes  # noqa: E402
from fdem.io import vtk as out  # noqa: E402
from fdem.solve.damping import Damping  # noqa: E402
from fdem.solve.simulation import Simulation  # noqa: E402

OLD_CELL = ("xx", "yy", "xy", "zz", "principal_1", "principal_2", "von_mises")
OLD_CRACK = ("crack_tag", "opening", "slip", "damage", "broken", "failure_mode", "fracture_energy",
             "strength_multiplier")


def scene(size: float, steps: int) -> Simulation:
    """The four-slope low-angle fine slope (Gmsh mesh of element size ``size`` [m], intact and
    DFN crack elements, contact) from its K0 stress, ``steps`` damped steps on: the fields of a
    real scene (an irregular mesh, a two-dimensional stress field with the face out of balance),
    not of a structured block, whose rows repeat and compress far better than any run's."""
    geometry, _, topology = four_slopes.build("low", "fine", size=size)
    sim, _ = four_slopes.simulation(geometry, topology, None, pictures=False, start="k0", progress=False)
    sim.run(n_steps=steps, history_every=steps, damping=Damping(local=0.1), final_output=False)
    return sim


def frame_content(sim: Simulation) -> dict:
    """Points, cells and fields of the triangle and crack files, new and old field sets."""
    topo = sim.model.topology
    f = sim.fields()
    s = sim.stresses()
    g = sim.crack_geometry()
    crack = {"crack_tag": topo.crack_tag, "opening": g["opening"], "slip": g["slip"]}
    crack.update(sim.cracks.crack_fields(sim.state.x))
    lines = np.arange(2 * topo.n_cracks, dtype=np.int64).reshape(-1, 2)
    old_cell = {f"stress_{k}": s[k] for k in OLD_CELL}
    old_cell.update(property=f["cell"]["property"], body=f["cell"]["body"])
    return {"tri": (sim.state.x, sim.triangles, f["point"], f["cell"]),
            "tri_old": (sim.state.x, sim.triangles, f["point"], old_cell),
            "crack": (g["points"], lines, crack),
            "crack_old": (g["points"], lines, {k: crack[k] for k in OLD_CRACK})}


def write_hand(d: Path, c: dict, compression, precision, old=False) -> list[Path]:
    x, tri, point, cell = c["tri_old" if old else "tri"]
    pts, lines, crack = c["crack_old" if old else "crack"]
    return [out.write_vtu(d / "t.vtu", x, tri, out.VTK_TRIANGLE, point, cell, compression=compression,
                          precision=precision),
            out.write_vtu(d / "c.vtu", pts, lines, out.VTK_LINE, None, crack, compression=compression,
                          precision=precision)]


def _vtk_grid(points, cells, cell_type, point_data, cell_data):
    import pyvista as pv

    pts = np.zeros((len(points), 3), np.float32)
    pts[:, :2] = points
    grid = pv.UnstructuredGrid({cell_type: np.asarray(cells, np.int64)}, pts)
    for target, data in ((grid.point_data, point_data or {}), (grid.cell_data, cell_data)):
        for name, a in data.items():
            a = np.asarray(a)
            if a.dtype == np.bool_:
                a = a.astype(np.uint8)
            if a.dtype.kind == "f":
                a = a.astype(np.float32)
            if a.ndim == 2 and a.shape[1] == 2:
                a = np.column_stack([a, np.zeros(len(a), a.dtype)])
            target[name] = a
    return grid


def write_vtk(d: Path, c: dict) -> list[Path]:
    import vtk

    x, tri, point, cell = c["tri"]
    pts, lines, crack = c["crack"]
    paths = []
    for name, grid in (("t.vtu", _vtk_grid(x, tri, out.VTK_TRIANGLE, point, cell)),
                       ("c.vtu", _vtk_grid(pts, lines, out.VTK_LINE, None, crack))):
        w = vtk.vtkXMLUnstructuredGridWriter()
        w.SetFileName(str(d / name))
        w.SetInputData(grid)
        w.SetDataModeToAppended()
        w.EncodeAppendedDataOff()
        w.SetCompressorTypeToZLib()
        w.SetCompressionLevel(1)
        w.Write()
        paths.append(d / name)
    return paths


def with_threads(n: int, fn):
    """``fn()`` with ``n`` compression threads (:func:`fdem.io.vtk.write_vtu` reads
    ``NUMBA_NUM_THREADS`` at each call)."""
    old = os.environ.get("NUMBA_NUM_THREADS")
    os.environ["NUMBA_NUM_THREADS"] = str(n)
    try:
        return fn()
    finally:
        if old is None:
            del os.environ["NUMBA_NUM_THREADS"]
        else:
            os.environ["NUMBA_NUM_THREADS"] = old


def best_time(fn, repeats: int):
    best, result = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[0.6, 0.18], help="element sizes [m]")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--name", default="frames", help="docs/benchmarks/<name>.json")
    args = ap.parse_args(argv)
    threads = int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1))
    records = []
    for size in args.sizes:
        sim = scene(size, args.steps)
        n_tri, n_crack = sim.model.n_triangles, sim.model.topology.n_cracks
        t_fields, c = best_time(lambda: frame_content(sim), args.repeats)
        records.append(record("fields of a frame pair computed (stresses, strain, crack tractions)", t_fields, "s",
                              n_tri, threads, n_crack_elements=n_crack, load_average=os.getloadavg()[0]))
        variants = {"before (float64, raw, old fields)": lambda d: write_hand(d, c, None, None, old=True),
                    "hand zlib f32 (new default)": lambda d: write_hand(d, c, "zlib", "float32"),
                    "hand zlib f32, 2 compression threads": lambda d: with_threads(
                        2, lambda: write_hand(d, c, "zlib", "float32")),
                    "hand raw f32": lambda d: write_hand(d, c, None, "float32"),
                    "hand lzma f32": lambda d: write_hand(d, c, "lzma", "float32"),
                    "hand zlib f64": lambda d: write_hand(d, c, "zlib", None),
                    "vtk zlib f32": lambda d: write_vtk(d, c)}
        best = dict.fromkeys(variants, float("inf"))
        sizes_b = {}
        with tempfile.TemporaryDirectory() as tmp:
            # repeats outside, variants inside: every variant meets the same spells of load
            for _ in range(args.repeats):
                for label, fn in variants.items():
                    d = Path(tmp) / str(len(sizes_b))
                    d.mkdir(exist_ok=True)
                    t0 = time.perf_counter()
                    paths = fn(d)
                    best[label] = min(best[label], time.perf_counter() - t0)
                    t1 = time.perf_counter()
                    __import__("pyvista").read(str(paths[0]))
                    sizes_b[label] = [p.stat().st_size for p in paths] + [time.perf_counter() - t1]
            for label in variants:
                tri_b, crack_b, t_read = sizes_b[label]
                if label.startswith("before"):  # its Int64 index arrays: 4 more bytes per
                    tri_b += 4 * 4 * n_tri        # connectivity (3 per triangle, 2 per line) and
                    crack_b += 4 * 3 * n_crack    # offset entry
                extra = dict(n_crack_elements=n_crack, triangle_file_B=tri_b, crack_file_B=crack_b,
                             triangle_file_pyvista_read_s=t_read, load_average=os.getloadavg()[0])
                records.append(record(f"frame pair bytes per triangle: {label}", (tri_b + crack_b) / n_tri,
                                      "B/triangle", n_tri, threads, element_size_m=size, **extra))
                records.append(record(f"frame pair write time: {label}", best[label], "s", n_tri, threads,
                                      load_average=os.getloadavg()[0]))
        # the topology alone, as the zlib frame stores it (what a shared topology could save)
        topo_b = 0
        for arr in (out._index_array(sim.triangles.ravel()), out._index_array(np.arange(1, n_tri + 1) * 3),
                    np.full(n_tri, out.VTK_TRIANGLE, np.uint8)):
            topo_b += len(out._compressed_block(arr.tobytes(), "zlib", 1))
        lines = np.arange(2 * n_crack)
        for arr in (out._index_array(lines), out._index_array(np.arange(1, n_crack + 1) * 2),
                    np.full(n_crack, out.VTK_LINE, np.uint8)):
            topo_b += len(out._compressed_block(arr.tobytes(), "zlib", 1))
        records.append(record("topology (connectivity, offsets, types) of the zlib frame pair", topo_b / n_tri,
                              "B/triangle", n_tri, threads))
    save(args.name, records, sizes=args.sizes, steps=args.steps, repeats=args.repeats)
    return records


if __name__ == "__main__":
    main()
