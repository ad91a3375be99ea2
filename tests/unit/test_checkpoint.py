"""Checkpoint and restart: a run split by a checkpoint (on disk or in memory) gives the same
numbers, to the last bit, as the run that was never interrupted.

The scene: a small block, fixed at its base, whose upper part is thrown sideways and down;
weak crack elements (strength reduced by 1.25) break in the shear band and the broken faces
press into each other, so damage, breakage, contact pairs and their slip history are all part
of the state that must survive the restart.
"""
from __future__ import annotations

import os

import numpy as np
import pytest

from fdem.solve import checkpoint as ck
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.contact import CONTACT_LAW, ContactSet
from fdem.physics.elastic import ElasticMaterial
from fdem.mesh.mesh import structured_rectangle
from fdem.solve.model import Model
from fdem.solve.simulation import Simulation
from fdem.mesh.topology import build_topology

HALF = 150
EVERY = 10


def scene(nx: int = 6, reduce: bool = True, width: float = 0.6, scheme: str = "colour", backend: str | None = None,
          softening: str = "vertex", rock_phi: float = 30.0):
    topo = build_topology(structured_rectangle(nx, 6, width, 0.6))
    model = Model(topo, ElasticMaterial(young=1e9, poisson=0.25, density=2500.0))
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    model.set_initial_velocity(vx=3.0, vy=-1.5, where=np.flatnonzero(topo.x0[:, 1] > 0.35))
    rock = CrackProperties(f_t=2e5, c=4e5, phi=rock_phi, G_I=5.0, G_II=20.0, p_n=1e10, name="rock")
    cracks = CrackSet(topo, {0: rock}, contact_penalty=1e10, scheme=scheme, parallel_min=0)
    contact = ContactSet(topo, 1e10, friction_angle=30.0, mass=model.node_mass(), cracks=cracks, softening=softening)
    if reduce:
        cracks.interfaces.set_reduction(1 / 0.8)
    sim = Simulation(model, providers=[cracks, contact], progress=False, backend=backend)
    return sim, cracks, contact


def run(sim, n, **kw):
    sim.run(n_steps=n, history_every=EVERY, energy_tolerance=None, stage="shear", **kw)


def assert_same(a, b):
    """Bit-identical state, crack elements, contact pairs and history of two simulations."""
    sa, sb = a[0], b[0]
    assert sa.state.step == sb.state.step and sa.state.time == sb.state.time and sa.dt == sb.dt
    assert np.array_equal(sa.state.x, sb.state.x)
    assert np.array_equal(sa.state.v, sb.state.v)
    ca, cb = a[1], b[1]
    assert np.array_equal(ca.damage_ip, cb.damage_ip)
    assert np.array_equal(ca.broken, cb.broken)
    assert np.array_equal(ca.dissipated, cb.dissipated)
    assert np.array_equal(ca.events, cb.events)
    assert np.array_equal(ca.active, cb.active)
    ka, kb = a[2], b[2]
    assert np.array_equal(ka.pairs, kb.pairs)
    assert np.array_equal(ka._history, kb._history)
    assert np.array_equal(ka._touching, kb._touching)
    assert ka.energy_terms() == kb.energy_terms()
    assert sa.history == sb.history  # every ledger row, every column, exactly
    assert sa.ledger.done == sb.ledger.done and sa.ledger.total0 == sb.ledger.total0


@pytest.fixture(scope="module")
def reference():
    """The uninterrupted run: two stages of HALF steps each."""
    ref = scene()
    run(ref[0], HALF)
    mid = {"broken": int(ref[1].broken.sum()), "touching": ref[2].n_touching, "steps": ref[0].state.step}
    run(ref[0], HALF)
    return ref, mid


def test_restart_from_disk_is_bit_identical(reference, tmp_path):
    ref, mid = reference
    first = scene()
    run(first[0], HALF)
    # The checkpoint carries damage, breakage and touching contact pairs.
    assert first[1].broken.sum() == mid["broken"] > 5
    assert first[2].n_touching == mid["touching"] > 5
    assert (first[1].damage_ip > 0).any() and first[1].events.size == mid["broken"]
    path = ck.save_checkpoint(first[0], tmp_path / "run.ckpt")
    assert sorted(os.listdir(tmp_path)) == ["run.ckpt"]  # the temporary file is gone

    again = scene(reduce=False)  # the reduction factor comes from the checkpoint
    assert again[1].interfaces.reduction == 1.0
    ck.load_checkpoint(again[0], path)
    assert again[1].interfaces.reduction == 1.25
    assert again[1]._x_last is again[0].state.x
    assert again[0].state.step == mid["steps"] and len(again[0].history) == len(first[0].history)
    run(again[0], HALF)
    assert_same(ref, again)
    assert ref[1].broken.sum() > mid["broken"]  # fracture went on after the restart


def test_snapshot_restores_in_memory(reference):
    ref, _ = reference
    sim = scene()
    run(sim[0], HALF)
    snap = ck.snapshot(sim[0])
    rows = len(sim[0].history)
    run(sim[0], HALF)
    assert_same(ref, sim)
    # Back to the snapshot: history truncated to it, and the same second half again.
    ck.restore(sim[0], snap)
    assert len(sim[0].history) == rows and sim[0].state.step == HALF
    run(sim[0], HALF)
    assert_same(ref, sim)
    # The snapshot is independent of the simulation: it restores a fresh one as well.
    other = scene()
    ck.restore(other[0], snap)
    run(other[0], HALF)
    assert_same(ref, other)


def test_gather_scheme_restarts_bit_for_bit(tmp_path):
    ref = scene(scheme="gather")
    run(ref[0], HALF)
    path = ck.save_checkpoint(ref[0], tmp_path / "gather.ckpt")
    assert ref[1].broken.sum() > 5
    run(ref[0], HALF)
    again = scene(scheme="gather")
    ck.load_checkpoint(again[0], path)
    run(again[0], HALF)
    assert_same(ref, again)
    colour = scene()  # the element order differs: a colour-scheme crack set refuses the state
    with pytest.raises(ValueError, match="scheme 'gather'"):
        ck.load_checkpoint(colour[0], path)


def test_periodic_checkpoint_mid_stage_and_continue_run(tmp_path):
    n = 2 * HALF - 10  # ends before step 300: the last write is at 201
    ref = scene()
    run(ref[0], n)
    path = tmp_path / "periodic.ckpt"
    sim = scene()
    writer = ck.periodic(path, 100)
    run(sim[0], n, stop_when=ck.chain(None, writer))
    # Written on the first history row at or after steps 100 and 200; writing changes nothing.
    assert writer.written == [101, 201]
    assert_same(ref, sim)
    # The file holds step 201; a fresh scene finishes the run from it, bit for bit.
    again = scene()
    ck.load_checkpoint(again[0], path)
    assert again[0].state.step == 201
    ck.continue_run(again[0], n - 201, EVERY, stage="shear", energy_tolerance=None)
    assert_same(ref, again)


def test_chain_calls_every_hook_and_stops_on_any():
    calls = []
    fns = [lambda s: calls.append("a") or False, None, lambda s: calls.append("b") or True]
    assert ck.chain(*fns)(None) is True and calls == ["a", "b"]
    assert ck.chain(lambda s: False)(None) is False


def test_checkpointed_run_writes_at_the_stage_end(tmp_path):
    sim = scene()
    path = tmp_path / "stage.ckpt"
    ck.checkpointed_run(sim[0], path, 1000, n_steps=40, history_every=EVERY, energy_tolerance=None)
    assert ck.read_checkpoint(path)["state"]["step"] == 40


def test_checkpoint_of_another_mesh_is_refused(tmp_path):
    sim = scene()
    path = ck.save_checkpoint(sim[0], tmp_path / "six.ckpt")
    other = scene(nx=5)
    with pytest.raises(ValueError, match=r"another mesh: saved with 216 nodes, 72 triangles, 96 crack elements.*"
                                         r"this simulation has 180 nodes, 60 triangles, 79 crack elements"):
        ck.load_checkpoint(other[0], path)
    # Same counts, other coordinates: the hash tells them apart.
    wider = scene(width=0.7)
    with pytest.raises(ValueError, match=r"another mesh: saved with 216 nodes.*mesh hash.*has 216 nodes"):
        ck.load_checkpoint(wider[0], path)
    assert wider[0].state.step == 0 and np.array_equal(wider[0].state.x, wider[0].x0)


def test_missing_or_corrupt_checkpoint_is_a_clear_error(tmp_path):
    sim = scene()
    with pytest.raises(FileNotFoundError, match="does not exist"):
        ck.load_checkpoint(sim[0], tmp_path / "nothing.ckpt")
    junk = tmp_path / "junk.ckpt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="corrupt"):
        ck.load_checkpoint(sim[0], junk)
    good = ck.save_checkpoint(sim[0], tmp_path / "good.ckpt")
    cut = tmp_path / "cut.ckpt"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ValueError, match="corrupt"):
        ck.load_checkpoint(sim[0], cut)


def test_failed_write_leaves_the_previous_checkpoint(tmp_path, monkeypatch):
    sim = scene()
    path = ck.save_checkpoint(sim[0], tmp_path / "run.ckpt")
    before = path.read_bytes()
    run(sim[0], 20)

    def broken_writer(f, **arrays):
        f.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(ck.np, "savez_compressed", broken_writer)
    with pytest.raises(OSError, match="disk full"):
        ck.save_checkpoint(sim[0], path)
    assert os.listdir(tmp_path) == ["run.ckpt"] and path.read_bytes() == before
    assert ck.read_checkpoint(path)["state"]["step"] == 0


def test_provider_without_state_is_named():
    sim = scene()

    class Push:
        def add_forces(self, x, v, f, dt, step):
            pass

    sim[0].add_provider(Push())
    with pytest.raises(TypeError, match="2: Push"):
        sim[0].state_dict()


def test_a_checkpoint_written_by_the_flat_layout_loads_and_runs_on(reference):
    """tests/data/checkpoint_flat_layout.npz was written by the package before its modules
    moved into subpackages (the same scene, HALF steps). It must load into today's scene,
    hold the state the uninterrupted run has at that step (equal to round-off: the kernels were
    compiled afresh), and run on with the energy ledger closed."""
    from pathlib import Path

    ref, mid = reference
    path = Path(__file__).resolve().parents[1] / "data" / "checkpoint_flat_layout.npz"
    sim, cracks, contact = scene()
    ck.load_checkpoint(sim, path)
    assert sim.state.step == mid["steps"] == HALF
    assert int(cracks.broken.sum()) == mid["broken"] and contact.n_touching == mid["touching"]
    fresh = scene()
    run(fresh[0], HALF)
    scale = np.abs(fresh[0].state.x - fresh[0].x0).max()
    assert np.abs(sim.state.x - fresh[0].state.x).max() <= 1e-9 * scale
    run(sim, HALF)
    assert sim.state.step == 2 * HALF
    errors = [abs(r["balance_error_relative"]) for r in sim.history]
    assert max(errors) < 1e-2
    np.testing.assert_allclose(sim.state.x, ref[0].state.x, rtol=0, atol=1e-6 * scale)


def continues_and_refuses_other_friction(ref, again, path) -> None:
    """``again`` (loaded from ``path``) runs on to ``ref``'s state bit for bit, and a model whose
    face friction is lower or higher than the one it ran with is refused."""
    run(again[0], HALF)
    assert_same(ref, again)
    for phi in (25.0, 35.0):
        other = scene(rock_phi=20.0)
        other[2].set_friction(friction_angle=phi)
        with pytest.raises(ValueError, match="contact parameters"):
            ck.load_checkpoint(other[0], path)


def test_a_run_whose_breakage_lowered_face_friction_resumes(tmp_path):
    """Broken faces take the crack's residual friction (20 deg here, below the faces' 30 deg):
    the face friction then differs from the one a fresh model is built with. That is state,
    restored from the checkpoint, not a changed model: the run resumes and goes on bit for
    bit. A model whose face friction was changed (``set_friction``) is still refused."""
    ref = scene(rock_phi=20.0)
    run(ref[0], HALF)
    run(ref[0], HALF)
    first = scene(rock_phi=20.0)
    run(first[0], HALF)
    lowered = int((first[2].face_friction < first[2].face_mu).sum())
    assert lowered > 5
    path = ck.save_checkpoint(first[0], tmp_path / "run.ckpt")
    again = scene(rock_phi=20.0)
    ck.load_checkpoint(again[0], path)
    assert np.array_equal(again[2].face_friction, first[2].face_friction)
    assert int((again[2].face_friction < again[2].face_mu).sum()) == lowered
    continues_and_refuses_other_friction(ref, again, path)


def test_a_checkpoint_of_the_earlier_contact_law_is_refused(tmp_path, monkeypatch):
    """Checkpoints written before a pair's friction came from the faces in touch (before
    2026-11-25) carry no contact law: carrying such a run on would mix two laws in one run, so
    it is refused, with a message that says why and what to do."""
    first = scene(rock_phi=20.0)
    run(first[0], HALF)
    path = ck.save_checkpoint(first[0], tmp_path / "old.ckpt")
    meta = ck.read_checkpoint(path)
    assert meta["model"]["contact_law"] == CONTACT_LAW
    del meta["model"]["contact_law"]  # as the earlier code wrote them
    again = scene(rock_phi=20.0)
    monkeypatch.setattr(ck, "read_checkpoint", lambda _path: meta)
    with pytest.raises(ValueError, match="contact law .*lowest of all six faces.*git checkout"):
        ck.load_checkpoint(again[0], path)
