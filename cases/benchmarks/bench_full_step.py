"""Full intact FDEM step: crack elements + triangles + integration, in triangle-steps per second.

An exploded elastic block under gravity with a fixed base, every interior edge an intact crack
element (four-slope intact-rock properties), stepped by :meth:`fdem.solver.Simulation.step`
(interaction-force zeroing, the crack pass, the fused triangle + update pass; no ledger row).
Also times the crack pass alone (crack-element updates per second).

    python cases/benchmarks/bench_full_step.py            # 1e5 and 1e6 triangles, 1 and 2 threads
    python cases/benchmarks/bench_full_step.py --quick    # 1e5 only

Writes docs/benchmarks/full_step.json.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from records import best_rate, record, save  # noqa: E402

from fdem.physics.cracks import CrackSet
from fdem.cases.four_slopes import four_slope_property_sets  # noqa: E402
from fdem.physics.elastic import ElasticMaterial  # noqa: E402
from fdem.mesh.mesh import structured_rectangle  # noqa: E402
from fdem.solve.model import Model  # noqa: E402
from fdem.solve.simulation import Simulation  # noqa: E402


def intact_block(n_tri_target: int) -> tuple[Simulation, CrackSet]:
    n = max(1, int(round(np.sqrt(n_tri_target / 2))))
    mesh = structured_rectangle(n, n, 100.0, 100.0)
    model = Model.from_mesh(mesh, ElasticMaterial(0.59e9, 0.29, 2680.0), exploded=True)
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    cracks = CrackSet(model.topology, four_slope_property_sets())
    sim = Simulation(model, providers=[cracks], progress=False)
    sim.monitors.clear()
    return sim, cracks


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    sizes = [100_000] if args.quick else [100_000, 1_000_000]
    seconds, repeats = (0.5, 3) if args.quick else (1.5, 5)
    records = []
    for size in sizes:
        sim, cracks = intact_block(size)
        n_tri, n_crack = sim.model.n_triangles, sim.model.topology.n_cracks
        f = np.zeros_like(sim.state.x)
        for threads in (1, 2):
            if threads > numba.config.NUMBA_NUM_THREADS:
                continue
            numba.set_num_threads(threads)
            full = best_rate(sim.step, n_tri, seconds, repeats)
            records.append(record("full intact step (cracks + triangles + integration)", full,
                                  "triangle-steps/s", n_tri, threads, n_crack_elements=n_crack,
                                  target_2_threads=40e6))

            def crack_pass():
                cracks.add_forces(sim.state.x, sim.state.v, f, sim.dt, sim.state.step)

            crack_rate = best_rate(crack_pass, n_crack, seconds, repeats)
            records.append(record("crack-element updates (crack pass alone)", crack_rate, "crack updates/s",
                                  n_tri, threads, n_crack_elements=n_crack, target_2_threads=80e6))
    save("full_step", records, scene="intact elastic block, structured mesh, four-slope intact crack properties")


if __name__ == "__main__":
    main()
