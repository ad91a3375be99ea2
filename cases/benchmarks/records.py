"""Shared benchmark bookkeeping: every figure is a record naming what was measured, the mesh
size, the thread count, the value, its unit and the machine, saved as JSON under docs/benchmarks/."""
from __future__ import annotations

import json
import os
import platform
from datetime import datetime, timezone
from pathlib import Path

DOCS = Path(__file__).resolve().parents[2] / "docs" / "benchmarks"


def machine() -> dict:
    """What the figures were measured on."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "logical_cores": os.cpu_count(), "python": platform.python_version(),
            "system": f"{platform.system()} {platform.release()}"}


def record(what: str, value: float, unit: str, mesh_size: int | None = None, threads: int | None = None,
           **extra) -> dict:
    rec = {"what": what, "mesh_size": mesh_size, "threads": threads, "value": value, "unit": unit}
    rec.update(extra)
    return rec


def save(name: str, records: list[dict], **meta) -> Path:
    """Write ``docs/benchmarks/<name>.json`` and print each record."""
    DOCS.mkdir(parents=True, exist_ok=True)
    path = DOCS / f"{name}.json"
    doc = {"benchmark": name, "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
           "machine": machine(), **meta, "records": records}
    path.write_text(json.dumps(doc, indent=2))
    for r in records:
        size = f" mesh {r['mesh_size']}" if r.get("mesh_size") is not None else ""
        thr = f" threads {r['threads']}" if r.get("threads") is not None else ""
        print(f"{r['what']}:{size}{thr} -> {r['value']:.6g} {r['unit']}")
    print(f"wrote {path}")
    return path


def best_rate(step, items_per_call: int, seconds: float = 1.0, repeats: int = 5) -> float:
    """Items per second of ``step()``: best of ``repeats`` timings of as many calls as fill about
    ``seconds``. The first call is a warm-up (Numba compilation, first touch of memory); the best
    sample is the one least disturbed by other processes."""
    import time

    step()
    n_calls = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(n_calls):
            step()
        elapsed = time.perf_counter() - t0
        if elapsed > 0.05:
            break
        n_calls *= 4
    n_calls = max(1, int(n_calls * seconds / elapsed))
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n_calls):
            step()
        best = min(best, (time.perf_counter() - t0) / n_calls)
    return items_per_call / best
