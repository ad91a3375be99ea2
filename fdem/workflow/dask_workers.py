"""Dask workers that run FDEM realizations: one Numba thread each, local or remote.

Imported only when an ensemble runs (:func:`fdem.workflow.ensembles.run_ensemble`): it needs
``dask.distributed`` (``pip install "fdem[ensembles]"``), which the rest of the package never
imports.

Why one thread: a realization is a small mesh (1e2 to 1e4 triangles) whose step lasts well under
a millisecond, so Numba's fork-join costs more than it gains, and a worker per core already keeps
every core busy. Numba's OpenMP threads also spin while they wait: two multi-threaded workers on
the same cores slow each other down tenfold and more (README, "Performance notes"). A worker
started by hand on a cluster node (``dask worker --scheduler-file ...``) inherits whatever
environment the batch system gives it, so the rule is carried to every worker by a plugin,
not by the environment of the process that started the cluster.

The kernels are compiled once per worker process, not once per task: a worker is a long-lived
process, Numba keeps each compiled dispatcher in it, and ``@njit(cache=True)`` loads the
machine code from the on-disk cache (``__pycache__`` beside the kernels) when one exists, so
only the first task on a worker pays the load (measured in ``docs/ensembles.md``).
"""
from __future__ import annotations

import os

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["SINGLE_THREAD_ENV", "SingleThreadNumba", "register_single_thread"]

SINGLE_THREAD_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                     "MKL_NUM_THREADS": "1"}
"""Environment of a single-threaded worker: Numba, OpenMP and the BLAS libraries on one thread."""


class SingleThreadNumba(WorkerPlugin):
    """Holds a worker to one Numba thread (``client.register_plugin(SingleThreadNumba())``).

    ``setup`` runs on every worker, those present and those that join later, before the
    worker's first task: it sets :data:`SINGLE_THREAD_ENV` in the worker's environment, so a
    worker that has not yet imported Numba starts it with one thread, and calls
    ``numba.set_num_threads(1)`` for one that already has. Numba's thread count is per calling
    thread, so :func:`fdem.workflow.ensembles.realize` applies the environment's
    ``NUMBA_NUM_THREADS`` again in the thread that runs the task.
    """

    name = "fdem-single-thread-numba"   # registering twice replaces, never stacks

    def setup(self, worker) -> None:
        os.environ.update(SINGLE_THREAD_ENV)
        import numba

        numba.set_num_threads(1)


def register_single_thread(client) -> None:
    """Register :class:`SingleThreadNumba` on every worker of ``client``'s cluster (waits for it)."""
    client.register_plugin(SingleThreadNumba())
