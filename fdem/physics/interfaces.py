"""One home for interface properties and the strength-reduction factor.

Crack elements (intact rock bridges, tag 0, and DFN joint set ``j``, tag ``j``) and the contact
between broken faces both read their strength and friction from one :class:`Interfaces`
object, so a strength reduction reaches every crack element, every joint set, the residual
friction of broken elements and the contact friction of broken faces and free surfaces at
once, whatever broke when.

Strength reduction (shear strength reduction, Dawson, Roth & Drescher 1999; Griffiths & Lane
1999; for jointed rock, the four-slope paper of ``shared/cases.md`` A): with the factor ``F``

    c_F = c / F,   tan(phi_F) = tan(phi) / F,   tan(phi_res,F) = tan(phi_res) / F,
    f_t,F = f_t / F          (default; ``reduce_tensile=False`` keeps f_t),

and the contact friction of every face ``mu_F = mu / F``. The tensile strength is reduced by
default because the four-slope paper reduces "the cohesive and frictional strength" of the
crack elements, and in a cohesive crack element the tensile strength is part of the cohesive
strength. Fracture energies and penalties are kept. ``F = 1`` is the material as given; the
factor of safety is the ``F`` at which the slope fails (:mod:`fdem.workflow.stages`).

Friction belongs to the interface, not to the triangle: a contact pair across a broken crack
element uses that element's residual friction; any other pair uses the lower friction of the
two faces in touch (see :class:`fdem.physics.contact.ContactSet`).
"""
from __future__ import annotations

import math
from typing import Callable, Mapping, Sequence
import numpy as np

__all__ = ["Interfaces"]


class Interfaces:
    """Interface property sets by tag, the free-surface friction, and the reduction factor ``F``.

    Parameters
    ----------
    property_sets : mapping ``tag -> CrackProperties`` (or a sequence indexed by tag); tag 0 is
        intact rock, ``j >= 1`` DFN joint set ``j`` (:class:`fdem.physics.crack_properties.CrackProperties`).
    surface_friction_angle : float, optional
        Friction angle [deg] of the external (never bonded) faces in contact; default: the
        residual friction of tag 0 (the rock itself), or 0 when there is no tag 0.
    reduce_tensile : bool
        Whether ``F`` also divides the tensile strength (default True; see the module docstring).
    """

    def __init__(self, property_sets: Mapping | Sequence, surface_friction_angle: float | None = None,
                 reduce_tensile: bool = True) -> None:
        from fdem.physics.crack_properties import CrackProperties

        if not isinstance(property_sets, Mapping):
            property_sets = dict(enumerate(property_sets))
        self.property_sets = dict(property_sets)
        for tag, p in self.property_sets.items():
            if not isinstance(tag, (int, np.integer)) or tag < 0:
                raise ValueError(f"property-set keys are joint-set tags (int >= 0), got {tag!r}")
            if not isinstance(p, CrackProperties):
                raise ValueError(f"property set for tag {tag} must be a CrackProperties, got {type(p).__name__}")
        n_tags = int(max(self.property_sets)) + 1 if self.property_sets else 1
        self.tan_phi_res_base = np.zeros(n_tags)
        for t, p in self.property_sets.items():
            self.tan_phi_res_base[t] = p.tan_phi_res
        if surface_friction_angle is None:
            self.surface_mu_base = float(self.tan_phi_res_base[0]) if 0 in self.property_sets else 0.0
        else:
            phi = float(surface_friction_angle)
            if not (math.isfinite(phi) and 0.0 <= phi < 90.0):
                raise ValueError(f"surface_friction_angle must lie in [0, 90) deg, got {surface_friction_angle!r}")
            self.surface_mu_base = math.tan(math.radians(phi))
        self.reduce_tensile = bool(reduce_tensile)
        self._reduction = 1.0
        self._checks: list[Callable[[float], None]] = []
        self._listeners: list[Callable[[], None]] = []

    @classmethod
    def of(cls, property_sets) -> "Interfaces":
        """``property_sets`` if it already is an :class:`Interfaces`, else a new one around them."""
        return property_sets if isinstance(property_sets, Interfaces) else cls(property_sets)

    # ------------------------------------------------------------------ the factor
    @property
    def reduction(self) -> float:
        """The strength-reduction factor ``F`` (> 0): strengths and friction are divided by it."""
        return self._reduction

    @property
    def strength_factor(self) -> float:
        """``1 / F``: the multiplier on ``c`` and ``tan(phi)``."""
        return 1.0 / self._reduction

    @property
    def tensile_factor(self) -> float:
        """Multiplier on ``f_t``: ``1 / F`` when ``reduce_tensile``, else 1."""
        return 1.0 / self._reduction if self.reduce_tensile else 1.0

    def subscribe(self, on_change: Callable[[], None], check: Callable[[float], None] | None = None) -> None:
        """Call ``check(F)`` before and ``on_change()`` after every change of ``F`` (crack
        elements re-fill their constants, contact rescales its pair friction)."""
        if check is not None:
            self._checks.append(check)
        self._listeners.append(on_change)

    def set_reduction(self, factor: float) -> None:
        """Set the strength-reduction factor ``F`` (absolute, not cumulative; ``F > 0``).

        Every subscriber first checks the new value (e.g. the crack elements' snap-back
        condition, raised as ``ValueError`` before anything changes), then applies it.
        """
        factor = float(factor)
        if not (math.isfinite(factor) and factor > 0.0):
            raise ValueError(f"strength-reduction factor F must be positive and finite, got {factor!r}")
        for check in self._checks:
            check(factor)
        self._reduction = factor
        for fn in self._listeners:
            fn()

    def restore_reduction(self, factor: float) -> None:
        """Put back a saved ``F`` without checks or notices (a restart: the subscribers restore
        their own state, which already holds the values that depend on ``F``)."""
        self._reduction = float(factor)

    # ------------------------------------------------------------------ friction
    def residual_mu(self, tags: np.ndarray) -> np.ndarray:
        """Reduced residual friction coefficients ``tan(phi_res) / F`` of interfaces ``tags``."""
        return self.tan_phi_res_base[np.asarray(tags)] / self._reduction

    @property
    def surface_mu(self) -> float:
        """Reduced friction coefficient of external faces, ``tan(phi_surface) / F``."""
        return self.surface_mu_base / self._reduction
