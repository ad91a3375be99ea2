"""Base shaking as a trigger of the bisection search: the critical acceleration amplitude.

:class:`BaseShaking` is a trigger for :func:`fdem.workflow.fos.factor_of_safety`, beside strength
reduction and gravity increase. Its factor is the peak base acceleration ``A`` [in g] of a
record of fixed shape,

    a_base(t) = A g s(t - t_0) d,      max |s| = 1,

``d`` the unit direction of the shaking, ``t_0`` the time the trial starts (each trial restarts
from the same equilibrium state, so every trial sees the record from its beginning). The base
(and any side boundary attached with it) moves rigidly with the record's exact velocity
(:class:`fdem.physics.shaking.AccelerationHistory`, :meth:`fdem.solve.model.Model.prescribe_velocity`).

A trial (:meth:`BaseShaking.trial_stage`) is a fixed-duration dynamic stage: the record plus a
settling time, with no stage damping (the model's own element and contact damping only, so the
inertia is the answer). Its verdict (:meth:`BaseShaking.judge`, passed to ``factor_of_safety`` as
``judge``) is the **permanent displacement** of the monitored nodes relative to the base,

    u_perm = max_i | (x_i(t_end) - x_i(t_0)) - (u_b(t_end) - u_b(t_0)) |,

``u_b`` the base displacement of the record [m]: *stable* when ``u_perm`` stays below the
threshold (default 1 % of the model height), *failing* otherwise. The search returns the
critical amplitude ``a_c`` [g]: the smallest amplitude of this record that displaces the slope
by the threshold. A rigid block with pseudo-static yield acceleration ``k_y`` [g] has
``a_c >= k_y`` for any record of finite length: below ``k_y`` it never slips (Newmark 1965),
and a pulse must exceed ``k_y`` long enough for the slip to reach the threshold.
"""
from __future__ import annotations

import math

import numpy as np

from fdem.physics.shaking import AccelerationHistory
from fdem.workflow.stages import Stage, StageResult

__all__ = ["BaseShaking", "sine_shape"]


def sine_shape(frequency: float, cycles: float = 2.0, samples_per_cycle: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Unit-peak sine record ``s(t) = sin(2 pi f t)`` for ``cycles`` periods: ``(t [s], s [-])``.
    Whole cycles end with the base at rest (zero velocity), displaced by ``A cycles / (2 pi f^2)``."""
    if not (math.isfinite(frequency) and frequency > 0):
        raise ValueError(f"sine_shape: frequency must be a positive number [Hz], got {frequency!r}")
    if not (math.isfinite(cycles) and cycles > 0):
        raise ValueError(f"sine_shape: cycles must be positive, got {cycles!r}")
    n = max(2, int(math.ceil(samples_per_cycle * cycles)) + 1)
    t = np.linspace(0.0, cycles / frequency, n)
    return t, np.sin(2.0 * np.pi * frequency * t)


class BaseShaking:
    """Trigger of the bisection search whose factor is the peak base acceleration [g] of a record.

    Parameters
    ----------
    t, shape : the record's sample times [s] (from 0) and its shape ``s`` [-], rescaled to a
        unit peak; linear between samples (:func:`sine_shape` gives a sine)
    direction : (2,) direction ``d`` of the base acceleration (normalised); a drive towards a
        face on the left (the project's convention) is a base accelerating to the right
        first, or a symmetric record
    settle : simulated time [s] after the record before the trial is judged
    threshold : permanent displacement [m] that counts as failure (default: 1 % of the model height)
    monitor : the nodes whose displacement is judged (group name, predicate or ids; default all)
    g : gravitational acceleration [m/s^2] of the unit ``g``

    Use: :meth:`attach` the base (and sides) to the model *before* the simulation is built (it
    prescribes their velocity; zero until a trial applies an amplitude), then
    ``factor_of_safety(sim, lower, upper, tol, trigger=shaking, trial=shaking.trial_stage(sim),
    judge=shaking.judge)``. Trials run in this process only (``workers = 1``): the record reaches
    the model through the velocity conditions :meth:`attach` installed, which a worker's own
    model would not have.
    """

    name = "base shaking"

    def __init__(self, t, shape, direction=(1.0, 0.0), settle: float = 0.5, threshold: float | None = None,
                 monitor=None, g: float = 9.81):
        t = np.asarray(t, float)
        s = np.asarray(shape, float)
        if t.ndim != 1 or t.shape != s.shape or len(t) < 2 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(s)):
            raise ValueError("BaseShaking: t and shape must be finite (n,) arrays, n >= 2, t strictly increasing")
        peak = float(np.abs(s).max())
        if not peak > 0:
            raise ValueError("BaseShaking: the record's shape is zero everywhere")
        d = np.asarray(direction, float)
        if d.shape != (2,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
            raise ValueError(f"BaseShaking: direction must be a nonzero (2,) vector, got {direction!r}")
        for label, value in (("settle", settle), ("g", g)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"BaseShaking: {label} must be finite and >= 0, got {value!r}")
        if threshold is not None and not (math.isfinite(threshold) and threshold > 0):
            raise ValueError(f"BaseShaking: threshold must be a positive length [m], got {threshold!r}")
        self.t = t - t[0]
        self.shape = s / peak
        self.direction = d / np.linalg.norm(d)
        self.settle = float(settle)
        self.threshold = threshold
        self.monitor = monitor
        self.g = float(g)
        self.factor = 0.0
        self.history: AccelerationHistory | None = None
        self._v = (None, None)
        self.t_start = 0.0
        self.x_start: np.ndarray | None = None
        self.log: list[dict] = []

    @classmethod
    def sine(cls, frequency: float, cycles: float = 2.0, **kw) -> "BaseShaking":
        """A sine record of ``frequency`` [Hz] and ``cycles`` periods (:func:`sine_shape`)."""
        return cls(*sine_shape(frequency, cycles), **kw)

    # ------------------------------------------------------------------ the record
    @property
    def duration(self) -> float:
        """Length of the record [s]."""
        return float(self.t[-1])

    def record(self, amplitude: float, start: float = 0.0) -> AccelerationHistory:
        """The base acceleration history at ``amplitude`` [g], starting at ``start`` [s]."""
        a = amplitude * self.g * self.shape
        return AccelerationHistory(start + self.t, a * self.direction[0], a * self.direction[1],
                                   name=f"{self.name} {amplitude:g} g")

    def drive(self, amplitude: float, direction) -> np.ndarray:
        """Inertial drive ``-a_base . e`` [m/s^2] along the unit vector ``direction`` at the record's
        samples: what a rigid mechanism moving along ``e`` feels (:mod:`fdem.blocks.newmark`)."""
        e = np.asarray(direction, float)
        e = e / np.linalg.norm(e)
        return -(amplitude * self.g * self.shape) * float(self.direction @ e)

    def _component(self, k: int):
        def v(time: float) -> float:
            f = self._v[k]
            return 0.0 if f is None else f(time)
        return v

    def attach(self, model, where, components: str = "xy") -> np.ndarray:
        """Prescribe the base motion on the nodes ``where`` selects, for the components in
        ``components`` (a side boundary moving with the base: ``"x"``). Call before the
        simulation is built. Returns the node ids."""
        if not components or set(components) - {"x", "y"}:
            raise ValueError(f"BaseShaking.attach: components must be 'x', 'y' or 'xy', got {components!r}")
        nodes = None
        for k, c in enumerate("xy"):
            if c in components:
                kw = {"vx": 1.0} if k == 0 else {"vy": 1.0}
                nodes = model.prescribe_velocity(where, history=self._component(k), _what="base shaking", **kw)
        return nodes

    # ------------------------------------------------------------------ the trigger
    def _set(self, sim, factor: float) -> None:
        self.factor = float(factor)
        self.t_start = float(sim.state.time)
        self.x_start = sim.state.x.copy()
        if self.factor == 0.0:
            self.history, self._v = None, (None, None)
        else:
            self.history = self.record(self.factor, self.t_start)
            self._v = (self.history.velocity_component(0), self.history.velocity_component(1))

    def apply(self, sim, factor: float) -> None:
        """Start the record at amplitude ``factor`` [g] now (the trial's start)."""
        if not (math.isfinite(factor) and factor >= 0):
            raise ValueError(f"base shaking: the amplitude must be finite and >= 0 [g], got {factor!r}")
        self._set(sim, factor)

    def reset(self, sim, factor: float) -> None:
        self._set(sim, factor)

    def current(self, sim) -> float:
        return self.factor

    # ------------------------------------------------------------------ the trial and its verdict
    def trial_stage(self, sim=None, name: str = "shake") -> Stage:
        """Fixed-duration dynamic stage: the record plus ``settle`` [s], no stage damping."""
        return Stage(name, duration=self.duration + self.settle)

    def base_displacement(self, time: float) -> np.ndarray:
        """(2,) displacement of the base [m] since the trial started."""
        if self.history is None:
            return np.zeros(2)
        return self.history.displacement(np.array([time]))[0] - self.history.displacement(np.array([self.t_start]))[0]

    def relative_displacement(self, sim) -> np.ndarray:
        """(n, 2) displacement of every node since the trial started, less the base's [m]."""
        if self.x_start is None:
            raise ValueError("base shaking: no trial has started (apply an amplitude first)")
        return sim.state.x - self.x_start - self.base_displacement(sim.state.time)

    def permanent_displacement(self, sim) -> float:
        """Largest displacement relative to the base of the monitored nodes [m] (module docstring)."""
        u = self.relative_displacement(sim)
        if self.monitor is not None:
            u = u[sim.model.select_nodes(self.monitor, "base shaking monitor")]
        return float(np.sqrt((u * u).sum(axis=1)).max()) if len(u) else 0.0

    def limit(self, sim) -> float:
        """The failure threshold [m]: ``threshold``, or 1 % of the model height."""
        if self.threshold is not None:
            return self.threshold
        return 0.01 * float(np.ptp(sim.model.topology.x0[:, 1]))

    def judge(self, sim, result: StageResult) -> bool:
        """Stable when the trial stage ran its time without a failure rule firing and the
        permanent displacement stays below :meth:`limit`. Each verdict is appended to ``log``
        (amplitude [g], permanent displacement [m], stable)."""
        disp = self.permanent_displacement(sim)
        stable = result.reason in ("completed", "converged") and disp < self.limit(sim)
        self.log.append({"amplitude_g": self.factor, "permanent_displacement_m": disp, "stable": bool(stable)})
        return stable
