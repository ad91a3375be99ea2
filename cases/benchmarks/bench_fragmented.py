"""Full FDEM step of a fully fragmented block: contact + triangles + integration, triangle-steps/s.

A square block (``structured_rectangle``, exploded) whose every crack element is broken: all
triangles are contactors and every triangle is a free body touching its neighbours (a
:class:`~fdem.contact.ContactSet` with all cracks activated, no crack-element provider). Under
gravity with a fixed base, it is settled briefly with mass-proportional damping, so that the
pile is compressed and most candidate pairs overlap; then :meth:`fdem.solver.Simulation.step`
(interaction-force zeroing, the contact provider, the fused triangle + update pass; no ledger
row) is timed on 1 and 2 threads. Also times the contact provider alone (``add_forces``, no
re-search) in pair forces per second.

    python cases/benchmarks/bench_fragmented.py            # 1e5 and 2.5e5 triangles
    python cases/benchmarks/bench_fragmented.py --quick    # 1e5 only, shorter timings

Writes docs/benchmarks/fragmented.json.
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
from records import best_rate, record, save  # noqa: E402

from fdem.physics.contact import ContactSet  # noqa: E402
from fdem.physics.elastic import ElasticMaterial  # noqa: E402
from fdem.mesh.mesh import structured_rectangle  # noqa: E402
from fdem.solve.model import Model  # noqa: E402
from fdem.solve.damping import Damping
from fdem.solve.simulation import Simulation  # noqa: E402

YOUNG, POISSON, DENSITY = 0.59e9, 0.29, 2680.0   # four-slope intact rock
SIDE = 100.0                                      # block side [m]


def fragmented_block(n_tri_target: int) -> tuple[Simulation, ContactSet]:
    """Exploded square block of about ``n_tri_target`` triangles, every crack element broken,
    gravity, fixed base; contact penalty 10 E, friction 30 deg, contact damping 0.1."""
    n = max(1, int(round(np.sqrt(n_tri_target / 2))))
    mesh = structured_rectangle(n, n, SIDE, SIDE)
    model = Model.from_mesh(mesh, ElasticMaterial(YOUNG, POISSON, DENSITY), exploded=True)
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    contact = ContactSet(model.topology, penalty=10.0 * YOUNG, friction_angle=30.0, damping_ratio=0.1,
                         mass=model.node_mass())
    contact.activate_cracks(np.arange(model.topology.n_cracks))
    sim = Simulation(model, providers=[contact], progress=False)
    sim.monitors.clear()
    return sim, contact


def settle(sim: Simulation, n_rows: int) -> int:
    """Damped steps until a compression wave has crossed the block about once (about
    ``2 n_rows`` steps at the automatic dt), so that the contacts carry the weight."""
    # critical damping of the fundamental mode of the column, alpha = 2 omega ~ pi c / H
    c = np.sqrt(YOUNG / DENSITY)
    damping = Damping(mass_proportional=np.pi * c / SIDE)
    steps = 3 * n_rows
    for _ in range(steps):
        sim.step(damping)
    return steps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sizes", type=float, nargs="*", default=None, help="triangle counts")
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.sizes] if args.sizes else ([100_000] if args.quick else [100_000, 250_000])
    seconds, repeats = (0.5, 3) if args.quick else (1.5, 5)
    max_threads = numba.config.NUMBA_NUM_THREADS
    records = []
    for size in sizes:
        t0 = time.perf_counter()
        sim, contact = fragmented_block(size)
        n_tri = sim.model.n_triangles
        n_rows = int(round(np.sqrt(n_tri / 2)))
        n_settle = settle(sim, n_rows)
        f = np.zeros_like(sim.state.x)
        contact.add_forces(sim.state.x, sim.state.v, f, sim.dt, sim.state.step)
        n_pairs, n_touch = contact.n_pairs, contact.n_touching
        print(f"{n_tri} triangles: settled {n_settle} steps in {time.perf_counter() - t0:.1f} s; "
              f"{n_pairs} candidate pairs, {n_touch} overlapping, {contact.n_searches} searches", flush=True)
        extra = dict(n_pairs=n_pairs, n_overlapping=n_touch, settle_steps=n_settle)
        for threads in (1, 2):
            if threads > max_threads:
                continue
            numba.set_num_threads(threads)
            searches = contact.n_searches
            load = os.getloadavg()[0]
            full = best_rate(sim.step, n_tri, seconds, repeats)
            records.append(record("full fragmented step (contact + triangles + integration)", full,
                                  "triangle-steps/s", n_tri, threads, target=5e6,
                                  searches_during_timing=contact.n_searches - searches,
                                  load_avg_1min=[load, os.getloadavg()[0]], **extra))

            def contact_pass():
                contact.add_forces(sim.state.x, sim.state.v, f, sim.dt, sim.state.step)

            load = os.getloadavg()[0]
            rate = best_rate(contact_pass, n_pairs, seconds, repeats)
            records.append(record("contact pair forces (ContactSet.add_forces, no re-search)", rate,
                                  "pairs/s", n_tri, threads, target_2_threads=15e6,
                                  ms_per_call=1e3 * n_pairs / rate, load_avg_1min=[load, os.getloadavg()[0]],
                                  **extra))
        numba.set_num_threads(max_threads)
    save("fragmented", records,
         scene="fully fragmented elastic block (every crack element broken), structured mesh, gravity, "
               "fixed base, settled with mass-proportional damping; contact penalty 10 E, friction 30 deg, "
               "contact damping ratio 0.1",
         note="numba threads via numba.set_num_threads; best of 5 timings; the full step includes the "
              "occasional re-search when some node has moved half the skin")


if __name__ == "__main__":
    main()
