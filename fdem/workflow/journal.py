"""A workflow's journal: what makes a run of hours resumable, bit for bit.

A workflow (:func:`fdem.workflow.slope.run_slope_workflow`) is a sequence of stages whose
path depends only on how earlier stages ended. The journal records that path and, with the
simulation's own state, writes it into one checkpoint file (``checkpoint.npz``,
:func:`fdem.solve.checkpoint.save_checkpoint`):

* ``done``: every finished stage's result (:class:`~fdem.workflow.stages.StageResult`), in order;
* ``marks``: side effects done once, by key, with their JSON value (the runout's start
  checkpoint, the factor-of-safety search's result);
* ``stage``: the runtime of the stage in progress when the file was written (its start time and
  step, the positions it measures displacement from, its end rule's state, its step count),
  or ``None`` between stages.

It is written when a stage ends, every ``every_seconds`` of wall time inside a stage (on a
history row), and when the run is interrupted (at a whole step: :class:`fdem.solve.simulation.StopRequest`).
A resumed run replays the workflow: finished stages return their recorded results without
stepping, the stage in progress continues from its saved runtime with the same history steps
(:meth:`fdem.solve.simulation.Simulation.run` ``phase``), and the rest runs as it would have.
The checkpoint is always a good state: an unstable step never writes one, so after an
instability it holds the last stage end or periodic write, to resume with a smaller step.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

__all__ = ["CHECKPOINT_NAME", "CAPPED_MARK", "RunJournal"]

CHECKPOINT_NAME = "checkpoint.npz"
"""The journal's checkpoint file in a run's output folder."""

CARRIED_ENDINGS = ("capped", "left_model")
"""Endings of a last stage that :meth:`RunJournal.carry_on` takes back into progress: its cap, and
the model's end (a runout ended by fly-rock before fragments leaving the model were held beyond
it, :attr:`fdem.workflow.stages.Stage.escape_share`: carried on, the fragment is held at the
first check and the runout goes on)."""

CAPPED_MARK = "capped_stage_runtime"
"""The journal mark holding the runtime of a last stage that ran to its cap (:meth:`RunJournal.carry_on`)."""


class RunJournal:
    """The journal of one workflow run (module docstring).

    path : the checkpoint file (``None``: nothing written; the journal still replays)
    every_seconds : wall time [s] between periodic checkpoints inside a stage (``None``: only at
        stage ends and interruptions)
    """

    def __init__(self, path=None, every_seconds: float | None = None):
        if every_seconds is not None and not every_seconds > 0:
            raise ValueError(f"checkpoint interval must be a positive number of seconds, got {every_seconds!r}")
        self.path = None if path is None else Path(path)
        self.every_seconds = every_seconds
        self.done: list[dict] = []
        self.marks: dict = {}
        self.resume: dict | None = None   # runtime of the stage to continue, from the checkpoint
        self.current: Callable[[], dict] | None = None   # runtime of the stage now running
        self.writes: list[tuple[str, int]] = []   # (why, simulation step) of every checkpoint written
        self.writer: dict | None = None   # the code writing the checkpoints (fdem.cases.common._source), kept in them
        self.written_by: dict | None = None   # the code that wrote the checkpoint this journal resumed from
        self._calls = 0
        self._last_write = time.monotonic()

    # ------------------------------------------------------------------ replay
    def next_stage(self, name: str) -> tuple[str, dict | None]:
        """What to do with the workflow's next stage ``name``: ``("done", result)`` when it
        finished before the checkpoint, ``("resume", runtime)`` when it was in progress,
        ``("fresh", None)`` otherwise. A replay that asks for another stage than the one
        recorded (the options changed the workflow's path) is refused."""
        i = self._calls
        self._calls += 1
        if i < len(self.done):
            recorded = self.done[i]["name"]
            if recorded != name:
                raise ValueError(f"resume: stage {i + 1} of the checkpoint is {recorded!r}, but this run's workflow "
                                 f"asks for {name!r}; resume with the options the run started with")
            return "done", self.done[i]
        if self.resume is not None:
            runtime, self.resume = self.resume, None
            if runtime["name"] != name:
                raise ValueError(f"resume: the checkpoint was written in stage {runtime['name']!r}, but this run's "
                                 f"workflow asks for {name!r} next; resume with the options the run started with")
            return "resume", runtime
        return "fresh", None

    def ahead(self) -> bool:
        """Whether the checkpoint's state lies beyond the stages replayed so far (a later stage
        finished or in progress): the simulation is not in the state the last replayed stage
        ended in, so nothing may be measured on it for that stage."""
        return self._calls < len(self.done) or self.resume is not None

    def once(self, key: str, action: Callable[[], object]):
        """``action()`` the first time ``key`` is asked for, its recorded value on a replay."""
        if key not in self.marks:
            self.marks[key] = action()
        return self.marks[key]

    # ------------------------------------------------------------------ writing
    def stage_finished(self, sim, result: dict, runtime: dict | None = None) -> None:
        """Record a finished stage and write the checkpoint (a stage end is a good state).
        ``runtime``: the runtime of a stage that ran to its cap, kept (:data:`CAPPED_MARK`) until
        the next stage ends, so that :meth:`carry_on` can continue it as if never capped."""
        self.done.append(dict(result))
        self.current = None
        if runtime is not None:
            self.marks[CAPPED_MARK] = runtime
        else:
            self.marks.pop(CAPPED_MARK, None)
        self.write(sim, "stage end")

    def carry_on(self, sim, prefix: str, x_start) -> dict:
        """Take the last finished stage back into progress: a stage named ``prefix...`` that ran
        to its cap (``reason`` ``"capped"``), to be carried on by the workflow to the longer cap
        it is now given (a runout capped while still moving, continued to rest). Its runtime at
        the cap is the stage's own when the checkpoint kept it (:meth:`stage_finished`); for a
        checkpoint written before it did, it is rebuilt from the stage's result and ``x_start()``
        (the positions the stage started from, [m]), the end rules' windows beginning afresh.
        The history row the cap added off the stage's history steps is dropped, so the carried-on
        run's rows are those of a run never capped; its end rules have seen that row (one more
        check, at the old cap, than the uncapped run). Returns the stage's result; a
        ``ValueError`` says why a stage cannot be carried on."""
        if not self.done:
            raise ValueError("the run finished no stage: there is nothing to carry on")
        last = self.done[-1]
        if not str(last["name"]).startswith(prefix) or last["reason"] not in CARRIED_ENDINGS:
            raise ValueError(f"the run's last stage is {last['name']!r}, which ended {last['reason']!r}: only a "
                             f"{prefix} stage that ran to its cap, or off the model, can be carried on")
        runtime = self.marks.pop(CAPPED_MARK, None)
        cap_row_extra = None  # known when the stage kept its runtime (stages.run_stage), else guessed below
        if runtime is not None and runtime.get("name") == last["name"]:
            runtime = dict(runtime)
            cap_row_extra = runtime.pop("cap_row_extra", None)
        else:
            runtime = {"name": last["name"], "t0": float(last["t_start"]), "dt": float(last["dt"]),
                       "measured_critical": last.get("measured_critical_dt"),
                       "step0": int(sim.state.step) - int(last["steps"]), "x_start": x_start(), "ramp": None,
                       "status": {"reason": None, "detail": "", "peak": float(last["peak_kinetic_energy"]),
                                  "ratio": float("nan"), "speed": 0.0, "disp": 0.0, "since": None},
                       "wall_seconds": float(last["wall_seconds"]), "output_seconds": last.get("output_seconds")}
        self.done.pop()
        self.resume = {**runtime, "n_total": None}  # the steps to the new cap: counted by the stage
        # the row the cap added off the stage's history steps goes: the run's rows, and the peak
        # kinetic energy between rows, are those of a run never capped. The stage says whether its
        # cap row is one; for a checkpoint that did not keep it, the row is taken as off the steps
        # when it is nearer its row before than that row is to the one before it (the stage's last
        # spacing, as a stage resumed with another step has another; a guess a renewed measured
        # step, whose segments end on rows of their own, can defeat)
        rows = [r for r in sim.history if r.get("stage") == last["name"]]
        if rows and sim.history[-1] is rows[-1]:
            if cap_row_extra is None and len(rows) >= 3:
                a, b, c = (int(r["step"]) for r in rows[-3:])
                cap_row_extra = 0 < c - b < b - a
            if cap_row_extra:
                cap_row = sim.history.pop()
                sim.kinetic_peak = max(sim.kinetic_peak, float(cap_row.get("kinetic_peak", 0.0)))
        return last

    def tick(self, sim) -> None:
        """Write a periodic checkpoint if ``every_seconds`` of wall time have passed."""
        if self.every_seconds is not None and time.monotonic() - self._last_write >= self.every_seconds:
            self.write(sim, "periodic")

    def write(self, sim, why: str) -> Path | None:
        """Write the checkpoint now (``why`` goes into :attr:`writes`)."""
        self._last_write = time.monotonic()
        if self.path is None:
            return None
        from fdem.solve.checkpoint import save_checkpoint

        # between stages, a stage in progress that a resume has not reached yet is still in
        # progress: the state is the checkpoint's (replayed stages do not step), and a stop now
        # (a signal right after a resume or a carry-on began) must keep it, or the resume after
        # it would start that stage afresh
        context = {"journal": 1, "done": self.done, "marks": self.marks,
                   "stage": self.current() if self.current is not None else self.resume, "why": why}
        if self.writer is not None:
            context["writer"] = self.writer
        t0 = time.perf_counter()
        save_checkpoint(sim, self.path, context=context)
        # the interval runs from the end of the write: a write slower than the interval (a large
        # model, a loaded disk or CPU) must not make every later tick write again
        self._last_write = time.monotonic()
        if hasattr(sim, "output_seconds"):
            sim.output_seconds["checkpoints"] += time.perf_counter() - t0
        self.writes.append((why, int(sim.state.step)))
        return self.path

    # ------------------------------------------------------------------ reading
    @classmethod
    def resume_from(cls, sim, path, every_seconds: float | None = None, write_to=None) -> "RunJournal":
        """Load the checkpoint ``path`` into ``sim`` (:func:`fdem.solve.checkpoint.load_checkpoint`)
        and return its journal, ready to replay; later checkpoints go to ``write_to`` (default
        ``path``). A checkpoint written without a journal (``interrupted_state.npz`` of a bare
        simulation, a stage's own file) restarts the workflow from its first stage on that state:
        refused here, as it would not repeat the run."""
        from fdem.solve.checkpoint import load_checkpoint

        context = load_checkpoint(sim, path)
        if not isinstance(context, dict) or context.get("journal") != 1:
            raise ValueError(f"{path} holds a simulation state but no workflow journal, so the run cannot be "
                             "continued where it stopped; load it with fdem.solve.checkpoint.load_checkpoint "
                             "to look at it or to start a new workflow from it")
        journal = cls(write_to or path, every_seconds)
        journal.done = [dict(r) for r in context["done"]]
        journal.marks = dict(context["marks"])
        journal.resume = context["stage"]
        journal.written_by = context.get("writer")
        return journal
