"""Where a step of a real four-slope run goes, from the run's own checkpoint: the contact pairs.

A structured block is a yardstick; a failing slope is the figure. This script rebuilds a
four-slope run's model from its folder (its mesh ``<angle>_<spacing>.npz`` and the case's
material, crack and contact settings, ``fdem.cases.four_slopes.simulation``), loads the state of
its ``checkpoint.npz`` (or ``final_state.npz``) and measures, on one thread:

* the pair list: contactors, candidate pairs within the skin, pairs that overlap;
* the pair kernel (:func:`fdem.kernels.contact_pairs.pair_forces`) on that list, each call on
  fresh copies of the per-pair history so that every call does the same work (min and median of
  ``--calls``): ns per candidate pair and per overlapping pair, the apart pairs costed at the
  separating-axis witness figure of ``docs/benchmarks.md`` (27 ns) so the overlapping ones get
  the rest;
* a whole step of the run's own stage (undamped, as in the runout), ``--steps`` steps timed
  after a warm-up, the state then discarded: ms per step and the pair kernel's share of it.

Prints and saves ``docs/benchmarks/pairs_in_run.json`` (one record set per ``--label``).

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_pairs_in_run.py /work/runs/s36/high_coarse_1.0_rest \\
        --label high_coarse_collapsing
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from records import DOCS, machine, record  # noqa: E402

APART_NS = 27.0
"""CPU ns of a candidate pair found apart by its separating-axis witness (``docs/benchmarks.md``,
"Contact pair law: levers": 27.1 ns on the settled pile of ``bench_fragmented``)."""


def scene_of(run: Path) -> tuple[str, str]:
    """``(angle, spacing)`` of a four-slope run, from its ``run.json`` command."""
    argv = json.loads((run / "run.json").read_text())["argv"]
    get = lambda flag, default: argv[argv.index(flag) + 1] if flag in argv else default  # noqa: E731
    return get("--angle", "low"), get("--spacing", "fine")


def build(run: Path):
    from fdem.cases import four_slopes
    from fdem.mesh.mesh import Mesh
    from fdem.mesh.topology import build_topology
    from fdem.solve.checkpoint import load_checkpoint

    angle, spacing = scene_of(run)
    topo = build_topology(Mesh.load(run / f"{angle}_{spacing}.npz"))
    sim, cracks = four_slopes.simulation(None, topo, None, pictures=False, progress=False)
    state = run / "checkpoint.npz" if (run / "checkpoint.npz").exists() else run / "final_state.npz"
    load_checkpoint(sim, state)
    return sim, cracks, state


def time_pairs(sim, calls: int) -> dict:
    from fdem.kernels import contact_pairs as kc

    c = sim.providers[1]
    x, v = sim.state.x, sim.state.v
    c._maybe_search(x)
    f = np.zeros_like(x)
    overlapping = int((kc.overlap_areas(x, c._pair_i, c._pair_j) > 0).sum())

    def once() -> float:
        history, f_target = c._history.copy(), c._f_target.copy()
        touching, witness = c._touching.copy(), c._witness.copy()
        f[:] = 0.0
        t0 = time.perf_counter()
        kc.pair_forces(x, v, c._pair_i, c._pair_j, c._bounds, c.penalty, c._mu_base_pair, c.face_friction,
                       1.0 / c.reduction, c._kt_pair, c._damp_pair, float(sim.dt), history, f_target, touching,
                       witness, f)
        return time.perf_counter() - t0

    once()
    samples = [once() for _ in range(calls)]
    n = len(c.pairs)
    best = min(samples)
    return {"contactors": int(c._active.size), "pairs": n, "overlapping": overlapping, "skin_m": float(c.skin),
            "pair_forces_min_s": best, "pair_forces_median_s": float(np.median(samples)),
            "ns_per_candidate": 1e9 * best / max(n, 1),
            "ns_per_overlapping": (1e9 * best - APART_NS * (n - overlapping)) / max(overlapping, 1)}


def time_steps(sim, steps: int) -> float:
    from fdem.solve.damping import NO_DAMPING

    sim.run(n_steps=20, damping=NO_DAMPING, history_every=10 ** 9, final_output=False)  # warm-up
    t0 = time.perf_counter()
    sim.run(n_steps=steps, damping=NO_DAMPING, history_every=10 ** 9, final_output=False)
    return (time.perf_counter() - t0) / steps


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a four-slope run's folder (run.json, its mesh .npz, checkpoint.npz)")
    ap.add_argument("--calls", type=int, default=30, help="pair-kernel calls timed")
    ap.add_argument("--steps", type=int, default=400, help="whole steps timed")
    ap.add_argument("--label", default=None, help="the record set's name (default: the run folder's)")
    ap.add_argument("--no-save", action="store_true")
    args = ap.parse_args(argv)
    import numba

    load0 = os.getloadavg()[0]
    sim, cracks, state = build(args.run)
    threads = numba.get_num_threads()
    pairs = time_pairs(sim, args.calls)
    step_s = time_steps(sim, args.steps)
    load1 = os.getloadavg()[0]
    n_tri = sim.model.n_triangles
    label = args.label or args.run.name
    figures = {**pairs, "step_s": step_s, "pair_share_of_step": pairs["pair_forces_min_s"] / step_s,
               "state": str(state), "simulated_time_s": float(sim.state.time),
               "broken": int(np.count_nonzero(cracks.broken)), "load_1min": [load0, load1]}
    recs = [record(f"{label}: pair kernel per candidate pair", figures["ns_per_candidate"], "ns", n_tri, threads),
            record(f"{label}: pair kernel per overlapping pair (apart ones at {APART_NS:g} ns)",
                   figures["ns_per_overlapping"], "ns", n_tri, threads),
            record(f"{label}: whole undamped step", 1e3 * step_s, "ms", n_tri, threads),
            record(f"{label}: pair kernel share of the step", figures["pair_share_of_step"], "-", n_tri, threads)]
    print(f"{n_tri:,} triangles at t = {sim.state.time:.4g} s, {figures['broken']:,} crack elements broken; "
          f"{pairs['contactors']:,} contactors, {pairs['pairs']:,} candidate pairs, {pairs['overlapping']:,} "
          f"overlapping; load {load0:.2f} -> {load1:.2f}")
    for r in recs:
        print(f"{r['what']}: {r['value']:.4g} {r['unit']}")
    if not args.no_save:
        path = DOCS / "pairs_in_run.json"
        doc = json.loads(path.read_text()) if path.exists() else {"benchmark": "pairs_in_run", "runs": {}}
        doc["runs"][label] = {"date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "machine": machine(),
                              "command": "NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_pairs_in_run.py "
                                         + " ".join(argv if argv is not None else sys.argv[1:]),
                              "figures": figures, "records": recs}
        DOCS.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(doc, indent=2))
        print(f"wrote {path}")
    sim.close()
    return figures


if __name__ == "__main__":
    main()
