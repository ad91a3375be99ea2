"""Publish one four-slope run into ``docs/cases/rest/``: its summary, its pictures, and the figures
that ``docs/cases.md`` section A sets beside the paper, as a Markdown table.

A run to rest (or one still going, whose ``summary.json`` says ``interrupted``) is read from its
folder; ``summary.json`` is copied to ``docs/cases/rest/<name>.json`` and ``mechanism.png``
(displacement with activated and broken joints at mid-failure and at the end) and
``kinetic_energy.png`` to ``docs/cases/rest/<name>_<picture>.png``. The table printed holds the
run's own figures only (what the paper says goes in by hand, beside them), every figure read from
the summary, so that a row is never typed twice:

    python cases/benchmarks/publish_four_slopes.py runs/rest2/low_fine_1.0_crest60_toe90
    python cases/benchmarks/publish_four_slopes.py runs/rate/high_fine_0.5_band5 --name high_fine_0.5_band5_rate
    python cases/benchmarks/publish_four_slopes.py --overview     # every published run in one table

Beside the summary goes ``<name>_run.json``: the run's ``run.json`` (its command, and the commits
that began and carried it on) with the contact law its checkpoint was written under.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import meshio
import numpy as np

from fdem.io.jsonable import write_json
from fdem.results.analysis import boundary_motion, displaced_areas
from fdem.workflow.slope import steps_bracket

sys.path.insert(0, str(Path(__file__).resolve().parent))
from convergence_four_slopes import STOPPED  # noqa: E402  (one list of the outcomes of a run stopped part-way)

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "cases" / "rest"
PICTURES = ("mechanism", "kinetic_energy")


def default_name(summary: dict) -> str:
    """``<scene>_<size>[_crest<C>][_toe<T>][_band<B>][_offset<f>]`` from the summary's own figures."""
    ext = summary.get("extents_m") or {}
    name = f"{summary['scene']}_{summary['size_m']}"  # 1.0, 0.5: as the run folders spell sizes
    for key, tag in (("crest_length", "crest"), ("toe_length", "toe"), ("boundary_band", "band")):
        if ext.get(key):
            name += f"_{tag}{ext[key]:g}"
    if summary.get("joint_offset") not in (None, 0.0) or summary.get("scene", "").endswith("coarse"):
        name += f"_offset{summary.get('joint_offset') or 0:g}"
    return name


def locked_now(run: Path, summary: dict) -> dict | None:
    """The locked part of the run's failed mass by this code's rule
    (:meth:`fdem.results.motion.MotionRecord.locked`), from the motion record and positions of
    the state the summary was written on (``final_state.npz``, or ``checkpoint.npz`` of a run
    stopped part-way) and the run's mesh (``<scene>.npz``, the form of the scene name before
    the size); ``None`` when one of them is missing. A run carried on by an older commit wrote
    its summary with that commit's rule: the rule is one source, applied again here."""
    from fdem.mesh.mesh import Mesh
    from fdem.mesh.topology import build_topology
    from fdem.results.motion import MotionRecord
    from fdem.solve.checkpoint import read_checkpoint

    state_file = run / ("checkpoint.npz" if summary.get("outcome") in STOPPED else "final_state.npz")
    meshes = sorted(run.glob(f"{summary.get('scene', '')}.npz"))
    if not state_file.is_file() or not meshes:
        return None
    state = read_checkpoint(state_file)["state"]
    if float(state["time"]) != float(summary.get("simulated_time_s", state["time"])):
        return None  # a checkpoint written after the summary (a run carried on since)
    records = state.get("monitor_records") or {}
    if "failed_d90" not in records:
        return None
    topology = build_topology(Mesh.load(meshes[0]))
    record = MotionRecord(topology)
    record.load_state_dict(records["failed_d90"])
    return {k: v for k, v in record.locked(np.asarray(state["x"])).items() if k != "mask"}


def redraw_mechanism(run: Path, summary: dict, path: Path) -> Path | None:
    """``mechanism.png`` of the run drawn again by this code (its locked part by this code's rule,
    :func:`locked_now`), from the run's mesh and the state its summary was written on; ``None``
    when either is missing. The run's own picture outlines the locked part by the rule of the
    commit that drew it."""
    from fdem.cases import four_slopes
    from fdem.mesh.mesh import Mesh
    from fdem.mesh.topology import build_topology
    from fdem.results.report import RunReport
    from fdem.solve.checkpoint import load_checkpoint, read_checkpoint

    state_file = run / ("checkpoint.npz" if summary.get("outcome") in STOPPED else "final_state.npz")
    meshes = sorted(run.glob(f"{summary.get('scene', '')}.npz"))
    toe = summary.get("toe")
    if not state_file.is_file() or not meshes or not toe:
        return None
    if float(read_checkpoint(state_file)["state"]["time"]) != float(summary.get("simulated_time_s", -1.0)):
        return None
    sim, _ = four_slopes.simulation(None, build_topology(Mesh.load(meshes[0])), None, pictures=False, progress=False)
    report = RunReport(sim, toe_x=float(toe[0]), floor_y=float(toe[1]))  # its motion record, then the saved one
    load_checkpoint(sim, state_file)
    try:
        return report.mechanism_picture(path)
    finally:
        sim.close()


def _mode(d: dict) -> str:
    m = d.get("broken_by_mode") or d.get("by_mode") or {}
    return f"I {m.get('I', 0)} / II {m.get('II', 0)} / mixed {m.get('mixed', 0)}"


def last_frame_figures(run: Path) -> dict | None:
    """``boundaries`` (:func:`fdem.results.analysis.boundary_motion`) and ``areas``
    (:func:`fdem.results.analysis.displaced_areas`) of the run's last triangle frame
    (``interrupted_state.vtu`` of a stopped run, else the last of ``slope.pvd``), for the
    summaries written before the summary carried them; the frames hold the positions and the
    displacement, so the reference positions are their difference (float32: 1e-5 m at the
    hundreds of metres of these models)."""
    from types import SimpleNamespace

    from fdem.io.vtk import read_pvd
    from fdem.mesh.triangles import triangle_areas

    try:
        stopped = ending(json.loads((run / "summary.json").read_text()))[0]
    except (OSError, ValueError):
        stopped = False
    if stopped and (run / "interrupted_state.vtu").exists():
        frame = run / "interrupted_state.vtu"  # the state at the stop (a runout's: a run stopped in a search has none)
    elif (run / "slope.pvd").exists() and read_pvd(run / "slope.pvd"):
        frame = read_pvd(run / "slope.pvd")[-1][1]  # the series' last frame, in its own time order
    else:
        return None
    m = meshio.read(frame)
    x = np.asarray(m.points[:, :2], np.float64)
    x0 = x - np.asarray(m.point_data["displacement"][:, :2], np.float64)
    tri = np.asarray(m.cells_dict["triangle"])
    mesh = SimpleNamespace(x0=x0, triangles=tri, triangle_area0=triangle_areas(x0, tri), n_nodes=len(x0))
    return {"boundaries": boundary_motion(x0, x), "areas": displaced_areas(mesh, x)}


def ending(summary: dict) -> tuple[bool, bool, dict]:
    """``(stopped, at_rest, last stage)`` of a run's summary: stopped before its end (it
    resumes), or at rest (its last stage a runout that converged)."""
    stages = (summary.get("workflow") or {}).get("stages") or []
    last = stages[-1] if stages else {}
    stopped = summary.get("outcome") in STOPPED
    return stopped, (not stopped and last.get("name", "").startswith("runout") and last.get("reason") == "converged"), last


EARLIER_LAW = "the lowest friction of the six faces of the two triangles (the law before 2026-11-25)"


def contact_law_of(run: Path) -> str | None:
    """The contact law the run's checkpoint was written under (``checkpoint.npz``, else
    ``final_state.npz``): checkpoints of the earlier law name none (:data:`EARLIER_LAW`)."""
    from fdem.solve.checkpoint import read_checkpoint

    for name in ("checkpoint.npz", "final_state.npz"):
        if (run / name).exists():
            return (read_checkpoint(run / name).get("model") or {}).get("contact_law") or EARLIER_LAW
    return None


def code_of(run: Path, law: str | None) -> str:
    """The commit that began the run and those that carried it on (its ``run.json``), and the
    contact law of its checkpoint; runs begun before run.json recorded commits say so."""
    try:
        record = json.loads((run / "run.json").read_text())
    except (OSError, ValueError):
        record = {}
    sources = [record.get("source")] + list(record.get("resumed_sources", []))

    def one(src):
        if not src:
            return "commit not recorded"
        commit = src["commit"][:7] if src.get("commit") else "an installed package"
        return commit + (" with local changes" if src.get("modified") else "")

    names = list(dict.fromkeys(one(src) for src in sources))
    return ", then ".join(names) + f"; contact: {law or '-'}"


def overview(folder: Path = DOCS) -> list[dict]:
    """One row per published run (``docs/cases/rest/<name>.json``), read from its summary and
    ``<name>_run.json``: where each scene stands, in one table."""
    rows = []
    for path in sorted(folder.glob("*.json")):
        if path.name.endswith("_run.json"):
            continue
        s = json.loads(path.read_text())
        sidecar = path.with_name(path.stem + "_run.json")
        side = json.loads(sidecar.read_text()) if sidecar.exists() else {}
        law = side.get("contact_law")
        areas = s.get("displaced_area_m2") or (side.get("last_frame") or {}).get("areas") or {}
        wf = s.get("workflow") or {}
        stages = wf.get("stages") or []
        run, ke, tags = s.get("runout") or {}, s.get("kinetic_energy") or {}, s.get("cracks_by_tag") or {}
        stopped, at_rest, last = ending(s)
        if stopped:
            state = f"stopped at t = {s.get('simulated_time_s', 0):.3g} s, moving"
        elif at_rest:
            state = f"at rest, t = {last.get('t_end', 0):.3g} s"
        else:
            state = f"{last.get('reason')} at t = {last.get('t_end', 0):.3g} s"
        rate = any(st["name"].startswith("reduction_rate") for st in stages)
        fos = (wf.get("fos") or {}).get("fos")
        ext = s.get("extents_m") or {}
        modes = (s.get("cracks") or {}).get("by_mode") or {}
        walls = sum(st.get("wall_seconds", 0.0) for st in stages) + ((wf.get("fos") or {}).get("wall_seconds") or 0.0)
        argv = list(side.get("argv") or [])
        if argv and ext:  # begun before run.json pinned the extents: add each one its argv lacks
            argv += [a for k, v in ext.items() if "--" + k.replace("_", "-") not in argv
                     for a in ("--" + k.replace("_", "-"), f"{v or 0:g}")]
        rows.append({
            "name": path.stem, "scene": f"{s.get('scene')} ({s.get('joint_offset', 0):g})", "size": s.get("size_m"),
            "triangles": s.get("n_triangles"),
            "extents": f"{ext.get('crest_length', 0):g} / {ext.get('toe_length', 0):g}"
                       + (f" / {ext['boundary_band']:g}" if ext.get("boundary_band") else ""),
            "schedule": (f"rate to F = {wf.get('final_reduction', 0):.3g}" if rate
                         else f"steps, failed at F = {wf.get('failed_at_factor') or 0:.3g}")
                        + (f"; FoS {fos:.3f}" if fos is not None else ""),
            "state": state, "max_displacement": run.get("max_displacement_m"), "runout": run.get("runout_distance_m"),
            "area": run.get("displaced_area_m2"), "area_1m": areas.get("1"), "ke_peak": ke.get("peak_J_per_m"),
            "broken": f"{(tags.get('rock') or {}).get('broken', 0):,} / {(tags.get('joints') or {}).get('broken', 0):,}",
            "law": "faces in touch" if law and law != EARLIER_LAW else ("lowest of six" if law else "-"),
            "released": ke.get("released_gravity_J_per_m"),
            "modes": " / ".join(f"{modes.get(m, 0):,}" for m in ("I", "II", "mixed")),
            "steps": s.get("steps"), "wall": f"{walls:,.0f} s" + (" (finished stages)" if stopped else ""),
            "command": "fdem run four-slopes " + " ".join(
                a for i, a in enumerate(argv) if a not in ("--quiet", "--yes", "--out") and not (i and argv[i - 1] == "--out")),
            "commit": ((side.get("source") or {}).get("commit") or "")[:7],
        })
    return rows


def print_overview(rows: list[dict]) -> None:
    """The table, then the command of each row (its options as ``run.json`` pinned them; the
    output folder left out) and the commit it ran at."""
    print("| run (docs/cases/rest) | scene (joint offset) | size | triangles | crest / floor / band [m] | schedule | "
          "state | max displacement | runout | area moved > 0.1 m / > 1 m | KE peak | gravity released | "
          "broken rock / joints | broken I / II / mixed | steps | wall (1 CPU thread) | contact |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        released = "-" if r["released"] is None else f"{r['released'] / 1e6:.3g} MJ/m"
        print(f"| {r['name']} | {r['scene']} | {r['size']} m | {r['triangles']:,} | {r['extents']} | {r['schedule']} | "
              f"{r['state']} | {r['max_displacement']:.3g} m | {r['runout']:.3g} m | {r['area']:.3g} / "
              f"{'-' if r['area_1m'] is None else format(r['area_1m'], '.3g')} m^2 | "
              f"{r['ke_peak'] / 1e6:.3g} MJ/m | {released} | {r['broken']} | {r['modes']} | "
              f"{'-' if r['steps'] is None else format(r['steps'], ',')} | {r['wall']} | {r['law']} |")
    print()
    print("The command of each row (`--out` left out; `--resume` carries a stopped one on), at the commit named:")
    print()
    for r in rows:
        print(f"    {r['name']}: {r['command'] or '-'}" + (f"    # {r['commit']}" if r['commit'] else ""))


def figures(summary: dict, frame: dict | None = None) -> list[tuple[str, str]]:
    """(row, this run) pairs of the beside-the-paper table, read from ``summary`` (and
    ``frame``, :func:`last_frame_figures`, for the figures the summary does not carry)."""
    wf = summary.get("workflow") or {}
    stages = wf.get("stages") or []
    fos = wf.get("fos") or {}
    run = summary.get("runout") or {}
    ke = summary.get("kinetic_energy") or {}
    tags = summary.get("cracks_by_tag") or {}
    rock, joints = tags.get("rock") or {}, tags.get("joints") or {}
    frag = summary.get("fragments") or {}
    locked = summary.get("locked") or {}
    mid = summary.get("mid_failure") or {}
    converged = [st["reduction"] for st in stages if st["reason"] == "converged" and not st["name"].startswith("runout")]
    crept = wf.get("crept_at_factors") or ([wf["crept_at_factor"]] if wf.get("crept_at_factor") else [])
    rows = []
    strength = []
    if fos.get("fos") is not None:
        b = fos.get("bracket") or [None, None]
        strength.append(f"bisection {fos['fos']:.3f} ({b[0]:.4g}-{b[1]:.4g}, tolerance {fos.get('tolerance'):g})")
    if any(st["name"].startswith("reduction_rate") or st["name"].startswith("rate") for st in stages):
        strength.append(f"the paper's rate to F = {wf.get('final_reduction', 0):.3g}")
    elif converged:
        lo, failed = steps_bracket(wf)   # converged, crept and local-fall factors stand
        falls = wf.get("local_falls") or []
        strength.append(f"damped steps {lo:.4g}-{'-' if failed is None else format(failed, '.4g')}"
                        + (f", crept and stopped at {', '.join(format(c, '.4g') for c in crept)}" if crept else "")
                        + "".join(f", a block off the face at {f['factor']:.4g} ("
                                  + ("area not recorded" if f.get("area_m2") is None else f"{f['area_m2']:.3g} m^2")
                                  + f", {f['max_displacement_m']:.3g} m)" for f in falls))
    rows.append(("strength reduction", "; ".join(strength) or "-"))
    rows.append(("maximum displacement", f"{run.get('max_displacement_m', 0):.3g} m (D50 {run.get('p50_displacement_m', 0):.3g} m, "
                                         f"D90 {run.get('p90_displacement_m', 0):.3g} m of the displaced mass)"))
    off = run.get("off_model_area_m2") or 0.0
    rows.append(("runout beyond the toe", f"{run.get('runout_distance_m', 0):.3g} m (99th percentile by area), front "
                                          f"{run.get('runout_front_max_m', 0):.3g} m"
                                          + ((f"; {off:.3g} m^2 of fly-rock left the model: the front is a lower bound"
                                              if off < 0.01 * run.get("displaced_area_m2", 0.0)
                                              else f"; {off:.3g} m^2 left the model: a lower bound") if off > 0 else "")))
    areas = summary.get("displaced_area_m2") or (frame or {}).get("areas") or {}
    rows.append(("volume", f"{run.get('displaced_area_m2', 0):.3g} m^2 displaced more than 0.1 m (per metre)"
                 + (f"; {areas['1']:.3g} m^2 more than 1 m, {areas['10']:.3g} m^2 more than 10 m" if areas else "")))
    final = ke.get("final_J_per_m", 0)
    final_text = f"{final / 1e6:.3g} MJ/m" if final >= 1e5 else f"{final / 1e3:.3g} kJ/m"
    rows.append(("kinetic energy", f"peak {ke.get('peak_J_per_m', 0) / 1e6:.3g} MJ/m, {final_text} at the end; "
                                   f"gravity released {ke.get('released_gravity_J_per_m', 0) / 1e6:.3g} MJ/m, "
                                   f"fracture {ke.get('fracture_J_per_m', 0) / 1e6:.3g} MJ/m"))
    rows.append(("breakage", f"{(summary.get('cracks') or {}).get('broken', 0):,} broken: intact rock {rock.get('broken', 0):,} "
                             f"({_mode(rock)}), joints {joints.get('broken', 0):,} ({_mode(joints)}); "
                             f"{rock.get('activated', 0) + joints.get('activated', 0):,} activated, unbroken"))
    if frag:
        rows.append(("fragments", f"{frag.get('n_fragments', 0):,}, {frag.get('n_blocks', 0):,} of them blocks of more "
                                  f"than one triangle"))
    apart = locked.get("stopped_apart_m2")  # summaries written before the rule told the two apart have none
    dragged = locked.get("dragged_m2")  # nor before it told dragged ground from carried blocks
    rows.append(("locked mass", f"{locked.get('area_m2', 0):.3g} m^2 ({100 * locked.get('share_of_failed', 0):.3g} % of "
                                f"the failed mass)" + (f"; {apart:.3g} m^2 stopped apart from it" if apart else "")
                 + (f"; {dragged:.3g} m^2 of ground dragged, not carried" if dragged else "")
                 if locked else "-"))
    bnd = summary.get("boundaries") or (frame or {}).get("boundaries")
    if bnd:
        rows.append(("boundaries", "; ".join(f"{side} {d['max_displacement_m'] * 1e3:.3g} mm (slip along it "
                                             f"{d['max_slip_m'] * 1e3:.3g} mm)" for side, d in bnd.items())
                     + " at the end: the largest displacement of the nodes that started on each side"))
    if mid:
        rows.append(("mid-failure picture", f"t = {mid['time_s']:.3g} s, D90 {mid['d90_m']:.3g} m"))
    stopped, at_rest, last = ending(summary)
    if stopped:  # the stage under way is not among the finished ones
        rest = f"no: {summary.get('ending') or summary.get('outcome')}, a run still going (it resumes)"
    else:
        rest = (("yes" if at_rest else "no") + f": the last stage ({last.get('name', '-')}) ended "
                f"{last.get('reason')} at t = {last.get('t_end', 0):.3g} s")
    rows.append(("at rest?", rest))
    walls = sum(st.get("wall_seconds", 0.0) for st in stages) + (fos.get("wall_seconds") or 0.0)
    rows.append(("run", f"{summary.get('n_triangles', 0):,} triangles, {summary.get('steps', 0):,} steps to "
                        f"t = {summary.get('simulated_time_s', 0):.3g} s, {walls:,.0f} s of wall time"
                        + (" in the finished stages" if stopped else "")
                        + f" on {summary.get('threads', '?')} CPU thread(s)"))
    return rows


def main(argv=None) -> list[tuple[str, str]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, nargs="?", help="the run's folder (holding summary.json)")
    parser.add_argument("--name", default=None, help="the name in docs/cases/rest (default from the summary)")
    parser.add_argument("--dry-run", action="store_true", help="print the table, copy nothing")
    parser.add_argument("--redraw-mechanism", action="store_true",
                        help="draw mechanism.png again with this code (the locked part by this code's rule) "
                             "instead of copying the run's own")
    parser.add_argument("--overview", action="store_true",
                        help="print one table of every run published in docs/cases/rest, and nothing else")
    args = parser.parse_args(argv)
    if args.overview:
        print_overview(overview())
        return []
    if args.run is None:
        parser.error("give a run's folder, or --overview")
    path = args.run / "summary.json"
    if not path.exists():
        parser.error(f"{path} does not exist: a run writes its summary when it ends or is stopped")
    summary = json.loads(path.read_text())
    if summary.get("case") != "four-slopes" or not summary.get("workflow"):
        parser.error(f"{path} is not the summary of a four-slope workflow run")
    name = args.name or default_name(summary)
    locked = locked_now(args.run, summary)
    if locked is not None and locked != summary.get("locked"):
        print(f"locked part by this code's rule: {locked['area_m2']:.3g} m^2 (the run's summary: "
              f"{(summary.get('locked') or {}).get('area_m2', 0):.3g} m^2)", file=sys.stderr)
        summary["locked"] = locked
        summary["locked_rule_applied_at_publication"] = True
    frame = None if summary.get("boundaries") and summary.get("displaced_area_m2") else last_frame_figures(args.run)
    rows = figures(summary, frame)
    law = contact_law_of(args.run)
    rows.append(("code", code_of(args.run, law)))
    print(f"| | this run: {name} |\n|---|---|")
    for k, v in rows:
        print(f"| {k} | {v} |")
    if not args.dry_run:
        DOCS.mkdir(parents=True, exist_ok=True)
        write_json(DOCS / f"{name}.json", summary)  # the run's summary, its locked part by this code's rule
        try:
            record = json.loads((args.run / "run.json").read_text())
        except (OSError, ValueError):
            record = {}
        write_json(DOCS / f"{name}_run.json", {**record, "contact_law": law, "last_frame": frame})
        redrawn = redraw_mechanism(args.run, summary, DOCS / f"{name}_mechanism.png") if args.redraw_mechanism else None
        if args.redraw_mechanism:
            print(f"mechanism picture {'drawn again by this code' if redrawn else 'not redrawn (no state or mesh)'}",
                  file=sys.stderr)
        for pic in PICTURES:
            if (args.run / f"{pic}.png").exists() and not (pic == "mechanism" and redrawn):
                shutil.copyfile(args.run / f"{pic}.png", DOCS / f"{name}_{pic}.png")
        print(f"wrote {DOCS.relative_to(ROOT)}/{name}.json and its pictures", file=sys.stderr)
    return rows


if __name__ == "__main__":
    main()
