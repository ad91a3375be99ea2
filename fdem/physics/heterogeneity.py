"""Spatially random strengths of the crack elements (:class:`Heterogeneity`): a seeded
Weibull or normal field of multipliers on ``f_t`` and ``c``, one per element."""
from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np

__all__ = ["Heterogeneity"]


@dataclass(frozen=True)
class Heterogeneity:
    """Per-element strength multipliers (applied to ``f_t`` and ``c``), mean 1.

    distribution : ``"none"``, ``"normal"`` (``1 + cov N(0,1)``) or ``"weibull"`` (shape
        ``weibull_modulus``, scaled to mean 1)
    cov : coefficient of variation of the normal distribution (e.g. 0.1 for the Muliashi bonds)
    weibull_modulus : Weibull shape ``m`` (> 0)
    seed : seed of ``numpy.random.default_rng``
    tags : joint-set tags it applies to (``None``: all)
    min_factor : draws below this multiplier are clipped to it (strength stays positive)
    """

    distribution: str = "none"
    cov: float = 0.1
    weibull_modulus: float = 10.0
    seed: int | None = 0
    tags: tuple[int, ...] | None = None
    min_factor: float = 0.05

    def __post_init__(self) -> None:
        if self.distribution not in ("none", "normal", "weibull"):
            raise ValueError(f"heterogeneity distribution must be 'none', 'normal' or 'weibull', got {self.distribution!r}")
        if not (math.isfinite(self.cov) and self.cov >= 0):
            raise ValueError(f"heterogeneity cov must be finite and >= 0, got {self.cov}")
        if not (math.isfinite(self.weibull_modulus) and self.weibull_modulus > 0):
            raise ValueError(f"heterogeneity weibull_modulus must be positive and finite, got {self.weibull_modulus}")
        if not (math.isfinite(self.min_factor) and 0 < self.min_factor <= 1):
            raise ValueError(f"heterogeneity min_factor must be in (0, 1], got {self.min_factor}")
        if self.seed is not None and not isinstance(self.seed, (int, np.integer)):
            raise ValueError(f"heterogeneity seed must be an integer or None, got {self.seed!r}")

    def draw(self, tag: np.ndarray) -> np.ndarray:
        """(n,) multipliers for elements with joint-set tags ``tag``."""
        n = tag.shape[0]
        out = np.ones(n)
        if self.distribution == "none":
            return out
        rng = np.random.default_rng(self.seed)
        if self.distribution == "normal":
            draw = 1.0 + self.cov * rng.standard_normal(n)
        else:
            m = self.weibull_modulus
            draw = rng.weibull(m, n) / math.gamma(1.0 + 1.0 / m)
        sel = np.ones(n, bool) if self.tags is None else np.isin(tag, np.asarray(self.tags))
        out[sel] = np.maximum(draw[sel], self.min_factor)
        return out
