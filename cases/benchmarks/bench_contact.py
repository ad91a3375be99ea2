"""Benchmark: contact pair forces per second, and the broad phase, on 1 and 2 threads.

A fully fragmented block (``structured_rectangle``, every crack element broken, so every
triangle is a contactor and pairs with all its neighbours):

* ``at rest``: the reference configuration, neighbours touching along edges and corners
  (the common state of a settled rubble pile: every pair is rejected by the separating-axis
  test after a few flops);
* ``compressed``: every triangle inflated by 1 % about its centroid, so every edge neighbour
  overlaps and runs the full distributed-potential law, with Coulomb friction and contact
  damping on and random velocities.

``pairs/s`` counts candidate pairs processed by one force evaluation (``ms_per_call`` is the
time of one evaluation: compare that across versions whose broad phase keeps different pairs) (pair law, friction,
gather onto the nodes: the whole ``ContactSet.add_forces`` without a re-search) per wall
second. The broad phase is timed separately as triangles binned and searched per second.
Prints the records and writes ``docs/benchmarks/contact.json``
(``{what, mesh_size, threads, value, unit, n_pairs, ...}`` plus the machine).

    python cases/benchmarks/bench_contact.py [--n 300] [--repeats 5]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
sys.path.insert(0, str(Path(__file__).resolve().parent))

from fdem.physics import contact as fc  # noqa: E402
from fdem.mesh.mesh import structured_rectangle  # noqa: E402
from fdem.mesh.topology import build_topology  # noqa: E402
from records import best_rate, record, save  # noqa: E402


def fragmented_block(n: int, penalty: float, inflate: float, rng):
    topo = build_topology(structured_rectangle(n, n, float(n), float(n)))
    x = topo.x0.reshape(-1, 3, 2)
    x = (x.mean(axis=1, keepdims=True) + (1.0 + inflate) * (x - x.mean(axis=1, keepdims=True))).reshape(-1, 2)
    mass = np.repeat(2700.0 * np.abs(topo.triangle_area0) / 3.0, 3)
    cs = fc.ContactSet(topo, penalty=penalty, friction_angle=30.0 if inflate else 0.0,
                       damping_ratio=0.1 if inflate else 0.0, mass=mass, skin=0.1, check_overlap=False)
    cs.activate_cracks(np.arange(topo.n_cracks))
    v = 0.01 * rng.normal(size=x.shape) if inflate else np.zeros_like(x)
    return topo, cs, np.ascontiguousarray(x), v


def cpu_seconds(step, repeats: int) -> float:
    """Best CPU time (``time.process_time``) of one ``step()`` over ``repeats`` calls."""
    step()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        step()
        best = min(best, time.process_time() - t0)
    return best


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=300, help="cells per side (2 n^2 triangles)")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    max_threads = numba.config.NUMBA_NUM_THREADS
    thread_counts = sorted({1, min(2, max_threads)})
    records = []
    for label, inflate in (("at rest", 0.0), ("compressed", 0.01)):
        topo, cs, x, v = fragmented_block(args.n, 1e11, inflate, rng)
        f = np.zeros_like(x)
        cs.search(x)
        n_pairs = len(cs.pairs)
        cs.add_forces(x, v, f, 1e-6, 0)
        touching = int(cs._touching.sum())
        for threads in thread_counts:
            numba.set_num_threads(threads)

            def forces():
                f[:] = 0.0
                cs.add_forces(x, v, f, 1e-6, 0)

            load = os.getloadavg()[0]
            rate = best_rate(forces, n_pairs, 0.3, args.repeats)
            extra = {}
            if threads == 1:   # CPU time per pair: less disturbed by other jobs than wall time
                extra["ns_per_pair_cpu"] = 1e9 * cpu_seconds(forces, args.repeats) / n_pairs
            records.append(record(f"contact pair forces, fragmented block {label}", rate, "pairs/s",
                                  mesh_size=topo.n_triangles, threads=threads, n_pairs=n_pairs,
                                  n_overlapping=touching, ms_per_call=1e3 * n_pairs / rate,
                                  load_avg_1min=[load, os.getloadavg()[0]], **extra))
            if inflate == 0.0:
                load = os.getloadavg()[0]
                srate = best_rate(lambda: cs.search(x), topo.n_triangles, 0.3, args.repeats)
                records.append(record("contact broad phase (grid + incidence), fragmented block", srate,
                                      "triangles/s", mesh_size=topo.n_triangles, threads=threads,
                                      n_pairs=n_pairs, load_avg_1min=[load, os.getloadavg()[0]]))
    numba.set_num_threads(max_threads)
    save("contact", records,
         note="numba threads via numba.set_num_threads; pairs/s = candidate pairs per wall second of "
              "ContactSet.add_forces (pair law + friction + gather, no re-search); ns_per_pair_cpu = "
              "best CPU time (process_time) of one call per pair, 1 thread; load_avg_1min before and after "
              "each timing; measured on a machine shared with other jobs")


if __name__ == "__main__":
    main()
