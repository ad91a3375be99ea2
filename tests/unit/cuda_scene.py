"""The GPU backend's comparison scene, run by ``tests/unit/test_cuda_backend.py``.

Run as a script in a process of its own: ``python cuda_scene.py BACKEND OUT.npz [--steps N]
[--from CKPT] [--save CKPT]``. The GPU side runs under numba-cuda's simulator, which hands the kernels
Python stand-ins for device arrays; the CPU laws they call must then be plain Python too, so
that process also sets ``NUMBA_DISABLE_JIT=1`` (the test sets both variables). The scene is the
checkpoint tests' block (``test_checkpoint.scene``): its upper part thrown sideways, crack
elements softening and breaking in a shear band, broken faces in contact with friction history.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

STEPS = 120       # steps of the comparison (the first breaks come at step 51)
HISTORY_EVERY = 10


def build(backend: str, softening: str = "vertex"):
    """The checkpoint tests' scene (``test_checkpoint.scene``) on ``backend``."""
    from test_checkpoint import scene

    return scene(backend=backend, softening=softening)


def outcome(sim, cracks, contact) -> dict[str, np.ndarray]:
    """What the comparison reads: state, crack elements, contact pairs, ledger rows."""
    rows = sim.history
    keys = ["kinetic", "strain", "crack_elastic", "contact_elastic", "friction", "fracture", "balance_error"]
    keys = [k for k in keys if k in rows[0]]
    return {
        "x": sim.state.x, "v": sim.state.v, "step": np.array(sim.state.step), "time": np.array(sim.state.time),
        "damage": cracks.damage_ip, "broken": cracks.broken, "dissipated": cracks.dissipated,
        "event_elements": cracks.events["element"] if len(cracks.events) else np.zeros(0, np.int64),
        "event_steps": cracks.events["step"] if len(cracks.events) else np.zeros(0, np.int64),
        "pairs": contact.pairs, "touching": contact._touching, "history": contact._history,
        "searches": np.array(contact.n_searches), "reduction": np.array(cracks.interfaces.reduction),
        "energies": np.array([contact.energy_terms()[k] for k in sorted(contact.energy_terms())]),
        "ledger_keys": np.array(keys), "ledger": np.array([[r[k] for k in keys] for r in rows]),
        "ledger_steps": np.array([r["step"] for r in rows]),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("backend")
    ap.add_argument("out", help="the outcome (.npz) after the last step")
    ap.add_argument("--steps", type=int, default=STEPS, help="the step to run to")
    ap.add_argument("--from", dest="start", default=None, help="a checkpoint to resume from")
    ap.add_argument("--save", default=None, help="write a checkpoint after the last step")
    ap.add_argument("--quasi-static", action="store_true",
                    help="a quasi-static stage: density-scaled masses, mass-proportional and local damping")
    ap.add_argument("--softening", default="vertex", help="the contact set's softening rule (vertex or all)")
    ap.add_argument("--ramp", type=float, default=None, metavar="F",
                    help="a stop rule that sets the strength reduction to F at the first history row after "
                         "step 40, during the run (as the paper's reduction rate does)")
    ap.add_argument("--hold", action="store_true",
                    help="a stop rule that holds the nodes of the three triangles highest in the block (both "
                         "velocity components prescribed zero) at the first history row after step 50, as a "
                         "runout holds fly-rock beyond the model (fdem.workflow.stages.hold_escaped)")
    ap.add_argument("--bare", type=int, default=0, metavar="N",
                    help="N bare Simulation.step calls before the run, all inside one device_session")
    args = ap.parse_args(argv)
    from fdem.solve import checkpoint as ck
    from fdem.solve.damping import Damping

    sim, cracks, contact = build(args.backend, args.softening)
    if args.start:
        ck.load_checkpoint(sim, args.start)
    done = sim.state.step
    damping = None
    if args.quasi_static:
        sim.set_density_scaling(True)
        damping = Damping(mass_proportional=200.0, local=0.3)
    tri = np.asarray(sim.model.topology.triangles)
    top = tri[np.argsort(sim.model.topology.x0[tri].mean(axis=1)[:, 1])[-3:]].ravel()

    def ramp(s) -> bool:
        if args.ramp is not None and s.state.step > 40 and cracks.interfaces.reduction != args.ramp:
            cracks.interfaces.set_reduction(args.ramp)
        if args.hold and s.state.step > 50 and not (s.flags[top] == 3).all():
            s.flags[top] = 3
            s.v_prescribed[top] = 0.0
        return False

    with sim.device_session():
        for _ in range(args.bare):
            sim.step(damping or Damping())
        done = sim.state.step
        sim.run(n_steps=args.steps - done, phase=done, history_every=HISTORY_EVERY, energy_tolerance=None,
                stage="shear", damping=damping, stop_when=ramp if args.ramp is not None or args.hold else None)
    if args.save:
        ck.save_checkpoint(sim, args.save)
    result = outcome(sim, cracks, contact)
    result["held_speed"] = np.array(np.abs(sim.state.v[top]).max())
    dev = sim._device
    result["batches"] = np.array([dev.batches_run, dev.batches_refused] if dev is not None else [0, 0])
    result["device_searches"] = np.array(dev.device_searches if dev is not None else 0)
    np.savez(args.out, **result)
    return 0


if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    sys.path[:0] = [str(here.parents[1]), str(here)]
    sys.exit(main())
