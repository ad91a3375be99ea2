"""The creep at rest against the strength-reduction factor, from finished searches whose trials
were followed to rest (``trial_end = "rest"``, the default of a strength search): each stood
trial's largest displacement, trial and follow together (:func:`fdem.workflow.fos.moved_in_all`),
and each failing trial's at the failure displacement it reached. Where the creep grows smoothly
with the factor, as on the high-angle coarse four-slope scene, the factor of safety is where it
reaches the failure displacement, and this curve is the figure to read beside it:

    python cases/benchmarks/creep_at_rest.py runs/s50/hc1_rest runs/s51/hc2_rest_2T5 runs/s50/hc2_rest \\
        runs/s51/hc2_rest_10T --labels "1.0 m, 5 T" "2.0 m, 2.5 T" "2.0 m, 5 T" "2.0 m, 10 T" \\
        --out docs/cases/convergence/high_coarse_creep_at_rest

writes ``<out>.png`` and ``<out>.json`` and prints each run's points.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from fdem.io.jsonable import write_json
from fdem.workflow.fos import moved_in_all


def points(run: Path) -> dict:
    """The run's trials as (factor, stood, displacement in all [m], followed), sorted by factor."""
    fos = json.loads((run / "fos.json").read_text())
    rows = sorted((float(t["factor"]), bool(t["stable"]), moved_in_all(t), t.get("follow") is not None)
                  for t in fos["trials"])
    return {"run": str(run), "fos": fos["fos"], "bracket": fos["bracket"],
            "trials": [{"factor": f, "stood": s, "moved_in_all_m": d, "followed": fw} for f, s, d, fw in rows]}


def picture(runs: list[dict], labels: list[str], fail_displacement: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for k, (run, label) in enumerate(zip(runs, labels)):
        colour = f"C{k}"
        stood = [(t["factor"], t["moved_in_all_m"]) for t in run["trials"] if t["stood"]]
        failed = [(t["factor"], t["moved_in_all_m"]) for t in run["trials"] if not t["stood"]]
        ax.plot(*zip(*stood), "o-", color=colour, label=f"{label}: stood (factor {run['fos']:.3g})")
        if failed:
            ax.plot(*zip(*failed), "x", color=colour, markersize=9, mew=2, label=f"{label}: failed")
    ax.axhline(fail_displacement, color="k", ls="--", lw=1, label=f"failure displacement {fail_displacement:g} m")
    ax.set_xlabel("strength-reduction factor F [-]")
    ax.set_ylabel("largest displacement, trial and follow [m]")
    ax.set_title("creep at rest of the trials followed to rest")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="run folders with fos.json")
    parser.add_argument("--labels", nargs="+", default=None, help="one label per run (default: the folder names)")
    parser.add_argument("--fail-displacement", type=float, default=0.30,
                        help="the failure displacement [m] drawn (default 0.30: 1 %% of the four slopes' 30 m)")
    parser.add_argument("--out", type=Path, required=True, help="path without suffix of the .png and .json")
    args = parser.parse_args(argv)
    labels = args.labels or [r.name for r in args.runs]
    if len(labels) != len(args.runs):
        parser.error(f"--labels: {len(labels)} labels for {len(args.runs)} runs")
    runs = [points(r) for r in args.runs]
    for run, label in zip(runs, labels):
        print(f"{label} ({run['run']}): factor {run['fos']:.4g}, bracket {run['bracket']}")
        for t in run["trials"]:
            print(f"  F = {t['factor']:.4g}: {'stood' if t['stood'] else 'failed'}, {t['moved_in_all_m']:.3f} m in all"
                  + ("" if t["followed"] else " (not followed: converged within its cap)"))
    picture(runs, labels, args.fail_displacement, args.out.with_suffix(".png"))
    write_json(args.out.with_suffix(".json"), {"labels": labels, "runs": runs})
    print(f"wrote {args.out.with_suffix('.png')} and {args.out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
