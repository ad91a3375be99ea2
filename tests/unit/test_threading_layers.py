"""Results do not depend on Numba's threading layer: the same scene stepped on two threads under
TBB and under GNU OpenMP (each in a process of its own: a process fixes its layer at the first
parallel kernel) ends in bit-identical states, crack elements, contact pairs and ledger rows.
The scene is the checkpoint tests' block thrown sideways (``cuda_scene.py``): crack elements
soften and break in a shear band, broken faces touch with friction history. TBB is the layer
``import fdem`` makes Numba use where pip installed it (``fdem.kernels.threading_layer``)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fdem.kernels.threading_layer import tbb_library

HERE = Path(__file__).resolve().parent


def run(layer: str, out: Path) -> str:
    env = {**os.environ, "NUMBA_THREADING_LAYER": layer, "NUMBA_NUM_THREADS": "2"}
    code = ("import sys, numba; sys.path.insert(0, sys.argv[1]); import cuda_scene; "
            "assert cuda_scene.main(['cpu', sys.argv[2]]) == 0; print(numba.threading_layer())")
    r = subprocess.run([sys.executable, "-c", code, str(HERE), str(out)], env=env, capture_output=True, text=True,
                       timeout=600, cwd=HERE)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout.strip().splitlines()[-1]


@pytest.mark.skipif(tbb_library() is None, reason="the tbb package is not installed here")
def test_tbb_and_openmp_give_bit_identical_runs(tmp_path):
    # kernels compiled in the running process and the same kernels loaded from Numba's cache
    # differ in round-off (docs/benchmarks.md, "Fresh and cached kernels"): a first run fills
    # the cache, so that both compared runs load the same machine code
    run("omp", tmp_path / "warm.npz")
    assert run("tbb", tmp_path / "tbb.npz") == "tbb"
    assert run("omp", tmp_path / "omp.npz") == "omp"
    a, b = np.load(tmp_path / "tbb.npz"), np.load(tmp_path / "omp.npz")
    assert set(a.files) == set(b.files)
    assert int(a["broken"].sum()) > 0 and len(a["pairs"]) > 0  # it broke and touched: every kernel ran
    for key in a.files:
        assert np.array_equal(a[key], b[key]), key


def test_import_fdem_lets_numba_load_tbb_where_pip_installed_it():
    if tbb_library() is None:
        pytest.skip("the tbb package is not installed here")
    code = ("import fdem, numba, numpy as np\n"
            "@numba.njit(parallel=True)\n"
            "def total(a):\n"
            "    s = 0.0\n"
            "    for i in numba.prange(a.size):\n"
            "        s += a[i]\n"
            "    return s\n"
            "assert total(np.ones(1000)) == 1000.0\n"
            "print(numba.threading_layer())")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_THREADING_LAYER"}
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "tbb"
