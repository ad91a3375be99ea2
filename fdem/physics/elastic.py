"""Pure elastic laws: Lame constants, plane strain / plane stress, wave speeds, stress invariants.

Critical time steps and viscosities are :mod:`fdem.physics.stability`.

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

__all__ = ["PLANE_STRAIN", "PLANE_STRESS", "lame_constants", "plane_stress_lambda", "plane_lame_constants",
           "elasticity_matrix", "k0_elastic", "p_wave_speed", "s_wave_speed", "bar_wave_speed",
           "ElasticMaterial", "principal_stresses", "von_mises"]


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
        :meth:`fdem.solve.model.Model.set_element_damping` (a fraction of :func:`critical_viscosity`,
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


def principal_stresses(sxx, syy, sxy) -> tuple[np.ndarray, np.ndarray]:
    """In-plane principal stresses ``s1 >= s2`` [Pa]: ``(sxx + syy)/2 +- sqrt(((sxx - syy)/2)^2 + sxy^2)``."""
    c = 0.5 * (sxx + syy)
    r = np.sqrt((0.5 * (sxx - syy)) ** 2 + sxy**2)
    return c + r, c - r


def von_mises(sxx, syy, sxy, szz) -> np.ndarray:
    """Von Mises equivalent stress [Pa] of a state with in-plane components and ``s_zz``."""
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * sxy**2)
