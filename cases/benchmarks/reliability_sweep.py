"""Bad inputs and faults against the installed ``fdem`` command: how each one ends.

Every try runs ``fdem`` in a fresh process and records its exit code, whether a traceback
reached the terminal, and the last line it printed. A try ends *clearly* when it exits with
the code its ending calls for (2 for a bad option, 1 for an error) and no traceback;
the faults that need a running simulation (signals, a full disk) are the tests of
``tests/cases/test_resume.py``. Writes ``docs/reliability/sweep.json`` and prints a table.

    python cases/benchmarks/reliability_sweep.py
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "docs" / "reliability" / "sweep.json"

QS = ["run", "quick-start", "--no-pictures"]
FS = ["run", "four-slopes", "--no-pictures"]
TRIES = [  # (what, argv, expected exit code); {out} is a fresh folder, {file} an existing file
    ("unknown case", ["run", "no-such-case"], 2),
    ("size zero", QS + ["--size", "0"], 2),
    ("size negative", QS + ["--size", "-1"], 2),
    ("size nan", QS + ["--size", "nan"], 2),
    ("size inf", QS + ["--size", "inf"], 2),
    ("size not a number", QS + ["--size", "big"], 2),
    ("size too fine for memory", QS + ["--size", "0.001", "--out", "{out}"], 2),
    ("threads zero", QS + ["--threads", "0"], 2),
    ("max-time negative", QS + ["--max-time", "-1"], 2),
    ("max-time zero", QS + ["--max-time", "0"], 2),
    ("density-scaling above 1", QS + ["--density-scaling", "2"], 2),
    ("density-scaling negative", QS + ["--density-scaling", "-0.1"], 2),
    ("dt-fraction above 1", QS + ["--dt-fraction", "1.5"], 2),
    ("dt-fraction zero", QS + ["--dt-fraction", "0"], 2),
    ("checkpoint-every negative", QS + ["--checkpoint-every", "-5"], 2),
    ("out is a file", QS + ["--out", "{file}"], 2),
    ("out below a file", QS + ["--out", "{file}/below"], 2),
    ("resume a folder with no run", QS + ["--resume", "{out}"], 2),
    ("resume with a changed option", QS + ["--resume", "{out}", "--size", "2"], 2),
    ("runout-time negative", FS + ["--runout-time", "-1"], 2),
    ("fos bracket inverted", FS + ["--fos", "2", "1", "0.1"], 2),
    ("fos tol zero", FS + ["--fos", "1", "2", "0"], 2),
    ("fos tol below resolution", FS + ["--fos", "1", "2", "1e-20"], 2),
    ("max-steps 100 (ignored before)", FS + ["--max-steps", "100"], 2),
    ("spacing not a number", FS + ["--spacing", "wide"], 2),
    ("angle unknown", FS + ["--angle", "steep"], 2),
    ("runout-dt-fraction above 1", FS + ["--runout-dt-fraction", "2"], 2),
    ("joint-offset 1.5", FS + ["--joint-offset", "1.5"], 2),
    ("refine 0", FS + ["--refine", "0"], 2),
    ("incline theta 95", ["run", "block-on-incline", "--theta", "95"], 2),
    ("incline theta 200", ["run", "block-on-incline", "--theta", "200"], 2),
    ("incline element damping -0.5", ["run", "block-on-incline", "--element-damping", "-0.5"], 2),
    ("disc platen speed 0", ["run", "brazilian-disc", "--v-platen", "0"], 2),
    ("disc platen speed -1", ["run", "brazilian-disc", "--v-platen", "-1"], 2),
    ("disc size 1.0 (clamped before)", ["run", "brazilian-disc", "--sizes", "1.0"], 2),
    ("planar lower above upper", ["run", "planar-failure", "--lower", "2", "--upper", "1"], 2),
    ("planar tol 0", ["run", "planar-failure", "--tol", "0"], 2),
    ("planar tol -1", ["run", "planar-failure", "--tol", "-1"], 2),
    ("planar lower -1", ["run", "planar-failure", "--lower", "-1"], 2),
    ("planar tol 1e-20 (hung before)", ["run", "planar-failure", "--tol", "1e-20"], 2),
    ("muliashi upper 0.5", ["run", "muliashi", "--upper", "0.5"], 2),
    ("muliashi workers 0", ["run", "muliashi", "--workers", "0"], 2),
    ("muliashi overload -1", ["run", "muliashi", "--overload", "-1"], 2),
    ("rigid-blocks lower above upper", ["run", "rigid-blocks", "--lower", "3", "--upper", "2"], 2),
    ("ensemble workers 0", ["run", "ensemble", "--workers", "0"], 2),
    ("info of a missing mesh", ["info", "{out}/none.msh"], 2),
]


def run_try(argv: list[str], scratch: Path) -> dict:
    out = scratch / f"out{time.monotonic_ns()}"
    taken = scratch / "taken"
    taken.write_text("a file, not a folder")
    argv = [a.replace("{out}", str(out)).replace("{file}", str(taken)) for a in argv]
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "fdem", *argv], capture_output=True, text=True, timeout=600)
    text = (r.stdout + r.stderr).strip()
    return {"argv": argv, "exit_code": r.returncode, "traceback": "Traceback" in text,
            "last_line": text.splitlines()[-1][-200:] if text else "", "seconds": time.perf_counter() - t0}


def main() -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for what, argv, expected in TRIES:
            r = {"what": what, "expected_exit": expected, **run_try(argv, Path(tmp))}
            r["clear"] = r["exit_code"] == expected and not r["traceback"]
            rows.append(r)
            print(f"{'ok ' if r['clear'] else 'BAD'} {what:36s} exit {r['exit_code']:3d}  {r['last_line'][:110]}",
                  flush=True)
    clear = sum(r["clear"] for r in rows)
    print(f"{clear} of {len(rows)} tries end clearly")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"command": "python cases/benchmarks/reliability_sweep.py", "tried": len(rows),
                               "clear": clear, "date": time.strftime("%Y-%m-%d"), "rows": rows}, indent=1))
    return rows


if __name__ == "__main__":
    main()
