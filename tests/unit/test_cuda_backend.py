"""The GPU backend against the CPU path, under numba-cuda's simulator (CI has no GPU).

The scene (``cuda_scene.py``): a 6 x 6 block, its upper part thrown sideways; crack elements
soften and break in a shear band from step 51 on, and the broken faces touch with friction.
The simulator process runs the GPU loops (``fdem.kernels.cuda_step``) over the CPU's laws in
plain Python (``NUMBA_DISABLE_JIT=1``, see ``cuda_scene.py``); the reference runs here with
Numba. Both sides are checkpointed and resumed by the other backend:

* CPU steps 0-50, checkpoint; GPU resumes it to step 62 (the first twelve breaks, contact
  activation, searches), checkpoint; CPU resumes that to step 70;
* GPU from step 0 to 24 with contact watching every softened element (the attach at the start,
  the first grid search, speculative batches that stand and batches refused and replayed);
* a stop rule that raises the strength reduction inside the run (the paper's reduction rate),
  GPU from the CPU's step-50 checkpoint to step 58;
* a quasi-static stage (density-scaled masses, mass-proportional and local damping), GPU from
  the CPU's step-50 checkpoint to step 56.

Every comparison is against the CPU run that was never interrupted. Breakage (which elements,
at which step), the contact pairs and which of them touch must be equal; the floating values
agree to round-off: the CPU kernels run with fastmath (fused multiply-adds; the crack kernels
also reassociate), the simulator in plain Python, and the GPU adds crack forces and block sums
with atomics in another order. Measured (steps 50-62, 8 elements broken, 96 pairs touching): positions 1e-16 m,
velocities 4e-12 m/s (of 3.2 m/s), damage 2e-13, the friction springs 2e-11 and the ledger's
terms 7e-13 of their largest value; over a 120-step run from the start (``python
tests/unit/cuda_scene.py``, 24 broken): 2e-14 m and 9e-10 m/s. The tolerances below are about
10^3-10^4 times the 12-step figures, far below anything physical (1e-8 m/s moves a node 1e-14 m
a step), and far above what the reordered sums can make.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cuda_scene
from fdem.solve.cuda_backend import BackendError, check_backend

pytest.importorskip("numba.cuda", reason="numba-cuda is not installed (pip install numba-cuda)")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CHECKPOINT, GPU_END, CPU_END = 50, 62, 70


def _gpu(*args, tmp: Path, simulator: bool = True) -> None:
    """Run ``cuda_scene.py cuda ...`` in a process of its own: the simulator's, or the real GPU's."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if simulator:
        env.update(NUMBA_ENABLE_CUDASIM="1", NUMBA_DISABLE_JIT="1", FDEM_CUDA_THREADS="32")
    r = subprocess.run([sys.executable, str(HERE / "cuda_scene.py"), "cuda", *map(str, args)], env=env,
                       capture_output=True, text=True, timeout=600, cwd=tmp)
    assert r.returncode == 0, r.stderr[-3000:]


def _cpu(*args) -> None:
    assert cuda_scene.main(["cpu", *map(str, args)]) == 0


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cuda")
    f = {name: tmp / f"{name}.npz" for name in ("ck50", "ck62g", "ref24", "ref62", "ref70", "gpu24", "gpu62",
                                                 "cpu70", "cpu50", "qs56", "gqs56", "ramp58", "gramp58", "bare", "gbare",
                                                 "hold58", "ghold58")}
    _cpu(f["cpu50"], "--steps", CHECKPOINT, "--save", f["ck50"])
    _gpu(f["gpu62"], "--steps", GPU_END, "--from", f["ck50"], "--save", f["ck62g"], tmp=tmp)
    _cpu(f["cpu70"], "--steps", CPU_END, "--from", f["ck62g"])
    _gpu(f["gpu24"], "--steps", 24, "--softening", "all", tmp=tmp)
    _gpu(f["gramp58"], "--steps", 58, "--from", f["ck50"], "--ramp", 1.6, tmp=tmp)
    _cpu(f["ramp58"], "--steps", 58, "--from", f["ck50"], "--ramp", 1.6)
    _gpu(f["ghold58"], "--steps", 58, "--from", f["ck50"], "--hold", tmp=tmp)
    _cpu(f["hold58"], "--steps", 58, "--from", f["ck50"], "--hold")
    _gpu(f["gbare"], "--steps", 8, "--bare", 3, tmp=tmp)
    _cpu(f["bare"], "--steps", 8, "--bare", 3)
    _gpu(f["gqs56"], "--steps", 56, "--from", f["ck50"], "--quasi-static", tmp=tmp)
    _cpu(f["qs56"], "--steps", 56, "--from", f["ck50"], "--quasi-static")
    for name, steps in (("ref62", GPU_END), ("ref70", CPU_END)):
        _cpu(f[name], "--steps", steps)
    _cpu(f["ref24"], "--steps", 24, "--softening", "all")
    return {name: dict(np.load(path)) for name, path in f.items() if not name.startswith("ck")}


def assert_same_run(a: dict, b: dict) -> None:
    """``a`` and ``b`` equal in every discrete outcome and to round-off in every number."""
    assert int(a["step"]) == int(b["step"])
    for key in ("broken", "event_elements", "event_steps", "pairs", "touching", "ledger_keys", "searches"):
        assert np.array_equal(a[key], b[key]), key
    assert np.abs(a["x"] - b["x"]).max() <= 1e-12                      # m
    assert np.abs(a["v"] - b["v"]).max() <= 1e-8                       # m/s
    assert np.abs(a["damage"] - b["damage"]).max() <= 1e-9
    assert np.abs(a["dissipated"] - b["dissipated"]).max() <= 1e-8 * max(1.0, np.abs(a["dissipated"]).max())
    scale = max(1.0, np.abs(a["history"]).max()) if a["history"].size else 1.0
    assert np.abs(a["history"] - b["history"]).max(initial=0.0) <= 1e-7 * scale   # friction springs [N/m]
    energy = max(1.0, np.abs(a["ledger"]).max())
    # the rows of the steps both have (a run split by a checkpoint books one more, at the split)
    common, ia, ib = np.intersect1d(a["ledger_steps"], b["ledger_steps"], return_indices=True)
    assert common.size >= min(a["ledger_steps"].size, b["ledger_steps"].size) - 1
    assert np.abs(a["ledger"][ia] - b["ledger"][ib]).max() <= 1e-9 * energy    # J/m
    assert np.allclose(a["energies"], b["energies"], rtol=1e-9, atol=1e-9 * energy)


def test_gpu_resumes_a_cpu_checkpoint_and_breaks_the_same_elements(runs):
    gpu, ref = runs["gpu62"], runs["ref62"]
    assert ref["broken"].sum() >= 5 and ref["touching"].sum() > 0  # the window holds breaks and contact
    assert gpu["device_searches"] >= 1  # grid searches made on the device give the CPU's pairs
    assert_same_run(gpu, ref)


def test_cpu_resumes_a_gpu_checkpoint(runs):
    assert_same_run(runs["cpu70"], runs["ref70"])


def test_gpu_from_the_start_with_speculative_batches(runs):
    """From the start, contact watching every softened element (``softening="all"``): the
    attach, the first grid search on the device (step 16, while the host still holds no pair),
    and batches of plain steps that stand (one round trip for several steps) and batches refused
    and replayed step by step (elements leaving the elastic range while the block is thrown)."""
    gpu = runs["gpu24"]
    ran, refused = gpu["batches"]
    assert ran >= 1 and refused >= 1
    assert gpu["device_searches"] >= 1 and len(gpu["pairs"]) > 0
    assert_same_run(gpu, runs["ref24"])


def test_a_stop_rule_that_changes_the_strength_mid_run_reaches_the_gpu(runs):
    """The paper's reduction rate changes the strength from the stage's stop rule, inside a run:
    the change must reach the device at once (here F = 1.25 -> 1.6 at the step-50 row)."""
    assert float(runs["gramp58"]["reduction"]) == float(runs["ramp58"]["reduction"]) == 1.6
    assert_same_run(runs["gramp58"], runs["ramp58"])


def test_a_stop_rule_that_holds_nodes_mid_run_reaches_the_gpu(runs):
    """A runout holds fly-rock from its stop rule (``hold_escaped``: both velocity components
    prescribed zero): the held nodes must stop on the device at once, the support's reaction
    booked as on the CPU (here the three highest triangles of the thrown block, held at the row
    of step 51 and carried to step 58)."""
    for run in (runs["ghold58"], runs["hold58"]):
        assert float(run["held_speed"]) == 0.0
    assert_same_run(runs["ghold58"], runs["hold58"])


def test_gpu_quasi_static_stage(runs):
    assert_same_run(runs["gqs56"], runs["qs56"])


def _real_gpu() -> bool:
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return False
    from numba import cuda

    return cuda.is_available()


@pytest.mark.skipif(not _real_gpu(), reason="no NVIDIA GPU on this machine (the simulator tests above run)")
def test_real_gpu_matches_cpu(runs, tmp_path):
    """The same comparison on the device itself (compiled kernels, hardware atomics)."""
    ck = tmp_path / "ck50.npz"
    _cpu(tmp_path / "cpu50.npz", "--steps", CHECKPOINT, "--save", ck)
    _gpu(tmp_path / "dev62.npz", "--steps", GPU_END, "--from", ck, tmp=tmp_path, simulator=False)
    assert_same_run(dict(np.load(tmp_path / "dev62.npz")), runs["ref62"])


def test_bare_steps_then_a_run_in_one_device_session(runs):
    """Bare steps leave the state on the device; a run inside the same session goes on from
    there (it neither uploads the host's older copy nor ends the session)."""
    assert_same_run(runs["gbare"], runs["bare"])


def test_unknown_backend_is_named():
    with pytest.raises(ValueError, match="backend must be one of cpu, cuda"):
        check_backend("opencl")


@pytest.mark.skipif(os.environ.get("NUMBA_ENABLE_CUDASIM") == "1", reason="the simulator counts as a GPU")
def test_cuda_without_a_gpu_stops_before_any_work():
    from numba import cuda

    if cuda.is_available():
        pytest.skip("this machine has a GPU")
    with pytest.raises(BackendError, match="needs an NVIDIA GPU"):
        cuda_scene.build("cuda")


def test_numpy_without_row_stack_gets_it_back_for_numba_cuda(monkeypatch):
    """numba-cuda 0.30 overloads ``np.row_stack``, which NumPy 2.5 removed: on such a node the
    first GPU compilation failed (seen on an H100, numpy 2.5.2, numba-cuda 0.30.4). The backend
    restores the name, as the function it always stood for."""
    from fdem.solve.cuda_backend import _numpy_aliases_for_numba_cuda

    monkeypatch.delattr(np, "row_stack", raising=False)
    assert "row_stack" not in vars(np)
    _numpy_aliases_for_numba_cuda()
    assert np.row_stack is np.vstack
