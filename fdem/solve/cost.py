"""What a run will cost before it starts: steps, wall time and memory (``design.md`` section 6).

Two moments to check:

* **Before meshing** (nothing built yet): :func:`estimate_triangles` turns an area and an
  element size into a triangle count, and :func:`check_mesh_budget` refuses a mesh whose
  estimated memory exceeds the memory the machine has free, with the largest count that
  fits. A ``--size 0.02`` demo meshed 1.47 M triangles and ran out of memory after a minute.
* **After building, before stepping**: :func:`estimate_cost` reads the simulation's stable
  step and the limits it combines (:meth:`fdem.solve.simulation.Simulation.critical_dt`), the
  arrays it holds, and a cost per step (measured over a few steps on request, else the
  machine's documented rate), and gives steps and wall time for a simulated time;
  :func:`dt_warning` says when a penalty, not the triangles, sets a step far below theirs
  (penalties of 1e6 E cut the demo's step 4,700-fold: 73 M steps, without a word).

The figures of this machine (2 cores, ``docs/benchmarks.md``):

* :data:`SECONDS_PER_TRIANGLE_STEP`: a full intact step (crack elements, triangles,
  integration) at 22.3 M triangle-steps per second on one thread, plus
  :data:`SECONDS_PER_STEP_OVERHEAD` per step; contact in a fragmented mass is about 10x
  slower (2.4 M), so a runout costs more than these figures say.
* :func:`mesh_memory_bytes`: the process's peak resident memory (``resource.getrusage``
  ``ru_maxrss``) once the demo scene (:mod:`fdem.cases.quick_start`) has been meshed, started
  in static equilibrium (a sparse LU factorisation, the peak) and run for 20 steps, one fresh
  process per size, one Numba thread:

  ========= ========== ============= =========================== =====================
  size [m]  triangles  peak RSS [MB] above the 215 MB base [kB/tri] arrays held [kB/tri]
  ========= ========== ============= =========================== =====================
  1.0           929         214.4          --                           1.43
  0.3         7,761         236.7          2.9                          1.44
  0.15       29,348         313.0          3.4                          1.44
  0.1        59,979         429.4          3.6                          1.52
  0.07      123,403         709.5          4.0                          1.52
  0.05      238,227       1,277.6          4.5                          1.52
  0.035     490,381       2,667.3          5.0                          1.52
  ========= ========== ============= =========================== =====================

  The memory above the base grows as ``n^1.16`` (the exponent between each pair of the three
  largest of the first five meshes: 1.156, 1.161), the LU factor's fill-in growing faster
  than the mesh. Fitted on the first five, the law predicted 2,670 MB for the sixth (measured
  afterwards: 2,667 MB, 13 min); beyond 490 k triangles it is extrapolated (1.47 M: about 9 GB).
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["CostEstimate", "estimate_cost", "estimate_triangles", "mesh_memory_bytes", "available_memory",
           "check_mesh_budget", "dt_warning", "held_array_bytes", "SECONDS_PER_TRIANGLE_STEP", "SECONDS_PER_STEP_OVERHEAD",
           "PEAK_BYTES_PER_TRIANGLE", "PEAK_REFERENCE_TRIANGLES", "PEAK_EXPONENT", "BASE_PEAK_BYTES",
           "DT_WARNING_RATIO"]

SECONDS_PER_TRIANGLE_STEP = 1.0 / 22.3e6
"""Wall seconds per triangle per step of a full intact step (crack elements, triangles,
integration) on one thread of this machine: 22.3 M triangle-steps/s on 999,698 triangles
(``docs/benchmarks.md``, ``bench_full_step.py``). Contact between fragments is not in it."""

SECONDS_PER_STEP_OVERHEAD = 0.5e-3
"""Wall seconds of a step that do not grow with the mesh (the Python side of a step: providers,
guard, history), one thread: the quick-start scene's 1,503 triangles took 0.5-0.7 ms per damped
step (``fdem.cases.common``), of which the triangles account for 0.07 ms at the rate above;
measured again on its 929-triangle mesh at 1.0 ms/step with the machine loaded."""

PEAK_BYTES_PER_TRIANGLE = 4.46e3
"""Peak resident memory per triangle above :data:`BASE_PEAK_BYTES` [bytes] of a scene meshed,
started in static equilibrium and stepped, at :data:`PEAK_REFERENCE_TRIANGLES` triangles
(the demo scene at size 0.05 m; module docstring)."""

PEAK_REFERENCE_TRIANGLES = 238_227
"""The mesh :data:`PEAK_BYTES_PER_TRIANGLE` was measured on."""

PEAK_EXPONENT = 1.16
"""Growth of the peak memory above the base with the triangles, ``n^1.16`` (module docstring)."""

BASE_PEAK_BYTES = 215e6
"""Peak resident memory [bytes] of a process that has built a small scene: Python, numpy,
scipy, Numba and its compiled kernels, Gmsh (214.4 MB measured at 929 triangles, 105 MB of
it the imports)."""

DT_WARNING_RATIO = 10.0
""":func:`dt_warning` speaks when the governing stable step is this many times below the
triangles' own."""

_LABELS = {"CrackSet": "cracks", "ContactSet": "contact"}


@dataclass
class CostEstimate:
    """The cost of running a simulation (:func:`estimate_cost`).

    n_triangles, n_cracks, n_nodes : sizes of the model (crack elements: 0 without a CrackSet)
    dt : the time step the simulation uses [s] (``dt_fraction`` times the critical step)
    dt_limits : critical step of each source [s], by name (``triangles``, ``cracks``,
        ``contact``, ...), as :meth:`~fdem.solve.simulation.Simulation.critical_dt` combines them
    governing : the source with the smallest limit, the one that sets the step
    steps_per_simulated_second : ``1 / dt``
    memory_bytes : bytes of the numpy arrays the simulation holds now (contact pairs grow as
        the mass fragments)
    peak_memory_bytes : projected peak resident memory of a process that meshed and runs this
        model (:func:`mesh_memory_bytes`)
    seconds_per_step : wall seconds per step [s]
    seconds_per_step_source : ``"measured"`` (a short run of this simulation) or
        ``"benchmark"`` (:data:`SECONDS_PER_STEP_OVERHEAD` plus :data:`SECONDS_PER_TRIANGLE_STEP`
        times the triangles)
    simulated_seconds : the simulated time the wall time is for [s], or ``None``
    steps : steps for ``simulated_seconds`` (``None`` without it)
    wall_seconds : wall time for ``simulated_seconds`` [s] (``None`` without it)
    """

    n_triangles: int
    n_cracks: int
    n_nodes: int
    dt: float
    dt_limits: dict = field(default_factory=dict)
    governing: str = "triangles"
    steps_per_simulated_second: float = math.nan
    memory_bytes: int = 0
    peak_memory_bytes: int = 0
    seconds_per_step: float = math.nan
    seconds_per_step_source: str = "benchmark"
    simulated_seconds: float | None = None
    steps: int | None = None
    wall_seconds: float | None = None

    def as_dict(self) -> dict:
        return asdict(self)

    def describe(self) -> str:
        """Two lines for a person: the model and its step, then steps, wall time and memory."""
        limits = ", ".join(f"{k} {v:.3g} s" for k, v in self.dt_limits.items())
        first = (f"{self.n_triangles:,} triangles, {self.n_cracks:,} crack elements, {self.n_nodes:,} nodes; "
                 f"dt {self.dt:.3g} s set by {self.governing} (limits: {limits})")
        if self.simulated_seconds is None:
            span = f"{self.steps_per_simulated_second:,.0f} steps per simulated second"
        else:
            span = (f"{self.steps:,} steps for {self.simulated_seconds:g} s simulated, about "
                    f"{_duration(self.wall_seconds)}")
        second = (f"{span} at {1e3 * self.seconds_per_step:.3g} ms/step ({self.seconds_per_step_source}); "
                  f"arrays {_bytes(self.memory_bytes)}, peak memory about {_bytes(self.peak_memory_bytes)}")
        return first + "\n" + second


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.3g} s"
    if seconds < 7200:
        return f"{seconds / 60:.3g} min"
    return f"{seconds / 3600:.3g} h"


def _bytes(n: float) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


def estimate_triangles(area_m2: float, size_m: float) -> int:
    """Triangles of a mesh of ``area_m2`` [m^2] at element size ``size_m`` [m], counted as
    equilateral triangles of side ``h``: ``area / (sqrt(3)/4 h^2)`` (rounded up). Gmsh's
    frontal meshes come within tens of per cent of it; joints refine locally, so treat it as
    an order of magnitude."""
    if not (math.isfinite(area_m2) and area_m2 > 0):
        raise ValueError(f"estimate_triangles: area must be a positive number of m^2, got {area_m2}")
    if not (math.isfinite(size_m) and size_m > 0):
        raise ValueError(f"estimate_triangles: element size must be a positive number of metres, got {size_m}")
    n = area_m2 / (math.sqrt(3.0) / 4.0) / size_m / size_m      # in this order: h^2 may underflow to 0
    return int(math.ceil(n)) if n < 2.0 ** 62 else 2 ** 62


def mesh_memory_bytes(n_triangles: int) -> float:
    """Projected peak resident memory [bytes] of meshing, starting and running ``n`` triangles:
    ``BASE_PEAK_BYTES + PEAK_BYTES_PER_TRIANGLE * n * (n / PEAK_REFERENCE_TRIANGLES)^(PEAK_EXPONENT - 1)``
    (within 8 % of the measured peaks above the base from 7,761 to 238,227 triangles)."""
    n = max(float(n_triangles), 0.0)
    return BASE_PEAK_BYTES + PEAK_BYTES_PER_TRIANGLE * n * (n / PEAK_REFERENCE_TRIANGLES) ** (PEAK_EXPONENT - 1.0)


def available_memory() -> int | None:
    """Memory the machine has free now [bytes]: ``MemAvailable`` of ``/proc/meminfo`` (free
    plus reclaimable caches), else ``os.sysconf`` free pages times the page size; ``None``
    where neither is readable."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_mesh_budget(n_triangles_estimated: int, memory_available: int | None = None) -> float:
    """Refuse, before meshing, a mesh whose projected peak memory (:func:`mesh_memory_bytes`)
    exceeds ``memory_available`` [bytes] (default :func:`available_memory`): a ``ValueError``
    naming the estimate, the memory and the largest triangle count that fits. Returns the
    projected bytes. With no way to read the free memory the check passes (nothing to compare
    against) and says nothing."""
    need = mesh_memory_bytes(n_triangles_estimated)
    free = available_memory() if memory_available is None else memory_available
    if free is None:
        return need
    if need > free:
        fits = _largest_fitting(free)
        raise ValueError(f"the mesh would have about {n_triangles_estimated:,} triangles and need about "
                         f"{_bytes(need)} of memory at its peak (meshing, static start; measured on this machine up "
                         f"to 238 k triangles), but only {_bytes(free)} is available: at most about {fits:,} "
                         f"triangles fit; use a larger element size")
    return need


def _largest_fitting(free: float) -> int:
    """The most triangles whose projected peak memory fits in ``free`` [bytes] (bisection)."""
    lo, hi = 0, 1
    while mesh_memory_bytes(hi) <= free and hi < 2 ** 62:
        lo, hi = hi, 2 * hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if mesh_memory_bytes(mid) <= free else (lo, mid)
    return lo


def held_array_bytes(sim) -> int:
    """Bytes of the numpy arrays reachable from ``sim`` through the attributes of ``fdem``
    objects (the simulation, its state, model, topology, mesh and force providers) and the
    lists, tuples and dicts they hold; each underlying buffer counted once."""
    seen_objects: set[int] = set()
    buffers: dict[int, int] = {}

    def visit(obj, depth: int) -> None:
        if depth > 6 or id(obj) in seen_objects:
            return
        seen_objects.add(id(obj))
        if isinstance(obj, np.ndarray):
            base = obj
            while isinstance(base.base, np.ndarray):
                base = base.base
            buffers[id(base)] = base.nbytes
            return
        if isinstance(obj, dict):
            for v in obj.values():
                visit(v, depth + 1)
            return
        if isinstance(obj, (list, tuple)):
            for v in obj[:10_000]:
                visit(v, depth + 1)
            return
        module = type(obj).__module__ or ""
        if module.startswith("fdem."):
            attrs = dict(getattr(obj, "__dict__", {}))
            for name in getattr(type(obj), "__slots__", ()):
                if hasattr(obj, name):
                    attrs[name] = getattr(obj, name)
            for v in attrs.values():
                visit(v, depth + 1)

    visit(sim, 0)
    return int(sum(buffers.values()))


def _measured_seconds_per_step(sim, steps: int) -> float:
    """Wall seconds per step of ``steps`` steps of ``sim``, which is then put back as it was
    (:func:`fdem.solve.checkpoint.snapshot` / ``restore``). One step first, untimed, so that a
    kernel compiled on first call does not count."""
    from fdem.solve.checkpoint import restore, snapshot

    start = snapshot(sim)
    history = list(sim.history) if hasattr(sim, "history") else None
    progress = sim.progress
    sim.progress = False
    try:
        sim.run(n_steps=1, energy_tolerance=None, output_every=10**9, history_every=10**9, final_output=False)
        t0 = time.perf_counter()
        sim.run(n_steps=steps, energy_tolerance=None, output_every=10**9, history_every=10**9, final_output=False)
        return (time.perf_counter() - t0) / steps
    finally:
        restore(sim, start)
        sim.progress = progress
        if history is not None:
            sim.history[:] = history


def estimate_cost(sim, simulated_seconds: float | None = None, steps_per_second_measured: float | None = None,
                  measure_steps: int = 0) -> CostEstimate:
    """The cost of running ``sim`` (a built :class:`~fdem.solve.simulation.Simulation`).

    ``simulated_seconds`` [s]: the simulated time to price (steps and wall time); ``None``: per
    simulated second only. Seconds per step: ``1 / steps_per_second_measured`` when given (a
    rate the caller measured); else, with ``measure_steps = n > 0``, ``n`` steps run now (about
    20 is enough; the simulation is restored afterwards, so nothing it holds changes); else the
    benchmark figures, :data:`SECONDS_PER_STEP_OVERHEAD` plus :data:`SECONDS_PER_TRIANGLE_STEP`
    times the triangles (intact; a fragmenting run costs more).
    """
    if simulated_seconds is not None and not (math.isfinite(simulated_seconds) and simulated_seconds >= 0):
        raise ValueError(f"estimate_cost: simulated_seconds must be a non-negative number, got {simulated_seconds}")
    if steps_per_second_measured is not None and not (math.isfinite(steps_per_second_measured)
                                                      and steps_per_second_measured > 0):
        raise ValueError(f"estimate_cost: steps_per_second_measured must be positive, got {steps_per_second_measured}")
    topo = sim.model.topology
    n_tri = int(topo.n_triangles)
    cracks = getattr(sim, "cracks", None)
    _, raw = sim.critical_dt()
    limits = {_LABELS.get(k, k): float(v) for k, v in raw.items()}
    governing = min(limits, key=limits.get)
    dt = float(sim.dt)
    if steps_per_second_measured is not None:
        per_step, source = 1.0 / steps_per_second_measured, "measured"
    elif measure_steps > 0:
        per_step, source = _measured_seconds_per_step(sim, int(measure_steps)), "measured"
    else:
        per_step, source = SECONDS_PER_STEP_OVERHEAD + SECONDS_PER_TRIANGLE_STEP * n_tri, "benchmark"
    steps = wall = None
    if simulated_seconds is not None:
        steps = int(math.ceil(simulated_seconds / dt - 1e-9))
        wall = steps * per_step
    return CostEstimate(
        n_triangles=n_tri, n_cracks=int(cracks.n_cracks) if cracks is not None else 0, n_nodes=int(topo.n_nodes),
        dt=dt, dt_limits=limits, governing=governing, steps_per_simulated_second=1.0 / dt,
        memory_bytes=held_array_bytes(sim), peak_memory_bytes=int(mesh_memory_bytes(n_tri)),
        seconds_per_step=per_step, seconds_per_step_source=source, simulated_seconds=simulated_seconds,
        steps=steps, wall_seconds=wall)


def dt_warning(estimate: CostEstimate) -> str | None:
    """A sentence when the governing stable step is more than :data:`DT_WARNING_RATIO` times
    below the triangles' own (a crack or contact penalty far stiffer than the rock), else
    ``None``."""
    tri = estimate.dt_limits.get("triangles")
    low = estimate.dt_limits.get(estimate.governing)
    if tri is None or low is None or not low > 0 or tri / low <= DT_WARNING_RATIO:
        return None
    per_second = estimate.steps_per_simulated_second
    return (f"the stable step is {tri / low:,.0f}x below the triangles' own ({low:.3g} s against {tri:.3g} s): "
            f"the {estimate.governing} penalty sets it, so a simulated second takes {per_second:,.0f} steps; "
            f"a penalty of 10-100 E (Munjiza's alpha) keeps the step near the triangles'")
