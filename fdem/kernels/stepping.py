"""Explicit central-difference step fused with the triangle forces (numba).

Leapfrog form of central differences (Belytschko et al. 2014, sec. 6.2): positions ``x_n`` at
whole steps, velocities ``v_{n-1/2}`` at half steps,

    m (v_{n+1/2} - v_{n-1/2}) / dt = f_n + f_damping,      x_{n+1} = x_n + dt v_{n+1/2},

with ``f_n = f_triangles(x_n, v_{n-1/2}) + f_interaction + m g + f_external``.

Damping, both off by default (dynamic phases):

* mass-proportional ``f = -alpha m v`` with the velocity taken at mid-step,
  ``(v_{n-1/2} + v_{n+1/2}) / 2``, which gives
  ``v_{n+1/2} = ((1 - alpha dt/2) v_{n-1/2} + dt f/m) / (1 + alpha dt/2)`` (no stability cost);
* local non-viscous (Cundall 1987; Itasca FLAC/UDEC "local damping"): per degree of freedom
  ``f = -beta |f_n| sign(v_{n-1/2})``, a fraction ``beta`` of the unbalanced force opposing the motion.

Constrained degrees of freedom (``flags`` bit 0: x, bit 1: y) take the prescribed velocity
``v_prescribed``; a fixed support is a prescribed velocity of zero.

Energy ledger, consistent with the scheme (exact for linear forces): the kinetic energy at
step n is ``K_n = sum m v_{n-1/2} . v_{n+1/2} / 2``, and a non-conservative force ``f_n``
does the work ``f_n . (x_{n+1} - x_{n-1}) / 2 = f_n . dt (v_{n-1/2} + v_{n+1/2}) / 2`` in step n;
then ``K_{n+1} - K_n`` equals the trapezoidal work of all forces over ``[x_n, x_{n+1}]``.
Every step returns the sums the solver needs; see :class:`StepSums`.
"""
from __future__ import annotations

from typing import NamedTuple

from numba import njit, prange
from fdem.kernels.triangles import (FASTMATH, TC_B00, TC_B01, TC_B10, TC_B11, TC_INV_MASS, TC_LAM, TC_MASS, TC_MU, TC_S0XX, TC_S0XY, TC_S0YY, corner_forces, svk_piola, triangle_response, velocity_gradient_power)

__all__ = ["StepSums", "LEDGER_FIELDS", "damped_velocity", "constrain_and_move", "advance_node", "BLOCK", "block_span",
           "n_blocks",
           "triangle_step", "step_exploded", "advance_node_elastic", "step_exploded_elastic", "triangle_pass", "viscous_power",
           "node_pass"]


class StepSums(NamedTuple):
    """What one step returns, by name: every step path (fused exploded, fast elastic, conforming
    two-pass) hands the solver these fields in this order.

    * ``strain``: elastic strain energy at ``x_n`` [J/m] (0 on steps that skip the energies);
    * ``kinetic``: ``sum m v_{n-1/2} . v_{n+1/2} / 2`` [J/m];
    * ``gravity_moment``: ``sum m g . x_n`` (the gravitational potential is minus its change) [J/m];
    * ``external_moment``: ``sum f_ext . x_n`` (constant external loads, same convention) [J/m];
    * ``<kind>_early`` / ``<kind>_late``: the halves ``f_n . dt v_{n-1/2} / 2`` and
      ``f_n . dt v_{n+1/2} / 2`` of the step's work for each non-conservative force kind:
      ``damping`` and ``viscous`` as energy *dissipated* (minus the work), ``reaction`` (supports
      and prescribed velocities) and ``interaction`` (providers) as work done *on* the body [J/m].
      The ledger needs the halves to stay exact: with ``K_n`` as above,
      ``K_N + U_N - K_0 - U_0 = sum_{n<N} (early_n + late_n) + early_N - early_0`` for linear forces;
    * ``n_inverted``: number of triangles with ``det F <= 0`` (or NaN) at ``x_n``.
    """

    strain: float
    kinetic: float
    gravity_moment: float
    external_moment: float
    damping_early: float
    damping_late: float
    viscous_early: float
    viscous_late: float
    reaction_early: float
    reaction_late: float
    interaction_early: float
    interaction_late: float
    n_inverted: int


LEDGER_FIELDS = StepSums._fields
"""Names of the values :func:`step_exploded` returns, in order (the fields of :class:`StepSums`)."""


@njit(fastmath=FASTMATH, cache=True, inline="always")
def damped_velocity(u, force, mass, inv_mass, dt, alpha, c_keep, c_div, local):
    """``v_{n+1/2}`` of one degree of freedom with mass-proportional and local damping, and the damping force.

    ``u = v_{n-1/2}``; ``force`` is the unbalanced force without damping [N/m];
    ``c_keep = 1 - alpha dt/2``, ``c_div = 1 / (1 + alpha dt/2)``. The damping force
    ``-beta |f| sign(u) - alpha m (u + v_new)/2`` [N/m] is returned for the ledger.
    """
    sgn = (u > 0.0) * 1.0 - (u < 0.0) * 1.0
    f_local = -local * abs(force) * sgn
    n = (c_keep * u + dt * inv_mass * (force + f_local)) * c_div
    return n, f_local - alpha * mass * 0.5 * (u + n)


@njit(fastmath=FASTMATH, cache=True, inline="always")
def constrain_and_move(x, u, v, i, px, py, ux, uy, nx, ny, gdx, gdy, fx, fy, mass, dt, flags, v_prescribed):
    """Apply node ``i``'s prescribed velocities to its new velocity ``(nx, ny)``, then write
    ``v[i]``, ``x[i] = (px, py) + dt v`` and the displacement ``u[i] += dt v``.

    ``u`` is kept apart from ``x`` (both advanced by the same ``dt v``) because the crack
    elements read it: two nodes that start together are then separated to the round-off of
    ``u``, not of ``x`` (:mod:`fdem.kernels.cracks`, "ref"). ``x`` and ``x0 + u`` agree to the
    round-off of ``x``.

    A prescribed component takes its value and drops its damping force; the support supplies the
    reaction ``r = m (v_p - u)/dt - f`` whose work is booked in half-steps, ``dt/2 r u`` (early)
    and ``dt/2 r v_p`` (late). Returns ``(nx, ny, gdx, gdy, reaction_early, reaction_late)``.
    """
    h = 0.5 * dt
    re = 0.0
    rl = 0.0
    flag = flags[i]
    if flag != 0:
        if flag & 1:
            vp = v_prescribed[i, 0]
            r = mass * (vp - ux) / dt - fx
            nx = vp
            gdx = 0.0
            re += h * r * ux
            rl += h * r * vp
        if flag & 2:
            vp = v_prescribed[i, 1]
            r = mass * (vp - uy) / dt - fy
            ny = vp
            gdy = 0.0
            re += h * r * uy
            rl += h * r * vp
    v[i, 0] = nx
    v[i, 1] = ny
    x[i, 0] = px + dt * nx
    x[i, 1] = py + dt * ny
    u[i, 0] += dt * nx
    u[i, 1] += dt * ny
    return nx, ny, gdx, gdy, re, rl


@njit(fastmath=FASTMATH, cache=True, inline="always")
def damping_factors(alpha, dt):
    """``(c_keep, c_div) = (1 - alpha dt/2, 1 / (1 + alpha dt/2))``: the factors of the
    central-difference update with mass-proportional damping ``alpha`` [1/s] (:func:`damped_velocity`)."""
    h = 0.5 * alpha * dt
    return 1.0 - h, 1.0 / (1.0 + h)


@njit(fastmath=FASTMATH, cache=True, inline="always")
def move_node(x, u, v, i, px, py, fx, fy, gmass, mass, inv_mass, gx, gy, use_ext, ex, ey, dt, damped, alpha, c_keep,
              c_div, local, flags, v_prescribed):
    """The central-difference update of node ``i``: the one law of every step kernel.

    ``v_{n+1/2} = v_{n-1/2} + dt (f + m_g g + f_ext) / m`` (damped by :func:`damped_velocity` if
    ``damped``), then the supports and ``x_{n+1} = x_n + dt v_{n+1/2}``
    (:func:`constrain_and_move`). ``(fx, fy)`` is the node's internal force with the interaction
    force already added [N/m], ``(ex, ey)`` the external load (added if ``use_ext``), ``gmass`` the gravitational and
    ``mass`` (``1 / inv_mass``) the inertial mass (different in a density-scaled stage), ``(px,
    py) = x[i]`` (the caller has it in registers). The forces are summed in one order (internal
    and interaction, then gravity, then external), so every kernel moves a node bit for bit alike.
    Returns ``(v_new_x, v_new_y, v_old_x, v_old_y, damping_force_x, damping_force_y,
    reaction_early, reaction_late)``.
    """
    ux, uy = v[i, 0], v[i, 1]
    fx += gmass * gx
    fy += gmass * gy
    if use_ext:
        fx += ex
        fy += ey
    if damped:
        nx, gdx = damped_velocity(ux, fx, mass, inv_mass, dt, alpha, c_keep, c_div, local)
        ny, gdy = damped_velocity(uy, fy, mass, inv_mass, dt, alpha, c_keep, c_div, local)
    else:
        nx = ux + dt * inv_mass * fx
        ny = uy + dt * inv_mass * fy
        gdx = 0.0
        gdy = 0.0
    nx, ny, gdx, gdy, re, rl = constrain_and_move(x, u, v, i, px, py, ux, uy, nx, ny, gdx, gdy, fx, fy, mass, dt,
                                                  flags, v_prescribed)
    return nx, ny, ux, uy, gdx, gdy, re, rl


@njit(fastmath=FASTMATH, cache=True, inline="always")
def advance_node(x, u, v, i, fx, fy, gmass, mass, inv_mass, gx, gy, dt, alpha, c_keep, c_div, local, damped,
                 f_int, use_int, f_ext, use_ext, flags, v_prescribed, ledger):
    """:func:`move_node` with the energies of the ledger: node ``i`` given the force ``(fx, fy)``
    of its triangle(s), plus the interaction force (if ``use_int``) and the external load (if
    ``use_ext``). Returns ``(v_new_x, v_new_y, kinetic, gravity_moment, external_moment,
    damping_early, damping_late, reaction_early, reaction_late, interaction_early,
    interaction_late)`` (halves already multiplied by ``dt/2``); the moments are computed only
    if ``ledger``, the kinetic energy every step (a few flops: it lets the solver follow the
    kinetic energy's peak step by step).
    """
    px, py = x[i, 0], x[i, 1]
    h = 0.5 * dt
    ix = 0.0
    iy = 0.0
    if use_int:
        ix = f_int[i, 0]
        iy = f_int[i, 1]
        fx += ix
        fy += iy
    ex = 0.0
    ey = 0.0
    if use_ext:
        ex = f_ext[i, 0]
        ey = f_ext[i, 1]
    nx, ny, ux, uy, gdx, gdy, re, rl = move_node(x, u, v, i, px, py, fx, fy, gmass, mass, inv_mass, gx, gy, use_ext, ex, ey,
                                                 dt, damped, alpha, c_keep, c_div, local, flags, v_prescribed)
    de = 0.0
    dl = 0.0
    if damped:
        de = -h * (gdx * ux + gdy * uy)
        dl = -h * (gdx * nx + gdy * ny)
    ie = 0.0
    il = 0.0
    if use_int:
        ie = h * (ix * ux + iy * uy)
        il = h * (ix * nx + iy * ny)
    kinetic = 0.5 * mass * (ux * nx + uy * ny)
    gmom = 0.0
    emom = 0.0
    if ledger:
        gmom = gmass * (gx * px + gy * py)
        emom = ex * px + ey * py
    return nx, ny, kinetic, gmom, emom, de, dl, re, rl, ie, il


BLOCK = 1024
"""Triangles (or nodes) per parallel work item: each block keeps its ledger sums in registers
and writes them once, which is much faster than one parallel reduction per sum."""


@njit(cache=True, inline="always")
def block_span(blk, n_tri, ranges):
    """Triangles ``[t_lo, t_hi)`` of block ``blk`` of a step kernel: the ``blk``-th run of
    :data:`BLOCK` triangles, or row ``blk`` of ``ranges`` (the awake runs of a sleeping
    scene, :mod:`fdem.solve.sleeping`) when given."""
    if ranges is None:
        return blk * BLOCK, min(n_tri, (blk + 1) * BLOCK)
    return ranges[blk, 0], ranges[blk, 1]


def n_blocks(n: int) -> int:
    """Number of work items of :data:`BLOCK` entries covering ``n`` entries."""
    return max(1, -(-n // BLOCK))


@njit(fastmath=FASTMATH, cache=True, inline="always")
def triangle_step(x, u, v, tc, t, inertia, f_int, use_int, f_ext, use_ext, flags, v_prescribed, gx, gy, dt, alpha,
                  c_keep, c_div, local, damped, use_viscous, ledger):
    """One triangle of an exploded mesh: its forces at ``x_n`` and the central-difference update
    of its own three nodes ``3t, 3t + 1, 3t + 2`` (:func:`advance_node`).

    The body of every fused step loop, the CPU's (:func:`step_exploded`) and the GPU's
    (:mod:`fdem.kernels.cuda_step`): one source for the step. ``inertia`` (n_nodes, 2) holds
    the inertial masses and their inverses of a density-scaled stage, or is ``None`` (the
    triangle's lumped mass; gravity always acts on that). ``c_keep = 1 - alpha dt/2`` and
    ``c_div = 1 / (1 + alpha dt/2)``. Returns this triangle's share of the sums named in
    :data:`LEDGER_FIELDS`, in that order, all floats (``n_inverted`` 0.0 or 1.0; the state
    energies are 0 unless ``ledger``).
    """
    h = 0.5 * dt
    i = 3 * t
    r = triangle_response(tc, t, x[i, 0], x[i, 1], x[i + 1, 0], x[i + 1, 1], x[i + 2, 0], x[i + 2, 1],
                          v[i, 0], v[i, 1], v[i + 1, 0], v[i + 1, 1], v[i + 2, 0], v[i + 2, 1], use_viscous)
    m = tc[t, TC_MASS]
    kin = 0.0
    gmom = 0.0
    emom = 0.0
    d_e = 0.0
    d_l = 0.0
    r_e = 0.0
    r_l = 0.0
    i_e = 0.0
    i_l = 0.0
    for k in range(3):  # one inlined call site keeps the compile time down
        mi = m if inertia is None else inertia[i + k, 0]
        im = tc[t, TC_INV_MASS] if inertia is None else inertia[i + k, 1]
        a = advance_node(x, u, v, i + k, r[2 * k], r[2 * k + 1], m, mi, im, gx, gy, dt, alpha, c_keep, c_div,
                         local, damped, f_int, use_int, f_ext, use_ext, flags, v_prescribed, ledger)
        kin += a[2]
        if ledger:
            gmom += a[3]
            emom += a[4]
        if damped:
            d_e += a[5]
            d_l += a[6]
        r_e += a[7]
        r_l += a[8]
        if use_int:
            i_e += a[9]
            i_l += a[10]
    v_e = 0.0
    v_l = 0.0
    if use_viscous:
        v_e = h * r[12]
        v_l = h * velocity_gradient_power(tc, t, r[8], r[9], r[10], r[11], v[i, 0], v[i, 1],
                                          v[i + 1, 0], v[i + 1, 1], v[i + 2, 0], v[i + 2, 1])
    strain = r[6] if ledger else 0.0
    bad = 0.0 if r[7] > 0.0 else 1.0  # a float: the 13 sums are one tuple type, indexable by a variable
    return strain, kin, gmom, emom, d_e, d_l, v_e, v_l, r_e, r_l, i_e, i_l, bad


@njit(parallel=True, fastmath=FASTMATH, cache=True)
def step_exploded(x, u, v, tc, f_int, use_int, f_ext, use_ext, flags, v_prescribed,
                  gx, gy, dt, alpha, local, use_viscous, ledger, partial, inertia, ranges=None):
    """One fused step on an exploded mesh (node ``3t + k`` is corner ``k`` of triangle ``t``).

    Each triangle computes its forces and advances its own three nodes (:func:`triangle_step`):
    race-free, one pass over memory. ``alpha`` [1/s] and ``local`` [-] are the damping
    coefficients (both 0: no damping code runs); ``ledger`` asks for the state energies
    (strain, kinetic, moments), which cost a little and are only needed on output steps.
    ``partial`` is a work array of shape ``(n_blocks(n_tri), len(LEDGER_FIELDS))``. ``inertia``
    (n_nodes, 2) gives the nodes' inertial masses and their inverses of a density-scaled stage,
    or ``None`` (the triangles' own lumped masses; gravity always acts on those). ``ranges``
    (n_items, 2) int64 lists the triangles to step as half-open ranges ``[start, end)``, one
    work item each (``partial`` then has ``n_items`` rows), or ``None``: every triangle, in
    blocks of :data:`BLOCK` (the triangles left out are asleep, :mod:`fdem.solve.sleeping`).
    Returns the sums named in :data:`LEDGER_FIELDS` (state energies 0 unless ``ledger``; sums
    over the stepped triangles only).
    """
    c_keep, c_div = damping_factors(alpha, dt)
    damped = alpha != 0.0 or local != 0.0
    n_tri = tc.shape[0]
    nb = partial.shape[0]
    for blk in prange(nb):
        strain = 0.0
        kin = 0.0
        gmom = 0.0
        emom = 0.0
        d_e = 0.0
        d_l = 0.0
        v_e = 0.0
        v_l = 0.0
        r_e = 0.0
        r_l = 0.0
        i_e = 0.0
        i_l = 0.0
        n_bad = 0.0
        t_lo, t_hi = block_span(blk, n_tri, ranges)
        for t in range(t_lo, t_hi):
            s = triangle_step(x, u, v, tc, t, inertia, f_int, use_int, f_ext, use_ext, flags, v_prescribed, gx, gy,
                              dt, alpha, c_keep, c_div, local, damped, use_viscous, ledger)
            strain += s[0]
            kin += s[1]
            gmom += s[2]
            emom += s[3]
            d_e += s[4]
            d_l += s[5]
            v_e += s[6]
            v_l += s[7]
            r_e += s[8]
            r_l += s[9]
            i_e += s[10]
            i_l += s[11]
            n_bad += s[12]
        partial[blk, 0] = strain
        partial[blk, 1] = kin
        partial[blk, 2] = gmom
        partial[blk, 3] = emom
        partial[blk, 4] = d_e
        partial[blk, 5] = d_l
        partial[blk, 6] = v_e
        partial[blk, 7] = v_l
        partial[blk, 8] = r_e
        partial[blk, 9] = r_l
        partial[blk, 10] = i_e
        partial[blk, 11] = i_l
        partial[blk, 12] = n_bad
    return _sum_partials(partial)


@njit(fastmath=FASTMATH, cache=True, inline="always")
def advance_node_elastic(x, u, v, i, px, py, fx, fy, gmass, mass, inv_mass, gx, gy, dt, damped, alpha, c_keep, c_div,
                         local, flags, v_prescribed):
    """:func:`move_node` for the fast path: gravity, optional damping (the factors of
    :func:`damping_factors`, computed once a step by the caller) and supports; no external
    loads, no state energies. ``(fx, fy)`` includes the interaction force.

    Returns ``(reaction_early, reaction_late, v_new_x, v_new_y, v_old_x, v_old_y,
    damping_early, damping_late)`` [J/m, m/s].
    """
    h = 0.5 * dt
    nx, ny, ux, uy, gdx, gdy, re, rl = move_node(x, u, v, i, px, py, fx, fy, gmass, mass, inv_mass, gx, gy, False, 0.0, 0.0,
                                                 dt, damped, alpha, c_keep, c_div, local, flags, v_prescribed)
    return re, rl, nx, ny, ux, uy, -h * (gdx * ux + gdy * uy), -h * (gdx * nx + gdy * ny)


@njit(parallel=True, fastmath=FASTMATH, cache=True)
def step_exploded_elastic(x, u, v, tc, f_int, damping, flags, v_prescribed, gx, gy, dt, partial, inertia, ranges=None):
    """Fast path of :func:`step_exploded`: elastic triangles, gravity, interaction forces
    (``f_int`` an array, or ``None`` when there are no providers), damping (``(alpha, local)``
    or ``None``), inertial masses of a density-scaled stage (``inertia`` (n_nodes, 2): masses and inverses, or ``None``)
    and constraints; no viscosity, external loads or state energies. ``None``
    arguments compile to specialisations without that code (numba prunes the branches).
    ``ranges``: the triangles to step, as in :func:`step_exploded` (``None``: all).

    Returns ``(reaction_early, reaction_late, interaction_early, interaction_late,
    damping_early, damping_late, n_inverted, kinetic)`` (``kinetic`` as in :data:`LEDGER_FIELDS`).
    """
    n_tri = tc.shape[0]
    nb = partial.shape[0]
    h = 0.5 * dt
    alpha = 0.0
    local = 0.0
    if damping is not None:
        alpha = damping[0]
        local = damping[1]
    damped = damping is not None
    c_keep, c_div = damping_factors(alpha, dt)
    for blk in prange(nb):
        r_e = 0.0
        r_l = 0.0
        i_e = 0.0
        i_l = 0.0
        d_e = 0.0
        d_l = 0.0
        kin = 0.0
        n_bad = 0
        t_lo, t_hi = block_span(blk, n_tri, ranges)
        for t in range(t_lo, t_hi):
            i = 3 * t
            b00 = tc[t, TC_B00]
            b01 = tc[t, TC_B01]
            b10 = tc[t, TC_B10]
            b11 = tc[t, TC_B11]
            x0, y0 = x[i, 0], x[i, 1]
            x1, y1 = x[i + 1, 0], x[i + 1, 1]
            x2, y2 = x[i + 2, 0], x[i + 2, 1]
            ax, ay = x1 - x0, y1 - y0
            bx, by = x2 - x0, y2 - y0
            f00 = ax * b00 + bx * b10
            f01 = ax * b01 + bx * b11
            f10 = ay * b00 + by * b10
            f11 = ay * b01 + by * b11
            p00, p01, p10, p11, _ = svk_piola(f00, f01, f10, f11, tc[t, TC_LAM], tc[t, TC_MU],
                                              tc[t, TC_S0XX], tc[t, TC_S0YY], tc[t, TC_S0XY])
            e0x, e0y, e1x, e1y, e2x, e2y = corner_forces(p00, p01, p10, p11, b00, b01, b10, b11)
            n_bad += 0 if f00 * f11 - f01 * f10 > 0.0 else 1
            if f_int is not None:
                g0x, g0y = f_int[i, 0], f_int[i, 1]
                g1x, g1y = f_int[i + 1, 0], f_int[i + 1, 1]
                g2x, g2y = f_int[i + 2, 0], f_int[i + 2, 1]
                e0x += g0x
                e0y += g0y
                e1x += g1x
                e1y += g1y
                e2x += g2x
                e2y += g2y
            m = tc[t, TC_MASS]
            if inertia is None:
                ma = mb = mc = m
                ia = ib = ic = tc[t, TC_INV_MASS]
            else:
                ma, mb, mc = inertia[i, 0], inertia[i + 1, 0], inertia[i + 2, 0]
                ia, ib, ic = inertia[i, 1], inertia[i + 1, 1], inertia[i + 2, 1]
            a = advance_node_elastic(x, u, v, i, x0, y0, e0x, e0y, m, ma, ia, gx, gy, dt, damped, alpha, c_keep, c_div,
                                     local, flags, v_prescribed)
            b = advance_node_elastic(x, u, v, i + 1, x1, y1, e1x, e1y, m, mb, ib, gx, gy, dt, damped, alpha, c_keep, c_div,
                                     local, flags, v_prescribed)
            c = advance_node_elastic(x, u, v, i + 2, x2, y2, e2x, e2y, m, mc, ic, gx, gy, dt, damped, alpha, c_keep, c_div,
                                     local, flags, v_prescribed)
            r_e += a[0] + b[0] + c[0]
            r_l += a[1] + b[1] + c[1]
            kin += 0.5 * (ma * (a[2] * a[4] + a[3] * a[5]) + mb * (b[2] * b[4] + b[3] * b[5])
                          + mc * (c[2] * c[4] + c[3] * c[5]))
            if damping is not None:
                d_e += a[6] + b[6] + c[6]
                d_l += a[7] + b[7] + c[7]
            if f_int is not None:
                i_e += h * (g0x * a[4] + g0y * a[5] + g1x * b[4] + g1y * b[5] + g2x * c[4] + g2y * c[5])
                i_l += h * (g0x * a[2] + g0y * a[3] + g1x * b[2] + g1y * b[3] + g2x * c[2] + g2y * c[3])
        partial[blk, 0] = r_e
        partial[blk, 1] = r_l
        partial[blk, 2] = i_e
        partial[blk, 3] = i_l
        partial[blk, 4] = d_e
        partial[blk, 5] = d_l
        partial[blk, 6] = n_bad
        partial[blk, 7] = kin
    s = partial[:, :8].sum(axis=0)
    return s[0], s[1], s[2], s[3], s[4], s[5], int(s[6]), s[7]


@njit(fastmath=FASTMATH, cache=True)
def _sum_partials(partial):
    s = partial.sum(axis=0)
    return s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10], s[11], int(s[12])


@njit(parallel=True, fastmath=FASTMATH, cache=True)
def triangle_pass(x, v, triangles, tc, corner_force, viscous_stress, use_viscous):
    """First pass on a conforming mesh: corner forces into ``corner_force`` (n_tri * 3, 2), corner ``3t + k``.

    ``viscous_stress`` (n_tri, 4) receives ``A0 P_v`` for the late half of the viscous work.
    Returns ``(strain energy, viscous_early, number of triangles with det F <= 0)``; multiply
    ``viscous_early`` by ``dt / 2``.
    """
    strain = 0.0
    rate = 0.0
    n_bad = 0
    for t in prange(triangles.shape[0]):
        n0, n1, n2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        r = triangle_response(tc, t, x[n0, 0], x[n0, 1], x[n1, 0], x[n1, 1], x[n2, 0], x[n2, 1],
                              v[n0, 0], v[n0, 1], v[n1, 0], v[n1, 1], v[n2, 0], v[n2, 1], use_viscous)
        c = 3 * t
        corner_force[c, 0] = r[0]
        corner_force[c, 1] = r[1]
        corner_force[c + 1, 0] = r[2]
        corner_force[c + 1, 1] = r[3]
        corner_force[c + 2, 0] = r[4]
        corner_force[c + 2, 1] = r[5]
        if use_viscous:
            viscous_stress[t, 0] = r[8]
            viscous_stress[t, 1] = r[9]
            viscous_stress[t, 2] = r[10]
            viscous_stress[t, 3] = r[11]
            rate += r[12]
        strain += r[6]
        n_bad += 0 if r[7] > 0.0 else 1
    return strain, rate, n_bad


@njit(parallel=True, fastmath=FASTMATH, cache=True)
def viscous_power(v, triangles, tc, viscous_stress):
    """``sum_t q_t : dF_t/dt(v)`` [W/m] for stored viscous stresses ``q`` (n_tri, 4) and velocities ``v``."""
    p = 0.0
    for t in prange(triangles.shape[0]):
        n0, n1, n2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        p += velocity_gradient_power(tc, t, viscous_stress[t, 0], viscous_stress[t, 1], viscous_stress[t, 2],
                                     viscous_stress[t, 3], v[n0, 0], v[n0, 1], v[n1, 0], v[n1, 1],
                                     v[n2, 0], v[n2, 1])
    return p


@njit(parallel=True, fastmath=FASTMATH, cache=True)
def node_pass(x, u, v, mass, node_corner_ptr, node_corners, corner_force,
              f_int, use_int, f_ext, use_ext, flags, v_prescribed, gx, gy, dt, alpha, local, ledger):
    """Second pass on a conforming mesh: each node gathers its corners' forces and advances.

    ``node_corners[node_corner_ptr[i]:node_corner_ptr[i + 1]]`` lists the corners ``3t + k`` at
    node ``i`` (CSR). Returns ``(kinetic, gravity_moment, external_moment, damping_early,
    damping_late, reaction_early, reaction_late, interaction_early, interaction_late)``.
    """
    c_keep, c_div = damping_factors(alpha, dt)
    damped = alpha != 0.0 or local != 0.0
    s2 = 0.0
    s3 = 0.0
    s4 = 0.0
    s5 = 0.0
    s6 = 0.0
    s7 = 0.0
    s8 = 0.0
    s9 = 0.0
    s10 = 0.0
    for i in prange(x.shape[0]):
        fx = 0.0
        fy = 0.0
        for j in range(node_corner_ptr[i], node_corner_ptr[i + 1]):
            c = node_corners[j]
            fx += corner_force[c, 0]
            fy += corner_force[c, 1]
        m = mass[i]
        a = advance_node(x, u, v, i, fx, fy, m, m, 1.0 / m, gx, gy, dt, alpha, c_keep, c_div, local, damped,
                         f_int, use_int, f_ext, use_ext, flags, v_prescribed, ledger)
        s2 += a[2]
        s3 += a[3]
        s4 += a[4]
        s5 += a[5]
        s6 += a[6]
        s7 += a[7]
        s8 += a[8]
        s9 += a[9]
        s10 += a[10]
    return s2, s3, s4, s5, s6, s7, s8, s9, s10
