"""Benchmark: triangle-steps per second of an intact elastic block (fused triangle + update kernel).

Measures the solver's own step (:meth:`fdem.solver.Simulation.step`, no providers, gravity and
a fixed base, no ledger row: the fast fused kernel) and, for reference, the same step with a
ledger row every step (the general kernel computing all energies, plus the Python row; the
monitors, which are O(n) numpy passes, are switched off), at 1e4, 1e5 and 1e6 triangles on 1
and 2 threads. Timings are the best of several repeats; on a shared machine they still vary:
each record carries the load average when it was taken.
Prints a table and writes ``docs/benchmarks/triangles.json``: a list of records with what was
measured, mesh size, threads, value, unit and the machine.

    python cases/benchmarks/bench_triangles.py            # 1e4, 1e5, 1e6 triangles
    python cases/benchmarks/bench_triangles.py --quick    # 1e4, 1e5 only, fewer repeats
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numba
import numpy as np

from fdem.materials import ElasticMaterial
from fdem.mesh import structured_rectangle
from fdem.model import Model
from fdem.solver import Simulation

ROOT = Path(__file__).resolve().parents[2]


def machine() -> dict:
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "python": platform.python_version(), "numba": numba.__version__, "numpy": np.__version__,
            "cpu_count": os.cpu_count(), "load_average_at_start": load}


def block(n_tri_target: int) -> Simulation:
    n = max(1, int(round(np.sqrt(n_tri_target / 2))))
    mesh = structured_rectangle(n, n, 10.0, 10.0)
    model = Model.from_mesh(mesh, ElasticMaterial(10e9, 0.25, 2600.0), exploded=True)
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    sim = Simulation(model, progress=False)
    sim.monitors.clear()
    return sim


def rate(sim: Simulation, ledger: bool, seconds: float, repeats: int) -> float:
    """Best of ``repeats`` timings of as many steps as fit in ``seconds``: triangle-steps per second."""
    sim.step(ledger=ledger)  # compile / warm up
    t0 = time.perf_counter()
    sim.step(ledger=ledger)
    per_step = max(time.perf_counter() - t0, 1e-7)
    n_steps = max(3, int(seconds / per_step))
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n_steps):
            sim.step(ledger=ledger)
        best = min(best, (time.perf_counter() - t0) / n_steps)
    return sim.model.n_triangles / best


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1e4 and 1e5 triangles, fewer repeats")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks" / "triangles.json"))
    args = ap.parse_args(argv)
    sizes = [10_000, 100_000] if args.quick else [10_000, 100_000, 1_000_000]
    seconds, repeats = (0.3, 3) if args.quick else (1.0, 5)
    info = machine()
    records = []
    print(f"{'what':<34}{'triangles':>11}{'threads':>9}{'Mtri-steps/s':>15}")
    for size in sizes:
        sim = block(size)
        for threads in (1, 2):
            if threads > numba.config.NUMBA_NUM_THREADS:
                continue
            numba.set_num_threads(threads)
            for what, ledger in (("fused step (fast kernel)", False), ("fused step + ledger row", True)):
                value = rate(sim, ledger, seconds, repeats)
                rec = {"measured": f"triangle-steps per second, intact elastic block, {what}",
                       "n_triangles": int(sim.model.n_triangles), "threads": threads, "value": value,
                       "unit": "triangle-steps/s", "machine": info,
                       "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None}
                records.append(rec)
                print(f"{what:<34}{sim.model.n_triangles:>11}{threads:>9}{value / 1e6:>15.1f}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(records, indent=2) + "\n")
    print(f"wrote {out}")
    return records


if __name__ == "__main__":
    main()
