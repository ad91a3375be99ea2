"""The GPU backend's figures (``--backend cuda``), one command each, on an NVIDIA GPU.

    python cases/benchmarks/bench_gpu.py intact --triangles 1000000      # goal >= 1e9 triangle-steps/s
    python cases/benchmarks/bench_gpu.py fragmented --triangles 250000   # goal >= 1e8 triangle-steps/s
    python cases/benchmarks/bench_gpu.py workflow                        # 180k four slopes to rest, goal <= 15 min

``intact``: the structured block of ``bench_full_step.py`` (every interior edge an intact crack
element, gravity, fixed base), stepped on the device (:meth:`Simulation.device_session`: state
on the GPU, two round trips a step). ``fragmented``: the block of ``bench_fragmented.py``, every
crack broken and every triangle a contactor, settled first so that the pairs overlap.
``workflow``: ``fdem run four-slopes --size 0.18 --backend cuda`` (the low-angle fine slope,
the default workflow, runout to rest with no cap), its wall time, steps and bracket.

Each writes ``docs/benchmarks/gpu_<figure>.json`` with the device, its driver and the
numba-cuda version; the CPU figures of the same scenes are in ``full_step.json`` and
``fragmented.json``. The step figures time ``Simulation.run`` in chunks of 256 steps and record
the host round trips per step; ``--max-batch 1`` measures them without speculative batches.
A machine without a GPU stops at once with the backend's error.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import records  # noqa: E402
from records import best_rate, record  # noqa: E402

from fdem.solve.cuda_backend import BackendError, require_cuda  # noqa: E402
from fdem.solve.simulation import set_default_backend  # noqa: E402


def gpu_info() -> dict:
    """The device the figures were measured on."""
    cuda = require_cuda()
    import numba

    try:
        import numba_cuda

        nc_version = numba_cuda.__version__
    except ImportError:
        nc_version = "built-in"
    dev = cuda.get_current_device()
    name = getattr(dev, "name", "numba-cuda simulator")
    name = name.decode() if isinstance(name, bytes) else str(name)
    try:
        driver = ".".join(map(str, cuda.cudadrv.driver.driver.get_version()))
    except Exception:  # the driver's version call differs between bindings
        driver = "unknown"
    return {"gpu": name, "compute_capability": list(dev.compute_capability), "cuda_driver": driver,
            "numba": numba.__version__, "numba_cuda": nc_version}


SIMULATED = os.environ.get("NUMBA_ENABLE_CUDASIM") == "1"


def save(name: str, recs: list[dict], **meta) -> None:
    """Save the records (``records.save``); under numba-cuda's simulator only print them: the
    simulator checks the script, its timings say nothing about a GPU."""
    if SIMULATED:
        for r in recs:
            print(f"(simulator, not saved) {r['what']}: {r['value']:.4g} {r['unit']}")
        return
    records.save(name, recs, **meta)


def _rate(sim, n_tri: int, seconds: float, repeats: int, max_batch: int) -> tuple[float, dict]:
    """Triangle-steps per second of ``sim.run`` in chunks of 256 steps (history rows at the chunk
    ends, as a run has them), and the round trips per step."""
    dev = sim._device
    dev.max_batch = max_batch
    dev.batch_limit = min(dev.batch_limit, max_batch)
    chunk = 256
    step0, trips0 = sim.state.step, dev.round_trips

    def run_chunk():
        sim.run(n_steps=chunk, history_every=chunk, output_every=10 ** 9, energy_tolerance=None,
                final_output=False, progress=False)

    rate = best_rate(run_chunk, n_tri * chunk, seconds, repeats)
    steps = max(1, sim.state.step - step0)
    return rate, {"round_trips_per_step": (dev.round_trips - trips0) / steps, "max_batch": max_batch,
                  "batches_run": dev.batches_run, "batches_refused": dev.batches_refused}


def intact(args) -> None:
    from bench_full_step import intact_block

    sim, _ = intact_block(args.triangles)
    n_tri = sim.model.n_triangles
    rate, extra = _rate(sim, n_tri, args.seconds, args.repeats, args.max_batch)
    save("gpu_intact", [record("full intact step on the GPU (cracks + triangles + integration)", rate,
                               "triangle-steps/s", n_tri, None, n_crack_elements=sim.model.topology.n_cracks,
                               goal=1e9, **extra)], **gpu_info())


def fragmented(args) -> None:
    from bench_fragmented import fragmented_block, settle

    sim, contact = fragmented_block(args.triangles)
    n_rows = int(round((args.triangles / 2) ** 0.5))
    with sim.device_session():
        settle(sim, n_rows)
    n_tri = sim.model.n_triangles
    rate, extra = _rate(sim, n_tri, args.seconds, args.repeats, args.max_batch)
    save("gpu_fragmented", [record("fully fragmented step on the GPU (contact + triangles + integration)", rate,
                                   "triangle-steps/s", n_tri, None, pairs=int(contact.n_pairs),
                                   touching=int(contact.n_touching), goal=1e8, **extra)], **gpu_info())


def workflow(args) -> None:
    from fdem.cases.four_slopes import main as four_slopes

    out = Path(args.out)
    t0 = time.perf_counter()
    summary = four_slopes(["--size", str(args.size), "--backend", "cuda", "--out", str(out), "--yes",
                           "--no-pictures", "--overwrite", *(["--threads", str(args.threads)] if args.threads else [])])
    wall = time.perf_counter() - t0
    fos = summary.get("fos", {}) if isinstance(summary, dict) else {}
    save("gpu_workflow", [record("four slopes (low angle, fine) through the default workflow to rest on the GPU",
                                 wall, "s wall", summary.get("n_triangles") if isinstance(summary, dict) else None,
                                 args.threads, size=args.size, bracket=fos.get("bracket"),
                                 outcome=summary.get("outcome") if isinstance(summary, dict) else None,
                                 goal=900.0, run_folder=str(out))], **gpu_info())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="figure", required=True)
    for name, default in (("intact", 1_000_000), ("fragmented", 250_000)):
        p = sub.add_parser(name)
        p.add_argument("--triangles", type=int, default=default)
        p.add_argument("--seconds", type=float, default=2.0, help="timing window of each sample")
        p.add_argument("--repeats", type=int, default=3)
        p.add_argument("--max-batch", type=int, default=64,
                       help="longest speculative batch of steps per round trip (1: none, one round trip a step)")
    p = sub.add_parser("workflow")
    p.add_argument("--size", type=float, default=0.18)
    p.add_argument("--out", default="runs/gpu_four_slopes")
    p.add_argument("--threads", type=int, default=None, help="CPU threads for meshing and host work")
    args = ap.parse_args(argv)
    try:
        set_default_backend("cuda")
    except BackendError as err:
        print(f"bench_gpu: {err}", file=sys.stderr)
        return 2
    {"intact": intact, "fragmented": fragmented, "workflow": workflow}[args.figure](args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
