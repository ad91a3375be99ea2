"""Limit-equilibrium factor of safety of a planar slope failure (the verification reference).

A rigid block slides on one persistent plane that daylights in the face. Hoek & Bray (Rock
Slope Engineering, 3rd ed. 1981, ch. 7) and Wyllie & Mah (Rock Slope Engineering, 4th ed. 2004,
ch. 6, eqs. 6.2-6.6):

    F = [c A + (W cos(psi_p) - U - V sin(psi_p)) tan(phi)] / [W sin(psi_p) + V cos(psi_p)]

per metre of slope, with

* ``A`` [m] the length of the sliding plane (from its daylight in the face to the upper ground
  surface, or to the foot of the tension crack): ``A = (H - z) / sin(psi_p)``;
* ``W`` [N/m] the block's weight. Horizontal upper surface, tension crack of depth ``z`` in it
  (Hoek & Bray eq. 7.7; Wyllie & Mah eq. 6.5 with ``psi_s = 0``):
  ``W = gamma H^2 / 2 [(1 - (z/H)^2) cot(psi_p) - cot(psi_f)]``, and ``z = 0`` without a crack;
* ``U = gamma_w z_w A / 2`` [N/m] the uplift of the water pressure on the plane, falling
  linearly from ``gamma_w z_w`` at the foot of the crack to zero at the daylight, and
  ``V = gamma_w z_w^2 / 2`` [N/m] the water thrust in a crack filled to depth ``z_w``.

The crack stands ``b`` behind the crest; with the plane through the daylight point its depth is
``z = H - (H cot(psi_f) + b) tan(psi_p)``, so either ``z`` or ``b`` fixes it. For a dry slope the
crack depth that minimises ``F`` is ``z_c / H = 1 - sqrt(cot(psi_f) tan(psi_p))`` at
``b_c / H = sqrt(cot(psi_f) cot(psi_p)) - cot(psi_f)`` (Hoek & Bray eqs. 7.12-7.13).

Units: SI; lengths in m, stresses in Pa, unit weights in N/m^3, forces per metre in N/m.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

__all__ = ["WATER_UNIT_WEIGHT", "PlanarResult", "crack_depth_from_offset", "crack_offset_from_depth",
           "critical_tension_crack", "planar_fos"]


WATER_UNIT_WEIGHT = 9.81e3
"""Unit weight of water ``gamma_w = rho_w g`` [N/m^3]."""


@dataclass(frozen=True)
class PlanarResult:
    """Result of :func:`planar_fos` (forces per metre of slope).

    fos : factor of safety F [-]
    weight : W [N/m]
    plane_length : A [m]
    uplift : U [N/m]
    crack_thrust : V [N/m]
    resisting : ``c A + (W cos psi_p - U - V sin psi_p) tan phi`` [N/m]
    driving : ``W sin psi_p + V cos psi_p`` [N/m]
    crack_depth : z [m] (0 without a crack)
    crack_offset : b [m] behind the crest (None without a crack)
    """

    fos: float
    weight: float
    plane_length: float
    uplift: float
    crack_thrust: float
    resisting: float
    driving: float
    crack_depth: float
    crack_offset: float | None

    @property
    def W(self) -> float:
        return self.weight

    @property
    def A(self) -> float:
        return self.plane_length

    @property
    def U(self) -> float:
        return self.uplift

    @property
    def V(self) -> float:
        return self.crack_thrust

    def as_dict(self) -> dict:
        return asdict(self)


def _cot(deg: float) -> float:
    return 1.0 / math.tan(math.radians(deg))


def crack_depth_from_offset(height: float, face_angle: float, plane_angle: float, offset: float) -> float:
    """Depth ``z = H - (H cot(psi_f) + b) tan(psi_p)`` [m] of a vertical crack ``b`` [m] behind the
    crest that reaches the plane daylighting at the foot of the face (Hoek & Bray fig. 7.4)."""
    return height - (height * _cot(face_angle) + offset) * math.tan(math.radians(plane_angle))


def crack_offset_from_depth(height: float, face_angle: float, plane_angle: float, depth: float) -> float:
    """Inverse of :func:`crack_depth_from_offset`: ``b = (H - z) cot(psi_p) - H cot(psi_f)`` [m]."""
    return (height - depth) * _cot(plane_angle) - height * _cot(face_angle)


def critical_tension_crack(height: float, face_angle: float, plane_angle: float) -> tuple[float, float]:
    """``(z_c, b_c)`` [m] of the dry slope: ``z_c = H (1 - sqrt(cot psi_f tan psi_p))``,
    ``b_c = H (sqrt(cot psi_f cot psi_p) - cot psi_f)`` (Hoek & Bray 1981, eqs. 7.12-7.13)."""
    cf, cp = _cot(face_angle), _cot(plane_angle)
    return height * (1.0 - math.sqrt(cf / cp)), height * (math.sqrt(cf * cp) - cf)


def planar_fos(height: float, face_angle: float, plane_angle: float, cohesion: float, friction_angle: float,
               unit_weight: float, tension_crack_depth: float | None = None,
               tension_crack_offset: float | None = None, water_depth: float = 0.0,
               water_unit_weight: float = WATER_UNIT_WEIGHT) -> PlanarResult:
    """Hoek-Bray factor of safety of a planar failure with a horizontal upper slope surface.

    Parameters
    ----------
    height : H [m], height of the face above the point where the plane daylights
    face_angle, plane_angle : psi_f, psi_p [deg], ``0 < psi_p < psi_f <= 90``
    cohesion : c [Pa] of the plane; friction_angle : phi [deg]
    unit_weight : gamma = rho g of the rock [N/m^3]
    tension_crack_depth : z [m], or ``tension_crack_offset`` b [m] behind the crest (give one,
        or both if consistent); neither: no crack, the plane runs to the upper surface
    water_depth : z_w [m] of water standing in the crack (needs a crack), ``0 <= z_w <= z``

    Returns a :class:`PlanarResult` with ``F`` and ``W, A, U, V`` per metre. Formula in the
    module docstring (Hoek & Bray 1981, eqs. 7.5-7.9; Wyllie & Mah 2004, eqs. 6.2-6.6).
    """
    H, pf, pp = float(height), float(face_angle), float(plane_angle)
    if not H > 0:
        raise ValueError(f"slope height must be positive, got {height} m")
    if not 0 < pp < pf <= 90:
        raise ValueError(f"need 0 < plane angle < face angle <= 90 deg for the plane to daylight in the face, "
                         f"got plane {plane_angle} deg, face {face_angle} deg")
    if cohesion < 0 or not 0 <= friction_angle < 90:
        raise ValueError(f"need cohesion >= 0 and 0 <= friction angle < 90 deg, got {cohesion} Pa, "
                         f"{friction_angle} deg")
    if not unit_weight > 0:
        raise ValueError(f"unit weight must be positive, got {unit_weight} N/m^3")
    z, b = 0.0, None
    if tension_crack_offset is not None:
        b = float(tension_crack_offset)
        z = crack_depth_from_offset(H, pf, pp, b)
        if tension_crack_depth is not None and not math.isclose(z, tension_crack_depth, rel_tol=1e-6, abs_tol=1e-9 * H):
            raise ValueError(f"tension crack depth {tension_crack_depth} m and offset {b} m disagree: a crack "
                             f"{b} m behind the crest reaches the plane at depth {z:.6g} m")
    elif tension_crack_depth is not None:
        z = float(tension_crack_depth)
        b = crack_offset_from_depth(H, pf, pp, z)
    if b is not None and not (0.0 <= z < H and b >= 0.0):
        raise ValueError(f"the tension crack must stand behind the crest (b >= 0) and reach the plane below the "
                         f"surface (0 <= z < H = {H} m), got z = {z:.6g} m, b = {b:.6g} m")
    zw = float(water_depth)
    if zw < 0 or zw > z + 1e-12 * H:
        raise ValueError(f"water depth must lie in [0, crack depth {z:.6g} m], got {water_depth} m"
                         + ("" if b is not None else " (water needs a tension crack)"))

    sp, cp = math.sin(math.radians(pp)), math.cos(math.radians(pp))
    A = (H - z) / sp
    W = 0.5 * unit_weight * H * H * ((1.0 - (z / H) ** 2) * _cot(pp) - _cot(pf))
    U = 0.5 * water_unit_weight * zw * A
    V = 0.5 * water_unit_weight * zw * zw
    resisting = cohesion * A + (W * cp - U - V * sp) * math.tan(math.radians(friction_angle))
    driving = W * sp + V * cp
    return PlanarResult(fos=resisting / driving, weight=W, plane_length=A, uplift=U, crack_thrust=V,
                        resisting=resisting, driving=driving, crack_depth=z, crack_offset=b)
