"""Where a GPU step's time goes: each kernel of ``--backend cuda`` timed on its own.

    python cases/benchmarks/gpu_kernel_times.py --intact 1000000 --fragmented 250000 --steps 200

The step figures of ``bench_gpu.py`` time whole steps; this one wraps every kernel of
:mod:`fdem.kernels.cuda_step` and :mod:`fdem.kernels.cuda_search` so that each launch is
bracketed by a device synchronisation, and adds up the wall time per kernel. The
synchronisations serialise what a step would overlap (launch latency against the previous
kernel), so the kernels' sum is an upper bound of their share, and the rest of the step
(``host``: Python, launches, copies) is what is left of the step's wall time. The scenes are
the two of ``bench_gpu.py``: the intact block (every interior edge a crack element) and the
fully fragmented block (every triangle a contactor), stepped ``--steps`` steps after a warm-up.
Prints a table and writes ``docs/benchmarks/gpu_kernel_times.json`` (not under the simulator).
"""
from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_gpu import SIMULATED, gpu_info, save  # noqa: E402
from records import record  # noqa: E402

from fdem.solve.cuda_backend import require_cuda  # noqa: E402
from fdem.solve.simulation import set_default_backend  # noqa: E402

SECONDS: dict[str, float] = defaultdict(float)
LAUNCHES: dict[str, int] = defaultdict(int)


class TimedKernel:
    """A kernel whose every launch is timed between two device synchronisations."""

    def __init__(self, name: str, kernel, cuda):
        self.name, self.kernel, self.cuda = name, kernel, cuda

    def __getitem__(self, config):
        launch = self.kernel[config]

        def timed(*args):
            self.cuda.synchronize()
            t0 = time.perf_counter()
            launch(*args)
            self.cuda.synchronize()
            SECONDS[self.name] += time.perf_counter() - t0
            LAUNCHES[self.name] += 1

        return timed


def wrap_kernels(cuda) -> None:
    """Replace every kernel of the two GPU modules by its timed wrapper (the backend looks them
    up on the module at each launch)."""
    from fdem.kernels import cuda_search, cuda_step

    for module in (cuda_step, cuda_search):
        for name in dir(module):
            if name.endswith("_kernel") and not isinstance(getattr(module, name), TimedKernel):
                setattr(module, name, TimedKernel(name, getattr(module, name), cuda))


def time_scene(label: str, sim, n_steps: int, cuda) -> dict:
    """Wall time per step and per kernel over ``n_steps`` steps of ``sim`` (after a warm-up of
    20 steps that compiles the kernels)."""
    def run(n):
        sim.run(n_steps=n, history_every=max(1, n), output_every=10 ** 9, energy_tolerance=None,
                final_output=False, progress=False)

    with sim.device_session():
        run(20)
        cuda.synchronize()
        SECONDS.clear()
        LAUNCHES.clear()
        t0 = time.perf_counter()
        run(n_steps)
        cuda.synchronize()
        wall = time.perf_counter() - t0
    per_step = {name: 1e3 * s / n_steps for name, s in sorted(SECONDS.items(), key=lambda kv: -kv[1])}
    kernels = sum(per_step.values())
    print(f"\n{label}: {sim.model.n_triangles:,} triangles, {n_steps} steps, {1e3 * wall / n_steps:.3f} ms/step")
    for name, ms in per_step.items():
        print(f"  {name:24s} {ms:8.3f} ms/step  ({LAUNCHES[name] / n_steps:.2f} launches/step)")
    print(f"  {'host and the rest':24s} {1e3 * wall / n_steps - kernels:8.3f} ms/step")
    return {"wall_ms_per_step": 1e3 * wall / n_steps, "kernel_ms_per_step": per_step,
            "launches_per_step": {k: v / n_steps for k, v in LAUNCHES.items()},
            "n_triangles": sim.model.n_triangles}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--intact", type=int, default=1_000_000, help="triangles of the intact block (0: skip)")
    ap.add_argument("--fragmented", type=int, default=250_000, help="triangles of the fragmented block (0: skip)")
    ap.add_argument("--steps", type=int, default=200)
    args = ap.parse_args(argv)
    cuda = require_cuda()
    set_default_backend("cuda")
    wrap_kernels(cuda)
    recs = []
    if args.intact:
        from bench_full_step import intact_block

        sim, _ = intact_block(args.intact)
        out = time_scene("intact block", sim, args.steps, cuda)
        recs.append(record("intact block: wall per step, kernels timed one by one", out["wall_ms_per_step"],
                           "ms/step", out["n_triangles"], None, **out))
    if args.fragmented:
        from bench_fragmented import fragmented_block, settle

        sim, _ = fragmented_block(args.fragmented)
        with sim.device_session():
            settle(sim, int(round((args.fragmented / 2) ** 0.5)))
        out = time_scene("fragmented block", sim, args.steps, cuda)
        recs.append(record("fragmented block: wall per step, kernels timed one by one", out["wall_ms_per_step"],
                           "ms/step", out["n_triangles"], None, **out))
    save("gpu_kernel_times", recs, **(gpu_info() if not SIMULATED else {}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
