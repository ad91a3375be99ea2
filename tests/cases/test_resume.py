"""Runs that lose nothing: a run stopped by SIGTERM or killed outright, resumed with
``--resume``, ends bit for bit where the uninterrupted run ends; an unstable run resumes from
its last good checkpoint with a smaller step; every ending has its exit code and ``run.json``.

The scene is the quick-start slope at 2 m elements (342 triangles): its whole workflow
(equilibrium, three reduction steps, failure at F = 1.43, runout to rest over 106,295 steps)
takes about 10 s on one thread, so a signal sent a few seconds in lands in a real stage.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fdem.solve import checkpoint as ck
from fdem.solve.checkpoint import read_checkpoint

SCENE = ["--size", "2.0", "--no-pictures", "--quiet", "--threads", "1"]


def fdem(*args, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fdem.cli", *args], capture_output=True, text=True, timeout=timeout)


def start(out: Path, *extra) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "fdem.cli", "run", "quick-start", *SCENE, "--out", str(out), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def wait_for_rows(out: Path, proc: subprocess.Popen, rows: int, timeout: float = 240.0) -> None:
    """Wait until the run has written ``rows`` history rows (it is then well inside its stages)."""
    t0 = time.monotonic()
    history = out / "history.csv"
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            pytest.fail(f"the run ended before it could be stopped:\n{proc.stdout.read()}")
        if history.exists() and sum(1 for _ in history.open()) > rows:
            return
        time.sleep(0.05)
    pytest.fail("the run wrote no history")


def state(path: Path) -> dict:
    return read_checkpoint(path)["state"]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("whole") / "run"
    done = fdem("run", "quick-start", *SCENE, "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    assert not (out / ".fdem_room").exists()  # the room kept against a full disk goes when the run ends
    return out


def assert_same_run(a: Path, b: Path) -> None:
    sa, sb = state(a / "final_state.npz"), state(b / "final_state.npz")
    assert sa["step"] == sb["step"] and sa["time"] == sb["time"]
    assert np.array_equal(sa["x"], sb["x"]) and np.array_equal(sa["v"], sb["v"])
    assert (a / "history.csv").read_bytes() == (b / "history.csv").read_bytes()
    ja, jb = json.loads((a / "summary.json").read_text()), json.loads((b / "summary.json").read_text())
    assert [(s["name"], s["reason"], s["steps"]) for s in ja["workflow"]["stages"]] == \
        [(s["name"], s["reason"], s["steps"]) for s in jb["workflow"]["stages"]]
    assert ja["runout"]["runout_distance_m"] == jb["runout"]["runout_distance_m"]


def earlier_law_refused(run: Path, copy: Path) -> None:
    """A copy of the stopped ``run`` whose checkpoint names no contact law, as those written before
    the friction of the faces in touch, is refused in one line with exit code 2, before any work."""
    shutil.copytree(run, copy)
    path = copy / "checkpoint.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(arrays[ck._META].tobytes().decode("utf-8"))
    del meta["model"]["contact_law"]
    arrays[ck._META] = np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)
    np.savez_compressed(path, **arrays)
    refused = fdem("run", "quick-start", "--resume", str(copy))
    assert refused.returncode == 2, refused.stdout + refused.stderr
    assert "cannot resume" in refused.stderr and "contact law" in refused.stderr
    assert "Traceback" not in refused.stderr and "contact parameters" not in refused.stderr


def test_sigterm_then_resume_is_bit_identical(uninterrupted, tmp_path):
    out = tmp_path / "run"
    proc = start(out)
    wait_for_rows(out, proc, 40)
    proc.send_signal(signal.SIGTERM)
    log = proc.communicate(timeout=120)[0]
    assert proc.returncode == 143, log
    record = json.loads((out / "run.json").read_text())
    assert record["outcome"] == "interrupted" and record["exit_code"] == 143
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "interrupted" and "SIGTERM" in summary["ending"]
    # the state the run stopped in is written once, resumable, and before its picture: at
    # 326,755 triangles each copy is over 100 MB, seconds a supervisor's SIGKILL may cut short
    checkpoint, picture = out / "checkpoint.npz", out / "interrupted_state.vtu"
    assert checkpoint.is_file() and picture.is_file()
    assert checkpoint.stat().st_mtime_ns <= picture.stat().st_mtime_ns
    assert not (out / "interrupted_state.npz").exists() and not (out / "final_state.npz").exists()
    stopped_at = state(checkpoint)["step"]
    assert stopped_at > 0 and json.loads((out / "run.json").read_text())["outcome"] == "interrupted"
    earlier_law_refused(out, tmp_path / "earlier_law")
    resumed = fdem("run", "quick-start", "--resume", str(out))
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    # the run's own options come back, --quiet with them: the resume is read off run.json
    record = json.loads((out / "run.json").read_text())
    assert record["resumed"] == 1
    # which code began the run and which carried it on: the package imported and the contact law
    import fdem as package
    from fdem.physics.contact import CONTACT_LAW
    assert record["source"]["path"] == str(Path(package.__file__).resolve().parent)
    assert record["source"]["contact_law"] == CONTACT_LAW
    assert record["resumed_sources"] == [record["source"]]
    assert_same_run(uninterrupted, out)


@pytest.fixture(scope="module")
def uninterrupted_fos(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("whole_fos") / "run"
    done = fdem("run", "quick-start", *SCENE, "--fos", "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    return out


def test_a_factor_of_safety_trial_cut_short_goes_on_where_it_stopped(uninterrupted_fos, tmp_path):
    # the state the trial had reached is the resumable checkpoint, with the trial's runtime; the
    # search's start state, from which the later trials begin, is kept apart in fos_start.npz;
    # resumed, the run ends as the search never cut, history.csv and all
    out = tmp_path / "run"
    proc = start(out, "--fos")
    history = out / "history.csv"

    def rows_of_the_upper_trial() -> int:  # F = 2.0 fails and runs to its cap: hundreds of rows
        return sum(1 for line in history.open() if line.startswith("trial_F2")) if history.exists() else 0

    t0 = time.monotonic()
    while rows_of_the_upper_trial() < 3:  # well inside a trial, not between two
        if proc.poll() is not None or time.monotonic() - t0 > 240:
            pytest.fail(f"the trial at F = 2 did not begin:\n{proc.stdout.read() if proc.poll() is not None else ''}")
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    log = proc.communicate(timeout=120)[0]
    assert proc.returncode == 130, log
    saved = read_checkpoint(out / "checkpoint.npz")
    assert saved["context"]["stage"]["name"] == "trial_F2.0000"
    assert saved["state"]["step"] > state(out / "fos_start.npz")["step"] > 0  # the trial had stepped on
    assert not (out / "interrupted_state.npz").exists() and not (out / "final_state.npz").exists()
    assert (out / "interrupted_state.vtu").is_file()
    resumed = fdem("run", "quick-start", "--resume", str(out))
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    a = json.loads((uninterrupted_fos / "summary.json").read_text())["workflow"]["fos"]
    b = json.loads((out / "summary.json").read_text())["workflow"]["fos"]
    key = lambda t: (t["factor"], t["stable"], t["steps"], t["reason"], t["max_displacement"])  # noqa: E731
    assert [key(t) for t in b["trials"]] == [key(t) for t in a["trials"]] and b["bracket"] == a["bracket"]
    assert_same_run(uninterrupted_fos, out)


def test_a_runout_capped_while_moving_is_carried_on_to_rest(uninterrupted, tmp_path):
    # a run to rest is hours at paper scale: one that hit its runout cap still moving is carried on
    # with a longer cap, not started again, and ends as the run never capped, history.csv and all
    out = tmp_path / "run"
    capped = fdem("run", "quick-start", *SCENE, "--runout-time", "0.3", "--out", str(out))
    assert capped.returncode == 0, capped.stdout + capped.stderr
    last = json.loads((out / "summary.json").read_text())["workflow"]["stages"][-1]
    assert last["name"] == "runout" and last["reason"] == "capped"
    shorter = fdem("run", "quick-start", "--resume", str(out), "--runout-time", "0.2")
    assert shorter.returncode == 2 and "longer cap" in shorter.stderr
    at_rest = fdem("run", "quick-start", "--resume", str(uninterrupted), "--runout-time", "100")
    assert at_rest.returncode == 2 and "ran to its cap" in at_rest.stderr   # nothing to carry on
    # stopped right after it began (SIGTERM at its first rows), the carry-on resumes as a carry-on
    proc = subprocess.Popen([sys.executable, "-m", "fdem.cli", "run", "quick-start", "--resume", str(out),
                             "--runout-time", "100"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    saved = out / "checkpoint.npz"
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < 120:
        if read_checkpoint(saved)["context"].get("why") == "carried on":
            proc.send_signal(signal.SIGTERM)
            break
        time.sleep(0.02)
    log = proc.communicate(timeout=120)[0]
    assert proc.returncode == 143, log
    assert read_checkpoint(saved)["context"]["stage"]["name"] == "runout"  # the carry-on, in progress
    carried = fdem("run", "quick-start", "--resume", str(out))  # its cap now the run's own
    assert carried.returncode == 0, carried.stdout + carried.stderr
    assert json.loads((out / "run.json").read_text())["argv"][-2:] == ["--runout-time", "100.0"]
    # the ending is the carried-on runout's, not the capped one's undecided creep
    assert json.loads((out / "summary.json").read_text())["ending"].startswith("failed at F = 1.429; the runout "
                                                                               "came to rest at t = ")
    assert_same_run(uninterrupted, out)


def test_sigkill_then_resume_from_the_periodic_checkpoint(uninterrupted, tmp_path):
    out = tmp_path / "run"
    proc = start(out, "--checkpoint-every", "0.3")
    checkpoint = out / "checkpoint.npz"
    wait_for_rows(out, proc, 40)
    t0 = time.monotonic()
    while not checkpoint.exists() and time.monotonic() - t0 < 60:
        time.sleep(0.05)
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert json.loads((out / "run.json").read_text())["outcome"] == "running"  # killed: no ending written
    resumed = fdem("run", "quick-start", "--resume", str(out))
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    assert_same_run(uninterrupted, out)


def test_resume_refuses_changed_options_and_finished_runs(uninterrupted, tmp_path):
    changed = fdem("run", "quick-start", "--resume", str(uninterrupted), "--size", "1.0")
    assert changed.returncode == 2 and "--size" in changed.stderr
    finished = fdem("run", "quick-start", "--resume", str(uninterrupted))
    assert finished.returncode == 2 and "has finished" in finished.stderr
    other = fdem("run", "four-slopes", "--resume", str(uninterrupted))
    assert other.returncode == 2 and "quick-start" in other.stderr


def test_out_folder_holding_a_run_is_refused_unless_overwrite(uninterrupted, tmp_path):
    again = fdem("run", "quick-start", *SCENE, "--out", str(uninterrupted), "--max-time", "0.01")
    assert again.returncode == 2 and "--overwrite" in again.stderr
    out = tmp_path / "run"
    first = fdem("run", "quick-start", *SCENE, "--out", str(out), "--max-time", "0.2")
    assert first.returncode == 0, first.stderr
    frames = sorted(p.name for p in out.glob("slope_*.vtu"))
    (out / "slope_99999.vtu").write_text("a frame of the earlier run")
    second = fdem("run", "quick-start", *SCENE, "--out", str(out), "--max-time", "0.05", "--overwrite")
    assert second.returncode == 0, second.stderr
    assert not (out / "slope_99999.vtu").exists()  # the earlier run's frames do not mix with the new ones
    assert len(list(out.glob("slope_*.vtu"))) <= len(frames)


def test_out_folder_that_cannot_be_written_is_refused_before_meshing(tmp_path):
    a_file = tmp_path / "taken"
    a_file.write_text("not a folder")
    r = fdem("run", "quick-start", *SCENE, "--out", str(a_file))
    assert r.returncode == 2 and "is a file" in r.stderr
    r = fdem("run", "quick-start", *SCENE, "--out", str(a_file / "below"))
    assert r.returncode == 2 and "cannot be written" in r.stderr
    if os.geteuid() != 0:  # root writes anywhere: the permission probe means nothing there
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
        r = fdem("run", "quick-start", *SCENE, "--out", str(locked / "run"))
        assert r.returncode == 2 and "cannot be written" in r.stderr


def test_unstable_run_resumes_with_a_smaller_step(tmp_path, monkeypatch):
    """A run made unstable on purpose (its critical step overstated 4x) ends ``unstable`` with
    the reason and a good checkpoint; resumed with the true step, the same workflow finishes."""
    from fdem.cases import quick_start
    from fdem.solve.simulation import Simulation
    from fdem.workflow.journal import CHECKPOINT_NAME, RunJournal
    from fdem.workflow.slope import SlopeWorkflow, run_slope_workflow

    out = tmp_path / "run"
    _, sim, _, _ = quick_start.build(2.0, out, progress=False)
    true_dt = Simulation.critical_dt
    journal = RunJournal(out / CHECKPOINT_NAME)
    wf = SlopeWorkflow(factors=(1.0 / 0.9,), runout_time=0.5)
    with monkeypatch.context() as m:  # the equilibrium stage runs right, the first reduction step blows up
        m.setattr(Simulation, "critical_dt", lambda self: (lambda c, d: (c * (4.0 if self.state.step > 0 else 1.0), d))(
            *true_dt(self)))
        result = run_slope_workflow(sim, wf, out_dir=out, journal=journal)
    assert result["outcome"] == "unstable" and "unstable at step" in result["ending"]
    assert [s["name"] for s in result["stages"]] == ["equilibrium"]
    good = state(out / CHECKPOINT_NAME)
    assert np.all(np.isfinite(good["x"])) and good["step"] == result["stages"][0]["steps"]
    sim.close()
    _, again, _, _ = quick_start.build(2.0, out, progress=False)
    journal = RunJournal.resume_from(again, out / CHECKPOINT_NAME)
    result = run_slope_workflow(again, wf, out_dir=out, journal=journal)
    again.close()
    assert result["outcome"] in ("stable", "failed")
    assert [s["name"] for s in result["stages"]][:2] == ["equilibrium", "reduction_F1.111"]


def test_checkpoint_of_another_model_names_what_differs(tmp_path):
    from fdem.cases import quick_start
    from fdem.solve.checkpoint import load_checkpoint, save_checkpoint

    _, sim, _, _ = quick_start.build(2.0, None, progress=False)
    path = save_checkpoint(sim, tmp_path / "c.npz")
    _, other, _, _ = quick_start.build(2.0, None, progress=False)
    other.model.gravity[:] = (0.0, -5.0)
    with pytest.raises(ValueError, match="gravity"):
        load_checkpoint(other, path)
    _, other, _, _ = quick_start.build(2.0, None, progress=False)
    other.cracks.interfaces.property_sets[1] = quick_start.property_sets(penalty=2 * quick_start.PENALTY)[1]
    with pytest.raises(ValueError, match="crack-element property sets"):
        load_checkpoint(other, path)
    state_file = tmp_path / "s.npz"
    np.savez(state_file, x=sim.state.x, v=sim.state.v, x0=sim.x0, triangles=sim.triangles)
    with pytest.raises(ValueError, match="state file"):
        load_checkpoint(sim, state_file)


def test_a_full_disk_ends_with_a_message_a_summary_and_exit_1(tmp_path):
    """On a 2 MB tmpfs the frames fill the disk mid-run: one line on stderr (no traceback), exit
    1, and the summary and run.json say ``write_error`` with the reason (written in the room the
    run kept from its start, however full the frames left the disk)."""
    small = tmp_path / "small"
    small.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(small)],
                                           capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs here (needs root)")
    try:
        r = fdem("run", "quick-start", *SCENE, "--out", str(small / "run"))
        assert r.returncode == 1, r.stdout + r.stderr
        assert "Traceback" not in r.stderr and "No space left on device" in r.stderr
        summary = json.loads((small / "run" / "summary.json").read_text())
        record = json.loads((small / "run" / "run.json").read_text())
        assert summary["outcome"] == record["outcome"] == "write_error"
        assert "No space left" in record["ending"] and record["exit_code"] == 1
        assert not (small / "run" / ".fdem_room").exists()  # the room kept for these last words is given back
    finally:
        subprocess.run(["umount", str(small)], capture_output=True)


def test_overwrite_clears_only_a_folder_that_fdem_made(tmp_path):
    """--overwrite deletes files, so a folder with a summary.json that is not a run's is refused."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "summary.json").write_text('{"my": "notes"}')
    (mine / "field_data.csv").write_text("x,y\n1,2\n")
    r = fdem("run", "quick-start", *SCENE, "--out", str(mine), "--overwrite", "--max-time", "0.01")
    assert r.returncode == 2 and "fdem did not write" in r.stderr
    assert (mine / "field_data.csv").exists() and (mine / "summary.json").exists()


def test_a_stop_in_one_run_does_not_leak_into_the_next_in_the_same_process():
    from fdem.cases.common import stop_cleanly_on_signals
    from fdem.solve.simulation import STOP

    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    STOP.received, STOP.forced = "SIGTERM", True
    try:
        stop_cleanly_on_signals()
        assert STOP.received is None and not STOP.forced and STOP.pending is None
    finally:  # give the test process its own handlers back
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


def test_a_scene_file_run_resumes_from_its_own_copy_bit_identical(uninterrupted, tmp_path):
    """``fdem run FILE.toml`` stopped by SIGTERM resumes with ``fdem run scene --resume DIR``
    from the run's own ``scene.toml`` (the user's file is gone by then) and ends where the
    quick-start case ends uninterrupted: the case's written scene is the same model."""
    scene = tmp_path / "qs.toml"
    assert fdem("run", "quick-start", "--size", "2.0", "--write-scene", str(scene)).returncode == 0
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "fdem.cli", "run", str(scene), *SCENE[2:], "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    wait_for_rows(out, proc, 40)
    proc.send_signal(signal.SIGTERM)
    log = proc.communicate(timeout=120)[0]
    assert proc.returncode == 143, log
    scene.unlink()
    done = fdem("run", "scene", "--resume", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    assert json.loads((out / "run.json").read_text())["resumed"] == 1
    assert_same_run(uninterrupted, out)


def test_a_muliashi_run_stopped_in_its_gravity_search_goes_on_from_its_last_finished_trial(tmp_path, monkeypatch):
    """The Muliashi case searches the critical gravity factor on its own model before the slide,
    so its trials cannot live in the slide's checkpoint: they go to search_checkpoint.npz. A run
    stopped in the fourth trial (SIGTERM reaches a run as KeyboardInterrupt at a whole step) and
    resumed runs only the trials not finished, and ends with the bracket and the trials (factor,
    verdict, stage result) of the run never stopped; a second resume of the finished search runs
    no trial at all. Trials capped at 5 ms of simulated time, so that the eight take seconds."""
    from fdem.cases import muliashi
    from fdem.workflow import fos

    scene = ["--size", "1.0", "--max-time", "0.005", "--no-pictures", "--quiet", "--yes", "--threads", "1"]
    run_trial, calls = fos._run_trial, []

    def counted(*args, **kwargs):
        calls.append(args[3])  # the trial's factor
        if stop_at is not None and len(calls) == stop_at:
            raise KeyboardInterrupt("SIGTERM")
        return run_trial(*args, **kwargs)

    monkeypatch.setattr(fos, "_run_trial", counted)
    stop_at = None
    muliashi.main(scene + ["--out", str(tmp_path / "whole")])
    whole = json.loads((tmp_path / "whole" / "fos.json").read_text())
    assert whole["n_trials"] >= 6 and len(calls) == whole["n_trials"]

    calls.clear()
    stop_at = 4
    cut = muliashi.main(scene + ["--out", str(tmp_path / "cut")])
    assert cut["outcome"] == "interrupted" and (tmp_path / "cut" / muliashi.SEARCH_CHECKPOINT).is_file()
    assert not (tmp_path / "cut" / "fos.json").exists()
    # the search's checkpoint names the code that wrote it, as the run's own does
    from fdem.cases.common import _source
    from fdem.solve.checkpoint import read_checkpoint

    assert read_checkpoint(tmp_path / "cut" / muliashi.SEARCH_CHECKPOINT)["context"].get("writer") == _source()

    calls.clear()
    stop_at = None
    muliashi.main(["--resume", str(tmp_path / "cut")])
    resumed = json.loads((tmp_path / "cut" / "fos.json").read_text())
    assert len(calls) == whole["n_trials"] - 3                  # the three finished trials replayed, not rerun
    assert resumed["bracket"] == whole["bracket"]
    keep = ("factor", "stable", "reason", "steps", "t_end", "max_displacement")
    assert [{k: t.get(k) for k in keep} for t in resumed["trials"]] == [{k: t.get(k) for k in keep} for t in whole["trials"]]

    # stopped in the first trial, before any trial finished: the search's start is on disk, so
    # the run resumes too (and runs every trial)
    calls.clear()
    stop_at = 1
    first = muliashi.main(scene + ["--out", str(tmp_path / "first")])
    assert first["outcome"] == "interrupted" and (tmp_path / "first" / muliashi.SEARCH_CHECKPOINT).is_file()
    calls.clear()
    stop_at = None
    muliashi.main(["--resume", str(tmp_path / "first")])
    assert len(calls) == whole["n_trials"]
    assert json.loads((tmp_path / "first" / "fos.json").read_text())["bracket"] == whole["bracket"]

    # stopped once the search is done, as the slide begins: the resume runs no trial
    from fdem.workflow import stages

    run_stage = stages.run_stage

    def stopped_slide(*args, **kwargs):
        raise KeyboardInterrupt("SIGTERM")

    calls.clear()
    monkeypatch.setattr(stages, "run_stage", stopped_slide)
    assert muliashi.main(scene + ["--out", str(tmp_path / "slide")])["outcome"] == "interrupted"
    assert len(calls) == whole["n_trials"]
    monkeypatch.setattr(stages, "run_stage", run_stage)
    calls.clear()
    searched = (tmp_path / "slide" / muliashi.SEARCH_CHECKPOINT).stat().st_mtime_ns
    done = muliashi.main(["--resume", str(tmp_path / "slide")])
    assert calls == [] and done["outcome"] == "finished"
    assert (tmp_path / "slide" / muliashi.SEARCH_CHECKPOINT).stat().st_mtime_ns == searched  # not written again
    assert done["critical_gravity_factor"]["bracket"] == whole["bracket"]


def test_a_resume_by_another_commit_names_the_one_that_wrote_the_checkpoint(tmp_path):
    """Each checkpoint names the code that wrote it, and a resume by another commit is told
    which one that was (not the commit of an earlier resume that was refused before it wrote
    anything): a commit that changed what a checkpoint holds refuses it or reads it wrongly,
    and a pinned checkout of the writer goes on with it."""
    from fdem.cases.common import other_writer
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation
    from fdem.workflow.journal import RunJournal

    def simulation():
        model = Model(build_topology(structured_rectangle(2, 2, 1.0, 1.0)),
                      ElasticMaterial(young=1e8, poisson=0.25, density=2500.0))
        return Simulation(model, progress=False)

    a, b = {"commit": "a" * 40}, {"commit": "b" * 40}
    journal = RunJournal(tmp_path / "checkpoint.npz")
    journal.writer = a
    journal.write(simulation(), "written by a")
    resumed = RunJournal.resume_from(simulation(), tmp_path / "checkpoint.npz")
    assert resumed.written_by == a
    note = other_writer(resumed.written_by, b)
    assert "this is commit bbbbbbbbbb" in note and "written by aaaaaaaaaa" in note
    assert other_writer(resumed.written_by, a) is None
    assert other_writer(None, b) is None                  # a checkpoint written before it named its writer
    assert other_writer(a, {"commit": None}) is None      # an installed package
