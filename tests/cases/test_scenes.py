"""Scene files: a slope written in TOML runs with ``fdem run FILE``; a built-in case's written
scene runs the same model bit for bit; a user's Gmsh mesh with named physical groups carries
its supports and joints; a bad file is refused before any work, naming the file, the section
and the key.
"""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from fdem.mesh.topology import build_topology
from fdem.scene.schema import SceneError, check_scene, read_scene
from fdem.scene.write import scene_text

SMALL_SLOPE = """
[scene]
name = "my-slope"
size = 2.0

[slope]
kind = "simple"
height = 10.0
face_angle = 60.0
crest_length = 8.0
toe_length = 16.0
base_depth = 3.0

[[joints]]
kind = "persistent"
dip = 30.0
spacing = 3.0
through_toe = 0.0

[rock]
young = 0.5e9
poisson = 0.25
density = 2600.0
damping = 0.1

[cracks.0]
f_t = 2e5
c = 5e5
phi = 35.0
G_I = 500.0
G_II = 5000.0
p_n = 0.5e9

[cracks.1]
f_t = 5e4
c = 1e5
phi = 30.0
G_I = 50.0
G_II = 500.0
p_n = 0.5e9

[contact]
penalty = 0.5e9
friction_angle = 30.0

[supports]
bottom = "fixed"
left = "fix-x"
right = "fix-x"
"""


def fdem(*args, cwd=None, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fdem", *args], capture_output=True, text=True, timeout=timeout,
                          cwd=cwd)


def scene_dict(text: str) -> dict:
    import tomllib

    return tomllib.loads(text)


# ----------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("edit, words", [
    (lambda s: s["rock"].update(young=-5e9), ["[rock] young", "must be > 0", "Young's modulus"]),
    (lambda s: s["rock"].update(yung=5e9), ["[rock]", "unknown key(s) yung"]),
    (lambda s: s.update(rocks={}), ["unknown section(s) [rocks]"]),
    (lambda s: s["cracks"].pop("1"), ["no crack property set for tag(s) [1]"]),
    (lambda s: s["cracks"].update({"2": dict(s["cracks"]["1"])}), ["[cracks.2]", "no joint set"]),
    (lambda s: s["joints"][0].pop("spacing"), ["[[joints]] #1", "needs spacing"]),
    (lambda s: s["joints"][0].update(dip=200.0), ["[[joints]] #1", "dip", "[0, 180)"]),
    (lambda s: s["slope"].update(face_angle=95.0), ["[slope] face_angle", "(0, 90]"]),
    (lambda s: s["supports"].update(bottom="clamped"), ["[supports] bottom", "'fixed'"]),
    (lambda s: s["rock"].update(poisson="0.25"), ["[rock] poisson", "finite number"]),
    (lambda s: s["cracks"]["1"].update(p_t=1e9, k_t=1e9), ["[cracks]", "at most one of p_t"]),
    (lambda s: s["workflow"].update(fos=[2.0, 1.0, 0.1]), ["[workflow]"]),
])
def test_a_bad_scene_is_refused_naming_file_section_and_key(edit, words):
    raw = scene_dict(SMALL_SLOPE)
    raw.setdefault("workflow", {})
    edit(raw)
    with pytest.raises(SceneError) as err:
        check_scene(raw, Path("my_slope.toml"))
    message = str(err.value)
    assert message.startswith("my_slope.toml: ")
    for w in words:
        assert w.lower() in message.lower(), message


def test_a_crack_law_that_snaps_back_on_the_mesh_is_refused_before_the_static_start(tmp_path):
    """Snap-back depends on each element's length, so it is checked on the mesh (seconds), before
    the static solve, naming the property set, the energy needed and the way out."""
    from fdem.mesh.topology import build_topology
    from fdem.scene.build import build_simulation, scene_mesh

    scene = read_scene(_write(tmp_path, SMALL_SLOPE.replace("G_I = 50.0", "G_I = 0.001")))
    topo = build_topology(scene_mesh(scene)[1])
    with pytest.raises(SceneError, match=r"my_slope.toml: \[cracks\]: property set 1 .*G_I = 0.001 .*snap back"):
        build_simulation(scene, topo, None, pictures=False, progress=False, where="my_slope.toml")


def test_a_bad_scene_file_exits_2_before_any_work(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(SMALL_SLOPE.replace("poisson = 0.25", "poisson = 0.7"))
    run = fdem("run", str(path), "--out", str(tmp_path / "out"))
    assert run.returncode == 2
    assert "bad.toml: [rock] poisson = 0.7: must be in [0, 0.5)" in run.stderr
    assert not (tmp_path / "out").exists()  # nothing was started: no folder, no run.json


def test_written_scene_reads_back_to_the_same_scene(tmp_path):
    """The writer's text is TOML that checks to the same scene, floats exact (``repr``)."""
    scene = read_scene(_write(tmp_path, SMALL_SLOPE.replace("size = 2.0", "size = 0.1 # or 1/3\nmin_joint_length = 0.3333333333333333")))
    again = check_scene(scene_dict(scene_text(_rawable(scene))), tmp_path / "scene.toml")
    assert again == scene


# ----------------------------------------------------------------------------- runs
def test_a_scene_file_runs_and_starts_in_static_equilibrium(tmp_path):
    """``fdem run FILE`` in a subprocess: the summary names the scene, the mesh has the joint set
    (its crack elements tagged 1), and the static start holds: after 0.05 s of damped
    equilibrium the largest displacement is a small fraction of the element size."""
    path = _write(tmp_path, SMALL_SLOPE + '\n[[monitors]]\nname = "crest"\nx = 27.0\ny = 10.0\n')
    out = tmp_path / "run"
    run = fdem("run", str(path), "--out", str(out), "--max-time", "0.05", "--no-pictures", "--quiet",
               "--threads", "1")
    assert run.returncode == 0, run.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["case"] == "scene" and summary["scene"] == "my-slope"
    assert summary["workflow"]["stages"][0]["name"] == "equilibrium"
    assert summary["runout"]["max_displacement_m"] < 0.01 * 2.0
    # the point monitor 3 m below the crest: at rest, under about the weight of the rock above
    from fdem.io.history import read_history

    h = read_history(out / "history.csv")
    assert np.all(np.abs(h["crest_uy"]) < 1e-3) and np.all(np.abs(h["crest_vy"]) < 1e-2)
    weight = 2600.0 * 9.81 * 3.0
    assert 0.6 * weight < -h["crest_syy"][-1] < 1.4 * weight, h["crest_syy"][-1]
    assert (out / "scene.toml").is_file() and read_scene(out / "scene.toml")["scene"]["name"] == "my-slope"
    record = json.loads((out / "run.json").read_text())
    assert record["case"] == "scene" and record["exit_code"] == 0


def test_a_cases_written_scene_runs_the_same_model(tmp_path):
    """``fdem run quick-start --write-scene FILE`` then ``fdem run FILE``: the same mesh, model
    and workflow, so the same history bit for bit (equilibrium at F = 1 and the first reduction
    steps, 0.6 s of simulated time at 2 m elements)."""
    from fdem.cases import quick_start, scene

    args = ["--size", "2.0", "--max-time", "0.6", "--no-pictures", "--quiet", "--threads", "1"]
    written = quick_start.main(["--size", "2.0", "--write-scene", str(tmp_path / "qs.toml")])
    assert written["outcome"] == "scene written"
    a = quick_start.main(args + ["--out", str(tmp_path / "case")])
    b = scene.main([str(tmp_path / "qs.toml")] + args[2:] + ["--out", str(tmp_path / "scene")])
    assert b["n_triangles"] == a["workflow"]["stages"][0].get("n_triangles", b["n_triangles"])
    assert (tmp_path / "case" / "history.csv").read_bytes() == (tmp_path / "scene" / "history.csv").read_bytes()
    assert a["cracks"] == b["cracks"]


def test_four_slopes_writes_a_scene_that_checks(tmp_path):
    from fdem.cases import four_slopes

    path = tmp_path / "fs.toml"
    four_slopes.main(["--angle", "high", "--spacing", "coarse", "--size", "1.0", "--fos", "1.0", "2.0", "0.1",
                      "--write-scene", str(path)])
    scene = read_scene(path)
    assert scene["joints"][0]["dip"] == 115.0 and scene["joints"][0]["spacing"] == 5.0
    assert scene["workflow"]["fos"] == [1.0, 2.0, 0.1]
    assert scene["cracks"][1]["k_t"] == 917e9  # the paper's tangential stiffness, not a penalty
    assert (scene["slope"]["crest_length"], scene["slope"]["toe_length"], scene["slope"]["base_depth"]) == (60, 90, 15)


def test_four_slopes_wider_model_keeps_the_slope_and_its_joints_and_refuses_a_bad_extent(tmp_path, capsys):
    """A wider model (the boundary check of docs/cases.md A) moves the boundaries, not the slope:
    the toe, the face and the persistent joints through the toe stay where they were."""
    from fdem.cases import four_slopes
    from fdem.geometry.polygons import slope_toe

    path = tmp_path / "wide.toml"
    four_slopes.main(["--angle", "high", "--crest-length", "60", "--base-depth", "30", "--write-scene", str(path)])
    scene = read_scene(path)
    assert (scene["slope"]["crest_length"], scene["slope"]["base_depth"]) == (60, 30)
    base = four_slopes.four_slope_geometry("high", "fine")
    wide = four_slopes.four_slope_geometry("high", "fine", crest_length=60.0, base_depth=30.0)
    (tx, ty), (wx, wy) = slope_toe(base.bodies[0]), slope_toe(wide.bodies[0])
    assert wx == tx and wy == ty + 15.0  # the same toe, 15 m more rock below it
    assert np.ptp(wide.bodies[0].vertices[:, 0]) == np.ptp(base.bodies[0].vertices[:, 0]) + 30.0
    # the persistent joints keep their place relative to the toe
    n = np.array([-np.sin(np.radians(115.0)), np.cos(np.radians(115.0))])
    fb, fw = base.joint_sets[0], wide.joint_sets[0]
    assert (fw.offset - n @ (wx, wy)) == pytest.approx(fb.offset - n @ (tx, ty))
    with pytest.raises(SystemExit) as exit_:
        four_slopes.main(["--base-depth", "0", "--out", str(tmp_path / "x")])
    assert exit_.value.code == 2 and "--base-depth must be a positive number of metres" in capsys.readouterr().err
    # a block off the face is told from the slope's failure: a tenth of the 45 deg face wedge, 11.25 m^2
    assert scene["workflow"]["local_fall_area"] == pytest.approx(0.1 * 15.0 ** 2 / 2)
    from fdem.scene.objects import workflow

    assert workflow(scene).local_fall_area == pytest.approx(11.25)  # the scene file's workflow carries it
    with pytest.raises(SystemExit) as exit_:
        four_slopes.main(["--local-fall-area", "-1", "--out", str(tmp_path / "y")])
    assert exit_.value.code == 2 and "--local-fall-area must be a number of square metres >= 0" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:  # the paper's rate has no steps to carry on
        four_slopes.main(["--reduction", "rate", "--local-fall-area", "5", "--out", str(tmp_path / "z")])
    assert exit_.value.code == 2 and "--reduction rate has no steps" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:  # a search alone needs its bracket
        four_slopes.main(["--reduction", "none", "--out", str(tmp_path / "z")])
    assert exit_.value.code == 2 and "give --fos LOWER UPPER TOL" in capsys.readouterr().err
    path = tmp_path / "search.toml"  # and a scene file says the same
    four_slopes.main(["--reduction", "none", "--fos", "1.0", "2.0", "0.1", "--write-scene", str(path)])
    assert workflow(read_scene(path)).reduction == "none"


def test_four_slopes_runs_use_extents_that_keep_the_boundaries_out_and_name_them(tmp_path):
    """A run's extents default by angle (the low-angle slope's toe joint must daylight on the crest
    and its debris fit on the floor; the high-angle slope's joints must not meet the rollers), are
    written into run.json so that a resumed run rebuilds the same mesh, and a run begun before they
    were written resumes with the extents of then."""
    from fdem.cases import four_slopes as fs

    H = fs.FOUR_SLOPE_HEIGHT
    none = dict.fromkeys(fs.EXTENTS_BEFORE_PINNING)
    low = fs.resolve_extents("low", none)
    assert (low["crest_length"], low["toe_length"], low["boundary_band"]) == (4 * H, 6 * H, None)
    # the low-angle toe joint (15 deg through the toe) reaches the crest surface inside the model
    assert H / math.tan(math.radians(fs.FOUR_SLOPE_JOINT_DIP["low"])) - H < low["crest_length"]
    assert fs.resolve_extents("high", none)["boundary_band"] == 5.0
    assert fs.resolve_extents("high", {**none, "boundary_band": 0.0})["boundary_band"] is None
    assert fs.resolve_extents("low", none, began_with=["--angle", "low"]) == fs.EXTENTS_BEFORE_PINNING
    assert fs.resolve_extents("low", {**none, "crest_length": 90.0}, began_with=["--crest-length", "90"]) == {
        **fs.EXTENTS_BEFORE_PINNING, "crest_length": 90.0}
    with pytest.raises(ValueError, match="--toe-length must be a positive"):
        fs.resolve_extents("low", {**none, "toe_length": -1.0})
    out = tmp_path / "mesh_only"
    summary = fs.main(["--spacing", "coarse", "--size", "3.0", "--max-steps", "0", "--fos", "1.0", "2.0", "0.5",
                       "--no-pictures", "--quiet", "--out", str(out)])
    argv = json.loads((out / "run.json").read_text())["argv"]
    # and the search's trial rule, today's default: a resume by a later default keeps it
    for flag, value in (("--crest-length", "60"), ("--toe-length", "90"), ("--base-depth", "15"),
                        ("--boundary-band", "0"), ("--trial-end", "rest")):
        assert argv[argv.index(flag) + 1] == value
    assert summary["extents_m"] == low


@pytest.mark.parametrize("reduction", ["steps", "rate"])
def test_a_resumed_four_slope_run_keeps_the_settings_it_began_with(reduction):
    """A run begun before --tensile, --runout-dt-fraction, --local-fall-area and --trial-end were
    pinned resumes with the behaviour of then (f_t divided by F, a runout step of 0.4, any fall
    the slope's failure, a capped trial failing), one that named them keeps its values, and a
    new run takes today's defaults."""
    from argparse import Namespace

    from fdem.cases import four_slopes as fs

    def settled(began_with, **given):
        args = Namespace(**{"tensile": None, "runout_dt_fraction": 0.8, "local_fall_area": None,
                            "reduction": reduction, "trial_end": None, **given})
        fs.keep_settings_of_then(args, began_with)
        return args.tensile, args.runout_dt_fraction, args.local_fall_area, args.trial_end

    steps_area = 0.0 if reduction == "steps" else None  # the rate has no steps to carry on
    assert settled(["--angle", "high"]) == ("reduced", 0.4, steps_area, "cap")
    pinned = ["--tensile", "kept", "--runout-dt-fraction", "0.8", "--local-fall-area", "11.25", "--trial-end", "rest"]
    assert settled(pinned, tensile="kept", local_fall_area=11.25 if reduction == "steps" else None,
                   trial_end="rest") == ("kept", 0.8, 11.25 if reduction == "steps" else None, "rest")
    assert settled(None) == (None, 0.8, fs.LOCAL_FALL_AREA if reduction == "steps" else None, None)
    assert fs.LOCAL_FALL_AREA == pytest.approx(0.1 * fs.FOUR_SLOPE_HEIGHT ** 2 / 2)  # a tenth of the 45 deg face wedge


def test_four_slopes_side_bands_go_into_the_scene_file(tmp_path):
    """``--boundary-band`` writes ``side_band`` into the joint set, and the scene builds the same
    joint traces as the case: none within the band of either boundary."""
    from fdem.cases import four_slopes
    from fdem.scene.objects import geometry as scene_geometry

    path = tmp_path / "banded.toml"
    four_slopes.main(["--angle", "high", "--boundary-band", "5", "--write-scene", str(path)])
    scene = read_scene(path)
    assert scene["joints"][0]["side_band"] == 5.0 and scene["joints"][0]["kind"] == "brick"
    extents = {k: v for k, v in four_slopes.RUN_EXTENTS["high"].items() if k != "boundary_band"}  # the run's
    case = four_slopes.four_slope_geometry("high", "fine", boundary_band=5.0, **extents)
    built = scene_geometry(scene)
    bounds = case.bodies[0].bounds
    a = case.joint_sets[0].raw_segments(bounds)
    b = built.joint_sets[0].raw_segments(bounds)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    x = b.reshape(-1, 2)[:, 0]
    assert x.min() >= bounds[0] + 5.0 - 1e-9 and x.max() <= bounds[2] - 5.0 + 1e-9
    bad = tmp_path / "bad.toml"
    bad.write_text(path.read_text().replace("side_band = 5.0", "side_band = -1.0"))
    with pytest.raises(SceneError, match="side_band"):
        read_scene(bad)


def test_four_slopes_elastic_side_bands_go_into_the_scene_file(tmp_path):
    """``--elastic-band`` writes ``[rock] elastic_side_bands``, and the scene's crack set gives
    the same elements the band's elastic set as the case's does: the intact elements within the
    band of either side, none of the joints; the outputs still read the geometry's tags."""
    from fdem.cases import four_slopes
    from fdem.physics.side_bands import side_band_mask
    from fdem.scene.build import build_simulation, scene_mesh

    path = tmp_path / "elastic.toml"
    four_slopes.main(["--angle", "high", "--spacing", "coarse", "--size", "3", "--elastic-band",
                      "--write-scene", str(path)])
    scene = read_scene(path)
    assert scene["rock"]["elastic_side_bands"] == 5.0 and scene["joints"][0]["side_band"] == 5.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, mesh = scene_mesh(scene)
    topo = build_topology(mesh)
    _, from_scene, _ = build_simulation(scene, topo, None, pictures=False, progress=False)
    _, from_case = four_slopes.simulation(None, topo, None, pictures=False, progress=False, elastic_band=5.0)
    band = side_band_mask(topo, 5.0) & (topo.crack_tag == 0)
    assert band.sum() > 0
    for cracks in (from_scene, from_case):
        assert cracks.topology is topo
        np.testing.assert_array_equal(cracks.tag == 2, band)
        assert cracks.props[2].tolist() == from_case.props[2].tolist()
    bad = tmp_path / "bad.toml"
    bad.write_text(path.read_text().replace("elastic_side_bands = 5.0", "elastic_side_bands = 0.0"))
    with pytest.raises(SceneError, match="elastic_side_bands"):
        read_scene(bad)


# ----------------------------------------------------------------------------- a user's mesh
def _user_mesh(path: Path, size: float = 1.5) -> None:
    """A slope meshed by Gmsh's own API with the user's group names: ``base`` and ``sides``
    (curves), ``bedding`` (a joint curve embedded in the rock), ``rock`` (the surface)."""
    import gmsh

    gmsh.initialize(["-v", "0"])
    try:
        gmsh.model.add("user")
        g = gmsh.model.geo
        pts = [(0, 0), (24, 0), (24, 13), (16, 13), (10, 3), (0, 3)]
        p = [g.addPoint(x, y, 0, size) for x, y in pts]
        lines = [g.addLine(p[i], p[(i + 1) % len(p)]) for i in range(len(p))]
        loop = g.addCurveLoop(lines)
        surface = g.addPlaneSurface([loop])
        a, b = g.addPoint(12, 4, 0, size), g.addPoint(22, 8, 0, size)
        joint = g.addLine(a, b)
        g.synchronize()
        gmsh.model.mesh.embed(1, [joint], 2, surface)
        gmsh.model.addPhysicalGroup(1, [lines[0]], name="base")
        gmsh.model.addPhysicalGroup(1, [lines[1], lines[5]], name="sides")
        gmsh.model.addPhysicalGroup(1, [joint], name="bedding")
        gmsh.model.addPhysicalGroup(2, [surface], name="rock")
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def test_a_users_gmsh_mesh_carries_its_supports_and_joints(tmp_path):
    from fdem.mesh.mesh import Mesh
    from fdem.mesh.topology import build_topology
    from fdem.scene.build import build_simulation, scene_mesh

    _user_mesh(tmp_path / "user.msh")
    text = SMALL_SLOPE.split("[[joints]]")[0].split("[slope]")[0] + "[rock]" + SMALL_SLOPE.split("[rock]")[1]
    text = text.replace('left = "fix-x"\nright = "fix-x"', 'sides = "fix-x"').replace('bottom = "fixed"',
                                                                                      'base = "fixed"')
    text = text.replace('[scene]\nname = "my-slope"\nsize = 2.0',
                        '[scene]\nname = "my-slope"\nsize = 1.5\nmesh = "user.msh"')
    text += '\n[mesh]\njoints = { bedding = 1 }\ntoe = [10.0, 3.0]\n'
    scene = read_scene(_write(tmp_path, text))
    _, mesh = scene_mesh(scene)
    raw = Mesh.load(tmp_path / "user.msh")
    bedding_edges = int((raw.line_group == raw.group_names.index("bedding")).sum())
    topo = build_topology(mesh)
    assert bedding_edges > 0 and int((topo.crack_tag == 1).sum()) == bedding_edges
    sim, cracks, start = build_simulation(scene, topo, None, pictures=False, progress=False)
    base, sides = topo.nodes_in_group("base"), topo.nodes_in_group("sides")
    x0 = topo.x0
    assert np.allclose(x0[base, 1], 0.0) and np.all((np.isclose(x0[sides, 0], 0) | np.isclose(x0[sides, 0], 24)))
    # the static start holds the slope: a few hundred damped steps move nothing measurable
    from fdem.solve.damping import Damping

    sim.run(n_steps=300, damping=Damping.quasi_static())
    assert np.abs(sim.state.x - x0).max() < 1e-3


def test_the_command_line_runs_a_scene_on_a_users_mesh(tmp_path):
    """``--mesh`` replaces the outline and joints: without a joint mapping the scene's joint
    tags are refused (exit 2, naming the tag); with ``[mesh] joints`` and the mesh's group names
    in ``[supports]`` it runs, on the mesh's own triangles."""
    from fdem.mesh.mesh import Mesh

    _user_mesh(tmp_path / "user.msh")
    opts = ["--out", str(tmp_path / "out"), "--max-time", "0.01", "--no-pictures", "--quiet", "--threads", "1"]
    refused = fdem("run", str(_write(tmp_path, SMALL_SLOPE)), "--mesh", str(tmp_path / "user.msh"), *opts)
    assert refused.returncode == 2 and "[cracks.1] names a tag no joint set has" in refused.stderr
    text = (SMALL_SLOPE.replace('left = "fix-x"\nright = "fix-x"', 'sides = "fix-x"')
            .replace('bottom = "fixed"', 'base = "fixed"') + '\n[mesh]\njoints = { bedding = 1 }\ntoe = [10.0, 3.0]\n')
    run = fdem("run", str(_write(tmp_path, text, "mapped.toml")), "--mesh", str(tmp_path / "user.msh"), *opts)
    assert run.returncode == 0, run.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["n_triangles"] == Mesh.load(tmp_path / "user.msh").n_triangles
    assert summary["toe"] == [10.0, 3.0]


# ----------------------------------------------------------------------------- helpers
def _write(folder: Path, text: str, name: str = "my_slope.toml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def _rawable(scene: dict) -> dict:
    """A checked scene as a TOML file holds it (tags as strings, ``None`` left out)."""
    out = {}
    for k, v in scene.items():
        if isinstance(v, dict):
            out[k] = {str(t): ({a: b for a, b in x.items() if b is not None} if isinstance(x, dict) else x)
                      for t, x in v.items() if x is not None}
        elif isinstance(v, list):
            out[k] = [{a: b for a, b in x.items() if b is not None} for x in v]
    return {k: v for k, v in out.items() if v}



def test_the_guide_shows_the_schema_and_the_example_as_they_are():
    """``docs/scenes.md`` holds the key tables generated from the schema and the example file
    verbatim, so the guide cannot drift from the code."""
    from fdem.scene.schema import schema_markdown

    root = Path(__file__).resolve().parents[2]
    doc = (root / "docs" / "scenes.md").read_text()
    table = doc.split("<!-- schema:start -->\n")[1].split("<!-- schema:end -->")[0]
    assert table == schema_markdown()
    example = (root / "cases" / "scenes" / "jointed_slope.toml").read_text()
    assert f"```toml\n{example}```" in doc
    read_scene(root / "cases" / "scenes" / "jointed_slope.toml")  # and the example checks


# ----------------------------------------------------------------------------- ensembles of a scene
ENSEMBLE = '''
[ensemble]
n = 4
seed = 3
fos = [0.5, 3.0, 0.2]

[ensemble.vary]
"cracks.1.phi" = ["normal", 30.0, 4.0, 20.0, 40.0]
"joints.1.through_toe" = ["uniform", 0.0, 0.5]
"heterogeneity.seed" = ["seed"]
'''


def test_an_ensemble_varies_the_scene_keys_it_names(tmp_path):
    """``[ensemble.vary]`` paths reach the scene's keys: every realization's scene holds its
    sampled values; sampling is reproducible; bad paths and distributions are refused naming
    them; and the factor of safety of a realization rises with its joints' friction."""
    from fdem.scene.ensemble import scene_ensemble
    from fdem.workflow.ensembles import realize

    weak = SMALL_SLOPE.replace("f_t = 5e4\nc = 1e5", "f_t = 5e3\nc = 1e4")  # joints that can fail
    path = _write(tmp_path, weak + ENSEMBLE)
    ens = scene_ensemble(path)
    rows = ens.sample()
    assert ens.n == 4 and rows == scene_ensemble(path).sample()
    assert set(rows[0]) == {"cracks_1_phi", "joints_1_through_toe", "heterogeneity_seed"}
    for row in rows:
        s = ens.scene.scene(**row)
        assert s["cracks"][1]["phi"] == row["cracks_1_phi"] and 20.0 <= row["cracks_1_phi"] <= 40.0
        assert s["joints"][0]["through_toe"] == row["joints_1_through_toe"]
        assert s["heterogeneity"]["seed"] == row["heterogeneity_seed"]
    for bad, words in ((('"cracks.3.phi"', '"cracks.1.phi"'), "no [cracks.3]"),
                       (('"joints.2.through_toe"', '"joints.1.through_toe"'), "1 [[joints]] table"),
                       (('"rock.colour"', '"cracks.1.phi"'), "no key 'colour'"),
                       (('["seed"]', '["normal", 30.0, 4.0, 20.0, 40.0]'), "whole-number keys")):
        text = SMALL_SLOPE + ENSEMBLE.replace(bad[1], bad[0], 1)
        with pytest.raises(SceneError, match=re.escape(words)):
            scene_ensemble(_write(tmp_path, text, "bad.toml"))
    # a workflow after each search, whose workflow is the search alone, is refused before any trial
    alone = (SMALL_SLOPE + '[workflow]\nreduction = "none"\nfos = [0.5, 3.0, 0.2]\n'
             + ENSEMBLE.replace("[ensemble]\n", "[ensemble]\nrunout = true\n", 1))
    with pytest.raises(SceneError, match='reduction = "none" has none'):
        scene_ensemble(_write(tmp_path, alone, "alone.toml"))
    # a realization's capped trials are judged as the scene's fdem run judges them: followed to
    # rest unless the scene says cap, and the rule is part of the description (never mixed)
    capped = scene_ensemble(_write(tmp_path, weak + '[workflow]\ntrial_end = "cap"\n' + ENSEMBLE, "cap.toml"))
    assert ens.trial_rule == "rest" and ens.describe()["trial_end"] == "rest"
    assert capped.trial_rule == "cap" and "trial_end" not in capped.describe()
    assert capped.fingerprint() != ens.fingerprint()
    low = realize(ens, 0, {"cracks_1_phi": 20.0, "joints_1_through_toe": 0.0, "heterogeneity_seed": 1})
    high = realize(ens, 1, {"cracks_1_phi": 40.0, "joints_1_through_toe": 0.0, "heterogeneity_seed": 1})
    assert low["status"] == high["status"] == "ok", (low["error"], high["error"])
    assert high["fos_lower"] >= low["fos_lower"] and high["fos"] > low["fos"]


def test_an_ensembles_search_judges_its_trials_by_the_scenes_rule(tmp_path, monkeypatch):
    """Each realization's search runs the trial ``fdem run`` runs for the scene's own search
    (:func:`fdem.workflow.slope.trial_stage`): a raised ``equilibrium_ratio`` and a hold in
    ``[workflow]`` reach it, and they are part of the ensemble's description (its table is not
    one of the default rule's); a scene on the default rule describes itself as before."""
    from fdem.scene.ensemble import scene_ensemble
    from fdem.workflow import fos as fos_module
    from fdem.workflow.ensembles import realize
    from fdem.workflow.slope import trial_stage
    from fdem.workflow.stages import response_time

    ruled = SMALL_SLOPE + '[workflow]\nequilibrium_ratio = 2e-4\nequilibrium_hold = 0.5\nstep_time = 0.4\n'
    plain, judged = scene_ensemble(_write(tmp_path, SMALL_SLOPE + ENSEMBLE)), scene_ensemble(
        _write(tmp_path, ruled + ENSEMBLE, "ruled.toml"))
    assert "search" not in plain.describe()
    assert judged.describe()["search"] == {"equilibrium_ratio": 2e-4, "equilibrium_hold": 0.5, "step_time": 0.4,
                                           "fail_displacement": None}
    assert judged.fingerprint() != plain.fingerprint()
    seen = {}

    def search(sim, lower, upper, tol, trial=None, **_):
        seen["trial"], seen["T"] = trial, response_time(sim.model)
        seen["expected"] = trial_stage(sim, judged.search)
        raise RuntimeError("the trial is all this test needs")

    monkeypatch.setattr(fos_module, "factor_of_safety", search)
    row = realize(judged, 0, judged.sample()[0])
    assert "the trial is all this test needs" in row["error"]
    trial = seen["trial"]
    assert trial.converge.unbalanced_ratio == 2e-4 and trial.max_time == 0.4
    assert trial.converge.hold_for == pytest.approx(0.5 * seen["T"])
    assert (trial.converge, trial.max_time, trial.fail) == (seen["expected"].converge, seen["expected"].max_time,
                                                            seen["expected"].fail)


# ----------------------------------------------------------------------------- gravity increase
def test_gravity_increase_matches_strength_reduction_for_frictionless_joints(tmp_path):
    """With no friction anywhere (phi = 0 on every crack set), the stresses grow as gravity
    ``k g`` and the strengths (c, f_t) do not, so the critical gravity factor equals the
    strength-reduction factor of safety (limit equilibrium scales linearly), provided the
    elements are ductile enough for limit equilibrium to hold: strength reduction divides c and
    f_t but not the fracture energies, so it makes the elements more ductile as it goes, and
    with the scene's brittle joints (G_II = 500 J/m^2) the two differ (F 3.81-3.97 against
    k 2.09-2.25); with G_II = 5e4 they meet (F 4.44-4.59, k 4.28-4.44). The two scene
    workflows' bisection brackets must overlap; then the gravity run loads the slope at the
    bracket's failing end."""
    from fdem.cases import scene as runner

    text = (SMALL_SLOPE.replace("phi = 35.0", "phi = 0.0").replace("phi = 30.0\nG_I = 50.0", "phi = 0.0\nG_I = 50.0")
            .replace("c = 1e5", "c = 1.5e5").replace("G_I = 50.0\nG_II = 500.0", "G_I = 5e3\nG_II = 5e4"))
    opts = ["--no-pictures", "--quiet", "--threads", "1"]
    strength = runner.main([str(_write(tmp_path, text + '\n[workflow]\nfos = [1.0, 6.0, 0.25]\n', "s.toml")),
                            "--out", str(tmp_path / "s"), "--max-time", "1.5"] + opts)
    gravity = runner.main([str(_write(tmp_path, text + '\n[workflow]\nkind = "gravity-increase"\n'
                                                       'fos = [1.0, 6.0, 0.25]\n', "g.toml")),
                           "--out", str(tmp_path / "g")] + opts)
    fs, kg = strength["workflow"]["fos"]["bracket"], gravity["workflow"]["fos"]["bracket"]
    assert fs[1] - fs[0] <= 0.25 and kg[1] - kg[0] <= 0.25
    assert kg[0] <= fs[1] and fs[0] <= kg[1], (fs, kg)  # the brackets overlap
    stages = [s["name"] for s in gravity["workflow"]["stages"]]
    assert stages == ["equilibrium", "onset", "runout"] and gravity["failed_at_factor"] == kg[1]
    # loaded at the bracket's failing end the slope does not settle (the onset fails or is capped
    # still moving, as the search's failing trial was) and moves more than 1 % of its height (13 m)
    assert gravity["workflow"]["stages"][1]["reason"] in ("failed", "capped")
    assert gravity["runout"]["max_displacement_m"] >= 0.01 * 13.0


@pytest.mark.parametrize("reduction, tensile", [("rate", "kept"), ("steps", "reduced")])
def test_four_slopes_paper_schedule_keeps_the_tensile_strength(tmp_path, monkeypatch, reduction, tensile):
    """The paper reduces the 'cohesive and frictional strength': its schedule (--reduction rate)
    leaves f_t alone, the project's damped steps divide it by F too."""
    from fdem.cases import four_slopes

    built = {}
    make = four_slopes.simulation

    def keep(*args, **kwargs):
        built["sim"], built["cracks"] = make(*args, **kwargs)
        return built["sim"], built["cracks"]

    monkeypatch.setattr(four_slopes, "simulation", keep)
    # the rate stage begins after equilibrium (about 0.3 s here)
    summary = four_slopes.main(["--spacing", "coarse", "--size", "2.5", "--reduction", reduction,
                                "--max-time", "0.5" if reduction == "rate" else "0.001",
                                "--no-pictures", "--quiet", "--out", str(tmp_path / reduction)])
    assert summary["tensile"] == tensile
    # the run keeps the settings it began with, and its scene file says the same
    saved = json.loads((tmp_path / reduction / "run.json").read_text())["argv"]
    assert saved[saved.index("--tensile") + 1] == tensile and "--runout-dt-fraction" in saved
    four_slopes.main(["--spacing", "coarse", "--size", "2.5", "--reduction", reduction,
                      "--write-scene", str(tmp_path / f"{reduction}.toml")])
    assert read_scene(tmp_path / f"{reduction}.toml")["workflow"]["reduce_tensile"] is (tensile == "reduced")
    cracks = built["cracks"]
    F = cracks.interfaces.reduction
    f_t, c = cracks._element_strengths(F)[:2]
    base_ft, base_c = cracks._element_strengths(1.0)[:2]
    if reduction == "rate":
        assert F > 1.0  # the strength fell during the run
        np.testing.assert_array_equal(f_t, base_ft)
        np.testing.assert_allclose(c, base_c / F)
    else:
        assert cracks.interfaces.reduce_tensile
        np.testing.assert_allclose(cracks._element_strengths(1.25)[0], base_ft / 1.25)
