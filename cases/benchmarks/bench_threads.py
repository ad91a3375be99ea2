"""Threads on a shared 2-core machine: does a second Numba thread pay, and under which threading
layer and wait policy, when the other core is busy with another job?

Scene: the low-angle fine four-slope scene at ``--size`` (the case's own build: renumbered mesh,
static start), crack elements held elastic, the scene's fundamental damping, contact dormant: the
step of a slope's quasi-static stages. Each variant runs in its own process (Numba fixes its
threading layer and pool size at the first parallel call), times ``--repeats`` blocks of
``--steps`` steps after a warm-up and reports the best block in ms per step. Variants: threads 1
or 2; layer ``omp`` (GNU OpenMP) with ``OMP_WAIT_POLICY`` unset (GOMP spins a while, then
sleeps), ``active`` (spins) or ``passive`` (sleeps at once); ``workqueue`` (Numba's own pool);
``tbb`` where the ``tbb`` package is installed.

Two situations: **idle** (the machine otherwise quiet) and **shared** (a competitor process
steps the same scene on one thread, at the same priority, for the whole measurement: the
"another job on the second core" of a laptop or a CI runner). A second thread that loses in the
shared situation costs the user wall time; the case scripts' thread choice
(:func:`fdem.cases.common.threads_for_mesh`) should follow what this measures.

    python cases/benchmarks/bench_threads.py --size 0.5 --situations idle shared [--tbb-lib DIR]

Prints a table and writes ``docs/benchmarks/threads.json`` (machine, load before and after each
variant). Other jobs on the machine spoil both situations: stop them first.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from records import record, save  # noqa: E402

VARIANTS = {
    "1 thread": {"NUMBA_NUM_THREADS": "1", "NUMBA_THREADING_LAYER": "omp"},
    "2 threads, omp": {"NUMBA_NUM_THREADS": "2", "NUMBA_THREADING_LAYER": "omp"},
    "2 threads, omp active": {"NUMBA_NUM_THREADS": "2", "NUMBA_THREADING_LAYER": "omp", "OMP_WAIT_POLICY": "active"},
    "2 threads, omp passive": {"NUMBA_NUM_THREADS": "2", "NUMBA_THREADING_LAYER": "omp",
                               "OMP_WAIT_POLICY": "passive"},
    "2 threads, workqueue": {"NUMBA_NUM_THREADS": "2", "NUMBA_THREADING_LAYER": "workqueue"},
    "2 threads, tbb": {"NUMBA_NUM_THREADS": "2", "NUMBA_THREADING_LAYER": "tbb"},
}


def worker(size: float, steps: int, repeats: int, forever: bool = False) -> dict:
    """Build the scene, step it; the best block's ms per step (or step until killed)."""
    import numba

    from fdem.cases import four_slopes
    from fdem.workflow.fos import fundamental_damping

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        geometry, _, topo = four_slopes.build("low", "fine", size)
        sim, cracks = four_slopes.simulation(geometry, topo, None, pictures=False, progress=False)
    cracks.hold_elastic(True)
    sim.monitors.clear()
    damping = fundamental_damping(sim)
    for _ in range(20):  # warm-up: compilation, first touch
        sim.step(damping)
    if forever:
        while True:
            sim.step(damping)
    blocks = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            sim.step(damping)
        blocks.append(1e3 * (time.perf_counter() - t0) / steps)
    return {"ms_per_step": min(blocks), "blocks_ms": blocks, "n_triangles": topo.n_triangles,
            "threading_layer": numba.threading_layer(), "threads": numba.get_num_threads()}


def measure(name: str, env: dict, size: float, steps: int, repeats: int, shared: bool,
            tbb_lib: str | None = None) -> dict | None:
    base = {k: v for k, v in os.environ.items() if k not in ("NUMBA_NUM_THREADS", "NUMBA_THREADING_LAYER",
                                                            "OMP_WAIT_POLICY")}
    if tbb_lib and env.get("NUMBA_THREADING_LAYER") == "tbb":  # libtbb.so.12 from the tbb wheel, not installed
        env = {**env, "LD_LIBRARY_PATH": os.pathsep.join(filter(None, [tbb_lib, os.environ.get("LD_LIBRARY_PATH")]))}
    competitor = None
    if shared:  # the other job: one thread, same priority, the same kind of work
        competitor = subprocess.Popen([sys.executable, __file__, "--worker", "--forever", "--size", str(size)],
                                      env={**base, "NUMBA_NUM_THREADS": "1", "NUMBA_THREADING_LAYER": "omp"},
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(8.0)  # it builds its scene and is stepping before the measurement begins
    load = os.getloadavg()[0]
    try:
        out = subprocess.run([sys.executable, __file__, "--worker", "--size", str(size), "--steps", str(steps),
                              "--repeats", str(repeats)], env={**base, **env}, capture_output=True, text=True)
    finally:
        if competitor is not None:
            competitor.kill()
            competitor.wait()
    if out.returncode != 0:
        print(f"{name}: failed ({out.stderr.strip().splitlines()[-1] if out.stderr.strip() else out.returncode})")
        return None
    r = json.loads(out.stdout.strip().splitlines()[-1])
    r.update({"variant": name, "situation": "shared" if shared else "idle", "env": env, "load_before": load,
              "load_after": os.getloadavg()[0]})
    return r


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=float, default=0.5, help="element size [m] (default 0.5: 22,600 triangles)")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--situations", nargs="+", choices=["idle", "shared"], default=["idle", "shared"])
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--label", default="threads")
    parser.add_argument("--tbb-lib", default=None, metavar="DIR",
                        help="folder holding libtbb.so.12 (e.g. the tbb wheel's data/lib unpacked) for the tbb "
                             "variant, when tbb is not installed in the environment")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--forever", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.size, args.steps, args.repeats, args.forever)))
        return []
    rows = []
    for situation in args.situations:
        for name in args.variants:
            r = measure(name, VARIANTS[name], args.size, args.steps, args.repeats, situation == "shared",
                        args.tbb_lib)
            if r is not None:
                rows.append(r)
                print(f"{situation:6s} {name:24s} {r['ms_per_step']:8.3f} ms/step  (layer {r['threading_layer']}, "
                      f"load {r['load_before']:.1f}-{r['load_after']:.1f})", flush=True)
    one = {r["situation"]: r["ms_per_step"] for r in rows if r["variant"] == "1 thread"}
    for r in rows:
        if r["situation"] in one:
            r["speedup_over_1_thread"] = one[r["situation"]] / r["ms_per_step"]
    records = [record(f"{r['situation']}: {r['variant']}", r["ms_per_step"], "ms/step", r["n_triangles"], r["threads"],
                      speedup_over_1_thread=r.get("speedup_over_1_thread")) for r in rows]
    save(args.label, records, size=args.size, steps=args.steps, repeats=args.repeats, runs=rows)
    return rows


if __name__ == "__main__":
    main()
