"""Numba kernel for output: the tractions crack elements carry at the current positions.

The tractions come from the same law the step uses, :func:`fdem.kernels.cracks.point_law`, fed
with the separations :func:`fdem.kernels.cracks.end_separations` measures and the element's
stored state; the state is read, never written, so an output frame changes nothing in the run.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from fdem.kernels.cracks import (CC_C, CC_INV_DK, CC_INV_DO, CC_KC, CC_KN, CC_KT, CC_OP, CC_TANPHI, CD_TANPSI,
                                 CD_ULIM, CS_D0, CS_DIL0, CS_END, CS_KAP0, CS_SIG0, CS_SPL0, CS_TAU0, LINEAR, MUNJIZA,
                                 UNKNOWN_TRACTION, end_separations, point_law)

__all__ = ["crack_tractions"]


@njit(cache=True, parallel=True)
def crack_tractions(u, ref, nodes, const, status, state, offset, dil, broken, out):
    """``out[c] = [sigma_0, tau_0, sigma_1, tau_1]``: normal and shear force per end [N/m per
    end] of element ``c`` (internal order) at the nodes' displacements ``u`` (reference rows ``ref``), as :func:`point_law` gives them
    with the constants carrying the end weight ``w = L0/2`` (divide by ``w`` for tractions [Pa]).

    Normal: tension positive, compression negative; shear: the force resisting the slip ``s``
    (sign of ``s - s_pl`` in the elastic range). An element that never left the elastic range
    (``status 0``) has a zero state row (``D = kappa = s_pl = d = 0``), which is what the law's
    fast path assumes; a broken element (``broken[c]``) carries nothing: zeros.
    """
    for c in prange(nodes.shape[0]):
        if broken[c]:
            for k in range(4):
                out[c, k] = 0.0
            continue
        o0, s0, o1, s1 = end_separations(c, u, ref, nodes, offset)
        signed_inv_dO = const[c, CC_INV_DO]
        kind = LINEAR if signed_inv_dO < 0.0 else MUNJIZA
        inelastic = status[c] != 0
        for e in range(2):
            o = o0 if e == 0 else o1
            s = s0 if e == 0 else s1
            D = 0.0
            kap = 0.0
            sp = 0.0
            d = 0.0
            tp = UNKNOWN_TRACTION
            sigp = UNKNOWN_TRACTION
            if inelastic:
                D = state[c, CS_D0 + CS_END * e]
                kap = state[c, CS_KAP0 + CS_END * e]
                sp = state[c, CS_SPL0 + CS_END * e]
                d = state[c, CS_DIL0 + e]
                tp = state[c, CS_TAU0 + e]
                sigp = state[c, CS_SIG0 + e]
            sig, tau, _, _, _, _, _, _, _ = point_law(
                o, s, D, kap, sp, tp, const[c, CC_KN], const[c, CC_KT], const[c, CC_OP], const[c, CC_C],
                const[c, CC_TANPHI], abs(signed_inv_dO), const[c, CC_INV_DK], kind, const[c, CC_KC], d, sigp,
                dil[c, CD_TANPSI], dil[c, CD_ULIM])
            out[c, 2 * e] = sig
            out[c, 2 * e + 1] = tau
