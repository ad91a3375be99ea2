"""Loops of region sleeping (numba): how much the nodes of a region move, which sleeping nodes
feel a changed force, and the frozen energies of a sleeping region.

A *region* is ``region_size`` consecutive triangles of an exploded mesh (triangles are numbered
along a Hilbert curve, :mod:`fdem.mesh.order`, so consecutive triangles form a compact patch);
node ``3t + k`` is corner ``k`` of triangle ``t``. The host is :mod:`fdem.solve.sleeping`.

The laws are two comparisons, written once as scalar functions:

* :func:`node_drifted`: a node has left its rest when it is farther than ``delta`` [m] from the
  position it had when the region's quiet window began: ``|x - x_ref|^2 > delta^2``. A node
  that rings about a rest position (elastic waves of amplitude below ``delta``) stays at rest;
  one that creeps or accelerates leaves it;
* :func:`force_changed`: a sleeping node wakes when its interaction force (crack elements and
  contact) differs from the one it fell asleep with by more than a tolerance:
  ``|f - f_sleep|^2 > f_tol^2`` [N/m], tested on the force of each step (an impact) and on its
  mean over the steps since the last check (a load that persists).
"""
from __future__ import annotations

from numba import njit
from fdem.kernels.triangles import FASTMATH, TC_MASS, triangle_response

__all__ = ["node_drifted", "force_changed", "region_drift", "changed_force_regions", "persistent_force_regions",
           "region_sums"]


@njit(fastmath=FASTMATH, cache=True, inline="always")
def node_drifted(x, y, xr, yr, delta2):
    """True when ``(x, y)`` lies farther than ``sqrt(delta2)`` [m] from the rest position ``(xr, yr)``."""
    dx = x - xr
    dy = y - yr
    return dx * dx + dy * dy > delta2


@njit(fastmath=FASTMATH, cache=True, inline="always")
def force_changed(fx, fy, bx, by, f_tol2):
    """True when the force ``(fx, fy)`` differs from ``(bx, by)`` by more than ``sqrt(f_tol2)`` [N/m]."""
    dx = fx - bx
    dy = fy - by
    return dx * dx + dy * dy > f_tol2


@njit(cache=True)
def region_drift(x, x_ref, regions, region_size, n_tri, delta2, restart, quiet):
    """The quiet test of regions ``regions[k]``: ``quiet[k] = True`` when no node of the region has
    drifted from ``x_ref`` (:func:`node_drifted`). A region with ``restart[k]``, or one that has
    drifted, starts a new quiet window: ``x_ref`` of its nodes is set to ``x`` (and ``quiet[k]``
    is True for a restart, False for a drift)."""
    for k in range(regions.shape[0]):
        r = regions[k]
        lo = 3 * r * region_size
        hi = 3 * min(n_tri, (r + 1) * region_size)
        ok = True
        if not restart[k]:
            for i in range(lo, hi):
                if node_drifted(x[i, 0], x[i, 1], x_ref[i, 0], x_ref[i, 1], delta2):
                    ok = False
                    break
        if restart[k] or not ok:
            for i in range(lo, hi):
                x_ref[i, 0] = x[i, 0]
                x_ref[i, 1] = x[i, 1]
        quiet[k] = ok


@njit(cache=True)
def changed_force_regions(f, f_base, nodes, f_tol2, region_size, f_sum, wake):
    """Mark ``wake[r] = True`` for the region ``r`` of every node of ``nodes`` whose force ``f``
    has changed from ``f_base`` (:func:`force_changed`; ``f_tol2`` (n_nodes,) squared
    tolerances), and add the change into ``f_sum`` (for :func:`persistent_force_regions`).
    Returns how many nodes changed."""
    n = 0
    for k in range(nodes.shape[0]):
        i = nodes[k]
        f_sum[i, 0] += f[i, 0] - f_base[i, 0]
        f_sum[i, 1] += f[i, 1] - f_base[i, 1]
        if force_changed(f[i, 0], f[i, 1], f_base[i, 0], f_base[i, 1], f_tol2[i]):
            wake[i // (3 * region_size)] = True
            n += 1
    return n


@njit(cache=True)
def persistent_force_regions(f_sum, n_steps, nodes, f_tol2, region_size, wake):
    """Mark ``wake[r] = True`` for the region of every node whose mean force change
    ``f_sum / n_steps`` exceeds its tolerance (:func:`force_changed` against zero), and reset
    ``f_sum`` of ``nodes``. Returns how many nodes changed."""
    n = 0
    inv = 1.0 / max(n_steps, 1)
    for k in range(nodes.shape[0]):
        i = nodes[k]
        if force_changed(f_sum[i, 0] * inv, f_sum[i, 1] * inv, 0.0, 0.0, f_tol2[i]):
            wake[i // (3 * region_size)] = True
            n += 1
        f_sum[i, 0] = 0.0
        f_sum[i, 1] = 0.0
    return n


@njit(cache=True)
def region_sums(x, tc, regions, region_size, n_tri, gx, gy, f_ext, use_ext, out):
    """Frozen state energies of regions: ``out[k] = (strain energy, sum m g . x, sum f_ext . x)``
    [J/m] over the triangles of ``regions[k]`` (the terms :class:`fdem.kernels.stepping.StepSums`
    sums for stepped triangles; velocities zero, as a sleeping region's are)."""
    for k in range(regions.shape[0]):
        r = regions[k]
        strain = 0.0
        gmom = 0.0
        emom = 0.0
        for t in range(r * region_size, min(n_tri, (r + 1) * region_size)):
            i = 3 * t
            res = triangle_response(tc, t, x[i, 0], x[i, 1], x[i + 1, 0], x[i + 1, 1], x[i + 2, 0], x[i + 2, 1],
                                    0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False)
            strain += res[6]
            m = tc[t, TC_MASS]
            for j in range(i, i + 3):
                gmom += m * (gx * x[j, 0] + gy * x[j, 1])
                if use_ext:
                    emom += f_ext[j, 0] * x[j, 0] + f_ext[j, 1] * x[j, 1]
        out[k, 0] = strain
        out[k, 1] = gmom
        out[k, 2] = emom
