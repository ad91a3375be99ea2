"""Profile of the four-slope scene: where a step's time goes in each phase of the run.

Builds the low-angle fine four-slope scene (``cases/four_slopes.py``: static geostatic start,
crack elements, contact), then drives it through :mod:`fdem.stages`:

* ``intact``: crack elements held elastic at ``F = 1`` (damped);
* ``softening``: strength reduced to ``--soften`` (damped): crack elements damage and slide,
  none has broken yet;
* ``failing``: strength reduced to ``--fail`` (damped) for ``--fail-steps``: elements break;
* ``runout``: the same strength, no damping (dynamic).

Each stage runs ``--steps`` steps (a window of each phase, not the whole run: at the
automatic time step a response time of the slope is tens of thousands of steps). Every step is
put in the phase of the scene's state when it starts (``intact`` while no crack element has
left the elastic range, ``softening`` while some have and none has broken, ``failing`` once
one has broken, ``runout`` in the dynamic stage), whatever stage it is in. The force providers'
``add_forces``, the contact search and pair kernels and the solver's triangle kernels are
wrapped with timers (the solver is not changed); a step's time splits into

* ``crack pass``: :meth:`CrackSet.add_forces`;
* ``contact search``: :meth:`ContactSet.search` (broad phase and pair bookkeeping);
* ``pair forces``: the pair kernel and the gather onto the nodes;
* ``contact other``: the rest of :meth:`ContactSet.add_forces` (watching crack elements,
  contactor bookkeeping, the re-search test);
* ``triangle step``: the fused triangle + integration kernel (with or without a ledger row);
* ``output``: output frames, provider energy terms and ledger rows;
* ``python``: everything else (the step and stage loops, rule checks, state copies).

``--from-checkpoint runs/low_fine/runout_start.npz`` (with the ``--angle``, ``--spacing``
and ``--size`` of that run) profiles the real failing phase instead: after the intact stage,
the scene loads the state a four-slope run failed in and runs ``--steps`` dynamic steps from
it, booked ``failing`` (elements broken) or ``runout``.

Prints a table (milliseconds per step and the cost of a step relative to an intact step) and
writes ``docs/benchmarks/profile.json``. ``--contact-softening all`` profiles the earlier
behaviour (every triangle of a softening element a contactor, searched against every other).

    NUMBA_NUM_THREADS=1 python cases/benchmarks/profile_scene.py --size 1.0 --steps 300
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
sys.path.insert(0, str(ROOT / "cases"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import four_slopes  # noqa: E402
from records import record, save  # noqa: E402

import fdem.solve.simulation as solver_mod  # noqa: E402
from fdem.kernels import contact_pairs as kc  # noqa: E402
from fdem.solve.damping import NO_DAMPING  # noqa: E402
from fdem.workflow.stages import Stage, run_stage
from fdem.workflow.fos import fundamental_damping  # noqa: E402

PARTS = ("crack pass", "contact search", "pair forces", "contact other", "triangle step", "output", "python")
PHASES = ("intact", "softening", "failing", "runout")


class Profiler:
    """Timers wrapped around a simulation's providers and kernels, summed per phase."""

    def __init__(self, sim, cracks, contact):
        self.sim, self.cracks, self.contact = sim, cracks, contact
        self.t = {p: defaultdict(float) for p in PHASES}
        self.steps = defaultdict(int)
        self.samples = {p: [] for p in PHASES}   # (n_inelastic, n_broken, n_contactors, n_pairs, n_touching)
        self.phase = "intact"
        self.runout = False
        self._last = None
        self._depth = 0

        def timed(fn, part):
            def wrapper(*a, **k):
                t0 = time.perf_counter()
                try:
                    return fn(*a, **k)
                finally:
                    dt = time.perf_counter() - t0
                    self.t[self.phase][part] += dt
                    self._inner += dt
            return wrapper

        self._inner = 0.0
        # providers (instance attributes shadow the methods the solver calls)
        cracks.add_forces = timed(cracks.add_forces, "crack pass")
        contact_add = contact.add_forces

        def contact_wrapper(*a, **k):
            inner0 = self._inner
            t0 = time.perf_counter()
            contact_add(*a, **k)
            total = time.perf_counter() - t0
            self.t[self.phase]["contact other"] += total - (self._inner - inner0)
            self._inner = inner0 + total

        contact.add_forces = contact_wrapper
        contact.search = timed(contact.search, "contact search")
        # kernels the contact set and the solver look up at call time
        self._saved = [(kc, "pair_forces", kc.pair_forces), (kc, "gather_forces", kc.gather_forces),
                       (solver_mod, "step_exploded_elastic", solver_mod.step_exploded_elastic),
                       (solver_mod, "step_exploded", solver_mod.step_exploded)]
        kc.pair_forces = timed(kc.pair_forces, "pair forces")
        kc.gather_forces = timed(kc.gather_forces, "pair forces")
        solver_mod.step_exploded_elastic = timed(solver_mod.step_exploded_elastic, "triangle step")
        solver_mod.step_exploded = timed(solver_mod.step_exploded, "triangle step")
        sim.write_output = timed(sim.write_output, "output")
        sim._collect_provider_terms = timed(sim._collect_provider_terms, "output")
        sim._record = timed(sim._record, "output")
        step = sim.step

        def step_wrapper(*a, **k):
            now = time.perf_counter()
            self._close(now)
            if sim.state.step % 16 == 0 or self.phase == "intact":
                self.phase = self._phase()
                if sim.state.step % 64 == 0:
                    self.samples[self.phase].append(self._sample())
            self.steps[self.phase] += 1
            self._inner = 0.0
            self._last = now
            return step(*a, **k)

        sim.step = step_wrapper

    def _phase(self) -> str:
        if self.runout:
            return "runout"
        if self.cracks.broken.any():
            return "failing"
        return "softening" if self.cracks.n_inelastic() else "intact"

    def _sample(self):
        c = self.contact
        return (self.cracks.n_inelastic(), int(self.cracks.broken.sum()), 0 if c.dormant else int(c.active.size),
                0 if c.dormant else c.n_pairs, 0 if c.dormant else c.n_touching)

    def _close(self, now):
        """Book the wall time since the previous step began (the step, and the loop after it)."""
        if self._last is not None:
            total = now - self._last
            self.t[self.phase]["total"] += total
            self.t[self.phase]["python"] += total - self._inner
            self._inner = 0.0
        self._last = None

    def stop(self):
        self._close(time.perf_counter())

    def restore(self):
        for mod, name, fn in self._saved:
            setattr(mod, name, fn)

    def table(self) -> dict:
        out = {}
        intact = self.t["intact"]["total"] / max(self.steps["intact"], 1)
        for p in PHASES:
            n = self.steps[p]
            if n == 0:
                continue
            row = {"steps": n, "ms_per_step": 1e3 * self.t[p]["total"] / n,
                   "relative_to_intact": (self.t[p]["total"] / n) / intact if intact > 0 else float("nan")}
            for part in PARTS:
                row[part] = 1e3 * self.t[p][part] / n
            s = np.array(self.samples[p]) if self.samples[p] else np.zeros((1, 5))
            for k, name in enumerate(("n_inelastic", "n_broken", "n_contactors", "n_pairs", "n_touching")):
                row[name] = int(s[:, k].max())
            out[p] = row
        return out


def _warm_contact_kernels() -> None:
    """Load the contact kernels (search, pair forces, gather) once, outside the profile."""
    from fdem.physics.contact import ContactSet
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology

    topo = build_topology(structured_rectangle(4, 4, 4.0, 4.0))
    cs = ContactSet(topo, penalty=1e9, friction_angle=30.0, check_overlap=False)
    cs.activate_cracks(np.arange(topo.n_cracks))
    x = topo.x0.copy()
    cs.add_forces(x, np.zeros_like(x), np.zeros_like(x), 1e-6, 0)


def print_table(tab: dict, title: str) -> None:
    print(f"\n{title}")
    head = f"{'phase':>10s} {'steps':>6s} {'ms/step':>8s} {'x intact':>8s} " + " ".join(f"{p:>14s}" for p in PARTS)
    print(head)
    for p, r in tab.items():
        print(f"{p:>10s} {r['steps']:6d} {r['ms_per_step']:8.3f} {r['relative_to_intact']:8.2f} "
              + " ".join(f"{r[part]:14.3f}" for part in PARTS))
    print(f"{'phase':>10s} {'inelastic':>10s} {'broken':>8s} {'contactors':>10s} {'pairs':>8s} {'touching':>8s}")
    for p, r in tab.items():
        print(f"{p:>10s} {r['n_inelastic']:10d} {r['n_broken']:8d} {r['n_contactors']:10d} {r['n_pairs']:8d} "
              f"{r['n_touching']:8d}")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=float, default=1.0, help="element size [m] of the four-slope mesh")
    ap.add_argument("--steps", type=int, default=300, help="steps per stage")
    ap.add_argument("--soften", type=float, default=2.0, help="reduction factor F of the softening stage")
    ap.add_argument("--fail", type=float, default=50.0, help="reduction factor F of the failing and runout stages")
    ap.add_argument("--fail-steps", type=int, default=3000, help="steps of the failing stage (elements must break)")
    ap.add_argument("--contact-softening", choices=["vertex", "all"], default=None,
                    help="contact of softening elements (default: the ContactSet default)")
    ap.add_argument("--angle", choices=["low", "high"], default="low")
    ap.add_argument("--spacing", choices=["fine", "coarse"], default="fine")
    ap.add_argument("--joint-offset", type=float, default=None, help="as the four-slopes case's --joint-offset")
    ap.add_argument("--from-checkpoint", type=Path, default=None,
                    help="after the intact stage, profile --steps dynamic steps from this state of a four-slope run")
    ap.add_argument("--mesh-order", choices=["hilbert", "morton", "none"], default="hilbert",
                    help="memory order of the mesh (none: Gmsh's numbering, which checkpoints of runs made "
                         "before renumbering belong to)")
    ap.add_argument("--label", default="", help="label of the records (e.g. before / after)")
    ap.add_argument("--no-save", action="store_true")
    args = ap.parse_args(argv)

    geometry, _, topo = four_slopes.build(args.angle, args.spacing, args.size, joint_offset=args.joint_offset,
                                          order=None if args.mesh_order == "none" else args.mesh_order)
    out = Path(tempfile.mkdtemp(prefix="fdem_profile_"))
    sim, cracks = four_slopes.simulation(geometry, topo, out, pictures=False, progress=False)
    contact = sim.providers[1]
    if args.contact_softening is not None:
        contact.softening = args.contact_softening
    threads = numba.get_num_threads()
    print(f"{topo.n_triangles} triangles, {topo.n_cracks} crack elements, dt {sim.dt:.3g} s, {threads} thread(s), "
          f"load {os.getloadavg()}", flush=True)
    # warm-up: compile every kernel the stages use, outside the profile
    state = sim.state_dict()
    for _ in range(3):
        sim.step(ledger=True)
    sim.load_state_dict(state)
    _warm_contact_kernels()

    prof = Profiler(sim, cracks, contact)
    damped = fundamental_damping(sim)
    load = [os.getloadavg()]
    length = args.steps * sim.dt
    stages = [Stage("intact", duration=length, reduction=1.0, hold_elastic=True, damping=damped),
              Stage("softening", duration=length, reduction=args.soften, hold_elastic=False, damping=damped),
              Stage("failing", duration=args.fail_steps * sim.dt, reduction=args.fail, damping=damped),
              Stage("runout", duration=length, damping=NO_DAMPING)]
    if args.from_checkpoint is not None:
        stages = [stages[0], Stage("from_checkpoint", duration=length, damping=NO_DAMPING)]
    wall = time.perf_counter()
    results = []
    for st in stages:
        if st.name == "from_checkpoint":
            from fdem.solve.checkpoint import load_checkpoint

            load_checkpoint(sim, args.from_checkpoint)   # the reduction factor comes with it
        prof.runout = st.name == "runout"
        r = run_stage(sim, st)
        prof.stop()
        load.append(os.getloadavg())
        results.append(r)
        print(f"  stage {st.name}: {r.steps} steps in {r.wall_seconds:.1f} s, {cracks.n_inelastic()} inelastic, "
              f"{int(cracks.broken.sum())} broken, load {load[-1][0]:.2f}", flush=True)
    wall = time.perf_counter() - wall
    prof.restore()
    sim.close()
    tab = prof.table()
    label = args.label or (args.contact_softening or "default")
    print_table(tab, f"four-slope scene, size {args.size} m ({topo.n_triangles} triangles), {threads} thread(s), "
                     f"contact softening: {getattr(contact, 'softening', 'all')}, ms per step")
    print(f"load averages (1, 5, 15 min) before/after each stage: {load}")
    if not args.no_save:
        recs = []
        for p, r in tab.items():
            recs.append(record(f"four-slope step, {p} phase ({label})", r["ms_per_step"], "ms/step",
                               topo.n_triangles, threads, label=label, relative_to_intact=r["relative_to_intact"],
                               relative_to_triangle_step=r["ms_per_step"] / max(r["triangle step"], 1e-12),
                               parts_ms_per_step={k: r[k] for k in PARTS},
                               counts={k: r[k] for k in ("steps", "n_inelastic", "n_broken", "n_contactors",
                                                          "n_pairs", "n_touching")}))
        # one file for every label: the records and settings of other labels are kept
        import json

        from records import DOCS
        runs = {}
        old = DOCS / "profile.json"
        if old.exists():
            runs = {k: v for k, v in json.loads(old.read_text()).get("runs", {}).items() if k != label}
            recs = [r for r in json.loads(old.read_text())["records"] if r.get("label") != label] + recs
        runs[label] = dict(size_m=args.size, n_crack_elements=topo.n_cracks,
                           contact_softening=getattr(contact, "softening", "all"), steps_per_stage=args.steps,
                           failing_stage_steps=args.fail_steps, reduction_soften=args.soften,
                           reduction_fail=args.fail, load_average=[list(x) for x in load], wall_seconds=wall,
                           stages=[r.as_dict() for r in results])
        save("profile", recs, runs=runs,
             note="one process per label; each step booked to the phase of the scene when it starts; load "
                  "averages of the shared 2-core machine before and after each stage")
    return tab


if __name__ == "__main__":
    main()
