"""Every GPU kernel compiles to PTX for a Hopper GPU (sm_90), with the argument types the
backend launches it with: the laws the CPU loops call are valid CUDA device code.

The simulator tests (``test_cuda_backend.py``) run the kernels as Python, which would accept
code that the CUDA compiler refuses (a NumPy ufunc without a CUDA version, a tuple indexed by a
variable); this test compiles them for real. It needs the CUDA compiler libraries (NVVM and
NVRTC: ``pip install -e ".[cuda]"``), not a GPU, and is skipped where they are missing (CI).
A kernel calling a CPU ``@njit`` law makes numba-cuda compile that law for the device on the
fly, and it asks the current GPU for its compute capability; with no GPU the test answers
(9, 0) for it.
"""
from __future__ import annotations

import os
import types

import pytest

if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
    pytest.skip("the simulator compiles nothing", allow_module_level=True)
cuda = pytest.importorskip("numba.cuda", reason="numba-cuda is not installed")

from numba import boolean, float64, int8, int32, int64, uint8  # noqa: E402

A2 = float64[:, :]
SIGNATURES = {
    "step_kernel": (A2, A2, A2, A2, A2, A2, boolean, A2, boolean, uint8[:], A2, float64, float64, float64, float64,
                    float64, boolean, boolean, float64[:]),
    "crack_kernel": (A2, A2, A2, int32[:, :], A2, int8[:], A2, A2, A2, A2, int64[:], int8[:], float64[:]),
    "contact_kernel": (A2, A2, int64[:], int64[:], int64[:], float64, float64[:], A2, float64, float64[:], float64[:],
                       float64, A2, A2, uint8[:], uint8[:], A2, float64[:]),
    "gather_kernel": (A2, int64[:], int64[:], int64[:], A2, uint8[:]),
    "moved_kernel": (A2, A2, int64[:], float64[:]),
    "zero_kernel": (A2,),
}
I2 = int64[:, :]
SEARCH_SIGNATURES = {
    "boxes_kernel": (A2, int64[:], float64, A2, float64[:]),
    "bin_count_kernel": (A2, float64, float64, float64, int64, int64[:]),
    "bin_fill_kernel": (A2, float64, float64, float64, int64, int64[:], int64[:], int64[:]),
    "partner_count_kernel": (A2, int64[:], I2, A2, float64, float64, float64, float64, int64, int64[:], int64[:],
                             int64[:], int64[:]),
    "partner_fill_kernel": (A2, int64[:], I2, A2, float64, float64, float64, float64, int64, int64[:], int64[:],
                            int64[:], int64[:], int64[:]),
    "pair_kernel": (int64[:], int64[:], int64, int64[:], A2, int64[:], A2, uint8[:], int64[:], int64[:],
                    uint8[:], float64[:], boolean, float64[:], float64[:], float64, float64[:], float64[:],
                    float64[:]),
    "incidence_count_kernel": (int64[:], int64[:], int64[:]),
    "incidence_fill_kernel": (int64[:], int64[:], int64[:], int64[:], int64[:]),
    "incidence_sort_kernel": (int64[:], int64[:]),
}


@pytest.fixture(scope="module")
def kernels():
    try:
        from numba.cuda.cudadrv import nvvm

        nvvm.NVVM()
    except Exception as exc:  # no NVVM library: nothing to compile with
        pytest.skip(f"the CUDA compiler libraries are not installed ({type(exc).__name__})")
    import numba.cuda.dispatcher as dispatcher

    real = dispatcher.get_current_device
    dispatcher.get_current_device = lambda: types.SimpleNamespace(compute_capability=(9, 0))
    try:
        from fdem.kernels import cuda_search, cuda_step
        from fdem.solve.cuda_backend import _numpy_aliases_for_numba_cuda

        _numpy_aliases_for_numba_cuda()  # what the backend does before any GPU work (NumPy 2.5)
        yield {**{n: getattr(cuda_step, n) for n in SIGNATURES}, **{n: getattr(cuda_search, n) for n in SEARCH_SIGNATURES}}
    finally:
        dispatcher.get_current_device = real


@pytest.mark.parametrize("name", sorted(SIGNATURES) + sorted(SEARCH_SIGNATURES))
def test_kernel_compiles_for_sm90(kernels, name):
    kernel = kernels[name]
    try:
        ptx, _ = cuda.compile_ptx(kernel.py_func, {**SIGNATURES, **SEARCH_SIGNATURES}[name], cc=(9, 0))
    except Exception as exc:
        if "nvrtc" in str(exc).lower() or "DynamicLibNotFound" in type(exc).__name__:
            pytest.skip(f"the CUDA compiler libraries are incomplete: {exc}")
        raise
    assert ".target sm_90" in ptx and ".entry" in ptx


def test_signatures_cover_every_kernel():
    from fdem.kernels import cuda_search, cuda_step

    assert set(SIGNATURES) == {n for n in cuda_step.__all__ if n.endswith("_kernel")}
    assert set(SEARCH_SIGNATURES) == {n for n in cuda_search.__all__ if n.endswith("_kernel")}
