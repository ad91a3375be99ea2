"""Newmark displacement of a rigid-block mechanism under a base acceleration record.

The pseudo-static analysis (:func:`fdem.blocks.limit.yield_acceleration`) gives the yield
acceleration ``a_y = k_y g`` of the weakest mechanism along a direction ``d``. Newmark (1965):
the mechanism slips only while the drive ``a(t) = -a_base(t) . d`` (the inertial load on the
blocks, per unit mass, along ``d``) exceeds ``a_y``, and slips one way (the up-slope yield
acceleration of a slope mechanism is far larger than any record):

    s'' = a(t) - a_y   while sliding (s' > 0) or a(t) > a_y;   s' = 0 otherwise

integrated exactly for a drive linear between samples (the slip velocity is quadratic in time
there; stops at the root). ``s`` is the permanent displacement along ``d`` [m] of the rigid
mechanism, Newmark's figure for a slope.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from fdem.blocks.limit import Statics, YieldResult, yield_acceleration
from fdem.blocks.strength import Strength

__all__ = ["one_way_slip", "mechanism_newmark"]


def _first_root(v0: float, r: float, c: float, span: float) -> float | None:
    """Smallest ``s`` in ``(0, span]`` where ``v0 + r s + c s^2`` falls to zero, or None."""
    roots = []
    if abs(c) < 1e-300:
        if r < 0:
            roots = [-v0 / r]
    else:
        disc = r * r - 4 * c * v0
        if disc >= 0:
            sq = math.sqrt(disc)
            roots = [(-r - sq) / (2 * c), (-r + sq) / (2 * c)]
    roots = [s for s in roots if 1e-15 < s <= span]
    return min(roots) if roots else None


def one_way_slip(t, drive, a_y: float) -> tuple[np.ndarray, np.ndarray]:
    """Slip ``s(t)`` [m] and slip velocity [m/s] at the samples ``t`` (n,) [s] of a drive
    ``drive`` (n,) [m/s^2] linear between samples and zero after them, with yield
    acceleration ``a_y`` > 0 (module docstring); the last entry adds the slip after the
    record until the mechanism stops."""
    t, a = np.asarray(t, float), np.asarray(drive, float)
    if t.ndim != 1 or t.shape != a.shape or len(t) < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("one_way_slip: t and drive must be (n,) arrays, n >= 2, t strictly increasing")
    if not a_y > 0:
        raise ValueError(f"one_way_slip: the yield acceleration must be positive, got {a_y} m/s^2")
    v = d = 0.0
    ds, vs = [0.0], [0.0]
    for k in range(len(t) - 1):
        h = t[k + 1] - t[k]
        a0, slope = a[k] - a_y, (a[k + 1] - a[k]) / h
        s = 0.0
        while s < h:
            r = a0 + slope * s
            if v <= 0.0 and not (r > 0 or (r == 0 and slope > 0)):
                # stuck: wait for the drive to rise through a_y within this segment
                s_up = -a0 / slope if slope > 0 else math.inf
                if not (s < s_up < h):
                    break
                s, v = s_up, 0.0
                continue
            span = h - s
            stop = _first_root(v, r, slope / 2, span)
            dt = span if stop is None else stop
            d += v * dt + r * dt * dt / 2 + slope * dt ** 3 / 6
            v = 0.0 if stop is not None else v + r * dt + slope * dt * dt / 2
            s += dt
        ds.append(d)
        vs.append(v)
    if v > 0:  # after the record the mechanism decelerates at a_y
        ds[-1] = d + v * v / (2 * a_y)
        vs[-1] = 0.0
    return np.array(ds), np.array(vs)


def mechanism_newmark(st: Statics, strengths: Mapping[int, Strength], t, a_base,
                      direction=(-1.0, 0.0), g: float = 9.81) -> tuple[float, YieldResult]:
    """Permanent Newmark displacement [m] along ``direction`` of the weakest mechanism of the
    block system under the base acceleration ``a_base`` (n, 2) or (n,) (horizontal) [m/s^2] at
    times ``t`` (n,) [s], and the pseudo-static :class:`YieldResult` it rests on."""
    y = yield_acceleration(st, strengths, direction, g=g)
    a = np.asarray(a_base, float)
    if a.ndim == 1:
        a = np.column_stack([a, np.zeros_like(a)])
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    s, _ = one_way_slip(t, -(a @ d), y.acceleration)
    return float(s[-1]), y
