"""Quasi-static damping of a stage (:class:`Damping`): mass-proportional and Cundall's local damping."""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Damping", "NO_DAMPING"]


@dataclass(frozen=True)
class Damping:
    """Quasi-static damping of a stage; both zero (the default) for dynamic phases.

    Attributes
    ----------
    mass_proportional : float
        ``alpha`` [1/s] of the force ``-alpha m v``. Critical for a mode of angular frequency
        ``omega`` at ``alpha = 2 omega``.
    local : float
        ``beta`` [-] of Cundall's local non-viscous damping ``-beta |f| sign(v)``
        (Cundall 1987; 0.8 is the usual quasi-static value), 0 <= beta < 1.
    """

    mass_proportional: float = 0.0
    local: float = 0.0

    def __post_init__(self):
        if not (math.isfinite(self.mass_proportional) and self.mass_proportional >= 0):
            raise ValueError(f"mass-proportional damping must be finite and >= 0, got {self.mass_proportional}")
        if not (math.isfinite(self.local) and 0.0 <= self.local < 1.0):
            raise ValueError(f"local damping must lie in [0, 1), got {self.local}")

    @classmethod
    def quasi_static(cls, local: float = 0.8) -> "Damping":
        return cls(local=local)

    @classmethod
    def critical(cls, omega: float) -> "Damping":
        """Mass-proportional damping critical for a mode of angular frequency ``omega`` [rad/s]:
        ``alpha = 2 omega``. That mode then settles as fast as any viscous damping can settle it
        (its displacement decays as ``(1 + omega t) exp(-omega t)``), and every higher mode decays at
        the same rate ``alpha / 2 = omega`` (Chopra 2017, *Dynamics of Structures*, sec. 2.2 and 11.4)."""
        if not (math.isfinite(omega) and omega > 0):
            raise ValueError(f"critical damping needs a positive finite angular frequency, got {omega!r}")
        return cls(mass_proportional=2.0 * omega)


NO_DAMPING = Damping()
