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
import os
import sys
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from records import best_rate, record, save  # noqa: E402

from fdem.physics.elastic import ElasticMaterial  # noqa: E402
from fdem.mesh.mesh import structured_rectangle  # noqa: E402
from fdem.solve.model import Model  # noqa: E402
from fdem.solve.simulation import Simulation  # noqa: E402


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
    """Triangle-steps per second of ``sim.step``, best of ``repeats`` timings."""
    return best_rate(lambda: sim.step(ledger=ledger), sim.model.n_triangles, seconds, repeats)


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1e4 and 1e5 triangles, fewer repeats")
    args = ap.parse_args(argv)
    sizes = [10_000, 100_000] if args.quick else [10_000, 100_000, 1_000_000]
    seconds, repeats = (0.3, 3) if args.quick else (1.0, 5)
    records = []
    for size in sizes:
        sim = block(size)
        for threads in (1, 2):
            if threads > numba.config.NUMBA_NUM_THREADS:
                continue
            numba.set_num_threads(threads)
            for what, ledger in (("fused step (fast kernel)", False), ("fused step + ledger row", True)):
                value = rate(sim, ledger, seconds, repeats)
                records.append(record(f"triangle-steps per second, intact elastic block, {what}", value,
                                      "triangle-steps/s", int(sim.model.n_triangles), threads,
                                      load_average_1min=round(os.getloadavg()[0], 2)))
    save("triangles", records, scene="structured elastic block, gravity, fixed base, no crack elements")
    return records


if __name__ == "__main__":
    main()
