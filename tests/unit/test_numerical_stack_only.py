"""The solver core runs on a machine with only the numerical stack (a GPU node: numpy, scipy,
numba, numba-cuda): a mesh saved as ``.npz`` elsewhere loads, and a model with crack elements
and contact is built, stepped and checkpointed with Gmsh, meshio, pyvista, matplotlib and Dask
all missing. A fresh interpreter marks them missing (``sys.modules[name] = None``, so that
importing any of them fails as if it were not installed) before importing ``fdem``.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from fdem.geometry.polygons import slope_toe
from fdem.mesh.mesh import Mesh, structured_rectangle
from fdem.scene.objects import geometry

ROOT = Path(__file__).resolve().parents[2]
MISSING = ("gmsh", "meshio", "pyvista", "vtk", "matplotlib", "dask", "distributed", "tqdm")


def test_npz_mesh_round_trip(tmp_path):
    mesh = structured_rectangle(3, 2, 1.5, 1.0)
    mesh.save(tmp_path / "m.npz")
    back = Mesh.load(tmp_path / "m.npz")
    for name in ("points", "triangles", "triangle_body", "lines", "line_group"):
        assert np.array_equal(getattr(back, name), getattr(mesh, name)), name
    assert back.group_names == mesh.group_names


def test_a_saved_mesh_runs_without_gmsh_meshio_pyvista_or_dask(tmp_path):
    structured_rectangle(4, 4, 0.4, 0.4).save(tmp_path / "block.npz")
    script = textwrap.dedent(f"""
        import sys
        for name in {MISSING!r}:
            sys.modules[name] = None
        import numpy as np
        from fdem.mesh.mesh import Mesh
        from fdem.mesh.topology import build_topology
        from fdem.physics.contact import ContactSet
        from fdem.physics.crack_properties import CrackProperties
        from fdem.physics.cracks import CrackSet
        from fdem.physics.elastic import ElasticMaterial
        from fdem.solve.checkpoint import save_checkpoint
        from fdem.solve.model import Model
        from fdem.solve.simulation import Simulation
        topo = build_topology(Mesh.load({str(tmp_path / "block.npz")!r}))
        model = Model(topo, ElasticMaterial(young=1e9, poisson=0.25, density=2500.0))
        model.set_gravity(0.0, -9.81)
        model.fix("bottom")
        rock = CrackProperties(f_t=2e5, c=4e5, phi=30.0, G_I=5.0, G_II=20.0, p_n=1e10, name="rock")
        cracks = CrackSet(topo, {{0: rock}}, contact_penalty=1e10)
        contact = ContactSet(topo, 1e10, friction_angle=30.0, mass=model.node_mass(), cracks=cracks)
        sim = Simulation(model, providers=[cracks, contact], progress=False)
        sim.run(n_steps=50, energy_tolerance=None)
        save_checkpoint(sim, {str(tmp_path / "ck.npz")!r})
        # the block settles under its weight: it moved, and downwards
        dy = (sim.state.x - sim.x0)[:, 1]
        assert dy.min() < 0 and np.isfinite(sim.state.x).all()
        print("ok", sim.state.step)
        """)
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.split() == ["ok", "50"]
    assert (tmp_path / "ck.npz").exists()


def test_a_scene_meshed_elsewhere_runs_from_its_npz_without_gmsh(tmp_path):
    """The GPU-node path of docs/gpu.md: the demo scene written as a file, meshed here and saved
    as ``.npz``; ``fdem run scene.toml --mesh mesh.npz`` then runs in an interpreter where Gmsh
    and meshio cannot be imported, the toe and the joint groups taken from what the mesh replaces."""
    import tomllib

    from fdem.cli import main
    from fdem.scene.build import scene_mesh
    from fdem.scene.schema import check_scene

    scene_file = tmp_path / "demo.toml"
    assert main(["run", "quick-start", "--size", "2.0", "--write-scene", str(scene_file)]) == 0
    s = check_scene(tomllib.loads(scene_file.read_text()), scene_file)
    _, mesh = scene_mesh(s)
    mesh.save(tmp_path / "demo.npz")
    script = textwrap.dedent(f"""
        import sys
        for name in {MISSING!r}:
            sys.modules[name] = None
        from fdem.cli import main
        sys.exit(main(["run", "demo.toml", "--mesh", "demo.npz", "--max-time", "0.002", "--no-pictures",
                       "--quiet", "--out", "run", "--threads", "1"]))
        """)
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["n_triangles"] == mesh.n_triangles
    assert summary["toe"] == [float(c) for c in slope_toe(geometry(s).bodies[0])]
