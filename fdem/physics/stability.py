"""Critical time steps and critical viscosities of the model's stiffnesses.

Stable explicit step of a triangle (``h / c_p`` from its smallest altitude, and the exact
largest eigenvalue of its element matrix), of a penalty spring ``h sqrt(rho / p)``, of a spring
between two masses, and their combination ``1 / sqrt(sum 1 / dt_i^2)``; the critical
viscosity of a triangle, ``eta_c`` at which its highest mode is critically damped (Munjiza 2004,
ch. 4)."""
from __future__ import annotations

import numpy as np
from fdem.mesh.triangles import triangle_shape_gradients
from fdem.physics.elastic import elasticity_matrix

__all__ = ["stable_dt_altitude", "stable_dt_penalty", "stable_dt_spring", "damped_critical_dt",
           "combine_stable_dt", "triangle_critical_dt", "critical_viscosity_equilateral",
           "critical_viscosity"]


# --------------------------------------------------------------------------- stable steps
def stable_dt_altitude(smallest_altitude: float | np.ndarray, wave_speed: float | np.ndarray):
    """The textbook estimate ``dt = h_min / c_p`` [s] (Courant number 1 on the smallest altitude).

    Not a bound for a constant-strain triangle with lumped mass: the exact element critical
    step ``2 / omega_max`` is 0.67 to 0.94 times this value depending on shape and ``nu``
    (equilateral, nu = 0.3: 0.79). The solver therefore uses :func:`triangle_critical_dt`.
    """
    return np.asarray(smallest_altitude) / np.asarray(wave_speed)


def stable_dt_penalty(length: float | np.ndarray, penalty: float | np.ndarray, density: float | np.ndarray):
    """Critical step of a penalty spring ``p`` [Pa] acting over a length ``h`` [m]: ``dt = h sqrt(rho / p)``.

    From ``omega = (2 / h) sqrt(p / rho)`` and ``dt = 2 / omega`` (Munjiza 2004, sec. 4.3).
    """
    return np.asarray(length) * np.sqrt(np.asarray(density) / np.asarray(penalty))


def stable_dt_spring(stiffness, mass_a, mass_b=np.inf):
    """Critical step ``2 / omega`` of a spring ``k`` [N/m/m] between masses ``m_a``, ``m_b`` [kg/m].

    ``omega^2 = k (1/m_a + 1/m_b)`` (two-mass oscillator; ``m_b = inf`` for a spring to ground).
    """
    omega2 = np.asarray(stiffness) * (1.0 / np.asarray(mass_a) + 1.0 / np.asarray(mass_b))
    with np.errstate(divide="ignore"):
        return 2.0 / np.sqrt(omega2)


def damped_critical_dt(omega_max, damping_ratio):
    """Critical step of central differences with viscous damping ratio ``xi`` at ``omega_max``.

    ``dt = (2 / omega) (sqrt(1 + xi^2) - xi)`` (Belytschko et al. 2014, eq. 6.3.22).
    """
    xi = np.asarray(damping_ratio)
    return 2.0 / np.asarray(omega_max) * (np.sqrt(1.0 + xi * xi) - xi)


def combine_stable_dt(*dts: float) -> float:
    """Critical step when several stiffnesses act on the same nodes: ``dt = 1 / sqrt(sum 1/dt_i^2)``.

    With ``K = sum K_i``, ``lambda_max(M^-1 K) <= sum lambda_max(M^-1 K_i)``, i.e.
    ``omega^2 <= sum omega_i^2`` with ``omega_i = 2 / dt_i``: a conservative combination
    (the minimum alone is not a bound). Infinite entries (no constraint) are ignored.
    """
    inv2 = sum(0.0 if not np.isfinite(d) else 1.0 / float(d) ** 2 for d in dts)
    if any(np.isfinite(d) and d <= 0 for d in dts):
        raise ValueError(f"stable time steps must be positive, got {dts}")
    return float("inf") if inv2 == 0.0 else 1.0 / np.sqrt(inv2)


def _voigt_gram(inv_dm: np.ndarray) -> np.ndarray:
    """(n, 3, 3) ``G = B_v B_v^T`` of the Voigt strain-displacement matrix ``B_v`` (3 x 6) of each triangle."""
    g = np.stack([-(inv_dm[:, 0] + inv_dm[:, 1]), inv_dm[:, 0], inv_dm[:, 1]], axis=1)  # (n, 3 nodes, 2)
    gx, gy = g[..., 0], g[..., 1]
    G = np.empty((len(inv_dm), 3, 3))
    G[:, 0, 0] = (gx * gx).sum(1)
    G[:, 1, 1] = (gy * gy).sum(1)
    G[:, 2, 2] = (gx * gx + gy * gy).sum(1)
    G[:, 0, 1] = G[:, 1, 0] = 0.0
    G[:, 0, 2] = G[:, 2, 0] = (gx * gy).sum(1)
    G[:, 1, 2] = G[:, 2, 1] = (gx * gy).sum(1)
    return G


def _sym_sqrt(c: np.ndarray) -> np.ndarray:
    w, q = np.linalg.eigh(c)
    return (q * np.sqrt(np.maximum(w, 0.0))) @ q.T


def triangle_critical_dt(x0: np.ndarray, triangles: np.ndarray, lam, mu, density, viscosity=0.0) -> np.ndarray:
    """(n_tri,) exact critical central-difference step [s] of each free constant-strain triangle.

    With lumped masses ``m = rho A0 / 3`` per corner and stiffness ``K = A0 B_v^T C B_v``,
    ``omega_max^2 = (3 / rho) lambda_max(C^1/2 G C^1/2)`` with ``G = B_v B_v^T`` (3 x 3). The
    viscous term ``S_v = eta dE/dt`` adds a damping matrix with Voigt ``C_v = diag(eta, eta, eta/2)``;
    its largest rate ``c_max = (3 / rho) lambda_max(C_v^1/2 G C_v^1/2)`` gives the damping ratio
    ``xi = c_max / (2 omega_max)`` used in :func:`damped_critical_dt`. By the element eigenvalue
    theorem (Belytschko et al. 2014, sec. 6.3.5) the assembled mesh, exploded or conforming, is
    no stiffer than its stiffest element. ``lam``, ``mu``, ``density``, ``viscosity`` are scalars
    or (n_tri,) arrays.
    """
    inv_dm, _ = triangle_shape_gradients(x0, triangles)
    G = _voigt_gram(inv_dm)
    n = len(triangles)
    lam, mu, rho, eta = (np.broadcast_to(np.asarray(a, dtype=float), (n,)) for a in (lam, mu, density, viscosity))
    omega = np.empty(n)
    rate = np.zeros(n)
    # group by distinct material so each C^1/2 is computed once
    keys = np.stack([lam, mu, rho, eta], axis=1)
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    for k, (l_, m_, r_, e_) in enumerate(uniq):
        sel = inverse == k
        s = _sym_sqrt(elasticity_matrix(l_, m_))
        omega[sel] = np.sqrt(3.0 / r_ * np.linalg.eigvalsh(s @ G[sel] @ s)[:, -1])
        if e_ > 0:
            sv = np.diag(np.sqrt([e_, e_, 0.5 * e_]))
            rate[sel] = 3.0 / r_ * np.linalg.eigvalsh(sv @ G[sel] @ sv)[:, -1]
    return damped_critical_dt(omega, rate / (2.0 * omega))


# --------------------------------------------------------------------------- element damping
def critical_viscosity_equilateral(altitude, lam, mu, density):
    """Viscosity [Pa s] that critically damps the highest mode of an equilateral CST.

    ``eta_crit = (4/3) h sqrt(rho (lambda + mu))`` with ``h`` the altitude [m], ``lambda``,
    ``mu`` the 2D Lame constants [Pa], ``rho`` [kg/m^3]. Derivation: the shape-function
    gradients of an equilateral triangle have length ``1/h`` at 120 degrees, so
    ``G = B_v B_v^T = (3 / (2 h^2)) diag(1, 1, 2)``; with lumped masses ``rho A0 / 3`` the
    highest mode is the uniform dilatation, ``omega_max^2 = 9 (lambda + mu) / (rho h^2)``, and
    the viscous law ``S_v = eta dE/dt`` (Voigt ``C_v = eta diag(1, 1, 1/2)``) damps it at the
    rate ``c = 9 eta / (2 rho h^2)`` with the same mode shape (no modal coupling). Critical
    damping ``c = 2 omega_max`` gives the formula. Plane strain, ``nu = 0.25``:
    ``eta_crit = 1.193 h sqrt(E rho)``, so Munjiza's (2004, sec. 4.2) ``2 h sqrt(E rho)`` is
    1.68 times critical. Belytschko et al. (2014, sec. 6.3) for modal damping ratios.
    """
    return 4.0 / 3.0 * np.asarray(altitude) * np.sqrt(np.asarray(density) * (np.asarray(lam) + np.asarray(mu)))


def critical_viscosity(x0: np.ndarray, triangles: np.ndarray, lam, mu, density) -> np.ndarray:
    """(n_tri,) viscosity ``eta_crit`` [Pa s] that critically damps each free triangle's highest mode.

    Highest mode of ``M^-1 K`` (lumped ``M = (rho A0 / 3) I``, ``K = A0 B_v^T C B_v``): the
    displacement ``u = B_v^T w`` with ``w = C^1/2 y``, ``y`` the top eigenvector of
    ``C^1/2 G C^1/2``, ``G = B_v B_v^T``; ``omega_max^2 = (3 / rho) lambda_max``. Its viscous
    rate per unit ``eta`` is the Rayleigh quotient ``c_1 = (3 / rho) (w^T G D G w) / (w^T G w)``
    with ``D = diag(1, 1, 1/2)`` (the Voigt matrix of ``S_v = eta dE/dt`` for ``eta = 1``).
    Critical damping of that mode: ``eta_crit = 2 omega_max / c_1``. Exact (the mode is also a
    mode of the damping) for the equilateral triangle, where it equals
    :func:`critical_viscosity_equilateral`; for other shapes the damping couples modes weakly
    and the value is the modal (Rayleigh-quotient) estimate. ``lam``, ``mu``, ``density`` are
    scalars or (n_tri,) arrays [Pa, Pa, kg/m^3].
    """
    inv_dm, _ = triangle_shape_gradients(x0, triangles)
    G = _voigt_gram(inv_dm)
    n = len(triangles)
    lam, mu, rho = (np.broadcast_to(np.asarray(a, dtype=float), (n,)) for a in (lam, mu, density))
    C = np.zeros((n, 3, 3))
    C[:, 0, 0] = C[:, 1, 1] = lam + 2.0 * mu
    C[:, 0, 1] = C[:, 1, 0] = lam
    C[:, 2, 2] = mu
    wc, qc = np.linalg.eigh(C)
    c_half = np.einsum("nij,nj,nkj->nik", qc, np.sqrt(wc), qc)
    w, q = np.linalg.eigh(c_half @ G @ c_half)
    y = q[:, :, -1]
    omega = np.sqrt(3.0 / rho * w[:, -1])
    gw = np.einsum("nij,nj->ni", G, np.einsum("nij,nj->ni", c_half, y))
    D = np.array([1.0, 1.0, 0.5])
    c1 = 3.0 / rho * (gw * gw * D).sum(1) / np.einsum("ni,ni->n", np.einsum("nij,nj->ni", c_half, y), gw)
    return 2.0 * omega / c1
