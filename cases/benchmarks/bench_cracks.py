"""Benchmark: crack-element updates per second (force + damage update of one element).

Meshes of about 1e5 and 1e6 triangles (``structured_rectangle``; about 1.5 crack elements per
triangle), the four-slope property sets (intact rock), nodes perturbed elastically so every
element evaluates the full law. Both race-free schemes are timed, on 1 and 2 threads
(``numba.set_num_threads``). Prints and writes ``docs/benchmarks/cracks.json`` as records (what, mesh size, threads,
value, unit, plus the scheme and the 1-minute load average, which shows how busy the machine
was).

    python cases/benchmarks/bench_cracks.py [--sizes 1e5 1e6] [--repeats 5]
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numba
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parents[1]))  # run from a checkout without installing
from records import best_rate, record, save  # noqa: E402

from fdem.physics.cracks import CrackSet
from fdem.cases.four_slopes import four_slope_property_sets  # noqa: E402
from fdem.mesh.mesh import structured_rectangle  # noqa: E402
from fdem.mesh.topology import build_topology  # noqa: E402


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[1e5, 1e6], help="target triangle counts")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--schemes", nargs="+", default=["colour", "gather"])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--name", default="cracks", help="docs/benchmarks/<name>.json")
    args = ap.parse_args(argv)

    records = []
    rng = np.random.default_rng(1)
    for size in args.sizes:
        nx = int(round(np.sqrt(size / 2.0)))
        topo = build_topology(structured_rectangle(nx, nx, 100.0, 100.0))
        h = 100.0 / nx
        # A perturbation well inside the elastic range (o << o_p) of the intact set.
        x = topo.x0 + 1e-9 * h * rng.standard_normal(topo.x0.shape)
        f = np.zeros_like(x)
        for scheme in args.schemes:
            cs = CrackSet(topo, four_slope_property_sets(), scheme=scheme)
            for th in args.threads:
                if th > numba.config.NUMBA_NUM_THREADS:
                    continue
                numba.set_num_threads(th)
                rate = best_rate(lambda: cs.add_forces(x, None, f, 1e-6, 0), cs.n_active, 0.2, args.repeats)
                assert not cs.broken.any()
                records.append(record(f"crack-element updates ({scheme} scheme)", rate, "crack updates/s",
                                      int(topo.n_triangles), th, n_crack_elements=int(topo.n_cracks),
                                      scheme=scheme, load_average_1min=round(os.getloadavg()[0], 2)))
    save(args.name, records, scene="structured block, four-slope intact crack properties, elastic range")
    return records


if __name__ == "__main__":
    main()
