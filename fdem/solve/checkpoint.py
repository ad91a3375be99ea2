"""Checkpoint and restart, bit for bit.

A checkpoint is everything :meth:`fdem.solve.simulation.Simulation.state_dict` returns: the state, the
energy ledger, the history rows and each force provider's own ``state_dict()`` (crack elements:
damage, status, offsets, events, active list, reduction factor; contact: broken faces, bonds,
contactors, the pair list with its slip history). Restored into a freshly built simulation of
the same scene (same mesh, model, providers, parameters), the run continues with the same
numbers to the last bit.

* :func:`snapshot` / :func:`restore`: an in-memory deep copy, e.g. for the factor-of-safety
  search, which restarts each trial factor from the same state.
* :func:`save_checkpoint` / :func:`load_checkpoint`: one file, written atomically (a temporary
  file in the same directory, flushed, fsynced, then ``os.replace``): a crash while writing
  leaves the previous checkpoint intact. Arrays go into a compressed ``.npz``; scalars, lists
  and dicts into a JSON document stored inside it (floats round-trip exactly), with a format
  version, a fingerprint of the mesh and one of the model (materials, supports, gravity, crack
  property sets, heterogeneity, providers and their parameters); a checkpoint of another mesh or
  another model is refused, naming what differs. A ``context`` (any JSON-able dict with arrays,
  e.g. the workflow's journal, :mod:`fdem.workflow.journal`) travels in the same file.
* :func:`periodic` and :func:`chain`: ``Simulation.run(..., stop_when=...)`` calls
  ``stop_when(sim)`` on every history row; ``periodic(path, every_steps)`` is such a callable
  that writes a checkpoint when due and never stops the run, and ``chain`` combines it with a
  stage's own end rule; :func:`checkpointed_run` runs with both and writes a checkpoint at the
  end. They are building blocks: no stage runner or case calls them yet (the tests do).
* :func:`continue_run`: finishes a run that a periodic checkpoint interrupted with the same
  step sequence (history steps and time step) as the uninterrupted run.

Bit for bit means the same sequence of steps: the solver takes history (ledger) steps with a
different kernel from the plain steps (equal up to round-off), so a restart must put its
history steps where the uninterrupted run had them. A restart at a stage end (a new
``run`` call in both) does that by itself; a restart from a periodic checkpoint in the middle
of a stage does it through :func:`continue_run`.
"""
from __future__ import annotations

import copy
import hashlib
import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Callable
import numpy as np

from fdem.physics.contact import CONTACT_LAW

__all__ = ["CheckpointMismatch", "FORMAT_VERSION", "mesh_fingerprint", "model_fingerprint", "snapshot", "restore", "save_checkpoint", "read_checkpoint",
           "load_checkpoint", "periodic", "chain", "checkpointed_run", "continue_run"]


FORMAT_VERSION = 1
"""Version of the checkpoint file layout; a file of another version is refused."""


_META = "__checkpoint__"


_ARRAY = "__ndarray__"


# ----------------------------------------------------------------------------- fingerprint
def mesh_fingerprint(sim) -> dict:
    """``n_nodes``, ``n_triangles``, ``n_cracks`` and a SHA-256 of the reference positions,
    the triangles and the crack-element nodes of the simulation's mesh."""
    topo = sim.model.topology
    crack_nodes = np.asarray(getattr(topo, "crack_nodes", np.zeros((0, 4))), dtype=np.int64)
    h = hashlib.sha256()
    for a in (np.asarray(topo.x0, dtype=np.float64), np.asarray(topo.triangles, dtype=np.int64), crack_nodes):
        h.update(str(a.shape).encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return {"n_nodes": int(topo.n_nodes), "n_triangles": int(topo.n_triangles),
            "n_cracks": int(crack_nodes.shape[0]), "sha256": h.hexdigest()}


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def _text_digest(obj) -> str:
    return hashlib.sha256(repr(obj).encode()).hexdigest()[:16]


def model_fingerprint(sim) -> dict:
    """What a restart must share with the run that saved the checkpoint, besides the mesh, as
    short digests by part: ``materials`` (the triangles' constants: elastic moduli, density,
    element damping, through :meth:`fdem.solve.model.Model.triangle_constants`),
    ``supports`` (the model's support flags and prescribed velocities), ``gravity`` (the
    model's own, [m/s^2]: stages scale it, the checkpoint's current gravity is restored),
    ``providers`` (their kinds in order), ``crack_properties`` (the property set of every tag,
    heterogeneity draws, scheme), ``contact`` (penalty, friction, damping and softening of
    the contact set) and ``contact_law`` (:data:`CONTACT_LAW`: a run is not carried on under
    another contact law than it began with)."""
    model = sim.model
    fp = {"materials": _digest(model.triangle_constants()),
          "supports": _digest(model.flags, model.v_prescribed),
          "gravity": [float(g) for g in model.gravity],
          "providers": [type(p).__name__ for p in sim.providers]}
    cracks = getattr(sim, "cracks", None)
    if cracks is not None:
        sets = getattr(cracks.interfaces, "property_sets", {})
        # (the crack set checks its own scheme and element order, with its own message)
        fp["crack_properties"] = _text_digest((sorted((int(k), repr(v)) for k, v in sets.items()),
                                               _digest(getattr(cracks, "strength_multiplier", np.zeros(0)))))
    contact = getattr(sim, "contact", None)
    if contact is not None:
        fp["contact"] = _contact_digest(contact, getattr(contact, "face_mu", np.zeros(0)))
        fp["contact_law"] = CONTACT_LAW
    return fp


def _contact_digest(contact, face_mu) -> str:
    """The contact set's parameters with the face friction ``face_mu`` (as built or set, not as
    lowered by breakage: that is state, restored from the checkpoint)."""
    return _text_digest(tuple(repr(getattr(contact, a, None)) for a in (
        "penalty", "tangential_ratio", "damping_ratio", "softening", "loose_fraction")) + (_digest(face_mu),))


_PART_NAMES = {"materials": "materials (elastic moduli, density or element damping)",
               "supports": "supports (fixed or roller boundaries, prescribed velocities)",
               "gravity": "gravity", "providers": "force providers",
               "crack_properties": "crack-element property sets (strengths, penalties, heterogeneity)",
               "contact": "contact parameters (penalty, friction, damping)",
               "contact_law": "contact law (a checkpoint without one was written with the friction of a pair taken "
                              "as the lowest of all six faces of its two triangles; carry such a run on with the "
                              "fdem that began it, git checkout c9b5bed, or start it again)"}


def _model_differences(saved: dict, here: dict) -> list[str]:
    return [f"{_PART_NAMES.get(k, k)}: saved {saved.get(k)!r}, here {here.get(k)!r}"
            for k in sorted(set(saved) | set(here)) if saved.get(k) != here.get(k)]


def _describe(fp: dict) -> str:
    return (f"{fp.get('n_nodes')} nodes, {fp.get('n_triangles')} triangles, {fp.get('n_cracks')} crack elements "
            f"(mesh hash {str(fp.get('sha256'))[:12]})")


# ----------------------------------------------------------------------------- in memory
def snapshot(sim) -> dict:
    """A deep copy of the simulation's state (:meth:`~fdem.solve.simulation.Simulation.state_dict`),
    independent of the running simulation; :func:`restore` may apply it any number of times."""
    return copy.deepcopy(sim.state_dict())


def restore(sim, snap: dict) -> None:
    """Put the simulation back into the state of ``snap`` (from :func:`snapshot`, this or an
    identically built simulation); ``snap`` itself is not changed."""
    sim.load_state_dict(copy.deepcopy(snap))


# ----------------------------------------------------------------------------- on disk
def _encode(obj, arrays: dict, name: str):
    """JSON-able copy of ``obj``; numpy arrays go into ``arrays`` under a unique name."""
    if isinstance(obj, np.ndarray):
        key = f"a{len(arrays)}"
        arrays[key] = obj
        return {_ARRAY: key}
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise TypeError(f"checkpoint: key {k!r} in {name} is not a string")
            out[k] = _encode(v, arrays, f"{name}.{k}")
        return out
    if isinstance(obj, (list, tuple)):
        return [_encode(v, arrays, f"{name}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj)
    if obj is None or isinstance(obj, str):
        return obj
    raise TypeError(f"checkpoint: cannot store {name} of type {type(obj).__name__}")


def _decode(obj, arrays):
    if isinstance(obj, dict):
        if len(obj) == 1 and _ARRAY in obj:
            return arrays[obj[_ARRAY]]
        return {k: _decode(v, arrays) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_decode(v, arrays) for v in obj]
    return obj


def save_checkpoint(sim, path, context: dict | None = None) -> Path:
    """Write the simulation's state to ``path`` atomically; returns the path.

    ``context``: what the caller needs to resume besides the simulation (a workflow's journal
    of finished stages and the runtime of the one in progress); arrays allowed, returned by
    :func:`read_checkpoint` under ``"context"``.

    The file is a compressed ``.npz`` holding the arrays and one JSON document (scalars,
    lists, the history rows, the format version and the mesh fingerprint). It is written to a
    temporary file in the same directory, flushed and fsynced, then renamed over ``path``:
    readers see the old file or the new one, never a partial one.
    """
    path = Path(path)
    arrays: dict[str, np.ndarray] = {}
    body = _encode(sim.state_dict(), arrays, "state")
    meta = {"format_version": FORMAT_VERSION, "mesh": mesh_fingerprint(sim), "model": model_fingerprint(sim),
            "state": body, "context": _encode(context, arrays, "context")}
    text = json.dumps(meta, allow_nan=True, separators=(",", ":"))
    arrays[_META] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    directory = path.parent if str(path.parent) else Path(".")
    directory.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    try:  # make the rename itself durable
        dfd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass
    return path


def read_checkpoint(path) -> dict:
    """The content of a checkpoint file: ``format_version``, ``mesh`` (fingerprint) and
    ``state`` (a :meth:`~fdem.solve.simulation.Simulation.state_dict`). Missing, corrupt or foreign files
    raise ``FileNotFoundError`` / ``ValueError`` naming the path."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            if _META not in z.files:
                if {"x", "v", "x0", "triangles"} <= set(z.files):
                    raise ValueError("it is a state file (positions and velocities, for looking at), which "
                                     "holds no crack, contact or ledger state to restart from; restart from "
                                     "the run's checkpoint.npz (fdem run NAME --resume DIR) or "
                                     "interrupted_state.npz")
                raise ValueError(f"no {_META} entry")
            meta = json.loads(z[_META].tobytes().decode("utf-8"))
            arrays = {k: z[k] for k in z.files if k != _META}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError, UnicodeDecodeError) as e:
        raise ValueError(f"checkpoint {path} is corrupt or not a checkpoint file: {e}") from e
    version = meta.get("format_version")
    if version != FORMAT_VERSION:
        raise ValueError(f"checkpoint {path} has format version {version!r}; this fdem reads version {FORMAT_VERSION}")
    try:
        meta["state"] = _decode(meta["state"], arrays)
        meta["context"] = _decode(meta.get("context"), arrays)
    except KeyError as e:
        raise ValueError(f"checkpoint {path} is corrupt: array {e} is missing") from e
    return meta


class CheckpointMismatch(ValueError):
    """A checkpoint that belongs to another mesh or model than the simulation it is loaded into:
    a user's condition (the message says what differs), not a defect."""


def load_checkpoint(sim, path) -> dict | None:
    """Restore the state saved by :func:`save_checkpoint` into ``sim``, a freshly built
    simulation of the same scene; returns the saved ``context`` (``None`` if none). A checkpoint
    of another mesh is refused with a :class:`CheckpointMismatch` naming both meshes' counts, one of
    another model with one naming every part that differs (:func:`model_fingerprint`; files written
    before the model was fingerprinted are checked on their mesh only); a missing file raises
    ``FileNotFoundError``, a corrupt one ``ValueError``."""
    meta = read_checkpoint(path)
    here = mesh_fingerprint(sim)
    saved = meta.get("mesh", {})
    if saved != here:
        raise CheckpointMismatch(f"checkpoint {path} belongs to another mesh: saved with {_describe(saved)}, "
                         f"this simulation has {_describe(here)}")
    if meta.get("model") is not None:
        here_model = model_fingerprint(sim)
        saved_model = meta["model"]
        if saved_model.get("contact_law") != here_model.get("contact_law"):
            # the contact digest's form goes with the law: only the law is worth naming then
            saved_model = {**saved_model, "contact": here_model.get("contact")}
        differences = _model_differences(saved_model, here_model)
        if differences:
            raise CheckpointMismatch(f"checkpoint {path} belongs to another model on the same mesh; it differs in "
                             + "; ".join(differences))
    sim.load_state_dict(meta["state"])
    return meta.get("context")


# ----------------------------------------------------------------------------- in the run loop
def periodic(path, every_steps: int) -> Callable:
    """A ``stop_when`` callable for :meth:`~fdem.solve.simulation.Simulation.run` that writes a
    checkpoint to ``path`` at the first history row at or after every multiple of
    ``every_steps`` (simulation step count) and never stops the run.

    The callable's ``written`` list holds the steps (``sim.state.step``) it wrote at. Combine
    it with a stage's end rule through :func:`chain`; :func:`checkpointed_run` does both and
    adds a checkpoint at the stage end.
    """
    every_steps = int(every_steps)
    if every_steps < 1:
        raise ValueError(f"checkpoint interval must be at least 1 step, got {every_steps}")
    state = {"last": None}

    def write_when_due(sim) -> bool:
        step = sim.state.step
        if state["last"] is None:
            state["last"] = (step - 1) // every_steps * every_steps  # the run's start counts as written
        if step // every_steps > state["last"] // every_steps:
            save_checkpoint(sim, path)
            state["last"] = step
            write_when_due.written.append(step)
        return False

    write_when_due.written = []
    write_when_due.path = Path(path)
    return write_when_due


def chain(*fns: Callable | None) -> Callable:
    """One ``stop_when`` callable from several (``None`` skipped): every one is called on
    every history row, in order (so a checkpoint writer runs even when an end rule fires);
    the run stops when any returns True."""
    live = [f for f in fns if f is not None]

    def any_stop(sim) -> bool:
        stop = False
        for f in live:
            stop = bool(f(sim)) or stop
        return stop

    return any_stop


def checkpointed_run(sim, path, every_steps: int, stop_when: Callable | None = None, **run_kwargs):
    """``sim.run(**run_kwargs)`` writing a checkpoint to ``path`` every ``every_steps`` steps
    (on history rows, :func:`periodic`) and once more when the stage ends, however it ends.
    ``stop_when`` is the stage's own end rule. Returns the simulation."""
    writer = periodic(path, every_steps)
    sim.run(stop_when=chain(stop_when, writer), **run_kwargs)
    save_checkpoint(sim, path)
    return sim


def continue_run(sim, n_steps: int, history_every: int, damping=None, **run_kwargs):
    """Finish a run from a checkpoint that :func:`periodic` wrote in its middle, with the step
    sequence of the uninterrupted run: the same time step and history steps.

    ``n_steps``: the steps the interrupted run still had to take (its ``n_steps`` minus
    ``sim.state.step`` minus the step it started at); ``history_every`` and ``damping``
    as in that run; pass its ``stage`` name in ``run_kwargs`` to keep the history rows' label.
    The checkpoint was written right after a history step, so the next ``history_every - 1``
    steps are plain steps and the one after is a history step, which the final ``run``
    call starts with. ``run`` chooses its time step anew from the current stiffness; the
    one the interrupted run used (restored with the checkpoint) is kept instead.
    """
    from fdem.solve.damping import NO_DAMPING

    n_steps = int(n_steps)
    history_every = max(1, int(history_every))
    damping = damping or NO_DAMPING
    if n_steps <= 0:
        return sim
    plain = min(history_every - 1, n_steps - 1)
    for _ in range(plain):
        step_before, time_before = sim.state.step, sim.state.time
        sums = sim.step(damping, ledger=False)
        sim._check(sums, step_before, time_before, False, None)
    user_dt = sim.user_dt
    sim.user_dt = sim.dt
    try:
        sim.run(n_steps=n_steps - plain, history_every=history_every, damping=damping, **run_kwargs)
    finally:
        sim.user_dt = user_dt
    return sim
