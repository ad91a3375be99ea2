"""Mesh convergence of the four slopes: the factor of safety (bisection and the damped 10 % steps),
and, where the runs went to rest, the failed area, runout distance and kinetic energy.

Each (scene, size) is one ``fdem run four-slopes`` run in ``<root>/<angle>_<spacing>_<size>``,
started, resumed from its checkpoint (a run of hours cut by the end of a session goes on where
it stopped) or, when its ``summary.json`` exists, only read. Runs go one after the other, one
Numba thread each (two commands side by side use the two cores). The table of every finished run
is printed and written to ``docs/cases/four_slopes_convergence.json``; ``--table-only`` runs
nothing. A row whose figure moves by more than the bisection's tolerance from the next coarser
size has not converged there.

    # the bisection alone (runout skipped), sizes 1.0 to 0.5, both angles, fine spacing
    nohup python cases/benchmarks/convergence_four_slopes.py --scenes low:fine high:fine \\
        --sizes 1.0 0.7 0.5 --fos 1.0 3.0 0.04 --root runs/conv &
    python cases/benchmarks/convergence_four_slopes.py --root runs/conv --table-only

A root's finished runs are only read: give ``--runout`` its own root (``runs/rest``), or a
bisection-only run there would be taken as done. ``--runout`` runs each failed slope on to rest (the workflow's runout stage, capped at
``--runout-time``, 60 s by default: in effect no cap) instead of skipping it: the failed area,
runout distance and the kinetic energy at rest, with the pictures (``mechanism.png``: the
activated and broken crack elements at mid-failure and at rest).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from fdem.workflow.slope import steps_bracket

ROOT = Path(__file__).resolve().parents[2]
TABLE = ROOT / "docs" / "cases" / "four_slopes_convergence.json"


def folder(root: Path, angle: str, spacing: str, size: str, joint_offset: float | None = None) -> Path:
    """``<root>/<angle>_<spacing>_<size>``, with ``_offset<f>`` when the persistent joints are
    placed explicitly (``--joint-offset``; without it each spacing has its own default)."""
    suffix = "" if joint_offset is None else f"_offset{joint_offset:g}"
    return root / f"{angle}_{spacing}_{size}{suffix}"


def command(out: Path, angle: str, spacing: str, size: str, fos, runout: bool, resume: bool,
            runout_time: float = 60.0, model: tuple[str, ...] = ()) -> list[str]:
    """The ``fdem run four-slopes`` command of one run: with ``runout`` to rest and with pictures
    (the mechanism at mid-failure and at rest), else the runout skipped and no pictures;
    ``model``: further options of the model (extents, side bands, the reduction schedule)."""
    exe = [sys.executable, "-c", "import sys; from fdem.cli import main; sys.exit(main())", "run", "four-slopes"]
    if resume:
        return exe + ["--resume", str(out)]
    argv = exe + ["--angle", angle, "--spacing", spacing, "--size", size, "--fos", *map(str, fos), *model,
                  "--threads", "1", "--quiet", "--yes", "--out", str(out)]
    return argv + ["--runout-time", str(runout_time)] if runout else argv + ["--runout-time", "0.001", "--no-pictures"]


STOPPED = ("interrupted", "unstable", "write_error")
"""Outcomes of a run that stopped before its end (it writes its summary too, and is resumed)."""


def finished(out: Path) -> bool:
    """A run is done when its summary says how it ended, unless it was stopped (interrupted, an
    unstable step, a full disk): such a run writes its summary too, and is resumed."""
    path = out / "summary.json"
    return path.exists() and json.loads(path.read_text()).get("outcome") not in STOPPED


def run_one(out: Path, angle: str, spacing: str, size: str, fos, runout: bool, runout_time: float = 60.0,
            model: tuple[str, ...] = ()) -> None:
    if finished(out):
        return
    resume = (out / "checkpoint.npz").exists()
    argv = command(out, angle, spacing, size, fos, runout, resume, runout_time, model)
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.parent / f"{out.name}.log", "a") as log:
        print(("resuming " if resume else "starting ") + " ".join(argv[3:]), flush=True)
        subprocess.run(argv, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT, check=False)


def row(summary: dict) -> dict:
    """The convergence figures of one run's summary.json."""
    wf = summary.get("workflow") or {}
    fos = wf.get("fos") or {}
    # the bracket of the steps: converged, crept and local-fall factors stand (one rule, the workflow's)
    # a search alone (--reduction none, outcome searched) has no steps
    steps = steps_bracket(wf) if wf.get("stages") and summary.get("outcome") != "searched" else [None, None]
    # the last undamped stage: after a creep or a local fall the reduction carries on, and a later
    # one is runout_F<factor>; its figures are the failure's only when the run failed
    runout_stage = next((st for st in reversed(wf.get("stages", [])) if st["name"].startswith("runout")), None)
    went_to_rest = (runout_stage is not None and runout_stage["reason"] == "converged"
                    and summary.get("outcome") in ("failed", "crept"))
    run = summary.get("runout", {})
    tags = summary.get("cracks_by_tag") or {}
    return {
        "scene": summary.get("scene"), "size_m": summary.get("size_m"), "n_triangles": summary.get("n_triangles"),
        "joint_offset": summary.get("joint_offset"), "extents_m": summary.get("extents_m"),
        "fos_bisection": fos.get("fos"), "bisection_bracket": fos.get("bracket"), "tolerance": fos.get("tolerance"),
        "n_trials": fos.get("n_trials"),
        "steps_bracket": steps, "outcome": summary.get("outcome"),
        "local_falls": wf.get("local_falls", []),
        "runout_to_rest": went_to_rest,
        "failed_area_m2": run.get("displaced_area_m2") if went_to_rest else None,
        "area_moved_1m_m2": (summary.get("displaced_area_m2") or {}).get("1") if went_to_rest else None,
        "runout_distance_m": run.get("runout_distance_m") if went_to_rest else None,
        "max_displacement_m": run.get("max_displacement_m"),
        "kinetic_peak_J_per_m": (summary.get("kinetic_energy") or {}).get("peak_J_per_m") if went_to_rest else None,
        "kinetic_final_J_per_m": (summary.get("kinetic_energy") or {}).get("final_J_per_m") if went_to_rest else None,
        "broken_rock": (tags.get("rock") or {}).get("broken"), "broken_joints": (tags.get("joints") or {}).get("broken"),
        "locked_area_m2": (summary.get("locked") or {}).get("area_m2") if went_to_rest else None,
        # every stage's wall time and the bisection's: a resumed run's seconds_simulation is its last part only
        "steps": summary.get("steps"),
        "wall_seconds": sum(st.get("wall_seconds", 0.0) for st in wf.get("stages", [])) + (fos.get("wall_seconds") or 0.0),
        "runout_ending": runout_stage["reason"] if runout_stage else None,
    }


def table(root: Path) -> list[dict]:
    """The rows of the runs under ``root``: every finished run, and a run stopped after its
    bisection ended (its factor of safety is a result; the outcome column says it stopped, and
    its steps bracket holds the stages it finished)."""
    rows = []
    for path in sorted(root.glob("*/summary.json")):
        s = json.loads(path.read_text())
        searched = ((s.get("workflow") or {}).get("fos") or {}).get("fos") is not None
        if s.get("case") == "four-slopes" and s.get("workflow") and (finished(path.parent) or searched):
            rows.append({**row(s), "folder": str(path.parent)})
    rows.sort(key=lambda r: (r["scene"] or "", r["joint_offset"] or 0.0, -(r["size_m"] or 0)))
    return rows


def fmt(v, spec=".3g") -> str:
    if v is None:
        return "-"
    if isinstance(v, list):
        return "-".join(fmt(x, ".4g") for x in v)
    return format(v, spec) if isinstance(v, float) else str(v)


def print_table(rows: list[dict]) -> None:
    print("| scene (joint offset) | size | triangles | FoS (bisection) | bracket | steps bracket | outcome | failed area "
          "(> 0.1 m / > 1 m) | runout | KE peak | broken rock / joints | wall |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    prev = {}
    for r in rows:
        moved = ""
        key = (r["scene"], r["joint_offset"])
        p = prev.get(key)
        if p is not None and r["fos_bisection"] is not None and p["fos_bisection"] is not None:
            moved = f" ({r['fos_bisection'] - p['fos_bisection']:+.3f})"
        print(f"| {r['scene']} ({fmt(r['joint_offset'], 'g')}) | {fmt(r['size_m'])} m | {fmt(r['n_triangles'])} | {fmt(r['fos_bisection'], '.3f')}{moved} | "
              f"{fmt(r['bisection_bracket'])} | {fmt(r['steps_bracket'])} | {r['outcome']} | "
              f"{fmt(r['failed_area_m2'])} / {fmt(r.get('area_moved_1m_m2'))} | {fmt(r['runout_distance_m'])} | {fmt(r['kinetic_peak_J_per_m'])} | "
              f"{fmt(r['broken_rock'])} / {fmt(r['broken_joints'])} | {fmt(r['wall_seconds'], '.0f')} s |")
        prev[key] = r


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["low:fine", "high:fine", "low:coarse", "high:coarse"],
                        help="angle:spacing pairs (default all four)")
    parser.add_argument("--sizes", nargs="+", default=["1.0", "0.7", "0.5"],
                        help="element sizes [m], as the run folders spell them (default 1.0 0.7 0.5)")
    parser.add_argument("--fos", type=float, nargs=3, default=[1.0, 3.0, 0.04], metavar=("LOWER", "UPPER", "TOL"))
    parser.add_argument("--runout", action="store_true", help="run each failed slope to rest (hours at fine sizes)")
    parser.add_argument("--runout-time", type=float, default=60.0, metavar="SECONDS",
                        help="with --runout: the cap of the runout stage [s simulated] (default 60: in effect none, "
                             "the stage ends when the kinetic energy has stayed below 1 %% of its peak for one "
                             "response time)")
    parser.add_argument("--crest-length", type=float, default=None, metavar="METRES",
                        help="crest plateau of every run (fdem run four-slopes --crest-length; default its own)")
    parser.add_argument("--boundary-band", type=float, default=None, metavar="METRES",
                        help="intact side bands of every run (fdem run four-slopes --boundary-band; default none)")
    parser.add_argument("--joint-offset", type=float, default=None, metavar="FRACTION",
                        help="persistent joints relative to the toe, a fraction of the spacing, for every run "
                             "(fdem run four-slopes --joint-offset; default each spacing's own); the folders "
                             "get the suffix _offset<FRACTION>")
    parser.add_argument("--reduction", choices=["steps", "rate", "none"], default=None,
                        help="the reduction schedule of every run (default the case's: damped steps; none: the "
                             "bisection alone, without the steps bracket)")
    parser.add_argument("--root", type=Path, default=Path("runs/convergence"))
    parser.add_argument("--table-only", action="store_true", help="run nothing: the table of the finished runs")
    args = parser.parse_args(argv)
    scenes = []
    for s in args.scenes:
        angle, _, spacing = s.partition(":")
        if angle not in ("low", "high") or spacing not in ("fine", "coarse"):
            parser.error(f"--scenes takes angle:spacing with angle low|high and spacing fine|coarse, got {s!r}")
        scenes.append((angle, spacing))
    try:
        if any(not float(size) > 0 for size in args.sizes):
            raise ValueError
    except ValueError:
        parser.error(f"--sizes must be positive numbers of metres, got {args.sizes}")
    lo, hi, tol = args.fos
    if not (0 < lo < hi and 0 < tol < hi - lo):
        parser.error(f"--fos needs 0 < LOWER < UPPER and 0 < TOL < UPPER - LOWER, got {args.fos}")
    if args.joint_offset is not None and not 0.0 <= args.joint_offset < 1.0:
        parser.error(f"--joint-offset must be a fraction of the spacing in [0, 1), got {args.joint_offset}")
    model = tuple(a for flag, value in (("--crest-length", args.crest_length), ("--boundary-band", args.boundary_band),
                                        ("--joint-offset", args.joint_offset), ("--reduction", args.reduction))
                  if value is not None for a in (flag, str(value)))
    if not args.table_only:
        for size in args.sizes:  # coarse to fine over all scenes: the cheap rows first
            for angle, spacing in scenes:
                run_one(folder(args.root, angle, spacing, size, args.joint_offset), angle, spacing, size, args.fos,
                        args.runout, args.runout_time, model)
    rows = table(args.root)
    print_table(rows)
    save_table(TABLE, "convergence_four_slopes.py", argv, rows, args.root)
    return rows


def save_table(path: Path, script: str, argv, rows: list[dict], root: Path) -> None:
    """Write ``rows`` (those of the runs under ``root``) into the JSON table ``path`` with the
    command that made it: this root's rows are read afresh (a run stopped part-way has none),
    other roots' are kept."""
    path.parent.mkdir(parents=True, exist_ok=True)
    old = json.loads(path.read_text()) if path.exists() else {"rows": []}
    keep = [r for r in old["rows"] if Path(r["folder"]).parent != root]
    path.write_text(json.dumps({"command": f"python cases/benchmarks/{script} "
                                           + " ".join(sys.argv[1:] if argv is None else argv),
                                "rows": keep + rows}, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
