"""The bracket of finished factor-of-safety searches read at shorter caps than their trials'
(:func:`fdem.workflow.fos.bracket_by_cap`): whether a search's factor depends on how long a
trial may take to converge.

A search writes this reading itself (``by_cap`` in ``fos.json``); this script makes it for
searches run before it did, from their ``fos.json`` and ``run.json``. The response time comes
from a capped trial's ``cap_trend`` (its window), else from the cap: 5 response times, or
``--step-time`` over ``--response-times`` when the run gave one (the scene's response time is
in its log: ``T = ...``):

    python cases/benchmarks/fos_by_cap.py runs/s49/hc1_10T_wide runs/s49/hc1_20T \\
        --json docs/cases/convergence/high_coarse_1.0_by_cap.json

prints each run's readings and, with ``--json``, writes them.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from fdem.io.jsonable import write_json
from fdem.workflow.fos import DEFAULT_CAP_RESPONSE_TIMES, bracket_by_cap, bracket_words


def readings(run: Path, response_times: float | None = None) -> dict:
    """The run's trials read at its cap, half of it, a quarter, ... (:func:`bracket_by_cap`)."""
    fos = json.loads((run / "fos.json").read_text())
    argv = json.loads((run / "run.json").read_text()).get("argv", [])
    trials = fos["trials"]
    windows = [t["cap_trend"]["window"] for t in trials if t.get("cap_trend")]
    if "--step-time" in argv:
        cap = float(argv[argv.index("--step-time") + 1])
    else:
        capped = [t["t_end"] - t["t_start"] for t in trials if t["reason"] == "capped"]
        if not capped:
            raise SystemExit(f"{run}: no trial reached its cap and the run names no --step-time: the cap is unknown")
        cap = max(capped)
    if windows:
        window = windows[0]
    elif response_times is not None:
        window = cap / response_times
    elif "--step-time" not in argv:
        window = cap / DEFAULT_CAP_RESPONSE_TIMES
    else:
        raise SystemExit(f"{run}: the run gave --step-time and no trial kept its window: give --response-times")
    return {"run": str(run), "fos": fos["fos"], "bracket": fos["bracket"], "response_time_s": window,
            "cap_s": cap, "by_cap": bracket_by_cap(trials, window, cap)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="run folders with fos.json and run.json")
    parser.add_argument("--response-times", type=float, default=None,
                        help="the trials' cap in response times, for a run with --step-time whose trials kept no window")
    parser.add_argument("--json", type=Path, default=None, help="write every run's readings here")
    args = parser.parse_args(argv)
    out = []
    for run in args.runs:
        r = readings(run, args.response_times)
        out.append(r)
        print(f"{run}: response time {r['response_time_s']:.4g} s, trials of {r['cap_s'] / r['response_time_s']:.3g} T")
        for b in r["by_cap"]:
            print(f"  at {b['cap_response_times']:5.3g} T: {bracket_words(b['bracket'])}"
                  + ("" if b["ordered"] else "  (not ordered: a stable factor above a failing one)"))
    if args.json is not None:
        write_json(args.json, out)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
