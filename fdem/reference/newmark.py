"""Newmark's sliding block, the closed form a shaken block is checked against.

A rigid block on a plane inclined at ``theta`` with friction angle ``phi`` slides down-slope
while the base acceleration exceeds the yield acceleration ``a_y = g sin(phi - theta) / cos(phi)``
(Newmark 1965); :func:`newmark_response` integrates the relative motion piecewise exactly for a
piecewise-linear base acceleration."""
from __future__ import annotations

import math
import numpy as np

__all__ = ["yield_acceleration", "newmark_response", "newmark_displacement", "rectangular_pulse_displacement"]


# ---------------------------------------------------------------------------- Newmark
def yield_acceleration(theta_deg: float, phi_deg: float, g: float = 9.81) -> tuple[float, float]:
    """Along-plane yield accelerations ``(a_y, a_u)`` [m/s^2] of a rigid block on a plane at ``theta``
    with friction ``phi``: ``a_y = g (cos theta tan phi - sin theta)`` (down-slope slip),
    ``a_u = g (cos theta tan phi + sin theta)`` (up-slope slip)."""
    th = math.radians(theta_deg)
    mu = math.tan(math.radians(phi_deg))
    return g * (math.cos(th) * mu - math.sin(th)), g * (math.cos(th) * mu + math.sin(th))


def _first_crossing(v0: float, r: float, c: float, span: float) -> float | None:
    """Smallest ``s`` in ``(0, span]`` where ``v0 + r s + c s^2`` reaches zero, or None."""
    if abs(c) < 1e-300:
        roots = [-v0 / r] if r != 0.0 else []
    else:
        disc = r * r - 4 * c * v0
        if disc < 0:
            return None
        q = -0.5 * (r + math.copysign(math.sqrt(disc), r))
        roots = [q / c, v0 / q] if q != 0.0 else [0.0]
    roots = [s for s in roots if 0.0 < s <= span]
    return min(roots) if roots else None


def _slide_segments(segments, ay: float, au: float):
    """Integrate the block over segments ``(t0, t1, a0, a1)`` of a linear drive; yield ``(t1, d, v, stop)``."""
    v = d = 0.0
    for t0, t1, a0, a1 in segments:
        h = t1 - t0
        stop = None
        if h <= 0:
            yield t1, d, v, stop
            continue
        slope = (a1 - a0) / h
        s = 0.0
        while s < h:
            a_now = a0 + slope * s
            if v == 0.0:  # stuck: slides once the drive leaves [-au, ay]
                if a_now > ay or (a_now == ay and slope > 0):
                    sign = 1.0
                elif a_now < -au or (a_now == -au and slope < 0):
                    sign = -1.0
                else:
                    target = ay if slope > 0 else (-au if slope < 0 else None)
                    s_next = (target - a0) / slope if target is not None else h
                    s = h if not (s < s_next < h) else s_next
                    continue
            else:
                sign = 1.0 if v > 0 else -1.0
            r = a_now - (ay if sign > 0 else -au)  # slip acceleration at s, growing by `slope`
            tau = _first_crossing(v, r, slope / 2, h - s)
            span = h - s if tau is None else tau
            d += v * span + r * span * span / 2 + slope * span ** 3 / 6
            v = 0.0 if tau is not None else v + r * span + slope * span * span / 2
            if tau is not None:
                stop = t0 + s + tau
            s += span
        yield t1, d, v, stop


def newmark_response(t, a_base, theta_deg: float, phi_deg: float, g: float = 9.81, t_eval=None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slip ``d(t)`` [m] and slip velocity ``v(t)`` [m/s] of Newmark's rigid block (module docstring).

    ``t`` (n,) [s] strictly increasing, ``a_base`` (n,) [m/s^2] the base acceleration along the
    plane, positive down the slope, linear between samples and zero outside ``[t_0, t_n]``.
    Slip is down-slope positive, relative to the base, zero at ``t_0``. Integrated exactly
    segment by segment (quadratic velocity, stopping times from the quadratic's roots).
    ``t_eval`` (m,) [s]: where to report; default the samples and the time the block comes to
    rest after the record. Returns ``(t_eval, d, v)``.
    """
    t = np.asarray(t, float)
    a = -np.asarray(a_base, float)  # driving acceleration in the base frame
    if t.ndim != 1 or t.shape != a.shape or len(t) < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("newmark_response: t and a_base must be (n,) arrays, n >= 2, t strictly increasing")
    ay, au = yield_acceleration(theta_deg, phi_deg, g)
    if ay <= 0:
        raise ValueError(f"newmark_response: phi = {phi_deg} deg <= theta = {theta_deg} deg: the block slides "
                         f"under gravity alone (a_y = {ay:.4g} m/s^2)")
    te = None if t_eval is None else np.asarray(t_eval, float).ravel()
    cuts = t if te is None else np.union1d(t, te[(te > t[0]) & (te < t[-1])])
    ac = np.interp(cuts, t, a)
    segments = list(zip(cuts[:-1], cuts[1:], ac[:-1], ac[1:]))
    # after the record the drive is zero; any slip left decays at a_y (or a_u) within vmax / min(ay, au)
    vmax = float(np.sum(np.abs(np.diff(t)) * (np.abs(a[:-1]) + np.abs(a[1:])) / 2))
    t_far = t[-1] + 2 * vmax / min(ay, au) + 1e-9
    after = np.array([t[-1], t_far]) if te is None else np.union1d([t[-1], t_far], te[te > t[-1]])
    segments += [(p, q, 0.0, 0.0) for p, q in zip(after[:-1], after[1:])]
    times, ds, vs = [t[0]], [0.0], [0.0]
    stop_after = None
    for t1, d, v, stop in _slide_segments(segments, ay, au):
        times.append(t1)
        ds.append(d)
        vs.append(v)
        if stop is not None and stop >= t[-1]:
            stop_after = (stop, d)
    times, ds, vs = np.array(times), np.array(ds), np.array(vs)
    if te is None:
        keep = times <= t[-1]
        out_t, out_d, out_v = times[keep], ds[keep], vs[keep]
        if stop_after is not None and stop_after[0] > t[-1]:
            out_t = np.append(out_t, stop_after[0])
            out_d = np.append(out_d, stop_after[1])
            out_v = np.append(out_v, 0.0)
        return out_t, out_d, out_v
    idx = np.clip(np.searchsorted(times, te, side="right") - 1, 0, len(times) - 1)
    before = te < t[0]
    return te, np.where(before, 0.0, ds[idx]), np.where(before, 0.0, vs[idx])


def newmark_displacement(t, a_base, theta_deg: float, phi_deg: float, g: float = 9.81) -> float:
    """Permanent down-slope slip [m] of Newmark's rigid block under ``a_base(t)`` (see :func:`newmark_response`),
    after the record ends and the block has stopped."""
    _, d, _ = newmark_response(t, a_base, theta_deg, phi_deg, g)
    return float(d[-1])


def rectangular_pulse_displacement(a_p: float, t_p: float, a_y: float) -> float:
    """Closed form ``d = a_p t_p^2 (a_p - a_y) / (2 a_y)`` [m] for a drive ``a_p > a_y`` lasting ``t_p``
    (zero when ``a_p <= a_y``); the drive is ``-a_b``, the base accelerating up the slope."""
    return 0.0 if a_p <= a_y else a_p * t_p * t_p * (a_p - a_y) / (2 * a_y)
