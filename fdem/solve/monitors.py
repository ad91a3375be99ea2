"""Point monitors (:class:`PointMonitor`): a material point's displacement, velocity and stress
in every history row (``history.csv`` columns ``<name>_ux`` ... ``<name>_sxy``), added with
:meth:`fdem.solve.simulation.Simulation.add_point_monitor` (a scene's ``[[monitors]]``)."""
from __future__ import annotations

import math

import numpy as np

from fdem.kernels.triangles import triangle_stress_state

__all__ = ["MONITOR_QUANTITIES", "PointMonitor"]


MONITOR_QUANTITIES = ("ux", "uy", "vx", "vy", "sxx", "syy", "sxy")
"""What a point monitor records, in this order: displacement [m], velocity [m/s], Cauchy stress [Pa]."""


class PointMonitor:
    """A material point watched through the triangle that contains it in the reference
    configuration: ``triangle`` (id) and ``weights`` (3,), the point's barycentric coordinates
    ``lambda_k`` in it, so that any nodal field ``u`` reads ``u(p) = sum_k lambda_k u_k``
    (exact for the linear displacement of a constant-strain triangle)."""

    def __init__(self, name: str, x: float, y: float, triangle: int, weights: np.ndarray):
        self.name, self.x, self.y = name, float(x), float(y)
        self.triangle = int(triangle)
        self.weights = np.asarray(weights, dtype=np.float64)
        self.columns = tuple(f"{name}_{q}" for q in MONITOR_QUANTITIES)
        self._key = None
        self._values = None

    @classmethod
    def locate(cls, name: str, x: float, y: float, x0: np.ndarray, triangles: np.ndarray) -> "PointMonitor":
        """The monitor of the point ``(x, y)`` [m]: the triangle whose smallest barycentric
        coordinate of the point is the largest (inside: all >= 0; on a shared edge either side
        gives the same displacement). Outside every triangle (by more than 1e-9 of a triangle's
        size, round-off on the boundary) is a ``ValueError`` naming the point."""
        if not (math.isfinite(float(x)) and math.isfinite(float(y))):
            raise ValueError(f"point monitor {name!r}: the point ({x}, {y}) is not finite")
        p = x0[triangles]  # (n, 3, 2)
        a, b, c = p[:, 0], p[:, 1], p[:, 2]
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        l1 = ((x - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (y - a[:, 1])) / det
        l2 = ((b[:, 0] - a[:, 0]) * (y - a[:, 1]) - (x - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
        lam = np.column_stack([1.0 - l1 - l2, l1, l2])
        worst = lam.min(axis=1)
        t = int(np.argmax(worst))
        if worst[t] < -1e-9:
            lo, hi = x0.min(axis=0), x0.max(axis=0)
            raise ValueError(
                f"point monitor {name!r}: the point ({float(x):.6g}, {float(y):.6g}) m lies outside the mesh "
                f"(reference configuration; the mesh spans x {lo[0]:.6g} to {hi[0]:.6g} m, y {lo[1]:.6g} to "
                f"{hi[1]:.6g} m, and no triangle contains the point)")
        return cls(name, x, y, t, np.clip(lam[t], 0.0, 1.0) / np.clip(lam[t], 0.0, 1.0).sum())

    def values(self, sim) -> tuple[float, ...]:
        """``(ux, uy, vx, vy, sxx, syy, sxy)`` of the point in the current state of ``sim`` (a
        :class:`fdem.solve.simulation.Simulation`, not imported here: it imports this module), computed once
        per history row (the columns of one row share it)."""
        st = sim.state
        key = (st.step, st.time)
        if key != self._key:
            nodes = sim.triangles[self.triangle]
            u = self.weights @ (st.x[nodes] - sim.x0[nodes])
            v = self.weights @ st.v[nodes]
            s = np.empty((1, 6))
            t = self.triangle
            triangle_stress_state(st.x, st.v, sim.triangles[t:t + 1], sim.tc[t:t + 1], s)
            self._values = (float(u[0]), float(u[1]), float(v[0]), float(v[1]),
                            float(s[0, 0]), float(s[0, 1]), float(s[0, 2]))
            self._key = key
        return self._values

    def state_dict(self) -> dict:
        return {"name": self.name, "x": self.x, "y": self.y}
