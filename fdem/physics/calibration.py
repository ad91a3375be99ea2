"""Fracture energies that keep crack elements of a given size off snap-back, as a rule in the element size.

A crack element of length ``L`` has the penalty stiffness ``k = p / L`` per unit area, so the
elastic energy it stores at its peak grows with ``L``; the softening branch must release more
than that, or it snaps back (:meth:`fdem.physics.cracks.CrackSet._check_snap_back`):

    mode I:   G_I  > f_t^2 L / (2 p_n)
    mode II:  G_II > Zbar max|z'| c^2 L / p_t        (Zbar max|z'| = 0.788 for Munjiza's curve)

(``docs/cohesive.md``). A metre-size element cannot carry a laboratory toughness (a mudstone's
25 J/m^2 needs ``L < 3`` cm at ``p = 10 E``), so a slope-scale model takes the energies from
the element size:

    G(h) = margin x G_min(L = longest x h, strength x peak_factor),

with ``longest = 1.5`` (the longest crack element of a Gmsh "delaunay" mesh of target size
``h``: 1.34 to 1.43 h measured on the Muliashi slope at h = 0.5 to 1.5 m), ``peak_factor = 1.5``
(five standard deviations of a normal strength heterogeneity of coefficient of variation 0.1;
the largest of 5,000 draws was 1.39) and ``margin = 1.2``. ``G`` in proportion to ``h`` keeps
the brittleness ``h f_t^2 / (E G_I)`` of an element the same at every size, so a test whose
specimen is scaled with ``h`` (``W = k h``) is exactly self-similar: the same mesh, stresses and
strains at every ``h``, displacements in proportion to ``h``, the same strength
(``docs/calibration.md``). What it costs: the elements are tougher than the rock (more ductile
post-peak) the coarser the mesh.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from fdem.physics.crack_properties import CrackProperties, softening_integral, softening_max_slope

__all__ = ["LONGEST_EDGE", "PEAK_FACTOR", "MARGIN", "snap_back_limits", "SizeScaledEnergies", "size_scaled_properties"]

LONGEST_EDGE = 1.5
"""Longest crack element of a Gmsh "delaunay" mesh as a multiple of its target size ``h``."""

PEAK_FACTOR = 1.5
"""Strongest element's strength multiplier the rule allows for (normal heterogeneity, cov 0.1: 5 sd)."""

MARGIN = 1.2
"""Energy above the snap-back limit, so that round-off and a slightly longer element still pass."""


def snap_back_limits(f_t: float, c: float, p_n: float, p_t: float, length: float,
                     softening: str = "munjiza") -> tuple[float, float]:
    """Smallest admissible ``(G_I, G_II)`` [J/m^2] of an element of length ``length`` [m] with
    penalties ``p_n``, ``p_t`` [Pa] (stiffness ``p / L``): ``f_t^2 L / (2 p_n)`` and
    ``Zbar max|z'| c^2 L / p_t`` (module docstring; the check of ``CrackSet``)."""
    zs = softening_integral(softening) * softening_max_slope(softening)
    return f_t ** 2 * length / (2.0 * p_n), zs * c ** 2 * length / p_t


@dataclass(frozen=True)
class SizeScaledEnergies:
    """``G_I = g_i h`` and ``G_II = g_ii h`` [J/m^2] for element size ``h`` [m]: ``g_i``, ``g_ii`` [J/m^3]."""

    g_i: float
    g_ii: float

    @classmethod
    def rule(cls, f_t: float, c: float, p_n: float, p_t: float, longest: float = LONGEST_EDGE,
             peak_factor: float = PEAK_FACTOR, margin: float = MARGIN, softening: str = "munjiza"):
        """The energies per metre of element size of the module's rule."""
        for name, v in (("f_t", f_t), ("p_n", p_n), ("p_t", p_t), ("longest", longest), ("peak_factor", peak_factor),
                        ("margin", margin)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"size-scaled energies: {name} must be positive and finite, got {v!r}")
        if not (math.isfinite(c) and c >= 0):
            raise ValueError(f"size-scaled energies: c must be >= 0 and finite, got {c!r}")
        gi, gii = snap_back_limits(peak_factor * f_t, peak_factor * c, p_n, p_t, longest, softening)
        return cls(margin * gi, margin * gii)

    def at(self, h: float) -> tuple[float, float]:
        """``(G_I, G_II)`` [J/m^2] at element size ``h`` [m]."""
        if not (math.isfinite(h) and h > 0):
            raise ValueError(f"size-scaled energies: element size h must be positive and finite, got {h!r}")
        return self.g_i * h, self.g_ii * h


def size_scaled_properties(f_t: float, c: float, phi: float, p_n: float, h: float, p_t: float | None = None,
                           name: str = "", **kw) -> CrackProperties:
    """:class:`CrackProperties` with ``f_t``, ``c`` [Pa], ``phi`` [deg], penalties ``p_n``,
    ``p_t`` [Pa] (default ``p_n``) and the rule's fracture energies at element size ``h`` [m];
    ``kw`` go to :class:`CrackProperties` (``phi_res``, ``dilation_angle``, ...)."""
    p_t = p_n if p_t is None else p_t
    g_i, g_ii = SizeScaledEnergies.rule(f_t, c, p_n, p_t).at(h)
    return CrackProperties(f_t=f_t, c=c, phi=phi, G_I=g_i, G_II=g_ii, p_n=p_n, p_t=p_t, name=name, **kw)
