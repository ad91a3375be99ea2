"""Ensemble workers: what the first task on a Dask worker costs beyond the second.

A 2-worker local cluster (:func:`fdem.workflow.ensembles.local_cluster`, one Numba thread per
worker held by :class:`fdem.workflow.dask_workers.SingleThreadNumba`) runs the same realization
of the ensemble case (``fdem.cases.ensemble``, planar slope with a DFN, ``--size`` 3 m, FoS
search in [0.5, 2.5] to 0.5) twice on each worker (pinned). Per
worker, the first task pays the imports and Numba's load of the compiled kernels from its
on-disk cache (``@njit(cache=True)``; compiled from scratch if the cache is empty); later tasks
reuse the dispatchers already in the process. Same parameters, so the work itself is the same.

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_ensemble_workers.py

Writes docs/benchmarks/ensemble_workers.json.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from records import record, save  # noqa: E402


def timed_realize(ens, index, params):
    """:func:`fdem.workflow.ensembles.realize` with its worker and start time (wall clock)."""
    from fdem.workflow.ensembles import realize

    start = time.time()
    return os.getpid(), start, realize(ens, index, params)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=float, default=3.0)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)

    import dataclasses

    from dask.distributed import Client

    from fdem.cases.ensemble import ensemble
    from fdem.workflow.dask_workers import register_single_thread
    from fdem.workflow.ensembles import local_cluster

    ens = dataclasses.replace(ensemble(n=1, size=args.size, fos=(0.5, 2.5, 0.5)), pictures=False)
    params = ens.sample()[0]
    with local_cluster(args.workers) as cluster, Client(cluster) as client:
        register_single_thread(client)
        client.wait_for_workers(args.workers)
        # two tasks pinned to each worker; one thread per worker runs them one after the other
        futures = [client.submit(timed_realize, ens, 0, params, pure=False, workers=[address],
                                 allow_other_workers=False)
                   for address in client.scheduler_info()["workers"] for _ in range(2)]
        results = client.gather(futures)
    by_worker: dict[int, list] = {}
    for pid, start, row in results:
        by_worker.setdefault(pid, []).append((start, row))
    records = []
    for w, (pid, runs) in enumerate(sorted(by_worker.items())):
        runs.sort(key=lambda r: r[0])
        for k, (_, row) in enumerate(runs):
            assert row["status"] in ("ok", "below_bracket", "above_bracket"), row["error"]
            records.append(record(f"worker {w} task {k + 1}: wall time of one realization", row["wall_s"], "s",
                                  mesh_size=row["n_triangles"], threads=row["numba_threads"],
                                  build_s=row["build_s"], fos_s=row["fos_s"], fos=row["fos"],
                                  n_trials=row["n_trials"], worker=w, task_on_worker=k + 1))
    firsts = [r["value"] for r in records if r["task_on_worker"] == 1]
    seconds = [r["value"] for r in records if r["task_on_worker"] == 2]
    save("ensemble_workers", records, size_m=args.size, workers=args.workers,
         first_task_mean_s=sum(firsts) / len(firsts), second_task_mean_s=sum(seconds) / len(seconds),
         load_average=os.getloadavg())
    print(f"first task per worker {sum(firsts) / len(firsts):.1f} s, second {sum(seconds) / len(seconds):.1f} s")


if __name__ == "__main__":
    main()
