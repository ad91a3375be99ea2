"""Base shaking: acceleration histories and base excitation.

Newmark's rigid sliding block, the closed form the shaking is verified against, is
:mod:`fdem.reference.newmark`.

Acceleration history
--------------------
An :class:`AccelerationHistory` holds samples ``(t_i, a_x,i, a_y,i)`` [s, m/s^2] (from arrays
or a CSV file), checked on entry: at least two samples, finite values, times strictly
increasing (errors name the offending row). Between samples the acceleration is linear;
before the first and after the last sample it is zero (the base is at rest before the
record and keeps its final velocity after it).

The velocity is the integral of that piecewise-linear acceleration, which is the
trapezoidal rule at the samples,

    v_{i+1} = v_i + (t_{i+1} - t_i) (a_i + a_{i+1}) / 2,    v_0 = 0,

and, exactly, a quadratic between them: ``v(t_i + s) = v_i + a_i s + (a_{i+1} - a_i) s^2 / (2 dt_i)``.
The displacement is its integral (a cubic between samples).

Baseline correction (optional, off by default): a record integrated to velocity usually ends
with a residual velocity ``v_end``, and the base would drift away for ever. ``baseline="linear"``
removes the linear trend of the velocity that brings it to rest at the last sample,
``v_c(t) = v(t) - v_end (t - t_0) / (t_N - t_0)``, i.e. it subtracts the constant acceleration
``v_end / (t_N - t_0)`` from every sample (so acceleration and velocity stay consistent).

Base excitation
---------------
:func:`shake_base` prescribes the history's velocity on the base nodes of a model through
:meth:`fdem.solve.model.Model.prescribe_velocity` (one condition per component with the velocity as
``history(t)``; the solver evaluates it at ``t_{n+1/2}``, where its leapfrog velocities live).
The work the base does on the model is the solver's ``boundary_work``.

Newmark sliding block
---------------------
A rigid block on a plane inclined at ``theta`` with friction angle ``phi``, whose base moves
along the plane with acceleration ``a_b(t)`` (positive down the slope). In the base frame the
block feels ``-a_b`` and its slip velocity ``v`` (down-slope positive) obeys (Newmark 1965):

* sliding down (``v > 0``):  ``dv/dt = -a_b - a_y``,  ``a_y = g (cos theta tan phi - sin theta)``;
* sliding up (``v < 0``):    ``dv/dt = -a_b + a_u``,  ``a_u = g (cos theta tan phi + sin theta)``;
* stuck (``v = 0``) while ``-a_u <= -a_b <= a_y``.

``a_y`` is the along-plane yield acceleration of down-slope slip (the base must accelerate
*up* the slope by more than ``a_y``). :func:`newmark_response` integrates this exactly for a
piecewise-linear ``a_b`` (quadratic velocity in each segment, stopping times from the roots of
the quadratic). For a rectangular pulse ``-a_b = a_p > a_y`` lasting ``t_p`` the block slides
with ``dv/dt = a_p - a_y`` until ``t_p`` (velocity ``(a_p - a_y) t_p``) and decelerates at
``a_y`` until it stops at ``t = a_p t_p / a_y``; the permanent displacement is

    d = (a_p - a_y) t_p^2 / 2 + ((a_p - a_y) t_p)^2 / (2 a_y) = a_p t_p^2 (a_p - a_y) / (2 a_y).

Reference: Newmark, N. M. (1965). Effects of earthquakes on dams and embankments.
Geotechnique 15(2), 139-160.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable
import numpy as np

__all__ = ["AccelerationHistory", "shake_base"]


def _bad_row(mask: np.ndarray) -> int:
    return int(np.flatnonzero(mask)[0])


class AccelerationHistory:
    """A base acceleration record ``a(t) = (a_x, a_y)`` [m/s^2], piecewise linear in ``t`` [s].

    Parameters
    ----------
    t : (n,) array
        Sample times [s], strictly increasing, ``n >= 2``.
    ax, ay : (n,) arrays
        Acceleration components [m/s^2]; ``ay`` defaults to zero.
    baseline : None or "linear"
        ``"linear"`` removes the linear velocity trend so the base ends at rest (module docstring).
    name : str
        Label for error messages and plots.

    Zero before ``t[0]`` and after ``t[-1]`` (see the module docstring for the velocity and
    displacement). Call it as ``history.velocity(t)`` or hand ``history.velocity_component(k)``
    to :meth:`fdem.solve.model.Model.prescribe_velocity`.
    """

    def __init__(self, t, ax, ay=None, baseline: str | None = None, name: str = "history"):
        self.name = name
        t = self._column(t, "t")
        ax = self._column(ax, "a_x")
        ay = np.zeros_like(ax) if ay is None else self._column(ay, "a_y")
        if not (len(t) == len(ax) == len(ay)):
            raise ValueError(f"{name}: t, a_x and a_y must have the same length, got {len(t)}, {len(ax)}, {len(ay)}")
        if len(t) < 2:
            raise ValueError(f"{name}: an acceleration history needs at least two samples, got {len(t)}")
        for label, arr in (("t", t), ("a_x", ax), ("a_y", ay)):
            bad = ~np.isfinite(arr)
            if bad.any():
                i = _bad_row(bad)
                raise ValueError(f"{name}: {label} is not finite in row {i} ({label} = {arr[i]!r}); "
                                 f"{int(bad.sum())} row(s) affected")
        dt = np.diff(t)
        bad = dt <= 0
        if bad.any():
            i = _bad_row(bad) + 1
            raise ValueError(f"{name}: times must be strictly increasing; row {i} has t = {t[i]:.9g} s "
                             f"after t = {t[i - 1]:.9g} s in row {i - 1}")
        if baseline not in (None, "linear"):
            raise ValueError(f"{name}: baseline must be None or 'linear', got {baseline!r}")
        self.t = t
        self.a = np.column_stack([ax, ay])
        self.baseline = baseline
        if baseline == "linear":
            v_end = self._integrate()[0][-1]
            self.a = self.a - v_end / (t[-1] - t[0])
        self.v_samples, self.d_samples = self._integrate()

    @staticmethod
    def _column(values, label: str) -> np.ndarray:
        try:
            arr = np.asarray(values, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise ValueError(f"{label} must be numbers, got {values!r}") from None
        return arr.copy()

    def _integrate(self) -> tuple[np.ndarray, np.ndarray]:
        """Velocities (trapezoidal) and displacements (exact for piecewise-linear a) at the samples."""
        h = np.diff(self.t)[:, None]
        a0, a1 = self.a[:-1], self.a[1:]
        dv = h * (a0 + a1) / 2
        v = np.vstack([np.zeros((1, 2)), np.cumsum(dv, axis=0)])
        dd = h * v[:-1] + h * h * (2 * a0 + a1) / 6
        d = np.vstack([np.zeros((1, 2)), np.cumsum(dd, axis=0)])
        return v, d

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_csv(cls, path, baseline: str | None = None, delimiter: str | None = None) -> "AccelerationHistory":
        """Read ``t, a_x[, a_y]`` [s, m/s^2] rows from a CSV file; a header line of non-numbers is skipped.

        Errors name the file and the line (1-based) of a row that cannot be read.
        """
        path = Path(path)
        text = path.read_text().splitlines()
        if delimiter is None:
            sample = next((line for line in text if line.strip() and not line.lstrip().startswith("#")), "")
            delimiter = ";" if ";" in sample else ("," if "," in sample else None)
        rows = []
        for lineno, line in enumerate(text, start=1):
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            cells = [c.strip() for c in (line.split(delimiter) if delimiter else line.split())]
            try:
                values = [float(c) for c in cells]
            except ValueError:
                if not rows:  # a header
                    continue
                raise ValueError(f"{path}: line {lineno} is not numbers: {line!r}") from None
            if len(values) not in (2, 3):
                raise ValueError(f"{path}: line {lineno} has {len(values)} columns, expected t, a_x[, a_y]")
            if rows and len(values) != len(rows[0]):
                raise ValueError(f"{path}: line {lineno} has {len(values)} columns, earlier lines {len(rows[0])}")
            rows.append(values)
        if not rows:
            raise ValueError(f"{path}: no samples")
        arr = np.array(rows)
        try:
            return cls(arr[:, 0], arr[:, 1], arr[:, 2] if arr.shape[1] == 3 else None, baseline=baseline,
                       name=str(path))
        except ValueError as err:
            raise ValueError(f"{err} (rows counted from 0 among the data lines)") from None

    @classmethod
    def sine_pulse(cls, amplitude: float, period: float, cycles: float = 1.0, direction=(1.0, 0.0),
                   start: float = 0.0, samples_per_cycle: int = 400, baseline: str | None = None
                   ) -> "AccelerationHistory":
        """``a(t) = A sin(2 pi (t - start) / T) d`` for ``cycles`` periods, sampled ``samples_per_cycle``
        per period (``A`` [m/s^2], ``T`` [s], ``d`` a direction). Whole cycles end with the base at rest."""
        n = max(2, int(math.ceil(samples_per_cycle * cycles)) + 1)
        s = np.linspace(0.0, cycles * period, n)
        a = amplitude * np.sin(2 * np.pi * s / period)
        d = np.asarray(direction, float)
        return cls(start + s, a * d[0], a * d[1], baseline=baseline, name=f"sine pulse {amplitude:g} m/s^2")

    @classmethod
    def rectangular_pulse(cls, amplitude: float, duration: float, direction=(1.0, 0.0), start: float = 0.0
                          ) -> "AccelerationHistory":
        """``a = A d`` for ``start <= t <= start + duration``, zero outside (two samples)."""
        d = np.asarray(direction, float)
        t = np.array([start, start + duration])
        return cls(t, amplitude * d[0] * np.ones(2), amplitude * d[1] * np.ones(2),
                   name=f"rectangular pulse {amplitude:g} m/s^2")

    # ------------------------------------------------------------------ evaluation
    @property
    def t_start(self) -> float:
        return float(self.t[0])

    @property
    def t_end(self) -> float:
        return float(self.t[-1])

    def _locate(self, t):
        t = np.asarray(t, dtype=np.float64)
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2)
        return t, i

    def acceleration(self, t) -> np.ndarray:
        """(..., 2) acceleration [m/s^2] at times ``t``: linear between samples, zero outside."""
        t, i = self._locate(t)
        h = self.t[i + 1] - self.t[i]
        w = ((t - self.t[i]) / h)[..., None]
        a = (1 - w) * self.a[i] + w * self.a[i + 1]
        inside = ((t >= self.t[0]) & (t <= self.t[-1]))[..., None]
        return np.where(inside, a, 0.0)

    def velocity(self, t) -> np.ndarray:
        """(..., 2) velocity [m/s]: exact integral of :meth:`acceleration` from ``t[0]``."""
        t, i = self._locate(t)
        s = np.clip(t - self.t[i], 0.0, None)[..., None]
        h = (self.t[i + 1] - self.t[i])[..., None]
        a0, a1 = self.a[i], self.a[i + 1]
        s = np.minimum(s, h)
        v = self.v_samples[i] + a0 * s + (a1 - a0) * s * s / (2 * h)
        v = np.where((t < self.t[0])[..., None], 0.0, v)
        return np.where((t > self.t[-1])[..., None], self.v_samples[-1], v)

    def displacement(self, t) -> np.ndarray:
        """(..., 2) displacement [m]: exact integral of :meth:`velocity` from ``t[0]``."""
        t, i = self._locate(t)
        h = (self.t[i + 1] - self.t[i])[..., None]
        s = np.minimum(np.clip(t - self.t[i], 0.0, None)[..., None], h)
        a0, a1 = self.a[i], self.a[i + 1]
        d = self.d_samples[i] + self.v_samples[i] * s + a0 * s * s / 2 + (a1 - a0) * s ** 3 / (6 * h)
        d = np.where((t < self.t[0])[..., None], 0.0, d)
        late = np.clip(t - self.t[-1], 0.0, None)[..., None]
        return np.where((t > self.t[-1])[..., None], self.d_samples[-1] + self.v_samples[-1] * late, d)

    def velocity_component(self, k: int) -> Callable[[float], float]:
        """``t -> v_k(t)`` [m/s] (k = 0: x, 1: y), a scalar function for ``prescribe_velocity(history=...)``."""
        if k not in (0, 1):
            raise ValueError(f"component must be 0 (x) or 1 (y), got {k!r}")
        t_arr, a, v_s = self.t, self.a, self.v_samples

        def v(time: float) -> float:
            if time <= t_arr[0]:
                return 0.0
            if time >= t_arr[-1]:
                return float(v_s[-1, k])
            i = int(np.searchsorted(t_arr, time, side="right")) - 1
            h = t_arr[i + 1] - t_arr[i]
            s = time - t_arr[i]
            return float(v_s[i, k] + a[i, k] * s + (a[i + 1, k] - a[i, k]) * s * s / (2 * h))

        return v

    def along(self, direction) -> np.ndarray:
        """(n,) the samples' acceleration component along the unit vector ``direction`` [m/s^2]."""
        d = np.asarray(direction, float)
        return self.a @ (d / np.linalg.norm(d))

    def __repr__(self) -> str:
        return (f"AccelerationHistory({self.name!r}, {len(self.t)} samples, t = {self.t[0]:g}..{self.t[-1]:g} s, "
                f"peak |a| = {np.abs(self.a).max():.4g} m/s^2, baseline={self.baseline!r})")


def shake_base(model, where, history: AccelerationHistory, components: str = "xy") -> np.ndarray:
    """Prescribe ``history``'s velocity on the nodes ``where`` selects (a group name, predicate or ids).

    Each component in ``components`` (``"x"``, ``"y"`` or ``"xy"``) becomes a velocity condition
    ``v_k = 1 m/s * history.velocity_component(k)(t)`` (:meth:`fdem.solve.model.Model.prescribe_velocity`);
    a component left out stays free. The base moves rigidly; the solver books its work on the
    model as ``boundary_work``. Returns the node ids.
    """
    if not components or set(components) - {"x", "y"}:
        raise ValueError(f"shake_base: components must be 'x', 'y' or 'xy', got {components!r}")
    nodes = None
    for k, c in enumerate("xy"):
        if c in components:
            kw = {"vx": 1.0} if k == 0 else {"vy": 1.0}
            nodes = model.prescribe_velocity(where, history=history.velocity_component(k),
                                             _what="shake_base", **kw)
    return nodes
