"""Memory order: the four-slope scene stepped in Gmsh's numbering and renumbered along a curve.

Builds the low-angle fine four-slope scene (:mod:`fdem.cases.four_slopes`: static geostatic
start, crack elements held elastic, contact) at ``--size`` once per variant
(``--variants``, :data:`VARIANTS`: ``before``, Gmsh's numbering with the crack set's old internal
order; ``gmsh``, Gmsh's numbering; ``hilbert`` or ``morton``, :func:`fdem.mesh.order.renumber`), and
the structured intact block of ``bench_full_step.py`` with as many triangles. Each is stepped
with the scene's fundamental damping (:func:`fdem.workflow.fos.fundamental_damping`); the
variants take turns, ``--repeats`` blocks of ``--steps`` steps each, so that a change of load on
the shared machine falls on all of them. The best block of each is reported, split as
``profile_scene.py`` does by timers wrapped around the providers and the solver's triangle
kernel (the solver is not changed):

* ``crack pass``: :meth:`CrackSet.add_forces` (and its rate, crack elements updated per second);
* ``contact``: :meth:`ContactSet.add_forces` (dormant while nothing is broken);
* ``triangle step``: the fused triangle + integration kernel;
* ``other``: the rest of :meth:`Simulation.step`.

Also the crack pass alone, best of 5 (``records.best_rate``, as ``bench_full_step.py``), and how
far apart in memory the two triangles of a crack element are (median ``|t_A - t_B|``).

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_memory_order.py --size 0.5 --steps 300
    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_memory_order.py --size 0.18 --steps 200

Writes ``docs/benchmarks/memory_order.json`` (the runs of other sizes already there are kept).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_full_step import intact_block  # noqa: E402
from records import DOCS, best_rate, record, save  # noqa: E402

import fdem.physics.cracks as cracks_mod  # noqa: E402
import fdem.solve.simulation as solver_mod  # noqa: E402
from fdem.cases import four_slopes  # noqa: E402
from fdem.workflow.fos import fundamental_damping  # noqa: E402

PARTS = ("crack pass", "contact", "triangle step", "other")
VARIANTS = {"before": (None, True), "gmsh": (None, False), "hilbert": ("hilbert", False), "morton": ("morton", False)}
"""Scene variants: (mesh order, crack set's legacy internal order). ``before``: Gmsh's numbering
and crack elements in topology order within each colour (the code before the memory order);
``gmsh``: Gmsh's numbering, each colour by triangle; ``hilbert`` / ``morton``: renumbered too."""
TRIANGLE_KERNELS = ("step_exploded_elastic", "step_exploded")


class Timers:
    """Seconds spent in the crack pass, contact and the triangle kernel, summed while ``on``."""

    def __init__(self):
        self.t = defaultdict(float)
        self.owner = None

    def wrap(self, fn, part, owner=None):
        """``fn`` timed while ``owner`` is being timed (``None``: while any variant is; the
        solver's kernels are shared by all)."""
        def timed(*a, **k):
            if self.owner is None or (owner is not None and self.owner is not owner):
                return fn(*a, **k)
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.t[part] += time.perf_counter() - t0
        return timed


class Variant:
    """One scene (or the block) with its simulation, damping and timers."""

    def __init__(self, name, sim, cracks, contact, build_seconds, start_seconds, timers):
        self.name, self.sim, self.cracks, self.contact = name, sim, cracks, contact
        self.build_seconds, self.start_seconds = build_seconds, start_seconds
        self.damping = fundamental_damping(sim)
        self.timers = timers
        cracks.add_forces = timers.wrap(cracks.add_forces, "crack pass", self)
        if contact is not None:
            contact.add_forces = timers.wrap(contact.add_forces, "contact", self)
        topo = sim.model.topology
        self.n_triangles, self.n_cracks = topo.n_triangles, topo.n_cracks
        self.gap = float(np.median(np.abs(np.diff(topo.crack_triangles, axis=1))))
        self.n_colours = cracks.n_colours
        self.blocks = []

    def run_block(self, steps: int) -> dict:
        self.timers.t.clear()
        self.timers.owner = self
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        for _ in range(steps):
            self.sim.step(self.damping)
        total = time.perf_counter() - t0
        self.timers.owner = None
        ms = {p: 1e3 * self.timers.t[p] / steps for p in PARTS[:-1]}
        ms["other"] = 1e3 * total / steps - sum(ms.values())
        row = {"ms_per_step": 1e3 * total / steps, **ms, "load_1min_before": load,
               "load_1min_after": os.getloadavg()[0]}
        self.blocks.append(row)
        return row

    def best(self) -> dict:
        return min(self.blocks, key=lambda r: r["ms_per_step"])


def scene(name: str, size: float, timers: Timers) -> Variant:
    """The low-angle fine four-slope scene meshed in the order of variant ``name`` (:data:`VARIANTS`),
    statically started, held elastic."""
    order, legacy = VARIANTS[name]
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # short joints dropped, a few sharp triangles: the case's own
        geometry, _, topo = four_slopes.build("low", "fine", size, order=order)
    t1 = time.perf_counter()
    within_colour = cracks_mod._colour_major_order
    if legacy:   # the crack set's internal order as it was: topology order within a colour
        cracks_mod._colour_major_order = lambda colour, tris: cracks_mod._legacy_colour_major_order(colour)
    try:
        sim, cracks = four_slopes.simulation(geometry, topo, None, pictures=False, start="static", progress=False)
    finally:
        cracks_mod._colour_major_order = within_colour
    t2 = time.perf_counter()
    cracks.hold_elastic(True)
    sim.monitors.clear()
    return Variant(name, sim, cracks, sim.providers[1], t1 - t0, t2 - t1, timers)


def block(n_triangles: int, timers: Timers) -> Variant:
    """The structured intact block of ``bench_full_step.py`` with about ``n_triangles`` triangles."""
    t0 = time.perf_counter()
    sim, cracks = intact_block(n_triangles)
    cracks.hold_elastic(True)
    return Variant("block", sim, cracks, None, time.perf_counter() - t0, 0.0, timers)


def crack_pass_alone(v: Variant) -> float:
    """Crack elements updated per second by the crack pass alone (best of 5, ``records.best_rate``)."""
    f = np.zeros_like(v.sim.state.x)
    sim = v.sim
    return best_rate(lambda: v.cracks.add_forces(sim.state.x, sim.state.v, f, sim.dt, sim.state.step),
                     v.cracks.n_active, seconds=1.0, repeats=5)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=float, default=0.5, help="element size [m] of the four-slope mesh")
    ap.add_argument("--steps", type=int, default=300, help="steps per timed block")
    ap.add_argument("--repeats", type=int, default=3, help="timed blocks per variant (taking turns)")
    ap.add_argument("--variants", default="before,gmsh,hilbert",
                    help=f"scene variants, comma separated ({', '.join(VARIANTS)})")
    ap.add_argument("--no-block", action="store_true", help="leave out the structured block")
    ap.add_argument("--no-save", action="store_true")
    args = ap.parse_args(argv)
    threads = numba.get_num_threads()
    print(f"{threads} thread(s), load {os.getloadavg()}", flush=True)

    timers = Timers()
    patched = {}
    for name in TRIANGLE_KERNELS:   # the solver looks its kernels up at call time
        if hasattr(solver_mod, name):
            patched[name] = getattr(solver_mod, name)
    variants = []
    for name in args.variants.split(","):
        v = scene(name, args.size, timers)
        print(f"scene, {v.name}: {v.n_triangles} triangles, {v.n_cracks} crack elements in {v.n_colours} colours, "
              f"median |tA - tB| {v.gap:g}; meshed in {v.build_seconds:.1f} s, static start {v.start_seconds:.1f} s, dt {v.sim.dt:.3g} s",
              flush=True)
        variants.append(v)
    if not args.no_block:
        v = block(variants[0].n_triangles, timers)
        print(f"block: {v.n_triangles} triangles, {v.n_cracks} crack elements in {v.n_colours} colours, "
              f"median |tA - tB| {v.gap:g}", flush=True)
        variants.append(v)
    for name, fn in patched.items():
        setattr(solver_mod, name, timers.wrap(fn, "triangle step"))
    try:
        for v in variants:   # warm-up: compile and touch every kernel outside the timing
            v.run_block(5)
            v.blocks.clear()
        for r in range(args.repeats):
            for v in variants:
                row = v.run_block(args.steps)
                print(f"  block {r + 1}: {v.name:8s} {row['ms_per_step']:8.3f} ms/step (crack pass "
                      f"{row['crack pass']:.3f}, triangle step {row['triangle step']:.3f}), load "
                      f"{row['load_1min_before']:.2f}", flush=True)
    finally:
        for name, fn in patched.items():
            setattr(solver_mod, name, fn)
    for v in variants:
        v.alone = crack_pass_alone(v)

    ref = variants[-1] if not args.no_block else None
    base = variants[0]   # "before" by default: the ratios say what the memory order gained
    print(f"\nfour-slope scene (low angle, fine joints), size {args.size} m, {threads} thread(s), "
          f"{args.steps} steps per block, best of {args.repeats}; ms per step")
    head = f"{'variant':>9s} {'triangles':>9s} {'cracks':>7s} {'|tA-tB|':>8s} {'ms/step':>8s} " + \
        " ".join(f"{p:>13s}" for p in PARTS) + f" {'crack M/s':>9s} {'alone M/s':>9s} {'x block':>7s} {'x ' + base.name:>9s}"
    print(head)
    out = {}
    for v in variants:
        b = v.best()
        in_step = v.cracks.n_active / (1e-3 * b["crack pass"]) / 1e6 if b["crack pass"] > 0 else float("nan")
        ratio_block = b["ms_per_step"] / ref.best()["ms_per_step"] if ref is not None else float("nan")
        ratio_base = b["ms_per_step"] / base.best()["ms_per_step"]
        print(f"{v.name:>9s} {v.n_triangles:9d} {v.n_cracks:7d} {v.gap:8g} {b['ms_per_step']:8.3f} "
              + " ".join(f"{b[p]:13.3f}" for p in PARTS)
              + f" {in_step:9.2f} {v.alone / 1e6:9.2f} {ratio_block:7.2f} {ratio_base:9.2f}")
        out[v.name] = {"n_triangles": v.n_triangles, "n_crack_elements": v.n_cracks, "median_triangle_gap": v.gap,
                       "n_colours": v.n_colours,
                       "best": b, "blocks": v.blocks, "crack_updates_per_s_in_step": in_step * 1e6,
                       "crack_updates_per_s_alone": v.alone, "relative_to_block": ratio_block,
                       "relative_to_first_variant": ratio_base, "mesh_seconds": v.build_seconds,
                       "static_start_seconds": v.start_seconds, "dt_s": v.sim.dt}
    load = os.getloadavg()
    print(f"load averages (1, 5, 15 min) at the end: {load}")
    if not args.no_save:
        label = f"size {args.size:g}"
        recs = []
        for name, r in out.items():
            recs.append(record(f"four-slope step, held elastic, {name} ({label})" if name != "block" else
                               f"structured block step, held elastic ({label})", r["best"]["ms_per_step"], "ms/step",
                               r["n_triangles"], threads, label=label, variant=name,
                               parts_ms_per_step={p: r["best"][p] for p in PARTS},
                               crack_updates_per_s_in_step=r["crack_updates_per_s_in_step"],
                               crack_updates_per_s_alone=r["crack_updates_per_s_alone"],
                               relative_to_block=r["relative_to_block"],
                               median_triangle_gap=r["median_triangle_gap"]))
        runs, old = {}, DOCS / "memory_order.json"
        if old.exists():
            doc = json.loads(old.read_text())
            runs = {k: v for k, v in doc.get("runs", {}).items() if k != label}
            recs = [r for r in doc["records"] if r.get("label") != label] + recs
        runs[label] = {"size_m": args.size, "steps_per_block": args.steps, "repeats": args.repeats,
                       "threads": threads, "variants": out, "load_average_end": list(load)}
        save("memory_order", recs, runs=runs,
             note="one process per size; variants take turns block by block; best block reported; load averages "
                  "of the shared 2-core machine before and after each block")
    return out


if __name__ == "__main__":
    main()
