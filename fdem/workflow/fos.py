"""Factor of safety: strength reduction and gravity increase as triggers, and the bisection search.

:func:`factor_of_safety` brackets the smallest reduction factor ``F`` (or gravity factor) at
which the slope fails, running one trial stage per factor from the same saved state
(optionally in a process pool); it returns a :class:`FoSResult`.

Factor of safety (:func:`factor_of_safety`): from a state in equilibrium, each trial sets a
factor ``F`` of a trigger (strength reduction: ``c / F``, ``tan(phi) / F`` everywhere, see
:mod:`fdem.physics.interfaces`), restarts from the saved state and runs a damped stage. The slope is
*stable* at ``F`` if that stage converges, *failing* if the failure rule fires or the stage
does not converge within its cap (non-convergence, as in the strength-reduction practice of
Dawson, Roth & Drescher 1999). Bisection narrows ``[stable, failing]`` to the tolerance."""
from __future__ import annotations

import dataclasses
from fdem.io.jsonable import write_json
from fdem.io.messages import say, warn
import math
import numbers
import time
from dataclasses import dataclass, field
from pathlib import Path
import numpy as np
from fdem.solve.damping import Damping
from fdem.solve.simulation import Simulation
from fdem.workflow.stages import (Convergence, Failure, Stage, StageResult, failure_displacement, ratio_limit,
                                  response_time, run_stage)

__all__ = ["StrengthReduction", "GravityIncrease", "Trial", "FoSResult", "BracketError", "most_trials", "fundamental_damping",
           "default_trial_stage", "factor_of_safety", "check_bracket", "MIN_RELATIVE_TOL", "DEFAULT_MAX_TRIALS",
           "TRIALS_MARK", "START_NAME", "trial_curves", "trial_curve", "settling_at_cap", "SETTLING_SHARE",
           "bracket_by_cap", "bracket_words", "SHORTEST_READ_CAP",
           "DEFAULT_CAP_RESPONSE_TIMES", "creep_verdict", "moved_in_all", "FOLLOW_SUFFIX"]

MIN_RELATIVE_TOL = 1e-6
"""Smallest tolerance of the search as a fraction of the bracket's upper end. Below it the
bisection asks for a resolution no trial can decide (a factor of safety is judged by stages
whose own convergence limits are far coarser) and, near float resolution (about 2e-16
relative), the bracket's midpoint stops moving and the search never ends."""

DEFAULT_MAX_TRIALS = 40
"""Default cap on the trials of one search, the two ends included. With the tolerance at its
smallest (:data:`MIN_RELATIVE_TOL` of the upper end) bisection of a bracket ``[0, upper]``
needs ``log2(1e6) + 2 = 22`` trials; the cap leaves room above that, and a search that meets
it says so (``FoSResult.ended_by``)."""


SETTLING_SHARE = 0.9
"""A trial at its cap reads as settling (:func:`settling_at_cap`) when its largest displacement
grew less than this share in its last response time of what it grew in the one before: a
tenth less each response time, clear of a steady creep's share of 1 and its scatter."""

DEFAULT_CAP_RESPONSE_TIMES = 5.0
"""The default cap of a trial, and of the slope workflow's damped stages (``step_time``), in
response times (:func:`fdem.workflow.stages.response_time`)."""

SHORTEST_READ_CAP = 2.0
"""The shortest cap, in response times, at which :func:`bracket_by_cap` reads a search's trials:
the first response time of a trial is the elastic answer to the change of strength, which
decays on a slope that then slides, so shorter trials say nothing of the slope."""

FOLLOW_SUFFIX = "_rest"
"""The name of a trial's follow to rest (:func:`factor_of_safety` ``follow``) is the trial's
stage name with this suffix."""

TRIALS_MARK = "fos_trials"
"""The journal mark (:attr:`fdem.workflow.journal.RunJournal.marks`) holding a search's finished
trials while it runs (:func:`factor_of_safety` ``journal``)."""

START_NAME = "fos_start.npz"
"""The search's start state, beside the journal's checkpoint (and in ``out_dir`` for parallel
trials): every trial restarts from it. With a journal the checkpoint holds a trial in progress
(written every ``--checkpoint-every`` seconds and when interrupted), so the start state a
resumed search needs for its later trials is kept apart."""


def _real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def most_trials(lower: float, upper: float, tol: float, max_trials: int = DEFAULT_MAX_TRIALS) -> int:
    """The trials a serial search of ``[lower, upper]`` to ``tol`` takes at most: the two ends
    and ``floor(log2((upper - lower) / tol)) + 1`` halvings, capped at ``max_trials``. One more
    halving than ``ceil`` when the width is ``tol`` times a power of two: the midpoints are
    rounded, and a bracket of exactly ``tol`` can come out a few ulps wider (``[1.0, 1.8]`` to 0.1
    takes 6 trials, not 5)."""
    width = upper - lower
    halvings = 0 if width <= tol else 1 + math.floor(math.log2(width / tol))
    return min(int(max_trials), 2 + halvings)


def check_bracket(lower: float, upper: float, tol: float, max_trials: int = DEFAULT_MAX_TRIALS) -> None:
    """A ``ValueError`` naming the first bad setting of a factor-of-safety search: ``lower`` and
    ``upper`` positive and finite with ``lower < upper``, ``tol`` finite and at least
    :data:`MIN_RELATIVE_TOL` times ``upper``, ``max_trials`` an integer >= 2 (the two ends).
    Cheap: cases call it when they parse their options, before any meshing."""
    for name, value in (("lower", lower), ("upper", upper)):
        if not (_real(value) and math.isfinite(value) and value > 0):
            raise ValueError(f"factor_of_safety: {name} must be a positive finite factor, got {value!r}")
    if not upper > lower:
        raise ValueError(f"factor_of_safety: upper ({upper}) must exceed lower ({lower})")
    if not (_real(tol) and math.isfinite(tol) and tol > 0):
        raise ValueError(f"factor_of_safety: tol must be a positive finite bracket width, got {tol!r}")
    if tol < MIN_RELATIVE_TOL * upper:
        raise ValueError(f"factor_of_safety: tol = {tol:g} is below the resolution a search can reach, "
                         f"{MIN_RELATIVE_TOL:g} of the upper factor ({MIN_RELATIVE_TOL * upper:.3g}); "
                         f"give tol >= {MIN_RELATIVE_TOL * upper:.3g}")
    if isinstance(max_trials, bool) or not isinstance(max_trials, (int, np.integer)) or max_trials < 2:
        raise ValueError(f"factor_of_safety: max_trials must be an integer >= 2 (the two ends of the bracket), "
                         f"got {max_trials!r}")


class BracketError(ValueError):
    """The trial at an end of the bracket contradicts it (``lower`` fails or ``upper`` stands).
    ``trial`` is that :class:`Trial`; ``trial.time_capped`` tells a trial stopped by the run's
    ``--max-time`` cap (a smoke run) from a genuine verdict."""

    def __init__(self, message: str, trial: "Trial"):
        super().__init__(message)
        self.trial = trial


def _interfaces(sim):
    """The strength-reduction home of ``sim``'s crack elements; a ``ValueError`` if it has none."""
    if sim.cracks is None:
        raise ValueError("this simulation has no crack elements (CrackSet): no strength to reduce")
    return sim.cracks.interfaces


# ----------------------------------------------------------------------------- factor of safety
class StrengthReduction:
    """Trigger of the factor-of-safety search: the strength-reduction factor ``F``
    (:meth:`fdem.physics.interfaces.Interfaces.set_reduction`); larger ``F`` is weaker."""

    name = "strength reduction"

    def apply(self, sim: Simulation, factor: float) -> None:
        _interfaces(sim).set_reduction(factor)

    def reset(self, sim: Simulation, factor: float) -> None:
        # a restored state already holds its factor: setting it again would re-project the
        # crack elements onto their envelopes and move the state it should leave alone
        if _interfaces(sim).reduction != factor:
            _interfaces(sim).set_reduction(factor)

    def current(self, sim: Simulation) -> float:
        return _interfaces(sim).reduction


class GravityIncrease:
    """Trigger of the factor-of-safety search: gravity multiplied by the factor ``k`` (larger
    is heavier), from the model's gravity, as the Muliashi study raises the density ten-fold
    (``shared/cases.md`` B). The critical gravity factor is the factor of safety against
    self-weight. :meth:`fdem.solve.simulation.Simulation.set_gravity` books each change in the ledger."""

    name = "gravity increase"

    def __init__(self, base_gravity=None):
        self.base = None if base_gravity is None else np.asarray(base_gravity, float)

    def _base(self, sim: Simulation) -> np.ndarray:
        if self.base is None:
            self.base = np.asarray(sim.model.gravity, float).copy()
            if not np.any(self.base):
                raise ValueError("gravity increase: the model has no gravity to multiply")
        return self.base

    def apply(self, sim: Simulation, factor: float) -> None:
        sim.set_gravity(*(factor * self._base(sim)))

    def reset(self, sim: Simulation, factor: float) -> None:
        sim.set_gravity(*(factor * self._base(sim)))

    def current(self, sim: Simulation) -> float:
        base = self._base(sim)
        return float(np.dot(sim.gravity, base) / np.dot(base, base))


@dataclass
class Trial:
    """One trial of the search: the factor, ``stable`` or not, and the stage that decided it.
    ``time_capped``: the trial stopped at the simulation's ``time_cap`` (``--max-time``), so
    "not stable" only means "not converged yet"."""

    factor: float
    stable: bool
    result: StageResult
    time_capped: bool = False
    rows: list = field(default_factory=list, repr=False)
    """The history rows the trial made (``history.csv``; the restore after it drops them from
    ``sim.history``), kept for a replay from the run's journal."""

    cap_trend: dict | None = None
    """For a trial that reached its cap: whether it was still settling there
    (:func:`settling_at_cap`); ``None`` otherwise, or without its rows."""

    follow: StageResult | None = None
    """For a trial that reached its cap in a search that follows such trials to rest
    (:func:`factor_of_safety` ``follow``): the undamped stage after it, whose end decided the
    verdict (:func:`creep_verdict`); ``None`` otherwise."""

    follow_verdict: str | None = None
    """:func:`creep_verdict` of a followed trial: ``crept`` (stable), ``failed`` or
    ``undecided`` (the follow reached its own cap short of the failure displacement; counted failing)."""

    def as_dict(self) -> dict:
        return {"factor": self.factor, "stable": self.stable, "time_capped": self.time_capped,
                **self.result.as_dict(), **({"cap_trend": self.cap_trend} if self.cap_trend is not None else {}),
                **({"follow": self.follow.as_dict(), "follow_verdict": self.follow_verdict}
                   if self.follow is not None else {})}


@dataclass
class FoSResult:
    """Result of :func:`factor_of_safety`.

    ``fos`` is the middle of ``bracket = (largest stable factor, smallest failing factor)``.
    ``ended_by`` says what ended the search: ``"tolerance"`` (the bracket is at most ``tolerance``
    wide) or ``"max_trials"`` (the trial cap came first: the bracket is wider than asked).
    ``failure_surface`` lists the crack elements broken
    or gone inelastic (softened or slid) in the first failing trial, ``failure_broken`` those
    broken; ``failure_positions`` the node positions at the end of that trial.
    """

    fos: float
    bracket: tuple[float, float]
    tolerance: float
    trigger: str
    trials: list[Trial]
    failure_surface: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    failure_broken: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    failure_positions: np.ndarray | None = None
    failure_mode: np.ndarray | None = None
    wall_seconds: float = 0.0
    ended_by: str = "tolerance"
    max_trials: int = DEFAULT_MAX_TRIALS
    by_cap: list = field(default_factory=list)
    """The bracket the same trials give at caps of a half, a quarter, ... of theirs
    (:func:`bracket_by_cap`), the trials' own cap last."""

    @property
    def leans_on_cap(self) -> bool:
        """The bracket's failing end is a trial that reached its cap still settling
        (:func:`settling_at_cap`): a longer cap might have found it stable and moved the factor up.
        ``False`` does not mean that the factor is the cap's own: a failing end that reached its
        cap creeping can stop later too (each capped trial's ``cap_trend``, :func:`settling_at_cap`)."""
        failing = [t for t in self.trials if not t.stable and t.factor == self.bracket[1]]
        # a trial followed to rest was judged by its follow, not by its cap: it leans on the
        # runout's cap when its follow ended there short of the failure displacement
        if failing and failing[0].follow is not None:
            return failing[0].follow_verdict == "undecided"
        return bool(failing and failing[0].cap_trend is not None and failing[0].cap_trend["settling"])

    def as_dict(self) -> dict:
        return {"fos": self.fos, "bracket": list(self.bracket), "tolerance": self.tolerance, "trigger": self.trigger,
                "ended_by": self.ended_by, "max_trials": self.max_trials, "leans_on_cap": self.leans_on_cap,
                "n_trials": len(self.trials), "wall_seconds": self.wall_seconds,
                "failure_surface_elements": int(self.failure_surface.size),
                "failure_broken_elements": int(self.failure_broken.size), "by_cap": self.by_cap,
                "trials": [t.as_dict() for t in self.trials]}


def fundamental_damping(sim: Simulation) -> Damping:
    """Mass-proportional damping critical for the model's fundamental mode:
    ``alpha = 2 omega_1 = 4 pi / T`` [1/s] (:func:`response_time`).

    The quasi-static damping of strength-reduction stages. Cundall's local damping
    (``-beta |f| sign(v)`` per node) acts on each node's whole force, and on a block sliding on
    a frictional joint the stick-slip forces of the joint nodes are many times the net driving
    force: a block at F = 4 times its strength crept 2 mm in 10 response times under local
    damping 0.8 instead of sliding. Mass-proportional damping resists a sliding block only in
    proportion to its speed, settles the fundamental mode in about one period, and gave
    factors of safety within 0.1 % of limit equilibrium on the planar slope
    (``docs/verification/planar_failure.json``)."""
    return Damping(mass_proportional=4.0 * math.pi / response_time(sim.model))


def default_trial_stage(sim: Simulation, equilibrium_ratio: float = 1e-4, max_time: float | None = None,
                        fail: Failure | None = None, damping: Damping | None = None, hold_for: float = 0.0) -> Stage:
    """The damped trial of a factor-of-safety search: :func:`fundamental_damping`, converged
    when the unbalanced-force ratio falls below ``equilibrium_ratio`` (default 1e-4), failed by
    ``fail`` (default: a node moves 1 % of the model height), capped at ``max_time`` (default 5
    response times; non-convergence counts as failure). The slope workflow passes its own
    ``equilibrium_ratio``, ``step_time`` and ``fail_displacement``
    (:class:`fdem.workflow.slope.SlopeWorkflow`), and the damping of its reduction steps
    (``damping``, default :func:`fundamental_damping`), so that its trials and its reduction
    steps judge a slope by one rule. ``hold_for`` [s]: the ratio must keep below its limit that
    long, check after check, before the trial counts as stable (default 0: the first check)."""
    return Stage("trial", max_time=max_time or DEFAULT_CAP_RESPONSE_TIMES * response_time(sim.model),
                 converge=Convergence(unbalanced_ratio=equilibrium_ratio, hold_for=hold_for), fail=fail or Failure(),
                 damping=damping if damping is not None else fundamental_damping(sim))


def _trial_stage_at(trial: Stage, factor: float) -> Stage:
    return dataclasses.replace(trial, name=f"{trial.name}_F{factor:.4f}", reduction=None, reduction_ramp=None,
                               gravity_factor=None)


class _TrialJournal:
    """The run's journal as one trial of a search sees it (:func:`run_stage` ``journal``): the
    trial's periodic and interrupted checkpoints go into the run's checkpoint, with the trial's
    runtime, so that a trial of hours goes on where it stopped; its end is not a workflow stage
    (no entry in ``done``, no write: the search writes after restoring its start state)."""

    def __init__(self, journal, resume: dict | None = None):
        self.journal = journal
        self.resume = resume

    def next_stage(self, name: str) -> tuple[str, dict | None]:
        runtime, self.resume = self.resume, None
        return ("fresh", None) if runtime is None else ("resume", runtime)

    @property
    def current(self):
        return self.journal.current

    @current.setter
    def current(self, runtime) -> None:
        self.journal.current = runtime

    def tick(self, sim) -> None:
        self.journal.tick(sim)

    def write(self, sim, why: str):
        return self.journal.write(sim, why)

    def stage_finished(self, sim, result: dict, runtime: dict | None = None) -> None:
        self.journal.current = None


def _stage_result(d: dict) -> StageResult:
    """A :class:`StageResult` from its journal record (a trial's record holds other keys too)."""
    keep = {f.name for f in dataclasses.fields(StageResult)}
    return StageResult(**{k: v for k, v in d.items() if k in keep})


def moved_in_all(trial: dict) -> float:
    """The largest displacement [m] a trial of ``fos.json`` (:meth:`Trial.as_dict`) reached, its
    follow's added when it was followed to rest (a bound: the two stages' largest node
    displacements, as :func:`creep_verdict` counts them). For a trial that stood it is the
    creep at rest; where that grows smoothly with the factor, the factor of safety is where it
    reaches the failure displacement."""
    follow = trial.get("follow")
    return float(trial["max_displacement"]) + (float(follow["max_displacement"]) if follow else 0.0)


def creep_verdict(stage_reason: str, stage_displacement: float, follow_reason: str, follow_displacement: float,
                  fail_displacement: float) -> str:
    """What a damped stage that did not settle within its cap, followed undamped, says of the
    slope: ``"crept"`` when the follow came to rest (``converged``) with less than the failure
    displacement [m] moved in the two stages together (bounded by the sum of their largest node
    displacements [m]): the slope crept and stood; ``"undecided"`` when the follow reached its
    own cap with less than that moved; ``"failed"`` otherwise (the damped stage failed by the
    rule itself, the motion reached the failure displacement, or the mass left the model).

    The one rule of the slope workflow's damped reduction steps (:func:`fdem.workflow.slope._tell_creep`)
    and of a search's trials followed to rest (:func:`factor_of_safety` ``follow``)."""
    if stage_reason == "failed" or stage_displacement + follow_displacement >= fail_displacement:
        return "failed"
    return {"converged": "crept", "capped": "undecided"}.get(follow_reason, "failed")


def _follow_stage_at(follow: Stage, trial: Stage, factor: float, remaining: float) -> Stage:
    """The follow of the trial at ``factor``: named after it, failing once the motion since the
    trial began could reach the failure displacement (``remaining`` [m] more)."""
    return dataclasses.replace(follow, name=_trial_stage_at(trial, factor).name + FOLLOW_SUFFIX,
                               fail=Failure(displacement=remaining))


def _run_trial(sim: Simulation, trigger, trial: Stage, factor: float, judge=None, journal=None,
               first_row: int | None = None, follow: Stage | None = None, capped: StageResult | None = None,
               on_follow=None) -> tuple[Trial, dict | None]:
    """One trial on ``sim`` (already restored to the starting state): the verdict (the stage
    converged, or ``judge(sim, result)`` when given), and for a failing trial what it broke
    (failure surface, broken elements, positions, modes).

    ``follow`` (a stage, undamped): a trial that reaches its cap goes on in it, and its verdict
    is :func:`creep_verdict`'s (stable when it crept and came to rest); ``on_follow(result)`` is
    called with the capped trial's result before the follow begins. ``capped``: the trial's
    result when it is resumed inside its follow (the trial stage is not run again).

    ``journal`` (a :class:`_TrialJournal`): the trial writes resumable checkpoints; one whose
    ``resume`` holds a runtime continues the trial from the restored mid-trial state, the
    factor already applied (applied again it would re-project damaged elements onto their
    envelope), its history rows from ``first_row`` on."""
    if capped is None and (journal is None or journal.resume is None):
        trigger.apply(sim, factor)
    first_row = len(sim.history) if first_row is None else first_row
    result = capped if capped is not None else run_stage(sim, _trial_stage_at(trial, factor), frames=False,
                                                         journal=journal)
    stable = bool(judge(sim, result)) if judge is not None else result.reason == "converged"
    followed = verdict = None
    if follow is not None and result.reason == "capped" and not getattr(sim, "time_capped", False):
        fail_d = failure_displacement(sim, trial.fail)
        if on_follow is not None:
            on_follow(result)
        # the capped stage ended within the failure displacement (checked at its last step)
        remaining = max(fail_d - result.max_displacement, 1e-9 * fail_d)
        followed = run_stage(sim, _follow_stage_at(follow, trial, factor, remaining), frames=False, journal=journal)
        verdict = creep_verdict(result.reason, result.max_displacement, followed.reason, followed.max_displacement,
                                fail_d)
        stable = verdict == "crept"
    info = None
    cracks = sim.cracks
    if not stable and cracks is not None:
        info = dict(factor=factor, surface=cracks.inelastic(), broken=np.flatnonzero(cracks.broken),
                    positions=sim.state.x.copy(), mode=cracks.failure_mode.copy())
    return Trial(factor, stable, result, time_capped=bool(getattr(sim, "time_capped", False)),
                 rows=[dict(r) for r in sim.history[first_row:]], follow=followed, follow_verdict=verdict), info


_WORKER: dict = {}


def _worker_trial(build, build_args: tuple, checkpoint: str, trigger, trial: Stage, factor: float, judge=None,
                  follow: Stage | None = None):
    """A trial in a worker process: build the scene once, load the equilibrium checkpoint, then
    restart every trial from it."""
    from fdem.solve.checkpoint import load_checkpoint, restore, snapshot

    key = (build, build_args, checkpoint)
    if _WORKER.get("key") != key:
        sim = build(*build_args)
        sim.progress = False
        load_checkpoint(sim, checkpoint)
        _WORKER.update(key=key, sim=sim, start=snapshot(sim))
    sim = _WORKER["sim"]
    restore(sim, _WORKER["start"])
    return _run_trial(sim, trigger, trial, factor, judge, follow=follow)


def factor_of_safety(sim: Simulation, lower: float = 1.0, upper: float = 4.0, tol: float = 0.01,
                     trial: Stage | None = None, trigger=None, out_dir=None, workers: int = 1,
                     build=None, build_args: tuple = (), max_trials: int = DEFAULT_MAX_TRIALS,
                     judge=None, journal=None, follow: Stage | None = None) -> FoSResult:
    """Factor of safety by bisection on a trigger's factor (default strength reduction).

    ``sim`` must hold a state in equilibrium (a geostatic start or a converged stage); every
    trial restarts from it (:func:`fdem.solve.checkpoint.snapshot`) with the trigger set to the trial
    factor and runs ``trial`` (default :func:`default_trial_stage`). ``lower`` must be stable
    and ``upper`` failing, else a :class:`BracketError` (a ``ValueError``) names the trial that
    contradicts the bracket. The search stops when the bracket is at most ``tol`` wide or after
    ``max_trials`` trials (the two ends included), whichever comes first; ``FoSResult.ended_by``
    says which. ``tol`` below :data:`MIN_RELATIVE_TOL` of ``upper`` is refused
    (:func:`check_bracket`): bisection cannot resolve it, and at float resolution it never ends. On return ``sim`` is back in
    its starting state with the trigger at its starting value; with ``out_dir`` the result is
    written to ``out_dir/fos.json`` and the first failing trial to ``out_dir/fos_failure.png``
    (displacement since the equilibrium state, broken crack elements coloured by mode and the
    softened or sliding ones in black: the failure surface).

    Trials in parallel: with ``workers = w > 1`` each round runs ``w`` trials at once in
    worker processes (one Numba thread each), at the ``w`` points that split the bracket into
    ``w + 1`` equal parts, so a round narrows it ``w + 1``-fold instead of 2-fold. Each worker
    builds the scene with ``build(*build_args)`` (a picklable, module-level function returning
    a simulation of the same mesh and providers as ``sim``) and restarts its trials from a
    checkpoint of ``sim`` (:func:`fdem.solve.checkpoint.save_checkpoint`; in ``out_dir`` when given).

    ``judge(sim, stage_result) -> bool`` (optional): the verdict of a trial, called on the trial's
    end state, for trials that end by their duration rather than by convergence (a shaken slope
    judged by its permanent displacement, :class:`fdem.workflow.seismic.BaseShaking`); the trial
    stage then needs no converge rule. Without it a trial is stable when its stage converged.
    With ``workers > 1`` it must be picklable.

    ``follow`` (an undamped stage, the slope workflow's runout stage): a trial that reaches its
    cap is followed in it, and is stable when it came to rest having moved less than the failure
    displacement in all (:func:`creep_verdict`, the rule of the slope workflow's damped steps),
    instead of failing at its cap. A damped creep that would stop after any cap is then judged
    by whether it stops, not by how long it takes: the high-angle four slopes creep for 10 T
    and more at factors where the damped steps, followed to rest, find them standing
    (``docs/cases.md`` A). Its verdicts do not read at shorter caps (no ``by_cap``). Not with
    ``judge``.

    ``journal`` (a :class:`fdem.workflow.journal.RunJournal`): every finished trial is recorded
    in it (its verdict and stage result; the first failing trial's broken elements and positions
    for the picture) and the checkpoint is written, holding the search's start state. A trial
    the journal already holds is not run again, so a search cut short (the end of a session in
    a bisection of hours) goes on from its last finished trial when the run is resumed. The
    trial under way is kept too, with one trial at a time and no ``judge``: it writes the journal's periodic
    checkpoint and, when interrupted, its state there with its stage's runtime, the start state
    kept apart in :data:`START_NAME` beside the checkpoint; resumed, it goes on from that state
    (a trial of the 0.5 m low-angle scene is an hour; restarted at every session's end, a
    search of such trials loses one each time). Parallel trials (``workers > 1``) under way are
    lost. The trials are the same as in a search that was never cut (each starts from the same
    state, the bisection's points follow from the verdicts alone, and a trial resumed takes
    the history steps of the uninterrupted one), and ``wall_seconds`` counts the replayed
    trials' own.
    """
    from fdem.solve.checkpoint import CheckpointMismatch, restore, save_checkpoint, snapshot

    check_bracket(lower, upper, tol, max_trials)
    workers = int(workers)
    if workers < 1:
        raise ValueError(f"factor_of_safety: workers must be >= 1, got {workers}")
    if workers > 1 and not callable(build):
        raise ValueError("factor_of_safety: workers > 1 needs build, a module-level function returning a "
                         "simulation identical to sim (the workers restart trials from a checkpoint of sim)")
    trigger = trigger or StrengthReduction()
    trial = trial or default_trial_stage(sim)
    if follow is not None and judge is not None:
        raise ValueError("factor_of_safety: follow judges a capped trial by whether it comes to rest; a judged "
                         "trial has its own verdict: give one or the other")
    if follow is not None and failure_displacement(sim, trial.fail) is None:
        raise ValueError("factor_of_safety: follow judges a capped trial by the failure displacement, and the trial "
                         "stage's fail rule gives none (a speed alone, or no rule): give it a displacement")
    if trial.converge is None and judge is None:
        raise ValueError("factor_of_safety: the trial stage needs a converge rule (stability is convergence) "
                         "or a judge of its end state")
    rule = trial.converge
    cracks = sim.cracks
    trials: list[Trial] = []
    first_fail: dict = {}
    wall = time.perf_counter()
    pool = None
    tmp = None
    saved_env = None

    search = {"lower": float(lower), "upper": float(upper), "tol": float(tol), "trigger": trigger.name,
              "trial": trial.name, "max_time": trial.max_time}
    if rule is not None and rule.unbalanced_ratio not in (None, 1e-4):  # a trial judged by another rule is
        search["ratio"] = rule.unbalanced_ratio                          # another search; the default keeps
    if rule is not None and rule.hold_for:                              # the keys of checkpoints written before
        search["hold_for"] = rule.hold_for
    if follow is not None:  # the follow's rules judge the trials too: a resume must keep them
        search["follow"] = {"name": follow.name, "max_time": follow.max_time, "dt_fraction": follow.dt_fraction,
                            "step_from": follow.step_from,
                            "converge": None if follow.converge is None else dataclasses.asdict(follow.converge)}
    progress = None
    cut = None   # (factor, runtime, state, capped result if inside its follow) of a trial the checkpoint holds
    start_file = None if journal is None or journal.path is None or workers > 1 else journal.path.with_name(START_NAME)
    if journal is not None:
        progress = journal.marks.get(TRIALS_MARK)
        if progress is not None and progress.get("search") != search:
            # refused, not set aside: run on, the next checkpoint would replace the trials it holds
            # (hours of a fine mesh's search) with this search's, and a resume by the code that
            # wrote them could no longer go on with them
            then = "rest" if "follow" in (progress.get("search") or {}) else "cap"
            hint = "" if then == ("rest" if "follow" in search else "cap") else (
                f"; its capped trials were judged by trial_end '{then}' and this search's would not be: set the "
                f"workflow's trial_end (scene key, --trial-end) to '{then}' (the default was 'cap' before 2026-12-08)")
            raise CheckpointMismatch(f"the checkpoint holds {len(progress['trials'])} finished trial(s) of another "
                             f"search ({progress.get('search')}) than this one ({search}); resume it with the "
                             f"commit and options that wrote it, or start the search again in a new directory{hint}")
        fresh = progress is None
        if fresh:
            progress = journal.marks[TRIALS_MARK] = {"search": search, "trials": [], "first_fail": None}
        running, runtime = progress.get("running"), journal.resume
        in_trial = runtime is not None and str(runtime.get("name", "")).startswith(f"{trial.name}_F")
        own = None if running is None else _trial_stage_at(trial, float(running)).name
        in_follow = in_trial and follow is not None and own is not None and runtime["name"] == own + FOLLOW_SUFFIX \
            and progress.get("running_capped") is not None
        if in_trial and not (workers == 1 and judge is None and running is not None
                             and (runtime["name"] == own or in_follow)):
            raise CheckpointMismatch(f"the checkpoint was written in the factor-of-safety trial {runtime['name']!r}, "
                             f"which this search ({workers} worker(s){', judged' if judge is not None else ''}, "
                             f"{search}) cannot go on with; resume with the options the run started with")
        if in_trial and (start_file is None or not start_file.is_file()):
            raise ValueError(f"resume: the checkpoint was written in the factor-of-safety trial at {trigger.name} "
                             f"{float(running):.6g}, but the search's start state {start_file} is missing; "
                             f"start the run again")
        if in_trial:  # the state loaded is the trial's, to go on with once the finished trials are replayed
            journal.resume = None
            cut = (float(running), runtime, snapshot(sim),
                   _stage_result(progress["running_capped"]) if in_follow else None)
        if not fresh and start_file is not None and start_file.is_file():
            # a resumed search starts from the state kept apart when it began, whatever state the
            # checkpoint holds (a trial's, or one written by a stop before the trial went on)
            from fdem.solve.checkpoint import load_checkpoint

            load_checkpoint(sim, start_file)
            sim.continue_outputs()  # history.csv back to the search's start, the trials' rows then in order
        elif start_file is not None:
            save_checkpoint(sim, start_file)
    start_factor = trigger.current(sim)
    start = snapshot(sim)
    if judge is None and trigger.name == "strength reduction":
        _tell_raised_limit(sim, rule)
    replayed = {float(d["factor"]): d for d in progress["trials"]} if progress else {}
    replayed_wall = 0.0

    def record(outcome, from_journal: bool = False) -> bool:
        t, info = outcome
        t.cap_trend = _cap_trend(sim, t)
        trials.append(t)
        if info is not None and (not first_fail or t.factor < first_fail["factor"]):
            first_fail.clear()
            first_fail.update(info)
        r = t.result
        fw = t.follow
        followed = "" if fw is None else (
            f"; followed undamped, {'came to rest' if fw.reason == 'converged' else fw.reason} after "
            f"{fw.t_end - fw.t_start:.3g} s, {r.max_displacement + fw.max_displacement:.3g} m at most in all, "
            f"{fw.wall_seconds:.3g} s of wall time")
        say(f"factor of safety: trial {len(trials)} at {trigger.name} {t.factor:.5g}: "
            f"{'stable' if t.stable else 'failing'} ({r.reason} after {r.t_end - r.t_start:.3g} s, "
            f"{r.wall_seconds:.3g} s of wall time{followed}{', replayed from the checkpoint' if from_journal else ''})")
        if progress is not None and not from_journal:
            # the trial's verdict, and the search's start state, onto disk before the next trial
            # (a worker's rows never reached this run's history.csv: none to write again)
            progress.pop("running", None)
            progress.pop("running_capped", None)
            progress["trials"].append({**t.as_dict(), "rows": t.rows if pool is None else []})
            progress["first_fail"] = dict(first_fail) if first_fail else None
            restore(sim, start)
            trigger.reset(sim, start_factor)
            journal.write(sim, f"factor-of-safety trial F = {t.factor:.6g}")
        return t.stable

    def replay(factor: float) -> bool:
        nonlocal replayed_wall
        d = replayed[factor]
        followed = d.get("follow")
        t = Trial(factor=factor, stable=bool(d["stable"]), time_capped=bool(d["time_capped"]),
                  result=_stage_result(d), rows=list(d.get("rows", [])),
                  follow=None if followed is None else _stage_result(followed), follow_verdict=d.get("follow_verdict"))
        sim.write_history_rows(t.rows)  # history.csv as the search never cut wrote it
        ff = progress["first_fail"]
        info = dict(ff) if ff is not None and not t.stable and float(ff["factor"]) == factor else None
        replayed_wall += t.result.wall_seconds + (t.follow.wall_seconds if t.follow is not None else 0.0)
        return record((t, info), from_journal=True)

    if workers > 1:
        import multiprocessing
        import os
        import tempfile
        from concurrent.futures import ProcessPoolExecutor

        if out_dir is not None:
            Path(out_dir).mkdir(parents=True, exist_ok=True)
            checkpoint = Path(out_dir) / START_NAME
        else:
            tmp = tempfile.TemporaryDirectory(prefix="fdem_fos_")
            checkpoint = Path(tmp.name) / START_NAME
        save_checkpoint(sim, checkpoint)
        # workers inherit the environment: one Numba thread each, so trials do not fight for cores
        saved_env = os.environ.get("NUMBA_NUM_THREADS")
        os.environ["NUMBA_NUM_THREADS"] = "1"
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))

    def on_follow(result: StageResult) -> None:
        # the capped trial's result, for a resume inside its follow (the trial is not run again)
        if progress is not None:
            progress["running_capped"] = result.as_dict()

    def run_many(factors: list[float]) -> list[bool]:
        nonlocal cut
        verdicts = {f: replay(f) for f in factors if f in replayed}
        todo = [f for f in factors if f not in verdicts]
        if pool is None:
            for f in todo:
                resume = capped = None
                if cut is not None and cut[0] == f:  # the trial the checkpoint holds: on from where it stopped
                    _, resume, state, capped = cut
                    restore(sim, state)
                    sim.write_history_rows(sim.history[len(start["history"]):])
                else:
                    restore(sim, start)
                cut = None
                if progress is not None:
                    progress["running"] = f  # a checkpoint written inside the trial names it
                # a judged trial's trigger keeps state outside the simulation (the shaking's
                # record): its trials are not checkpointed inside, a cut one begins again
                inside = journal is not None and judge is None
                verdicts[f] = record(_run_trial(sim, trigger, trial, f, judge,
                                                journal=_TrialJournal(journal, resume) if inside else None,
                                                first_row=len(start["history"]), follow=follow, capped=capped,
                                                on_follow=on_follow))
        else:
            futures = [pool.submit(_worker_trial, build, tuple(build_args), str(checkpoint), trigger, trial, f, judge,
                                   follow) for f in todo]
            for f, fut in zip(todo, futures):
                verdicts[f] = record(fut.result())
        return [verdicts[f] for f in factors]

    try:
        ends = run_many([lower, upper])
        if not ends[0]:
            r = trials[0].result
            raise BracketError(f"factor_of_safety: the slope already fails at the lower factor F = {lower:g} "
                               f"({r.reason}: {r.detail}); lower the bracket", trials[0])
        if ends[1]:
            r = trials[1].result
            raise BracketError(f"factor_of_safety: the slope is still stable at the upper factor F = {upper:g} "
                               f"({r.reason} {r.detail}); raise the bracket", trials[1])
        lo, hi = lower, upper
        ended_by = "tolerance"
        while hi - lo > tol:
            room = max_trials - len(trials)
            if room <= 0:
                ended_by = "max_trials"
                break
            n = min(workers, room)
            points = [lo + (hi - lo) * (k + 1) / (n + 1) for k in range(n)]
            stable = run_many(points)
            failing = [f for f, st in zip(points, stable) if not st]
            hi = min(failing + [hi])
            lo = max([f for f, st in zip(points, stable) if st and f < hi] + [lo])
    except BracketError:
        if journal is not None:  # a search that cannot go on: nothing of it to carry in later checkpoints
            journal.marks.pop(TRIALS_MARK, None)
        raise
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
            import os

            if saved_env is None:
                os.environ.pop("NUMBA_NUM_THREADS", None)
            else:
                os.environ["NUMBA_NUM_THREADS"] = saved_env
        if tmp is not None:
            tmp.cleanup()
        restore(sim, start)
        trigger.reset(sim, start_factor)
    result = FoSResult(fos=0.5 * (lo + hi), bracket=(lo, hi), tolerance=tol, trigger=trigger.name, trials=trials,
                       failure_surface=first_fail.get("surface", np.zeros(0, np.int64)),
                       failure_broken=first_fail.get("broken", np.zeros(0, np.int64)),
                       failure_positions=first_fail.get("positions"), failure_mode=first_fail.get("mode"),
                       wall_seconds=time.perf_counter() - wall + replayed_wall, ended_by=ended_by,
                       max_trials=int(max_trials))
    if trials and trial.duration is None and trial.max_time is not None and follow is None:  # capped trials
        stretch = trials[0].result.period_stretch  # times of a density-scaled trial are the scaled model's
        result.by_cap = bracket_by_cap([t.as_dict() for t in trials], response_time(sim.model) * stretch,
                                       stretch * trial.max_time)
    if journal is not None:  # the search is whole: its caller records the result itself
        journal.marks.pop(TRIALS_MARK, None)
    _tell_leaning_on_cap(sim, result)
    _tell_by_cap(result)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "fos.json", result.as_dict())
        # the pictures come after the result is on disk, and a picture that cannot be drawn (a
        # full disk, a broken matplotlib) is told, not raised: the search of hours is kept
        try:
            if result.failure_positions is not None and cracks is not None:
                _failure_picture(out / "fos_failure.png", sim, cracks, result)
            _trials_picture(out / "fos_trials.png", sim, result, trial)
        except Exception as err:  # noqa: BLE001 - any picture failure; the result is what matters
            warn(f"factor of safety: a picture of the search could not be drawn ({type(err).__name__}: {err}); "
                 f"the result is in {out / 'fos.json'}")
    return result


def _tell_raised_limit(sim: Simulation, rule: Convergence | None) -> None:
    """Warn, once before a strength-reduction search's first trial (on its start state, which
    every trial's floor is taken from), when the model's round-off floor raises the ratio limit
    and the rule takes it at its first check. (A gravity search's trials each take the floor of
    their own gravity, ``1 / k`` of it: no one limit to name.)"""
    if rule is None or rule.unbalanced_ratio is None or rule.hold_for:
        return
    limit = ratio_limit(sim, rule)
    if limit > rule.unbalanced_ratio:
        warn(f"factor of safety: the ratio limit {rule.unbalanced_ratio:.3g} is raised to {limit:.3g}, "
             f"{rule.roundoff_factor:g} times this model's round-off floor; taken at its first check a raised "
             f"limit can pass a trial that still creeps (docs/cases.md A: the low-angle coarse slope at 1.0 m), "
             f"and one held for a response time does not (SlopeWorkflow and scene key equilibrium_hold = 1, "
             f"fdem run four-slopes --equilibrium-hold 1)")


def trial_curves(result: FoSResult) -> list[dict]:
    """Each trial's history (its ``rows``) as the curves of
    :func:`fdem.io.pictures.trial_histories_plot`: time since the trial's first row [s], the
    unbalanced-force ratio, the growth of the largest displacement since that row [m], and the
    ratio limit the trial's rule applied (``StageResult.ratio_limit``); a trial followed to rest
    goes on into its follow, from ``follow_from`` [s]. Trials without rows (run
    by parallel workers) or histories without the ratio column are left out."""
    curves = []
    for t in result.trials:
        rows = [r for r in t.rows if "unbalanced_ratio" in r and "max_displacement" in r]
        if rows:
            curve = trial_curve(t.factor, t.stable, [float(r["time"]) for r in rows],
                                [float(r["unbalanced_ratio"]) for r in rows],
                                [float(r["max_displacement"]) for r in rows], t.result.ratio_limit)
            # a followed trial was judged by its follow, drawn on from the cap; not by its cap
            curve["settling"] = bool(t.follow is None and t.cap_trend and t.cap_trend["settling"])
            curve["follow_from"] = None if t.follow is None else float(t.result.t_end - float(rows[0]["time"]))
            curves.append(curve)
    return curves


def trial_curve(factor: float, stable: bool, time, ratio, max_displacement, limit: float | None = None) -> dict:
    """One trial's curve for :func:`fdem.io.pictures.trial_histories_plot` from its history
    columns ``time`` [s], ``unbalanced_ratio`` and ``max_displacement`` [m] (from the reference
    state): time and displacement taken from the trial's first row."""
    time, disp = np.asarray(time, float), np.asarray(max_displacement, float)
    return {"factor": factor, "stable": stable, "time": time - time[0], "ratio": np.asarray(ratio, float),
            "displacement": disp - disp[0], "limit": limit}


def settling_at_cap(time, max_displacement, ratio, window: float, limit: float | None = None) -> dict | None:
    """Whether a trial that reached its cap was still settling there, from its history rows.

    Over the last two windows of ``window`` [s] (a response time): the growth of the largest
    displacement in the last window against the one before, ``share = d_last / d_before``, and
    the fall of the unbalanced-force ratio, ``ratio_fall = g_before / g_last`` (``g`` the
    geometric mean of the ratio over a window). The trial is *settling* when both say so:
    ``share`` under :data:`SETTLING_SHARE` and ``ratio_fall > 1``; a creeping slope keeps
    ``share`` at 1 or above. Were the growth to keep shrinking by ``share`` per window, the
    slope would move a further ``d_last share / (1 - share)`` [m]
    (``further_if_geometric``, a geometric series) and its ratio would meet ``limit`` after
    ``log(g_last / limit) / log(ratio_fall) - (n - 1) / (2 n)`` more windows after the cap
    (``windows_to_limit``; ``g_last`` is the ratio at the middle of the window's ``n`` rows). Both
    are exact for a response that decays geometrically.

    A reading of the trend, not a verdict, either way: a slope that breaks elements one by one
    can settle for a window and slip again (on the low-angle coarse four-slope scene at 1.0 m a
    trial settling at its 5 T cap was still creeping at 15 T), and a creep can stop later (the
    high-angle coarse scene at 1.0 m, F = 1.6, crept 1.8 and then 2.7 mm in the last two
    response times before its 5 T cap, then slowed and converged at 9.3 T after 2.0 cm;
    ``docs/cases.md`` A). Only a longer trial tells. Returns ``None`` for a trial shorter than
    two windows (its first response time is the elastic answer to the
    change of strength, which decays on a slope that then slides) or with fewer than four rows
    a window."""
    time = np.asarray(time, float)
    disp = np.asarray(max_displacement, float)
    ratio = np.asarray(ratio, float)
    if time.size < 9:
        return None
    # a window is the last n rows (the checks are evenly spaced in time); its growth runs from
    # the row before it to its last row
    n = int(round(float(window) / float(np.median(np.diff(time)))))
    if n < 4 or time.size < 2 * n + 1:
        return None
    d_last = float(disp[-1] - disp[-1 - n])
    d_before = float(disp[-1 - n] - disp[-1 - 2 * n])
    share = d_last / d_before if d_before > 0 else math.inf
    r_last, r_before = ratio[-n:], ratio[-2 * n:-n]
    if not (np.all(np.isfinite(r_last) & (r_last > 0)) and np.all(np.isfinite(r_before) & (r_before > 0))):
        return None
    g_last = float(np.exp(np.mean(np.log(r_last))))
    g_before = float(np.exp(np.mean(np.log(r_before))))
    fall = g_before / g_last
    settling = bool(share < SETTLING_SHARE and fall > 1.0)
    trend = {"window": float(window), "displacement_last": d_last, "displacement_before": d_before, "share": share,
             "ratio_last": g_last, "ratio_before": g_before, "ratio_fall": fall, "settling": settling}
    if settling:
        trend["further_if_geometric"] = d_last * share / (1.0 - share)
        if limit is not None and limit > 0:
            trend["windows_to_limit"] = max(0.0, math.log(g_last / limit) / math.log(fall) - (n - 1) / (2.0 * n))
    return trend


def bracket_by_cap(trials: list[dict], window: float, cap: float) -> list[dict]:
    """The bracket a search's trials give at shorter caps than their own: whether the factor of
    safety depends on how long a trial may take to converge.

    A trial steps the same whatever its cap until it stops, so trials capped at ``cap`` [s]
    hold the verdicts of trials capped at any ``c < cap``: a trial is stable at ``c`` when it
    converged within ``c`` (``t_end - t_start <= c``), and failing otherwise (one that failed by
    displacement, or reached ``cap``, fails at every shorter cap too). Read at ``cap``, ``cap/2``,
    ``cap/4``, ... down to :data:`SHORTEST_READ_CAP` response times (``window`` [s]), shortest
    first. Each reading: ``cap_s``, ``cap_response_times``, the factors ``stable`` and ``failing``
    there, ``bracket = [largest stable, smallest failing]`` (``None`` where no trial is stable,
    or none failing: the factor lies below, or above, every factor tried), and ``ordered``, false
    where a stable factor lies above a failing one (a creep that settled at a higher factor
    than one that did not, within that cap).

    ``trials``: :meth:`Trial.as_dict` of each (``factor``, ``stable``, ``reason``, ``t_start``,
    ``t_end``, ``time_capped``; ``fos.json``'s ``trials``); trials the run's ``--max-time`` cut
    have no verdict and are left out. At ``cap`` the reading is the search's own bracket when
    the verdicts there are ordered. A bracket that moves from ``cap/2`` to ``cap`` is a factor
    set by the trials' length (``docs/cases.md`` A, "The high-angle coarse factor against the
    trial's cap"); one that does not is no proof that a longer cap would leave it (a creep can
    stop later than any cap read here)."""
    caps = [float(cap)]
    while caps[-1] / 2.0 >= SHORTEST_READ_CAP * window * (1.0 - 1e-9):
        caps.append(caps[-1] / 2.0)
    judged = [t for t in trials if not t.get("time_capped")]
    readings = []
    for c in reversed(caps):
        # at the trials' own cap their own verdicts (a trial that converged on its last step may
        # end a step past the cap)
        stable = sorted(float(t["factor"]) for t in judged
                        if t["stable"] and (c == caps[0] or t["t_end"] - t["t_start"] <= c * (1.0 + 1e-9)))
        failing = sorted(float(t["factor"]) for t in judged if float(t["factor"]) not in stable)
        lo = stable[-1] if stable else None
        hi = failing[0] if failing else None
        readings.append({"cap_s": c, "cap_response_times": c / window, "stable": stable, "failing": failing,
                         "bracket": [lo, hi], "ordered": lo is None or hi is None or lo < hi})
    return readings


def bracket_words(bracket: list) -> str:
    """A bracket of :func:`bracket_by_cap` in words: ``lo-hi``, or below / above every factor tried."""
    lo, hi = bracket
    if lo is None:
        return f"below {hi:.5g} (every trial failing)" if hi is not None else "no trials"
    if hi is None:
        return f"above {lo:.5g} (every trial stable)"
    return f"{lo:.5g}-{hi:.5g}"


def _tell_by_cap(result: FoSResult) -> None:
    """One line: the bracket the search's trials give at its shorter caps, when any differs
    from the trials' own (:func:`bracket_by_cap`)."""
    if len(result.by_cap) < 2 or all(r["bracket"] == result.by_cap[-1]["bracket"] for r in result.by_cap):
        return
    say("factor of safety against the trials' length (the same trials read at shorter caps): "
        + "; ".join(f"{r['cap_response_times']:.3g} T {bracket_words(r['bracket'])}"
                    + ("" if r["ordered"] else " (not ordered: a stable factor above a failing one)")
                    for r in result.by_cap)
        + ": the factor moved with the cap, and may move further with longer trials; trials followed to rest "
          "(the slope workflow's trial_end 'rest', its default) give the slope's")


def _cap_trend(sim: Simulation, t: Trial) -> dict | None:
    """:func:`settling_at_cap` of a trial that ran to its cap, over windows of a response time."""
    r = t.result
    rows = [row for row in t.rows if "unbalanced_ratio" in row and "max_displacement" in row
            and row.get("stage", r.name) == r.name]   # not its follow's, when it had one
    if r.reason != "capped" or not rows:
        return None
    return settling_at_cap([float(row["time"]) for row in rows], [float(row["max_displacement"]) for row in rows],
                           [float(row["unbalanced_ratio"]) for row in rows],
                           window=response_time(sim.model) * r.period_stretch, limit=r.ratio_limit)


def _tell_leaning_on_cap(sim: Simulation, result: FoSResult) -> None:
    """Warn when the bracket's failing end reached its cap still settling (``leans_on_cap``)."""
    if not result.leans_on_cap:
        return
    t = next(t for t in result.trials if not t.stable and t.factor == result.bracket[1])
    trend, r = t.cap_trend, t.result
    if t.follow is not None:   # judged by its follow, which reached the runout's cap still short of failing
        fw = t.follow
        warn(f"factor of safety: the bracket's failing end, F = {t.factor:.5g}, was followed undamped to the "
             f"runout's cap ({fw.t_end - fw.t_start:.4g} s) and had moved {r.max_displacement + fw.max_displacement:.3g} m, "
             f"short of the failure displacement, still moving: counted failing, the factor may lean on that cap "
             f"(a longer runout cap, SlopeWorkflow.runout_time, --runout-time, tells)")
        return
    if trend is None:   # a trial whose rows carry no unbalanced ratio: no reading to give
        return
    T = response_time(sim.model) * r.period_stretch
    warn(f"factor of safety: the bracket's failing end, F = {t.factor:.5g}, reached its cap of "
         f"{r.t_end - r.t_start:.4g} s ({(r.t_end - r.t_start) / T:.3g} response times) still settling: its largest "
         f"displacement grew {trend['share']:.2f} times as much in the last response time as in the one before, "
         f"and its unbalanced ratio fell {trend['ratio_fall']:.2f}-fold (to {trend['ratio_last']:.3g}); the factor "
         f"may lean on the cap, and longer trials may move it: trials followed to rest (SlopeWorkflow and "
         f"scene key trial_end 'rest', the default; fdem run four-slopes --trial-end rest) tell whether the slope "
         f"stands there")


def _trials_picture(path: Path, sim: Simulation, result: FoSResult, trial: Stage) -> Path | None:
    """``fos_trials.png``: every trial's ratio and displacement against its own time, with the
    limit each trial's rule applied (one line where they agree; a gravity search's trials,
    whose floor falls as ``1 / k``, each draw their own) and the hold in the trials' time."""
    from fdem.io.pictures import trial_histories_plot

    curves = trial_curves(result)
    if not curves:
        return None
    limits = {c["limit"] for c in curves} - {None}   # None: a trial replayed from before limits were kept
    if not limits:   # all such: the limit the rule takes on the search's start state (sim is back in it)
        limits = {ratio_limit(sim, trial.converge)}
    limit = limits.pop() if len(limits) == 1 else None
    if limit is not None:
        for c in curves:
            c.pop("limit")
    stretch = result.trials[0].result.period_stretch   # density-scaled trials hold in the scaled time
    hold = trial.converge.hold_for * stretch if trial.converge is not None else 0.0
    return trial_histories_plot(path, curves, limit=limit, hold=hold,
                                trigger="F" if result.trigger == "strength reduction" else "k")


def _failure_picture(path: Path, sim: Simulation, cracks, result: FoSResult) -> Path:
    """The first failing trial: displacement from the equilibrium state and the failure surface."""
    from fdem.io.pictures import failure_frame

    x = result.failure_positions
    topo = sim.model.topology
    cn = topo.crack_nodes
    segs = np.stack([0.5 * (x[cn[:, 0]] + x[cn[:, 3]]), 0.5 * (x[cn[:, 1]] + x[cn[:, 2]])], axis=1)
    show = np.zeros(topo.n_cracks, bool)
    show[result.failure_surface] = True
    mode = np.zeros(topo.n_cracks, np.int8)
    if result.failure_mode is not None:
        mode[result.failure_broken] = result.failure_mode[result.failure_broken]
    disp = np.linalg.norm(x - sim.state.x, axis=1)
    failing = min((t.factor for t in result.trials if not t.stable), default=float("nan"))
    return failure_frame(path, x, topo.triangles, disp, segs, show, mode,
                         title=f"first failing trial F = {failing:.3f} (FoS {result.fos:.3f}, "
                               f"bracket {result.bracket[0]:.3f}-{result.bracket[1]:.3f}); black: softened or sliding")
