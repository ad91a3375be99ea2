"""Density scaling of quasi-static stages: node masses chosen so that the stiffest springs stop setting the step.

In a damped stage (equilibrium, a strength-reduction step, a factor-of-safety trial, a gravity
increase) inertia is not part of the answer: only the state the stage settles in is. The
step of an FDEM slope is set by a few light nodes on stiff crack and contact penalties (on
the 180,000-triangle four-slope model the tangential crack penalty is about 280 times the
rock's stiffness over an element), so most of the steps of a quasi-static stage are spent on
them. Density scaling (FLAC and 3DEC's "density scaling", Cundall 1982; Itasca's partial
scaling) gives those nodes more inertial mass and keeps the rest:

* every node ``i`` needs ``m_i >= S_i dt^2 / 4`` to be stable at a step ``dt``, where ``S_i``
  [N/m] sums the stiffness shares of everything acting on it (:func:`nodal_stiffness`): its
  triangles' ``m_t omega_t^2`` (exact element frequency), the crack springs'
  ``2 sum k`` and contact's per-triangle bound. By Irons' theorem (the largest eigenvalue of
  ``M^-1 K`` is at most the largest element eigenvalue when element masses add up to the
  nodal ones; Irons 1970, Belytschko et al. 2014 sec. 6.3) the whole model is then stable;
* :func:`scaled_critical_step` finds the largest critical step whose added mass
  ``sum max(0, S dt^2/4 - m)`` stays within a budget (default 1 % of the model's mass), in
  closed form over the sorted node thresholds;
* :func:`inertial_masses` gives the scaled masses ``m' = max(m, S dt^2 / 4)``.

Gravity keeps acting on the real masses (``m a' = f + m g`` becomes ``m' a = f + m g``): the
loads, the unbalanced-force ratio and therefore the equilibrium reached are those of the real
slope; only how the stage gets there changes. The scaled system is a consistent mechanical
system, so its ledger closes with its own kinetic energy ``1/2 m' v^2``; switching the masses at
fixed velocities books the kinetic-energy jump as ``mass_change_work``
(:class:`fdem.solve.ledger.EnergyLedger`). Dynamic stages (runout, shaking) keep the real masses.

The slope's response time grows with its mass: a stage run on scaled masses stretches its time
rules by :func:`period_stretch`, ``sqrt(sum m' / sum m)`` (the fundamental period of a mode
that moves the whole mass alike), so a stage converges or fails in the same number of response
times.
"""
from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_MASS_BUDGET", "triangle_nodal_stiffness", "nodal_stiffness", "scaled_critical_step",
           "inertial_masses", "period_stretch"]


DEFAULT_MASS_BUDGET = 0.01
"""Added inertial mass of a density-scaled stage, as a fraction of the model's mass: on the
180k four-slope model the critical step is 8.3 us at 0.1 %, 9.35 us at 1 % and 10.2 us at 5 %,
against 3.40 us unscaled (``docs/benchmarks.md``); 1 % keeps the fundamental period within 0.5 %."""


def triangle_nodal_stiffness(model) -> np.ndarray:
    """(n_nodes,) triangles' stiffness shares ``S = sum_t m_t omega_t^2`` [N/m]: ``m_t = rho A / 3``
    the triangle's lumped mass at the node and ``omega_t = 2 / dt_t`` its exact highest element
    frequency (:meth:`fdem.solve.model.Model.triangle_critical_dt`)."""
    topo = model.topology
    share = model.property_array("density") * np.abs(topo.triangle_area0) / 3.0
    omega2 = (2.0 / model.triangle_critical_dt()) ** 2
    s = np.zeros(model.n_nodes)
    np.add.at(s, topo.triangles.ravel(), np.repeat(share * omega2, 3))
    return s


def nodal_stiffness(model, providers, mass: np.ndarray, triangles: np.ndarray | None = None) -> np.ndarray:
    """(n_nodes,) stiffness ``S_i`` [N/m] every node must carry mass for (module docstring):
    the triangles' shares (``triangles``, or :func:`triangle_nodal_stiffness` when not given:
    it does not change, a simulation computes it once) plus the providers'
    (:func:`provider_stiffness`)."""
    s = (triangle_nodal_stiffness(model) if triangles is None else triangles).copy()
    return s + provider_stiffness(providers, mass)


def provider_stiffness(providers, mass: np.ndarray) -> np.ndarray:
    """(n_nodes,) stiffness [N/m] the force ``providers`` put on each node: each one's
    ``nodal_stiffness(mass)``; a provider with only a ``stable_dt(mass)`` counts as
    ``m (2 / dt_p)^2`` on every node (its bound applies to the real masses); one with neither
    adds no stiffness."""
    s = np.zeros(np.shape(mass), dtype=np.float64)
    for p in providers:
        fn = getattr(p, "nodal_stiffness", None)
        if fn is not None:
            s = s + np.asarray(fn(mass), dtype=np.float64)
            continue
        fn = getattr(p, "stable_dt", None)
        if fn is not None:
            dt_p = float(fn(mass))
            if np.isfinite(dt_p):
                s = s + mass * (2.0 / dt_p) ** 2
    return s


def scaled_critical_step(mass: np.ndarray, stiffness: np.ndarray, budget: float = DEFAULT_MASS_BUDGET) -> float:
    """The largest critical step ``dt`` [s] whose added mass ``sum max(0, S dt^2/4 - m)`` is at
    most ``budget * sum m`` (``budget >= 0``).

    With ``q = dt^2`` the added mass is piecewise linear in ``q``, with a kink at each node's
    threshold ``r_i = 4 m_i / S_i`` (the step it is stable at unscaled); sorting the thresholds
    solves it exactly. ``budget = 0`` gives the unscaled nodal bound ``min 2 sqrt(m / S)``."""
    if not budget >= 0.0:
        raise ValueError(f"added-mass budget must be >= 0, got {budget!r}")
    mass = np.asarray(mass, dtype=np.float64)
    stiffness = np.asarray(stiffness, dtype=np.float64)
    loaded = stiffness > 0.0
    if not loaded.any():
        return float("inf")
    m, s = mass[loaded], stiffness[loaded]
    order = np.argsort(4.0 * m / s, kind="stable")
    r = (4.0 * m / s)[order]
    cum_s = np.cumsum(s[order]) / 4.0  # added(q) = cum_s[k] q - cum_m[k] for r[k] <= q < r[k+1]
    cum_m = np.cumsum(m[order])
    allowed = budget * float(mass.sum())
    # the largest q in each interval [r[k], r[k+1]) allowed by the budget
    q = (allowed + cum_m) / cum_s
    upper = np.append(r[1:], np.inf)
    fits = q >= r  # the budget reaches into interval k
    k = int(np.flatnonzero(fits)[-1]) if fits.any() else 0
    return float(np.sqrt(min(q[k], upper[k]) if fits.any() else r[0]))


def inertial_masses(mass: np.ndarray, stiffness: np.ndarray, dt_critical: float) -> np.ndarray:
    """(n_nodes,) scaled masses ``m' = max(m, S dt^2 / 4)`` [kg/m]: stable at ``dt_critical``."""
    return np.maximum(np.asarray(mass, dtype=np.float64), np.asarray(stiffness) * (0.25 * dt_critical ** 2))


def period_stretch(mass: np.ndarray, inertia: np.ndarray) -> float:
    """``sqrt(sum m' / sum m)`` [-]: how much longer the scaled model's fundamental period is
    (exact for a mode that moves all the mass alike; with a budget of 1 % it is at most 1.005)."""
    return float(np.sqrt(np.sum(inertia) / np.sum(mass)))
