"""Crack-element property sets: strengths, fracture energies and penalties of one interface type.

:class:`CrackProperties` holds what the crack point law (:mod:`fdem.kernels.cracks`) needs for
intact rock bridges (tag 0) or a joint set (tag ``j``): ``f_t``, ``c``, ``phi``, ``G_I``,
``G_II``, the penalties, residual friction and the softening curve, and checks them against
snap-back before any run (the softening branch must be longer than the elastic one)."""
from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np
from fdem.kernels import cracks as K

__all__ = ["SOFTENING_KINDS", "softening_integral", "softening_max_slope", "ELASTIC_ONLY_LIMIT",
           "CrackProperties"]


SOFTENING_KINDS = {"munjiza": K.MUNJIZA, "linear": K.LINEAR}


def _softening_constants(kind: int) -> tuple[float, float]:
    """``(Zbar, max|z'|)`` of a softening shape: area ``int_0^1 z dD`` and steepest slope."""
    if kind == K.LINEAR:
        return 0.5, 1.0
    xg, wg = np.polynomial.legendre.leggauss(80)
    d = 0.5 * (xg + 1.0)
    zbar = 0.5 * float(sum(wi * K.softening(di, kind) for di, wi in zip(d, wg)))
    grid = np.linspace(0.0, 1.0, 100001)
    zz = np.array([K.softening(g, kind) for g in grid])
    slope = float(np.max(-np.diff(zz)) / (grid[1] - grid[0]))
    return zbar, slope


_ZCONST: dict[int, tuple[float, float]] = {}


def softening_integral(kind: str = "munjiza") -> float:
    """Area under the normalised softening curve, ``int_0^1 z(D) dD`` (0.38631 Munjiza, 0.5 linear)."""
    k = SOFTENING_KINDS[kind]
    if k not in _ZCONST:
        _ZCONST[k] = _softening_constants(k)
    return _ZCONST[k][0]


def softening_max_slope(kind: str = "munjiza") -> float:
    """Steepest descent ``max |dz/dD|`` of the softening curve (2.0402 Munjiza, 1 linear)."""
    k = SOFTENING_KINDS[kind]
    if k not in _ZCONST:
        _ZCONST[k] = _softening_constants(k)
    return _ZCONST[k][1]


ELASTIC_ONLY_LIMIT = 1e100
"""Peak opening [m] and cohesion [N/m] written into the constants while elements are held elastic."""


@dataclass(frozen=True)
class CrackProperties:
    """Parameters of one crack-element property set (intact rock bridges, or one DFN joint set).

    Attributes
    ----------
    f_t : tensile strength [Pa], > 0
    c : cohesion [Pa], >= 0
    phi : friction angle [deg], in [0, 90)
    G_I : mode-I fracture energy [J/m^2]: total work to separate a unit area in pure opening
    G_II : mode-II fracture energy [J/m^2]: work of the cohesive part ``c`` of the shear
        strength in pure sliding; the frictional part ``sigma_n tan(phi)`` is dissipated as
        friction (reported separately) and is not part of ``G_II``
    p_n, p_t : normal / tangential penalty in Munjiza's convention [Pa]: the stiffness per unit
        area of an element of reference length ``L0`` is ``k = p / L0`` [Pa/m]
    k_n, k_t : alternatively the stiffness per unit area directly [Pa/m]; give exactly one of
        ``p_n``/``k_n`` and at most one of ``p_t``/``k_t`` (default ``p_t = p_n`` or ``k_t = k_n``)
    phi_res : residual friction angle of the broken faces handed to contact [deg]
        (default ``phi``)
    softening : ``"munjiza"`` (Evans-Marathe shape, default) or ``"linear"``
    name : label used in error messages
    dilation_angle : joint dilation angle ``psi`` [deg], in ``[0, phi]`` (default 0: none).
        While an end slides plastically its faces separate normally by
        ``d = tan(psi) min(kappa, u_lim)`` (``kappa`` the accumulated plastic slip): the law
        sees the effective opening ``o - d``, so under normal confinement sliding raises the
        compression (and the friction), and free faces open. ``psi <= phi`` keeps the
        dissipation ``c z + sigma_n (tan(phi) - tan(psi))`` per unit slip non-negative once the
        cohesion is gone. See ``docs/cohesive.md`` (Joint dilation).
    dilation_limit : plastic slip ``u_lim`` [m] beyond which the joint stops dilating (asperities
        sheared off; the largest dilatant opening is ``tan(psi) u_lim``); finite, >= 0, and > 0
        when ``dilation_angle > 0``
    """

    f_t: float
    c: float
    phi: float
    G_I: float
    G_II: float
    p_n: float | None = None
    p_t: float | None = None
    k_n: float | None = None
    k_t: float | None = None
    phi_res: float | None = None
    softening: str = "munjiza"
    name: str = ""
    dilation_angle: float = 0.0
    dilation_limit: float = 0.0

    def __post_init__(self) -> None:
        who = f"crack property set {self.name!r}" if self.name else "crack property set"
        for attr in ("f_t", "c", "phi", "G_I", "G_II"):
            v = getattr(self, attr)
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ValueError(f"{who}: {attr} must be a finite number, got {v!r}")
            if v < 0:
                raise ValueError(f"{who}: {attr} must not be negative, got {v}")
        if self.f_t <= 0:
            raise ValueError(f"{who}: tensile strength f_t must be positive, got {self.f_t} Pa")
        if self.G_I <= 0:
            raise ValueError(f"{who}: mode-I fracture energy G_I must be positive, got {self.G_I} J/m^2")
        if self.c > 0 and self.G_II <= 0:
            raise ValueError(f"{who}: mode-II fracture energy G_II must be positive when c > 0, got {self.G_II} J/m^2")
        if not 0.0 <= self.phi < 90.0:
            raise ValueError(f"{who}: friction angle phi must be in [0, 90) deg, got {self.phi}")
        if self.phi_res is not None and not 0.0 <= self.phi_res < 90.0:
            raise ValueError(f"{who}: residual friction angle phi_res must be in [0, 90) deg, got {self.phi_res}")
        if (self.p_n is None) == (self.k_n is None):
            raise ValueError(f"{who}: give exactly one of p_n [Pa] or k_n [Pa/m] for the normal penalty")
        if self.p_t is not None and self.k_t is not None:
            raise ValueError(f"{who}: give at most one of p_t [Pa] or k_t [Pa/m] for the tangential penalty")
        for attr in ("p_n", "p_t", "k_n", "k_t"):
            v = getattr(self, attr)
            if v is not None and (not math.isfinite(v) or v <= 0):
                raise ValueError(f"{who}: penalty {attr} must be positive and finite, got {v}")
        if self.softening not in SOFTENING_KINDS:
            raise ValueError(f"{who}: softening must be one of {sorted(SOFTENING_KINDS)}, got {self.softening!r}")
        for attr in ("dilation_angle", "dilation_limit"):
            v = getattr(self, attr)
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ValueError(f"{who}: {attr} must be a finite number, got {v!r}")
        if not 0.0 <= self.dilation_angle < 90.0:
            raise ValueError(f"{who}: dilation_angle psi must be in [0, 90) deg, got {self.dilation_angle}")
        if self.dilation_angle > self.phi:
            raise ValueError(
                f"{who}: dilation_angle psi = {self.dilation_angle} deg exceeds the friction angle phi = {self.phi} deg: "
                f"a sliding joint would then dissipate c z + sigma_n (tan(phi) - tan(psi)) < 0 per unit slip once "
                f"the cohesion is gone (energy created); include the asperity angle in phi (Patton: phi = phi_b + i)")
        if self.dilation_limit < 0.0:
            raise ValueError(f"{who}: dilation_limit u_lim must not be negative, got {self.dilation_limit} m")
        if self.dilation_angle > 0.0 and self.dilation_limit <= 0.0:
            raise ValueError(
                f"{who}: dilation_angle = {self.dilation_angle} deg needs a dilation_limit u_lim > 0 [m], the plastic "
                f"slip beyond which the joint stops dilating (with u_lim = 0 it would never dilate)")

    def stiffness(self, length0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normal and tangential stiffness per unit area ``(k_n, k_t)`` [Pa/m] of elements of
        reference length ``length0`` [m]."""
        L = np.asarray(length0, dtype=np.float64)
        kn = np.full_like(L, self.k_n) if self.k_n is not None else self.p_n / L
        if self.k_t is not None:
            kt = np.full_like(L, self.k_t)
        elif self.p_t is not None:
            kt = self.p_t / L
        elif self.k_n is not None:
            kt = np.full_like(L, self.k_n)
        else:
            kt = self.p_n / L
        return kn, kt

    @property
    def tan_phi(self) -> float:
        return math.tan(math.radians(self.phi))

    @property
    def tan_psi(self) -> float:
        """Dilation coefficient ``tan(psi)`` [-]."""
        return math.tan(math.radians(self.dilation_angle))

    @property
    def tan_phi_res(self) -> float:
        return math.tan(math.radians(self.phi if self.phi_res is None else self.phi_res))
