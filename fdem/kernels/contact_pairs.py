"""Numba kernels for triangle-triangle contact: the pair law and the pair forces (narrow phase).

The broad phase (boxes, binned grid) is :mod:`fdem.kernels.contact_search`.

Narrow phase: the distributed-potential penalty method of Munjiza & Andrews (2000), "Penalty
function method for combined finite-discrete element systems comprising large number of separate
bodies", IJNME 49:1377-1396; Munjiza (2004), *The Combined Finite-Discrete Element Method*, ch. 3.

Potential of a triangle (dimensionless)
---------------------------------------
With barycentric coordinates ``lambda_k(x) = 1/3 + b_k . (x - G)`` of the current triangle
(``lambda_k`` belongs to corner ``k``, ``G`` is the centroid, ``b_k = rot(P_{k+1} - P_{k+2}) / 2A``
the inward normal of the edge opposite ``k`` divided by the altitude on it)::

    phi(x) = 3 min_k lambda_k(x)          (0 on the boundary, 1 at the centroid)

``phi`` is linear on each of the three sub-triangles ``S_k = (G, P_{k+1}, P_{k+2})`` where
``lambda_k`` is the smallest, with gradient ``3 b_k``.

Pair energy and forces
----------------------
For two triangles ``c`` and ``t`` with overlap ``D = Omega_c  cap  Omega_t`` and penalty ``p`` [Pa]::

    E = p * integral_D (phi_c + phi_t) dA                     [J/m, per unit thickness]

Translating ``c`` rigidly, ``-dE/du`` is exactly the Munjiza-Andrews resultant
``f_c = p * integral_D grad(phi_c - phi_t) dA = p * oint_dD (phi_c - phi_t) n dGamma``
(``n`` the outward normal of ``D``). The nodal forces are the exact gradient of ``E`` with
respect to the six corner positions (shape derivative, ``delta x = sum_i lambda_i delta x_i``)::

    F_i^c = -dE/dx_i^c = p [ sum_k 3 b_k^c integral_{S_k^c cap Omega_t} lambda_i^c dA
                             - integral_{dOmega_c cap Omega_t} phi_t lambda_i^c n_c dGamma ]

and symmetrically for ``t``. So the contact is conservative (a potential exists for all nodal
motions, not only rigid ones), ``sum F = 0`` and ``sum x x F = 0`` exactly (``E`` is invariant
under rigid motions of the pair), and the force is zero when the triangles do not overlap.

Evaluation (all integrals exact)
--------------------------------
1. Separating-axis test on the six edges with orientation determinants of raw coordinate
   differences, ``2A_t lambda^t_j(x) = (P^t_{j+1} - x) x (P^t_{j+2} - x)``, in strict
   arithmetic: exact zeros for corners lying on an edge of the other triangle (touching
   counts as apart). Most candidate pairs of a settled pile end here after 18 differences
   and 18 determinants, inlined in the pair loop (no call, no reference counting).
   Round-off slivers count as touching too: the pair is skipped unless ``c`` reaches past
   every edge line of ``t`` by more than ``TOUCH_EPS = 1e-12`` of the altitude on it
   (``max_i u_ij > TOUCH_EPS 2A_t`` for each ``j``) and ``t`` past every edge line of ``c``
   likewise (``max_k v_kj > TOUCH_EPS 2A_c``). Bound on what a skipped pair would have carried: if
   ``max_i lambda^t_j(c_i) <= eps`` then ``D`` lies in the strip ``0 <= lambda^t_j <= eps`` of
   ``t``, so ``area(D) <= 2 eps A_t``, ``phi_t <= 3 eps`` on ``D`` and ``phi_c <= 3 eps h_t / h_c``
   on ``t``'s boundary inside ``c``; hence ``E <= 2 eps p A_t (1 + 3 eps)`` and every nodal force
   is ``O(eps p L max(1, h_t / h_c))``, the force of a flat overlap ``eps h`` deep (about
   ``1e-13`` m for metre-size triangles: far below the physical overlaps ``F / p``). Dropping
   it makes ``E`` jump by at most that bound when the reach crosses the threshold; such a pair
   is treated as separated (its friction history is dropped, as for any pair that separates,
   with the spring's stored energy, at most ``(mu F_n)^2 / 2k_t``, booked as dissipated). In a
   settled pile more than half the "overlapping" neighbour pairs are such slivers (corners
   and edges that coincide up to round-off).
2. Overlap polygon ``D``: ``c`` clipped by the half-planes of ``t`` that cut one of ``c``'s
   corners off (Sutherland-Hodgman on a pool of vertices referenced by index, so a kept
   corner costs one index copy). Each corner carries
   both triangles' barycentrics (interpolated: exact, they are affine); each edge of ``D``
   carries a *label*, the triangle edge it lies on (``c``'s edge ``m`` or ``t``'s edge ``j``).
   An evaluation of the same law from the overlap's edges, without the polygon, was 5 % faster
   on a compressed block but 10-15 % slower on the slivers of a settled pile
   (``docs/benchmarks.md``); it lives in ``tests/unit/contact_oracle.py`` as an independent check of
   the clipping (``tests/unit/test_contact_kernel.py``).
3. Area terms by parts. ``grad phi_q = 3 b_k`` on ``S_k``, ``grad lambda_i = b_i``, so
   ``3 sum_k b_k int_{D cap S_k} lambda_i dA = int_D grad(phi_q) lambda_i dA
   = oint_dD phi_q lambda_i n dGamma - b_i int_D phi_q dA``, and ``phi_q = 0`` on ``q``'s own
   boundary: only the edges of ``D`` on the *other* triangle's boundary contribute. With
   ``lambda_i(x) = 1/3 + b_i . (x - G)`` all nodal forces of a pair reduce to two sums over
   the edges ``a -> b = a + d`` of ``D`` (``s = -1`` on ``c``'s edges, ``+1`` on ``t``'s,
   ``n dGamma = (dy, -dx) ds``, ``f = max(min_k lambda^q_k, 0)`` of the triangle ``q`` that
   does not own the edge, ``I_f = int_0^1 f ds``, ``I_fs = int_0^1 f s ds``)::

       N = sum s n I_f,     T = sum s n (x) (a I_f + d I_fs)        (a about c's centroid)
       F_i^c = 3p (N / 3 + T b_i^c) - p b_i^c int_D phi_c dA
       F_i^t = 3p (-N / 3 + (N (x) G_t - T) b_i^t) - p b_i^t int_D phi_t dA

   and the energy from fans: ``phi_q`` is linear on the fan ``(G_q, u, w)`` of a piece of an
   edge inside one sector, so ``int_D phi_q dA = area(D) / 3 + sum (a - G_q) x d I_f`` over
   the other triangle's edges. ``f`` is linear between the kinks of ``min_k lambda^q_k``
   along an edge (at most two: the argmin visits each index once), so ``I_f`` and ``I_fs``
   are exact (trapezoids; ``h (2 f_u u + f_u w + f_w u + 2 f_w w) / 6`` per piece).

Parallelism
-----------
Pairs come sorted by their first triangle ``i`` (the contactor ``c``), and the pair loop is cut
into chunks at changes of ``i``: a chunk owns its contactors, so it adds their forces straight
into ``f`` (summed over consecutive pairs in registers). The target side is stored per pair (six
numbers) and gathered per triangle afterwards (a triangle writes only its own nodes), so there
are no races and the forces are bitwise independent of the thread count (the chunking depends
on the pair list only). Below ``PARALLEL_MIN_PAIRS`` pairs the per-step kernels run serially.

Units: coordinates [m], penalty [Pa], forces [N/m], energies [J/m] (plane, per unit thickness).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from fdem.kernels.triangles import FASTMATH

__all__ = ["N_OUT", "N_WORK", "MAX_VERT", "N_COL", "N_HIST", "FASTMATH", "TOUCH_EPS", "CLOSE_TOL",
           "PARALLEL_MIN_PAIRS", "N_IWORK", "pair_normal", "tangential_law", "chunk_bounds", "pair_forces",
           "overlap_areas", "gather_forces", "target_incidence", "carry_history", "lower_bound", "pair_constants_one",
           "pair_constants", "crack_friction", "crack_between", "carry_row", "carry_history_one", "FROM_FACES",
           "facing_face", "pair_friction"]


N_OUT = 12
"""Nodal forces of a pair written by :func:`pair_normal` to ``w[0:12]``: on c's corners
(x0, y0, x1, y1, x2, y2) [N/m], then on t's corners."""


N_WORK = N_OUT
"""Length of the float work vector of :func:`pair_normal`."""


MAX_VERT = 16
"""Vertex pool of the overlap polygon: 3 corners + at most 2 + 4 + 6 new ones (two per pass for
a convex polygon; the bound also covers round-off on degenerate ones)."""


N_COL = 8


FROM_FACES = -1.0
"""Base friction of a pair that takes it from the two faces in touch (:func:`pair_friction`):
every pair but those across a broken crack element, which keep that element's friction."""


N_HIST = 10
"""Per-pair history row: tangential spring force (x, y) [N/m], damping force (x, y) [N/m], and
the barycentric weights of the point they were applied at, in c (3) and in t (3)."""


"""Columns of a polygon vertex: x, y (frame at c's centroid), t's three, c's three barycentrics."""


# FASTMATH (imported above): the triangle kernels' flags, one set for both, so that fresh and
# cached machine code agree (no ``reassoc``) and NaNs still propagate (no ``nnan``/``ninf``).
# The separating-axis determinants (:func:`_sat`) are compiled strictly, so that touching
# corners give exact zeros (no fused multiply-add).


TOUCH_EPS = 1e-12
"""Relative reach below which a pair counts as touching, not overlapping (see :func:`_sat`):
round-off slivers of settled neighbours skip the narrow phase (bound in the module docstring)."""


CLOSE_TOL = 1e-9
"""Relative gap (to the perimeter) above which the edge parts of an overlap do not close and the
pair is evaluated by clipping instead (see :func:`_overlap`)."""


PARALLEL_MIN_PAIRS = 4096
"""Below this many candidate pairs the per-step kernels run serially: waking the thread pool
costs more than the work (and far more on a loaded machine, where OpenMP workers spin)."""


# Layout of the int work vector (offsets; no array views in the hot path): two index lists
# (ping-pong between clipping passes) at 0 and MAX_VERT, their edge labels at _L0 and
# _L0 + MAX_VERT. Label of the edge ending at a vertex: m < 3 c's edge opposite corner m,
# 3 + j t's edge opposite corner j.
_L0 = 2 * MAX_VERT


N_IWORK = 4 * MAX_VERT


# ----------------------------------------------------------------------------- geometry helpers
@njit(cache=True, error_model="numpy", inline="always")
def _orient(ux, uy, wx, wy):
    """``u x w``; with ``u = P_{j+1} - x``, ``w = P_{j+2} - x`` it is ``2A lambda_j(x)``."""
    return ux * wy - uy * wx


@njit(cache=True, error_model="numpy", inline="always")
def _max3(a, b, c):
    return max(a, max(b, c))


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _clip(pool, nv, iw, src, dst, lsrc, ldst, n, col, label_new):
    """Sutherland-Hodgman on indices: keep the part of the polygon ``iw[src:src+n]`` (vertex ids
    into ``pool``; ``iw[lsrc + e]`` labels the edge ending at vertex ``e``) where column ``col``
    is ``>= 0``; new vertices are appended to ``pool`` from ``nv`` on, interpolated in every
    column (exact 0 in ``col``), and the new edge along the clipping line gets ``label_new``.
    Returns ``(n_out, nv)``.
    """
    m = 0
    p = iw[src + n - 1]
    dp = pool[p, col]
    for e in range(n):
        i = iw[src + e]
        dq = pool[i, col]
        pin = dp >= 0.0
        qin = dq >= 0.0
        if pin != qin:
            s = dp / (dp - dq)
            for r in range(N_COL):
                pool[nv, r] = pool[p, r] + s * (pool[i, r] - pool[p, r])
            pool[nv, col] = 0.0
            iw[dst + m] = nv
            iw[ldst + m] = iw[lsrc + e] if pin else label_new
            nv += 1
            m += 1
        if qin:
            iw[dst + m] = i
            iw[ldst + m] = iw[lsrc + e]
            m += 1
        p = i
        dp = dq
    return m, nv


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _pick(k, v0, v1, v2):
    return v0 if k == 0 else (v1 if k == 1 else v2)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _kinks(l0, l1, l2, d0, d1, d2):
    """Where ``min_j (l_j + s d_j)``, ``s in [0, 1]``, changes its argmin.

    The set where one coordinate is the smallest is convex, so the argmin along a segment
    visits each index at most once: equal argmins at both ends mean one piece; otherwise the
    two end indices cross once, unless the third is smaller there (then two kinks).
    Returns ``(s1, s2, k_first, k_middle, k_last)``: pieces ``[0, s1]``, ``[s1, s2]``,
    ``[s2, 1]`` (some possibly empty) with those argmins (all three valid indices).
    """
    ka = 0
    va = l0
    if l1 < va:
        ka = 1
        va = l1
    if l2 < va:
        ka = 2
    e0 = l0 + d0
    e1 = l1 + d1
    e2 = l2 + d2
    kb = 0
    vb = e0
    if e1 < vb:
        kb = 1
        vb = e1
    if e2 < vb:
        kb = 2
    if ka == kb:
        return 1.0, 1.0, ka, ka, ka
    la = _pick(ka, l0, l1, l2)
    da = _pick(ka, d0, d1, d2)
    lb = _pick(kb, l0, l1, l2)
    db = _pick(kb, d0, d1, d2)
    km = 3 - ka - kb
    lm = _pick(km, l0, l1, l2)
    dm = _pick(km, d0, d1, d2)
    # (coincident lines, a zero denominator, can only happen on an empty middle piece)
    den = da - db
    s = min(max((lb - la) / den, 0.0), 1.0) if den != 0.0 else 0.5
    if lm + s * dm >= la + s * da:
        return s, s, ka, km, kb
    den = da - dm
    s1 = min(max((lm - la) / den, 0.0), 1.0) if den != 0.0 else 0.0
    den = dm - db
    s2 = min(max((lb - lm) / den, s1), 1.0) if den != 0.0 else s1
    return s1, s2, ka, km, kb


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _fmin(s, l0, l1, l2, d0, d1, d2):
    """``max(min_k (l_k + s d_k), 0)``: the (clamped) smallest barycentric at ``a + s d``."""
    return max(min(l0 + s * d0, min(l1 + s * d1, l2 + s * d2)), 0.0)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _edge_integrals(pool, a, b, lq):
    """``(int_0^1 f ds, int_0^1 f s ds)`` along the overlap edge ``a -> b`` of
    ``f = max(min_k lambda^q_k, 0)``, ``lambda^q`` in columns ``lq:lq+3`` of ``pool``
    (:func:`_line_integrals` of the values at ``a`` and their change to ``b``)."""
    l0 = pool[a, lq]
    l1 = pool[a, lq + 1]
    l2 = pool[a, lq + 2]
    return _line_integrals(l0, l1, l2, pool[b, lq] - l0, pool[b, lq + 1] - l1, pool[b, lq + 2] - l2)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _line_integrals(l0, l1, l2, d0, d1, d2):
    """``(int_0^1 f ds, int_0^1 f s ds)`` of ``f(s) = max(min_k (l_k + s d_k), 0)``.

    ``f`` is linear between the kinks ``0 <= s1 <= s2 <= 1`` of the minimum, so both integrals
    are exact: trapezoids for ``int f``, ``h (2 f_u u + f_u w + f_w u + 2 f_w w) / 6`` for
    ``int f s`` on a piece ``[u, w]`` of length ``h``.
    """
    s1, s2, k1, k2, k3 = _kinks(l0, l1, l2, d0, d1, d2)
    f0 = max(min(l0, min(l1, l2)), 0.0)
    f3 = _fmin(1.0, l0, l1, l2, d0, d1, d2)
    if k1 == k3:   # one piece
        return 0.5 * (f0 + f3), (f0 + 2.0 * f3) / 6.0
    f1 = _fmin(s1, l0, l1, l2, d0, d1, d2)
    f2 = _fmin(s2, l0, l1, l2, d0, d1, d2)
    h1 = s1
    h2 = s2 - s1
    h3 = 1.0 - s2
    i_f = 0.5 * (h1 * (f0 + f1) + h2 * (f1 + f2) + h3 * (f2 + f3))
    i_fs = (h1 * (f0 * s1 + 2.0 * f1 * s1)
            + h2 * (2.0 * f1 * s1 + f1 * s2 + f2 * s1 + 2.0 * f2 * s2)
            + h3 * (2.0 * f2 * s2 + f2 + f3 * s2 + 2.0 * f3)) / 6.0
    return i_f, i_fs


@njit(cache=True, error_model="numpy")
def _sat(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y):
    """Separating-axis test of triangles c and t (:func:`_sat_axis`).
    Returns ``(overlap?, u00, u01, ..., u22)``."""
    axis, u00, u01, u02, u10, u11, u12, u20, u21, u22 = _sat_axis(c0x, c0y, c1x, c1y, c2x, c2y,
                                                                  t0x, t0y, t1x, t1y, t2x, t2y)
    return axis == 0, u00, u01, u02, u10, u11, u12, u20, u21, u22


@njit(cache=True, error_model="numpy")
def _sat_axis(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y):
    """Separating-axis test of triangles c and t on their six edges, in strict arithmetic (no
    fast-math, and scalars only, so that it costs no reference counting: corners lying on the
    other's edge give exact zeros, and touching counts as apart).

    ``u_ij = 2A_t lambda^t_j(c_i) = D_{i,j+1} x D_{i,j+2}`` and
    ``v_kj = 2A_c lambda^c_j(t_k) = D_{j+1,k} x D_{j+2,k}`` with ``D_ik = t_k - c_i``; the pair
    is apart when, for some ``j``, all three ``u_ij <= 0`` or all three ``v_kj <= 0``; it also
    counts as apart (a round-off sliver, see the module docstring) when, for some ``j``,
    ``max_i u_ij <= TOUCH_EPS 2A_t`` or ``max_k v_kj <= TOUCH_EPS 2A_c``.
    Returns ``(axis, u00, u01, ..., u22)``: ``axis`` 0 when the triangles overlap, else the
    first axis that separates them, ``1 + j`` for t's edge ``j``, ``4 + j`` for c's edge ``j``
    (the witness that :func:`_apart_on` re-checks at the next step).
    """
    # differences D_ik = t_k - c_i
    d00x = t0x - c0x
    d00y = t0y - c0y
    d01x = t1x - c0x
    d01y = t1y - c0y
    d02x = t2x - c0x
    d02y = t2y - c0y
    d10x = t0x - c1x
    d10y = t0y - c1y
    d11x = t1x - c1x
    d11y = t1y - c1y
    d12x = t2x - c1x
    d12y = t2y - c1y
    d20x = t0x - c2x
    d20y = t0y - c2y
    d21x = t1x - c2x
    d21y = t1y - c2y
    d22x = t2x - c2x
    d22y = t2y - c2y
    # 2A_t lambda^t_j(c_i) = D_{i,j+1} x D_{i,j+2}
    u00 = _orient(d01x, d01y, d02x, d02y)
    u01 = _orient(d02x, d02y, d00x, d00y)
    u02 = _orient(d00x, d00y, d01x, d01y)
    u10 = _orient(d11x, d11y, d12x, d12y)
    u11 = _orient(d12x, d12y, d10x, d10y)
    u12 = _orient(d10x, d10y, d11x, d11y)
    u20 = _orient(d21x, d21y, d22x, d22y)
    u21 = _orient(d22x, d22y, d20x, d20y)
    u22 = _orient(d20x, d20y, d21x, d21y)
    # 2A_c lambda^c_j(t_k) = D_{j+1,k} x D_{j+2,k}
    v00 = _orient(d10x, d10y, d20x, d20y)
    v01 = _orient(d20x, d20y, d00x, d00y)
    v02 = _orient(d00x, d00y, d10x, d10y)
    v10 = _orient(d11x, d11y, d21x, d21y)
    v11 = _orient(d21x, d21y, d01x, d01y)
    v12 = _orient(d01x, d01y, d11x, d11y)
    v20 = _orient(d12x, d12y, d22x, d22y)
    v21 = _orient(d22x, d22y, d02x, d02y)
    v22 = _orient(d02x, d02y, d12x, d12y)
    # deepest reach of c past each edge line of t (and of t past c's), against the threshold
    # TOUCH_EPS 2A (2A_t = u_i0 + u_i1 + u_i2, 2A_c = v_k0 + v_k1 + v_k2 for any i, k)
    thr_t = TOUCH_EPS * (u00 + u01 + u02)
    thr_c = TOUCH_EPS * (v00 + v01 + v02)
    axis = 0
    if _max3(u00, u10, u20) <= thr_t:
        axis = 1
    elif _max3(u01, u11, u21) <= thr_t:
        axis = 2
    elif _max3(u02, u12, u22) <= thr_t:
        axis = 3
    elif _max3(v00, v10, v20) <= thr_c:
        axis = 4
    elif _max3(v01, v11, v21) <= thr_c:
        axis = 5
    elif _max3(v02, v12, v22) <= thr_c:
        axis = 6
    return axis, u00, u01, u02, u10, u11, u12, u20, u21, u22


@njit(cache=True, error_model="numpy")
def _apart_on(axis, c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y):
    """True when the witness ``axis`` of :func:`_sat_axis` (1-3: t's edge ``axis - 1``, 4-6:
    c's edge ``axis - 4``) still separates c and t.

    The same strict expressions as :func:`_sat_axis` for that one axis (its three ``u_ij`` or
    ``v_kj`` and the ``2A`` they are measured against), so "apart" here is bit for bit the
    verdict of the full test: 6 orientation determinants (3 for ``2A``, 3 for the reach) instead of 18. Pairs of a settled pile
    or of neighbouring blocks stay apart on the same axis for many steps. c's edges are t's with
    the roles swapped: ``v_kj(c, t) = u_kj(t, c)`` exactly (both differences change sign).
    """
    if axis <= 3:
        return _apart_on_edge_of_t(axis - 1, c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y)
    return _apart_on_edge_of_t(axis - 4, t0x, t0y, t1x, t1y, t2x, t2y, c0x, c0y, c1x, c1y, c2x, c2y)


@njit(cache=True, error_model="numpy", inline="always")
def _apart_on_edge_of_t(j, c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y):
    """``max_i u_ij <= TOUCH_EPS 2A_t`` for t's edge ``j`` (from ``t_{j+1}`` to ``t_{j+2}``),
    ``u_ij = (t_{j+1} - c_i) x (t_{j+2} - c_i)``, ``2A_t = u_00 + u_01 + u_02``."""
    if j == 0:
        ax, ay, bx, by = t1x, t1y, t2x, t2y
    elif j == 1:
        ax, ay, bx, by = t2x, t2y, t0x, t0y
    else:
        ax, ay, bx, by = t0x, t0y, t1x, t1y
    thr = TOUCH_EPS * (_orient(t1x - c0x, t1y - c0y, t2x - c0x, t2y - c0y)
                       + _orient(t2x - c0x, t2y - c0y, t0x - c0x, t0y - c0y)
                       + _orient(t0x - c0x, t0y - c0y, t1x - c0x, t1y - c0y))
    return _max3(_orient(ax - c0x, ay - c0y, bx - c0x, by - c0y),
                 _orient(ax - c1x, ay - c1y, bx - c1x, by - c1y),
                 _orient(ax - c2x, ay - c2y, bx - c2x, by - c2y)) <= thr


@njit(cache=True, error_model="numpy", inline="always")
def _corners(x, i, j):
    """The six corners ``c0x, c0y, ..., t2y`` of triangles ``i`` (c) and ``j`` (t)."""
    ix = 3 * i
    jx = 3 * j
    return (x[ix, 0], x[ix, 1], x[ix + 1, 0], x[ix + 1, 1], x[ix + 2, 0], x[ix + 2, 1],
            x[jx, 0], x[jx, 1], x[jx + 1, 0], x[jx + 1, 1], x[jx + 2, 0], x[jx + 2, 1])


# ----------------------------------------------------------------------------- per-pair laws
_NONE = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
"""What :func:`pair_normal` returns for a pair that does not overlap."""


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def pair_normal(x, i, j, penalty, w, iw, pool):
    """Distributed-potential normal contact of one triangle pair (the per-pair law), by clipping
    (Sutherland-Hodgman).

    Parameters
    ----------
    x : (n_nodes, 2) float64
        Node positions [m]; triangle ``t`` has nodes ``3t, 3t+1, 3t+2`` (counter-clockwise).
    i, j : int
        Contactor ``c`` and target ``t``.
    penalty : float
        ``p`` [Pa]; ``E = p int_D (phi_c + phi_t) dA``.
    w : (N_WORK,) float64, iw : (N_IWORK,) int64, pool : (MAX_VERT, N_COL) float64
        Work space. On return ``w[0:12]`` holds the nodal forces on ``c`` (0:6) and ``t`` (6:12)
        [N/m] when the triangles overlap (it is not written otherwise).

    Returns
    -------
    (E, area, gx, gy, gtx, gty, bc0x, bc0y, bc1x, bc1y, bc2x, bc2y, bt0x, bt0y, bt1x, bt1y, bt2x, bt2y)
        Pair energy ``E`` [J/m]; overlap area [m^2] (0 when apart or touching: then nothing
        else is meaningful); overlap centroid ``(gx, gy)`` and t's centroid ``(gtx, gty)``, both
        relative to c's centroid [m]; the barycentric gradients ``b_k`` of c and of t [1/m]
        (``lambda_k = 1/3 + b_k . (x - G)``, for the friction point).
    """
    c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y = _corners(x, i, j)
    hit, u00, u01, u02, u10, u11, u12, u20, u21, u22 = _sat(c0x, c0y, c1x, c1y, c2x, c2y,
                                                            t0x, t0y, t1x, t1y, t2x, t2y)
    if not hit:
        return _NONE
    return _overlap_clip(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y,
                         u00, u01, u02, u10, u11, u12, u20, u21, u22, penalty, w, iw, pool)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _overlap_clip(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y,
                  u00, u01, u02, u10, u11, u12, u20, u21, u22, penalty, w, iw, pool):
    """:func:`pair_normal` (clipping) of a pair that passed the separating-axis test (corners and
    ``u_ij = 2A_t lambda^t_j(c_i)`` from :func:`_sat`): overlap polygon, edge integrals, forces."""
    # local frame at c's centroid; barycentric gradients b_k = rot(P_{k+1} - P_{k+2}) / 2A
    ox = (c0x + c1x + c2x) / 3.0
    oy = (c0y + c1y + c2y) / 3.0
    ic = 1.0 / ((c1x - c0x) * (c2y - c0y) - (c1y - c0y) * (c2x - c0x))
    it = 1.0 / ((t1x - t0x) * (t2y - t0y) - (t1y - t0y) * (t2x - t0x))
    bc0x = (c1y - c2y) * ic
    bc0y = (c2x - c1x) * ic
    bc1x = (c2y - c0y) * ic
    bc1y = (c0x - c2x) * ic
    bc2x = (c0y - c1y) * ic
    bc2y = (c1x - c0x) * ic
    bt0x = (t1y - t2y) * it
    bt0y = (t2x - t1x) * it
    bt1x = (t2y - t0y) * it
    bt1y = (t0x - t2x) * it
    bt2x = (t0y - t1y) * it
    bt2y = (t1x - t0x) * it
    gtx = (t0x + t1x + t2x) / 3.0 - ox
    gty = (t0y + t1y + t2y) / 3.0 - oy
    # overlap polygon: c's corners (columns 2:5 t's barycentrics, 5:8 c's), clipped by t
    pool[0, 0] = c0x - ox
    pool[0, 1] = c0y - oy
    pool[0, 2] = u00 * it
    pool[0, 3] = u01 * it
    pool[0, 4] = u02 * it
    pool[1, 0] = c1x - ox
    pool[1, 1] = c1y - oy
    pool[1, 2] = u10 * it
    pool[1, 3] = u11 * it
    pool[1, 4] = u12 * it
    pool[2, 0] = c2x - ox
    pool[2, 1] = c2y - oy
    pool[2, 2] = u20 * it
    pool[2, 3] = u21 * it
    pool[2, 4] = u22 * it
    for r in range(3):
        for k in range(3):
            pool[r, 5 + k] = 1.0 if r == k else 0.0
        iw[r] = r
        iw[_L0 + r] = (r + 1) % 3   # edge (r-1 -> r) is c's edge opposite corner r+1
    n = 3
    nv = 3
    src = 0
    # t's half-plane j cuts c iff one of c's corners lies outside it; c (and every polygon clipped
    # from it) then lies inside the others, so the corners decide for all three passes
    cut0 = min(u00, min(u10, u20)) < 0.0
    cut1 = min(u01, min(u11, u21)) < 0.0
    cut2 = min(u02, min(u12, u22)) < 0.0
    for jj in range(3):
        if cut0 if jj == 0 else (cut1 if jj == 1 else cut2):
            n, nv = _clip(pool, nv, iw, src * MAX_VERT, (1 - src) * MAX_VERT, _L0 + src * MAX_VERT,
                          _L0 + (1 - src) * MAX_VERT, n, 2 + jj, 3 + jj)
            src = 1 - src
            if n < 3:
                return _NONE
    # one pass over the edges of D (see the module docstring, "Evaluation")
    area2 = 0.0    # 2 area(D)
    mx6 = 0.0      # 6 int_D x dA, 6 int_D y dA (about c's centroid)
    my6 = 0.0
    phi_c = 0.0    # int_D phi dA - area / 3 of c and of t: sum over the other's edges of 2 fan x int f
    phi_t = 0.0
    nx = 0.0       # N = sum s n int f ds  (s = -1 on c's edges, +1 on t's; n dGamma = (dy, -dx) ds)
    ny = 0.0
    txx = 0.0      # T = sum s n (x) m,  m = a int f ds + d int f s ds  (a about c's centroid)
    txy = 0.0
    tyx = 0.0
    tyy = 0.0
    base = src * MAX_VERT
    a = iw[base + n - 1]
    for e in range(n):
        b = iw[base + e]
        c_owns = iw[_L0 + base + e] < 3
        ax = pool[a, 0]
        ay = pool[a, 1]
        dx = pool[b, 0] - ax
        dy = pool[b, 1] - ay
        cr = ax * dy - ay * dx                  # a x b: twice the fan from c's centroid
        area2 += cr
        mx6 += cr * (2.0 * ax + dx)
        my6 += cr * (2.0 * ay + dy)
        # f = min lambda of the triangle that does not own the edge
        i_f, i_fs = _edge_integrals(pool, a, b, 2 if c_owns else 5)
        if c_owns:     # t's potential on c's boundary: fan from t's centroid
            phi_t += (cr - (gtx * dy - gty * dx)) * i_f
        else:
            phi_c += cr * i_f
        sx = -dy if c_owns else dy
        sy = dx if c_owns else -dx
        mx = ax * i_f + dx * i_fs
        my = ay * i_f + dy * i_fs
        nx += sx * i_f
        ny += sy * i_f
        txx += sx * mx
        txy += sx * my
        tyx += sy * mx
        tyy += sy * my
        a = b
    if not area2 > 0.0:
        return _NONE
    area = 0.5 * area2
    # int_D phi dA = area / 3 + 2 sum (fan area x int f ds) over the other's edges
    ic_ = area / 3.0 + phi_c
    it_ = area / 3.0 + phi_t
    p3 = 3.0 * penalty
    # F_i = 3p (N / 3 + T b_i) - p b_i int_D phi dA on c; on t -N and T_t = -T + N (x) G_t
    w[0] = penalty * nx + p3 * (txx * bc0x + txy * bc0y) - penalty * bc0x * ic_
    w[1] = penalty * ny + p3 * (tyx * bc0x + tyy * bc0y) - penalty * bc0y * ic_
    w[2] = penalty * nx + p3 * (txx * bc1x + txy * bc1y) - penalty * bc1x * ic_
    w[3] = penalty * ny + p3 * (tyx * bc1x + tyy * bc1y) - penalty * bc1y * ic_
    w[4] = penalty * nx + p3 * (txx * bc2x + txy * bc2y) - penalty * bc2x * ic_
    w[5] = penalty * ny + p3 * (tyx * bc2x + tyy * bc2y) - penalty * bc2y * ic_
    txx = nx * gtx - txx
    txy = nx * gty - txy
    tyx = ny * gtx - tyx
    tyy = ny * gty - tyy
    w[6] = -penalty * nx + p3 * (txx * bt0x + txy * bt0y) - penalty * bt0x * it_
    w[7] = -penalty * ny + p3 * (tyx * bt0x + tyy * bt0y) - penalty * bt0y * it_
    w[8] = -penalty * nx + p3 * (txx * bt1x + txy * bt1y) - penalty * bt1x * it_
    w[9] = -penalty * ny + p3 * (tyx * bt1x + tyy * bt1y) - penalty * bt1y * it_
    w[10] = -penalty * nx + p3 * (txx * bt2x + txy * bt2y) - penalty * bt2x * it_
    w[11] = -penalty * ny + p3 * (tyx * bt2x + tyy * bt2y) - penalty * bt2y * it_
    e = penalty * (ic_ + it_)
    gx = mx6 / (3.0 * area2)    # int_D x dA / area = (mx6 / 6) / (area2 / 2)
    gy = my6 / (3.0 * area2)
    return (e, area, gx, gy, gtx, gty, bc0x, bc0y, bc1x, bc1y, bc2x, bc2y, bt0x, bt0y, bt1x, bt1y, bt2x, bt2y)


@njit(cache=True, error_model="numpy", inline="always")
def facing_face(p0x, p0y, p1x, p1y, p2x, p2y, nx, ny):
    """The face of a counter-clockwise triangle that looks most nearly along ``(nx, ny)``: the
    ``k`` (edge from corner ``k`` to corner ``k + 1``) whose outward unit normal
    ``(e_y, -e_x) / |e|`` has the largest dot product with ``(nx, ny)``."""
    ex = p1x - p0x
    ey = p1y - p0y
    best = 0
    cos_best = (ey * nx - ex * ny) / math.sqrt(ex * ex + ey * ey)
    ex = p2x - p1x
    ey = p2y - p1y
    c = (ey * nx - ex * ny) / math.sqrt(ex * ex + ey * ey)
    if c > cos_best:
        best = 1
        cos_best = c
    ex = p0x - p2x
    ey = p0y - p2y
    c = (ey * nx - ex * ny) / math.sqrt(ex * ex + ey * ey)
    if c > cos_best:
        best = 2
    return best


@njit(cache=True, error_model="numpy", inline="always")
def pair_friction(mu_pair, face_mu, i, j, c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y, nx, ny):
    """Base Coulomb coefficient of a touching pair (contactor ``i`` with corners ``c``, target
    ``j`` with corners ``t``): ``mu_pair`` when the pair has its own (across a broken crack
    element: that element's residual friction), else (``mu_pair = FROM_FACES``) the lower
    friction of the two faces in touch, ``min(face_mu[i, k_i], face_mu[j, k_j])``: ``k_i`` the
    face of ``i`` that looks along ``-n``, ``k_j`` the face of ``j`` that looks along ``n``, with
    ``n = (nx, ny)`` the unit normal of the contact force on ``i`` (it pushes ``i`` away from
    ``j``). A triangle whose three faces have one friction needs no face picked.

    Friction belongs to the surfaces that slide on each other: a block with one face on a
    smooth joint (phi = 11 deg) and another, broken through rock, on the floor slides on the
    floor at the rock's friction, not the joint's."""
    if mu_pair >= 0.0:
        return mu_pair
    fi = face_mu[i, 0]
    if face_mu[i, 1] != fi or face_mu[i, 2] != fi:
        fi = face_mu[i, facing_face(c0x, c0y, c1x, c1y, c2x, c2y, -nx, -ny)]
    fj = face_mu[j, 0]
    if face_mu[j, 1] != fj or face_mu[j, 2] != fj:
        fj = face_mu[j, facing_face(t0x, t0y, t1x, t1y, t2x, t2y, nx, ny)]
    return min(fi, fj)


@njit(cache=True, error_model="numpy")
def tangential_law(ft, du, kt, cap):
    """Incremental tangential penalty with a Coulomb cap (return mapping), one pair.

    ``ft`` [N/m] is the tangential force on c carried from the last step (rotated into the
    current tangent), ``du = v_t dt`` [m] the tangential slip increment of c relative to t,
    ``kt`` [N/m per m] the tangential stiffness, ``cap = mu |F_n|`` [N/m]. Trial
    ``f* = ft - kt du``; if ``|f*| <= cap`` the pair sticks, else it slips and the force is
    returned to the cap (Cundall & Strack 1979; Munjiza 2004 ch. 3).

    Returns ``(ft_new, dissipated)``; ``dissipated = cap (|f*| - cap) / kt`` [J/m] is the
    frictional work of the step (Coulomb force times plastic slip).
    """
    f_trial = ft - kt * du
    if abs(f_trial) <= cap:
        return f_trial, 0.0
    # f/|f| is exactly +-1 (and keeps a NaN): the sign without np.sign, which CUDA lacks
    return cap * (f_trial / abs(f_trial)), cap * (abs(f_trial) - cap) / kt


# ----------------------------------------------------------------------------- pair loop
@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def _pair_range(lo, hi, x, v, pair_i, pair_j, penalty, mu_base, face_mu, inv_f, kt_pair, damp, dt, spring, f_t,
                touching, witness, f, w, iw, pool):
    """The pair loop of :func:`pair_forces` over ``q in [lo, hi)`` (``lo`` and ``hi`` at changes of
    ``pair_i``): adds the contactors' forces into ``f``, stores the targets' in ``f_t``; returns
    the four energy sums."""
    c_en = 0.0
    c_et = 0.0
    c_wf = 0.0
    c_wd = 0.0
    cur = -1
    s0x = 0.0
    s0y = 0.0
    s1x = 0.0
    s1y = 0.0
    s2x = 0.0
    s2y = 0.0
    for q in range(lo, hi):
        i = pair_i[q]
        if i != cur:
            # flush the forces summed on the previous contactor (this chunk owns it)
            if cur >= 0:
                f[3 * cur, 0] += s0x
                f[3 * cur, 1] += s0y
                f[3 * cur + 1, 0] += s1x
                f[3 * cur + 1, 1] += s1y
                f[3 * cur + 2, 0] += s2x
                f[3 * cur + 2, 1] += s2y
            cur = i
            s0x = 0.0
            s0y = 0.0
            s1x = 0.0
            s1y = 0.0
            s2x = 0.0
            s2y = 0.0
        j = pair_j[q]
        c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y = _corners(x, i, j)
        area = 0.0
        wq = witness[q]
        # a pair still apart on last step's separating axis skips the full test (same verdict)
        if wq == 0 or not _apart_on(wq, c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y):
            axis, u00, u01, u02, u10, u11, u12, u20, u21, u22 = _sat_axis(c0x, c0y, c1x, c1y, c2x, c2y,
                                                                          t0x, t0y, t1x, t1y, t2x, t2y)
            if axis != wq:
                witness[q] = axis
            if axis == 0:
                (e, area, gx, gy, gtx, gty, bc0x, bc0y, bc1x, bc1y, bc2x, bc2y,
                 bt0x, bt0y, bt1x, bt1y, bt2x, bt2y) = _overlap_clip(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y,
                                                                     t1x, t1y, t2x, t2y, u00, u01, u02, u10,
                                                                     u11, u12, u20, u21, u22, penalty, w, iw,
                                                                     pool)
        if not area > 0.0:
            if touching[q]:   # it separated: drop its history (untouched pairs have none)
                touching[q] = 0
                for r in range(N_HIST):
                    spring[q, r] = 0.0
            continue
        touching[q] = 1
        c_en += e
        fx = w[0] + w[2] + w[4]
        fy = w[1] + w[3] + w[5]
        fn = math.sqrt(fx * fx + fy * fy)
        gfx = 0.0
        gfy = 0.0
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        mu = 0.0
        if fn > 0.0:
            mu = inv_f * pair_friction(mu_base[q], face_mu, i, j, c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y,
                                       t2x, t2y, fx / fn, fy / fn)
        if fn <= 0.0 or (mu <= 0.0 and damp[q] <= 0.0):
            for r in range(4):
                spring[q, r] = 0.0
        else:
            nx = fx / fn
            ny = fy / fn
            # barycentrics of the overlap centroid in c and in t (lambda = 1/3 + b . (p - G))
            a1 = 1.0 / 3.0 + bc1x * gx + bc1y * gy
            a2 = 1.0 / 3.0 + bc2x * gx + bc2y * gy
            a0 = 1.0 - a1 - a2
            b1 = 1.0 / 3.0 + bt1x * (gx - gtx) + bt1y * (gy - gty)
            b2 = 1.0 / 3.0 + bt2x * (gx - gtx) + bt2y * (gy - gty)
            b0 = 1.0 - b1 - b2
            ix = 3 * i
            jx = 3 * j
            vrx = (a0 * v[ix, 0] + a1 * v[ix + 1, 0] + a2 * v[ix + 2, 0]
                   - b0 * v[jx, 0] - b1 * v[jx + 1, 0] - b2 * v[jx + 2, 0])
            vry = (a0 * v[ix, 1] + a1 * v[ix + 1, 1] + a2 * v[ix + 2, 1]
                   - b0 * v[jx, 1] - b1 * v[jx + 1, 1] - b2 * v[jx + 2, 1])
            # relative velocity at last step's application point (its barycentric weights are
            # kept with the history): the second half-step work of last step's forces
            p0, p1, p2 = spring[q, 4], spring[q, 5], spring[q, 6]
            r0, r1, r2 = spring[q, 7], spring[q, 8], spring[q, 9]
            wpx = (p0 * v[ix, 0] + p1 * v[ix + 1, 0] + p2 * v[ix + 2, 0]
                   - r0 * v[jx, 0] - r1 * v[jx + 1, 0] - r2 * v[jx + 2, 0])
            wpy = (p0 * v[ix, 1] + p1 * v[ix + 1, 1] + p2 * v[ix + 2, 1]
                   - r0 * v[jx, 1] - r1 * v[jx + 1, 1] - r2 * v[jx + 2, 1])
            spring[q, 4] = a0
            spring[q, 5] = a1
            spring[q, 6] = a2
            spring[q, 7] = b0
            spring[q, 8] = b1
            spring[q, 9] = b2
            # secant normal stiffness of this pair now, k = F_n^2 / (2E) [Pa]: exact for a flat
            # overlap (E = k d^2 / 2), 3/4 of the tangent one for a corner; vanishes with the overlap
            k_sec = fn * fn / (2.0 * e) if e > 0.0 else 0.0
            if mu > 0.0 and k_sec > 0.0:
                tx = -ny
                ty = nx
                sx = spring[q, 0]
                sy = spring[q, 1]
                smag = math.sqrt(sx * sx + sy * sy)
                ft = smag if sx * tx + sy * ty >= 0.0 else -smag  # rotate into the new tangent
                kt = kt_pair[q]
                # Work of the tangential force on the pair, leapfrog-consistent like the ledger:
                # last step's force over the second half-step, this step's over the first; the
                # friction dissipation is then minus this work minus the spring energy (booking
                # mu F_n times the slip of v_{n-1/2} instead is a first-order error in dt that
                # accumulates while a sticking contact vibrates).
                c_wf += 0.5 * (sx * wpx + sy * wpy) * dt
                ft, _ = tangential_law(ft, (vrx * tx + vry * ty) * dt, kt, mu * fn)
                spring[q, 0] = ft * tx
                spring[q, 1] = ft * ty
                c_wf += 0.5 * ft * (tx * vrx + ty * vry) * dt
                c_et += 0.5 * ft * ft / kt
                gfx += ft * tx
                gfy += ft * ty
            else:
                spring[q, 0] = 0.0
                spring[q, 1] = 0.0
            if damp[q] > 0.0 and k_sec > 0.0:
                vn = vrx * nx + vry * ny
                # leapfrog-consistent dissipation: the work of a force applied at step n is
                # F_n . (v_{n-1/2} + v_{n+1/2}) dt / 2; the second half of last step's is booked now
                c_wd -= 0.5 * (spring[q, 2] * wpx + spring[q, 3] * wpy) * dt
                fd = max(-damp[q] * math.sqrt(k_sec) * vn, -fn)  # never pull beyond the elastic push
                c_wd -= 0.5 * fd * vn * dt
                spring[q, 2] = fd * nx
                spring[q, 3] = fd * ny
                gfx += fd * nx
                gfy += fd * ny
            else:
                spring[q, 2] = 0.0
                spring[q, 3] = 0.0
        # friction and damping act at the overlap centroid, equal and opposite
        s0x += w[0] + a0 * gfx
        s0y += w[1] + a0 * gfy
        s1x += w[2] + a1 * gfx
        s1y += w[3] + a1 * gfy
        s2x += w[4] + a2 * gfx
        s2y += w[5] + a2 * gfy
        f_t[q, 0] = w[6] - b0 * gfx
        f_t[q, 1] = w[7] - b0 * gfy
        f_t[q, 2] = w[8] - b1 * gfx
        f_t[q, 3] = w[9] - b1 * gfy
        f_t[q, 4] = w[10] - b2 * gfx
        f_t[q, 5] = w[11] - b2 * gfy
    if cur >= 0:
        f[3 * cur, 0] += s0x
        f[3 * cur, 1] += s0y
        f[3 * cur + 1, 0] += s1x
        f[3 * cur + 1, 1] += s1y
        f[3 * cur + 2, 0] += s2x
        f[3 * cur + 2, 1] += s2y
    return c_en, c_et, c_wf, c_wd


@njit(cache=True, error_model="numpy")
def _gcd(a, b):
    while b:
        a, b = b, a % b
    return a


@njit(cache=True, error_model="numpy")
def chunk_bounds(pair_i, n_chunks):
    """(n_chunks + 1,) boundaries of the pair loop's chunks: about equal pair counts, each moved
    forward to the next change of ``pair_i`` (a chunk owns all pairs of its contactors)."""
    n = pair_i.shape[0]
    bounds = np.empty(n_chunks + 1, np.int64)
    bounds[0] = 0
    for ch in range(1, n_chunks):
        b = max(ch * n // n_chunks, bounds[ch - 1])
        while 0 < b < n and pair_i[b] == pair_i[b - 1]:
            b += 1
        bounds[ch] = b
    bounds[n_chunks] = n
    return bounds


@njit(parallel=True, cache=True, error_model="numpy")
def _pair_chunks_parallel(x, v, pair_i, pair_j, bounds, penalty, mu_base, face_mu, inv_f, kt_pair, damp, dt, spring,
                          f_t, touching, witness, f, stride):
    """Parallel driver of :func:`pair_forces`: (n_chunks, 4) energy sums per chunk of pairs.
    Iteration ``it`` runs chunk ``it * stride mod n_chunks`` (``stride`` coprime, about 0.618
    n_chunks), so each thread's contiguous share of iterations is spread over the whole pair
    list: balanced when the overlapping pairs cluster (the bottom of a pile)."""
    n_chunks = bounds.shape[0] - 1
    sums = np.zeros((n_chunks, 4))
    for it in prange(n_chunks):
        ch = (it * stride) % n_chunks
        w = np.empty(N_WORK)
        iw = np.empty(N_IWORK, np.int64)
        pool = np.empty((MAX_VERT, N_COL))
        a, b, c, d = _pair_range(bounds[ch], bounds[ch + 1], x, v, pair_i, pair_j, penalty, mu_base, face_mu, inv_f,
                                 kt_pair, damp, dt, spring, f_t, touching, witness, f, w, iw, pool)
        sums[ch, 0] = a
        sums[ch, 1] = b
        sums[ch, 2] = c
        sums[ch, 3] = d
    return sums


@njit(cache=True, error_model="numpy")
def pair_forces(x, v, pair_i, pair_j, bounds, penalty, mu_base, face_mu, inv_f, kt_pair, damp, dt, spring, f_t,
                touching, witness, f):
    """Contact forces of all candidate pairs: contactors' added into ``f``, targets' stored per pair.

    Parameters
    ----------
    x, v : (n_nodes, 2) float64
        Positions [m] and velocities [m/s] of the exploded nodes.
    pair_i, pair_j : (n_pairs,) int64
        Triangles of each candidate pair, sorted by ``pair_i`` (``i`` plays contactor ``c``).
    bounds : (n_chunks + 1,) int64
        Chunks of the pair loop (:func:`chunk_bounds`); fixed by the pair list, so the sums
        (and forces) are bitwise independent of the thread count.
    penalty : float
        Normal penalty ``p`` [Pa].
    mu_base : (n_pairs,) float64
        Base (unreduced) Coulomb coefficient ``tan(phi)`` of each pair that has its own (across a
        broken crack element), else :data:`FROM_FACES`: the pair then takes the lower friction
        of the two faces in touch, picked each step by the contact normal (:func:`pair_friction`).
    face_mu : (n_triangles, 3) float64
        Base Coulomb coefficient of each triangle's faces (face ``k`` from corner ``k`` to ``k + 1``).
    inv_f : float
        ``1 / F``, the strength-reduction factor dividing every coefficient; a pair whose
        coefficient is 0 skips the friction branch.
    kt_pair : (n_pairs,) float64
        Tangential stiffness of each pair [N/m per m], constant while the pair exists, so the
        tangential spring stores ``f_t^2 / (2 k_t)`` consistently with the work done on it (a
        stiffness that followed the normal force would create or destroy energy whenever the
        normal force changed while the spring was loaded).
    damp : (n_pairs,) float64
        ``2 xi sqrt(m_eff)`` of each pair [sqrt(kg/m)]: the normal viscous coefficient is
        ``c_n = damp sqrt(k)`` with the same secant stiffness ``k`` (so a sliver overlap is
        damped in proportion to its own stiffness); 0 skips the branch.
    dt : float
        Time step [s] (slip increment ``v_t dt``).
    spring : (n_pairs, 4) float64
        Per-pair history, updated in place: tangential (friction) force vector on ``c`` [N/m]
        (the slip history), then the normal damping force vector of the last step [N/m] (to
        book its dissipation time-centred).
    f_t : (n_pairs, 6) float64
        Overwritten where the pair overlaps: forces on t's corners (friction and damping
        included) [N/m]; gather them with :func:`gather_forces`.
    touching : (n_pairs,) uint8
        Updated: 1 where the pair overlaps (its ``f_t`` row needs gathering). On entry 0 must
        mean that the pair's ``spring`` row is zero (the loop reads neither for pairs that
        stay apart).
    witness : (n_pairs,) uint8
        Updated: the axis that separated the pair at its last test (:func:`_sat_axis`; 0 when
        it overlapped or is new). A cache, not state: zeros are always valid, and the forces
        do not depend on it.
    f : (n_nodes, 2) float64
        Forces on c's corners are added here [N/m].

    Returns
    -------
    (E_normal, E_tangential, W_friction, W_damping) : floats [J/m]
        Normal contact energy and tangential spring energy ``|F_t|^2 / (2 k_t)`` now; frictional
        and damping work dissipated during this step.
    """
    n_chunks = bounds.shape[0] - 1
    if pair_i.shape[0] >= PARALLEL_MIN_PAIRS:
        stride = max(1, int(0.618 * n_chunks))
        while _gcd(stride, n_chunks) != 1:
            stride += 1
        sums = _pair_chunks_parallel(x, v, pair_i, pair_j, bounds, penalty, mu_base, face_mu, inv_f, kt_pair, damp,
                                     dt, spring, f_t, touching, witness, f, stride)
    else:
        sums = np.zeros((n_chunks, 4))
        w = np.empty(N_WORK)
        iw = np.empty(N_IWORK, np.int64)
        pool = np.empty((MAX_VERT, N_COL))
        for ch in range(n_chunks):
            a, b, c, d = _pair_range(bounds[ch], bounds[ch + 1], x, v, pair_i, pair_j, penalty, mu_base, face_mu,
                                     inv_f, kt_pair, damp, dt, spring, f_t, touching, witness, f, w, iw, pool)
            sums[ch, 0] = a
            sums[ch, 1] = b
            sums[ch, 2] = c
            sums[ch, 3] = d
    # sequential sum in chunk order: bitwise the same for any thread count
    e = np.zeros(4)
    for ch in range(n_chunks):
        for r in range(4):
            e[r] += sums[ch, r]
    return e[0], e[1], e[2], e[3]


@njit(cache=True, error_model="numpy")
def overlap_areas(x, pair_i, pair_j):
    """(n_pairs,) overlap area of each pair [m^2] (0 when apart or touching)."""
    n = pair_i.shape[0]
    out = np.zeros(n)
    w = np.empty(N_WORK)
    iw = np.empty(N_IWORK, np.int64)
    pool = np.empty((MAX_VERT, N_COL))
    for q in range(n):
        out[q] = pair_normal(x, pair_i[q], pair_j[q], 1.0, w, iw, pool)[1]
    return out


@njit(cache=True, error_model="numpy", inline="always")
def _gather_one(f, t, r0, r1, inc_pair, f_t, touching):
    for r in range(r0, r1):
        q = inc_pair[r]
        if touching[q] == 0:
            continue
        for k in range(3):
            f[3 * t + k, 0] += f_t[q, 2 * k]
            f[3 * t + k, 1] += f_t[q, 2 * k + 1]


@njit(parallel=True, cache=True, error_model="numpy")
def _gather_parallel(f, active, inc_ptr, inc_pair, f_t, touching):
    for a in prange(active.shape[0]):
        _gather_one(f, active[a], inc_ptr[a], inc_ptr[a + 1], inc_pair, f_t, touching)


@njit(cache=True, error_model="numpy")
def gather_forces(f, active, inc_ptr, inc_pair, f_t, touching):
    """Add the stored target-side pair forces to the nodes: ``f[3t+k] += sum over the pairs
    whose target is t`` (race-free: each triangle writes only its own three nodes).

    ``active`` (n_act,) triangle ids; the pairs with target ``active[a]`` are
    ``inc_pair[inc_ptr[a]:inc_ptr[a+1]]`` (:func:`target_incidence`). Small sets run serially.
    """
    if inc_pair.shape[0] >= PARALLEL_MIN_PAIRS:
        _gather_parallel(f, active, inc_ptr, inc_pair, f_t, touching)
    else:
        for a in range(active.shape[0]):
            _gather_one(f, active[a], inc_ptr[a], inc_ptr[a + 1], inc_pair, f_t, touching)


@njit(cache=True, error_model="numpy", inline="always")
def lower_bound(keys, key):
    """First index ``r`` of sorted ``keys`` with ``keys[r] >= key`` (``len(keys)`` if none):
    ``np.searchsorted(keys, key)``, written out so that the GPU can run it."""
    lo = 0
    hi = keys.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, error_model="numpy", inline="always")
def pair_constants_one(q, pair_i, pair_j, crack, broken, crack_mu, kt_tri, mass_tri, damping_ratio, mu_base,
                       kt_pair, damp_pair):
    """The constants of candidate pair ``q = (i, j)``, written to row ``q``; ``crack`` is the
    crack element between ``i`` and ``j``, or -1 (:func:`crack_between`):

    * ``mu_base``: the base (unreduced) Coulomb coefficient: the residual friction ``crack_mu``
      of that crack element if it is broken, else :data:`FROM_FACES` (the faces in touch decide,
      step by step: :func:`pair_friction`);
    * ``kt_pair``: the tangential stiffness ``min(kt_tri[i], kt_tri[j])`` [N/m per m];
    * ``damp_pair``: ``2 xi sqrt(m_i m_j / (m_i + m_j))`` [sqrt(kg/m)] of the triangles'
      masses, 0 without contact damping (``damping_ratio = 0``).
    """
    i = pair_i[q]
    j = pair_j[q]
    mu_base[q] = crack_friction(crack, broken, crack_mu, FROM_FACES)
    kt_pair[q] = min(kt_tri[i], kt_tri[j])
    if damping_ratio > 0.0:
        mi = mass_tri[i]
        mj = mass_tri[j]
        damp_pair[q] = 2.0 * damping_ratio * math.sqrt(mi * mj / (mi + mj))
    else:
        damp_pair[q] = 0.0


@njit(cache=True, error_model="numpy", inline="always")
def crack_friction(crack, broken, crack_mu, face):
    """The base friction of a pair: ``crack_mu[crack]`` when crack element ``crack`` between the
    two triangles is broken, else ``face`` (``crack = -1``: none)."""
    if crack >= 0 and broken[crack]:
        return crack_mu[crack]
    return face


@njit(cache=True, error_model="numpy", inline="always")
def crack_between(key, crack_keys, crack_order, start):
    """``(crack, r)``: the crack element whose sorted key ``i * n_tri + j`` is ``key`` (-1 if
    none), and ``r`` the first index of ``crack_keys`` at or after ``key``, searched forward
    from ``start`` (a merge over sorted keys: pass the last ``r``; 0 or any lower bound)."""
    r = start
    n = crack_keys.shape[0]
    while r < n and crack_keys[r] < key:
        r += 1
    return (crack_order[r] if r < n and crack_keys[r] == key else -1), r


@njit(cache=True, error_model="numpy")
def pair_constants(pair_i, pair_j, n_tri, crack_keys, crack_order, broken, crack_mu, any_broken, kt_tri,
                   mass_tri, damping_ratio):
    """``(mu_base, kt_pair, damp_pair)`` of every candidate pair (:func:`pair_constants_one`);
    the crack elements between pairs are found by one merge over the sorted keys (pairs sorted by
    ``(i, j)``, as every search makes them; a key out of order restarts by bisection)."""
    n = pair_i.shape[0]
    mu_base = np.empty(n)
    kt_pair = np.empty(n)
    damp_pair = np.empty(n)
    for q in range(n):
        pair_constants_one(q, pair_i, pair_j, -1, broken, crack_mu, kt_tri, mass_tri, damping_ratio,
                           mu_base, kt_pair, damp_pair)
    if any_broken:  # then the pairs across a crack element, found by one merge over the sorted keys
        r = 0
        last = -1
        for q in range(n):
            key = pair_i[q] * n_tri + pair_j[q]
            if key < last:
                r = lower_bound(crack_keys, key)
            crack, r = crack_between(key, crack_keys, crack_order, r)
            last = key
            if crack >= 0:
                mu_base[q] = crack_friction(crack, broken, crack_mu, mu_base[q])
    return mu_base, kt_pair, damp_pair


@njit(cache=True, error_model="numpy", inline="always")
def carry_row(q, a, old_hist, new_hist, has_hist):
    """The history of new pair ``q``: row ``a`` of the old pairs' (the same pair before the
    search), or zeros for a new pair (``a < 0``); ``has_hist[q] = 1`` where the row is nonzero."""
    flag = 0
    for r in range(new_hist.shape[1]):
        h = old_hist[a, r] if a >= 0 else 0.0
        new_hist[q, r] = h
        if h != 0.0:
            flag = 1
    has_hist[q] = flag


@njit(cache=True, error_model="numpy", inline="always")
def carry_history_one(q, old_keys, old_hist, new_keys, new_hist, has_hist):
    """:func:`carry_row` for pair ``q`` on its own (the GPU's loop, one thread a pair): the old
    pair with the same key found by bisection in the sorted ``old_keys``."""
    k = new_keys[q]
    a = lower_bound(old_keys, k)
    carry_row(q, a if a < old_keys.shape[0] and old_keys[a] == k else -1, old_hist, new_hist, has_hist)


@njit(cache=True, error_model="numpy")
def target_incidence(pair_j, slot_of_tri, n_active):
    """CSR of the pairs whose target (second triangle) is each active triangle (counting sort,
    O(n)): ``inc_pair[inc_ptr[a]:inc_ptr[a+1]]`` in pair order."""
    n = pair_j.shape[0]
    ptr = np.zeros(n_active + 1, np.int64)
    for q in range(n):
        ptr[slot_of_tri[pair_j[q]] + 1] += 1
    for a in range(n_active):
        ptr[a + 1] += ptr[a]
    fill = ptr[:-1].copy()
    inc = np.empty(n, np.int64)
    for q in range(n):
        b = slot_of_tri[pair_j[q]]
        inc[fill[b]] = q
        fill[b] += 1
    return ptr, inc


@njit(cache=True, error_model="numpy")
def carry_history(old_keys, old_hist, new_keys, new_hist, has_hist):
    """Copy the per-pair history rows of pairs that survive a re-search, zero the new ones
    (:func:`carry_row`; both key lists sorted: one merge pass, O(n)); ``has_hist[q] = 1`` where
    the row is nonzero."""
    a = 0
    na = old_keys.shape[0]
    for q in range(new_keys.shape[0]):
        k = new_keys[q]
        while a < na and old_keys[a] < k:
            a += 1
        carry_row(q, a if a < na and old_keys[a] == k else -1, old_hist, new_hist, has_hist)
