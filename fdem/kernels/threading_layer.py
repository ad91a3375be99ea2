"""Let Numba find the TBB library that pip installed, so that its TBB threading layer can run.

Numba picks its threading layer at the first parallel kernel: TBB when it can load it, else GNU
OpenMP, else its own workqueue. The ``tbb`` wheel puts ``libtbb.so.12`` in the environment's
``lib`` folder, but Numba's ``tbbpool`` extension carries no search path to it (a conda
environment finds it, a virtual environment does not), so a pip install silently falls back to
OpenMP. Loading the library first, by its full path and with global symbols, lets the dynamic
linker resolve ``tbbpool``'s dependency to it.

Why TBB: on the project's 2-core machine a second thread gains 1.75-1.87x with TBB and
1.54-1.78x with OpenMP when the machine is otherwise idle, and when another job runs on the
other core OpenMP's spinning threads make a two-thread run 1.5-1.8x *slower* than one thread,
where TBB stays within 13 % of it at 22,600 triangles and gains 1.46x at 180,000
(``cases/benchmarks/bench_threads.py``, ``docs/benchmarks.md``, "Threads on a shared machine").
Results do not depend on the layer: the kernels give bit-identical states under both
(``tests/unit/test_threading_layers.py``).

Nothing is done when ``NUMBA_THREADING_LAYER`` names another layer, when the library is not
there (other platforms, no ``tbb``), or when it cannot be loaded: Numba then chooses as usual.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["tbb_library", "preload_tbb"]

_LOADED: list = []  # keeps the handle alive for the process


def tbb_library() -> Path | None:
    """Path of the ``libtbb.so.12`` the ``tbb`` distribution installed, or None."""
    if sys.platform != "linux":
        return None
    candidates = [Path(sys.prefix) / "lib" / "libtbb.so.12"]
    try:
        from importlib.metadata import PackageNotFoundError, distribution

        dist = distribution("tbb")
        candidates += [Path(dist.locate_file(f)).resolve() for f in (dist.files or ())
                       if str(f).endswith("libtbb.so.12")]
    except (ImportError, PackageNotFoundError):
        pass
    return next((p for p in candidates if p.is_file()), None)


def preload_tbb() -> bool:
    """Load TBB's library for Numba (see the module docstring); True when it is loaded."""
    if _LOADED:
        return True
    if os.environ.get("NUMBA_THREADING_LAYER", "default").lower() not in ("default", "tbb", "safe", "threadsafe",
                                                                          "forksafe"):
        return False
    path = tbb_library()
    if path is None:
        return False
    import ctypes

    try:
        _LOADED.append(ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL))
    except OSError:
        return False
    return True
