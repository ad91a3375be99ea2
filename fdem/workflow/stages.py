"""Stages with physical end rules: :class:`Stage`, :func:`run_stage` and why a stage ended.

The factor-of-safety search and its triggers are :mod:`fdem.workflow.fos`.

A stage is a stretch of simulated time with its own damping, strength-reduction factor and
end rule. It ends by physics, never by a bare step count (the step count that means "settled"
changes with the mesh and the penalties):

* ``duration``: a fixed length of simulated time [s] (a dynamic runout window, a ramp);
* ``converge``: equilibrium reached — the unbalanced-force ratio
  (:func:`fdem.solve.geostatic.unbalanced_force_ratio`), the kinetic energy relative to the stage's
  peak, and/or the largest monitored speed fall below their limits;
* ``fail``: an objective failure criterion fires — a monitored node moves more than a set
  displacement since the stage began, or keeps a speed above a limit;
* ``max_time``: the cap [s] on a stage with rules; a capped stage reports so;
* ``domain_margin``: material has left the model: a node lies more than this margin beyond
  the model's initial x range or below its base (debris run off the end of the floor, where
  nothing holds it and it would fall for ever).

Every stage reports why it ended (:class:`StageResult`): ``converged``, ``failed``,
``capped``, ``completed`` (a fixed-duration stage that ran its time) or ``left_model``.

Time scales come from the model (:func:`response_time`): the fundamental period of a
slope of height ``H`` (shear beam on a rigid base) is ``T = 4 H / c_s`` with
``c_s = sqrt(mu / rho)`` (Kramer 1996, *Geotechnical Earthquake Engineering*, sec. 7.2); a
15-30 m slope rings for about 0.3 s. Checks run every ``T / 40``; a stage with rules is
capped at ``10 T`` by default, a factor-of-safety trial at ``5 T`` (:func:`default_trial_stage`;
the slope workflow gives its trials its own ``step_time``).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, fields as dataclass_fields
import numpy as np
from fdem.io.messages import warn
from fdem.solve.damping import NO_DAMPING, Damping
from fdem.solve.simulation import STOP, Simulation

__all__ = ["Convergence", "Failure", "Stage", "StageResult", "STEP_FROM", "response_time", "ratio_limit", "run_stage"]


STEP_FROM = ("bound", "measured")
"""What a stage's time-step factor multiplies (:attr:`Stage.step_from`)."""


# ----------------------------------------------------------------------------- rules
def _positive_or_none(value, name: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive finite number or None, got {value!r}")


@dataclass(frozen=True)
class Convergence:
    """Equilibrium rule: the stage has converged when every given limit holds at a check.

    unbalanced_ratio : limit on :func:`fdem.solve.geostatic.unbalanced_force_ratio`
        ``sum |f_net| / sum |m g|`` over free components [-] (default 1e-4)
    kinetic_ratio : limit on the kinetic energy over the stage's peak kinetic energy [-]
    speed : limit on the largest monitored speed [m/s]
    min_time : simulated time [s] before the rule may fire (default 0)
    hold_for : simulated time [s] the limits must keep holding, check after check, before the
        stage ends (default 0: the first check that meets them); a runout that comes to rest
        and stays at rest
    drift : alternative rest rule [m]: the stage has also converged when no monitored node has
        moved more than ``drift`` within the last ``drift_window`` [s] of simulated time, whatever
        the other limits say (default ``None``: no such rule). A slope that crept a few
        centimetres and stopped keeps ringing elastically in an undamped stage at a kinetic
        energy that never falls to a small share of its small peak; its positions stand still.
        Moving less than ``drift`` per window, a mass cannot travel ``drift * n`` in ``n``
        windows: the workflow's runout takes ``drift`` = 1 % of its failure displacement over
        5 response times, so a mass declared at rest would need 100 windows to fail
    drift_window : the window [s] of the drift rule (required with ``drift``)
    roundoff_factor : the ratio limit is raised to this multiple of the model's round-off floor
        :func:`fdem.solve.geostatic.unbalanced_ratio_floor` where that is higher (default 10;
        ``None``: the bare limit). Positions are stored in float64, and the crack penalties turn
        their last bits into forces: on the 180,000-triangle four-slope scene the ratio at rest
        sits at 1.66e-4, above the usual 1e-4, and a stage with the bare limit never converges
        (it ran 1.27 s, 169,740 steps, at rest from 0.45 s on). The ratio at rest measured 1.3-2
        (a column), 2.6 (size 1.0) and 5 (size 0.18) times the floor estimate; 10 keeps a
        margin. On the four-slope scene with a crest of 2 H the raised limit is at most the usual
        1e-4 at sizes 0.5 and coarser, and 3.3e-4 at 0.18 (``docs/benchmarks.md``, "Equilibrium
        stage at scale"); with the run extents (x up to 165 m, where float64 positions are half
        as fine) it is 1.83e-4 at 0.5 and 2.8e-4 at 0.35. The limit so moves with the element
        size, and a factor of safety judged at each size's own limit drifts with it: a
        convergence study gives every size the finest model's limit
        (:class:`fdem.workflow.slope.SlopeWorkflow` ``equilibrium_ratio``, ``docs/cases.md`` A).
    """

    unbalanced_ratio: float | None = 1e-4
    kinetic_ratio: float | None = None
    speed: float | None = None
    min_time: float = 0.0
    hold_for: float = 0.0
    roundoff_factor: float | None = 10.0
    drift: float | None = None
    drift_window: float = 0.0

    def __post_init__(self):
        _positive_or_none(self.unbalanced_ratio, "Convergence.unbalanced_ratio")
        _positive_or_none(self.kinetic_ratio, "Convergence.kinetic_ratio")
        _positive_or_none(self.speed, "Convergence.speed")
        if not (math.isfinite(self.min_time) and self.min_time >= 0):
            raise ValueError(f"Convergence.min_time must be >= 0, got {self.min_time!r}")
        if not (math.isfinite(self.hold_for) and self.hold_for >= 0):
            raise ValueError(f"Convergence.hold_for must be >= 0, got {self.hold_for!r}")
        _positive_or_none(self.roundoff_factor, "Convergence.roundoff_factor")
        _positive_or_none(self.drift, "Convergence.drift")
        if self.drift is not None and not (math.isfinite(self.drift_window) and self.drift_window > 0):
            raise ValueError(f"Convergence.drift_window must be a positive time with drift, got {self.drift_window!r}")
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
    damping : :class:`fdem.solve.damping.Damping` of the stage (default none: dynamic)
    reduction : strength-reduction factor ``F`` set when the stage starts (``None``: keep)
    reduction_ramp : ``(F_end, seconds)``: the strength ``1/F`` moves linearly from its value
        at the stage start to ``1/F_end`` over ``seconds`` of simulated time, updated at every
        check (the four-slope paper's schedule, 10 % of the initial strength per 10,000 steps
        of 2 us, is ``1/F`` falling by 5 per second)
    gravity_factor : gravity set to this multiple of ``base_gravity`` when the stage starts
        (``None``: keep); :meth:`fdem.solve.simulation.Simulation.set_gravity` books the change
    base_gravity : (gx, gy) [m/s^2] the factor multiplies (default: the model's gravity)
    hold_elastic : hold the crack elements elastic during the stage (``None``: keep)
    check_interval : simulated time [s] between checks of the rules (default ``T / 40``)
    output_interval : simulated time [s] between output frames (default: 4 per stage)
    monitor : nodes the rules watch (a group name, predicate or ids; default all nodes)
    dt_fraction : time-step factor of the stage, the fraction of the critical step (``None``: the
        simulation's ``dt_fraction``; ignored when the simulation has a user time step). The
        simulation's own factor is restored when the stage ends.
    domain_margin : end the stage ``left_model`` when a node lies more than this [m] beyond the
        model's initial x range or below its initial base (``None``: never); a runout whose
        debris runs off the end of the floor stops there, with the state that shows it, instead
        of following the debris falling into the void until its cap
    escape_share : with ``domain_margin``, the fragments that leave the model (triangles still
        bonded by unbroken crack elements, one of whose nodes is beyond the margin) are held
        where they are (both velocity components prescribed zero from the next step, their
        kinetic energy taken out as boundary work) and the stage goes on, as long as all those
        held come to at most this share of the area displaced more than 0.1 m; beyond it the
        mass itself is running off the model and the stage ends ``left_model`` (``None``: the
        first node beyond ends it). A single fly-rock, a 0.005 m^2 sliver thrown 45 m along the
        floor at 6 m/s, ended both high-angle coarse collapses so, the mass still moving behind it
    density_scaling : run the stage on density-scaled inertial masses
        (:mod:`fdem.solve.density_scaling`, within the simulation's added-mass budget).
        ``None`` (default): yes for a damped (quasi-static) stage, no for an undamped (dynamic)
        one, whose inertia is the answer. A scaled stage stretches its time rules (``duration``,
        ``max_time``, ``check_interval``, ``output_interval``, ``reduction_ramp`` time,
        ``min_time``, ``hold_for``) by the period stretch and divides its mass-proportional
        damping by it, so it runs the same number of response times.
    step_from : what ``dt_fraction`` is a fraction of: ``"bound"`` (default) the solver's
        combined bound on the critical step (:meth:`fdem.solve.simulation.Simulation.critical_dt`);
        ``"measured"`` the critical step measured on the model when the stage starts
        (:func:`fdem.solve.step_probe.measured_critical_dt`, 21-51 steps of the model), 1.26-1.63
        times the bound on the four-slope scenes (``docs/benchmarks.md``, "How far the step is
        below the critical one"), held for the stage (a resumed stage keeps the one it began with)
        or measured again every ``remeasure_every``.
        An undamped stage on its own masses only (damping lowers the critical step, and a
        density-scaled stage chooses its masses for its step); a model with forces on velocities
        is refused when the stage starts (:func:`fdem.solve.step_probe.velocity_readers`), and a
        probe that fails leaves the stage on the bound, with a warning and the reason in its
        ``detail``; with a user time step (``Simulation(dt=...)``) there is nothing to measure.
    remeasure_every : simulated time [s] between measurements of the critical step of a
        ``step_from="measured"`` stage (``None``: the step measured at the start is held). The
        stage steps at ``dt_fraction`` of the latest, down, or up at most to the contact's own
        bound (:func:`_renewed_critical`): the limit moves as crack
        elements break (the high-angle coarse slope's grew 1.57x from its start to rest, its
        limiting element broken) and contacts form, as an explicit code's global step estimate
        is renewed during a run (Abaqus/Explicit's "global estimation"). A probe that fails
        keeps the step of the last one. The measurements are in the result's ``detail`` and
        every history row's ``dt``.
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
    dt_fraction: float | None = None
    density_scaling: bool | None = None
    domain_margin: float | None = None
    escape_share: float | None = None
    step_from: str = "bound"
    remeasure_every: float | None = None

    def __post_init__(self):
        if not self.name:
            raise ValueError("a stage needs a name")
        if self.step_from not in STEP_FROM:
            raise ValueError(f"stage {self.name!r}: step_from must be one of {', '.join(STEP_FROM)}, got {self.step_from!r}")
        damped = self.damping.mass_proportional != 0.0 or self.damping.local != 0.0 if isinstance(
            self.damping, Damping) else False
        if self.step_from == "measured" and (damped or self.density_scaling):
            raise ValueError(f"stage {self.name!r}: step_from='measured' measures the step of the undamped model on "
                             "its own masses, and this stage is damped or density-scaled: step_from='bound'")
        _positive_or_none(self.remeasure_every, f"stage {self.name!r}: remeasure_every")
        if self.remeasure_every is not None and self.step_from != "measured":
            raise ValueError(f"stage {self.name!r}: remeasure_every renews a measured step, and this stage steps "
                             f"from the {self.step_from}: give step_from='measured' or no remeasure_every")
        if self.dt_fraction is not None and not 0.0 < self.dt_fraction <= 1.0:
            raise ValueError(f"stage {self.name!r}: dt_fraction (time-step factor) must lie in (0, 1], got {self.dt_fraction}")
        _positive_or_none(self.duration, f"stage {self.name!r}: duration")
        _positive_or_none(self.max_time, f"stage {self.name!r}: max_time")
        _positive_or_none(self.domain_margin, f"stage {self.name!r}: domain_margin")
        if self.escape_share is not None and not (self.domain_margin is not None and 0.0 < self.escape_share < 1.0):
            raise ValueError(f"stage {self.name!r}: escape_share must lie in (0, 1) and needs a domain_margin, "
                             f"got {self.escape_share!r} (domain_margin {self.domain_margin!r})")
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
            raise ValueError(f"stage {self.name!r}: damping must be a fdem.solve.damping.Damping, got {self.damping!r}")


@dataclass
class StageResult:
    """How a stage went. ``reason``: ``converged``, ``failed``, ``capped`` or ``completed``;
    ``period_stretch`` > 1 when it ran density-scaled (times are then the scaled model's);
    ``measured_critical_dt`` [s] the critical step measured on the model that a
    ``step_from="measured"`` stage stepped from (``dt`` is its ``dt_fraction`` of it), else
    ``None`` (the stage stepped from the bounds, or at a user time step)."""

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
    period_stretch: float = 1.0
    output_seconds: dict | None = None
    """Wall seconds of the stage spent on output frames, history rows and checkpoints
    (``Simulation.output_seconds``), against ``wall_seconds`` in all."""
    measured_critical_dt: float | None = None
    ratio_limit: float | None = None
    """The unbalanced-ratio limit the stage's rule applied: its ``unbalanced_ratio``, raised to
    ``roundoff_factor`` times the round-off floor at the stage's start where that is higher
    (``None`` without a ratio rule; stages recorded before it was kept read ``None`` too)."""

    @property
    def converged(self) -> bool:
        return self.reason == "converged"

    def as_dict(self) -> dict:
        return asdict(self)


# ----------------------------------------------------------------------------- helpers
def failure_displacement(sim: Simulation, fail: Failure | None) -> float | None:
    """The displacement [m] at which ``fail`` fires on ``sim``: its own, 1 % of the model
    height when it gives neither a displacement nor a speed, ``None`` when it gives only a
    speed or there is no rule."""
    if fail is None or (fail.displacement is None and fail.speed is not None):
        return None
    return fail.displacement if fail.displacement is not None else 0.01 * float(np.ptp(sim.model.topology.x0[:, 1]))


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


def ratio_limit(sim: Simulation, conv: Convergence | None) -> float | None:
    """The unbalanced-ratio limit ``conv`` applies to ``sim`` in its present state:
    ``max(unbalanced_ratio, roundoff_factor * R_eps)`` with ``R_eps`` the round-off floor
    (:func:`fdem.solve.geostatic.unbalanced_ratio_floor`); ``None`` without a ratio rule. A stage
    takes it once, at its start."""
    if conv is None or conv.unbalanced_ratio is None:
        return None
    from fdem.solve.geostatic import unbalanced_ratio_floor

    try:
        floor = unbalanced_ratio_floor(sim) if conv.roundoff_factor is not None else 0.0
    except ValueError:  # no gravity and no load: the ratio itself says so at the first check
        floor = 0.0
    return max(conv.unbalanced_ratio, conv.roundoff_factor * floor) if floor > 0.0 else conv.unbalanced_ratio


def _monitor_nodes(sim: Simulation, monitor) -> np.ndarray | None:
    if monitor is None:
        return None
    return sim.model.select_nodes(monitor, "stage monitor")


def _max_norm(a: np.ndarray, nodes: np.ndarray | None) -> float:
    if nodes is not None:
        a = a[nodes]
    return float(np.sqrt((a * a).sum(axis=1)).max()) if len(a) else 0.0


HELD = 3
"""``Simulation.flags`` of a node held in place: both components prescribed (``FIX_X | FIX_Y``)."""

ESCAPE_THRESHOLD = 0.1
"""Displacement [m] above which a triangle counts in the displaced area that
:attr:`Stage.escape_share` is a share of (``fdem.results.analysis.runout``'s threshold)."""


def hold_escaped(sim: Simulation, out: np.ndarray, share: float, held_before: float = 0.0) -> tuple[int, float] | None:
    """Hold the fragments that left the model (:attr:`Stage.escape_share`): the triangles bonded
    to one with a node in ``out`` (n_nodes,) bool by unbroken crack elements (every triangle on
    its own without crack elements) get both velocity components prescribed zero, so the next
    step stops them and books their kinetic energy as boundary work (the support's reaction,
    :func:`fdem.kernels.stepping.constrain_and_move`). Returns ``(triangles, area [m^2])`` held,
    or ``None`` (nothing held) when ``held_before`` plus their area would exceed ``share`` of the
    area displaced more than :data:`ESCAPE_THRESHOLD`."""
    from fdem.results.analysis import fragments

    topo = sim.model.topology
    tri = np.asarray(topo.triangles)
    broken = sim.cracks.broken if sim.cracks is not None else np.ones(topo.n_cracks, bool)
    _, body = fragments(topo, broken)
    held = np.isin(body, np.unique(body[out[tri].any(axis=1)]))
    area = float(topo.triangle_area0[held].sum())
    moved = np.linalg.norm(sim.state.x[tri].mean(axis=1) - topo.x0[tri].mean(axis=1), axis=1) > ESCAPE_THRESHOLD
    if held_before + area > share * float(topo.triangle_area0[moved].sum()):
        return None
    nodes = np.unique(tri[held])
    sim.flags[nodes] = HELD
    sim.v_prescribed[nodes] = 0.0
    return int(held.sum()), area


def _measured_critical(sim: Simulation, stage: Stage, saved: dict | None) -> tuple[float | None, str]:
    """The critical step [s] a ``step_from="measured"`` stage steps from, and why it is ``None``
    (the stage then steps from the bounds): the one it began with when it is resumed (so that it
    repeats the uninterrupted run), else measured now on the stage's own masses
    (:func:`fdem.solve.step_probe.measured_critical_dt`). A model that cannot be probed
    (:func:`fdem.solve.step_probe.unmeasurable`, or density-scaled) is refused with a ``ValueError``; a probe that
    does not converge falls back on the bounds rather than end a run hours in."""
    if sim.user_dt is not None:
        return None, ""
    if sim.density_scaled:
        raise ValueError(f"stage {stage.name!r}: step_from='measured' needs the model's own masses, and it is "
                         "density-scaled")
    if saved is not None and "measured_critical" in saved:  # resumed: the step it began with, bound or measured
        return (None if saved["measured_critical"] is None else float(saved["measured_critical"])), ""
    from fdem.solve import step_probe

    why = step_probe.unmeasurable(sim)
    if why:  # refused, not fallen back on: the bounds would hide a setting that cannot hold
        raise ValueError(f"stage {stage.name!r}: step_from='measured' cannot measure this model: {why}; use "
                         "step_from='bound'")
    sim.measured_critical = None
    critical, why = step_probe.critical_or_bounds(sim)
    if critical is None:
        warn(f"stage {stage.name!r}: {why}")
    return critical, why


def _probes_note(status: dict) -> str:
    """The renewed measurements of a stage's critical step, for its detail (``""``: none)."""
    probes = status.get("probes") or []
    note = ""
    if len(probes) >= 2:
        raw, used = [p[1] * 1e6 for p in probes], [p[2] * 1e6 for p in probes]
        note = (f"; critical step measured {len(raw)} times, {min(raw):.4g}-{max(raw):.4g} us (first {raw[0]:.4g}, "
                f"last {raw[-1]:.4g}), stepped from {min(used):.4g}-{max(used):.4g} us")
        if status.get("held_to_contact"):
            note += f" ({status['held_to_contact']} rise(s) held to the contact's bound)"
    if status.get("probe_failed"):
        note += f"; a probe failed {status['probe_failed']}"
    return note


def _schedule_probe(sim: Simulation, stage: Stage, status: dict) -> None:
    """The next renewal of a measured step, ``remeasure_every`` from now: its time and step."""
    status["next_probe_time"] = sim.state.time + stage.remeasure_every
    status["next_probe_step"] = sim.state.step + max(1, sim.steps_to(status["next_probe_time"]))


def _contact_bound(sim: Simulation) -> float | None:
    """The contact's own bound on the critical step [s] (the face-to-face limit of any contact
    that may form, :meth:`fdem.physics.contact.ContactSet.stable_dt`), or ``None`` without contact."""
    from fdem.physics.contact import ContactSet

    bounds = [p.stable_dt(sim.state.mass) for p in sim.providers if isinstance(p, ContactSet)]
    return min(bounds) if bounds else None


def _renewed_critical(sim: Simulation, stage: Stage, status: dict, measured: float) -> float:
    """The critical step [s] a stage renewing its measured step goes on from: measured now
    (:func:`fdem.solve.step_probe.critical_or_bounds`), or ``measured``, the last one, when the
    probe fails (said in the stage's detail). A fall is taken whole; a rise at most to the
    contact's own bound (:func:`_contact_bound`) when that lies above ``measured``: the probe
    sees the contacts of the moment, and one that forms after it is bounded by that limit alone.
    Each measurement goes into ``status["probes"]`` as ``[time, measured now, stepped from]``."""
    from fdem.solve import step_probe

    critical, why = step_probe.critical_or_bounds(sim)
    if critical is None:
        if "probe_failed" not in status:
            status["probe_failed"] = f"at t = {sim.state.time:.4g} s ({why.replace('stepped from the bounds', 'kept the last step')})"
            warn(f"stage {stage.name!r}: {status['probe_failed']}")
        return measured
    used = critical
    if critical > measured:
        bound = _contact_bound(sim)
        if bound is not None and critical > max(measured, bound):
            used = max(measured, bound)
            status["held_to_contact"] = status.get("held_to_contact", 0) + 1
    status["probes"].append([sim.state.time, critical, used])
    return used


def run_stage(sim: Simulation, stage: Stage, frames: bool = True, journal=None) -> StageResult:
    """Run ``stage`` on ``sim`` until its end rule (see the module docstring); returns its result.

    ``frames=False`` writes no output frames (the history rows are still written), as for the
    trials of a factor-of-safety search.

    The stage's factor, hold and damping are set first. Rules are checked every
    ``check_interval`` of simulated time (a history row of the ledger is written at each
    check); the run stops at the first rule that holds. A run that goes unstable raises
    :class:`fdem.solve.simulation.InstabilityError` with its last good state on disk, as every run does.

    ``journal`` (:class:`fdem.workflow.journal.RunJournal`): the stage is one of a resumable
    workflow. A stage the journal finished before its checkpoint returns its recorded result
    without stepping; the stage that was in progress continues from its saved runtime, taking
    the history steps the uninterrupted run took; a running stage writes periodic checkpoints on
    history rows and one when interrupted, and the journal writes one when it ends.
    """
    from fdem.solve.geostatic import unbalanced_force_ratio

    kind, saved = journal.next_stage(stage.name) if journal is not None else ("fresh", None)
    if kind == "done":  # finished before the checkpoint: its effects are in the restored state
        # a field a later commit added (read by this one from a checkpoint that commit wrote) is
        # left out rather than refused: the stage's verdict and times are what the replay needs
        keep = {f.name for f in dataclass_fields(StageResult)}
        return StageResult(**{k: v for k, v in saved.items() if k in keep})
    T = response_time(sim.model)
    cracks = sim.cracks
    if stage.reduction is not None or stage.reduction_ramp is not None or stage.hold_elastic is not None:
        if cracks is None:
            raise ValueError(f"stage {stage.name!r} changes strength, but the simulation has no crack elements")
    # a resumed stage's strengths, hold and gravity are in the restored state: setting them again
    # would re-project damaged elements onto their envelope and the run would not repeat itself
    if stage.hold_elastic is not None and kind != "resume":
        cracks.hold_elastic(stage.hold_elastic)
    if stage.reduction is not None and kind != "resume":
        cracks.interfaces.set_reduction(stage.reduction)
    if stage.gravity_factor is not None and kind != "resume":
        base = np.asarray(stage.base_gravity if stage.base_gravity is not None else sim.model.gravity, float)
        sim.set_gravity(*(stage.gravity_factor * base))
    nodes = _monitor_nodes(sim, stage.monitor)
    fail = stage.fail
    fail_disp = failure_displacement(sim, fail)
    damping = stage.damping
    quasi_static = damping.mass_proportional != 0.0 or damping.local != 0.0
    want_scaled = quasi_static if stage.density_scaling is None else stage.density_scaling
    if kind == "resume" and want_scaled == sim.density_scaled:
        scaled = want_scaled  # the restored scaled masses are the stage's own: keep them
    else:
        scaled = sim.set_density_scaling(want_scaled)
    stretch = sim.period_stretch  # the stage's time rules in the scaled model's time
    if scaled and damping.mass_proportional != 0.0:
        damping = Damping(mass_proportional=damping.mass_proportional / stretch, local=damping.local)
    length = stretch * (stage.duration if stage.duration is not None else (stage.max_time or 10.0 * T))
    sim_dt_fraction = sim.dt_fraction
    probe_note = ""
    try:
        if stage.dt_fraction is not None:
            sim.dt_fraction = stage.dt_fraction
        if stage.step_from == "measured":
            sim.measured_critical, probe_note = _measured_critical(sim, stage, saved if kind == "resume" else None)
        sim.dt = sim._choose_dt()
    except BaseException:  # a bad step, or a stop during the probe: the simulation's own settings back
        sim.dt_fraction = sim_dt_fraction
        sim.measured_critical = None
        raise
    dt = sim.dt
    measured = sim.measured_critical
    # a measured step is the stage's alone: whatever ends the stage, the next one steps from the
    # bounds (critical_dt() of a cost estimate or the guard included)
    sim.measured_critical = None

    def spacings(step: float) -> tuple[int, int]:
        """Steps between the rule checks (history rows) and between frames at time step ``step``
        [s]: ``check_interval`` (default T/40) and ``output_interval`` (default a quarter of the
        stage), in the scaled model's time; no frames when ``frames`` is off."""
        check = max(1, int(round(stretch * (stage.check_interval or T / 40.0) / step)))
        output = max(1, int(round(stretch * (stage.output_interval or length / stretch / 4.0) / step)))
        return check, (output if frames else 2 ** 62)

    check_steps, output_steps = spacings(dt)
    if kind == "resume":
        t0, step0 = float(saved["t0"]), int(saved["step0"])
        n_total = None if saved.get("n_total") is None else int(saved["n_total"])
        if saved.get("n_total") is None or float(saved.get("dt", dt)) != dt:
            # resumed with another step (after an instability), or a capped stage carried on to a
            # longer cap (fdem.workflow.journal.RunJournal.carry_on): the steps to the stage's end time
            n_total = sim.state.step - step0 + sim.steps_to(t0 + length)
        x_start = saved["x_start"].copy()
        ramp = None if saved["ramp"] is None else tuple(saved["ramp"])
        status = dict(saved["status"])
    else:
        t0 = sim.state.time
        step0 = sim.state.step
        n_total = sim.steps_to(t0 + length)
        x_start = sim.state.x.copy()
        ramp = None
        if stage.reduction_ramp is not None:
            ramp = (1.0 / cracks.interfaces.reduction, 1.0 / stage.reduction_ramp[0], stretch * stage.reduction_ramp[1])
        status = {"reason": None, "detail": "", "peak": 0.0, "ratio": math.nan, "speed": 0.0, "disp": 0.0,
                  "since": None}
    conv = stage.converge
    if probe_note:  # kept with the stage, so that a resumed stage still says why it stepped from the bounds
        status["probe_note"] = probe_note
    if "limit" not in status:  # the ratio limit, raised to the round-off floor once per stage (kept on resume)
        status["limit"] = ratio_limit(sim, conv)

    x0 = sim.model.topology.x0
    box = (x0[:, 0].min(), x0[:, 0].max(), x0[:, 1].min())

    def rule(s: Simulation) -> bool:
        t = s.state.time - t0
        if stage.domain_margin is not None:
            m, x = stage.domain_margin, s.state.x
            out = (x[:, 0] < box[0] - m) | (x[:, 0] > box[1] + m) | (x[:, 1] < box[2] - m)
            out &= s.flags != HELD  # fragments already held beyond it
            if out.any() and stage.escape_share is not None:
                held = hold_escaped(s, out, stage.escape_share, status.get("escaped_area", 0.0))
                if held is not None:
                    status["escaped_triangles"] = status.get("escaped_triangles", 0) + held[0]
                    status["escaped_area"] = status.get("escaped_area", 0.0) + held[1]
                    out[:] = False
            if out.any():
                status["reason"] = "left_model"
                status["detail"] = (f"{int(out.sum())} node(s) more than {m:.3g} m beyond the model's initial extent "
                                    f"(x {box[0]:.4g}..{box[1]:.4g} m, base y {box[2]:.4g} m) after {t:.4g} s")
                return True
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
        if conv is not None and t >= stretch * conv.min_time:
            ok = True
            if conv.speed is not None:
                ok = speed <= conv.speed
            if ok and conv.kinetic_ratio is not None:
                ok = status["peak"] > 0 and kin <= conv.kinetic_ratio * status["peak"]
            if ok and conv.unbalanced_ratio is not None:
                status["ratio"] = float(row["unbalanced_ratio"]) if row and "unbalanced_ratio" in row \
                    else unbalanced_force_ratio(s)
                ok = status["ratio"] <= status["limit"]
            if conv.drift is not None and not ok:
                # still within drift of where the window began, for the whole window: at rest
                if status.get("anchor") is None or _max_norm(s.state.x - status["anchor"], nodes) > conv.drift:
                    status["anchor"], status["anchor_t"] = s.state.x.copy(), t
                elif t - status["anchor_t"] >= stretch * conv.drift_window:
                    status["reason"] = "converged"
                    status["detail"] = (f"after {t:.4g} s: no node moved more than {conv.drift:.3g} m in the last "
                                        f"{t - status['anchor_t']:.4g} s")
                    return True
            if not ok:
                status["since"] = None
            else:
                if status["since"] is None:
                    status["since"] = t
                if t - status["since"] >= stretch * conv.hold_for:
                    status["reason"] = "converged"
                    status["detail"] = f"after {t:.4g} s"
                    if conv.unbalanced_ratio is not None and status["limit"] > conv.unbalanced_ratio:
                        status["detail"] += (f" (unbalanced ratio {status['ratio']:.3g} <= {status['limit']:.3g}, "
                                             f"{conv.roundoff_factor:g} times the round-off floor, above the limit "
                                             f"{conv.unbalanced_ratio:.3g})")
                    return True
        if journal is not None:
            journal.tick(s)
        return False

    def runtime() -> dict:  # what a checkpoint needs to continue this stage (fdem.workflow.journal)
        return {"name": stage.name, "t0": t0, "step0": step0, "n_total": n_total, "dt": dt,
                "measured_critical": measured, "x_start": x_start,
                "ramp": None if ramp is None else list(ramp), "status": dict(status),
                "wall_seconds": wall_before + time.perf_counter() - wall, "output_seconds": output_so_far()}

    def output_so_far() -> dict:
        return {k: output_before.get(k, 0.0) + sim.output_seconds[k] - output0[k] for k in output0}

    wall_before = float(saved.get("wall_seconds", 0.0)) if kind == "resume" else 0.0
    output_before = dict(saved.get("output_seconds") or {}) if kind == "resume" else {}
    output0 = dict(sim.output_seconds)
    wall = time.perf_counter()
    # a measured step renewed every remeasure_every: the stage runs in segments between probes,
    # whose steps (next_probe_step) and results (probes) a checkpoint keeps, so that a resumed
    # stage probes on the same steps as the uncut one
    probing = stage.remeasure_every is not None and measured is not None
    if probing and status.get("next_probe_step") is None:
        _schedule_probe(sim, stage, status)
        status["probes"] = [[sim.state.time, measured, measured]]
    elif probing and kind == "resume" and float(saved.get("dt", dt)) != dt:
        # resumed with another step (after an instability): the next probe at the time it stood for
        status["next_probe_step"] = sim.state.step + max(0, sim.steps_to(status["next_probe_time"]))
    if journal is not None:
        journal.current = runtime
        sim.caller_checkpoints_interrupts = True  # the journal's checkpoint below is the interrupted state
    try:
        final_written = False
        while status["reason"] is None:  # a stage resumed after its rule held has nothing left to run
            done = sim.state.step - step0
            n = n_total - done
            last = not probing or n <= status["next_probe_step"] - sim.state.step
            if not last:
                n = max(0, status["next_probe_step"] - sim.state.step)
            sim.measured_critical = measured  # sim.run chooses its step again: from the same critical step
            sim.run(n_steps=n, phase=done, damping=damping, stage=stage.name, history_every=check_steps,
                    output_every=output_steps, stop_when=rule, final_output=frames and last)
            final_written = last
            if last or status["reason"] is not None or sim.state.step - step0 - done < n:
                break
            STOP.running += 1  # a signal waits for the next step: the renewal is made whole or not begun
            try:
                if frames and (sim.state.step - step0) % output_steps == 0:
                    sim.write_output()  # a frame due on the segment's last step (run writes it only at the end)
                measured = _renewed_critical(sim, stage, status, measured)
                sim.measured_critical = measured
                dt = sim.dt = sim._choose_dt()
                n_total = sim.state.step - step0 + sim.steps_to(t0 + length)
                check_steps, output_steps = spacings(dt)
                _schedule_probe(sim, stage, status)
            finally:
                STOP.running -= 1
        if frames and probing and not final_written:  # the stage's rule ended a segment before its last
            STOP.running += 1
            try:
                sim.write_output()
            finally:
                STOP.running -= 1
    except KeyboardInterrupt:
        if journal is not None and not STOP.forced:  # stopped at a whole step: the stage continues from here
            journal.write(sim, "interrupted")  # first: the file a resume needs
            sim.write_interrupted(checkpoint=False)  # then the state's .vtu, to look at
        raise
    finally:
        sim.dt_fraction = sim_dt_fraction   # the next stage chooses its step afresh
        sim.measured_critical = None
        if journal is not None:
            journal.current = None
            sim.caller_checkpoints_interrupts = False
    wall_total = wall_before + time.perf_counter() - wall
    reason = status["reason"] or ("completed" if stage.duration is not None else "capped")
    if reason == "capped":
        status["detail"] = f"no rule held within {length:.4g} s ({length / (stretch * T):.3g} response times)"
    if status.get("escaped_triangles"):
        status["detail"] += (f"; {status['escaped_triangles']} triangle(s) of fragments that left the model "
                             f"({status['escaped_area']:.3g} m^2) held beyond it")
    ratio = status["ratio"] if math.isfinite(status["ratio"]) else unbalanced_force_ratio(sim)
    row = sim.last_row or {}
    result = StageResult(
        name=stage.name, reason=reason, t_start=t0, t_end=sim.state.time, steps=sim.state.step - step0,
        wall_seconds=wall_total, dt=dt, reduction=cracks.interfaces.reduction if cracks is not None else 1.0,
        unbalanced_ratio=float(ratio), kinetic_energy=float(row.get("kinetic", 0.0)),
        peak_kinetic_energy=float(status["peak"]), max_speed=_max_norm(sim.state.v, nodes),
        max_displacement=_max_norm(sim.state.x - x_start, nodes),
        n_broken=int(cracks.broken.sum()) if cracks is not None else 0,
        detail=status["detail"] + (f"; {status['probe_note']}" if status.get("probe_note") else "") + _probes_note(status),
        period_stretch=stretch, output_seconds=output_so_far(), measured_critical_dt=measured,
        ratio_limit=None if status["limit"] is None else float(status["limit"]))
    if journal is not None:
        # a stage that ran to its cap keeps its runtime, so that it can be carried on to a longer one
        capped = None
        if reason == "capped":
            # the cap writes a row at its last step; a stage given a longer cap writes none there
            # unless that step is on its history steps or ends a segment of a renewed measured
            # step: otherwise the carry-on drops the row (fdem.workflow.journal.RunJournal.carry_on)
            end = sim.state.step
            capped = {**runtime(), "cap_row_extra": bool((end - 1 - step0) % check_steps != 0
                                                        and end != status.get("next_probe_step"))}
        journal.stage_finished(sim, result.as_dict(), capped)
    return result
