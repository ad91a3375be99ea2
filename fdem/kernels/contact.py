"""Numba kernels for triangle-triangle contact: binned-grid broad phase and pair forces.

Narrow phase: the distributed-potential penalty method of Munjiza & Andrews (2000), "Penalty
function method for combined finite-discrete element systems comprising large number of separate
bodies", IJNME 49:1377-1396; Munjiza (2004), *The Combined Finite-Discrete Element Method*, ch. 3.

Potential of a triangle (dimensionless)
---------------------------------------
With barycentric coordinates ``lambda_k(x) = a_k + b_k . x`` of the current triangle (``lambda_k``
belongs to corner ``k``; ``A_k = lambda_k A`` is the area of the sub-triangle between ``x`` and
the edge opposite ``k``)::

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

Evaluation (all integrals exact): the overlap ``D`` is built once as a closed polygon (``c``
clipped by ``t``'s half-planes; robust when edges touch, where it degenerates to zero area);
each edge of ``D`` lies on the boundary of ``c`` or of ``t``. One pass over those edges gives
both triangles' sector moments ``int_{D cap S_k} (1, x, y) dA`` (signed fans from each centroid,
split where the edge crosses a median) and the edge integrals of the other's potential
(products of linear functions between the kinks of ``min lambda``).

Parallelism: pair results are stored per pair and gathered per triangle (a triangle writes only
its own nodes), so there are no races and the forces are bitwise independent of the thread
count. Below ``PARALLEL_MIN_PAIRS`` pairs the per-step kernels run serially.

Units: coordinates [m], penalty [Pa], forces [N/m], energies [J/m] (plane, per unit thickness).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

# Layout of the per-pair output row of ``pair_normal`` (and of ``pair_force`` in the loop).
N_OUT = 16
"""out[0:6] forces on c's corners (x0, y0, x1, y1, x2, y2) [N/m]; out[6:12] forces on t's
corners; out[12] overlap area [m^2]; out[13:15] overlap centroid (local frame) [m]."""
MAX_POLY = 8
"""A triangle clipped by three half-planes has at most six corners; buffers hold eight."""
N_COL = 8
"""Columns of a polygon corner: x, y, the target's three and the contactor's three barycentrics."""
N_SCRATCH = 64
"""Length of the per-thread scratch vector of :func:`pair_normal`."""
PARALLEL_MIN_PAIRS = 4096
"""Below this many candidate pairs the per-step kernels run serially: waking the thread pool
costs more than the work (and far more on a loaded machine, where OpenMP workers spin)."""


# ----------------------------------------------------------------------------- geometry helpers
# Scratch layout of pair_normal (offsets into one float64 vector; no array views are made in
# the hot path: each view costs reference-count traffic).
_COEF = 0    # 18: (a, bx, by) of lambda_0..2 of c, then of t
_LAM = 18    # 18: t's lambdas at c's corners (3i + j), then c's lambdas at t's corners
_ACC_C = 36  # 9: (area, int x, int y) of D cap S_k of c, k = 0..2
_ACC_T = 45  # 9: the same for t


@njit(cache=True, error_model="numpy", inline="always")
def _bary_coeffs(pts, o, sc, co):
    """Barycentric coefficients of the triangle at ``pts[o:o+6]``: ``lambda_k = a + bx x + by y``.

    Writes ``sc[co + 3k : co + 3k + 3] = (a_k, bx_k, by_k)``. ``b_k = rot(P_{k+2} - P_{k+1}) / (2A)``
    is the inward normal of the edge opposite ``k`` divided by the altitude on it.
    """
    x0, y0, x1, y1, x2, y2 = pts[o], pts[o + 1], pts[o + 2], pts[o + 3], pts[o + 4], pts[o + 5]
    inv = 1.0 / ((x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0))
    # lambda_0 = cross(P1 - x, P2 - x) / 2A, and cyclic.
    sc[co + 0] = (x1 * y2 - x2 * y1) * inv
    sc[co + 1] = (y1 - y2) * inv
    sc[co + 2] = (x2 - x1) * inv
    sc[co + 3] = (x2 * y0 - x0 * y2) * inv
    sc[co + 4] = (y2 - y0) * inv
    sc[co + 5] = (x0 - x2) * inv
    sc[co + 6] = (x0 * y1 - x1 * y0) * inv
    sc[co + 7] = (y0 - y1) * inv
    sc[co + 8] = (x1 - x0) * inv


@njit(cache=True, error_model="numpy", inline="always")
def _clip(poly, sb, n, db, c):
    """Sutherland-Hodgman: keep the part of polygon ``poly[sb, :n]`` where column ``c`` is ``>= 0``.

    Rows are ``(x, y, lambda^t_0..2, lambda^c_0..2)``: each corner carries both triangles'
    barycentric coordinates, interpolated (exactly: they are affine) at new corners, so no
    half-plane is evaluated twice; the clipping column is set to exactly 0 on new corners.
    Writes ``poly[db]`` and returns its corner count.
    """
    m = 0
    p = n - 1
    dp = poly[sb, p, c]
    for i in range(n):
        dq = poly[sb, i, c]
        if (dq >= 0.0) != (dp >= 0.0):
            s = dp / (dp - dq)
            for r in range(N_COL):
                poly[db, m, r] = poly[sb, p, r] + s * (poly[sb, i, r] - poly[sb, p, r])
            poly[db, m, c] = 0.0
            m += 1
        if dq >= 0.0:
            for r in range(N_COL):
                poly[db, m, r] = poly[sb, i, r]
            m += 1
        p = i
        dp = dq
    return m


@njit(cache=True, error_model="numpy", inline="always")
def _pick(k, v0, v1, v2):
    return v0 if k == 0 else (v1 if k == 1 else v2)


@njit(cache=True, error_model="numpy", inline="always")
def _kinks(l0, l1, l2, d0, d1, d2):
    """Where ``min_j (l_j + s d_j)``, ``s in [0, 1]``, changes its argmin.

    The set where one coordinate is the smallest is convex, so the argmin along a segment
    visits each index at most once: equal argmins at both ends mean one piece; otherwise the
    two end indices cross once, unless the third is smaller there (then two kinks).
    Returns ``(s1, s2, k_first, k_middle, k_last)``: pieces ``[0, s1]``, ``[s1, s2]``,
    ``[s2, 1]`` (some possibly empty) with those argmins.
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
        return s, s, ka, ka, kb
    den = da - dm
    s1 = min(max((lm - la) / den, 0.0), 1.0) if den != 0.0 else 0.0
    den = dm - db
    s2 = min(max((lb - lm) / den, s1), 1.0) if den != 0.0 else s1
    return s1, s2, ka, km, kb


@njit(cache=True, error_model="numpy", inline="always")
def _fan(sc, acc, k, gx, gy, ux, uy, wx, wy):
    """Add the triangle ``(G, u, w)`` (``u``, ``w`` relative to ``G``) to the moments of sector k."""
    area = 0.5 * (ux * wy - uy * wx)
    sc[acc + 3 * k] += area
    sc[acc + 3 * k + 1] += area * (gx + (ux + wx) / 3.0)
    sc[acc + 3 * k + 2] += area * (gy + (uy + wy) / 3.0)


@njit(cache=True, error_model="numpy", inline="always")
def _piece(u, w, k, l0, l1, l2, d0, d1, d2, sc, acc_q, gqx, gqy, rx, ry, dx, dy):
    """One piece ``[u, w]`` of an overlap edge inside the other triangle's sector ``k``: add its
    fan to the moments at ``acc_q``; return ``(int f ds, int f s ds)`` of ``f = lambda^q_k``."""
    if w <= u:
        return 0.0, 0.0
    _fan(sc, acc_q, k, gqx, gqy, rx + u * dx, ry + u * dy, rx + w * dx, ry + w * dy)
    lk = _pick(k, l0, l1, l2)
    dk = _pick(k, d0, d1, d2)
    fu = max(lk + u * dk, 0.0)
    fw = max(lk + w * dk, 0.0)
    h = w - u
    return 0.5 * h * (fu + fw), h / 6.0 * (2.0 * fu * u + fu * w + fw * u + 2.0 * fw * w)


@njit(cache=True, error_model="numpy", inline="always")
def _edge_pass(poly, sb, a, b, gox, goy, gqx, gqy, lo, lq, sc, acc_o, acc_q, p3, out, q, fo, m_o):
    """Contributions of one edge ``a -> b`` of the overlap polygon ``poly[sb]``, lying on the
    boundary of the *owner* triangle ``o`` (its edge opposite corner ``m_o``), to both triangles.

    * owner's sector moments: the whole edge lies in the owner's sub-triangle ``m_o``;
    * other triangle ``q``'s sector moments: the edge split at the kinks of ``min lambda^q``;
    * owner's edge term ``-3p n int lambda^q_min lambda^o_i dGamma`` on the same pieces (exact:
      products of linear functions), ``n dGamma = (dy, -dx) ds``, added to ``out[q, fo:fo+6]``.

    ``(gox, goy)``, ``(gqx, gqy)``: centroids; ``lo``/``lq``: first columns of the owner's /
    other's barycentrics in ``poly``; ``acc_o``/``acc_q``: offsets of their moments in ``sc``.
    """
    ax = poly[sb, a, 0]
    ay = poly[sb, a, 1]
    bx = poly[sb, b, 0]
    by = poly[sb, b, 1]
    dx = bx - ax
    dy = by - ay
    _fan(sc, acc_o, m_o, gox, goy, ax - gox, ay - goy, bx - gox, by - goy)
    l0 = poly[sb, a, lq]
    l1 = poly[sb, a, lq + 1]
    l2 = poly[sb, a, lq + 2]
    d0 = poly[sb, b, lq] - l0
    d1 = poly[sb, b, lq + 1] - l1
    d2 = poly[sb, b, lq + 2] - l2
    s1, s2, k1, k2, k3 = _kinks(l0, l1, l2, d0, d1, d2)
    rx = ax - gqx
    ry = ay - gqy
    f1, fs1 = _piece(0.0, s1, k1, l0, l1, l2, d0, d1, d2, sc, acc_q, gqx, gqy, rx, ry, dx, dy)
    f2, fs2 = _piece(s1, s2, k2, l0, l1, l2, d0, d1, d2, sc, acc_q, gqx, gqy, rx, ry, dx, dy)
    f3, fs3 = _piece(s2, 1.0, k3, l0, l1, l2, d0, d1, d2, sc, acc_q, gqx, gqy, rx, ry, dx, dy)
    i_f = p3 * (f1 + f2 + f3)
    i_fs = p3 * (fs1 + fs2 + fs3)
    # owner's shape functions along the edge: g_i(s) = g_i(a) + s (g_i(b) - g_i(a))
    for i in range(3):
        ga = poly[sb, a, lo + i]
        val = ga * i_f + (poly[sb, b, lo + i] - ga) * i_fs
        out[q, fo + 2 * i] -= dy * val
        out[q, fo + 2 * i + 1] += dx * val


@njit(cache=True, error_model="numpy", inline="always")
def _area_terms(sc, co, acc, p3, out, q, fo):
    """Area term ``3p sum_k b_k int_{D cap S_k} lambda_i dA`` of one triangle's nodal forces;
    returns its part ``p int_D phi dA`` of the energy."""
    energy = 0.0
    for k in range(3):
        area = sc[acc + 3 * k]
        mx = sc[acc + 3 * k + 1]
        my = sc[acc + 3 * k + 2]
        bxk = p3 * sc[co + 3 * k + 1]
        byk = p3 * sc[co + 3 * k + 2]
        for i in range(3):
            ii = sc[co + 3 * i] * area + sc[co + 3 * i + 1] * mx + sc[co + 3 * i + 2] * my
            out[q, fo + 2 * i] += bxk * ii
            out[q, fo + 2 * i + 1] += byk * ii
        energy += p3 * (sc[co + 3 * k] * area + sc[co + 3 * k + 1] * mx + sc[co + 3 * k + 2] * my)
    return energy


# ----------------------------------------------------------------------------- per-pair laws
@njit(cache=True, error_model="numpy")
def pair_normal(pts, penalty, out, q, sc, poly):
    """Distributed-potential normal contact of one triangle pair (the per-pair law).

    Parameters
    ----------
    pts : (12,) float64
        Corners ``c0x, c0y, c1x, c1y, c2x, c2y, t0x, ..., t2y`` of contactor ``c`` and target
        ``t`` (both counter-clockwise) in a local frame near the pair [m].
    penalty : float
        ``p`` [Pa]; ``E = p int_D (phi_c + phi_t) dA``.
    out : (n, N_OUT) float64, q : int
        Row ``q`` is overwritten: nodal forces on ``c`` (0:6) and ``t`` (6:12) [N/m], overlap
        area (12) [m^2], overlap centroid (13:15) [m].
    sc : (N_SCRATCH,) float64, poly : (2, MAX_POLY, N_COL) float64
        Work space.

    Returns
    -------
    float
        Pair energy ``E`` [J/m]; 0 (and zero forces) when the triangles do not overlap.

    Steps: barycentric coefficients of both; separating-axis test (touching counts as apart);
    overlap polygon ``D`` = ``c`` clipped by ``t``'s three half-planes, each corner carrying
    both triangles' barycentrics (exact zeros on the clipping lines, so every edge of ``D``
    knows which triangle's boundary it lies on); one pass over the edges of ``D`` gives both
    triangles' sector moments (fans from their centroids) and edge integrals.
    """
    for i in range(N_OUT):
        out[q, i] = 0.0
    _bary_coeffs(pts, 0, sc, _COEF)
    _bary_coeffs(pts, 6, sc, _COEF + 9)
    for i in range(3):
        xc, yc = pts[2 * i], pts[2 * i + 1]
        xt, yt = pts[6 + 2 * i], pts[7 + 2 * i]
        for j in range(3):
            sc[_LAM + 3 * i + j] = sc[_COEF + 9 + 3 * j] + sc[_COEF + 10 + 3 * j] * xc + sc[_COEF + 11 + 3 * j] * yc
            sc[_LAM + 9 + 3 * i + j] = sc[_COEF + 3 * j] + sc[_COEF + 3 * j + 1] * xt + sc[_COEF + 3 * j + 2] * yt
    # separating-axis test on the six edges (touching counts as apart)
    for j in range(3):
        if sc[_LAM + j] <= 0.0 and sc[_LAM + 3 + j] <= 0.0 and sc[_LAM + 6 + j] <= 0.0:
            return 0.0
        if sc[_LAM + 9 + j] <= 0.0 and sc[_LAM + 12 + j] <= 0.0 and sc[_LAM + 15 + j] <= 0.0:
            return 0.0
    # overlap polygon: c clipped by t (columns 2:5 t's barycentrics, 5:8 c's)
    for i in range(3):
        poly[0, i, 0] = pts[2 * i]
        poly[0, i, 1] = pts[2 * i + 1]
        for j in range(3):
            poly[0, i, 2 + j] = sc[_LAM + 3 * i + j]
            poly[0, i, 5 + j] = 1.0 if i == j else 0.0
    n = 3
    sb = 0
    for j in range(3):
        lo = poly[sb, 0, 2 + j]
        for r in range(1, n):
            lo = min(lo, poly[sb, r, 2 + j])
        if lo < 0.0:  # this half-plane cuts (the SAT ruled out "all outside" for the triangle)
            n = _clip(poly, sb, n, 1 - sb, 2 + j)
            sb = 1 - sb
            if n < 3:
                return 0.0
    for r in range(18):
        sc[_ACC_C + r] = 0.0
    p3 = 3.0 * penalty
    gcx = (pts[0] + pts[2] + pts[4]) / 3.0
    gcy = (pts[1] + pts[3] + pts[5]) / 3.0
    gtx = (pts[6] + pts[8] + pts[10]) / 3.0
    gty = (pts[7] + pts[9] + pts[11]) / 3.0
    for a in range(n):
        b = a + 1 if a + 1 < n else 0
        # which boundary does the edge lie on? (exact zeros, see above)
        m_c = -1
        for m in range(3):
            if poly[sb, a, 5 + m] == 0.0 and poly[sb, b, 5 + m] == 0.0:
                m_c = m
        if m_c >= 0:
            _edge_pass(poly, sb, a, b, gcx, gcy, gtx, gty, 5, 2, sc, _ACC_C, _ACC_T, p3, out, q, 0, m_c)
            continue
        m_t = 0
        for m in range(3):
            if poly[sb, a, 2 + m] == 0.0 and poly[sb, b, 2 + m] == 0.0:
                m_t = m
        _edge_pass(poly, sb, a, b, gtx, gty, gcx, gcy, 2, 5, sc, _ACC_T, _ACC_C, p3, out, q, 6, m_t)
    area = sc[_ACC_C] + sc[_ACC_C + 3] + sc[_ACC_C + 6]
    if area <= 0.0:
        for i in range(12):
            out[q, i] = 0.0
        return 0.0
    out[q, 12] = area
    out[q, 13] = (sc[_ACC_C + 1] + sc[_ACC_C + 4] + sc[_ACC_C + 7]) / area
    out[q, 14] = (sc[_ACC_C + 2] + sc[_ACC_C + 5] + sc[_ACC_C + 8]) / area
    return _area_terms(sc, _COEF, _ACC_C, p3, out, q, 0) + _area_terms(sc, _COEF + 9, _ACC_T, p3, out, q, 6)


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
    return np.sign(f_trial) * cap, cap * (abs(f_trial) - cap) / kt


# ----------------------------------------------------------------------------- pair loop
@njit(cache=True, error_model="numpy")
def _load_pair(x, i, j, pts):
    """Corners of triangles i (c) and j (t) into ``pts`` relative to c's centroid; returns it."""
    ox = (x[3 * i, 0] + x[3 * i + 1, 0] + x[3 * i + 2, 0]) / 3.0
    oy = (x[3 * i, 1] + x[3 * i + 1, 1] + x[3 * i + 2, 1]) / 3.0
    for k in range(3):
        pts[2 * k] = x[3 * i + k, 0] - ox
        pts[2 * k + 1] = x[3 * i + k, 1] - oy
        pts[6 + 2 * k] = x[3 * j + k, 0] - ox
        pts[7 + 2 * k] = x[3 * j + k, 1] - oy
    return ox, oy


@njit(cache=True, error_model="numpy")
def _bary_at(x, t, px, py):
    """Barycentric coordinates of the point (px, py) in triangle t of ``x``."""
    x0, y0 = x[3 * t, 0], x[3 * t, 1]
    x1, y1 = x[3 * t + 1, 0], x[3 * t + 1, 1]
    x2, y2 = x[3 * t + 2, 0], x[3 * t + 2, 1]
    inv = 1.0 / ((x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0))
    l1 = ((px - x0) * (y2 - y0) - (py - y0) * (x2 - x0)) * inv
    l2 = ((x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)) * inv
    return 1.0 - l1 - l2, l1, l2


@njit(cache=True, error_model="numpy")
def _pair_range(lo, hi, x, v, pair_i, pair_j, penalty, mu, kt_ratio, damp, dt, spring, pair_force, touching):
    """The pair loop of :func:`pair_forces` over ``q in [lo, hi)``; returns the four energy sums."""
    pts = np.empty(12)
    scratch = np.empty(N_SCRATCH)
    poly = np.empty((2, MAX_POLY, N_COL))
    c_en = 0.0
    c_et = 0.0
    c_wf = 0.0
    c_wd = 0.0
    for q in range(lo, hi):
        i = pair_i[q]
        j = pair_j[q]
        ox, oy = _load_pair(x, i, j, pts)
        e = pair_normal(pts, penalty, pair_force, q, scratch, poly)
        if pair_force[q, 12] <= 0.0:
            touching[q] = 0
            for r in range(4):
                spring[q, r] = 0.0
            continue
        touching[q] = 1
        c_en += e
        pair_force[q, 13] += ox
        pair_force[q, 14] += oy
        fx = pair_force[q, 0] + pair_force[q, 2] + pair_force[q, 4]
        fy = pair_force[q, 1] + pair_force[q, 3] + pair_force[q, 5]
        fn = np.sqrt(fx * fx + fy * fy)
        if fn <= 0.0 or (mu[q] <= 0.0 and damp[q] <= 0.0):
            for r in range(4):
                spring[q, r] = 0.0
            continue
        nx = fx / fn
        ny = fy / fn
        px, py = pair_force[q, 13], pair_force[q, 14]
        a0, a1, a2 = _bary_at(x, i, px, py)
        b0, b1, b2 = _bary_at(x, j, px, py)
        vrx = (a0 * v[3 * i, 0] + a1 * v[3 * i + 1, 0] + a2 * v[3 * i + 2, 0]
               - b0 * v[3 * j, 0] - b1 * v[3 * j + 1, 0] - b2 * v[3 * j + 2, 0])
        vry = (a0 * v[3 * i, 1] + a1 * v[3 * i + 1, 1] + a2 * v[3 * i + 2, 1]
               - b0 * v[3 * j, 1] - b1 * v[3 * j + 1, 1] - b2 * v[3 * j + 2, 1])
        # secant normal stiffness of this pair now, k = F_n^2 / (2E) [Pa]: exact for a flat
        # overlap (E = k d^2 / 2), 3/4 of the tangent one for a corner; vanishes with the overlap
        k_sec = fn * fn / (2.0 * e) if e > 0.0 else 0.0
        gx = 0.0
        gy = 0.0
        if mu[q] > 0.0 and k_sec > 0.0:
            tx = -ny
            ty = nx
            sx, sy = spring[q, 0], spring[q, 1]
            smag = np.sqrt(sx * sx + sy * sy)
            ft = smag if sx * tx + sy * ty >= 0.0 else -smag  # rotate into the new tangent
            kt = kt_ratio * k_sec
            ft, wf = tangential_law(ft, (vrx * tx + vry * ty) * dt, kt, mu[q] * fn)
            spring[q, 0] = ft * tx
            spring[q, 1] = ft * ty
            c_et += 0.5 * ft * ft / kt
            c_wf += wf
            gx += ft * tx
            gy += ft * ty
        else:
            spring[q, 0] = 0.0
            spring[q, 1] = 0.0
        if damp[q] > 0.0 and k_sec > 0.0:
            vn = vrx * nx + vry * ny
            # leapfrog-consistent dissipation: the work of a force applied at step n is
            # F_n . (v_{n-1/2} + v_{n+1/2}) dt / 2; the second half of last step's is booked now
            c_wd -= 0.5 * (spring[q, 2] * vrx + spring[q, 3] * vry) * dt
            fd = max(-damp[q] * np.sqrt(k_sec) * vn, -fn)  # never pull beyond the elastic push
            c_wd -= 0.5 * fd * vn * dt
            spring[q, 2] = fd * nx
            spring[q, 3] = fd * ny
            gx += fd * nx
            gy += fd * ny
        else:
            spring[q, 2] = 0.0
            spring[q, 3] = 0.0
        pair_force[q, 0] += a0 * gx
        pair_force[q, 1] += a0 * gy
        pair_force[q, 2] += a1 * gx
        pair_force[q, 3] += a1 * gy
        pair_force[q, 4] += a2 * gx
        pair_force[q, 5] += a2 * gy
        pair_force[q, 6] -= b0 * gx
        pair_force[q, 7] -= b0 * gy
        pair_force[q, 8] -= b1 * gx
        pair_force[q, 9] -= b1 * gy
        pair_force[q, 10] -= b2 * gx
        pair_force[q, 11] -= b2 * gy
    return c_en, c_et, c_wf, c_wd


@njit(parallel=True, cache=True, error_model="numpy")
def _pair_chunks_parallel(x, v, pair_i, pair_j, penalty, mu, kt_ratio, damp, dt, spring, pair_force, touching,
                          n_chunks):
    """Parallel driver of :func:`pair_forces`: (n_chunks, 4) energy sums per chunk of pairs."""
    n = pair_i.shape[0]
    sums = np.zeros((n_chunks, 4))
    for ch in prange(n_chunks):
        a, b, c, d = _pair_range(ch * n // n_chunks, (ch + 1) * n // n_chunks, x, v, pair_i, pair_j, penalty,
                                 mu, kt_ratio, damp, dt, spring, pair_force, touching)
        sums[ch, 0] = a
        sums[ch, 1] = b
        sums[ch, 2] = c
        sums[ch, 3] = d
    return sums


@njit(cache=True, error_model="numpy")
def _pair_chunks_serial(x, v, pair_i, pair_j, penalty, mu, kt_ratio, damp, dt, spring, pair_force, touching,
                        n_chunks):
    """Serial twin of :func:`_pair_chunks_parallel` (same chunks, so the same bits)."""
    n = pair_i.shape[0]
    sums = np.zeros((n_chunks, 4))
    for ch in range(n_chunks):
        a, b, c, d = _pair_range(ch * n // n_chunks, (ch + 1) * n // n_chunks, x, v, pair_i, pair_j, penalty,
                                 mu, kt_ratio, damp, dt, spring, pair_force, touching)
        sums[ch, 0] = a
        sums[ch, 1] = b
        sums[ch, 2] = c
        sums[ch, 3] = d
    return sums


@njit(cache=True, error_model="numpy")
def pair_forces(x, v, pair_i, pair_j, penalty, mu, kt_ratio, damp, dt, spring, pair_force, touching):
    """Contact forces of all candidate pairs, stored per pair (race-free; gather afterwards).

    Parameters
    ----------
    x, v : (n_nodes, 2) float64
        Positions [m] and velocities [m/s] of the exploded nodes.
    pair_i, pair_j : (n_pairs,) int64
        Triangles of each candidate pair (``i < j``; ``i`` plays contactor ``c``).
    penalty : float
        Normal penalty ``p`` [Pa].
    mu : (n_pairs,) float64
        Coulomb coefficient ``tan(phi)`` of each pair; 0 skips the friction branch.
    kt_ratio : float
        Tangential stiffness of a pair as a fraction of its current secant normal stiffness
        ``k = F_n^2 / (2 E)`` [-] (so the elastic pre-slip ``mu F_n / k_t`` is ``mu / kt_ratio``
        times the normal penetration, and vanishes with it as ``p`` grows).
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
    pair_force : (n_pairs, N_OUT) float64
        Overwritten: row as in :func:`pair_normal` (forces include friction and damping).
    touching : (n_pairs,) uint8
        Overwritten: 1 where the pair overlaps (its forces need gathering).

    Returns
    -------
    (E_normal, E_tangential, W_friction, W_damping) : floats [J/m]
        Normal contact energy and tangential spring energy ``|F_t|^2 / (2 k_t)`` now; frictional
        and damping work dissipated during this step.
    """
    n = pair_i.shape[0]
    # chunking depends on n only, so sums (and forces) are bitwise independent of the thread count
    n_chunks = min(1024, max(1, n // 128))
    if n >= PARALLEL_MIN_PAIRS:
        sums = _pair_chunks_parallel(x, v, pair_i, pair_j, penalty, mu, kt_ratio, damp, dt, spring, pair_force,
                                     touching, n_chunks)
    else:
        sums = _pair_chunks_serial(x, v, pair_i, pair_j, penalty, mu, kt_ratio, damp, dt, spring, pair_force,
                                   touching, n_chunks)
    # sequential sum in chunk order: bitwise the same for any thread count
    e = np.zeros(4)
    for ch in range(sums.shape[0]):
        for r in range(4):
            e[r] += sums[ch, r]
    return e[0], e[1], e[2], e[3]


@njit(cache=True, error_model="numpy", inline="always")
def _gather_one(f, t, r0, r1, inc_code, pair_force, touching):
    for r in range(r0, r1):
        code = inc_code[r]
        q = code >> 1
        if touching[q] == 0:
            continue
        o = 6 * (code & 1)
        for k in range(3):
            f[3 * t + k, 0] += pair_force[q, o + 2 * k]
            f[3 * t + k, 1] += pair_force[q, o + 2 * k + 1]


@njit(parallel=True, cache=True, error_model="numpy")
def _gather_parallel(f, active, inc_ptr, inc_code, pair_force, touching):
    for a in prange(active.shape[0]):
        _gather_one(f, active[a], inc_ptr[a], inc_ptr[a + 1], inc_code, pair_force, touching)


@njit(cache=True, error_model="numpy")
def gather_forces(f, active, inc_ptr, inc_code, pair_force, touching):
    """Add stored pair forces to the nodes: ``f[3t+k] += sum over t's pairs`` (race-free).

    ``active`` (n_act,) triangle ids; their incident pairs are ``inc_code[inc_ptr[a]:inc_ptr[a+1]]``
    with ``code = 2 * pair + side`` (side 0: the triangle is the pair's ``c``, 1: its ``t``).
    Each triangle writes only its own three nodes. Small sets run serially.
    """
    if inc_code.shape[0] >= 2 * PARALLEL_MIN_PAIRS:
        _gather_parallel(f, active, inc_ptr, inc_code, pair_force, touching)
    else:
        for a in range(active.shape[0]):
            _gather_one(f, active[a], inc_ptr[a], inc_ptr[a + 1], inc_code, pair_force, touching)


# ----------------------------------------------------------------------------- broad phase
@njit(cache=True, error_model="numpy")
def triangle_boxes(x, active, margin):
    """(n_act, 4) axis-aligned boxes ``[xmin, ymin, xmax, ymax]`` of triangles, grown by ``margin``."""
    n = active.shape[0]
    box = np.empty((n, 4))
    for a in range(n):
        t = active[a]
        x0, x1, x2 = x[3 * t, 0], x[3 * t + 1, 0], x[3 * t + 2, 0]
        y0, y1, y2 = x[3 * t, 1], x[3 * t + 1, 1], x[3 * t + 2, 1]
        box[a, 0] = min(x0, min(x1, x2)) - margin
        box[a, 1] = min(y0, min(y1, y2)) - margin
        box[a, 2] = max(x0, max(x1, x2)) + margin
        box[a, 3] = max(y0, max(y1, y2)) + margin
    return box


@njit(cache=True, error_model="numpy")
def _boxes_overlap(box, a, b):
    return (box[a, 0] <= box[b, 2] and box[b, 0] <= box[a, 2]
            and box[a, 1] <= box[b, 3] and box[b, 1] <= box[a, 3])


@njit(cache=True, error_model="numpy")
def _bonded(bond, i, j):
    return bond[i, 0] == j or bond[i, 1] == j or bond[i, 2] == j


@njit(cache=True, error_model="numpy")
def brute_force_pairs(box, active, bond):
    """Reference broad phase, O(n^2): all ``(i, j)``, ``i < j``, of active triangles whose grown
    boxes overlap and that are not bonded by an intact crack element, sorted by ``(i, j)``.

    ``active`` must be sorted ascending; ``bond[t]`` lists the (up to 3) triangles bonded to t, -1
    padded.
    """
    n = active.shape[0]
    cnt = 0
    for a in range(n):
        for b in range(a + 1, n):
            if _boxes_overlap(box, a, b) and not _bonded(bond, active[a], active[b]):
                cnt += 1
    pi = np.empty(cnt, np.int64)
    pj = np.empty(cnt, np.int64)
    cnt = 0
    for a in range(n):
        for b in range(a + 1, n):
            if _boxes_overlap(box, a, b) and not _bonded(bond, active[a], active[b]):
                pi[cnt] = active[a]
                pj[cnt] = active[b]
                cnt += 1
    return pi, pj


@njit(cache=True, error_model="numpy")
def _grid_bin(box, cell, max_cells):
    """Grid geometry and the counting sort of boxes into every cell they cover.

    Returns ``(x0, y0, cell, nx, ny, cell_ptr, cell_items)``; ``cell`` is enlarged when the
    requested one would make more than ``max_cells`` cells.
    """
    n = box.shape[0]
    x0 = np.inf
    y0 = np.inf
    x1 = -np.inf
    y1 = -np.inf
    for a in range(n):
        x0 = min(x0, box[a, 0])
        y0 = min(y0, box[a, 1])
        x1 = max(x1, box[a, 2])
        y1 = max(y1, box[a, 3])
    w = max(x1 - x0, 1e-300)
    h = max(y1 - y0, 1e-300)
    if (w / cell + 1.0) * (h / cell + 1.0) > max_cells:
        cell = max(cell, np.sqrt(w * h / max_cells), w / max_cells, h / max_cells) * 1.0001
    nx = int(w / cell) + 1
    ny = int(h / cell) + 1
    cell_cnt = np.zeros(nx * ny + 1, np.int64)
    for a in range(n):
        ix0 = int((box[a, 0] - x0) / cell)
        ix1 = int((box[a, 2] - x0) / cell)
        iy0 = int((box[a, 1] - y0) / cell)
        iy1 = int((box[a, 3] - y0) / cell)
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                cell_cnt[iy * nx + ix + 1] += 1
    for c in range(nx * ny):
        cell_cnt[c + 1] += cell_cnt[c]
    cell_ptr = cell_cnt.copy()
    cell_items = np.empty(cell_ptr[nx * ny], np.int64)
    fill = cell_cnt[:-1].copy()
    for a in range(n):
        ix0 = int((box[a, 0] - x0) / cell)
        ix1 = int((box[a, 2] - x0) / cell)
        iy0 = int((box[a, 1] - y0) / cell)
        iy1 = int((box[a, 3] - y0) / cell)
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                c = iy * nx + ix
                cell_items[fill[c]] = a
                fill[c] += 1
    return x0, y0, cell, nx, ny, cell_ptr, cell_items


@njit(cache=True, error_model="numpy")
def _query(a, box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items, outj, write):
    """Partners ``b`` of box ``a`` with ``active[b] > active[a]``: each pair is reported once, from
    the cell holding the lower-left corner of the two boxes' intersection. Returns the count."""
    ix0 = int((box[a, 0] - x0) / cell)
    ix1 = int((box[a, 2] - x0) / cell)
    iy0 = int((box[a, 1] - y0) / cell)
    iy1 = int((box[a, 3] - y0) / cell)
    ta = active[a]
    cnt = 0
    for iy in range(iy0, iy1 + 1):
        for ix in range(ix0, ix1 + 1):
            c = iy * nx + ix
            for r in range(cell_ptr[c], cell_ptr[c + 1]):
                b = cell_items[r]
                tb = active[b]
                if tb <= ta or not _boxes_overlap(box, a, b):
                    continue
                cx = int((max(box[a, 0], box[b, 0]) - x0) / cell)
                cy = int((max(box[a, 1], box[b, 1]) - y0) / cell)
                if cx != ix or cy != iy or _bonded(bond, ta, tb):
                    continue
                if write:
                    outj[cnt] = tb
                cnt += 1
    return cnt


@njit(cache=True, error_model="numpy")
def _fill_partners(a, lo, hi, box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items, pi, pj):
    """Write box ``a``'s partners into ``pj[lo:hi]`` sorted (insertion sort: they are few)."""
    if hi == lo:
        return
    seg = pj[lo:hi]
    _query(a, box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items, seg, True)
    for r in range(1, hi - lo):
        val = seg[r]
        s = r - 1
        while s >= 0 and seg[s] > val:
            seg[s + 1] = seg[s]
            s -= 1
        seg[s + 1] = val
    for r in range(lo, hi):
        pi[r] = active[a]


@njit(parallel=True, cache=True, error_model="numpy")
def _grid_query_parallel(box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items, counts):
    n = box.shape[0]
    dummy = np.empty(0, np.int64)
    for a in prange(n):
        counts[a + 1] = _query(a, box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items, dummy, False)
    for a in range(n):
        counts[a + 1] += counts[a]
    pi = np.empty(counts[n], np.int64)
    pj = np.empty(counts[n], np.int64)
    for a in prange(n):
        _fill_partners(a, counts[a], counts[a + 1], box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items,
                       pi, pj)
    return pi, pj


@njit(cache=True, error_model="numpy")
def grid_pairs(box, active, bond, cell, max_cells):
    """Linear-time broad phase on a uniform grid (counting sort of boxes into cells).

    Same result as :func:`brute_force_pairs` (same box test, same bond exclusion), for any cell
    size. Pairs come out sorted by ``(i, j)`` because ``active`` is sorted and each triangle's
    partners are sorted. Cost O(n) for a cell about the size of a box. The queries run in
    parallel for large sets (two passes: count, then fill).
    """
    n = box.shape[0]
    if n < 2:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    x0, y0, cell, nx, ny, cell_ptr, cell_items = _grid_bin(box, cell, max_cells)
    counts = np.zeros(n + 1, np.int64)
    if n >= PARALLEL_MIN_PAIRS // 4:
        return _grid_query_parallel(box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items, counts)
    dummy = np.empty(0, np.int64)
    for a in range(n):
        counts[a + 1] = counts[a] + _query(a, box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items, dummy,
                                           False)
    pi = np.empty(counts[n], np.int64)
    pj = np.empty(counts[n], np.int64)
    for a in range(n):
        _fill_partners(a, counts[a], counts[a + 1], box, active, bond, x0, y0, cell, nx, cell_ptr, cell_items,
                       pi, pj)
    return pi, pj


@njit(cache=True, error_model="numpy")
def pair_incidence(pair_i, pair_j, slot_of_tri, n_active):
    """CSR of pairs per active triangle: ``code = 2 * pair + side`` (counting sort, O(n))."""
    n = pair_i.shape[0]
    ptr = np.zeros(n_active + 1, np.int64)
    for q in range(n):
        ptr[slot_of_tri[pair_i[q]] + 1] += 1
        ptr[slot_of_tri[pair_j[q]] + 1] += 1
    for a in range(n_active):
        ptr[a + 1] += ptr[a]
    fill = ptr[:-1].copy()
    code = np.empty(2 * n, np.int64)
    for q in range(n):
        a = slot_of_tri[pair_i[q]]
        code[fill[a]] = 2 * q
        fill[a] += 1
        b = slot_of_tri[pair_j[q]]
        code[fill[b]] = 2 * q + 1
        fill[b] += 1
    return ptr, code


@njit(cache=True, error_model="numpy")
def carry_history(old_keys, old_hist, new_keys, new_hist):
    """Copy the per-pair history rows of pairs that survive a re-search, zero the new ones
    (both key lists sorted; one merge pass, O(n))."""
    a = 0
    na = old_keys.shape[0]
    nc = new_hist.shape[1]
    for q in range(new_keys.shape[0]):
        k = new_keys[q]
        while a < na and old_keys[a] < k:
            a += 1
        if a < na and old_keys[a] == k:
            for r in range(nc):
                new_hist[q, r] = old_hist[a, r]
        else:
            for r in range(nc):
                new_hist[q, r] = 0.0


@njit(cache=True, error_model="numpy")
def max_displacement(x, x_ref, active):
    """Largest ``|x - x_ref|`` over the nodes of the active triangles [m] (serial: memory-bound,
    one pass, cheaper than waking threads)."""
    m = 0.0
    for a in range(active.shape[0]):
        t = active[a]
        for k in range(3):
            dx = x[3 * t + k, 0] - x_ref[3 * t + k, 0]
            dy = x[3 * t + k, 1] - x_ref[3 * t + k, 1]
            m = max(m, dx * dx + dy * dy)
    return np.sqrt(m)
