"""The slope workflow: equilibrium, factor of safety, strength reduction to failure, runout to rest.

Composed of :mod:`fdem.workflow.stages` so that a case script only builds the model and calls
:func:`run_slope_workflow`:

1. **Equilibrium check** at ``F = 1`` (the model must come from a geostatic start,
   :func:`fdem.solve.geostatic.geostatic_start`): a damped stage that must converge; a slope that
   does not stand at ``F = 1`` is reported, not hidden. It is damped critically for the slope's
   Rayleigh frequency (:func:`equilibrium_damping`); the later damped stages use
   :func:`fdem.workflow.fos.fundamental_damping` (mass-proportional, critical for the shear-beam mode).
2. **Factor of safety** (optional): :func:`fdem.workflow.fos.factor_of_safety` from that state.
3. **Strength reduction** until failure, either in *steps* (``F = 1/0.9, 1/0.8, ...``, each a
   damped stage that converges — stable — or fails), or at a *rate* (the four-slope paper:
   the strength falls by 10 % of its initial value per 10,000 steps of 2 us, i.e. ``1/F``
   falls by 5 per second, undamped). With ``trigger="gravity"`` instead: gravity increase, the
   critical gravity factor by bisection and the slide at it (:func:`_gravity_increase`).
4. **Runout** at the factor where the slope failed: dynamic (no quasi-static damping), until
   the kinetic energy falls below a fraction of its peak and stays there for one response
   time, capped in simulated time. With ``out_dir`` the state it starts from is saved to
   ``runout_start.npz`` (:func:`fdem.solve.checkpoint.load_checkpoint` restarts from it).

Every stage's result (why it ended, when, how many steps) goes into the returned summary, and
every ending is one of its outcomes: ``stable``, ``failed``, ``crept`` (a reduction stage did not
settle, but the undamped stage after it came to rest after less than the failure displacement:
the slope crept and stopped; in steps, the reduction then carries on from the resting state,
and a later factor may still fail; with ``local_fall_area`` likewise after a *local fall*, a
runout that came to rest with less than that area moved the failure displacement: a block
off the face, not the slope), ``undecided`` (such a stage whose runout was capped before
it came to rest or moved the failure displacement), ``time_capped``, ``interrupted`` (Ctrl-C or a signal: the state reached is kept) or ``unstable`` (the guard stopped an unstable
step: the reason, and the last good state to resume from with a smaller step). With a
:class:`~fdem.workflow.journal.RunJournal` the run writes resumable checkpoints and a resumed
run replays the workflow to where it stopped (:mod:`fdem.workflow.journal`).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import NamedTuple
import numpy as np
from fdem.solve.damping import NO_DAMPING, Damping
from fdem.geometry.polygons import ground_surface, slope_crest, slope_toe
from fdem.solve.geostatic import crack_strength_check, rayleigh_frequency, unbalanced_force_ratio
from fdem.solve.simulation import STOP, InstabilityError, Simulation
from fdem.workflow.stages import STEP_FROM, Convergence, Failure, Stage, response_time, run_stage
from fdem.workflow.fos import (DEFAULT_CAP_RESPONSE_TIMES, BracketError, GravityIncrease, bracket_words, check_bracket,
                               creep_verdict, default_trial_stage, factor_of_safety, fundamental_damping,
                               moved_in_all)

__all__ = ["TRIAL_ENDS", "reduction_steps", "final_factor", "start_against_strength", "SlopeWorkflow", "run_slope_workflow", "equilibrium_damping", "runout_stage",
           "factor_of_safety_figures", "steps_bracket"]


def reduction_steps(final_strength: float = 0.3, step: float = 0.1) -> tuple[float, ...]:
    """Reduction factors ``F`` whose strengths ``1/F`` fall by ``step`` of the initial value,
    from ``1 - step`` down to ``final_strength`` (the four-slope schedule: 0.9, ..., 0.3)."""
    if not (0 < final_strength < 1 and 0 < step < 1):
        raise ValueError(f"final_strength and step must lie in (0, 1), got {final_strength}, {step}")
    n = int(math.floor((1.0 - final_strength) / step + 1e-9))
    return tuple(1.0 / round(1.0 - k * step, 10) for k in range(1, n + 1))


TRIAL_ENDS = ("cap", "rest")
"""What a factor-of-safety trial that reaches its cap says (:attr:`SlopeWorkflow.trial_end`)."""


@dataclass
class SlopeWorkflow:
    """Settings of :func:`run_slope_workflow` (times in simulated seconds; ``None``: from the
    model's response time ``T``, :func:`fdem.workflow.stages.response_time`).

    reduction : ``"steps"`` (damped equilibrium at each factor; default), ``"rate"``, or
        ``"none"``: the factor-of-safety search (``fos``, required) is the whole analysis, and the
        run ends after it, outcome ``searched`` (a convergence or boundary study reads only the
        bracket, and a schedule after it would cost as much again)
    factors : the factors ``F`` of the steps (default :func:`reduction_steps`: 1/0.9 ... 1/0.3)
    reduction_rate : fall of the strength ``1/F`` per second in ``"rate"`` mode (paper: 5 /s)
    final_strength : the strength ``1/F`` the rate mode stops at (paper: 0.3)
    fos : ``(lower, upper, tol)`` to search the factor of safety first, or ``None``
    equilibrium_ratio : unbalanced-force ratio that counts as equilibrium (default 1e-4), in the
        equilibrium stage, the reduction steps and the factor-of-safety trials alike
    equilibrium_hold : response times the ratio must keep below ``equilibrium_ratio``, check after
        check, before a factor-of-safety trial or a reduction step counts as converged (default 0:
        the first check that meets it). A slope near its factor breaks a few elements and creeps,
        its ratio dipping below a raised limit and rising again: on the low-angle coarse
        four-slope scene with a joint through the toe at 1.0 m, the limit 2.8e-4 passes a trial
        at F = 1.1125 that is still creeping 15 T later (``docs/cases.md`` A)
    step_time : cap of each damped stage, the factor-of-safety trials included (default ``5 T``: with
        the fundamental-mode damping a stable slope converges within about 1.5 T). The
        equilibrium stage at ``F = 1`` gets twice that, and never less than twice the default
        (:attr:`StageRules.equilibrium_time`): it is where the elastic start's over-strength
        joints slip into place, and a slope that cannot stand at ``F = 1`` ends the analysis, so
        shorter trials must not shorten it. The high-angle fine four-slope scene at 1.0 m needs
        it: joints slipping beside its right-hand boundary break 23 elements, and its ratio falls
        from 0.05 at 0.6 s to 1.15e-4 at the 5 T cap (2.06 s), still falling about 2.5x per
        0.2 s; the high-angle coarse one at 2.0 m converges at 5.3 T, so trials of 2.5 T with an
        equilibrium of twice theirs "failed" at F = 1 with the slope at 8e-5 m/s
    fail_displacement : displacement since a stage began that counts as failure [m], in every
        damped stage and trial (default 1 % of the model height)
    runout_time : cap of the runout stage (default ``max(20 T, 4 sqrt(2 H / g))``, four times
        the free-fall time over the model height ``H``)
    rest_kinetic_ratio : the runout ends when the kinetic energy stays below this fraction of
        its peak for one response time (default 0.01)
    local_fall_area : in steps, a runout that comes to rest with less than this reference area
        [m^2 per metre] of triangles moved more than the failure displacement since the start (all
        falls so far together) is a local fall, a block off the face, not the slope's failure: the
        reduction carries on from the resting state as after a creep (:func:`_tell_local_fall`).
        Default ``None``: any failure ends the reduction
    trigger : ``"strength"`` (strength reduction, default) or ``"gravity"``: gravity increase, the
        loading of the bonded-particle Muliashi paper (density raised until the slope fails). With
        ``"gravity"``, ``fos`` is the gravity-factor bracket, required; the slope then slides at
        the bracket's failing factor (a damped onset stage, then the runout at that gravity)
    runout_dt_fraction : time-step factor of the runout stage (default 0.8, as the other stages).
        A runout is chaotic, and what it reports does not move with the step beyond its spread:
        runs nudged by 1e-3 m/s give 15.08 +- 0.84 m at 0.4 and 14.68 +- 0.51 m at 0.8 on the demo
        slope (to rest, 6 runs each), 3.13 +- 0.71 m and 3.37 +- 0.11 m on the low-angle fine
        four-slope scene (2 s, 4 runs each), the broken elements and peak kinetic energy alike
        (docs/pareto.md); 0.8 takes half the steps of 0.4. A single two-body impact loses more of
        its energy at 0.8 (1.5 % with 4 elements across the body, against 0.25 % at 0.4): pass 0.4
        where impact energies themselves are the answer.
    trial_end : what a factor-of-safety trial that reaches its cap (``step_time``) says:
        ``"rest"`` it is followed undamped in the runout stage and stands when it comes to rest
        having moved less than ``fail_displacement`` in all, fails otherwise: the rule the damped
        reduction steps apply to a stage that did not settle
        (:func:`fdem.workflow.fos.creep_verdict`), so that the search and the steps judge a slope
        alike; ``"cap"`` it fails, as in shear-strength-reduction practice: quicker (no follow),
        and the same factor for a slope that slides, but the cap's factor for one that creeps
        and stops. ``None`` (default): ``"rest"`` for a strength search, ``"cap"`` for the
        gravity one, whose trials are not followed (:attr:`trial_rule`). The high-angle coarse
        four-slope scene at 1.0 m creeps for 20 response times and more at factors where it then
        stands: capped trials of 5, 10 and 20 T give 1.516, 2.112 and 2.416, followed ones
        2.669 (``docs/cases.md`` A, "The high-angle coarse factor against the trial's cap");
        the low-angle coarse one, which slides, 1.084 either way. A follow begins where the
        damped trial stopped, so its verdict still leans on the cap, less: at 2.0 m the same
        scene gives 2.881, 3.019 and 3.156 with trials of 2.5, 5 and 10 T followed to rest
    runout_step : what ``runout_dt_fraction`` multiplies: ``"bound"`` (default) the solver's
        combined bound on the critical step, or ``"measured"`` the critical step measured on the
        model when the runout starts (:attr:`fdem.workflow.stages.Stage.step_from`), 1.26-1.63
        times the bound on the four slopes: 1.25-1.4 times fewer steps at 0.8 (``docs/benchmarks.md``,
        "How far the step is below the critical one"), and measured again every response time
        of the runout (:data:`REMEASURE_EVERY_T`), the step following it up or down. CPU only.
    """

    reduction: str = "steps"
    factors: tuple[float, ...] = field(default_factory=reduction_steps)
    reduction_rate: float = 5.0
    final_strength: float = 0.3
    fos: tuple[float, float, float] | None = None
    equilibrium_ratio: float = 1e-4
    equilibrium_hold: float = 0.0
    step_time: float | None = None
    fail_displacement: float | None = None
    runout_time: float | None = None
    rest_kinetic_ratio: float = 0.01
    runout_dt_fraction: float | None = 0.8
    trigger: str = "strength"
    local_fall_area: float | None = None
    runout_step: str = "bound"
    trial_end: str | None = None

    def __post_init__(self):
        """Every field checked, the message naming it: a negative time or displacement, an
        inverted bracket or a ratio outside (0, 1) would otherwise run and mean nothing."""
        if self.trigger not in ("strength", "gravity"):
            raise ValueError(f"SlopeWorkflow.trigger must be 'strength' or 'gravity', got {self.trigger!r}")
        if self.trigger == "gravity" and self.fos is None:
            raise ValueError("SlopeWorkflow.trigger = 'gravity' needs fos = (lower, upper, tol), the gravity-factor "
                             "bracket of the critical factor's search")
        if self.reduction not in ("steps", "rate", "none"):
            raise ValueError(f"SlopeWorkflow.reduction must be 'steps', 'rate' or 'none', got {self.reduction!r}")
        if self.reduction == "none" and (self.fos is None or self.trigger != "strength"):
            raise ValueError("SlopeWorkflow.reduction = 'none' runs the factor-of-safety search alone: it needs "
                             "fos = (lower, upper, tol) and the strength trigger")
        try:
            factors = tuple(self.factors)
        except TypeError:
            factors = ()
        if not factors or any(not (_real(f) and math.isfinite(f) and f > 0) for f in factors):
            raise ValueError(f"SlopeWorkflow.factors must be a non-empty sequence of positive finite reduction "
                             f"factors, got {self.factors!r}")
        if any(b <= a for a, b in zip(factors, factors[1:])):
            raise ValueError(f"SlopeWorkflow.factors must increase (each step weakens the slope), got {self.factors!r}")
        _check_positive(self, "reduction_rate")
        for name in ("final_strength", "equilibrium_ratio", "rest_kinetic_ratio"):
            v = getattr(self, name)
            if not (_real(v) and 0.0 < v < 1.0):
                raise ValueError(f"SlopeWorkflow.{name} must lie in (0, 1), got {v!r}")
        for name in ("step_time", "fail_displacement", "runout_time", "local_fall_area"):
            _check_positive(self, name, optional=True)
        if not (_real(self.equilibrium_hold) and math.isfinite(self.equilibrium_hold) and self.equilibrium_hold >= 0):
            raise ValueError(f"SlopeWorkflow.equilibrium_hold must be a number of response times >= 0, "
                             f"got {self.equilibrium_hold!r}")
        if self.local_fall_area is not None and (self.reduction != "steps" or self.trigger != "strength"):
            raise ValueError(f"SlopeWorkflow.local_fall_area carries the reduction steps on after a local fall; "
                             f"with reduction = {self.reduction!r} and trigger = {self.trigger!r} there are none: "
                             f"leave it unset")
        if self.runout_dt_fraction is not None and not (_real(self.runout_dt_fraction)
                                                        and 0.0 < self.runout_dt_fraction <= 1.0):
            raise ValueError(f"SlopeWorkflow.runout_dt_fraction (time-step factor) must lie in (0, 1], got "
                             f"{self.runout_dt_fraction!r}")
        if self.trial_end is not None and self.trial_end not in TRIAL_ENDS:
            raise ValueError(f"SlopeWorkflow.trial_end must be one of {', '.join(TRIAL_ENDS)} or None (the "
                             f"default: rest for a strength search), got {self.trial_end!r}")
        if self.trial_end == "rest" and self.fos is None:
            raise ValueError("SlopeWorkflow.trial_end = 'rest' judges the trials of the factor-of-safety search, and "
                             "there is none (fos = None): give fos = (lower, upper, tol), or leave trial_end unset")
        if self.trial_end == "rest" and self.trigger != "strength":
            raise ValueError("SlopeWorkflow.trial_end = 'rest' follows the trials of a strength-reduction search; "
                             "the gravity search's trials end at their cap: leave trial_end unset or 'cap'")
        if self.runout_step not in STEP_FROM:
            raise ValueError(f"SlopeWorkflow.runout_step must be one of {', '.join(STEP_FROM)}, got {self.runout_step!r}")
        if self.fos is not None:
            try:
                lower, upper, tol = self.fos
            except (TypeError, ValueError):
                raise ValueError(f"SlopeWorkflow.fos must be (lower, upper, tol) or None, got {self.fos!r}") from None
            try:
                check_bracket(lower, upper, tol)
            except ValueError as err:
                raise ValueError(f"SlopeWorkflow.fos = {self.fos!r}: {err}".replace("factor_of_safety: ", "")) from None

    @property
    def trial_rule(self) -> str:
        """What the search's capped trials say under these settings: :attr:`trial_end` when
        given, else ``"rest"`` for the strength trigger and ``"cap"`` for the gravity one."""
        if self.trial_end is not None:
            return self.trial_end
        return "rest" if self.trigger == "strength" else "cap"


def _real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _check_positive(wf: "SlopeWorkflow", name: str, optional: bool = False) -> None:
    """A ``ValueError`` naming ``SlopeWorkflow.<name>`` unless it is a positive finite number
    (or, with ``optional``, ``None``: its default from the model)."""
    v = getattr(wf, name)
    if optional and v is None:
        return
    if not (_real(v) and math.isfinite(v) and v > 0):
        raise ValueError(f"SlopeWorkflow.{name} must be a positive finite number{' or None' if optional else ''}, "
                         f"got {v!r}")


def equilibrium_damping(sim: Simulation) -> Damping:
    """Damping of the equilibrium stage: mass-proportional, critical for the slope's Rayleigh
    frequency ``omega_R`` (:func:`fdem.solve.geostatic.rayleigh_frequency`, the mode of its
    deflection under gravity), ``alpha = 2 omega_R``; :func:`fdem.workflow.fos.fundamental_damping`
    when the static deflection cannot be solved.

    The stage starts from the static start with the crack elements whose pre-load is above
    their strength put back on their envelope, which unbalances the slope (ratio 0.22 at once on
    the four-slope scene) and rings its modes. The shear-beam damping ``4 pi / T`` settled them
    at ``2 pi / T`` per second, because ``omega_R`` is twice ``2 pi / T`` there: the stage took
    1.26 T. Critical for ``omega_R`` it takes 0.68 T, and less of the released energy goes into
    fracture through the ringing (208 J/m instead of 225 at size 1.0); twice that damping (4
    times the shear-beam value) overdamps the slope's slow mode and takes 1.18 T
    (``docs/benchmarks.md``, "Equilibrium stage at scale")."""
    try:
        return Damping.critical(rayleigh_frequency(sim.model))
    except ValueError:
        return fundamental_damping(sim)


def check_measured_step(sim: Simulation) -> None:
    """Refuse ``runout_step = 'measured'`` on a model whose step cannot be measured
    (:func:`fdem.solve.step_probe.unmeasurable`), before the first stage rather than at the runout."""
    from fdem.solve.step_probe import unmeasurable

    why = unmeasurable(sim)
    if why:
        raise ValueError(f"runout_step = 'measured' cannot measure this model: {why}; use runout_step = 'bound'")


class StageRules(NamedTuple):
    """The scales and rules every damped stage of the workflow shares: the response time ``T``
    [s] (:func:`fdem.workflow.stages.response_time`), the model height [m], ``g`` [m/s^2], the
    cap of a trial or reduction step [s] (``step_time``, default ``5 T``), its failure rule
    (``fail_displacement``, default 1 % of the height), its damping
    (:func:`fdem.workflow.fos.fundamental_damping`) and its convergence rule (the unbalanced-force
    ratio below ``equilibrium_ratio``, kept there ``equilibrium_hold * T`` seconds)."""

    T: float
    height: float
    g: float
    step_time: float
    fail: Failure
    damped: Damping
    converge: Convergence

    @property
    def equilibrium_time(self) -> float:
        """Cap of the equilibrium stage at ``F = 1`` [s]: ``2 max(step_time, 5 T)``, twice the
        trials' cap and never under twice the default's (:attr:`SlopeWorkflow.step_time`)."""
        return 2.0 * max(self.step_time, DEFAULT_CAP_RESPONSE_TIMES * self.T)


def stage_rules(sim: Simulation, wf: SlopeWorkflow) -> StageRules:
    """The :class:`StageRules` of ``wf`` on ``sim``; a hold that does not fit in the stage cap is
    refused here, before any step (every trial and step would run to its cap and count as failing)."""
    T = response_time(sim.model)
    height = float(np.ptp(sim.model.topology.x0[:, 1]))
    step_time = wf.step_time or DEFAULT_CAP_RESPONSE_TIMES * T
    hold = wf.equilibrium_hold * T
    if hold >= step_time:
        raise ValueError(f"SlopeWorkflow.equilibrium_hold: {wf.equilibrium_hold:g} response times ({hold:.4g} s) "
                         f"do not fit in a stage capped at {step_time:.4g} s (step_time): hold for less, or give a longer step_time")
    return StageRules(T=T, height=height, g=float(np.linalg.norm(sim.gravity)) or 9.81, step_time=step_time,
                      fail=Failure(displacement=wf.fail_displacement or 0.01 * height), damped=fundamental_damping(sim),
                      converge=Convergence(unbalanced_ratio=wf.equilibrium_ratio, hold_for=hold))


def trial_follow(wf: SlopeWorkflow, rules: StageRules, rule: str | None = None) -> Stage | None:
    """What follows a factor-of-safety trial that reaches its cap: under the rule ``"rest"`` the
    workflow's runout stage (:func:`runout_stage`: undamped, to rest or to the failure
    displacement, :func:`fdem.workflow.fos.creep_verdict`), under ``"cap"`` nothing (``None``).
    ``rule``: default ``wf.trial_rule``; an ensemble gives its own (its searches are strength
    searches whatever the scene's trigger)."""
    return runout_stage(wf, rules.T, rules.height, rules.g) if (rule or wf.trial_rule) == "rest" else None


def trial_stage(sim: Simulation, wf: SlopeWorkflow, rules: StageRules | None = None) -> Stage:
    """The factor-of-safety trial ``wf`` judges by (:func:`fdem.workflow.fos.default_trial_stage`
    with the workflow's :class:`StageRules`): the strength and gravity searches of
    :func:`run_slope_workflow` and each realization of a scene's ensemble run the same trial."""
    r = rules or stage_rules(sim, wf)
    return default_trial_stage(sim, r.converge.unbalanced_ratio, r.step_time, r.fail, r.damped, r.converge.hold_for)


def run_slope_workflow(sim: Simulation, workflow: SlopeWorkflow | None = None, out_dir=None,
                       journal=None) -> dict:
    """Run the slope workflow (module docstring) on ``sim``; returns a summary of plain JSON
    values: every stage's result, the factor of safety when searched (``FoSResult.as_dict()``),
    the factor at failure and the state the run ended in (``stable``, ``failed``, ``crept``,
    ``undecided``, ``searched``, ``time_capped``, ``interrupted``, ``write_error`` or
    ``unstable``, with ``ending`` saying why).
    ``journal``: a :class:`fdem.workflow.journal.RunJournal` to write resumable checkpoints
    (and, loaded from one, to continue where it stopped)."""
    wf = workflow or SlopeWorkflow()
    cracks = sim.cracks
    if cracks is None:
        raise ValueError("run_slope_workflow needs crack elements (a CrackSet provider)")
    if wf.runout_step == "measured":  # refused now, not when the runout starts hours in
        check_measured_step(sim)
    rules = stage_rules(sim, wf)
    if "unbalanced_ratio" not in sim.monitors:  # how far from equilibrium, in every history row
        sim.add_monitor("unbalanced_ratio", unbalanced_force_ratio)
    summary: dict = {"response_time_s": rules.T, "stages": [], "fos": None, "failed_at_factor": None}

    def record(result):
        summary["stages"].append(result.as_dict())
        return result

    try:
        _run_stages(sim, wf, summary, record, cracks, rules, out_dir, journal)
    except KeyboardInterrupt as stop:
        # Ctrl-C or a signal, at a whole step: the stages so far and the state reached are
        # kept, so the caller can still write its report and pictures; the journal has written
        # its checkpoint (and the solver ``interrupted_state.npz``)
        summary["outcome"] = "interrupted"
        summary["ending"] = f"interrupted ({stop.args[0] if stop.args else 'Ctrl-C'}) at t = {sim.state.time:.6g} s"
        summary["interrupted_at_s"] = float(sim.state.time)
        if STOP.forced:  # a second signal: mid-step, so the last periodic or stage checkpoint is the one to resume
            summary["ending"] += "; stopped mid-step by a second signal: resume from the last checkpoint"
        # between stages nothing has written the stop yet; a stage (a factor-of-safety trial
        # among them) wrote its own state and runtime when the signal came, which the search's
        # restored start state must not overwrite
        if (journal is not None and journal.current is None and not STOP.forced
                and not (journal.writes and journal.writes[-1][0] == "interrupted")):
            journal.write(sim, "interrupted")
    except OSError as err:
        # a frame or checkpoint could not be written (a full disk, a folder gone read-only): the
        # run stops with the reason; the stages so far and the last checkpoint are kept
        what = f"{err.strerror} ({err.filename})" if err.strerror and err.filename else str(err)
        summary["outcome"] = "write_error"
        summary["ending"] = f"could not write: {what} at t = {sim.state.time:.6g} s"
    except InstabilityError as err:
        # the guard stopped an unstable step: the summary says why and where, the journal's
        # checkpoint (the last stage end or periodic write) is the good state to resume from
        summary["outcome"] = "unstable"
        summary["ending"] = str(err)
        summary["unstable_at_s"] = float(err.time)
        summary["instability"] = {"kind": getattr(err, "kind", None), "step": int(err.step), "time_s": float(err.time),
                                  "triangle": int(err.triangle),
                                  "reason": err.reason, "suggested_dt_s": float(err.suggested_dt),
                                  "state_file": None if err.state_path is None else str(err.state_path)}
    summary["final_reduction"] = cracks.interfaces.reduction
    summary["n_broken"] = int(cracks.broken.sum())
    return summary


def _run_stages(sim, wf, summary, record, cracks, rules, out_dir, journal) -> None:
    T, height, g, step_time, fail, damped = rules[:6]
    if journal is None or journal.resume is None and not journal.done:
        cracks.hold_elastic(False)
    eq = record(run_stage(sim, Stage("equilibrium", max_time=rules.equilibrium_time, reduction=1.0,
                                     damping=equilibrium_damping(sim),
                                     converge=Convergence(unbalanced_ratio=wf.equilibrium_ratio), fail=fail),
                          journal=journal))
    summary["equilibrium"] = eq.reason
    if eq.reason != "converged" and sim.time_capped:
        summary["outcome"] = "time_capped"
        return
    if eq.reason != "converged":
        summary["outcome"] = "failed"
        summary["failed_at_factor"] = 1.0
    elif wf.trigger == "gravity":
        _gravity_increase(sim, wf, summary, record, rules, out_dir, journal)
        return
    else:
        if wf.fos is not None:
            lower, upper, tol = wf.fos

            # its trials restart from this state and leave the simulation in it; the journal keeps
            # each finished trial, so a search cut short goes on from its last one on resume. A
            # bracket whose end contradicts it is a result too (the factor lies beyond it), kept
            # and reported; the schedule after it does not depend on it and goes on.
            def search():
                try:
                    follow = trial_follow(wf, rules)
                    return factor_of_safety(sim, lower=lower, upper=upper, tol=tol, out_dir=out_dir, journal=journal,
                                            trial=trial_stage(sim, wf, rules), follow=follow).as_dict()
                except BracketError as err:
                    return beyond_bracket(err, lower, upper)

            summary["fos"] = journal.once("fos", search) if journal is not None else search()
            fos = summary["fos"]
            if fos.get("time_capped") or any(t.get("time_capped") for t in fos.get("trials", [])):
                # the run's --max-time stopped a trial before its rule decided: no verdict
                summary["outcome"] = "time_capped"
                return
        if wf.reduction == "none":
            _tell_searched(summary)
            return
        if wf.reduction == "steps":
            for F in wf.factors:
                r = record(run_stage(sim, Stage(f"reduction_F{F:.3f}", max_time=step_time, reduction=F,
                                                damping=damped, fail=fail, converge=rules.converge),
                                     journal=journal))
                if r.reason == "converged":
                    continue
                if sim.time_capped:
                    summary["outcome"] = "time_capped"
                    return
                summary["failed_at_factor"] = F
                # A node moved the failure displacement, or the stage did not settle within its
                # cap: follow it undamped. A slope that creeps and comes to rest stands at F, as
                # does one that lost only a block off its face (with local_fall_area), and the
                # reduction carries on from the resting state; one that runs on has failed, and
                # that was its runout.
                _runout(sim, wf, summary, record, T, height, g, fail, out_dir, journal)
                _tell_local_fall(sim, wf, summary, fail.displacement, journal)
                if summary.get("outcome") not in ("crept", "local_fall"):
                    return
                summary.pop("outcome")
            else:
                summary["outcome"] = "crept" if summary.get("crept_at_factors") else "stable"
                if summary.get("crept_at_factors") or summary.get("local_falls"):
                    summary["ending"] += f"; the reduction carried on and the slope stood at every factor to F = {F:.4g}"
                return
        else:
            F_end = 1.0 / wf.final_strength
            seconds = (1.0 - wf.final_strength) / wf.reduction_rate
            r = record(run_stage(sim, Stage("reduction_rate", duration=seconds, reduction_ramp=(F_end, seconds),
                                            damping=NO_DAMPING), journal=journal))
            summary["failed_at_factor"] = F_end
        summary["outcome"] = "failed" if summary["failed_at_factor"] is not None else "stable"
    if summary["outcome"] == "failed" and wf.reduction == "none":
        # the slope does not stand at F = 1, so there is no factor to search: the search was the
        # whole analysis, and no runout is wanted of it
        summary["ending"] = (f"the slope did not settle at F = 1 ({eq.reason}: {eq.detail}), so there is no "
                             f"factor of safety above 1 to search; with reduction 'none' no runout follows (run "
                             f"the steps to see whether it creeps or collapses)")
    elif summary["outcome"] == "failed":
        _runout(sim, wf, summary, record, T, height, g, fail, out_dir, journal)


def _tell_searched(summary: dict) -> None:
    """The ending of a run whose analysis is the factor-of-safety search (``reduction = "none"``):
    outcome ``searched``, the bracket in words; the state is the equilibrium at ``F = 1`` the
    trials started from."""
    fos = summary["fos"]
    summary["outcome"] = "searched"
    if fos["fos"] is None:
        summary["ending"] = f"{fos['error']} (the search was the analysis, reduction 'none')"
        return
    lo, hi = fos["bracket"]
    summary["ending"] = (f"factor of safety {fos['fos']:.4g} (stable at {lo:.4g}, not at {hi:.4g}; "
                         f"{fos['n_trials']} trials): the search was the analysis (reduction 'none')")
    followed = [t for t in fos.get("trials", []) if t.get("follow")]
    if fos.get("leans_on_cap") and not followed:
        summary["ending"] += (f"; F = {hi:.4g} reached the trial cap still settling: the factor may lean on "
                              f"the cap (trials followed to rest, trial_end 'rest', the default, tell whether it stands)")
    if followed:
        # the creep at rest of each trial that stood: where it grows smoothly with F, as on the
        # high-angle four slopes, the factor is where it reaches the failure displacement
        stood = sorted((t["factor"], moved_in_all(t)) for t in followed if t["follow_verdict"] == "crept")
        open_ = sorted(t["factor"] for t in followed if t["follow_verdict"] == "undecided")
        summary["ending"] += (f"; {len(followed)} trial(s) reached their cap and were followed undamped"
                              + (", standing after creeping at F = "
                                 + ", ".join(f"{f:.4g} ({moved:.3g} m in all)" for f, moved in stood) if stood else "")
                              + (f", the follow capped short of the failure displacement at F = "
                                 f"{', '.join(f'{f:.4g}' for f in open_)} (counted failing: a longer runout cap, "
                                 f"--runout-time, tells)" if open_ else "")
                              + ("" if stood or open_ else ", each reaching the failure displacement"))
    by_cap = fos.get("by_cap") or []
    if len(by_cap) > 1 and by_cap[-2]["bracket"] != by_cap[-1]["bracket"]:
        summary["ending"] += (f"; read at half the trials' length ({by_cap[-2]['cap_response_times']:.3g} "
                              f"response times) the same trials bracket it at {bracket_words(by_cap[-2]['bracket'])}: "
                              f"the factor moves with the trials' length (fos.json by_cap; trials followed to "
                              f"rest, trial_end 'rest', the default, give the slope's)")


def beyond_bracket(err: BracketError, lower: float, upper: float) -> dict:
    """The search's record when an end of its bracket contradicts it: no factor, the bracket open
    on the side the factor lies beyond (``[upper, None]``: stable at the upper end; ``[None,
    lower]``: failing at the lower), and the message (``error``), which says which way to move
    the bracket."""
    stable_at_upper = err.trial.stable
    return {"fos": None, "bracket": [upper, None] if stable_at_upper else [None, lower], "error": str(err),
            "time_capped": bool(err.trial.time_capped)}


def _runout(sim, wf, summary, record, T, height, g, fail, out_dir, journal) -> None:
    """The undamped runout after the stage at ``summary["failed_at_factor"]``, to rest (or its cap),
    with ``runout_start.npz`` written first; then :func:`_tell_creep`. The first runout of a run
    is named ``runout`` (and its start mark ``runout_start``); a later one, after a creep the
    reduction carried on from, carries its factor in both names (``runout_F1.429``), so that a
    resumed run replays each by name."""
    F = summary["failed_at_factor"]
    later = any(st["name"] == "runout" for st in summary["stages"])
    suffix = f"_F{F:.3f}" if later else ""
    if out_dir is not None:
        # the failed state before the runout: rerun the runout from it with other settings
        # (a longer cap, a smaller step), or profile it (cases/benchmarks/profile_scene.py)
        from pathlib import Path

        from fdem.solve.checkpoint import save_checkpoint

        def save_start():
            return str(save_checkpoint(sim, Path(out_dir) / "runout_start.npz"))

        summary["runout_checkpoint"] = journal.once("runout_start" + suffix, save_start) if journal else save_start()
    stage = runout_stage(wf, T, height, g)
    if suffix:
        import dataclasses

        stage = dataclasses.replace(stage, name=stage.name + suffix)
    runout = record(run_stage(sim, stage, journal=journal))
    summary["outcome"] = "failed"
    # this runout's end, not an earlier creep's (the reduction carried on from a slope at rest)
    how = {"converged": "came to rest", "capped": "reached its time cap"}.get(runout.reason, f"ended ({runout.reason})")
    # (t: the run's clock; the detail's "after" counts from the runout's start)
    summary["ending"] = f"failed at F = {F:.4g}; the runout {how} at t = {runout.t_end:.4g} s ({runout.detail})"
    if runout.reason == "left_model":
        summary["ending"] = (f"the failed mass ran off the end of the model at t = {runout.t_end:.4g} s ({runout.detail}): "
                             f"the runout distance is a lower bound; lengthen the floor in front of the toe")
    _tell_creep(summary, runout, fail.displacement)
    if summary["outcome"] == "undecided" and sim.time_capped:  # the run's own cap (--max-time) ended it
        summary["outcome"] = "time_capped"


def _tell_creep(summary: dict, runout, fail_displacement: float) -> None:
    """A slope whose failing stage did not settle within its cap but that came to rest in the
    runout having moved less than the failure displacement (1 % of the height) crept and
    stopped: it did not fail at that factor. Its outcome is ``crept``; ``crept_at_factor`` is
    the factor (``crept_at_factors`` every such factor, when the reduction steps carried on from
    the resting state), ``failed_at_factor`` goes back to None, and the reduction-step bracket
    reads it as a factor the slope stands at (:func:`factor_of_safety_figures`). The creep is
    bounded by the sum of the two stages' largest node displacements.

    A runout cut short by its cap (``--runout-time``) before it came to rest, with less than the
    failure displacement moved, has not told a creep from a collapse: its outcome is
    ``undecided`` (``failed_at_factor`` kept: the factor at which the slope did not settle),
    with an ending that says so and how to decide it."""
    if len(summary["stages"]) < 2:
        return
    failing = summary["stages"][-2]
    verdict = creep_verdict(failing.get("reason"), float(failing["max_displacement"]), runout.reason,
                            float(runout.max_displacement), fail_displacement)
    if verdict == "failed":
        return
    creep = float(failing["max_displacement"]) + float(runout.max_displacement)
    factor = summary["failed_at_factor"]
    if verdict == "undecided":
        summary["outcome"] = "undecided"
        summary["ending"] = (f"did not settle at F = {factor:.4g}, and the runout was capped at t = {runout.t_end:.4g} s "
                             f"after {creep:.3g} m, less than the failure displacement ({fail_displacement:.3g} m): "
                             f"failed or crept is undecided; rerun with a longer runout cap (--runout-time) to follow "
                             f"it to rest")
        return
    summary["outcome"] = "crept"
    summary["crept_at_factor"] = factor
    summary.setdefault("crept_at_factors", []).append(factor)
    summary["failed_at_factor"] = None
    summary["crept_m"] = max(creep, summary.get("crept_m", 0.0))
    summary["ending"] = (f"crept at most {creep:.3g} m at F = {factor:.4g} and came to rest: no failure there "
                         f"(the failure displacement is {fail_displacement:.3g} m, 1 % of the height)")


def _tell_local_fall(sim, wf, summary: dict, fail_displacement: float, journal=None) -> None:
    """A failed runout that came to rest with less than ``wf.local_fall_area`` [m^2] of triangles
    whose centroid moved more than the failure displacement since the start (every fall so far
    counted together, so that a slope losing its face block by block fails once the blocks add
    up) is a local fall: a block off the face, not the slope. It is booked in ``local_falls``
    (factor, area, the runout's largest displacement, time), its outcome is ``local_fall`` until
    the reduction carries on from the resting state, ``failed_at_factor`` goes back to None, and
    the reduction-step bracket reads the factor as one the slope stands at
    (:func:`factor_of_safety_figures`). A runout cut by its cap, or one whose mass ran off the
    model, is no local fall.

    The area is measured on the state the runout came to rest in, once: with a ``journal`` it is
    recorded (mark ``local_fall:<runout>``), so that a resumed run, whose replayed runout returns
    without stepping and leaves the simulation in a later state, takes the figure it measured
    then instead of measuring the later state."""
    if wf.local_fall_area is None or summary.get("outcome") != "failed" or not summary["stages"]:
        return
    runout = summary["stages"][-1]
    if runout.get("reason") != "converged":
        return
    from fdem.results.analysis import displaced

    def measure() -> float:
        topology = sim.model.topology
        return float(topology.triangle_area0[displaced(topology, sim.state.x, fail_displacement)].sum())

    key = f"local_fall:{runout['name']}"
    if journal is not None and key not in journal.marks and journal.ahead():
        # a replay past this runout, by a run whose journal holds no measure of it: the run
        # carried on from it, so it was told a local fall then; the later state cannot say its area
        area = journal.marks[key] = None
    else:
        area = journal.once(key, measure) if journal is not None else measure()
    if area is not None and area >= wf.local_fall_area:
        return
    factor = summary["failed_at_factor"]
    moved = float(runout["max_displacement"])
    summary.setdefault("local_falls", []).append({"factor": factor, "area_m2": area, "max_displacement_m": moved,
                                                  "at_rest_s": float(runout["t_end"])})
    summary["outcome"] = "local_fall"
    summary["failed_at_factor"] = None
    summary["ending"] = (f"a local fall at F = {factor:.4g}: {'an unrecorded area' if area is None else f'{area:.3g} m^2'}"
                         f" moved more than {fail_displacement:.3g} m (at most {moved:.3g} m) and came to rest at "
                         f"t = {runout['t_end']:.4g} s, under the local-fall area {wf.local_fall_area:.3g} m^2: a block "
                         f"off the face, not the slope")


def _gravity_increase(sim, wf, summary, record, rules, out_dir, journal) -> None:
    """The gravity-increase workflow after equilibrium: the critical gravity factor ``k`` by
    bisection on ``wf.fos`` (:class:`fdem.workflow.fos.GravityIncrease`), then, at the bracket's
    failing factor, a damped ``onset`` stage (the failing trial's: it ends when a node has moved
    1 % of the model height, so the jump of gravity does not ring the slope to twice its load)
    and the undamped runout at that gravity to rest (:func:`runout_stage` with ``k g``). A slope
    still standing at the upper factor is ``stable``; one failing at the lower is loaded there."""
    import dataclasses

    T, height, g = rules.T, rules.height, rules.g
    lower, upper, tol = wf.fos
    trial = trial_stage(sim, wf, rules)

    def search():
        try:
            return factor_of_safety(sim, lower=lower, upper=upper, tol=tol, trigger=GravityIncrease(),
                                    out_dir=out_dir, journal=journal, trial=trial).as_dict()
        except BracketError as err:
            return beyond_bracket(err, lower, upper)

    summary["fos"] = journal.once("fos", search) if journal is not None else search()
    summary["trigger"] = "gravity"
    k = summary["fos"]["bracket"][1]
    if k is None:
        summary["outcome"] = "stable"
        summary["ending"] = summary["fos"]["error"]
        return
    summary["failed_at_factor"] = k
    summary["outcome"] = "failed"
    onset = dataclasses.replace(trial, name="onset", gravity_factor=k)
    record(run_stage(sim, onset, journal=journal))
    slide = dataclasses.replace(runout_stage(wf, T, height, k * g), gravity_factor=k)
    record(run_stage(sim, slide, journal=journal))


ESCAPE_SHARE = 0.01
"""Share of the displaced area that fragments leaving the model may take before a runout ends
``left_model`` (:attr:`fdem.workflow.stages.Stage.escape_share`): fly-rock is held beyond the
model's end and the runout goes on; a mass running off the floor ends it."""


REMEASURE_EVERY_T = 1.0
"""Response times ``T`` between measurements of the critical step of a runout that steps from
it (``runout_step = "measured"``): the slope's own time scale, over which crack elements break
and contacts form. A probe (21-51 steps of the model and the Lanczos iterations: 0.3-2.4 s of
wall time at 1.0 m elements, 14 s at 180,000 triangles) costs 1-2 % of the wall time of one
``T`` (about 0.4 s of simulated time, 50,000-90,000 steps, on the four slopes)."""


def runout_stage(wf: SlopeWorkflow, T: float, height: float, g: float) -> Stage:
    """The dynamic runout stage of the workflow: no damping, time-step factor
    ``wf.runout_dt_fraction`` of the bound or of the measured critical step (``wf.runout_step``); ends when the kinetic energy has stayed below
    ``wf.rest_kinetic_ratio`` of its peak for one response time ``T`` [s] (after at least
    ``T``), capped at ``wf.runout_time`` or ``max(20 T, 4 sqrt(2 H / g))`` (four free falls over
    the model height ``H`` [m] under gravity ``g`` [m/s^2]); it stops ``left_model`` when a node
    runs 1 % of ``H`` beyond the model's initial extent (off the end of the floor), unless the
    fragments beyond are fly-rock: up to :data:`ESCAPE_SHARE` of the displaced area is held
    there and the runout goes on (:attr:`~fdem.workflow.stages.Stage.escape_share`). It also ends
    at rest when no node has moved more than 1 % of the failure displacement within 5 ``T``
    (:class:`~fdem.workflow.stages.Convergence` ``drift``): a slope that crept and stopped rings
    on at a kinetic energy that never falls to 1 % of its small peak (the high-angle coarse
    slope: 0.05-0.3 J/m for 14 s after a peak of 5.5 J/m, 2.6 cm of creep). A frame every half
    free-fall time ``sqrt(2 H / g) / 2`` (1.2 s on a 30 m model): the runout's own time scale,
    not a quarter of its cap, which gave the four-slope runs (cap 60 s, at rest after 10-20 s)
    one frame of their collapse."""
    free_fall = math.sqrt(2.0 * height / g)
    cap = wf.runout_time or max(20.0 * T, 4.0 * free_fall)
    fail_displacement = wf.fail_displacement or 0.01 * height
    return Stage("runout", max_time=cap, damping=NO_DAMPING, dt_fraction=wf.runout_dt_fraction, step_from=wf.runout_step,
                 remeasure_every=REMEASURE_EVERY_T * T if wf.runout_step == "measured" else None,
                 output_interval=min(0.5 * free_fall, cap / 4.0),
                 converge=Convergence(unbalanced_ratio=None, kinetic_ratio=wf.rest_kinetic_ratio, min_time=T, hold_for=T,
                                      drift=0.01 * fail_displacement, drift_window=5.0 * T),
                 domain_margin=0.01 * height, escape_share=ESCAPE_SHARE)


def factor_of_safety_figures(result: dict) -> dict:
    """``fos``, ``fos_bracket`` and ``fos_method`` from a workflow summary: the bisection's when
    it searched, else the bracket of the reduction steps, ``[largest factor at which the slope
    converged, factor at which it failed]``, with ``fos`` its middle (``None`` if it never failed)."""
    fos = result.get("fos")
    stepped = any(st["name"].startswith("reduction_F") for st in result["stages"])
    # a search whose bracket was contradicted gives way to the steps' bracket, when there are steps
    if fos and (fos.get("fos") is not None or not stepped):
        return {"fos": fos["fos"], "fos_bracket": fos["bracket"], "fos_method": "bisection"}
    lo, failing = steps_bracket(result)
    return {"fos": None if lo is None or failing is None else 0.5 * (lo + failing), "fos_bracket": [lo, failing],
            "fos_method": "reduction steps"}


def steps_bracket(result: dict) -> list:
    """``[largest factor the slope stood at, factor at which it failed]`` of the reduction steps
    of a workflow summary (either ``None`` when there is none): it stands where a damped stage
    converged, where it crept and came to rest, and where it lost only a block off its face."""
    stable = [st["reduction"] for st in result["stages"]
              if st["name"].startswith("reduction") or st["name"] == "equilibrium"
              if st["reason"] == "converged"]
    if result.get("crept_at_factor") is not None:  # crept and came to rest: it stands there
        stable.append(result["crept_at_factor"])
    stable += [fall["factor"] for fall in result.get("local_falls", [])]  # lost a block and stood
    return [max(stable) if stable else None, result.get("failed_at_factor")]


def final_factor(wf: SlopeWorkflow) -> float:
    """The strength-reduction factor a schedule ends at: ``1 / final_strength`` at the rate,
    the last of ``factors`` in steps (both 1/0.3 by default), the search's upper factor when the
    search is the analysis (``"none"``)."""
    if wf.reduction == "none":
        return float(wf.fos[1])
    return 1.0 / wf.final_strength if wf.reduction == "rate" else float(wf.factors[-1])


def start_against_strength(cracks, slope, factor: float) -> dict:
    """The static start's stress against the strength at the reduction factor ``factor``, before
    any step: which crack elements a schedule that ends there must make yield whatever the slope
    does, and whether the level ground does too.

    ``cracks`` must have been pre-loaded by the static start (``cracks.preload_forces``,
    :func:`fdem.solve.geostatic.geostatic_start`); ``slope``: the slope polygon (toe on the
    left). An element is over strength when an end's traction exceeds Mohr-Coulomb with the
    tension cut-off (:func:`fdem.solve.geostatic.crack_strength_check` at ``factor``). The level
    ground is where the element's midpoint lies more than one slope height ``H`` in front of the
    toe or behind the crest; an element's cover is the depth of its deeper end below the ground
    surface, where its traction is the larger (the shallowest such cover is reported among
    elements at least half the median element length: slivers at joint crossings carry noisy
    end tractions). Under level ground
    in uniaxial strain a plane is over strength below a depth ``z*`` that
    :func:`fdem.reference.level_ground.slip_depth` gives in closed form.

    Returns ``{"factor", "elements", "over", "joints", "joints_over", "level_ground": {"elements",
    "over", "joints", "joints_over", "shallowest_cover_m", "joints_shallowest_cover_m"}}``
    (covers ``None`` where nothing is over).
    """
    forces = getattr(cracks, "preload_forces", None)
    if forces is None:
        raise ValueError("start_against_strength: the crack set has no static preload (run geostatic_start "
                         "with it first)")
    over = crack_strength_check(cracks, forces, reduction=factor)
    topo = cracks.topology
    flagged = np.zeros(topo.n_cracks, bool)
    flagged[np.union1d(over["tensile"], over["shear"])] = True
    mid = np.asarray(topo.x0, float)[np.asarray(topo.crack_nodes)].mean(axis=1)
    toe_x, toe_y = slope_toe(slope)
    crest_x, crest_y = slope_crest(slope)
    height = crest_y - toe_y
    level = (mid[:, 0] < toe_x - height) | (mid[:, 0] > crest_x + height)
    ends = np.asarray(topo.x0, float)[np.asarray(topo.crack_nodes)[:, :2]]   # the two ends of one face
    surface = ground_surface(slope)
    cover = np.maximum(*(surface(ends[:, k, 0]) - ends[:, k, 1] for k in (0, 1)))
    joints = np.asarray(topo.crack_tag) > 0
    length = np.asarray(topo.crack_length0, float)
    whole = length >= 0.5 * np.median(length)  # a sliver's end tractions are discretization noise

    def shallowest(sel):
        sel = sel & whole
        return float(cover[sel].min()) if sel.any() else None

    return {"factor": float(factor), "elements": int(topo.n_cracks), "over": int(flagged.sum()),
            "joints": int(joints.sum()), "joints_over": int((flagged & joints).sum()),
            "level_ground": {"elements": int(level.sum()), "over": int((flagged & level).sum()),
                             "joints": int((level & joints).sum()), "joints_over": int((flagged & level & joints).sum()),
                             "shallowest_cover_m": shallowest(flagged & level),
                             "joints_shallowest_cover_m": shallowest(flagged & level & joints)}}
