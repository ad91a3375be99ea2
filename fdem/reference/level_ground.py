"""Level ground at rest: the depth below which a plane of given dip is beyond Mohr-Coulomb.

Under level ground with the sides held (uniaxial strain, plane strain), a linear elastic rock of
unit weight ``gamma`` carries ``sigma_v = gamma z`` and ``sigma_h = K0 gamma z`` at depth ``z``
with ``K0 = nu / (1 - nu)`` (compression positive here). On a plane dipping ``theta`` (its normal
``theta`` from the vertical)::

    sigma_n = (cos^2 theta + K0 sin^2 theta) gamma z
    tau     = (1 - K0) sin theta cos theta gamma z

and Mohr-Coulomb ``|tau| <= c + sigma_n tan(phi)`` fails first at

    z* = c / (gamma [ (1 - K0) |sin theta cos theta| - (cos^2 theta + K0 sin^2 theta) tan(phi) ])

where the bracket is positive; where it is not, the plane holds at every depth (friction alone
carries the stress ratio). Jaeger, Cook & Zimmerman (2007), *Fundamentals of Rock Mechanics*,
4th ed., sec. 2.2 (tractions on a plane) and 4.5 (Coulomb); the same stress state as the static
start of a model with rollers on its sides (``tests/verification/test_geostatic.py``).

Imports nothing else of the package (ground floor).
"""
from __future__ import annotations

import math

__all__ = ["k0_uniaxial_strain", "plane_tractions_per_depth", "slip_depth"]


def k0_uniaxial_strain(poisson: float) -> float:
    """``K0 = nu / (1 - nu)``: horizontal over vertical stress in uniaxial strain [-]."""
    if not 0.0 <= poisson < 0.5:
        raise ValueError(f"Poisson's ratio must lie in [0, 0.5), got {poisson}")
    return poisson / (1.0 - poisson)


def plane_tractions_per_depth(dip_deg: float, k0: float) -> tuple[float, float]:
    """``(sigma_n, |tau|) / (gamma z)`` on a plane dipping ``dip_deg`` under level ground [-]."""
    t = math.radians(dip_deg)
    return (math.cos(t) ** 2 + k0 * math.sin(t) ** 2, (1.0 - k0) * abs(math.sin(t) * math.cos(t)))


def slip_depth(cohesion: float, friction_angle_deg: float, dip_deg: float, unit_weight: float, k0: float) -> float:
    """Depth ``z*`` [m] below which a plane dipping ``dip_deg`` is beyond Mohr-Coulomb under level
    ground (module docstring); ``inf`` where it holds at every depth.

    ``cohesion`` [Pa], ``friction_angle_deg`` [deg], ``unit_weight`` ``gamma = rho g`` [N/m^3]."""
    if cohesion < 0 or unit_weight <= 0:
        raise ValueError(f"need cohesion >= 0 and unit_weight > 0, got {cohesion} and {unit_weight}")
    sn, tau = plane_tractions_per_depth(dip_deg, k0)
    excess = tau - sn * math.tan(math.radians(friction_angle_deg))
    return cohesion / (unit_weight * excess) if excess > 0 else math.inf
