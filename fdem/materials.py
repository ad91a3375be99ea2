"""Pure elastic laws: Lame constants, plane strain / plane stress, wave speeds, stable steps.

Everything here is a small function of numbers or arrays, with no solver state, so the laws
can be tested alone and reused by the kernels (which receive the numbers, never the objects).

Conventions
-----------
* SI units throughout. Two-dimensional quantities are **per unit thickness** (1 m): forces
  [N/m], energies [J/m], masses [kg/m].
* Stresses are positive in tension.
* Voigt order ``(xx, yy, xy)`` with *engineering* shear strain ``gamma_xy = 2 eps_xy`` where a
  3x3 elasticity matrix is used.

References
----------
* Timoshenko & Goodier (1970), *Theory of Elasticity*, 3rd ed., ch. 2 (plane strain/stress).
* Graff (1975), *Wave Motion in Elastic Solids*, ch. 1 and 8 (bar and P-wave speeds).
* Belytschko, Liu, Moran & Elkhodary (2014), *Nonlinear Finite Elements for Continua and
  Structures*, 2nd ed., sec. 6.3 (critical step of central differences, element eigenvalue
  theorem, damping).
* Munjiza (2004), *The Combined Finite-Discrete Element Method*, ch. 4 and 8 (penalty step).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PLANE_STRAIN = "strain"
PLANE_STRESS = "stress"


# --------------------------------------------------------------------------- moduli
def lame_constants(young: float, poisson: float) -> tuple[float, float]:
    """Lame constants ``(lambda, mu)`` [Pa] of an isotropic solid (3D / plane strain).

    ``lambda = E nu / ((1 + nu)(1 - 2 nu))``, ``mu = E / (2 (1 + nu))``
    (Timoshenko & Goodier 1970, eq. 8-9).
    """
    _check_elastic(young, poisson)
    lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    mu = young / (2.0 * (1.0 + poisson))
    return lam, mu


def plane_stress_lambda(lam: float, mu: float) -> float:
    """Effective first Lame constant for plane stress [Pa]: ``lambda* = 2 lambda mu / (lambda + 2 mu)``.

    Eliminating ``sigma_zz = 0`` from the 3D law gives the 2D law with ``lambda*`` in place of
    ``lambda`` and the same ``mu`` (Timoshenko & Goodier 1970, sec. 16).
    """
    return 2.0 * lam * mu / (lam + 2.0 * mu)


def plane_lame_constants(young: float, poisson: float, plane: str = PLANE_STRAIN) -> tuple[float, float]:
    """2D Lame constants ``(lambda_2d, mu)`` [Pa] for ``plane="strain"`` or ``"stress"``."""
    lam, mu = lame_constants(young, poisson)
    if plane == PLANE_STRAIN:
        return lam, mu
    if plane == PLANE_STRESS:
        return plane_stress_lambda(lam, mu), mu
    raise ValueError(f"plane must be {PLANE_STRAIN!r} or {PLANE_STRESS!r}, got {plane!r}")


def elasticity_matrix(lam: float, mu: float) -> np.ndarray:
    """3x3 Voigt matrix ``C`` with ``[s_xx, s_yy, s_xy] = C [e_xx, e_yy, gamma_xy]`` [Pa]."""
    return np.array([[lam + 2.0 * mu, lam, 0.0], [lam, lam + 2.0 * mu, 0.0], [0.0, 0.0, mu]])


def k0_elastic(poisson: float) -> float:
    """Earth-pressure coefficient at rest of a laterally confined elastic column: ``K0 = nu / (1 - nu)``.

    Uniaxial strain (``eps_xx = eps_zz = 0``) gives ``sigma_xx = nu/(1-nu) sigma_yy``.
    """
    return poisson / (1.0 - poisson)


# --------------------------------------------------------------------------- wave speeds
def p_wave_speed(young: float, poisson: float, density: float, plane: str = PLANE_STRAIN) -> float:
    """Speed [m/s] of a longitudinal wave under uniaxial strain in the 2D model.

    Plane strain: ``c_p = sqrt((lambda + 2 mu)/rho) = sqrt(E (1 - nu) / (rho (1 + nu)(1 - 2 nu)))``
    (Graff 1975, eq. 5.1.11). Plane stress: ``sqrt((lambda* + 2 mu)/rho) = sqrt(E / (rho (1 - nu^2)))``,
    the plate (sheet) wave speed.
    """
    lam, mu = plane_lame_constants(young, poisson, plane)
    return float(np.sqrt((lam + 2.0 * mu) / density))


def s_wave_speed(young: float, poisson: float, density: float) -> float:
    """Shear-wave speed ``c_s = sqrt(mu / rho)`` [m/s]."""
    _, mu = lame_constants(young, poisson)
    return float(np.sqrt(mu / density))


def bar_wave_speed(young: float, density: float) -> float:
    """Long-wavelength speed in a slender bar with free sides, ``c_0 = sqrt(E / rho)`` [m/s] (Graff 1975, sec. 2.1)."""
    return float(np.sqrt(young / density))


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


def triangle_shape_gradients(x0: np.ndarray, triangles: np.ndarray):
    """Inverse reference shape matrices and areas of triangles.

    ``Dm = [X1 - X0, X2 - X0]`` (columns), ``B = Dm^-1`` (n_tri, 2, 2) [1/m], ``A0 = det(Dm)/2``
    (n_tri,) [m^2]. Shape-function gradients: ``grad N1 = B[0]``, ``grad N2 = B[1]``,
    ``grad N0 = -(B[0] + B[1])``.
    """
    p0, p1, p2 = x0[triangles[:, 0]], x0[triangles[:, 1]], x0[triangles[:, 2]]
    dm = np.empty((len(triangles), 2, 2))
    dm[:, :, 0] = p1 - p0
    dm[:, :, 1] = p2 - p0
    det = dm[:, 0, 0] * dm[:, 1, 1] - dm[:, 0, 1] * dm[:, 1, 0]
    inv = np.empty_like(dm)
    inv[:, 0, 0] = dm[:, 1, 1] / det
    inv[:, 0, 1] = -dm[:, 0, 1] / det
    inv[:, 1, 0] = -dm[:, 1, 0] / det
    inv[:, 1, 1] = dm[:, 0, 0] / det
    return inv, 0.5 * det


def smallest_altitude(x0: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(n_tri,) smallest altitude ``h = 2 A / L_max`` of each triangle [m]."""
    p = x0[triangles]
    edges = np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2)
    area = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                        - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    return 2.0 * area / edges.max(axis=1)


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


# --------------------------------------------------------------------------- material
@dataclass(frozen=True)
class ElasticMaterial:
    """Isotropic St Venant-Kirchhoff rock with an optional viscous term.

    Attributes
    ----------
    young : float
        Young's modulus ``E`` [Pa].
    poisson : float
        Poisson's ratio ``nu`` [-], ``-1 < nu < 0.5``.
    density : float
        Mass density ``rho`` [kg/m^3].
    viscosity : float
        ``eta`` [Pa s] of the viscous stress ``S_v = eta dE/dt``; 0 for a conservative solid.
        Element-scale damping depends on the element size, so set it per triangle with
        :meth:`fdem.model.Model.set_element_damping` (a fraction of :func:`critical_viscosity`,
        about ``1.19 h sqrt(E rho)`` at ``nu = 0.25``; Munjiza 2004, sec. 4.2, uses ``2 h sqrt(E rho)``).
    plane : str
        ``"strain"`` (default) or ``"stress"``.
    """

    young: float
    poisson: float
    density: float
    viscosity: float = 0.0
    plane: str = PLANE_STRAIN

    def __post_init__(self):
        for name in ("young", "poisson", "density", "viscosity"):
            value = getattr(self, name)
            try:
                finite = bool(np.isfinite(float(value)))
            except (TypeError, ValueError):
                raise ValueError(f"ElasticMaterial: {name} must be a number, got {value!r}") from None
            if not finite:
                raise ValueError(f"ElasticMaterial: {name} must be finite, got {value!r}")
        _check_elastic(self.young, self.poisson)
        if not self.density > 0:
            raise ValueError(f"ElasticMaterial: density must be positive, got {self.density!r}")
        if not self.viscosity >= 0:
            raise ValueError(f"ElasticMaterial: viscosity must be >= 0, got {self.viscosity!r}")
        plane_lame_constants(self.young, self.poisson, self.plane)

    @property
    def lame(self) -> tuple[float, float]:
        """2D ``(lambda, mu)`` [Pa] for the chosen plane condition."""
        return plane_lame_constants(self.young, self.poisson, self.plane)

    @property
    def p_wave_modulus(self) -> float:
        """``M = lambda + 2 mu`` [Pa] (2D)."""
        lam, mu = self.lame
        return lam + 2.0 * mu

    @property
    def p_wave_speed(self) -> float:
        """Uniaxial-strain wave speed [m/s] of the 2D model, see :func:`p_wave_speed`."""
        return p_wave_speed(self.young, self.poisson, self.density, self.plane)

    @property
    def s_wave_speed(self) -> float:
        return s_wave_speed(self.young, self.poisson, self.density)

    def elasticity_matrix(self) -> np.ndarray:
        lam, mu = self.lame
        return elasticity_matrix(lam, mu)


def _check_elastic(young: float, poisson: float) -> None:
    if not young > 0:
        raise ValueError(f"Young's modulus must be positive, got {young}")
    if not -1.0 < poisson < 0.5:
        raise ValueError(f"Poisson's ratio must lie in (-1, 0.5), got {poisson}")
