"""Your own slope from a scene file: outline or Gmsh mesh, joints, rock, crack elements, workflow.

    fdem run my_slope.toml                        # = fdem run scene my_slope.toml
    fdem run my_slope.toml --size 0.5 --out runs/my_slope_fine
    fdem run my_slope.toml --mesh my_slope.msh    # your own mesh: supports and joints by group name
    fdem run quick-start --write-scene demo.toml  # a built-in case as a scene file to start from
    fdem run my_slope.toml --write-scene full.toml   # the scene with every default written out

The file is checked whole before any meshing (unknown keys, ranges, what each outline and
joint kind needs, the crack laws' snap-back, the workflow); every error names the file, the
section and the key. The run is the slope workflow of the built-in cases (static start,
equilibrium, strength reduction to failure, runout to rest; ``[workflow]``) and writes the same
outputs (``summary.json``, ``history.csv`` with the monitors, ParaView series, pictures), plus
``scene.toml``: the scene as run, every default filled in, which ``--resume`` reads back.
``docs/scenes.md`` is the guide and lists every key.
"""
from __future__ import annotations

from fdem.io.messages import say, warn

import time
import warnings
from pathlib import Path

from fdem.cases.common import (_option_names, add_resume_options, cap_simulated_time, case_parser, check_common,
                               check_mesh_size, finish_run, open_run, prepare_run, report_runout_cost, save_final_state, set_threads,
                               start_journal, stop_cleanly_on_signals, threads_for_mesh, time_capped,
                               use_density_scaling, write_report, failing_factor_words)
from fdem.io.jsonable import write_json

__all__ = ["NAME", "SCENE_COPY", "main", "run_scene"]

NAME = "scene"
SCENE_COPY = "scene.toml"
"""The scene as run, written into the run's folder (``--resume`` reads it back)."""

_SCENE_OVERRIDES = {"--dt-fraction": "dt_fraction", "--density-scaling": "density_scaling", "--max-time": "max_time"}


def _parser():
    parser = case_parser(__doc__, name=NAME, out="runs/<scene name>", size=None,
                         size_help="element size [m] (default: the scene's [scene] size)")
    parser.add_argument("scene", type=Path, nargs="?", default=None, help="the scene file (.toml)")
    parser.add_argument("--mesh", type=Path, default=None,
                        help="a Gmsh .msh with named physical groups (or a mesh saved as .npz), instead of the "
                             "scene's [slope] and [[joints]]; the toe and the joint groups joint_set_N come from "
                             "what it replaces unless [mesh] gives them")
    parser.add_argument("--write-scene", type=Path, default=None, metavar="FILE",
                        help="write the checked scene, every default filled in, to FILE and stop")
    add_resume_options(parser)
    return parser


def _read(parser, args) -> dict:
    """The scene of ``args.scene`` with ``--size`` and ``--mesh`` applied, checked whole."""
    import tomllib

    from fdem.scene.schema import SceneError, check_scene

    path = args.scene
    if path is None:
        parser.error("give the scene file: fdem run my_slope.toml (or fdem run scene my_slope.toml)")
    if not path.is_file():
        parser.error(f"no scene file {path}")
    try:
        raw = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        parser.error(f"{path}: not valid TOML: {err}")
    if not isinstance(raw.get("scene", {}), dict):
        parser.error(f"{path}: scene must be a table [scene]")
    if args.size is not None:
        raw.setdefault("scene", {})["size"] = args.size
    try:
        if args.mesh is not None:
            _use_mesh(raw, args.mesh, path)
        return check_scene(raw, path)
    except SceneError as err:
        parser.error(str(err))


def _use_mesh(raw: dict, mesh: Path, path: Path) -> None:
    """``--mesh``: the mesh replaces ``[slope]`` and ``[[joints]]``. What the mesh cannot say
    comes from what it replaces: the toe from the outline, and the mesh's joint groups
    ``joint_set_1``, ``joint_set_2``, ... (the names of fdem's own meshes, ``Mesh.save``) as the
    joint sets in their order, unless ``[mesh]`` gives them (a mesh without such groups needs
    ``[mesh] joints``, and the check says so before any work). So a scene meshed on one machine
    (``Mesh.save("slope.npz")``) runs on another with ``--mesh slope.npz`` and no Gmsh."""
    from fdem.mesh.mesh import JOINT_GROUP_PREFIX, Mesh
    from fdem.scene.objects import geometry
    from fdem.scene.schema import check_scene
    from fdem.geometry.polygons import slope_toe

    mesh_keys = raw.setdefault("mesh", {})
    if "slope" in raw and "toe" not in mesh_keys and "toe" not in raw.get("outputs", {}):
        outline = check_scene({k: v for k, v in raw.items() if k != "mesh"}, path)
        mesh_keys["toe"] = [float(c) for c in slope_toe(geometry(outline).bodies[0])]
    if raw.get("joints") and "joints" not in mesh_keys:
        try:  # cheap for .npz; a mesh that cannot be read is refused by the checks that follow
            groups = set(Mesh.load(mesh).group_names)
        except Exception:
            groups = set()
        found = {f"{JOINT_GROUP_PREFIX}{i}": i for i in range(1, len(raw["joints"]) + 1)
                 if f"{JOINT_GROUP_PREFIX}{i}" in groups}
        if found:
            mesh_keys["joints"] = found
    if not mesh_keys:
        raw.pop("mesh")
    dropped = [s for s in ("slope", "joints") if raw.pop(s, None)]
    if dropped:
        say(f"--mesh {mesh} replaces the scene's " + " and ".join(f"[{d}]" for d in dropped)
            + (f" (toe {tuple(mesh_keys['toe'])} from the outline)" if "toe" in mesh_keys else ""))
    raw.setdefault("scene", {})["mesh"] = str(mesh.resolve())


def main(argv=None) -> dict:
    import sys

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    if "--resume" in _option_names(argv):  # the run's own scene.toml, not the one named again
        argv = [a for i, a in enumerate(argv) if not (a.endswith(".toml") and not a.startswith("-")
                                                      and (i == 0 or argv[i - 1] != "--write-scene"))]
    args = parser.parse_args(argv)
    if args.resume is None:
        scene = _read(parser, args)
        if args.write_scene is not None:
            return _write_full_scene(parser, scene, args.write_scene, args.scene)
        if "--out" not in _option_names(argv):
            args.out = Path("runs") / scene["scene"]["name"]
    args = prepare_run(parser, args, argv, NAME, open_now=False)
    if args.resume is not None:
        scene = _read(parser, args)
    return run_scene(parser, args, scene)


def _write_full_scene(parser, scene: dict, path: Path, source: Path) -> dict:
    from fdem.scene.write import write_scene

    try:
        write_scene(path, scene, title=f"{scene['scene']['name']}: the scene of {source}, every default written out")
    except OSError as err:
        parser.error(f"--write-scene {path}: {err.strerror or err}")
    print(f"wrote {path}")
    return {"case": NAME, "outcome": "scene written", "scene_file": str(path)}


def _effective_options(args, scene: dict) -> None:
    """The scene's ``dt_fraction``, ``density_scaling`` and ``max_time`` unless the command
    line gave them (a command-line option overrides the file)."""
    record = getattr(args, "run_record", {})
    given = set(_option_names(list(record.get("argv", [])) + list(record.get("resumed_with", []))))
    w = scene["workflow"]
    for option, key in _SCENE_OVERRIDES.items():
        if option not in given:
            setattr(args, key, w[key])


def run_scene(parser, args, scene: dict) -> dict:
    """Mesh, build and run the checked ``scene`` with the case options ``args`` (the folder
    not yet opened: options are checked first); returns the summary."""
    from fdem.mesh.topology import build_topology
    from fdem.results.report import RunReport
    from fdem.scene.build import build_simulation, scene_mesh, scene_toe
    from fdem.scene.objects import geometry as scene_geometry
    from fdem.scene.objects import workflow as scene_workflow
    from fdem.scene.schema import SceneError
    from fdem.scene.write import write_scene
    from fdem.workflow.slope import factor_of_safety_figures, run_slope_workflow

    wall = time.perf_counter()
    _effective_options(args, scene)
    check_common(parser, args)
    set_threads(args.threads)
    workflow = scene_workflow(scene)
    if workflow.runout_step == "measured" and getattr(args, "backend", "cpu") != "cpu":
        parser.error(f"[workflow] runout_step = 'measured' probes the model on the host, and --backend {args.backend} "
                     "steps on the GPU: run on the CPU, or set runout_step = 'bound'")
    sc = scene["scene"]
    if sc["mesh"] is None:
        check_mesh_size(parser, scene_geometry(scene), sc["size"])
    out = Path(args.out)
    if args.resume is None:  # the run re-reads its own copy: record it, not the user's file
        kept = [a for i, a in enumerate(args.run_record["argv"])
                if a != str(args.scene) and a not in ("--size", "--mesh") and not a.startswith(("--size=", "--mesh="))
                and not (i and args.run_record["argv"][i - 1] in ("--size", "--mesh"))]
        args.run_record["argv"] = [str((out / SCENE_COPY).resolve())] + kept
    open_run(parser, args, NAME)
    if args.resume is None:
        write_scene(out / SCENE_COPY, scene, title=f"{sc['name']}: the scene as run (from {args.scene})")

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            geo, mesh = scene_mesh(scene)
        except SceneError as err:
            parser.error(str(err))
        except ValueError as err:  # the mesher's own refusal (a size too large for the outline, ...)
            parser.error(f"{args.scene}: {err}")
    for w in caught:
        warn(str(w.message))
    topo = build_topology(mesh)
    try:
        sim, cracks, start = build_simulation(scene, topo, out, pictures=not args.no_pictures,
                                              progress=not args.quiet, where=str(args.scene))
    except SceneError as err:
        parser.error(str(err))
    stop_cleanly_on_signals()  # after meshing: Gmsh installs its own handlers
    toe_x, toe_y = scene_toe(scene, geo)
    report = RunReport(sim, toe_x=toe_x, floor_y=toe_y)
    cap_simulated_time(sim, args.max_time)
    use_density_scaling(sim, args.density_scaling)
    threads = threads_for_mesh(args.threads, topo.n_triangles)
    say(f"{sc['name']}: {topo.n_triangles} triangles, {topo.n_cracks} crack elements "
          f"({int((topo.crack_tag > 0).sum())} on joints), time step {sim.dt:.3g} s, {threads} thread(s)")
    cost = report_runout_cost(parser, sim, args, workflow)
    journal = start_journal(sim, args)
    try:
        result = run_slope_workflow(sim, workflow, out_dir=out, journal=journal)
        save_final_state(sim, out, result["outcome"])
    finally:
        sim.close()
    extra = {"case": NAME, "scene": sc["name"], "scene_file": str(out / SCENE_COPY), "size_m": sc["size"],
             "n_triangles": topo.n_triangles, "threads": threads, "toe": [toe_x, toe_y],
             "time_capped": time_capped(sim), "geostatic_seconds": None if start is None else start.seconds,
             "workflow": result, "failed_at_factor": result["failed_at_factor"], "outcome": result["outcome"],
             "ending": result.get("ending"), "checkpoints": journal.writes, "cost_estimate": cost,
             **factor_of_safety_figures(result)}
    summary = write_report(report, out, extra, pictures_on=scene["outputs"]["pictures"] and not args.no_pictures)
    if summary["outcome"] != "write_error":
        summary["wall_seconds"] = time.perf_counter() - wall
        write_json(out / "summary.json", summary)
    finish_run(out, summary)
    if summary["outcome"] != "write_error":
        lo, hi = summary.get("fos_bracket") or (None, None)
        what = "critical gravity factor" if workflow.trigger == "gravity" else "factor of safety"
        print(f"outcome {summary['outcome']}"
              + (f", {what} between {lo:.3f} and {hi:.3f}" if lo is not None and hi is not None else
                 f", stable up to F = {lo:.3f}" if lo is not None else "")
              + failing_factor_words(summary)
              + f"; {summary['cracks']['broken']} crack elements broken; {summary['wall_seconds']:.0f} s")
        say(f"wrote {out / 'summary.json'}, {out / 'slope.pvd'}")
    return summary
