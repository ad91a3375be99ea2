"""The trials of finished factor-of-safety searches, drawn from their run folders.

A search run with an output folder draws ``fos_trials.png`` itself (each trial's unbalanced-force
ratio and displacement against its own time, :func:`fdem.io.pictures.trial_histories_plot`);
this script draws the same picture for a run made before it did, from the run's ``history.csv``
(the rows of each ``trial_F...`` stage), ``fos.json`` (each trial's verdict, and the raised
limit its converged trials name in their ``detail``) and ``run.json`` (the rule's options). A
trial that reached its cap still settling (:func:`fdem.workflow.fos.settling_at_cap`) is drawn
dashed: from its ``cap_trend`` where ``fos.json`` has one, else read from its rows over windows
of a fifth of its cap (the default cap of 5 response times):

    python cases/benchmarks/trial_pictures.py runs/s46/lc1_eq2.8e-4_hold1 runs/s46/lc05_eq2.8e-4_hold1 \\
        --out docs/cases/convergence/rule --names low_coarse_1.0_offset0_eq2.8e-4_hold1 low_coarse_0.5_offset0_eq2.8e-4_hold1

writes ``<out>/<name>_fos_trials.png`` for each run.
"""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np

from fdem.io.history import read_history
from fdem.io.pictures import trial_histories_plot
from fdem.workflow.fos import FOLLOW_SUFFIX, settling_at_cap, trial_curve


def option(argv: list[str], flag: str, default: float) -> float:
    return float(argv[argv.index(flag) + 1]) if flag in argv else default


def curves_of(run: Path) -> tuple[list[dict], float, str]:
    """The trials' curves, the limit their rule applied, and a title naming the rule."""
    fos = json.loads((run / "fos.json").read_text())
    argv = json.loads((run / "run.json").read_text()).get("argv", [])
    history = read_history(run / "history.csv")
    stage = np.asarray(history["stage"])
    limit = option(argv, "--equilibrium-ratio", 1e-4)
    for t in fos["trials"]:  # a raised limit is named in a converged trial's detail
        raised = re.search(r"<= ([0-9.eE+-]+), [0-9.]+ times the round-off floor", t.get("detail", ""))
        if raised:
            limit = max(limit, float(raised.group(1)))
    curves = []
    for t in fos["trials"]:
        # the trial's rows, and its follow's when it was followed to rest
        rows = (stage == t["name"]) | (stage == t["name"] + FOLLOW_SUFFIX) if t.get("follow") else stage == t["name"]
        if rows.any():  # the same curve a search draws of its own trials
            curve = trial_curve(t["factor"], t["stable"], history["time"][rows],
                                history["unbalanced_ratio"][rows], history["max_displacement"][rows])
            curve["follow_from"] = t["t_end"] - float(history["time"][rows][0]) if t.get("follow") else None
            trend = t.get("cap_trend") if not t.get("follow") else None
            if trend is None and not t.get("follow") and t["reason"] == "capped" and "--step-time" not in argv:
                trend = settling_at_cap(history["time"][rows], history["max_displacement"][rows],
                                        history["unbalanced_ratio"][rows], window=(t["t_end"] - t["t_start"]) / 5.0)
            curve["settling"] = bool(trend and trend["settling"])
            curves.append(curve)
    hold = option(argv, "--equilibrium-hold", 0.0)
    size = option(argv, "--size", float("nan"))
    title = (f"{size:g} m: FoS {fos['fos']:.4g} ({fos['bracket'][0]:.4g}-{fos['bracket'][1]:.4g}), limit {limit:.3g}"
             + (f" held {hold:g} T" if hold else " at its first check"))
    return curves, limit, title


def main(argv=None) -> list[Path]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--names", nargs="+", required=True)
    args = p.parse_args(argv)
    if len(args.names) != len(args.runs):
        p.error(f"--names: one name a run ({len(args.runs)}), got {len(args.names)}")
    written = []
    for run, name in zip(args.runs, args.names):
        curves, limit, title = curves_of(run)
        path = trial_histories_plot(args.out / f"{name}_fos_trials.png", curves, limit=limit, title=title)
        print(f"{run}: {len(curves)} trials -> {path}")
        written.append(path)
    return written


if __name__ == "__main__":
    main()
