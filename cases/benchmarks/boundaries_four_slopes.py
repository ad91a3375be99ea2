"""Do the four slopes' boundaries take part? The factor of safety of one scene with wider models
and with intact side bands, each a bisection from the equilibrium state.

A model is far enough from its boundaries when a wider one gives the same bracket and the same
mechanism. Each variant is one ``fdem run four-slopes`` run in ``<root>/<angle>_<spacing>[_crest<C>]
[_band<B>][_elastic]`` (crest plateau ``C`` m, folder suffix when not 30 m; joints kept ``B`` m off the
left and right rollers, those bands elastic with ``_elastic``; floor 45 m and base 15 m in every variant), started, resumed from its checkpoint, or, when its ``summary.json``
exists, only read, one Numba thread each. The table is printed and written to
``docs/cases/four_slopes_boundaries.json``; the pictures of each variant's first failing trial
(``fos_failure.png``) show its mechanism.

    python cases/benchmarks/boundaries_four_slopes.py --scene low:fine --variants 30 60 90 60:5 --root runs/bnd
    python cases/benchmarks/boundaries_four_slopes.py --scene high:fine --variants 30 30:5 60:5 --fos 1.0 3.0 0.04 --root runs/bnd
    python cases/benchmarks/boundaries_four_slopes.py --scene high:fine --variants 30:5:elastic --fos 1.5 2.0 0.02 --root runs/bnd
    python cases/benchmarks/boundaries_four_slopes.py --root runs/bnd --table-only

A variant is ``CREST`` or ``CREST:BAND`` in metres, or ``CREST:BAND:elastic`` for side bands whose
crack elements never soften or break (``fdem run four-slopes --elastic-band``).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from convergence_four_slopes import finished, save_table  # noqa: E402  (a run stopped part-way is resumed, not read)

ROOT = Path(__file__).resolve().parents[2]
TABLE = ROOT / "docs" / "cases" / "four_slopes_boundaries.json"
# the variants share the extents of runs begun before they were named (crest 2H, floor 3H, base H):
# one source, the case's own
from fdem.cases.four_slopes import EXTENTS_BEFORE_PINNING as BASE_EXTENTS  # noqa: E402

DEFAULT_CREST = BASE_EXTENTS["crest_length"]


def parse_variant(text: str) -> tuple[float, float | None, bool]:
    """``"60"`` -> (60.0, None, False); ``"60:5"`` -> (60.0, 5.0, False); ``"60:5:elastic"`` ->
    (60.0, 5.0, True)."""
    crest, _, rest = text.partition(":")
    band, _, law = rest.partition(":")
    try:
        c, b = float(crest), (float(band) if band else None)
    except ValueError:
        c = b = float("nan")
    if not c > 0 or (b is not None and not b > 0) or law not in ("", "elastic") or (law and b is None):
        raise ValueError(f"a variant is CREST, CREST:BAND or CREST:BAND:elastic with positive metres, got {text!r}")
    return c, b, law == "elastic"


def folder(root: Path, angle: str, spacing: str, crest: float, band: float | None, elastic: bool = False) -> Path:
    name = f"{angle}_{spacing}"
    if crest != DEFAULT_CREST:
        name += f"_crest{crest:g}"
    if band is not None:
        name += f"_band{band:g}" + ("_elastic" if elastic else "")
    return root / name


def command(out: Path, angle: str, spacing: str, size: str, crest: float, band: float | None, fos,
            toe: float = BASE_EXTENTS["toe_length"], base: float = BASE_EXTENTS["base_depth"],
            elastic: bool = False) -> list[str]:
    """Every extent named, so that the variants differ in the crest and the bands alone (the
    case's own defaults differ by angle)."""
    exe = [sys.executable, "-c", "import sys; from fdem.cli import main; sys.exit(main())", "run", "four-slopes"]
    if (out / "checkpoint.npz").exists():
        return exe + ["--resume", str(out)]
    argv = exe + ["--angle", angle, "--spacing", spacing, "--size", size, "--fos", *map(str, fos),
                  "--crest-length", f"{crest:g}", "--toe-length", f"{toe:g}", "--base-depth", f"{base:g}",
                  "--boundary-band", f"{band or 0:g}"] + (["--elastic-band"] if elastic else [])
    # only the bracket and its mechanism (the first failing trial's picture) matter here: the search
    # is the whole run (runs begun before --reduction none went on down the steps to a 0.5 s runout)
    return argv + ["--reduction", "none", "--threads", "1", "--quiet", "--yes", "--out", str(out)]


def row(summary: dict, fos_json: dict | None) -> dict:
    """The boundary figures of one run: its bracket, and what broke at F = 1 (boundary slip shows there)."""
    wf = summary.get("workflow") or {}
    fos = wf.get("fos") or {}
    stages = wf.get("stages") or []
    eq = stages[0] if stages else {}
    ext = summary.get("extents_m") or {}
    return {
        "scene": summary.get("scene"), "size_m": summary.get("size_m"), "n_triangles": summary.get("n_triangles"),
        "crest_length_m": ext.get("crest_length"), "toe_length_m": ext.get("toe_length"),
        "side_band_m": ext.get("boundary_band"),
        "side_bands": summary.get("side_bands") or ("rock" if ext.get("boundary_band") else None),
        "equilibrium": eq.get("reason"), "broken_at_F1": eq.get("n_broken"),
        "failed_at_F1": summary.get("failed_at_factor") == 1.0,
        "fos": fos.get("fos"), "bracket": fos.get("bracket"), "tolerance": fos.get("tolerance"),
        "trials": [[t["factor"], t["stable"], t.get("n_broken")] for t in fos.get("trials", [])],
        "failing_trial_broken": (fos_json or {}).get("failure_broken_elements"),
        # every stage's wall time and the bisection's (a resumed run's seconds_simulation is its last part)
        "wall_seconds": sum(st.get("wall_seconds", 0.0) for st in stages) + (fos.get("wall_seconds") or 0.0),
        "outcome": summary.get("outcome"),
    }


def extents_from_command(folder: Path) -> dict:
    """The extents a run's ``run.json`` command names, the defaults of runs begun before they were
    named (crest 30, floor 45, base 15, no bands) for the others."""
    argv = json.loads((folder / "run.json").read_text()).get("argv", [])
    given = {a: float(argv[i + 1]) for i, a in enumerate(argv[:-1])
             if a in ("--crest-length", "--toe-length", "--base-depth", "--boundary-band")}
    band = given.get("--boundary-band")
    return {"crest_length": given.get("--crest-length", DEFAULT_CREST),
            "toe_length": given.get("--toe-length", BASE_EXTENTS["toe_length"]),
            "base_depth": given.get("--base-depth", BASE_EXTENTS["base_depth"]), "boundary_band": band or None}


def table(root: Path) -> list[dict]:
    rows = []
    for folder in sorted(p.parent for p in root.glob("*/run.json")):
        fj = folder / "fos.json"
        fos_json = json.loads(fj.read_text()) if fj.exists() else None
        if (folder / "summary.json").exists():
            s = json.loads((folder / "summary.json").read_text())
            if s.get("case") != "four-slopes" or not s.get("workflow"):
                continue
        elif fos_json is not None:  # still running (its runout) with its bisection done: the bracket is known
            argv = json.loads((folder / "run.json").read_text()).get("argv", [])
            opt = {a: argv[i + 1] for i, a in enumerate(argv[:-1]) if a.startswith("--")}
            scene = f"{opt.get('--angle', 'low')}_{opt.get('--spacing', 'fine')}"
            with np.load(folder / f"{scene}.npz") as mesh:
                n_triangles = int(mesh["triangles"].shape[0])
            s = {"case": "four-slopes", "scene": scene, "size_m": float(opt.get("--size", 0.5)),
                 "n_triangles": n_triangles, "workflow": {"fos": fos_json, "stages": []}, "outcome": "running",
                 "side_bands": "elastic" if "--elastic-band" in argv else None}
        else:
            continue
        if not (s.get("extents_m") or {}).get("toe_length"):  # summaries of older runs do not name them all
            s["extents_m"] = extents_from_command(folder)
        rows.append({**row(s, fos_json), "folder": str(folder)})
    rows.sort(key=lambda r: (r["scene"] or "", r["size_m"] or 0, r["crest_length_m"] or 0, r["side_band_m"] or 0,
                             r["side_bands"] or ""))
    return rows


def print_table(rows: list[dict]) -> None:
    print("| scene | size | crest | floor | side bands | triangles | broken at F = 1 | FoS (bisection) | bracket | wall |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        b = r["bracket"] or [None, None]
        bracket = ("fails at F = 1" if r["failed_at_F1"] else
                   f"{'-' if b[0] is None else format(b[0], '.4g')}-{'-' if b[1] is None else format(b[1], '.4g')}")
        print(f"| {r['scene']} | {r['size_m']} m | {r['crest_length_m']:g} m | {r['toe_length_m']:g} m | "
              f"{'-' if r['side_band_m'] is None else format(r['side_band_m'], 'g') + ' m'}"
              f"{' (elastic)' if r['side_bands'] == 'elastic' else ''} | {r['n_triangles']} | "
              f"{r['broken_at_F1']} | {'-' if r['fos'] is None else format(r['fos'], '.3f')} | "
              f"{bracket} | "
              f"{r['wall_seconds']:.0f} s |")


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="low:fine", help="angle:spacing (default low:fine)")
    parser.add_argument("--variants", nargs="+", default=["30", "60", "90"],
                        help="CREST or CREST:BAND [m] per run (default 30 60 90)")
    parser.add_argument("--size", default="1.0", help="element size [m] (default 1.0)")
    parser.add_argument("--fos", type=float, nargs=3, default=[1.0, 2.0, 0.04], metavar=("LOWER", "UPPER", "TOL"))
    parser.add_argument("--root", type=Path, default=Path("runs/bnd"))
    parser.add_argument("--table-only", action="store_true", help="run nothing: the table of the finished runs")
    args = parser.parse_args(argv)
    angle, _, spacing = args.scene.partition(":")
    if angle not in ("low", "high") or spacing not in ("fine", "coarse"):
        parser.error(f"--scene takes angle:spacing with angle low|high and spacing fine|coarse, got {args.scene!r}")
    try:
        variants = [parse_variant(v) for v in args.variants]
    except ValueError as err:
        parser.error(str(err))
    lo, hi, tol = args.fos
    if not (0 < lo < hi and 0 < tol < hi - lo):
        parser.error(f"--fos needs 0 < LOWER < UPPER and 0 < TOL < UPPER - LOWER, got {args.fos}")
    if not args.table_only:
        for crest, band, elastic in variants:
            out = folder(args.root, angle, spacing, crest, band, elastic)
            if finished(out):
                continue
            argv_run = command(out, angle, spacing, args.size, crest, band, args.fos, elastic=elastic)
            out.parent.mkdir(parents=True, exist_ok=True)
            print(" ".join(argv_run[3:]), flush=True)
            with open(out.parent / f"{out.name}.log", "a") as log:
                subprocess.run(argv_run, env={**os.environ, "NUMBA_NUM_THREADS": "1"}, stdout=log,
                               stderr=subprocess.STDOUT, cwd=ROOT, check=False)
    rows = table(args.root)
    print_table(rows)
    save_table(TABLE, "boundaries_four_slopes.py", argv, rows, args.root)
    return rows


if __name__ == "__main__":
    main()
