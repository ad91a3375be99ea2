"""Numba kernels for the four-node cohesive crack element.

Arrays in, arrays out; the Python side (:mod:`fdem.cohesive`) owns the data and unpacks it.

Layout (``n`` crack elements, ``m`` exploded nodes)
---------------------------------------------------
``nodes : (n, 4) int32``
    ``[A_p, A_q, B_q, B_p]`` (see :mod:`fdem.topology`). End 0 of the element is the node pair
    (0, 3), end 1 the pair (1, 2); the integration points are these two ends.
``const : (n, N_CONST) float64``
    Per-element constants, one 64-byte row, already multiplied by the end weight ``w = L0/2``
    where marked ``*w``; columns ``CC_*``:

    ====  =============  ===========  ===========================================================
    col   name           symbol       meaning
    ====  =============  ===========  ===========================================================
    0     ``CC_KN``      ``Kn``       normal penalty stiffness of one end, ``k_n w`` [N/m] (``*w``)
    1     ``CC_KT``      ``Kt``       tangential penalty stiffness, ``k_t w`` [N/m]         (``*w``)
    2     ``CC_OP``      ``op``       opening at the tensile peak ``o_p = f_t / k_n`` [m]
    3     ``CC_C``       ``C``        cohesion force, ``c w`` [N]                           (``*w``)
    4     ``CC_TANPHI``  ``tanphi``   friction coefficient ``tan(phi)`` [-]
    5     ``CC_INV_DO``  ``inv_dO``   ``1/(o_r - o_p)``, inverse opening from peak to full damage
                                      [1/m]; negative for linear softening (the sign carries the
                                      shape, so the row stays one cache line)
    6     ``CC_INV_DK``  ``inv_dK``   ``1/kappa_r``, inverse plastic slip to full damage [1/m]
                                      (0: no cohesion)
    7     ``CC_KC``      ``Kc``       normal stiffness in compression, ``k_c w`` [N/m]      (``*w``);
                                      ``Kn`` unless matched to contact (see ``CrackSet``)
    ====  =============  ===========  ===========================================================

    A strength reduction or heterogeneity changes the numbers in these rows, never the code.
``status : (n,) int8``
    0 while the element has never left the elastic range (its ``state`` row is then all
    zero and is not read), 1 after it first damaged or slid.
``state : (n, N_STATE) float64``
    Columns ``CS_*``. ``[D, kappa, s_pl]`` of end 0 then of end 1 (``CS_END`` columns on): damage (never decreases, >= 1 is fully
    damaged), accumulated plastic slip [m], signed plastic slip [m]; then the shear traction
    applied at the last update of end 0 and of end 1 [N/m per end] (for the trapezoidal
    booking of plastic work, see :func:`point_law`); then the normal traction applied at the
    last update of end 0 and of end 1 [N/m per end] (trapezoidal booking of the dilatant
    work); then the dilatant opening ``d`` of end 0 and of end 1 [m] (joint dilation: the law
    sees the effective opening ``o - d``).
``dil : (n, N_DIL) float64``
    ``[tan(psi), u_lim]`` (columns ``CD_TANPSI``, ``CD_ULIM``): dilation coefficient [-] and the plastic slip [m] beyond which the
    end stops dilating (``fdem.cohesive.CrackProperties.dilation_angle`` / ``dilation_limit``).
    Read only in the inelastic branch (an element on the elastic fast path has no plastic
    slip, so it has no dilation), which is why it is not part of the 64-byte ``const`` row.
``diss : (n, N_DISS) float64``
    Energy dissipated by each element [J per metre of thickness]: mode-I (normal damage),
    mode-II (cohesive part of the shear strength), friction inside the intact element
    (columns ``CW_MODE_I``, ``CW_MODE_II``, ``CW_FRICTION``).
``offset : (n, N_OFFSET) float64``
    ``[o0, s0, o1, s1]`` (columns ``CO_O0, CO_S0, CO_O1, CO_S1``): separation offsets [m] added to the measured opening and slip of end
    0 and end 1. Zero by default; a geostatic start pre-loads the elements through them (the
    law then gives the equilibrium traction at zero separation), as the triangles' initial
    stress pre-loads the triangles.
``ref : (n, N_REF) float64``
    ``[a_x, a_y, d0_x, d0_y, d1_x, d1_y]`` (columns ``CR_*``): the element's geometry at the
    reference positions ``X``: face A ``a = X_1 - X_0``, and the separations of end 0,
    ``X_3 - X_0``, and of end 1, ``X_2 - X_1`` (zero when the element joins coincident nodes, as
    every element inserted between the triangles of a mesh does). The kernels read the nodes'
    displacement ``u = x - X``, never their positions: the separation ``d0 + u_3 - u_0`` is then
    resolved to the spacing of floating-point numbers at the size of ``u`` (1e-18 m for
    centimetres), not at the size of ``x`` (1e-14 to 3e-14 m at 100 m from the origin), and the
    stiff penalty springs turn no coordinate round-off into force (docs/benchmarks.md, "The
    floor and the origin").
``fe : (n, N_FE) float64``
    ``[F0x, F0y, F1x, F1y]`` (columns ``CF_*``): force on the A node of end 0 and of end 1
    [N/m], the per-element store of the store-and-gather scheme.

The column names are module-level integers, compile-time constants in the kernels: the
machine code is the same as with the bare numbers.

The law (per integration point, per unit area; Munjiza 2004 ch. 7; Munjiza, Andrews & White
1999; Lisjak et al. 2014, elliptical mixed-mode interaction) is documented in
:func:`point_law` and in ``docs/cohesive.md``.
"""
from __future__ import annotations

import math
import numpy as np
from numba import njit, prange

__all__ = ["EM_A", "EM_B", "EM_C", "MUNJIZA", "LINEAR", "N_CONST", "N_STATE", "N_STATE_V1", "N_DIL",
           "CC_KN", "CC_KT", "CC_OP", "CC_C", "CC_TANPHI", "CC_INV_DO", "CC_INV_DK", "CC_KC",
           "CS_D0", "CS_KAP0", "CS_SPL0", "CS_D1", "CS_KAP1", "CS_SPL1", "CS_END", "CS_TAU0", "CS_TAU1",
           "CS_SIG0", "CS_SIG1", "CS_DIL0", "CS_DIL1", "CD_TANPSI", "CD_ULIM",
           "CW_MODE_I", "CW_MODE_II", "CW_FRICTION", "N_DISS", "CO_O0", "CO_S0", "CO_O1", "CO_S1", "CO_END",
           "N_OFFSET", "CR_AX", "CR_AY", "CR_D0X", "CR_D0Y", "CR_D1X", "CR_D1Y", "N_REF", "reference_geometry",
           "element_kinematics", "CF_F0X", "CF_F0Y", "CF_F1X", "CF_F1Y", "CF_END", "N_FE",
           "UNKNOWN_TRACTION", "PARALLEL_MIN", "softening", "point_law", "element_update",
           "update_and_scatter", "crack_forces_coloured", "crack_forces_serial", "crack_forces_store",
           "gather_node_forces", "colour_elements", "end_separations", "crack_elastic_energy",
           "node_spring_stiffness", "stable_dt_kernel", "secant_stiffness", "remap_damage", "project_to_envelope"]


# Evans-Marathe softening constants used by Munjiza (2004, ch. 7): a, b, c.
EM_A = 0.63


EM_B = 1.8


EM_C = 6.0


MUNJIZA = 0


LINEAR = 1


# Columns of ``const`` (one row per element; ``*w``: multiplied by the end weight w = L0/2).
CC_KN = 0  # normal penalty stiffness of one end in tension, k_n w [N/m]
CC_KT = 1  # tangential penalty stiffness of one end, k_t w [N/m]
CC_OP = 2  # opening at the tensile peak, o_p = f_t / k_n [m]
CC_C = 3  # cohesion force of one end, c w [N]
CC_TANPHI = 4  # friction coefficient tan(phi) [-]
CC_INV_DO = 5  # 1/(o_r - o_p), inverse opening from peak to full damage [1/m]; < 0: linear softening
CC_INV_DK = 6  # 1/kappa_r, inverse plastic slip to full damage [1/m] (0: no cohesion)
CC_KC = 7  # normal stiffness of one end in compression, k_c w [N/m]
N_CONST = 8


# Columns of ``state``: [D, kappa, s_pl] of end 0, then of end 1 (CS_END columns on), then the
# end-0/end-1 pairs of the last shear traction, the last normal traction and the dilatant opening.
CS_D0 = 0  # damage of end 0 [-] (never decreases; >= 1 fully damaged)
CS_KAP0 = 1  # accumulated plastic slip kappa of end 0 [m]
CS_SPL0 = 2  # signed plastic slip s_pl of end 0 [m]
CS_D1 = 3  # damage of end 1 [-]
CS_KAP1 = 4  # accumulated plastic slip kappa of end 1 [m]
CS_SPL1 = 5  # signed plastic slip s_pl of end 1 [m]
CS_END = 3  # column stride of [D, kappa, s_pl] from end 0 to end 1 (end e: CS_D0 + CS_END e, ...)
CS_TAU0 = 6  # shear traction applied at the last update of end 0 [N/m per end] (end e: CS_TAU0 + e)
CS_TAU1 = 7  # shear traction applied at the last update of end 1 [N/m per end]
CS_SIG0 = 8  # normal traction applied at the last update of end 0 [N/m per end] (end e: CS_SIG0 + e)
CS_SIG1 = 9  # normal traction applied at the last update of end 1 [N/m per end]
CS_DIL0 = 10  # dilatant opening d of end 0 [m] (end e: CS_DIL0 + e)
CS_DIL1 = 11  # dilatant opening d of end 1 [m]
N_STATE = 12


N_STATE_V1 = 8
"""State columns before joint dilation (``[D, kappa, s_pl] x 2, tau_prev x 2``, up to
``CS_SIG0``): checkpoints written then are padded on load (``sigma_prev`` unknown, ``d = 0``)."""


# Columns of ``dil``.
CD_TANPSI = 0  # dilation coefficient tan(psi) [-]
CD_ULIM = 1  # plastic slip u_lim beyond which the end stops dilating [m]
N_DIL = 2


# Columns of ``diss`` (energy dissipated per element [J/m]).
CW_MODE_I = 0  # mode I: normal damage [J/m]
CW_MODE_II = 1  # mode II: cohesive part of the shear strength [J/m]
CW_FRICTION = 2  # friction inside the intact element, dilatant work included [J/m]
N_DISS = 3


# Columns of ``offset`` (separation offsets added to the measured separations).
CO_O0 = 0  # opening offset of end 0 [m] (end e: CO_O0 + CO_END e)
CO_S0 = 1  # slip offset of end 0 [m] (end e: CO_S0 + CO_END e)
CO_O1 = 2  # opening offset of end 1 [m]
CO_S1 = 3  # slip offset of end 1 [m]
CO_END = 2  # column stride of [o, s] from end 0 to end 1
N_OFFSET = 4


CR_AX = 0  # face A at the reference, X_1 - X_0 [m]
CR_AY = 1
CR_D0X = 2  # separation of end 0 at the reference, X_3 - X_0 [m]
CR_D0Y = 3
CR_D1X = 4  # separation of end 1 at the reference, X_2 - X_1 [m]
CR_D1Y = 5
N_REF = 6


# Columns of ``fe`` (store-and-gather: force on the A node of each end; the B node gets minus it).
CF_F0X = 0  # x force of end 0 [N/m] (end e: CF_F0X + CF_END e)
CF_F0Y = 1  # y force of end 0 [N/m] (end e: CF_F0Y + CF_END e)
CF_F1X = 2  # x force of end 1 [N/m]
CF_F1Y = 3  # y force of end 1 [N/m]
CF_END = 2  # column stride of [Fx, Fy] from end 0 to end 1
N_FE = 4


UNKNOWN_TRACTION = -1.0e308
"""Sentinel for "no previous shear traction stored" (a NaN test would not survive fastmath)."""


PARALLEL_MIN = 4096
"""Below this many live elements the serial loop is used (a parallel region costs more)."""


@njit(cache=True, fastmath=True)
def softening(D, kind):
    """Normalised softening curve ``z(D)`` with ``z(0) = 1``, ``z(1) = 0``, ``z' <= 0``.

    Munjiza (Evans & Marathe 1968, as used in Munjiza 2004, sec. 7.2 and Munjiza, Andrews &
    White 1999)::

        z(D) = [1 - (a+b-1)/(a+b) exp(D (a + c b) / ((a+b)(1-a-b)))] [a (1-D) + b (1-D)^c]

    with ``a = 0.63, b = 1.8, c = 6``; ``z'(0) = 0`` and ``int_0^1 z dD = 0.38631``.
    Linear: ``z(D) = 1 - D``. ``D`` is clamped to [0, 1]. Dimensionless.
    """
    d = min(max(D, 0.0), 1.0)
    if kind == LINEAR:
        return 1.0 - d
    e = 1.0 - d
    e2 = e * e
    e6 = e2 * e2 * e2
    ab = EM_A + EM_B
    first = 1.0 - (ab - 1.0) / ab * math.exp(d * (EM_A + EM_C * EM_B) / (ab * (1.0 - ab)))
    return first * (EM_A * e + EM_B * e6)


@njit(cache=True, fastmath=True)
def point_law(o, s, D, kap, sp, tp, Kn, Kt, op, C, tanphi, inv_dO, inv_dK, kind, Kc,
              d=0.0, sigp=UNKNOWN_TRACTION, tanpsi=0.0, ulim=0.0):
    """Cohesive law at one integration point: tractions and the updated state.

    Inputs are the opening ``o`` (>0 opens) and slip ``s`` [m] at the point, the state
    ``D, kap, sp, d``, the shear and normal tractions ``tp``, ``sigp`` applied at the previous
    update (:data:`UNKNOWN_TRACTION` if unknown)
    and the constants: penalties ``Kn, Kt`` (``Kc`` in compression), peak opening ``op = Ft/Kn``,
    cohesion ``C``, ``tanphi``, ``inv_dO = 1/(o_r - o_p)``, ``inv_dK = 1/kappa_r``, softening
    ``kind``, dilation ``tanpsi = tan(psi)`` and its slip limit ``ulim`` [m]. Stiffnesses,
    strengths and energies are per unit area, or all multiplied by the point weight ``w`` (the
    law is homogeneous in that scaling).

    Law (derived in ``docs/cohesive.md``), with the effective opening ``oe = o - d``::

        xi_I = max(oe - o_p, 0) / (o_r - o_p)      normalised post-peak opening
        xi_II = kap / kappa_r                       normalised cohesive plastic slip
        D'   = max(D, sqrt(xi_I^2 + xi_II^2))       elliptical mixed mode, never heals
        normal:  sigma = Kc oe                      (oe <= 0, full penalty in compression)
                 sigma = z(D') Ft oe / (o_p + D' (o_r - o_p))   (oe > 0: secant, damaged stiffness)
        shear:   tau_tr = Kt (s - sp)
                 F = z(D') C + max(-sigma, 0) tanphi          Mohr-Coulomb, tension cut-off
                 excess = max(|tau_tr| - F, 0)                 return map (plastic slip)
                 tau = tau_tr - sign(tau_tr) excess;  kap += excess/Kt;  sp += sign excess/Kt

    **Dilation** (non-associated joint dilation, Goodman 1976 *Methods of Geological
    Engineering* ch. 5; Itasca PFC smooth-joint model, Mas Ivars et al. 2011 IJRMMS 48):
    while the end slides, its faces separate normally by ``d = tan(psi) min(kap, u_lim)``
    (accumulated increment by increment, ``dd = tan(psi) [min(kap', u_lim) - min(kap, u_lim)]``,
    so a later change of ``tan(psi)`` changes no stored energy). The slip increment ``dk`` is
    implicit in the dilation: ``|tau_tr| - Kt dk = F(dk)`` with
    ``F(dk) = z C + Kc tanphi max(tan(psi) min(dk, u_lim - kap) - max(oe, 0), 0) + F_0`` (the
    compression the dilation adds, ``F_0`` the friction before it), solved exactly on the
    (at most three) linear pieces; so the returned tractions satisfy ``|tau| = F(sigma)`` with
    the returned ``sigma``. ``tan(psi) = 0`` takes the original arithmetic (bit for bit).

    In pure mode I the envelope is ``sigma = Ft z(D)`` at ``oe = o_p + D (o_r - o_p)``, area
    ``Ft o_p/2 + Ft (o_r - o_p) Zbar = G_I``; in pure mode II the cohesive part softens as
    ``C z(kap/kappa_r)``, area ``C kappa_r Zbar = G_II``; the frictional part
    ``sigma_n tanphi`` is dissipated as friction and never softens (residual = contact).
    The shear strength uses the damage of the previous plastic slip (one-step lag, an O(step)
    error that vanishes with the explicit time step).

    Plastic work is booked by the trapezoidal rule of the central-difference ledger: over an
    update from traction ``tp`` to ``tau = sgn F`` with plastic slip ``dk``, the work of the
    applied tractions minus the change of stored energy is ``dW = dk (F + sgn tp) / 2``
    (``F dk`` in steady sliding; ``F dk`` too when ``tp`` is unknown), shared between the
    cohesive part ``z C`` and friction in proportion. In dynamic sliding the strength ``F``
    changes from step to step with the normal traction, and ``F dk`` alone leaves a
    first-order error in the ledger. With dilation the normal spring takes part of it: the
    trapezoidal normal work minus the change of ``sigma oe/2`` is ``(sigma + sigp) dd / 2``
    (``sigma < 0`` in compression: negative, energy stored in the normal spring or spent
    against the confinement, not dissipated), added to the friction share; with ``sigp``
    unknown the normal traction before the slip at the same opening stands in for it (then
    ``(sigma_0 + sigma) dd / 2`` is exactly minus the change of normal stored energy at fixed
    opening). Steady sliding at ``sigma_n = -sigma``: ``dW = dk (z C + sigma_n (tanphi -
    tan(psi)))``, non-negative because ``psi <= phi`` (checked by ``CrackProperties`` and kept
    under strength reduction, see ``CrackSet``).

    Returns ``(sigma, tau, D', kap', sp', d', dW_I, dW_II, dW_fric)``: tractions (tension and
    slip-resisting positive), the updated state and the energy dissipated in this update by
    normal damage, by the cohesive part and by friction (dilatant work included) [J/m^2, or J
    when the constants carry ``w``].
    """
    sig_e = Kn * max(o, 0.0) + Kc * min(o, 0.0)
    ttr = Kt * (s - sp)
    # Fast path, taken by nearly every element: intact, below the tensile peak, elastic shear
    # (no plastic slip, hence no dilation: d = 0).
    if D == 0.0 and kap == 0.0 and o <= op:
        if abs(ttr) <= C + max(-sig_e, 0.0) * tanphi:
            return sig_e, ttr, 0.0, 0.0, sp, d, 0.0, 0.0, 0.0
    return _point_law_inelastic(o - d, D, kap, sp, d, tp, sigp, ttr, Kn, Kt, op, C, tanphi, inv_dO, inv_dK, kind, Kc,
                                tanpsi, ulim)


@njit(cache=True, fastmath=True)
def _point_law_inelastic(o, D, kap, sp, d, tp, sigp, ttr, Kn, Kt, op, C, tanphi, inv_dO, inv_dK, kind, Kc,
                         tanpsi, ulim):
    """Damaging / sliding branch of :func:`point_law` (same law, general case); ``o`` is the
    effective opening ``o - d`` here."""
    Ft = Kn * op
    dO = 1.0 / inv_dO
    xi1 = max(o - op, 0.0) * inv_dO
    xi2 = kap * inv_dK
    q = xi1 * xi1 + xi2 * xi2
    Dn = D
    if q > D * D:
        Dn = math.sqrt(q)
    opos = max(o, 0.0)
    oneg = min(o, 0.0)
    if Dn > 0.0:
        z = softening(Dn, kind)
        sec = z * Ft / (op + Dn * dO)
    else:
        z = 1.0
        sec = Kn
    sig = sec * opos + Kc * oneg
    dWI = 0.0
    dsig = 0.0
    if Dn > D:
        sec_old = Kn
        if D > 0.0:
            sec_old = softening(D, kind) * Ft / (op + D * dO)
        # Work of the traction over the step minus the change of stored energy, with the
        # opening at the start of the step estimated by the envelope point of D (exact for
        # monotonic mode I, and for fixed opening below it): dW = (sec_old - sec) o_ref o / 2.
        # It matches the trapezoidal work of the central-difference ledger; a jump of the
        # envelope at fixed opening (a strength change) is booked by project_to_envelope.
        oref = min(op + D * dO, opos)
        dWI = 0.5 * (sec_old - sec) * oref * opos
        dsig = (sec_old - sec) * opos  # traction drop of that damage step (for the dilatant work)
    att = abs(ttr)
    fric = max(-sig, 0.0) * tanphi
    F = z * C + fric
    excess = max(att - F, 0.0)
    sgn = 1.0 if ttr >= 0.0 else -1.0
    tau = ttr - sgn * excess
    dk = excess / Kt
    dd = 0.0
    wdil = 0.0
    if dk > 0.0 and tanpsi > 0.0 and ulim > kap:
        # Implicit dilation: F(dk) = F + a clip(dk - qo, 0, r - qo), a = Kc tanphi tanpsi,
        # qo = slip that closes an open end, r = slip left before u_lim.
        r = ulim - kap
        qo = opos / tanpsi
        a = Kc * tanphi * tanpsi
        if a > 0.0 and dk > qo and r > qo:
            dk = (att - F + a * qo) / (Kt + a)
            if dk > r:
                dk = (att - F - a * (r - qo)) / Kt
            F = att - Kt * dk
            tau = sgn * F
        dd = tanpsi * min(dk, r)
        oe = o - dd
        sig0 = sig
        sig = sec * max(oe, 0.0) + Kc * min(oe, 0.0)
        fric = F - z * C
        # Trapezoidal normal work minus the change of normal stored energy: (sigma + sigp) dd/2,
        # sigp taken after this update's damage step (its energy is in dW_I already).
        wdil = 0.5 * (sig + (sig0 if sigp == UNKNOWN_TRACTION else sigp - dsig)) * dd
    dWII = 0.0
    dWf = 0.0
    if dk > 0.0:
        work = F * dk if tp == UNKNOWN_TRACTION else 0.5 * dk * (F + sgn * tp)
        if F > 0.0:
            dWII = work * (z * C / F)
            dWf = work * (fric / F) + wdil
        else:
            dWII = work + wdil
    return sig, tau, Dn, kap + dk, sp + sgn * dk, d + dd, dWI, dWII, dWf


def reference_geometry(x0, nodes):
    """(n, N_REF) ``ref`` rows of the elements ``nodes`` at the reference positions ``x0``:
    face A ``X_1 - X_0`` and the separations ``X_3 - X_0``, ``X_2 - X_1`` (see the layout)."""
    x0 = np.asarray(x0, dtype=np.float64)
    nodes = np.asarray(nodes)
    ref = np.empty((nodes.shape[0], N_REF))
    ref[:, CR_AX:CR_AY + 1] = x0[nodes[:, 1]] - x0[nodes[:, 0]]
    ref[:, CR_D0X:CR_D0Y + 1] = x0[nodes[:, 3]] - x0[nodes[:, 0]]
    ref[:, CR_D1X:CR_D1Y + 1] = x0[nodes[:, 2]] - x0[nodes[:, 1]]
    return ref


@njit(cache=True, fastmath=True, inline="always")
def element_kinematics(c, u, ref, nodes, offset):
    """Frame and separations of element ``c`` from its nodes' displacements ``u`` [m].

    With ``x = X + u`` and the reference rows ``ref`` (face A ``a``, end separations ``d0``,
    ``d1``): face A is ``a + u_1 - u_0``, face B ``x_2 - x_3 = a + d1 - d0 + u_2 - u_3``; the
    tangent ``t`` runs along the mid-line of the faces, ``m = (A + B)/2``, ``t = m/|m|``, the
    normal ``n = (t_y, -t_x)`` points from A into B. The separation of end 0 is
    ``d0 + u_3 - u_0``, of end 1 ``d1 + u_2 - u_1``; ``o = d.n + o_off``, ``s = d.t + s_off``
    with the element's offsets ``offset[c]``.

    Returns ``(t_x, t_y, o0, s0, o1, s1, fold)``, ``fold = A . B`` [m^2] (<= 0: the faces have
    turned more than 90 degrees apart).
    """
    i0 = nodes[c, 0]
    i1 = nodes[c, 1]
    i2 = nodes[c, 2]
    i3 = nodes[c, 3]
    d0x = ref[c, CR_D0X] + (u[i3, 0] - u[i0, 0])
    d0y = ref[c, CR_D0Y] + (u[i3, 1] - u[i0, 1])
    d1x = ref[c, CR_D1X] + (u[i2, 0] - u[i1, 0])
    d1y = ref[c, CR_D1Y] + (u[i2, 1] - u[i1, 1])
    ax = ref[c, CR_AX] + (u[i1, 0] - u[i0, 0])
    ay = ref[c, CR_AY] + (u[i1, 1] - u[i0, 1])
    # face B = x_2 - x_3 = face A + d1 - d0
    bx = ax + d1x - d0x
    by = ay + d1y - d0y
    mx = 0.5 * (ax + bx)
    my = 0.5 * (ay + by)
    inv = 1.0 / math.sqrt(max(mx * mx + my * my, 1e-300))
    tx = mx * inv
    ty = my * inv
    # n = (t_y, -t_x)
    o0 = d0x * ty - d0y * tx + offset[c, CO_O0]
    s0 = d0x * tx + d0y * ty + offset[c, CO_S0]
    o1 = d1x * ty - d1y * tx + offset[c, CO_O1]
    s1 = d1x * tx + d1y * ty + offset[c, CO_S1]
    return tx, ty, o0, s0, o1, s1, ax * bx + ay * by


@njit(cache=True, fastmath=True, inline="always")
def element_update(c, u, ref, nodes, const, status, state, diss, offset, dil):
    """One crack element: kinematics (:func:`element_kinematics`, from the nodes'
    displacements ``u``), the law at both ends, state update. The dilation constants ``dil[c]``
    and the state row are read only when the element leaves the fast path.

    Returns ``(broke, F0x, F0y, F1x, F1y)``: ``F_i = sigma_i n + tau_i t`` [N/m] is the force on
    the A node of end ``i``; the B node gets ``-F_i``. ``broke`` is True when both ends reached
    ``D >= 1`` in this update, or when the faces of an inelastic element have turned more than
    90 degrees apart (``(x1 - x0) . (x2 - x3) <= 0``: hinged open about one end); forces are then
    zero and the faces belong to contact.
    """
    tx, ty, o0, s0, o1, s1, fold = element_kinematics(c, u, ref, nodes, offset)
    nx = ty
    ny = -tx

    Kn = const[c, CC_KN]
    Kt = const[c, CC_KT]
    op = const[c, CC_OP]
    C = const[c, CC_C]
    tanphi = const[c, CC_TANPHI]
    Kc = const[c, CC_KC]
    # Fast path of point_law for both ends at once (nearly every element, every step): an
    # element that never left the elastic range (status 0: D = kappa = s_pl = 0) and stays
    # below the tensile peak and inside the Mohr-Coulomb envelope. Reads no state, stores nothing.
    sig0 = (Kn if o0 > 0.0 else Kc) * o0
    tau0 = Kt * s0
    sig1 = (Kn if o1 > 0.0 else Kc) * o1
    tau1 = Kt * s1
    elastic = ((status[c] == 0) & (o0 <= op) & (o1 <= op)
               & (abs(tau0) <= C + max(-sig0, 0.0) * tanphi) & (abs(tau1) <= C + max(-sig1, 0.0) * tanphi))
    broke = False
    if not elastic:
        tp0 = UNKNOWN_TRACTION
        tp1 = UNKNOWN_TRACTION
        np0 = UNKNOWN_TRACTION
        np1 = UNKNOWN_TRACTION
        if status[c] != 0:
            tp0 = state[c, CS_TAU0]
            tp1 = state[c, CS_TAU1]
            np0 = state[c, CS_SIG0]
            np1 = state[c, CS_SIG1]
        status[c] = 1
        signed_inv_dO = const[c, CC_INV_DO]
        inv_dO = abs(signed_inv_dO)
        inv_dK = const[c, CC_INV_DK]
        kind = LINEAR if signed_inv_dO < 0.0 else MUNJIZA
        tanpsi = dil[c, CD_TANPSI]
        ulim = dil[c, CD_ULIM]
        sig0, tau0, Dn0, kn0, sn0, dn0, wI0, wII0, wf0 = point_law(
            o0, s0, state[c, CS_D0], state[c, CS_KAP0], state[c, CS_SPL0], tp0, Kn, Kt, op, C, tanphi, inv_dO,
            inv_dK, kind, Kc, state[c, CS_DIL0], np0, tanpsi, ulim)
        sig1, tau1, Dn1, kn1, sn1, dn1, wI1, wII1, wf1 = point_law(
            o1, s1, state[c, CS_D1], state[c, CS_KAP1], state[c, CS_SPL1], tp1, Kn, Kt, op, C, tanphi, inv_dO,
            inv_dK, kind, Kc, state[c, CS_DIL1], np1, tanpsi, ulim)
        state[c, CS_D0] = Dn0
        state[c, CS_KAP0] = kn0
        state[c, CS_SPL0] = sn0
        state[c, CS_D1] = Dn1
        state[c, CS_KAP1] = kn1
        state[c, CS_SPL1] = sn1
        state[c, CS_TAU0] = tau0
        state[c, CS_TAU1] = tau1
        state[c, CS_SIG0] = sig0
        state[c, CS_SIG1] = sig1
        state[c, CS_DIL0] = dn0
        state[c, CS_DIL1] = dn1
        diss[c, CW_MODE_I] += wI0 + wI1
        diss[c, CW_MODE_II] += wII0 + wII1
        diss[c, CW_FRICTION] += wf0 + wf1
        # Faces turned more than 90 degrees apart (face A along x1 - x0, face B along x2 - x3,
        # parallel at the reference): the element only hinges on one end, which in this law is
        # a frictionless pin, and its mid-line frame degenerates as the fold nears 180 degrees
        # (|m| -> 0 flips n, turning a free opening into a huge closure). It breaks; its
        # faces belong to contact from here on.
        folded = fold <= 0.0
        broke = (Dn0 >= 1.0 and Dn1 >= 1.0) or folded
    keep = 0.0 if broke else 1.0
    F0x = keep * (sig0 * nx + tau0 * tx)
    F0y = keep * (sig0 * ny + tau0 * ty)
    F1x = keep * (sig1 * nx + tau1 * tx)
    F1y = keep * (sig1 * ny + tau1 * ty)
    return broke, F0x, F0y, F1x, F1y


@njit(cache=True, fastmath=True, inline="always")
def update_and_scatter(c, u, ref, f, nodes, const, status, state, diss, offset, dil, broke_flag):
    """Update element ``c`` and add its forces to its four nodes (``+F_i`` on the A node of end
    ``i``, ``-F_i`` on the B node). Returns 1 if it broke (and sets ``broke_flag[c]``), else 0."""
    broke, F0x, F0y, F1x, F1y = element_update(c, u, ref, nodes, const, status, state, diss, offset, dil)
    i0 = nodes[c, 0]
    i1 = nodes[c, 1]
    i2 = nodes[c, 2]
    i3 = nodes[c, 3]
    f[i0, 0] += F0x
    f[i0, 1] += F0y
    f[i3, 0] -= F0x
    f[i3, 1] -= F0y
    f[i1, 0] += F1x
    f[i1, 1] += F1y
    f[i2, 0] -= F1x
    f[i2, 1] -= F1y
    if broke:
        broke_flag[c] = 1
        return 1
    return 0


@njit(cache=True, parallel=True, fastmath=True)
def crack_forces_coloured(u, ref, f, nodes, const, status, state, diss, offset, dil, active, colour_ptr, broke_flag):
    """Add crack forces into ``f`` (n_nodes, 2) [N/m], colour by colour.

    ``active`` holds the live element ids grouped by colour, colour ``k`` in
    ``active[colour_ptr[k]:colour_ptr[k+1]]``; elements of one colour share no node, so each
    colour is scattered in parallel without races. Elements that break set
    ``broke_flag[c] = 1``. Returns the number of elements that broke.
    """
    nb = 0
    for k in range(colour_ptr.shape[0] - 1):
        for j in prange(colour_ptr[k], colour_ptr[k + 1]):
            nb += update_and_scatter(active[j], u, ref, f, nodes, const, status, state, diss, offset, dil, broke_flag)
    return nb


@njit(cache=True, fastmath=True)
def crack_forces_serial(u, ref, f, nodes, const, status, state, diss, offset, dil, active, broke_flag):
    """Serial version of :func:`crack_forces_coloured` for small active sets (no threading
    overhead; any element order is race-free on one thread)."""
    nb = 0
    for j in range(active.shape[0]):
        nb += update_and_scatter(active[j], u, ref, f, nodes, const, status, state, diss, offset, dil, broke_flag)
    return nb


@njit(cache=True, parallel=True, fastmath=True)
def crack_forces_store(u, ref, nodes, const, status, state, diss, offset, dil, active, fe, broke_flag):
    """Per-element pass of the store-and-gather scheme: ``fe[c] = [F0x, F0y, F1x, F1y]``.

    Returns the number of elements that broke (their ``fe`` row is zero from then on).
    """
    nb = 0
    for j in prange(active.shape[0]):
        c = active[j]
        broke, F0x, F0y, F1x, F1y = element_update(c, u, ref, nodes, const, status, state, diss, offset, dil)
        fe[c, CF_F0X] = F0x
        fe[c, CF_F0Y] = F0y
        fe[c, CF_F1X] = F1x
        fe[c, CF_F1Y] = F1y
        if broke:
            broke_flag[c] = 1
            nb += 1
    return nb


@njit(cache=True, parallel=True, fastmath=True)
def gather_node_forces(f, node_list, node_map, fe):
    """Gather pass: ``f[n] += sum of the (at most 2) element-end forces on node n``.

    ``node_map[n, k] = 4 c + slot`` (slot 0..3 in ``[A_p, A_q, B_q, B_p]``) or -1. Slots 0/3
    take ``+/-`` end 0 of ``fe``, slots 1/2 take ``+/-`` end 1.
    """
    for j in prange(node_list.shape[0]):
        n = node_list[j]
        fx = 0.0
        fy = 0.0
        for k in range(2):
            code = node_map[n, k]
            if code >= 0:
                c = code >> 2
                slot = code & 3
                end = 1 if (slot == 1 or slot == 2) else 0
                sgn = 1.0 if slot < 2 else -1.0
                fx += sgn * fe[c, CF_F0X + CF_END * end]
                fy += sgn * fe[c, CF_F0Y + CF_END * end]
        f[n, 0] += fx
        f[n, 1] += fy


@njit(cache=True)
def colour_elements(crack_triangles, n_tri):
    """Greedy colouring so that no two elements of one colour share a node.

    Two crack elements share a node exactly when they border the same triangle (the mesh is
    exploded), so the conflict graph is the line graph of the triangle adjacency graph
    (degree <= 3): greedy needs at most 5 colours, usually 4. Returns (n,) int32 colours.
    """
    used = np.zeros(n_tri, dtype=np.int32)  # bit mask of colours used around each triangle
    col = np.empty(crack_triangles.shape[0], dtype=np.int32)
    for c in range(crack_triangles.shape[0]):
        a = crack_triangles[c, 0]
        b = crack_triangles[c, 1]
        m = used[a] | used[b]
        k = 0
        while (m >> k) & 1:
            k += 1
        col[c] = k
        used[a] |= 1 << k
        used[b] |= 1 << k
    return col


@njit(cache=True, fastmath=True, inline="always")
def end_separations(c, u, ref, nodes, offset):
    """Opening and slip ``(o0, s0, o1, s1)`` [m] of both ends of element ``c``, offsets
    included, from the nodes' displacements ``u`` (:func:`element_kinematics`)."""
    _, _, o0, s0, o1, s1, _ = element_kinematics(c, u, ref, nodes, offset)
    return o0, s0, o1, s1


@njit(cache=True, fastmath=True)
def crack_elastic_energy(u, ref, nodes, const, state, offset, active):
    """Elastic energy stored in the live elements [J/m]: per end
    ``sec oe+^2/2 + Kc oe-^2/2 + tau^2/(2 Kt)`` with ``tau = Kt (s - s_pl)`` and the effective
    opening ``oe = o - d`` (``d`` the dilatant opening of the end, 0 without dilation)."""
    e = 0.0
    for j in range(active.shape[0]):
        c = active[j]
        o0, s0, o1, s1 = end_separations(c, u, ref, nodes, offset)
        e += _end_energy(o0, s0, state[c, CS_D0], state[c, CS_SPL0], state[c, CS_DIL0], const[c])
        e += _end_energy(o1, s1, state[c, CS_D1], state[c, CS_SPL1], state[c, CS_DIL1], const[c])
    return e


@njit(cache=True)
def node_spring_stiffness(nodes, const, active, n_nodes):
    """(n_nodes,) ``K_node = sum max(Kn, Kt, Kc)`` [N/m] over the ends of live elements on each
    node (a node is an end of at most 2 elements): the stiffest spring each node carries."""
    K = np.zeros(n_nodes)
    for j in range(active.shape[0]):
        c = active[j]
        k = max(const[c, CC_KN], const[c, CC_KT], const[c, CC_KC])
        for q in range(4):
            K[nodes[c, q]] += k
    return K


@njit(cache=True)
def stable_dt_kernel(mass, nodes, const, active, n_nodes):
    """Critical step of the crack springs: ``dt = min 2 / sqrt(K_a/m_a + K_b/m_b)`` over the
    node pairs of live elements, where ``K_node`` sums ``max(Kn, Kt, Kc)`` of the (<= 2) elements
    on the node (a Gershgorin bound on the highest frequency of the crack springs alone)."""
    K = node_spring_stiffness(nodes, const, active, n_nodes)
    dt = np.inf
    for j in range(active.shape[0]):
        c = active[j]
        for a, b in ((0, 3), (1, 2)):
            na = nodes[c, a]
            nb = nodes[c, b]
            w2 = K[na] / mass[na] + K[nb] / mass[nb]
            if w2 > 0.0:
                dt = min(dt, 2.0 / math.sqrt(w2))
    return dt


@njit(cache=True, fastmath=True)
def secant_stiffness(D, const_row):
    """Secant normal stiffness ``sec(D) = z(D) F_t / (o_p + D (o_r - o_p))`` of an end with
    damage ``D`` (``K_n`` at ``D = 0``, 0 at ``D >= 1``), from one constant row [N/m per end]."""
    Kn = const_row[CC_KN]
    if D <= 0.0:
        return Kn
    if D >= 1.0:
        return 0.0
    op = const_row[CC_OP]
    signed_inv_dO = const_row[CC_INV_DO]
    kind = LINEAR if signed_inv_dO < 0.0 else MUNJIZA
    return softening(D, kind) * Kn * op / (op + D / abs(signed_inv_dO))


@njit(cache=True)
def remap_damage(old_const, new_const, state, status, active):
    """Carry the damage of every damaged end over to new constants (a strength change).

    The secant stiffness ``sec(D)`` sets the stored normal energy ``sec o^2 / 2``; a change of
    strength changes ``sec`` at fixed ``D``. Each damaged end gets the damage ``D'`` with
    ``sec_new(D') = sec_old(D)`` (``sec`` falls monotonically from ``K_n`` to 0 on [0, 1], solved
    by bisection), so the change neither stores nor releases energy. If the current separation
    lies beyond the new envelope, the next update of the law softens the end and books the
    released energy as fracture dissipation. Plastic slip is kept; the shear spring energy
    ``K_t (s - s_pl)^2 / 2`` does not depend on the strength, nor does the dilatant opening
    ``d`` (a state variable), so the effective opening ``o - d`` and with it the stored energy
    ``sec (o - d)+^2 / 2`` are unchanged. Fully damaged ends (``D >= 1``) stay fully damaged.
    """
    for j in range(active.shape[0]):
        c = active[j]
        if status[c] == 0:
            continue
        for end in range(2):
            D = state[c, CS_D0 + CS_END * end]
            if D <= 0.0 or D >= 1.0:
                continue
            target = secant_stiffness(D, old_const[c])
            lo = 0.0
            hi = 1.0
            for _ in range(64):
                mid = 0.5 * (lo + hi)
                if secant_stiffness(mid, new_const[c]) > target:
                    lo = mid
                else:
                    hi = mid
            state[c, CS_D0 + CS_END * end] = 0.5 * (lo + hi)


@njit(cache=True, fastmath=True)
def _end_energy(o, s, D, sp, d, const_row):
    """Elastic energy stored at one end [J/m]: ``sec(D) oe+^2/2 + K_c oe-^2/2 + K_t (s - s_pl)^2/2``
    with the effective opening ``oe = o - d``."""
    opos = max(o - d, 0.0)
    oneg = min(o - d, 0.0)
    ds = s - sp
    return 0.5 * (secant_stiffness(D, const_row) * opos * opos + const_row[CC_KC] * oneg * oneg
                  + const_row[CC_KT] * ds * ds)


@njit(cache=True, fastmath=True)
def project_to_envelope(u, ref, nodes, const, status, state, diss, offset, dil, active):
    """Bring every end whose separation lies outside the (new) strength envelope back onto
    it at the current displacements ``u``, booking the energy this releases exactly.

    Called after a strength change: ends beyond the new tensile envelope soften, ends above
    the new shear strength slip plastically, by the law itself (:func:`point_law`) at fixed
    separation. With no motion there is no work, so the dissipation is the drop of stored
    energy ``E_before - E_after`` (:func:`_end_energy`, with the effective opening
    ``o - d`` before and after: a dilating slip moves energy from the shear to the normal
    spring), shared between mode I, mode II and friction in the proportions the law reports.
    Returns the energy released [J/m].
    """
    total = 0.0
    for j in range(active.shape[0]):
        c = active[j]
        o0, s0, o1, s1 = end_separations(c, u, ref, nodes, offset)
        Kn = const[c, CC_KN]
        Kt = const[c, CC_KT]
        op = const[c, CC_OP]
        C = const[c, CC_C]
        tanphi = const[c, CC_TANPHI]
        signed_inv_dO = const[c, CC_INV_DO]
        inv_dK = const[c, CC_INV_DK]
        Kc = const[c, CC_KC]
        kind = LINEAR if signed_inv_dO < 0.0 else MUNJIZA
        for end in range(2):
            o = o0 if end == 0 else o1
            s = s0 if end == 0 else s1
            D = state[c, CS_D0 + CS_END * end]
            kap = state[c, CS_KAP0 + CS_END * end]
            sp = state[c, CS_SPL0 + CS_END * end]
            d = state[c, CS_DIL0 + end]
            before = _end_energy(o, s, D, sp, d, const[c])
            sig, tau, Dn, kn, sn, dn, wI, wII, wf = point_law(
                o, s, D, kap, sp, UNKNOWN_TRACTION, Kn, Kt, op, C, tanphi, abs(signed_inv_dO), inv_dK, kind, Kc,
                d, UNKNOWN_TRACTION, dil[c, CD_TANPSI], dil[c, CD_ULIM])
            if Dn == D and kn == kap:
                continue
            if status[c] == 0:
                # The other end keeps its zero state; its normal traction history is unknown.
                state[c, CS_SIG0 + 1 - end] = UNKNOWN_TRACTION
            status[c] = 1
            state[c, CS_D0 + CS_END * end] = Dn
            state[c, CS_KAP0 + CS_END * end] = kn
            state[c, CS_SPL0 + CS_END * end] = sn
            state[c, CS_TAU0 + end] = tau
            state[c, CS_SIG0 + end] = sig
            state[c, CS_DIL0 + end] = dn
            released = max(before - _end_energy(o, s, Dn, sn, dn, const[c]), 0.0)
            share = wI + wII + wf
            if share > 0.0:
                diss[c, CW_MODE_I] += released * wI / share
                diss[c, CW_MODE_II] += released * wII / share
                diss[c, CW_FRICTION] += released * wf / share
            else:
                diss[c, CW_MODE_I] += released
            total += released
    return total
