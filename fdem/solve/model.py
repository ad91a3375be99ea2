"""The model: topology + materials + supports + loads + initial state, assembled into arrays.

A :class:`Model` is built once, before any time step, and checked there: every selection
that matches no node, every unknown group name or bad parameter raises a ``ValueError`` that
names it. The solver only reads the arrays it produces (:meth:`Model.triangle_constants`,
:meth:`Model.node_mass`, :attr:`Model.flags`, ...).

Selections (``where``) are a physical-group name (``"bottom"``), a vectorised predicate on
the reference coordinates ``lambda x, y: x < 1.0``, or an array of node ids.

Two node layouts are supported:

* **exploded** (the FDEM layout, :func:`fdem.mesh.topology.build_topology`): node ``3t + k`` is
  corner ``k`` of triangle ``t``; triangles are tied only by crack elements (providers). The
  solver uses the fused one-pass kernel.
* **conforming** (:class:`ConformingTopology`): triangles share mesh nodes, a plain finite
  element continuum without crack elements, used for verification of the continuum and for
  elastic pre-phases. The solver uses a two-pass (triangle, then node) kernel.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable, Sequence
import numpy as np
from fdem.physics.elastic import ElasticMaterial, PLANE_STRAIN, k0_elastic
from fdem.physics.stability import critical_viscosity, triangle_critical_dt
from fdem.mesh.mesh import Mesh
from fdem.kernels.triangles import triangle_constants
from fdem.mesh.topology import ConformingTopology

__all__ = ["FIX_X", "FIX_Y", "DEFAULT_ELEMENT_DAMPING", "geostatic_stress", "Model"]




FIX_X = 1
"""Bit of :attr:`Model.flags`: the x velocity of the node is prescribed."""


FIX_Y = 2
"""Bit of :attr:`Model.flags`: the y velocity of the node is prescribed."""


DEFAULT_ELEMENT_DAMPING = 0.1
"""Default fraction of critical damping of each triangle's highest mode that
:meth:`Model.set_element_damping` applies. Chosen in ``docs/damping.md``: with it the block
on an incline slides within 0.2 % of the rigid-block answer at three mesh sizes (undamped:
1.5 % on the finest), twice the smallest fraction that did so, for a 10 % shorter triangle
step (0.1 % on the combined step when contact and crack penalties set it)."""


def _finite(values, what: str) -> np.ndarray:
    """``values`` as a float array; a ``ValueError`` naming ``what`` and the value if any entry is not finite."""
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be numbers, got {values!r}") from None
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be finite, got {values!r}")
    return arr


def geostatic_stress(density: float, gravity: float = 9.81, surface: float | Callable = 0.0,
                     k0: float | None = None, poisson: float | None = None):
    """Initial-stress function ``(x, y) -> (n, 3) [s_xx, s_yy, s_xy]`` of a gravity-loaded ground [Pa].

    ``sigma_yy = -rho g (y_s - y)``, ``sigma_xx = K0 sigma_yy``, ``sigma_xy = 0`` below the ground
    surface ``y_s`` (a number or a function ``y_s(x)``); zero above it. ``K0`` defaults to the
    laterally confined elastic value ``nu / (1 - nu)`` when ``poisson`` is given.
    Compression is negative.
    """
    if k0 is None:
        if poisson is None:
            raise ValueError("geostatic_stress needs k0 or poisson")
        k0 = k0_elastic(poisson)

    def stress(x, y):
        ys = surface(x) if callable(surface) else surface
        depth = np.maximum(np.asarray(ys) - y, 0.0)
        syy = -density * gravity * depth
        return np.column_stack([k0 * syy, syy, np.zeros_like(syy)])

    return stress


@dataclass
class _VelocityCondition:
    nodes: np.ndarray
    component: int
    value: float
    history: Callable[[float], float]


class Model:
    """Topology, materials, supports, loads and initial state of a 2D FDEM model.

    Parameters
    ----------
    topology : Topology or ConformingTopology
        Exploded mesh (:func:`fdem.mesh.topology.build_topology`) or conforming mesh.
    materials : ElasticMaterial or sequence of them
        Property sets; triangle ``t`` uses ``materials[triangle_property[t]]``.
    triangle_property : (n_tri,) int array, optional
        Property-set id of each triangle; default: 0 for one material, else the body id.

    All 2D quantities are per unit thickness. Gravity defaults to zero; call
    :meth:`set_gravity`.
    """

    def __init__(self, topology, materials: ElasticMaterial | Sequence[ElasticMaterial],
                 triangle_property: np.ndarray | None = None):
        self.topology = topology
        self.materials = (materials,) if isinstance(materials, ElasticMaterial) else tuple(materials)
        if not self.materials:
            raise ValueError("a model needs at least one material")
        planes = {m.plane for m in self.materials}
        if len(planes) > 1:
            raise ValueError(f"all materials must use the same plane condition, got {sorted(planes)}")
        n_tri = topology.n_triangles
        if triangle_property is None:
            triangle_property = (np.zeros(n_tri, np.int32) if len(self.materials) == 1
                                 else np.asarray(topology.triangle_body, np.int32))
        self.triangle_property = np.asarray(triangle_property, np.int32).copy()
        if self.triangle_property.shape != (n_tri,):
            raise ValueError(f"triangle_property must have shape ({n_tri},), got {self.triangle_property.shape}")
        bad = (self.triangle_property < 0) | (self.triangle_property >= len(self.materials))
        if bad.any():
            t = int(np.flatnonzero(bad)[0])
            raise ValueError(f"triangle {t} has property id {self.triangle_property[t]}, "
                             f"but only {len(self.materials)} material(s) are defined")
        self.gravity = np.zeros(2)
        self.flags = np.zeros(topology.n_nodes, np.uint8)
        self.v_prescribed = np.zeros((topology.n_nodes, 2))
        self.external_force = np.zeros((topology.n_nodes, 2))
        self.initial_stress = np.zeros((n_tri, 3))
        self.initial_velocity = np.zeros((topology.n_nodes, 2))
        self._velocity_conditions: list[_VelocityCondition] = []
        self.viscosity = self.property_array("viscosity").copy()
        """(n_tri,) viscosity ``eta`` [Pa s] of each triangle: the material's, or what
        :meth:`set_element_damping` derived from the mesh."""

    @classmethod
    def from_mesh(cls, mesh: Mesh, materials, exploded: bool = True, triangle_property=None) -> "Model":
        """Model on an exploded (FDEM, default) or conforming (continuum) version of ``mesh``."""
        if exploded:
            from fdem.mesh.topology import build_topology

            topology = build_topology(mesh)
        else:
            topology = ConformingTopology.from_mesh(mesh)
        return cls(topology, materials, triangle_property)

    # ------------------------------------------------------------------ layout
    @property
    def n_nodes(self) -> int:
        return self.topology.n_nodes

    @property
    def n_triangles(self) -> int:
        return self.topology.n_triangles

    @cached_property
    def is_exploded(self) -> bool:
        """True when node ``3t + k`` is corner ``k`` of triangle ``t`` (one triangle per node)."""
        tris = self.topology.triangles
        return bool(np.array_equal(tris.ravel(), np.arange(3 * len(tris))))

    @property
    def plane(self) -> str:
        return self.materials[0].plane

    def property_array(self, name: str) -> np.ndarray:
        """(n_tri,) per-triangle value of a material attribute or property (e.g. ``"density"``, ``"poisson"``)."""
        table = np.array([getattr(m, name) for m in self.materials], dtype=float)
        return table[self.triangle_property]

    def viscosity_array(self) -> np.ndarray:
        """(n_tri,) viscosity ``eta`` [Pa s] of the viscous stress ``S_v = eta dE/dt`` of each triangle."""
        return self.viscosity

    def critical_viscosity(self) -> np.ndarray:
        """(n_tri,) viscosity [Pa s] that critically damps each triangle's highest mode,
        see :func:`fdem.physics.stability.critical_viscosity` (about ``(4/3) h sqrt(rho (lambda + mu))``,
        ``h`` the smallest altitude)."""
        lam, mu = self.lame_arrays()
        return critical_viscosity(self.topology.x0, self.topology.triangles, lam, mu, self.property_array("density"))

    def set_element_damping(self, fraction: float = DEFAULT_ELEMENT_DAMPING, where=None) -> np.ndarray:
        """Element viscosity: ``eta_t = fraction * eta_crit,t`` on the triangles selected by ``where``.

        ``eta_crit,t`` [Pa s] critically damps triangle ``t``'s highest (element-scale) mode
        (:meth:`critical_viscosity`); for an equilateral triangle of altitude ``h``,
        ``eta_crit = (4/3) h sqrt(rho (lambda + mu))`` (``1.19 h sqrt(E rho)`` at ``nu = 0.25``,
        plane strain; Munjiza 2004, sec. 4.2, uses ``2 h sqrt(E rho)``). It damps the ringing
        of the constant-strain triangles in dynamic stages and leaves rigid motion alone. The
        default fraction is :data:`DEFAULT_ELEMENT_DAMPING` (``docs/damping.md``); 0 switches
        element damping off (the selected triangles get viscosity 0). Replaces the material
        viscosity of the selected triangles. ``where`` selects by reference centroid
        ``where(xc, yc)``; default all. Returns the (n_selected,) viscosities set [Pa s].
        The stable step shortens by about ``sqrt(1 + xi^2) - xi`` with ``xi`` about ``fraction``.
        """
        fraction = float(_finite(fraction, "set_element_damping: fraction"))
        if fraction < 0:
            raise ValueError(f"set_element_damping: fraction must be >= 0, got {fraction}")
        tris = self.select_triangles(where)
        eta = fraction * self.critical_viscosity()[tris]
        self.viscosity[tris] = eta
        return eta

    def element_damping_fraction(self) -> np.ndarray:
        """(n_tri,) each triangle's viscosity as a fraction of its critical value :meth:`critical_viscosity`."""
        return self.viscosity / self.critical_viscosity()

    def lame_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(n_tri,) 2D Lame constants ``lambda``, ``mu`` [Pa]."""
        table = np.array([m.lame for m in self.materials])
        return table[self.triangle_property, 0], table[self.triangle_property, 1]

    # ------------------------------------------------------------------ selections
    def select_nodes(self, where, what: str = "selection") -> np.ndarray:
        """Node ids of a group name, a predicate ``f(x, y) -> bool array`` or an id array; never empty."""
        if isinstance(where, str):
            try:
                nodes = self.topology.nodes_in_group(where)
            except KeyError as err:
                raise ValueError(f"{what}: {err.args[0]}") from None
        elif callable(where):
            nodes = self.topology.nodes_where(where)
        else:
            nodes = np.asarray(where, dtype=np.int64).ravel()
            if nodes.size and (nodes.min() < 0 or nodes.max() >= self.n_nodes):
                raise ValueError(f"{what}: node ids must lie in [0, {self.n_nodes}), got {nodes.min()}..{nodes.max()}")
        if nodes.size == 0:
            raise ValueError(f"{what}: selection {where!r} matches no node")
        return nodes

    def select_triangles(self, where) -> np.ndarray:
        """Triangle ids whose reference centroid satisfies ``where(xc, yc)``; ``None`` selects all."""
        if where is None:
            return np.arange(self.n_triangles)
        c = self.centroids0
        ids = np.flatnonzero(np.asarray(where(c[:, 0], c[:, 1]), dtype=bool))
        if ids.size == 0:
            raise ValueError(f"triangle selection {where!r} matches no triangle")
        return ids

    @cached_property
    def centroids0(self) -> np.ndarray:
        """(n_tri, 2) reference centroids [m]."""
        return self.topology.x0[self.topology.triangles].mean(axis=1)

    # ------------------------------------------------------------------ supports
    def fix(self, where, x: bool = True, y: bool = True) -> np.ndarray:
        """Fix the selected nodes in x and/or y (zero velocity). A roller on a vertical side is ``fix(side, y=False)``."""
        if not (x or y):
            raise ValueError("fix: choose at least one of x, y")
        return self.prescribe_velocity(where, vx=0.0 if x else None, vy=0.0 if y else None, _what="fix")

    def roller(self, where, normal: str) -> np.ndarray:
        """Roller support: zero velocity along ``normal`` (``"x"`` or ``"y"``), free along the other axis."""
        if normal not in ("x", "y"):
            raise ValueError(f"roller normal must be 'x' or 'y', got {normal!r}")
        return self.fix(where, x=normal == "x", y=normal == "y")

    def prescribe_velocity(self, where, vx: float | None = None, vy: float | None = None,
                           history: Callable[[float], float] | None = None, _what: str = "prescribe_velocity"):
        """Prescribe the velocity [m/s] of the selected nodes in x and/or y (``None`` leaves it free).

        ``history(t)`` multiplies the values at time ``t`` (default constant). A later call
        overrides an earlier one on the same node and direction. Returns the node ids.
        """
        if vx is None and vy is None:
            raise ValueError(f"{_what}: give vx and/or vy")
        for label, value in (("vx", vx), ("vy", vy)):
            if value is not None:
                _finite(value, f"{_what}: {label} (selection {where!r})")
        if history is not None and not callable(history):
            raise ValueError(f"{_what}: history must be a function of time, got {history!r}")
        nodes = self.select_nodes(where, _what)
        for comp, value, bit in ((0, vx, FIX_X), (1, vy, FIX_Y)):
            if value is None:
                continue
            self.flags[nodes] |= bit
            self.v_prescribed[nodes, comp] = value
            for c in self._velocity_conditions:  # a later condition overrides earlier ones
                if c.component == comp:
                    c.nodes = c.nodes[~np.isin(c.nodes, nodes)]
            if history is not None:
                self._velocity_conditions.append(_VelocityCondition(nodes, comp, float(value), history))
        return nodes

    @property
    def has_time_dependent_velocity(self) -> bool:
        return any(c.nodes.size for c in self._velocity_conditions)

    def update_prescribed_velocity(self, v_prescribed: np.ndarray, time: float) -> None:
        """Write the time-dependent prescribed velocities at ``time`` into ``v_prescribed`` (n_nodes, 2)."""
        for c in self._velocity_conditions:
            factor = c.history(time)
            try:
                ok = bool(np.isfinite(float(factor)))
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(
                    f"prescribe_velocity: history({time:.6g} s) of the {'xy'[c.component]} velocity "
                    f"(v{'xy'[c.component]} = {c.value:g} m/s on {c.nodes.size} node(s), first node "
                    f"{int(c.nodes[0]) if c.nodes.size else -1}) returned {factor!r}, not a finite number")
            v_prescribed[c.nodes, c.component] = c.value * factor

    # ------------------------------------------------------------------ loads
    def set_gravity(self, gx: float = 0.0, gy: float = -9.81) -> None:
        """Gravitational acceleration [m/s^2], applied as ``m g`` on every node."""
        self.gravity = _finite([gx, gy], "set_gravity: gravity (gx, gy) [m/s^2]").copy()

    def add_body_force(self, bx: float, by: float, where=None) -> None:
        """Constant body force density ``b`` [N/m^3] on the triangles whose centroid satisfies ``where``.

        Lumped as ``b A0 / 3`` on each corner (exact for constant ``b`` on linear triangles).
        """
        _finite([bx, by], f"add_body_force: body force (bx, by) [N/m^3] (where={where!r})")
        tris = self.select_triangles(where)
        share = np.abs(self.topology.triangle_area0[tris]) / 3.0
        for k in range(3):
            np.add.at(self.external_force, self.topology.triangles[tris, k], np.outer(share, [bx, by]))

    def add_nodal_force(self, where, fx: float, fy: float) -> None:
        """Constant force [N/m] on each selected node."""
        _finite([fx, fy], f"add_nodal_force: force (fx, fy) [N/m] (selection {where!r})")
        nodes = self.select_nodes(where, "add_nodal_force")
        np.add.at(self.external_force, nodes, np.array([fx, fy]))

    @property
    def has_external_force(self) -> bool:
        return bool(np.any(self.external_force))

    # ------------------------------------------------------------------ initial state
    def set_initial_stress(self, stress, where=None) -> None:
        """Initial (e.g. geostatic) stress [Pa] of the triangles selected by ``where`` (default all).

        ``stress`` is a function ``(xc, yc) -> (n, 3) [s_xx, s_yy, s_xy]`` of the reference
        centroids (see :func:`geostatic_stress`), a (3,) constant or an (n_tri, 3) array. It
        enters the law as the initial second Piola-Kirchhoff stress ``S0``.
        """
        tris = self.select_triangles(where)
        if callable(stress):
            c = self.centroids0[tris]
            values = np.asarray(stress(c[:, 0], c[:, 1]), dtype=float)
        else:
            values = np.asarray(stress, dtype=float)
            if values.shape == (self.n_triangles, 3):
                values = values[tris]
        try:
            values = np.broadcast_to(values, (tris.size, 3))
        except ValueError:
            raise ValueError(f"set_initial_stress: stress must give 3 components [s_xx, s_yy, s_xy] per "
                             f"triangle ({tris.size} selected), got shape {values.shape}") from None
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            t = int(tris[k])
            c = self.centroids0[t]
            raise ValueError(f"set_initial_stress: stress of triangle {t} (centroid ({c[0]:.4g}, {c[1]:.4g}) m) "
                             f"is not finite: {values[k].tolist()} Pa ({int(bad.sum())} triangle(s) affected)")
        self.initial_stress[tris] = values

    def set_initial_velocity(self, vx: float = 0.0, vy: float = 0.0, where=None) -> None:
        """Initial velocity [m/s] of the selected nodes (default all)."""
        _finite([vx, vy], "set_initial_velocity: velocity (vx, vy) [m/s]")
        nodes = np.arange(self.n_nodes) if where is None else self.select_nodes(where, "set_initial_velocity")
        self.initial_velocity[nodes] = (vx, vy)

    def out_of_plane_initial_stress(self) -> np.ndarray:
        """(n_tri,) initial ``s_zz`` [Pa]: ``nu (s_xx + s_yy)`` in plane strain, 0 in plane stress."""
        if self.plane != PLANE_STRAIN:
            return np.zeros(self.n_triangles)
        return self.property_array("poisson") * (self.initial_stress[:, 0] + self.initial_stress[:, 1])

    # ------------------------------------------------------------------ arrays for the kernels
    def triangle_constants(self) -> np.ndarray:
        """(n_tri, N_TRI_CONST) per-triangle constants of :mod:`fdem.kernels.triangles`."""
        lam, mu = self.lame_arrays()
        return triangle_constants(self.topology.x0, self.topology.triangles, lam, mu,
                                  self.viscosity_array(), self.property_array("density"),
                                  self.initial_stress)

    def node_mass(self) -> np.ndarray:
        """(n_nodes,) lumped masses ``sum rho A0 / 3`` over the triangles at each node [kg/m]."""
        share = self.property_array("density") * np.abs(self.topology.triangle_area0) / 3.0
        mass = np.zeros(self.n_nodes)
        np.add.at(mass, self.topology.triangles.ravel(), np.repeat(share, 3))
        return mass

    def triangle_critical_dt(self) -> np.ndarray:
        """(n_tri,) exact critical step of each triangle [s], see :func:`fdem.physics.stability.triangle_critical_dt`."""
        lam, mu = self.lame_arrays()
        return triangle_critical_dt(self.topology.x0, self.topology.triangles, lam, mu,
                                    self.property_array("density"), self.viscosity_array())

    def node_corner_csr(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR map node -> corners ``3t + k`` (for the conforming two-pass kernel)."""
        corners_node = self.topology.triangles.ravel()
        order = np.argsort(corners_node, kind="stable")
        counts = np.bincount(corners_node, minlength=self.n_nodes)
        ptr = np.zeros(self.n_nodes + 1, np.int64)
        np.cumsum(counts, out=ptr[1:])
        return ptr, order.astype(np.int64)
