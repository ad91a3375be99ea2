"""Constant-strain triangles: finite rotation, small strain, St Venant-Kirchhoff (numba).

Per triangle ``t`` with reference corners ``X0, X1, X2`` and current corners ``x0, x1, x2``:

* ``F = [x1 - x0, x2 - x0] B`` with ``B = [X1 - X0, X2 - X0]^-1`` (precomputed),
* Green strain ``E = (F^T F - I) / 2``,
* second Piola-Kirchhoff stress ``S = S0 + lambda tr(E) I + 2 mu E`` (``S0`` the initial
  stress, e.g. geostatic), viscous part ``S_v = eta dE/dt`` with ``dE/dt = sym(F^T dF/dt)``,
* first Piola ``P = F (S + S_v)``, internal corner forces ``f_a = A0 P grad N_a``
  (``grad N1 = B[0]``, ``grad N2 = B[1]``, ``grad N0 = -(B[0] + B[1])``),
* strain energy ``A0 (S0 : E + lambda tr(E)^2 / 2 + mu E : E)``.

A rigid rotation ``F = R`` gives ``E = 0`` and therefore zero force; a rotating pre-stressed
triangle carries its Cauchy stress ``R S0 R^T`` (objective). References: Munjiza (2004),
*The Combined Finite-Discrete Element Method*, ch. 4; Bonet & Wood (2008), *Nonlinear Continuum
Mechanics for Finite Element Analysis*, 2nd ed., sec. 6.4 (St Venant-Kirchhoff) and 9.4
(constant-strain triangle).

Per-triangle constants live in one contiguous ``(n_tri, N_TRI_CONST)`` float64 array, with the
moduli and initial stress *pre-multiplied by the reference area* ``A0`` so the kernel gets
``A0 P`` and ``A0 W`` directly. Column layout: ``TC_*`` below.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["FASTMATH", "TC_LAM", "TC_MU", "TC_ETA", "TC_MASS", "TC_INV_MASS", "N_TRI_CONST",
           "triangle_constants", "svk_piola", "viscous_piola", "corner_forces", "triangle_response",
           "velocity_gradient_power", "assemble_triangle_forces", "triangle_stress_state",
           "deformation_gradients", "TC_B00", "TC_B01", "TC_B10", "TC_B11", "TC_S0XX", "TC_S0YY", "TC_S0XY"]


FASTMATH = {"nsz", "arcp", "contract", "afn"}
"""LLVM fast-math flags of the triangle and contact-pair kernels (and of the kernels that inline
their helpers). Not ``nnan``/``ninf``, so that NaN and infinity still propagate into the energy
sums the instability guard checks. Not ``reassoc``: with ``contract`` and ``reassoc`` together,
a kernel compiled in the running process and the same kernel loaded from Numba's on-disk cache
are different machine codes and part in round-off, so that a first run and its resumption (or
any later run) were not the same computation (``docs/benchmarks.md``, "Fresh and cached kernels
differ in round-off"); without ``reassoc`` they agree to the bit
(``tests/unit/test_kernel_cache.py``). It costs the triangle step alone about 13 % on a
structured block and nothing measurable on the four-slope scene's step.

The crack-element kernels (``fdem/kernels/cracks.py``) keep Numba's full ``fastmath=True``
(``reassoc``, ``nnan`` and ``ninf`` included); their fresh and cached codes agree to the bit on a
block shaken until its elements soften and break (the same test file), so they do not split a
run, but a NaN they produce is not guaranteed to reach the guard's energy sums as NaN."""


# column layout of the per-triangle constants
TC_B00, TC_B01, TC_B10, TC_B11 = 0, 1, 2, 3  # B = [X1-X0, X2-X0]^-1 [1/m]


TC_LAM = 4  # A0 * lambda (2D, plane strain or plane stress) [N]


TC_MU = 5  # A0 * mu [N]


TC_ETA = 6  # A0 * eta [N s]


TC_S0XX, TC_S0YY, TC_S0XY = 7, 8, 9  # A0 * initial 2nd Piola-Kirchhoff stress [N]


TC_MASS = 10  # lumped mass of each corner, rho A0 / 3 [kg/m]


TC_INV_MASS = 11  # 1 / TC_MASS


N_TRI_CONST = 12


def triangle_constants(x0, triangles, lam, mu, eta, density, initial_stress=None) -> np.ndarray:
    """Build the ``(n_tri, N_TRI_CONST)`` constants array (see module docstring for the layout).

    ``lam``, ``mu``, ``eta``, ``density`` are scalars or (n_tri,) arrays [Pa, Pa, Pa s, kg/m^3];
    ``initial_stress`` is ``None`` or (n_tri, 3) ``[s_xx, s_yy, s_xy]`` [Pa].
    """
    from fdem.mesh.triangles import triangle_shape_gradients

    inv_dm, area = triangle_shape_gradients(np.asarray(x0, float), np.asarray(triangles))
    n = len(area)
    tc = np.zeros((n, N_TRI_CONST))
    tc[:, TC_B00] = inv_dm[:, 0, 0]
    tc[:, TC_B01] = inv_dm[:, 0, 1]
    tc[:, TC_B10] = inv_dm[:, 1, 0]
    tc[:, TC_B11] = inv_dm[:, 1, 1]
    tc[:, TC_LAM] = area * lam
    tc[:, TC_MU] = area * mu
    tc[:, TC_ETA] = area * eta
    if initial_stress is not None:
        s0 = np.asarray(initial_stress, float).reshape(n, 3)
        tc[:, TC_S0XX:TC_S0XY + 1] = area[:, None] * s0
    tc[:, TC_MASS] = density * area / 3.0
    tc[:, TC_INV_MASS] = 1.0 / tc[:, TC_MASS]
    return tc


# --------------------------------------------------------------------------- laws
@njit(fastmath=FASTMATH, cache=True, inline="always")
def svk_piola(f00, f01, f10, f11, lam, mu, s0xx, s0yy, s0xy):
    """First Piola stress of St Venant-Kirchhoff with initial stress, and the energy density.

    ``E = (F^T F - I)/2``, ``S = S0 + lam tr(E) I + 2 mu E``, ``P = F S``,
    ``W = S0 : E + lam tr(E)^2 / 2 + mu E : E``. Moduli and ``S0`` may be pre-multiplied by an
    area (then ``P`` and ``W`` are too). Returns ``(P00, P01, P10, P11, W)``.
    """
    e00 = 0.5 * (f00 * f00 + f10 * f10 - 1.0)
    e11 = 0.5 * (f01 * f01 + f11 * f11 - 1.0)
    e01 = 0.5 * (f00 * f01 + f10 * f11)
    tr = e00 + e11
    s00 = s0xx + lam * tr + 2.0 * mu * e00
    s11 = s0yy + lam * tr + 2.0 * mu * e11
    s01 = s0xy + 2.0 * mu * e01
    w = (s0xx * e00 + s0yy * e11 + 2.0 * s0xy * e01
         + 0.5 * lam * tr * tr + mu * (e00 * e00 + e11 * e11 + 2.0 * e01 * e01))
    return (f00 * s00 + f01 * s01, f00 * s01 + f01 * s11,
            f10 * s00 + f11 * s01, f10 * s01 + f11 * s11, w)


@njit(fastmath=FASTMATH, cache=True, inline="always")
def viscous_piola(f00, f01, f10, f11, d00, d01, d10, d11, eta):
    """First Piola stress ``P_v = F eta dE/dt`` of the viscous term, ``dE/dt = sym(F^T dF/dt)``.

    ``dF/dt = (d00, d01; d10, d11)``. ``dE/dt`` vanishes for a rigid spin (``dF/dt = W F``,
    ``W`` skew), so the term damps straining only. Returns ``(Pv00, Pv01, Pv10, Pv11)``.
    """
    g00 = eta * (f00 * d00 + f10 * d10)
    g11 = eta * (f01 * d01 + f11 * d11)
    g01 = eta * 0.5 * (f00 * d01 + f10 * d11 + d00 * f01 + d10 * f11)
    return (f00 * g00 + f01 * g01, f00 * g01 + f01 * g11,
            f10 * g00 + f11 * g01, f10 * g01 + f11 * g11)


@njit(fastmath=FASTMATH, cache=True, inline="always")
def corner_forces(p00, p01, p10, p11, b00, b01, b10, b11):
    """External-sign corner forces ``-P grad N_a`` of a triangle for a Piola stress ``P`` (times area).

    Returns ``(f0x, f0y, f1x, f1y, f2x, f2y)``; they sum to zero.
    """
    f1x = -(p00 * b00 + p01 * b01)
    f1y = -(p10 * b00 + p11 * b01)
    f2x = -(p00 * b10 + p01 * b11)
    f2y = -(p10 * b10 + p11 * b11)
    return -(f1x + f2x), -(f1y + f2y), f1x, f1y, f2x, f2y


@njit(fastmath=FASTMATH, cache=True, inline="always")
def triangle_response(tc, t, x0, y0, x1, y1, x2, y2, u0, w0, u1, w1, u2, w2, use_viscous):
    """Corner forces, strain energy, ``J = det F`` and viscous stress of triangle ``t``.

    ``(x_k, y_k)`` current corner positions, ``(u_k, w_k)`` corner velocities; the viscous term
    is evaluated only if ``use_viscous``. Returns
    ``(f0x, f0y, f1x, f1y, f2x, f2y, energy, J, q00, q01, q10, q11, rate)``: total (elastic +
    viscous) corner forces [N/m], strain energy ``A0 W`` [J/m], ``det F``, the viscous Piola
    stress times area ``q = A0 P_v`` [N] and its dissipation rate ``q : dF/dt`` [W/m].
    """
    b00 = tc[t, TC_B00]
    b01 = tc[t, TC_B01]
    b10 = tc[t, TC_B10]
    b11 = tc[t, TC_B11]
    ax, ay, bx, by = x1 - x0, y1 - y0, x2 - x0, y2 - y0
    f00 = ax * b00 + bx * b10
    f01 = ax * b01 + bx * b11
    f10 = ay * b00 + by * b10
    f11 = ay * b01 + by * b11
    p00, p01, p10, p11, energy = svk_piola(f00, f01, f10, f11, tc[t, TC_LAM], tc[t, TC_MU],
                                           tc[t, TC_S0XX], tc[t, TC_S0YY], tc[t, TC_S0XY])
    q00 = 0.0
    q01 = 0.0
    q10 = 0.0
    q11 = 0.0
    rate = 0.0
    if use_viscous:
        au, aw, bu, bw = u1 - u0, w1 - w0, u2 - u0, w2 - w0
        d00 = au * b00 + bu * b10
        d01 = au * b01 + bu * b11
        d10 = aw * b00 + bw * b10
        d11 = aw * b01 + bw * b11
        q00, q01, q10, q11 = viscous_piola(f00, f01, f10, f11, d00, d01, d10, d11, tc[t, TC_ETA])
        rate = q00 * d00 + q01 * d01 + q10 * d10 + q11 * d11
    f0x, f0y, f1x, f1y, f2x, f2y = corner_forces(p00 + q00, p01 + q01, p10 + q10, p11 + q11, b00, b01, b10, b11)
    return (f0x, f0y, f1x, f1y, f2x, f2y, energy, f00 * f11 - f01 * f10, q00, q01, q10, q11, rate)


@njit(fastmath=FASTMATH, cache=True, inline="always")
def velocity_gradient_power(tc, t, q00, q01, q10, q11, u0, w0, u1, w1, u2, w2):
    """``q : dF/dt`` for corner velocities ``(u_k, w_k)``: the power of the stress ``q`` (times area) [W/m]."""
    au, aw, bu, bw = u1 - u0, w1 - w0, u2 - u0, w2 - w0
    b00 = tc[t, TC_B00]
    b01 = tc[t, TC_B01]
    b10 = tc[t, TC_B10]
    b11 = tc[t, TC_B11]
    return (q00 * (au * b00 + bu * b10) + q01 * (au * b01 + bu * b11)
            + q10 * (aw * b00 + bw * b10) + q11 * (aw * b01 + bw * b11))


# --------------------------------------------------------------------------- loops
@njit(parallel=True, fastmath=FASTMATH, cache=True)
def assemble_triangle_forces(x, v, triangles, tc, force):
    """Reference (non-fused) pass: ``force`` (n_tri * 3, 2) gets each corner's force, corner ``3t + k``.

    Returns the total strain energy [J/m]. Used by tests and by the conforming-mesh path.
    """
    energy = 0.0
    for t in prange(triangles.shape[0]):
        n0, n1, n2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        r = triangle_response(tc, t, x[n0, 0], x[n0, 1], x[n1, 0], x[n1, 1], x[n2, 0], x[n2, 1],
                              v[n0, 0], v[n0, 1], v[n1, 0], v[n1, 1], v[n2, 0], v[n2, 1], True)
        c = 3 * t
        force[c, 0] = r[0]
        force[c, 1] = r[1]
        force[c + 1, 0] = r[2]
        force[c + 1, 1] = r[3]
        force[c + 2, 0] = r[4]
        force[c + 2, 1] = r[5]
        energy += r[6]
    return energy


@njit(parallel=True, fastmath=FASTMATH, cache=True)
def triangle_stress_state(x, v, triangles, tc, out):
    """Cauchy stress of every triangle: ``out[t] = [s_xx, s_yy, s_xy, tr(E), J, W/A0]``.

    ``sigma = F (S + S_v) F^T / J`` [Pa]; ``tr(E)`` lets the caller add the out-of-plane stress
    ``lambda tr(E)`` of plane strain; ``W/A0`` is the strain-energy density [J/m^3].
    """
    for t in prange(triangles.shape[0]):
        n0, n1, n2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        b00, b01, b10, b11 = tc[t, TC_B00], tc[t, TC_B01], tc[t, TC_B10], tc[t, TC_B11]
        area = 1.0 / (b00 * b11 - b01 * b10) * 0.5
        ax, ay = x[n1, 0] - x[n0, 0], x[n1, 1] - x[n0, 1]
        bx, by = x[n2, 0] - x[n0, 0], x[n2, 1] - x[n0, 1]
        f00 = ax * b00 + bx * b10
        f01 = ax * b01 + bx * b11
        f10 = ay * b00 + by * b10
        f11 = ay * b01 + by * b11
        au, aw = v[n1, 0] - v[n0, 0], v[n1, 1] - v[n0, 1]
        bu, bw = v[n2, 0] - v[n0, 0], v[n2, 1] - v[n0, 1]
        d00 = au * b00 + bu * b10
        d01 = au * b01 + bu * b11
        d10 = aw * b00 + bw * b10
        d11 = aw * b01 + bw * b11
        inv_a = 1.0 / area
        lam, mu, eta = tc[t, TC_LAM] * inv_a, tc[t, TC_MU] * inv_a, tc[t, TC_ETA] * inv_a
        e00 = 0.5 * (f00 * f00 + f10 * f10 - 1.0)
        e11 = 0.5 * (f01 * f01 + f11 * f11 - 1.0)
        e01 = 0.5 * (f00 * f01 + f10 * f11)
        tr = e00 + e11
        s00 = tc[t, TC_S0XX] * inv_a + lam * tr + 2.0 * mu * e00 + eta * (f00 * d00 + f10 * d10)
        s11 = tc[t, TC_S0YY] * inv_a + lam * tr + 2.0 * mu * e11 + eta * (f01 * d01 + f11 * d11)
        s01 = (tc[t, TC_S0XY] * inv_a + 2.0 * mu * e01
               + eta * 0.5 * (f00 * d01 + f10 * d11 + d00 * f01 + d10 * f11))
        jac = f00 * f11 - f01 * f10
        # sigma = F S F^T / J
        a00 = f00 * s00 + f01 * s01
        a01 = f00 * s01 + f01 * s11
        a10 = f10 * s00 + f11 * s01
        a11 = f10 * s01 + f11 * s11
        out[t, 0] = (a00 * f00 + a01 * f01) / jac
        out[t, 1] = (a10 * f10 + a11 * f11) / jac
        out[t, 2] = (a00 * f10 + a01 * f11) / jac
        out[t, 3] = tr
        out[t, 4] = jac
        out[t, 5] = (tc[t, TC_S0XX] * e00 + tc[t, TC_S0YY] * e11 + 2.0 * tc[t, TC_S0XY] * e01) * inv_a \
            + 0.5 * lam * tr * tr + mu * (e00 * e00 + e11 * e11 + 2.0 * e01 * e01)


@njit(parallel=True, cache=True)
def deformation_gradients(x, triangles, tc, out):
    """``out[t] = [F00, F01, F10, F11]`` of every triangle (for tests and diagnostics)."""
    for t in prange(triangles.shape[0]):
        n0, n1, n2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        ax, ay = x[n1, 0] - x[n0, 0], x[n1, 1] - x[n0, 1]
        bx, by = x[n2, 0] - x[n0, 0], x[n2, 1] - x[n0, 1]
        out[t, 0] = ax * tc[t, TC_B00] + bx * tc[t, TC_B10]
        out[t, 1] = ax * tc[t, TC_B01] + bx * tc[t, TC_B11]
        out[t, 2] = ay * tc[t, TC_B00] + by * tc[t, TC_B10]
        out[t, 3] = ay * tc[t, TC_B01] + by * tc[t, TC_B11]
