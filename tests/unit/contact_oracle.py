"""Test oracle: the distributed-potential pair law of :mod:`fdem.kernels.contact` evaluated from
the overlap's edges instead of by clipping the overlap polygon.

Each edge of the overlap is the part of one triangle's edge inside the other, found from the
separating-axis values, so no polygon is built; rare collinear edges fall back to clipping.
It measured 5 % faster than clipping on a compressed block and 10-15 % slower on a settled pile
(docs/benchmarks.md), so the pair loop clips; this independent evaluation checks it
(tests/unit/test_contact_kernel.py).
"""
from __future__ import annotations

from numba import njit

from fdem.kernels.contact_pairs import (CLOSE_TOL, FASTMATH, MAX_VERT, N_COL, N_IWORK, N_WORK, _NONE, _corners, _line_integrals, _overlap_clip, _sat)



@njit(cache=True, error_model="numpy")
def _sat_uv(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y):
    """The kernel's separating-axis test (:func:`fdem.kernels.contact._sat`) with the ``v``
    values too: ``v_kj = 2A_c lambda^c_j(t_k)`` are the ``u`` values of the swapped call, bit
    for bit (its differences are the exact negatives ``-D``, and ``(-a) x (-b) = a x b``).
    Returns ``(overlap?, u00, ..., u22, v00, ..., v22)``."""
    a = _sat(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y)
    b = _sat(t0x, t0y, t1x, t1y, t2x, t2y, c0x, c0y, c1x, c1y, c2x, c2y)
    return (a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9],
            b[1], b[2], b[3], b[4], b[5], b[6], b[7], b[8], b[9])

@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _span(a0, a1, a2, b0, b1, b2, strict):
    """Part ``[lo, hi]`` of ``s in [0, 1]`` where all three ``l_k(s) = a_k + s (b_k - a_k) >= 0``
    (an edge of one triangle inside the other: ``l`` the other's barycentrics times its
    ``2A``). ``strict``: a ``k`` with ``l_k = 0`` all along (the edge lies on the other's edge
    line) leaves nothing. Returns ``(lo, hi)``; nothing is left when ``hi <= lo``."""
    lo = 0.0
    hi = 1.0
    for k in range(3):
        a = a0 if k == 0 else (a1 if k == 1 else a2)
        b = b0 if k == 0 else (b1 if k == 1 else b2)
        if a < 0.0:
            if b < 0.0:
                return 1.0, 0.0
            lo = max(lo, a / (a - b))
        elif b < 0.0:
            hi = min(hi, a / (a - b))
        elif strict and a == 0.0 and b == 0.0:
            return 1.0, 0.0
    return lo, hi


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _edge_part(px, py, qx, qy, a0, a1, a2, b0, b1, b2, scale, strict):
    """The edge of D on the triangle edge ``p -> q``: the part where the other triangle's
    barycentrics, ``a_k`` at ``p`` and ``b_k`` at ``q`` (times its ``2A = 1 / scale``), are all
    ``>= 0``. Returns ``(ok, ax, ay, dx, dy, I_f, I_fs)``: start ``a``, direction ``d`` and the
    integrals of ``f = max(min_k lambda_k, 0)`` along it (:func:`_line_integrals`)."""
    lo, hi = _span(a0, a1, a2, b0, b1, b2, strict)
    if not hi > lo:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    ex = qx - px
    ey = qy - py
    h = hi - lo
    i_f, i_fs = _line_integrals(a0 + lo * (b0 - a0), a1 + lo * (b1 - a1), a2 + lo * (b2 - a2),
                                h * (b0 - a0), h * (b1 - a1), h * (b2 - a2))
    return True, px + lo * ex, py + lo * ey, h * ex, h * ey, i_f * scale, i_fs * scale


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def _add_edge(acc, ok, ax, ay, dx, dy, i_f, i_fs, c_owns, gtx, gty):
    """Add the terms of one overlap edge ``a -> a + d`` to the sums ``acc = (area2, mx6, my6,
    phi_c, phi_t, nx, ny, txx, txy, tyx, tyy, sum dx, sum dy, sum |dx| + |dy|)`` (module
    docstring, "Evaluation"; the last three check that the edges close)."""
    if not ok:
        return acc
    area2, mx6, my6, phi_c, phi_t, nx, ny, txx, txy, tyx, tyy, gx, gy, perim = acc
    cr = ax * dy - ay * dx                  # a x b: twice the fan from c's centroid
    area2 += cr
    mx6 += cr * (2.0 * ax + dx)
    my6 += cr * (2.0 * ay + dy)
    if c_owns:     # t's potential on c's boundary: fan from t's centroid
        phi_t += (cr - (gtx * dy - gty * dx)) * i_f
        sx = -dy
        sy = dx
    else:
        phi_c += cr * i_f
        sx = dy
        sy = -dx
    mx = ax * i_f + dx * i_fs
    my = ay * i_f + dy * i_fs
    return (area2, mx6, my6, phi_c, phi_t, nx + sx * i_f, ny + sy * i_f,
            txx + sx * mx, txy + sx * my, tyx + sy * mx, tyy + sy * my, gx + dx, gy + dy, perim + abs(dx) + abs(dy))


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _forces_from_sums(acc, gtx, gty, bc0x, bc0y, bc1x, bc1y, bc2x, bc2y, bt0x, bt0y, bt1x, bt1y, bt2x, bt2y,
                      penalty, w):
    """Nodal forces into ``w[0:12]`` and the :func:`pair_normal` tuple from the edge sums ``acc``
    (:func:`_add_edge`)."""
    area2, mx6, my6, phi_c, phi_t, nx, ny, txx, txy, tyx, tyy = acc[:11]
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


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def pair_normal_edges(x, i, j, penalty, w, iw, pool):
    """:func:`pair_normal` evaluated from the overlap's edges, without building the polygon
    (module docstring, "Evaluation" 2); an independent check of the per-pair law in the tests.

    Parameters
    ----------
    x : (n_nodes, 2) float64
        Node positions [m]; triangle ``t`` has nodes ``3t, 3t+1, 3t+2`` (counter-clockwise).
    i, j : int
        Contactor ``c`` and target ``t``.
    penalty : float
        ``p`` [Pa]; ``E = p int_D (phi_c + phi_t) dA``.
    w : (N_WORK,) float64, iw : (N_IWORK,) int64, pool : (MAX_VERT, N_COL) float64
        Work space (``iw`` and ``pool`` only for the fallback to clipping). On return
        ``w[0:12]`` holds the nodal forces on ``c`` (0:6) and ``t`` (6:12) [N/m] when the
        triangles overlap (it is not written otherwise).

    Returns
    -------
    (E, area, gx, gy, gtx, gty, bc0x, bc0y, bc1x, bc1y, bc2x, bc2y, bt0x, bt0y, bt1x, bt1y, bt2x, bt2y)
        Pair energy ``E`` [J/m]; overlap area [m^2] (0 when apart or touching: then nothing
        else is meaningful); overlap centroid ``(gx, gy)`` and t's centroid ``(gtx, gty)``, both
        relative to c's centroid [m]; the barycentric gradients ``b_k`` of c and of t [1/m]
        (``lambda_k = 1/3 + b_k . (x - G)``, for the friction point).
    """
    c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y = _corners(x, i, j)
    sat = _sat_uv(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y)
    if not sat[0]:
        return _NONE
    return _overlap(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y, sat, penalty, w, iw, pool)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def _overlap(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y, sat, penalty, w, iw, pool):
    """:func:`pair_normal` of a pair that passed the separating-axis test, from its corners and
    the separating-axis values ``u_ij = 2A_t lambda^t_j(c_i)``, ``v_kj = 2A_c lambda^c_j(t_k)``
    (``sat``, the tuple of :func:`_sat_uv`): no polygon is built. Every edge of the overlap
    ``D`` is the part of one triangle edge inside the other triangle (both convex), found from the other's barycentrics
    at the edge's two ends (linear along it), so the six edge parts are independent; a part of
    ``t``'s edge lying on a line of ``c``'s edge is left to ``c`` (``strict``), so that an edge
    the two triangles share is counted once. Where round-off decides the two sides of such a
    shared line differently (the edge parts then fail to close: a gap above ``CLOSE_TOL`` of
    the perimeter, seen only for edges collinear to round-off), the pair is evaluated by
    clipping instead (:func:`_overlap_clip`, work space ``iw``, ``pool``)."""
    (_, u00, u01, u02, u10, u11, u12, u20, u21, u22, v00, v01, v02, v10, v11, v12, v20, v21, v22) = sat
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
    p0x = c0x - ox
    p0y = c0y - oy
    p1x = c1x - ox
    p1y = c1y - oy
    p2x = c2x - ox
    p2y = c2y - oy
    q0x = t0x - ox
    q0y = t0y - oy
    q1x = t1x - ox
    q1y = t1y - oy
    q2x = t2x - ox
    q2y = t2y - oy
    acc = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    # c's edges (m opposite corner m, from corner m+1 to m+2) inside t; f from t's barycentrics
    r = _edge_part(p1x, p1y, p2x, p2y, u10, u11, u12, u20, u21, u22, it, False)
    acc = _add_edge(acc, r[0], r[1], r[2], r[3], r[4], r[5], r[6], True, gtx, gty)
    r = _edge_part(p2x, p2y, p0x, p0y, u20, u21, u22, u00, u01, u02, it, False)
    acc = _add_edge(acc, r[0], r[1], r[2], r[3], r[4], r[5], r[6], True, gtx, gty)
    r = _edge_part(p0x, p0y, p1x, p1y, u00, u01, u02, u10, u11, u12, it, False)
    acc = _add_edge(acc, r[0], r[1], r[2], r[3], r[4], r[5], r[6], True, gtx, gty)
    # t's edges inside c; f from c's barycentrics
    r = _edge_part(q1x, q1y, q2x, q2y, v10, v11, v12, v20, v21, v22, ic, True)
    acc = _add_edge(acc, r[0], r[1], r[2], r[3], r[4], r[5], r[6], False, gtx, gty)
    r = _edge_part(q2x, q2y, q0x, q0y, v20, v21, v22, v00, v01, v02, ic, True)
    acc = _add_edge(acc, r[0], r[1], r[2], r[3], r[4], r[5], r[6], False, gtx, gty)
    r = _edge_part(q0x, q0y, q1x, q1y, v00, v01, v02, v10, v11, v12, ic, True)
    acc = _add_edge(acc, r[0], r[1], r[2], r[3], r[4], r[5], r[6], False, gtx, gty)
    gap_x = acc[11]
    gap_y = acc[12]
    tol = CLOSE_TOL * acc[13]
    if gap_x * gap_x + gap_y * gap_y > tol * tol:
        return _overlap_by_clipping(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y, sat, penalty, w, iw,
                                    pool)
    return _forces_from_sums(acc, gtx, gty, bc0x, bc0y, bc1x, bc1y, bc2x, bc2y, bt0x, bt0y, bt1x, bt1y, bt2x, bt2y,
                             penalty, w)



@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def _overlap_by_clipping(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y, sat, penalty, w, iw, pool):
    """:func:`_overlap_clip` as a call of its own (the rare fallback of :func:`_overlap`)."""
    u00, u01, u02, u10, u11, u12, u20, u21, u22 = sat[1:10]
    return _overlap_clip(c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y,
                         u00, u01, u02, u10, u11, u12, u20, u21, u22, penalty, w, iw, pool)
