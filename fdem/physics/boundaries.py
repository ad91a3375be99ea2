"""Quiet (viscous, absorbing) boundaries: Lysmer-Kuhlemeyer dashpots as a force provider.

Theory
------
A plane wave meeting a truncated boundary at normal incidence leaves the model without
reflection if the boundary carries the tractions the missing half-space would (Lysmer and
Kuhlemeyer 1969):

    t_n = -rho c_p v_n,        t_s = -rho c_s v_s                                  [Pa]

with ``v_n = v . n`` and ``v_s = v . s`` the normal and tangential velocities of the boundary,
``n`` its outward normal, ``s`` its tangent, and the wave speeds of the 2D model
``c_p = sqrt((lambda + 2 mu) / rho)``, ``c_s = sqrt(mu / rho)`` (``lambda``, ``mu`` the 2D Lame
constants of :meth:`fdem.solve.model.Model.lame_arrays`: plane strain, or the plane-stress
``lambda``). The tractions are lumped to the nodes: each external edge of length ``L`` gives
each of its two (exploded) nodes the dashpot matrix

    C_e = (L / 2) rho (c_p n n^T + c_s s s^T)                                       [N s/m^2]

summed over the selected edges a node lies on (a corner node gets one per edge), and the
nodal force is ``f = -C v`` [N/m]. Normals and lengths are those of the reference mesh
(small rotations of the boundary). Absorption is perfect for plane P and S waves at normal
incidence in the continuum and good (a few per cent reflected) for oblique incidence beyond
about 30 degrees from grazing; the discrete mesh adds a small reflection of its own.

Input through a quiet base
--------------------------
For a compliant base under an upward incident wave of particle velocity ``v_in(t)``, the
standard input is the traction ``2 rho c v_in(t)`` applied together with the dashpot (the
factor 2: the dashpot takes half of it back for the free-field motion); ``input_velocity``
applies ``f = C (2 v_in(t) - v)``.

Time integration and energy
---------------------------
The solver hands the provider ``v`` at ``t_{n-1/2}`` (leapfrog), so the dashpot force at step
``n`` is ``f_n = -C v_{n-1/2}`` (lagged half a step). Its work is booked with the solver's
half-step convention, ``W_n = (dt/2) f_n . (v_{n-1/2} + v_{n+1/2})``: the early half when the
force is computed, the late half at the next call, when ``v_{n+1/2}`` is known. The energy
the dashpots absorbed (``quiet_boundary`` in the ledger) is ``-sum W`` (minus the work of the
input traction ``2 C v_in``, which is work done *on* the model, booked as negative absorption).

Stability: a node of mass ``m`` with a spring of frequency ``omega`` and a lagged dashpot
``c`` (``v_{n+1/2} = v_{n-1/2} + dt/m (-k x_n - c v_{n-1/2})``) is stable when

    (omega dt)^2 + 2 c dt / m < 4

(Jury's test on ``z^2 - (2 - omega^2 dt^2 - c dt/m) z + 1 - c dt/m``); the dashpot alone needs
``dt < 2 m / c``. The solver combines the providers' steps as ``1/dt^2 = sum 1/dt_i^2``, which
does not bound the mixed condition, so :meth:`QuietBoundary.stable_dt` reports ``sqrt(2) m / c``
(``2 m / c`` over ``sqrt 2``): then every combined step times a time-step fraction up to 0.93
satisfies the condition above for any ``omega`` the other limits allow (``s^2 + 1/8 < 1``).
"""
from __future__ import annotations

import math
from typing import Callable, Sequence
import numpy as np

__all__ = ["external_edges", "QuietBoundary"]


def external_edges(topology) -> np.ndarray:
    """(n_edge, 2) node ids of each external edge, counter-clockwise in its triangle.

    An exploded topology lists them (``boundary_edges``); for a conforming mesh they are the
    triangle edges used once."""
    edges = getattr(topology, "boundary_edges", None)
    if edges is not None:
        return np.asarray(edges, np.int64)
    tri = np.asarray(topology.triangles, np.int64)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return e[count[inv.ravel()] == 1]


def _edge_triangle(topology, edges: np.ndarray) -> np.ndarray:
    bt = getattr(topology, "boundary_triangle", None)
    if bt is not None and getattr(topology, "boundary_edges", None) is not None and len(bt) == len(edges):
        return np.asarray(bt, np.int64)
    tri = np.asarray(topology.triangles, np.int64)
    lookup = {}
    for t, (a, b, c) in enumerate(tri):
        for p, q in ((a, b), (b, c), (c, a)):
            lookup[(p, q)] = t
    return np.array([lookup[(int(p), int(q))] for p, q in edges], np.int64)


class QuietBoundary:
    """Lysmer-Kuhlemeyer dashpots on selected external edges; a force provider (module docstring).

    Parameters
    ----------
    model : fdem.solve.model.Model
        Supplies the topology, the triangles' density and 2D Lame constants.
    where : str, sequence of str, or callable
        Physical group name(s) (``"left"``, ``"right"``, ``"bottom"``: an edge is selected when
        both its nodes lie in the group), or a predicate ``f(xm, ym) -> bool array`` on the
        reference midpoints of the external edges.
    normal_factor, shear_factor : float
        Multipliers of ``rho c_p`` and ``rho c_s`` (1: Lysmer-Kuhlemeyer).
    input_velocity : callable, optional
        ``t -> (v_x, v_y)`` [m/s], the incident free-field particle velocity for a compliant base;
        the boundary then applies ``C (2 v_in - v)``. The provider needs the time: it keeps its
        own clock from the ``dt`` of each call (start at ``time0``).

    Attributes
    ----------
    nodes : (k,) int64        nodes carrying a dashpot
    damping : (k, 2, 2)       their dashpot matrices ``C`` [N s/m^2]
    absorbed : float          energy absorbed so far [J/m] (the ``quiet_boundary`` ledger term)
    """

    def __init__(self, model, where="boundary", normal_factor: float = 1.0, shear_factor: float = 1.0,
                 input_velocity: Callable[[float], Sequence[float]] | None = None, time0: float = 0.0):
        topo = model.topology
        edges = external_edges(topo)
        x0 = np.asarray(topo.x0, float)
        mid = 0.5 * (x0[edges[:, 0]] + x0[edges[:, 1]])
        keep = self._select(model, topo, edges, mid, where)
        if not keep.any():
            raise ValueError(f"QuietBoundary: selection {where!r} matches no external edge")
        for label, val in (("normal_factor", normal_factor), ("shear_factor", shear_factor)):
            if not (math.isfinite(val) and val >= 0):
                raise ValueError(f"QuietBoundary: {label} must be finite and >= 0, got {val}")
        edges = edges[keep]
        tris = _edge_triangle(topo, edges)
        lam, mu = model.lame_arrays()
        rho = model.property_array("density")
        z_p = normal_factor * np.sqrt(rho[tris] * (lam[tris] + 2 * mu[tris]))  # rho c_p [Pa s/m]
        z_s = shear_factor * np.sqrt(rho[tris] * mu[tris])                     # rho c_s
        d = x0[edges[:, 1]] - x0[edges[:, 0]]
        length = np.hypot(d[:, 0], d[:, 1])
        s = d / length[:, None]
        n = np.column_stack([s[:, 1], -s[:, 0]])  # outward for a counter-clockwise triangle edge
        c_edge = 0.5 * length[:, None, None] * (z_p[:, None, None] * n[:, :, None] * n[:, None, :]
                                                + z_s[:, None, None] * s[:, :, None] * s[:, None, :])
        all_nodes = edges.ravel()
        self.nodes, inv = np.unique(all_nodes, return_inverse=True)
        self.damping = np.zeros((len(self.nodes), 2, 2))
        np.add.at(self.damping, inv, np.repeat(c_edge, 2, axis=0))
        self.edges = edges
        self.edge_length = length
        self.edge_normal = n
        self.n_nodes_model = model.n_nodes
        self.input_velocity = input_velocity
        self.time = float(time0)
        self.absorbed = 0.0
        self._f_last: np.ndarray | None = None   # f_n of the last call, for its late half
        self._dt_last = 0.0

    @staticmethod
    def _select(model, topo, edges, mid, where) -> np.ndarray:
        if callable(where):
            keep = np.asarray(where(mid[:, 0], mid[:, 1]), dtype=bool)
            if keep.shape != (len(edges),):
                raise ValueError(f"QuietBoundary: predicate must return one boolean per external edge "
                                 f"({len(edges)}), got shape {keep.shape}")
            return keep
        names = [where] if isinstance(where, str) else list(where)
        if names == ["boundary"]:
            return np.ones(len(edges), bool)
        keep = np.zeros(len(edges), bool)
        for name in names:
            try:
                nodes = topo.nodes_in_group(name)
            except KeyError as err:
                raise ValueError(f"QuietBoundary: {err.args[0]}") from None
            inside = np.zeros(topo.n_nodes, bool)
            inside[nodes] = True
            keep |= inside[edges[:, 0]] & inside[edges[:, 1]]
        return keep

    # ------------------------------------------------------------------ provider interface
    def add_forces(self, x: np.ndarray, v: np.ndarray, f: np.ndarray, dt: float, step: int) -> None:
        """Add ``-C v_{n-1/2}`` (plus ``2 C v_in`` with an input) to ``f``; book the work halves."""
        vn = v[self.nodes]
        if self._f_last is not None:  # late half of the previous step: v is now v_{n-1/2} = its v_{n+1/2}
            self.absorbed -= 0.5 * self._dt_last * float((self._f_last * vn).sum())
        fn = -np.einsum("kij,kj->ki", self.damping, vn)
        if self.input_velocity is not None:
            vin = np.asarray(self.input_velocity(self.time + 0.5 * dt), float).reshape(2)
            fn += 2.0 * self.damping @ vin
        np.add.at(f, self.nodes, fn)
        self.absorbed -= 0.5 * dt * float((fn * vn).sum())
        self._f_last = fn
        self._dt_last = dt
        self.time += dt

    def energy_terms(self) -> dict[str, float]:
        """``{"quiet_boundary": absorbed}`` [J/m]: energy taken out by the dashpots (net of input work),
        booked to the early half of the current step like the solver's cumulative terms."""
        return {"quiet_boundary": self.absorbed}

    def stable_dt(self, mass: np.ndarray) -> float:
        """``min sqrt(2) m / c_max`` over the dashpot nodes [s], ``c_max`` the largest eigenvalue of the
        node's ``C`` (module docstring: keeps the mixed spring-dashpot condition under the solver's
        combination rule)."""
        mass = np.asarray(mass, float)
        c_max = np.linalg.eigvalsh(self.damping)[:, -1]
        ok = c_max > 0
        if not ok.any():
            return math.inf
        return float(np.min(math.sqrt(2.0) * mass[self.nodes[ok]] / c_max[ok]))

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self) -> dict:
        return {"kind": type(self).__name__, "absorbed": float(self.absorbed), "time": float(self.time),
                "dt_last": float(self._dt_last), "f_last": None if self._f_last is None else self._f_last.copy()}

    def load_state_dict(self, d: dict, x=None) -> None:
        self.absorbed = float(d["absorbed"])
        self.time = float(d["time"])
        self._dt_last = float(d["dt_last"])
        self._f_last = None if d["f_last"] is None else np.array(d["f_last"], float)
