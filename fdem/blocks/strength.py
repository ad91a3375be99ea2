"""Mohr-Coulomb strength of the interfaces of a block system, by tag, reduced by a factor F.

An interface of length ``L`` carries a normal force ``N`` (compression positive) and a shear
force ``T`` [N/m] with

    |T| <= N tan(phi) / F + c L / F        (Mohr-Coulomb, the cone of the SOCP)
    N   >= -f_t L / F                      (tension cut-off)

the same strength-reduction factor ``F`` on ``c``, ``tan(phi)`` and ``f_t`` as the FDEM path
(:mod:`fdem.physics.interfaces`). The cut-off cannot exceed the cone's apex ``c / tan(phi)``
(there the cone alone allows no more tension); it is clamped to it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

__all__ = ["Strength", "strengths_from", "interface_strength"]


@dataclass(frozen=True)
class Strength:
    """Strength of one interface tag: cohesion ``c`` [Pa], friction angle ``phi`` [deg], tensile
    strength ``f_t`` [Pa]."""

    c: float
    phi: float
    f_t: float = 0.0
    name: str = ""

    def __post_init__(self):
        if not (self.c >= 0 and self.f_t >= 0 and 0 <= self.phi < 90):
            raise ValueError(f"strength {self.name!r}: need c >= 0, f_t >= 0 and 0 <= phi < 90 deg, got "
                             f"c = {self.c} Pa, f_t = {self.f_t} Pa, phi = {self.phi} deg")


def strengths_from(properties: Mapping[int, object], contact_friction: float | None = None) -> dict[int, Strength]:
    """:class:`Strength` per tag from objects with ``c``, ``phi`` and ``f_t`` (e.g. the cases'
    :class:`~fdem.physics.crack_properties.CrackProperties` tables), plus a cohesionless contact
    (tag -1) of friction ``contact_friction`` [deg] when given."""
    out = {int(k): Strength(float(p.c), float(p.phi), float(p.f_t), getattr(p, "name", str(k)))
           for k, p in properties.items()}
    if contact_friction is not None:
        out[-1] = Strength(0.0, float(contact_friction), 0.0, "contact")
    return out


def interface_strength(tags: np.ndarray, strengths: Mapping[int, Strength], factor: float = 1.0
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(mu, c, f_t)`` per interface, reduced by ``factor`` F: ``tan(phi)/F``, ``c/F`` [Pa] and
    ``min(f_t, c/tan(phi))/F`` [Pa]. A tag without a strength is an error naming it."""
    if not (math.isfinite(factor) and factor > 0):
        raise ValueError(f"strength reduction factor must be positive, got {factor}")
    missing = sorted(set(np.unique(tags).tolist()) - set(strengths))
    if missing:
        raise ValueError(f"no strength given for interface tag(s) {missing} (0: rock bridges, >= 1: joint sets, "
                         f"-1: contacts between bodies); given: {sorted(strengths)}")
    table = {t: (math.tan(math.radians(s.phi)), s.c, s.f_t) for t, s in strengths.items()}
    mu = np.array([table[t][0] for t in tags.tolist()], dtype=np.float64)
    c = np.array([table[t][1] for t in tags.tolist()], dtype=np.float64)
    ft = np.array([table[t][2] for t in tags.tolist()], dtype=np.float64)
    with np.errstate(divide="ignore"):
        apex = np.where(mu > 0, c / np.where(mu > 0, mu, 1.0), np.inf)
    return mu / factor, c / factor, np.minimum(ft, apex) / factor
