"""Stages with physical end rules, strength-reduction schedules and the factor-of-safety search.

A stage is a stretch of simulated time with its own damping, strength-reduction factor and
end rule. It ends by physics, never by a bare step count (the step count that means "settled"
changes with the mesh and the penalties):

* ``duration``: a fixed length of simulated time [s] (a dynamic runout window, a ramp);
* ``converge``: equilibrium reached — the unbalanced-force ratio
  (:func:`fdem.geostatic.unbalanced_force_ratio`), the kinetic energy relative to the stage's
  peak, and/or the largest monitored speed fall below their limits;
* ``fail``: an objective failure criterion fires — a monitored node moves more than a set
  displacement since the stage began, or keeps a speed above a limit;
* ``max_time``: the cap [s] on a stage with rules; a capped stage reports so.

Every stage reports why it ended (:class:`StageResult`): ``converged``, ``failed``,
``capped`` or ``completed`` (a fixed-duration stage that ran its time).

Time scales come from the model (:func:`response_time`): the fundamental period of a
slope of height ``H`` (shear beam on a rigid base) is ``T = 4 H / c_s`` with
``c_s = sqrt(mu / rho)`` (Kramer 1996, *Geotechnical Earthquake Engineering*, sec. 7.2); a
15-30 m slope rings for about 0.3 s. Checks run every ``T / 40``; a stage with rules is
capped at ``10 T`` by default, a factor-of-safety trial at ``5 T`` (:func:`default_trial_stage`).

Factor of safety (:func:`factor_of_safety`): from a state in equilibrium, each trial sets a
factor ``F`` of a trigger (strength reduction: ``c / F``, ``tan(phi) / F`` everywhere, see
:mod:`fdem.interfaces`), restarts from the saved state and runs a damped stage. The slope is
*stable* at ``F`` if that stage converges, *failing* if the failure rule fires or the stage
does not converge within its cap (non-convergence, as in the strength-reduction practice of
Dawson, Roth & Drescher 1999). Bisection narrows ``[stable, failing]`` to the tolerance.
"""
from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .solver import NO_DAMPING, Damping, Simulation

__all__ = ["Convergence", "Failure", "Stage", "StageResult", "run_stage", "response_time", "interfaces_of",
           "crack_set_of", "fundamental_damping", "default_trial_stage", "StrengthReduction", "GravityIncrease", "Trial", "FoSResult", "factor_of_safety"]


# ----------------------------------------------------------------------------- rules
def _positive_or_none(value, name: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number or None, got {value!r}")


@dataclass(frozen=True)
class Convergence:
    """Equilibrium rule: the stage has converged when every given limit holds at a check.

    unbalanced_ratio : limit on :func:`fdem.geostatic.unbalanced_force_ratio`
        ``sum |f_net| / sum |m g|`` over free components [-] (default 1e-4)
    kinetic_ratio : limit on the kinetic energy over the stage's peak kinetic energy [-]
    speed : limit on the largest monitored speed [m/s]
    min_time : simulated time [s] before the rule may fire (default 0)
    hold_for : simulated time [s] the limits must keep holding, check after check, before the
        stage ends (default 0: the first check that meets them); a runout that comes to rest
        and stays at rest
    """

    unbalanced_ratio: float | None = 1e-4
    kinetic_ratio: float | None = None
    speed: float | None = None
    min_time: float = 0.0
    hold_for: float = 0.0

    def __post_init__(self):
        _positive_or_none(self.unbalanced_ratio, "Convergence.unbalanced_ratio")
        _positive_or_none(self.kinetic_ratio, "Convergence.kinetic_ratio")
        _positive_or_none(self.speed, "Convergence.speed")
        if not (math.isfinite(self.min_time) and self.min_time >= 0):
            raise ValueError(f"Convergence.min_time must be >= 0, got {self.min_time!r}")
        if not (math.isfinite(self.hold_for) and self.hold_for >= 0):
            raise ValueError(f"Convergence.hold_for must be >= 0, got {self.hold_for!r}")
        if self.unbalanced_ratio is None and self.kinetic_ratio is None and self.speed is None:
            raise ValueError("Convergence needs at least one of unbalanced_ratio, kinetic_ratio, speed")


@dataclass(frozen=True)
class Failure:
    """Failure rule: fires when a monitored node has moved more than ``displacement`` [m]
    since the stage began, or when the largest monitored speed exceeds ``speed`` [m/s].
    ``displacement=None`` and ``speed=None`` together mean "1 % of the model height"."""

    displacement: float | None = None
    speed: float | None = None

    def __post_init__(self):
        _positive_or_none(self.displacement, "Failure.displacement")
        _positive_or_none(self.speed, "Failure.speed")


@dataclass(frozen=True)
class Stage:
    """One stage of a run (see the module docstring).

    Attributes
    ----------
    name : label of the stage in the history and the outputs
    duration : fixed simulated time [s]; the stage then ends ``completed`` (rules may end it earlier)
    max_time : cap [s] of a stage with rules (default ``10 T``, :func:`response_time`)
    converge, fail : the end rules (:class:`Convergence`, :class:`Failure`)
    damping : :class:`fdem.solver.Damping` of the stage (default none: dynamic)
    reduction : strength-reduction factor ``F`` set when the stage starts (``None``: keep)
    reduction_ramp : ``(F_end, seconds)``: the strength ``1/F`` moves linearly from its value
        at the stage start to ``1/F_end`` over ``seconds`` of simulated time, updated at every
        check (the four-slope paper's schedule, 10 % of the initial strength per 10,000 steps
        of 2 us, is ``1/F`` falling by 5 per second)
    gravity_factor : gravity set to this multiple of ``base_gravity`` when the stage starts
        (``None``: keep); :meth:`fdem.solver.Simulation.set_gravity` books the change
    base_gravity : (gx, gy) [m/s^2] the factor multiplies (default: the model's gravity)
    hold_elastic : hold the crack elements elastic during the stage (``None``: keep)
    check_interval : simulated time [s] between checks of the rules (default ``T / 40``)
    output_interval : simulated time [s] between output frames (default: 4 per stage)
    monitor : nodes the rules watch (a group name, predicate or ids; default all nodes)
    safety : time-step factor of the stage, the fraction of the critical step (``None``: the
        simulation's ``safety``; ignored when the simulation has a user time step). The
        simulation's own factor is restored when the stage ends.
    """

    name: str
    duration: float | None = None
    max_time: float | None = None
    converge: Convergence | None = None
    fail: Failure | None = None
    damping: Damping = NO_DAMPING
    reduction: float | None = None
    reduction_ramp: tuple[float, float] | None = None
    gravity_factor: float | None = None
    base_gravity: tuple[float, float] | None = None
    hold_elastic: bool | None = None
    check_interval: float | None = None
    output_interval: float | None = None
    monitor: object = None
    safety: float | None = None

    def __post_init__(self):
        if not self.name:
            raise ValueError("a stage needs a name")
        if self.safety is not None and not 0.0 < self.safety <= 1.0:
            raise ValueError(f"stage {self.name!r}: safety (time-step factor) must lie in (0, 1], got {self.safety}")
        _positive_or_none(self.duration, f"stage {self.name!r}: duration")
        _positive_or_none(self.max_time, f"stage {self.name!r}: max_time")
        _positive_or_none(self.reduction, f"stage {self.name!r}: reduction")
        if self.gravity_factor is not None and not (math.isfinite(self.gravity_factor) and self.gravity_factor >= 0):
            raise ValueError(f"stage {self.name!r}: gravity_factor must be finite and >= 0, got {self.gravity_factor!r}")
        _positive_or_none(self.check_interval, f"stage {self.name!r}: check_interval")
        _positive_or_none(self.output_interval, f"stage {self.name!r}: output_interval")
        if self.duration is None and self.converge is None and self.fail is None:
            raise ValueError(f"stage {self.name!r} can never end: give a duration, or a converge/fail rule "
                             "(with max_time as its cap)")
        if self.reduction_ramp is not None:
            f_end, seconds = self.reduction_ramp
            _positive_or_none(f_end, f"stage {self.name!r}: reduction_ramp end factor")
            _positive_or_none(seconds, f"stage {self.name!r}: reduction_ramp time")
        if not isinstance(self.damping, Damping):
            raise ValueError(f"stage {self.name!r}: damping must be a fdem.solver.Damping, got {self.damping!r}")


@dataclass
class StageResult:
    """How a stage went. ``reason``: ``converged``, ``failed``, ``capped`` or ``completed``."""

    name: str
    reason: str
    t_start: float
    t_end: float
    steps: int
    wall_seconds: float
    dt: float
    reduction: float
    unbalanced_ratio: float
    kinetic_energy: float
    peak_kinetic_energy: float
    max_speed: float
    max_displacement: float
    n_broken: int
    detail: str = ""

    @property
    def converged(self) -> bool:
        return self.reason == "converged"

    def as_dict(self) -> dict:
        return asdict(self)


# ----------------------------------------------------------------------------- helpers
def response_time(model) -> float:
    """Fundamental period ``T = 4 H / c_s`` [s] of the model as a shear beam on a rigid base:
    ``H`` the vertical extent of the reference mesh [m], ``c_s = sqrt(mu / rho)`` the slowest
    shear-wave speed of its materials (Kramer 1996, sec. 7.2)."""
    y = model.topology.x0[:, 1]
    height = float(y.max() - y.min())
    _, mu = model.lame_arrays()
    rho = model.property_array("density")
    cs = float(np.sqrt(mu / rho).min())
    if not (height > 0 and cs > 0):
        raise ValueError(f"cannot define a response time: model height {height} m, shear-wave speed {cs} m/s")
    return 4.0 * height / cs


def crack_set_of(sim: Simulation):
    """The crack-element provider of ``sim`` (the one with ``interfaces`` and ``hold_elastic``), or None."""
    for p in sim.providers:
        if hasattr(p, "interfaces") and hasattr(p, "hold_elastic"):
            return p
    return None


def interfaces_of(sim: Simulation):
    """The :class:`fdem.interfaces.Interfaces` of ``sim``'s crack elements; a ``ValueError`` if none."""
    cracks = crack_set_of(sim)
    if cracks is None:
        raise ValueError("this simulation has no crack elements (CrackSet): no strength to reduce")
    return cracks.interfaces


def _monitor_nodes(sim: Simulation, monitor) -> np.ndarray | None:
    if monitor is None:
        return None
    return sim.model.select_nodes(monitor, "stage monitor")


def _max_norm(a: np.ndarray, nodes: np.ndarray | None) -> float:
    if nodes is not None:
        a = a[nodes]
    return float(np.sqrt((a * a).sum(axis=1)).max()) if len(a) else 0.0


def run_stage(sim: Simulation, stage: Stage, frames: bool = True) -> StageResult:
    """Run ``stage`` on ``sim`` until its end rule (see the module docstring); returns its result.

    ``frames=False`` writes no output frames (the history rows are still written), as for the
    trials of a factor-of-safety search.

    The stage's factor, hold and damping are set first. Rules are checked every
    ``check_interval`` of simulated time (a history row of the ledger is written at each
    check); the run stops at the first rule that holds. A run that goes unstable raises
    :class:`fdem.solver.InstabilityError` with its last good state on disk, as every run does.
    """
    from .geostatic import unbalanced_force_ratio

    T = response_time(sim.model)
    cracks = crack_set_of(sim)
    if stage.reduction is not None or stage.reduction_ramp is not None or stage.hold_elastic is not None:
        if cracks is None:
            raise ValueError(f"stage {stage.name!r} changes strength, but the simulation has no crack elements")
    if stage.hold_elastic is not None:
        cracks.hold_elastic(stage.hold_elastic)
    if stage.reduction is not None:
        cracks.interfaces.set_reduction(stage.reduction)
    if stage.gravity_factor is not None:
        base = np.asarray(stage.base_gravity if stage.base_gravity is not None else sim.model.gravity, float)
        sim.set_gravity(*(stage.gravity_factor * base))
    nodes = _monitor_nodes(sim, stage.monitor)
    height = float(np.ptp(sim.model.topology.x0[:, 1]))
    fail = stage.fail
    fail_disp = None
    if fail is not None:
        fail_disp = fail.displacement if (fail.displacement is not None or fail.speed is not None) else 0.01 * height
    length = stage.duration if stage.duration is not None else (stage.max_time or 10.0 * T)
    sim_safety = sim.safety
    try:
        if stage.safety is not None:
            sim.safety = stage.safety
        sim.dt = sim._choose_dt()
    except ValueError:
        sim.safety = sim_safety
        raise
    dt = sim.dt
    check_steps = max(1, int(round((stage.check_interval or T / 40.0) / dt)))
    output_steps = max(1, int(round((stage.output_interval or length / 4.0) / dt)))
    if not frames:
        output_steps = 2 ** 62
    t0 = sim.state.time
    step0 = sim.state.step
    x_start = sim.state.x.copy()
    ramp = None
    if stage.reduction_ramp is not None:
        ramp = (1.0 / cracks.interfaces.reduction, 1.0 / stage.reduction_ramp[0], stage.reduction_ramp[1])
    status = {"reason": None, "detail": "", "peak": 0.0, "ratio": math.nan, "speed": 0.0, "disp": 0.0,
              "since": None}
    conv = stage.converge

    def rule(s: Simulation) -> bool:
        t = s.state.time - t0
        if ramp is not None:
            s0, s1, seconds = ramp
            strength = s0 + (s1 - s0) * min(t / seconds, 1.0)
            cracks.interfaces.set_reduction(1.0 / strength)
        row = s.last_row
        kin = float(row["kinetic"]) if row else 0.0
        status["peak"] = max(status["peak"], kin)
        speed = _max_norm(s.state.v, nodes)
        disp = _max_norm(s.state.x - x_start, nodes)
        status["speed"], status["disp"] = speed, disp
        if fail is not None:
            if fail_disp is not None and disp > fail_disp:
                status["reason"] = "failed"
                status["detail"] = f"displacement {disp:.4g} m > {fail_disp:.4g} m after {t:.4g} s"
                return True
            if fail.speed is not None and speed > fail.speed:
                status["reason"] = "failed"
                status["detail"] = f"speed {speed:.4g} m/s > {fail.speed:.4g} m/s after {t:.4g} s"
                return True
        if conv is not None and t >= conv.min_time:
            ok = True
            if conv.speed is not None:
                ok = speed <= conv.speed
            if ok and conv.kinetic_ratio is not None:
                ok = status["peak"] > 0 and kin <= conv.kinetic_ratio * status["peak"]
            if ok and conv.unbalanced_ratio is not None:
                status["ratio"] = unbalanced_force_ratio(s)
                ok = status["ratio"] <= conv.unbalanced_ratio
            if not ok:
                status["since"] = None
            else:
                if status["since"] is None:
                    status["since"] = t
                if t - status["since"] >= conv.hold_for:
                    status["reason"] = "converged"
                    status["detail"] = f"after {t:.4g} s"
                    return True
        return False

    wall = time.perf_counter()
    try:
        sim.run(t_end=t0 + length, damping=stage.damping, stage=stage.name, history_every=check_steps,
                output_every=output_steps, stop_when=rule, final_output=frames)
    finally:
        sim.safety = sim_safety   # the next stage chooses its step afresh
    wall = time.perf_counter() - wall
    reason = status["reason"] or ("completed" if stage.duration is not None else "capped")
    if reason == "capped":
        status["detail"] = f"no rule held within {length:.4g} s ({length / T:.3g} response times)"
    ratio = status["ratio"] if math.isfinite(status["ratio"]) else unbalanced_force_ratio(sim)
    row = sim.last_row or {}
    return StageResult(
        name=stage.name, reason=reason, t_start=t0, t_end=sim.state.time, steps=sim.state.step - step0,
        wall_seconds=wall, dt=dt, reduction=cracks.interfaces.reduction if cracks is not None else 1.0,
        unbalanced_ratio=float(ratio), kinetic_energy=float(row.get("kinetic", 0.0)),
        peak_kinetic_energy=float(status["peak"]), max_speed=_max_norm(sim.state.v, nodes),
        max_displacement=_max_norm(sim.state.x - x_start, nodes),
        n_broken=int(cracks.broken.sum()) if cracks is not None else 0, detail=status["detail"])


# ----------------------------------------------------------------------------- factor of safety
class StrengthReduction:
    """Trigger of the factor-of-safety search: the strength-reduction factor ``F``
    (:meth:`fdem.interfaces.Interfaces.set_reduction`); larger ``F`` is weaker."""

    name = "strength reduction"

    def apply(self, sim: Simulation, factor: float) -> None:
        interfaces_of(sim).set_reduction(factor)

    def reset(self, sim: Simulation, factor: float) -> None:
        interfaces_of(sim).set_reduction(factor)

    def current(self, sim: Simulation) -> float:
        return interfaces_of(sim).reduction


class GravityIncrease:
    """Trigger of the factor-of-safety search: gravity multiplied by the factor ``k`` (larger
    is heavier), from the model's gravity, as the Muliashi study raises the density ten-fold
    (``shared/cases.md`` B). The critical gravity factor is the factor of safety against
    self-weight. :meth:`fdem.solver.Simulation.set_gravity` books each change in the ledger."""

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
    """One trial of the search: the factor, ``stable`` or not, and the stage that decided it."""

    factor: float
    stable: bool
    result: StageResult

    def as_dict(self) -> dict:
        return {"factor": self.factor, "stable": self.stable, **self.result.as_dict()}


@dataclass
class FoSResult:
    """Result of :func:`factor_of_safety`.

    ``fos`` is the middle of ``bracket = (largest stable factor, smallest failing factor)``,
    whose width is at most the tolerance. ``failure_surface`` lists the crack elements broken
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

    def as_dict(self) -> dict:
        return {"fos": self.fos, "bracket": list(self.bracket), "tolerance": self.tolerance, "trigger": self.trigger,
                "n_trials": len(self.trials), "wall_seconds": self.wall_seconds,
                "failure_surface_elements": int(self.failure_surface.size),
                "failure_broken_elements": int(self.failure_broken.size),
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


def default_trial_stage(sim: Simulation) -> Stage:
    """The damped trial of a factor-of-safety search: :func:`fundamental_damping`, converged
    when the unbalanced-force ratio falls below 1e-4, failed when a node moves 1 % of the model
    height, capped at 5 response times (non-convergence counts as failure)."""
    return Stage("trial", max_time=5.0 * response_time(sim.model), converge=Convergence(unbalanced_ratio=1e-4),
                 fail=Failure(), damping=fundamental_damping(sim))


def _trial_stage_at(trial: Stage, factor: float) -> Stage:
    return dataclasses.replace(trial, name=f"{trial.name}_F{factor:.4f}", reduction=None, reduction_ramp=None,
                               gravity_factor=None)


def _run_trial(sim: Simulation, trigger, trial: Stage, factor: float) -> tuple[Trial, dict | None]:
    """One trial on ``sim`` (already restored to the starting state): the verdict, and for a
    failing trial what it broke (failure surface, broken elements, positions, modes)."""
    trigger.apply(sim, factor)
    result = run_stage(sim, _trial_stage_at(trial, factor), frames=False)
    stable = result.reason == "converged"
    info = None
    cracks = crack_set_of(sim)
    if not stable and cracks is not None:
        info = dict(factor=factor, surface=cracks.inelastic(), broken=np.flatnonzero(cracks.broken),
                    positions=sim.state.x.copy(), mode=cracks.failure_mode.copy())
    return Trial(factor, stable, result), info


_WORKER: dict = {}


def _worker_trial(build, build_args: tuple, checkpoint: str, trigger, trial: Stage, factor: float):
    """A trial in a worker process: build the scene once, load the equilibrium checkpoint, then
    restart every trial from it."""
    from .checkpoint import load_checkpoint, restore, snapshot

    key = (build, build_args, checkpoint)
    if _WORKER.get("key") != key:
        sim = build(*build_args)
        sim.progress = False
        load_checkpoint(sim, checkpoint)
        _WORKER.update(key=key, sim=sim, start=snapshot(sim))
    sim = _WORKER["sim"]
    restore(sim, _WORKER["start"])
    return _run_trial(sim, trigger, trial, factor)


def factor_of_safety(sim: Simulation, lower: float = 1.0, upper: float = 4.0, tol: float = 0.01,
                     trial: Stage | None = None, trigger=None, out_dir=None, workers: int = 1,
                     build=None, build_args: tuple = ()) -> FoSResult:
    """Factor of safety by bisection on a trigger's factor (default strength reduction).

    ``sim`` must hold a state in equilibrium (a geostatic start or a converged stage); every
    trial restarts from it (:func:`fdem.checkpoint.snapshot`) with the trigger set to the trial
    factor and runs ``trial`` (default :func:`default_trial_stage`). ``lower`` must be stable
    and ``upper`` failing, else a ``ValueError`` names the trial that contradicts the bracket.
    The search stops when the bracket is narrower than ``tol``. On return ``sim`` is back in
    its starting state with the trigger at its starting value; with ``out_dir`` the result is
    written to ``out_dir/fos.json`` and the first failing trial to ``out_dir/fos_failure.png``
    (displacement since the equilibrium state, broken crack elements coloured by mode and the
    softened or sliding ones in black: the failure surface).

    Trials in parallel: with ``workers = w > 1`` each round runs ``w`` trials at once in
    worker processes (one Numba thread each), at the ``w`` points that split the bracket into
    ``w + 1`` equal parts, so a round narrows it ``w + 1``-fold instead of 2-fold. Each worker
    builds the scene with ``build(*build_args)`` (a picklable, module-level function returning
    a simulation of the same mesh and providers as ``sim``) and restarts its trials from a
    checkpoint of ``sim`` (:func:`fdem.checkpoint.save_checkpoint`; in ``out_dir`` when given).
    """
    from .checkpoint import restore, save_checkpoint, snapshot

    for name, value in (("lower", lower), ("upper", upper), ("tol", tol)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"factor_of_safety: {name} must be positive and finite, got {value!r}")
    if not upper > lower:
        raise ValueError(f"factor_of_safety: upper ({upper}) must exceed lower ({lower})")
    workers = int(workers)
    if workers < 1:
        raise ValueError(f"factor_of_safety: workers must be >= 1, got {workers}")
    if workers > 1 and not callable(build):
        raise ValueError("factor_of_safety: workers > 1 needs build, a module-level function returning a "
                         "simulation identical to sim (the workers restart trials from a checkpoint of sim)")
    trigger = trigger or StrengthReduction()
    trial = trial or default_trial_stage(sim)
    if trial.converge is None:
        raise ValueError("factor_of_safety: the trial stage needs a converge rule (stability is convergence)")
    start_factor = trigger.current(sim)
    start = snapshot(sim)
    cracks = crack_set_of(sim)
    trials: list[Trial] = []
    first_fail: dict = {}
    wall = time.perf_counter()
    pool = None
    tmp = None
    saved_env = None

    def record(outcome) -> bool:
        t, info = outcome
        trials.append(t)
        if info is not None and (not first_fail or t.factor < first_fail["factor"]):
            first_fail.clear()
            first_fail.update(info)
        return t.stable

    if workers > 1:
        import multiprocessing
        import os
        import tempfile
        from concurrent.futures import ProcessPoolExecutor

        if out_dir is not None:
            Path(out_dir).mkdir(parents=True, exist_ok=True)
            checkpoint = Path(out_dir) / "fos_start.npz"
        else:
            tmp = tempfile.TemporaryDirectory(prefix="fdem_fos_")
            checkpoint = Path(tmp.name) / "fos_start.npz"
        save_checkpoint(sim, checkpoint)
        # workers inherit the environment: one Numba thread each, so trials do not fight for cores
        saved_env = os.environ.get("NUMBA_NUM_THREADS")
        os.environ["NUMBA_NUM_THREADS"] = "1"
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))

    def run_many(factors: list[float]) -> list[bool]:
        if pool is None:
            out = []
            for f in factors:
                restore(sim, start)
                out.append(record(_run_trial(sim, trigger, trial, f)))
            return out
        futures = [pool.submit(_worker_trial, build, tuple(build_args), str(checkpoint), trigger, trial, f)
                   for f in factors]
        return [record(fut.result()) for fut in futures]

    try:
        ends = run_many([lower, upper])
        if not ends[0]:
            r = trials[0].result
            raise ValueError(f"factor_of_safety: the slope already fails at the lower factor F = {lower:g} "
                             f"({r.reason}: {r.detail}); lower the bracket")
        if ends[1]:
            r = trials[1].result
            raise ValueError(f"factor_of_safety: the slope is still stable at the upper factor F = {upper:g} "
                             f"(converged {r.detail}); raise the bracket")
        lo, hi = lower, upper
        while hi - lo > tol:
            points = [lo + (hi - lo) * (k + 1) / (workers + 1) for k in range(workers)]
            stable = run_many(points)
            failing = [f for f, st in zip(points, stable) if not st]
            hi = min(failing + [hi])
            lo = max([f for f, st in zip(points, stable) if st and f < hi] + [lo])
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
                       wall_seconds=time.perf_counter() - wall)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "fos.json").write_text(json.dumps(result.as_dict(), indent=2))
        if result.failure_positions is not None and cracks is not None:
            _failure_picture(out / "fos_failure.png", sim, cracks, result)
    return result


def _failure_picture(path: Path, sim: Simulation, cracks, result: FoSResult) -> Path:
    """The first failing trial: displacement from the equilibrium state and the failure surface."""
    from .pictures import failure_frame

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
