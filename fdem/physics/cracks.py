"""Cohesive crack elements: :class:`CrackSet`, the force provider that hosts the crack law.

Property sets are :mod:`fdem.physics.crack_properties`, random strengths
:mod:`fdem.physics.heterogeneity`, the strength-reduction factor :mod:`fdem.physics.interfaces`.

The law (per integration point; Munjiza 2004 ch. 7; Munjiza, Andrews & White 1999; Lisjak et
al. 2014) lives in :func:`fdem.kernels.cracks.point_law` and is derived in ``docs/cohesive.md``:

* penalty (elastic) rise ``sigma = k_n o`` to the tensile strength ``f_t`` and
  ``tau = k_t s`` to the Mohr-Coulomb strength ``f_s = c + sigma_n tan(phi)``
  (``sigma_n`` compressive, tension cut-off: in tension ``f_s = c``);
* softening with the Munjiza (Evans-Marathe) shape ``z(D)`` (default) or linear, with areas
  ``G_I`` (total work to open a unit area at zero shear) and ``G_II`` (work of the cohesive
  part of the shear strength; the frictional part ``sigma_n tan(phi)`` is friction);
* elliptical mixed-mode damage ``D = sqrt(xi_I^2 + xi_II^2)``, never healing; full normal
  penalty in compression; the element breaks when ``D >= 1`` at both integration points, or
  when an inelastic element's faces have turned more than 90 degrees apart (``docs/cohesive.md``).

Integration points: the two end points (node pairs 0-3 and 1-2). Nodal (Lobatto)
quadrature of an interface element decouples the ends, so each node pair has its own traction
and damage, avoids the traction oscillations that Gauss quadrature causes in stiff penalty
interfaces (Schellekens & de Borst 1993), integrates a uniform separation exactly and maps
tractions to nodal forces without an interpolation matrix (``f = w T``, ``w = L0/2``).

Units: SI, plane strain per metre of thickness (forces in N/m, energies in J/m).
"""
from __future__ import annotations

import math
import warnings
from typing import Collection, Mapping, Sequence
import numpy as np
from fdem.physics.interfaces import Interfaces
from fdem.kernels import cracks as K
from fdem.kernels.crack_output import crack_tractions
from fdem.mesh.topology import INTACT, Topology
from fdem.physics.crack_properties import CrackProperties, ELASTIC_ONLY_LIMIT, SOFTENING_KINDS, softening_integral, softening_max_slope
from fdem.physics.heterogeneity import Heterogeneity

__all__ = ["EVENT_DTYPE", "MODE_NAMES", "MODE_SHARE", "CP_FT", "CP_C", "CP_TANPHI", "CP_GI", "CP_GII", "CP_KIND",
           "CP_TANPHI_RES", "N_PROPS", "CrackSet"]


EVENT_DTYPE = np.dtype([
    ("element", np.int64), ("step", np.int64), ("time", np.float64),
    ("x", np.float64), ("y", np.float64), ("mode", "U5"), ("tag", np.int32),
    ("length", np.float64), ("energy", np.float64),
    ("energy_I", np.float64), ("energy_II", np.float64),
])
"""Fracture event: element id, step, time [s], midpoint [m], mode ("I", "II", "mixed"),
joint-set tag, reference length [m], dissipated fracture energy [J/m] (total, mode-I part,
mode-II part; friction excluded)."""


MODE_NAMES = ("I", "II", "mixed")


MODE_SHARE = 0.2
"""Failure mode of an event from the elliptical damage at breakage: with
``share = xi_II^2 / D^2`` (mean of the two ends), mode I when ``share < 0.2``, mode II when
``share > 0.8``, mixed otherwise."""


# Columns of the property table ``CrackSet.props`` (one row per tag, unreduced, no heterogeneity).
CP_FT = 0  # tensile strength f_t [Pa]
CP_C = 1  # cohesion c [Pa]
CP_TANPHI = 2  # friction coefficient tan(phi) [-]
CP_GI = 3  # mode-I fracture energy G_I [J/m^2]
CP_GII = 4  # mode-II fracture energy G_II [J/m^2]
CP_KIND = 5  # softening shape, fdem.kernels.cracks.MUNJIZA or LINEAR (stored as float)
CP_TANPHI_RES = 6  # residual friction coefficient of the broken faces tan(phi_res) [-]
N_PROPS = 7


def _colour_major_order(colour: np.ndarray, crack_triangles: np.ndarray) -> np.ndarray:
    """(n,) topology ids in internal order: by colour, then by the smaller and the larger of the
    element's two triangles (the two never repeat together: one edge per pair of triangles)."""
    t = np.sort(np.asarray(crack_triangles, dtype=np.int64), axis=1)
    return np.lexsort((t[:, 1], t[:, 0], colour)).astype(np.int64)


def _legacy_colour_major_order(colour: np.ndarray) -> np.ndarray:
    """The internal order of crack sets before the within-colour triangle order: by colour,
    topology order inside a colour. States saved without their order were saved in it."""
    return np.argsort(colour, kind="stable").astype(np.int64)


def _snap_back_advice(energy: str, given: float, need: float, length: float, per_length: bool,
                      penalty: str) -> str:
    """What a user can do about a snap-back of the element of reference length ``length`` [m]
    that needs the most energy, ``need`` [J/m^2] against ``given``. Where the stiffness is a
    penalty over the element length (``k = p / L0``) the energy needed grows in proportion to
    ``L0``: elements ``need / given`` times shorter everywhere (this one below
    ``length * given / need``) satisfy it. Else, or too, raise the energy (or the penalty) of
    the property set."""
    fix = f"raise {energy} of this property set above {need:.4g} J/m^2"
    if not per_length:
        return f"To fix it, {fix} (its stiffness does not depend on the element size)."
    factor = need / given
    return (f"The energy needed grows with the element length (stiffness = {penalty} / L0): refine the mesh by at "
            f"least a factor {factor:.3g} (element sizes divided by {factor:.3g}; this element would need "
            f"L0 < {length * given / need:.4g} m), or {fix}, or raise its penalty {penalty} by that factor.")


def _check_unused_sets(property_sets: Mapping[int, CrackProperties], present: np.ndarray,
                       absent_ok: Collection[int]) -> None:
    """Property sets for joint-set tags with no crack element: a ``UserWarning`` for those in
    ``absent_ok`` and for any when the mesh has no joint at all (an intact-rock mesh given a
    scene's whole table, as the benchmarks do, or every joint dropped at a coarse size: no
    joint set for a typo to stand for); a ``ValueError`` otherwise (see :class:`CrackSet`)."""
    have = {int(t) for t in present}
    unused = sorted(int(t) for t in property_sets if int(t) != INTACT and int(t) not in have)
    if not unused:
        return
    allowed = {int(t) for t in absent_ok} | (set(unused) if not have - {INTACT} else set())
    label = {t: property_sets[t].name or f"joint set {t}" for t in unused}
    wrong = [t for t in unused if t not in allowed]
    if wrong:
        raise ValueError(f"property set(s) for tag(s) {wrong} ({', '.join(label[t] for t in wrong)}) match no crack "
                         f"element: the mesh has tags {sorted(have)}; check the tag numbers (joint set j of the "
                         f"geometry has tag j)")
    warnings.warn(f"joint set(s) {unused} ({', '.join(label[t] for t in unused)}) have no crack element in this "
                  f"mesh (its tags: {sorted(have)}): their property sets are unused (joints all shorter than the "
                  f"geometry's min_joint_length at this element size, or a mesh without joints)", UserWarning,
                  stacklevel=3)


class CrackSet:
    """All crack elements of a topology: the force provider the solver calls every step.

    Parameters
    ----------
    topology : Topology
    property_sets : :class:`fdem.interfaces.Interfaces`, or a mapping ``tag -> CrackProperties``
        (or a sequence indexed by tag) wrapped into one; tag 0 is intact rock, ``j >= 1`` DFN
        joint set ``j``. Every tag of the elements (``tags``, by default
        ``topology.crack_tag``) needs a set. The
        strength-reduction factor lives there (``cracks.interfaces.set_reduction(F)``) and
        reaches contact too.
    heterogeneity : Heterogeneity or None
    scheme : ``"colour"`` (elements coloured so each colour scatters race-free) or
        ``"gather"`` (per-element forces stored, then gathered per node through a
        node -> (crack, slot) map of at most 2 entries). Both give identical forces; colour is
        the faster on this hardware (see ``docs/benchmarks/cracks.json``).
    parallel_min : below this many live elements a serial loop runs instead (no threading
        overhead on small problems).
    absent_ok : joint-set tags that may have no crack element in this mesh (a set whose joints
        were all dropped as shorter than the geometry's ``min_joint_length`` at a coarse size):
        a property set given for one of them draws a ``UserWarning`` naming it, as does any
        joint-set property set when the mesh has no joint at all. A property set for any other
        tag without elements is a ``ValueError`` naming the tag and the tags the mesh has (a
        mistyped tag would otherwise leave its joints on another set's properties without a
        word). The intact set (tag 0) may always be absent.
    contact_penalty : the contact penalty ``p`` [Pa] of the scene, if the crack elements' faces
        will be handed to contact. Compression across an element is then resisted with the
        stiffness contact would have for a flat penetration of its two triangles,
        ``k_c = 3 p (1/h_A + 1/h_B)`` per unit area (``h`` the altitudes on the edge), so a
        compressed element that breaks hands over the same force and energy instead of a jump
        (with ``k_c = k_n`` contact typically pushes several times harder and creates energy).
        Default: ``k_c = k_n``.
    tags : (n_cracks,) int, the property-set tag of each element, when it differs from the
        geometry's ``topology.crack_tag`` (elastic side bands, ground kept at full strength).
        The crack set reads its properties by these (its ``tag``); ``topology``, which the model
        and the outputs share, keeps the geometry's tags, so pictures and summaries still count
        such elements as what the geometry made them. Default: ``topology.crack_tag``.

    State exposed for output (topology order): ``damage`` (n,) in [0, 1], ``damage_ip`` (n, 2),
    ``broken`` (n,) bool, ``dissipated`` (n, 3), ``crack_fields()``, ``events`` (structured
    array, :data:`EVENT_DTYPE`), ``newly_broken`` (ids broken by the last :meth:`add_forces`,
    for contact to pick up their faces), ``residual_friction`` (n,) ``tan(phi_res)`` for contact,
    ``active`` (ids of live elements), ``preload_forces`` ((n, 2, 2) [N/m] or ``None``: the end
    forces :meth:`set_preload` was given).
    """

    def __init__(self, topology: Topology, property_sets: Mapping[int, CrackProperties] | Sequence[CrackProperties],
                 heterogeneity: Heterogeneity | None = None, scheme: str = "colour",
                 parallel_min: int = K.PARALLEL_MIN, contact_penalty: float | None = None,
                 absent_ok: Collection[int] = (), tags: np.ndarray | None = None) -> None:
        if scheme not in ("colour", "gather"):
            raise ValueError(f"scheme must be 'colour' or 'gather', got {scheme!r}")
        self.topology = topology
        self.scheme = scheme
        self.parallel_min = int(parallel_min)
        self.interfaces = Interfaces.of(property_sets)
        self.property_sets: dict[int, CrackProperties] = self.interfaces.property_sets
        self.heterogeneity = heterogeneity or Heterogeneity()

        tag = np.asarray(topology.crack_tag if tags is None else tags, dtype=np.int32)
        if tag.shape != (len(topology.crack_tag),):
            raise ValueError(f"tags must give one tag per crack element ({len(topology.crack_tag)}), got shape {tag.shape}")
        self.tag = tag
        n = tag.shape[0]
        present = np.unique(tag)
        missing = [int(t) for t in present if int(t) not in self.property_sets]
        if missing:
            t = missing[0]
            c = int(np.flatnonzero(tag == t)[0])
            mid = topology.x0[topology.crack_nodes[c, :2]].mean(axis=0)
            what = "intact rock bridges" if t == INTACT else f"DFN joint set {t}"
            raise ValueError(
                f"crack elements with tag(s) {missing} have no property set (e.g. element {c} at "
                f"({mid[0]:.6g}, {mid[1]:.6g}) on {what}); given sets: {sorted(self.property_sets)}")
        _check_unused_sets(self.property_sets, present, absent_ok)

        self.length0 = np.asarray(topology.crack_length0, dtype=np.float64)
        self.nodes = np.ascontiguousarray(topology.crack_nodes, dtype=np.int32)
        self.strength_multiplier = self.heterogeneity.draw(tag)

        # Small property table indexed by tag: [f_t, c, tan(phi), G_I, G_II, kind, tan(phi_res)] (CP_*).
        n_tags = int(max(self.property_sets)) + 1 if self.property_sets else 1
        self.props = np.zeros((n_tags, N_PROPS))
        for t, p in self.property_sets.items():
            self.props[t, [CP_FT, CP_C, CP_TANPHI, CP_GI, CP_GII, CP_KIND, CP_TANPHI_RES]] = [
                p.f_t, p.c, p.tan_phi, p.G_I, p.G_II, SOFTENING_KINDS[p.softening], p.tan_phi_res]
        # Dilation by tag: [tan(psi), u_lim] (K.CD_*); geometric, not reduced (see _fill_constants).
        self.dilation = np.zeros((n_tags, K.N_DIL))
        for t, p in self.property_sets.items():
            self.dilation[t, [K.CD_TANPSI, K.CD_ULIM]] = [p.tan_psi, p.dilation_limit]
        self.kn = np.empty(n)
        self.kt = np.empty(n)
        for t in present:
            sel = tag == t
            self.kn[sel], self.kt[sel] = self.property_sets[int(t)].stiffness(self.length0[sel])
        self.kc = self.kn.copy()
        if contact_penalty is not None:
            if not (math.isfinite(contact_penalty) and contact_penalty > 0):
                raise ValueError(f"contact_penalty must be positive and finite, got {contact_penalty}")
            # Flat penetration d of triangle B into A under distributed-potential contact stores
            # p L (3 d^2 / 2)(1/h_A + 1/h_B) (h: altitudes on the shared edge), a stiffness per
            # unit area k_c = 3 p (1/h_A + 1/h_B): the same resistance before and after breakage.
            area = topology.triangle_area0
            h = 2.0 * area[topology.crack_triangles] / self.length0[:, None]
            self.kc = 3.0 * contact_penalty * (1.0 / h[:, 0] + 1.0 / h[:, 1])
        self._check_snap_back(self.interfaces.reduction)

        # Internal element order: colour-major for the colour scheme, so that every colour
        # pass streams its rows contiguously, and within a colour by the element's triangles
        # (smaller, then larger): node 3t+k belongs to triangle t, so each colour then sweeps
        # the node arrays forward instead of jumping wherever the topology's edge order puts
        # its elements (:func:`_colour_major_order`). Identity for the gather scheme. Public
        # arrays (damage, broken, events) are in topology order.
        tris = np.ascontiguousarray(topology.crack_triangles, dtype=np.int64)
        if scheme == "colour":
            colour = K.colour_elements(tris, topology.n_triangles)
            self._perm = _colour_major_order(colour, tris)
            self._colour = np.ascontiguousarray(colour[self._perm])
        else:
            self._perm = np.arange(n, dtype=np.int64)
            self._colour = np.zeros(n, dtype=np.int32)
        self._inv = np.empty(n, dtype=np.int64)
        self._inv[self._perm] = np.arange(n)
        self._nodes = np.ascontiguousarray(self.nodes[self._perm])
        # The kernels read displacements against the reference geometry, never positions
        # (fdem.kernels.cracks, "ref"): the separation of two nodes that start together is then
        # resolved to the round-off of u, not of x.
        self._x0 = np.ascontiguousarray(topology.x0, dtype=np.float64)
        self._ref = K.reference_geometry(self._x0, self._nodes)
        self._bound: tuple[np.ndarray, np.ndarray] | None = None  # (x, u) of the simulation's state

        self._const = np.zeros((n, K.N_CONST))
        self._status = np.zeros(n, dtype=np.int8)
        self._state = np.zeros((n, K.N_STATE))
        self._diss = np.zeros((n, K.N_DISS))
        self._offset = np.zeros((n, K.N_OFFSET))
        self.preload_forces = None  # (n, 2, 2) [N/m] once set_preload has run: the start's static end forces
        self._dil = np.zeros((n, K.N_DIL))
        self._fill_constants()
        self.interfaces.subscribe(self._fill_constants, check=self._check_snap_back)
        self.broken = np.zeros(n, dtype=bool)
        self.failure_mode = np.zeros(n, dtype=np.int8)  # 0 intact, 1 mode I, 2 mode II, 3 mixed
        self._broke_flag = np.zeros(n, dtype=np.int8)
        self.released = 0.0
        self.newly_broken = np.zeros(0, dtype=np.int64)
        self._events: list[tuple] = []
        self._events_arr: np.ndarray | None = None
        self._time = 0.0
        self._last_step: int | None = None
        self._x_last: np.ndarray | None = None

        if scheme == "gather":
            self._fe = np.zeros((n, K.N_FE))
            self._node_map = np.full((topology.n_nodes, 2), -1, dtype=np.int64)
            codes = (4 * np.arange(n)[:, None] + np.arange(4)[None, :]).ravel()
            nodes_flat = self._nodes.ravel().astype(np.int64)
            order = np.argsort(nodes_flat, kind="stable")
            nf, cf = nodes_flat[order], codes[order]
            first = np.r_[True, nf[1:] != nf[:-1]]
            rank = np.arange(nf.size) - np.maximum.accumulate(np.where(first, np.arange(nf.size), 0))
            if np.any(rank > 1):
                raise ValueError("a node belongs to more than two crack elements: topology is not exploded")
            self._node_map[nf, rank] = cf
        self._awake: np.ndarray | None = None  # (n,) bool, internal order: elements evaluated; None: all
        self._carry_broken = np.zeros(0, dtype=np.int64)  # broken outside add_forces, handed on by the next call
        # the GPU's copy of the element arrays while a simulation runs on one
        # (fdem.solve.cuda_backend); None on the CPU
        self.device = None
        self._set_active(np.arange(n, dtype=np.int64))

    # ------------------------------------------------------------------ constants
    def _element_strengths(self, reduction: float) -> tuple[np.ndarray, ...]:
        """Per-element ``f_t, c, tan(phi), G_I, G_II, kind`` under the reduction factor ``F``."""
        P = self.props[self.tag]
        h = self.strength_multiplier
        ft_factor = 1.0 / reduction if self.interfaces.reduce_tensile else 1.0
        return (P[:, CP_FT] * h * ft_factor, P[:, CP_C] * h / reduction, P[:, CP_TANPHI] / reduction, P[:, CP_GI],
                P[:, CP_GII], P[:, CP_KIND])

    def _check_snap_back(self, reduction: float) -> None:
        """G must exceed the elastic energy at the peak, or the softening branch snaps back.

        Mode I: ``G_I > f_t^2 / (2 k_n)`` (so that ``o_r > o_p``). Mode II (plastic cohesive
        slip, slip-controlled): ``G_II > c^2 Zbar max|z'| / k_t`` (``= c^2/(2 k_t)`` for linear
        softening). Checked with the strongest element and the softest penalty of each set.
        """
        ft, c, _, GI, GII, kind = self._element_strengths(reduction)
        for t, p in self.property_sets.items():
            sel = np.flatnonzero(self.tag == t)
            if sel.size == 0:
                continue
            label = f"property set {t} ({p.name or ('intact' if t == INTACT else f'joint set {t}')})"
            need_I = ft[sel] ** 2 / (2.0 * self.kn[sel])
            i = int(np.argmax(need_I))
            if not GI[sel[i]] > need_I[i]:
                raise ValueError(
                    f"{label}: G_I = {p.G_I:.6g} J/m^2 is too small for f_t = {ft[sel[i]]:.6g} Pa and "
                    f"k_n = {self.kn[sel[i]]:.6g} Pa/m (element {sel[i]}, L0 = {self.length0[sel[i]]:.4g} m): the "
                    f"softening branch would snap back; smallest admissible G_I is {need_I[i]:.6g} J/m^2. "
                    + _snap_back_advice("G_I", p.G_I, need_I[i], self.length0[sel[i]], p.k_n is None, "p_n"))
            zs = softening_integral(p.softening) * softening_max_slope(p.softening)
            need_II = zs * c[sel] ** 2 / self.kt[sel]
            i = int(np.argmax(need_II))
            if c[sel[i]] > 0 and not GII[sel[i]] > need_II[i]:
                raise ValueError(
                    f"{label}: G_II = {p.G_II:.6g} J/m^2 is too small for c = {c[sel[i]]:.6g} Pa and "
                    f"k_t = {self.kt[sel[i]]:.6g} Pa/m (element {sel[i]}, L0 = {self.length0[sel[i]]:.4g} m): the "
                    f"softening branch would snap back; smallest admissible G_II is {need_II[i]:.6g} J/m^2. "
                    + _snap_back_advice("G_II", p.G_II, need_II[i], self.length0[sel[i]], p.k_t is None and
                                        (p.p_t is not None or p.k_n is None), "p_t" if p.p_t is not None else "p_n"))

    _elastic_only = False

    def _fill_constants(self) -> None:
        # counts the changes of the constants (strength reduction, hold elastic): sleeping
        # regions (fdem.solve.sleeping) wake when the strengths change
        self.constants_version = getattr(self, "constants_version", -1) + 1
        """Write the per-element constant rows for the current reduction factor and hold state.

        Damaged ends keep their secant stiffness (:func:`fdem.kernels.cracks.remap_damage`), so
        the change neither creates nor removes stored energy."""
        ft, c, tanphi, GI, GII, kind = self._element_strengths(self.interfaces.reduction)
        w = 0.5 * self.length0
        zbar = np.where(kind == K.LINEAR, softening_integral("linear"), softening_integral("munjiza"))
        dO = (GI - ft ** 2 / (2.0 * self.kn)) / (ft * zbar)
        with np.errstate(divide="ignore"):
            inv_dK = np.where(c > 0, c * zbar / np.where(GII > 0, GII, 1.0), 0.0)
        C = np.empty_like(self._const)
        C[:, K.CC_KN] = self.kn * w
        C[:, K.CC_KT] = self.kt * w
        C[:, K.CC_OP] = ft / self.kn
        C[:, K.CC_C] = c * w
        C[:, K.CC_TANPHI] = tanphi
        C[:, K.CC_INV_DO] = np.where(kind == K.LINEAR, -1.0, 1.0) / dO  # sign: softening shape
        C[:, K.CC_INV_DK] = inv_dK
        C[:, K.CC_KC] = self.kc * w
        if self._elastic_only:
            # Peak opening and cohesion out of reach: every update takes the elastic fast path.
            C[:, K.CC_OP] = ELASTIC_ONLY_LIMIT
            C[:, K.CC_C] = ELASTIC_ONLY_LIMIT
        self._dil[:] = self._dilation_constants(tanphi)[self._perm]
        new = np.ascontiguousarray(C[self._perm])
        if not hasattr(self, "_active"):  # construction: nothing to carry over
            self._const[:] = new
            return
        if self._status.any():
            K.remap_damage(self._const, new, self._state, self._status, self._active)
        self._const[:] = new
        # Ends now outside the envelope soften or slip at once, at fixed positions, with the
        # released stored energy booked exactly (there is no work without motion).
        x = self._positions_now()
        K.project_to_envelope(self.displacement(x), self._ref, self._nodes, self._const, self._status,
                              self._state, self._diss, self._offset, self._dil, self._active)

    def _dilation_constants(self, tanphi: np.ndarray) -> np.ndarray:
        """(n, 2) ``[tan(psi_F), u_lim]`` per element (topology order) under the friction
        ``tanphi = tan(phi) / F`` of the current reduction factor.

        Dilation is geometry (the asperity angle), so a strength reduction keeps it, with one
        exception: it is capped at the reduced friction, ``tan(psi_F) = min(tan(psi), tan(phi)/F)``,
        because a joint sliding with ``tan(psi) > tan(phi_F)`` would dissipate
        ``sigma_n (tan(phi_F) - tan(psi)) < 0`` per unit slip once its cohesion is gone, i.e.
        create energy. The cap acts only where ``F > tan(phi)/tan(psi)``; the dilatant opening
        already accumulated is state and does not change (no stored energy is created or lost).
        """
        D = self.dilation[self.tag]  # a copy (fancy indexing)
        D[:, K.CD_TANPSI] = np.minimum(D[:, K.CD_TANPSI], tanphi)
        return D

    def hold_elastic(self, on: bool = True) -> None:
        """Keep every element elastic (no damage, no breakage, no shear yield) while ``on``.

        For geostatic initialisation: gravity is switched on and damped to equilibrium with the
        crack elements acting as elastic penalties, as in the paper's initial FEM stage; then
        ``hold_elastic(False)`` restores the strengths (divided by the current reduction factor).
        Damage already done is kept at its secant stiffness: holding or releasing creates no energy.
        """
        self._elastic_only = bool(on)
        self._fill_constants()

    @property
    def strength_factor(self) -> float:
        """``1 / F``, the multiplier on ``c`` and ``tan(phi)`` (see :mod:`fdem.interfaces`)."""
        return self.interfaces.strength_factor

    @property
    def residual_friction(self) -> np.ndarray:
        """(n,) reduced friction coefficient ``tan(phi_res) / F`` of the faces of each element."""
        return self.interfaces.residual_mu(self.tag)

    # ------------------------------------------------------------------ pre-load
    def set_preload(self, end_forces: np.ndarray) -> None:
        """Pre-load the elements: ``end_forces`` (n, 2, 2) [N/m] is the force on the A node of
        each end (end 0: nodes A_p/B_p, end 1: A_q/B_q; topology order) at zero separation.

        Stored as separation offsets in the element frame at the reference positions:
        ``o_off = (F.n) / K`` (``K = K_n w`` in tension, ``K_c w`` in compression) and
        ``s_off = (F.t) / (K_t w)``, ``w = L0 / 2``, so the law gives ``F`` at zero separation
        and every later change of separation adds to it (the crack-element counterpart of the
        triangles' initial stress). Pre-loads above the strength soften or slide the element
        at its first update. See :func:`fdem.geostatic.geostatic_start`.
        """
        F = np.asarray(end_forces, dtype=np.float64)
        n = self.n_cracks
        if F.shape != (n, 2, 2):
            raise ValueError(f"end_forces must have shape ({n}, 2, 2), got {F.shape}")
        bad = np.flatnonzero(~np.isfinite(F).all(axis=(1, 2)))
        if bad.size:
            c = int(bad[0])
            mid = self.topology.x0[self.nodes[c, :2]].mean(axis=0)
            raise ValueError(f"end_forces of crack element {c} at ({mid[0]:.6g}, {mid[1]:.6g}) are not finite "
                             f"({bad.size} element(s) in all)")
        x = self.topology.x0
        cn = self.nodes
        m0 = 0.5 * (x[cn[:, 0]] + x[cn[:, 3]])
        m1 = 0.5 * (x[cn[:, 1]] + x[cn[:, 2]])
        t = (m1 - m0) / np.maximum(np.linalg.norm(m1 - m0, axis=1, keepdims=True), 1e-300)
        nrm = np.column_stack([t[:, 1], -t[:, 0]])
        w = 0.5 * self.length0
        off = np.zeros((n, K.N_OFFSET))
        for e in range(2):
            fn = (F[:, e] * nrm).sum(axis=1)
            ft = (F[:, e] * t).sum(axis=1)
            off[:, K.CO_O0 + K.CO_END * e] = fn / (np.where(fn > 0.0, self.kn, self.kc) * w)
            off[:, K.CO_S0 + K.CO_END * e] = ft / (self.kt * w)
        self._offset[:] = off[self._perm]
        self.preload_forces = F.copy()  # kept to check the start against a later strength (geostatic.crack_strength_check)

    # ------------------------------------------------------------------ active list
    def _set_active(self, alive: np.ndarray) -> None:
        """``alive``: sorted internal ids of the live elements (colour-major already)."""
        self._active = np.ascontiguousarray(alive, dtype=np.int64)
        n_col = int(self._colour.max()) + 1 if self._colour.size else 1
        self._colour_ptr = np.searchsorted(self._colour[self._active], np.arange(n_col + 1)).astype(np.int64)
        if self.scheme == "gather":
            self._node_list = np.unique(self._nodes[self._active].ravel()).astype(np.int64)
        self._refresh_run()

    def _refresh_run(self) -> None:
        """The elements :meth:`add_forces` evaluates: the live ones, less those :meth:`set_awake` left out."""
        awake = getattr(self, "_awake", None)
        if awake is None:
            self._run, self._run_ptr = self._active, self._colour_ptr
            return
        self._run = np.ascontiguousarray(self._active[awake[self._active]])
        n_col = int(self._colour_ptr.shape[0] - 1)
        self._run_ptr = np.searchsorted(self._colour[self._run], np.arange(n_col + 1)).astype(np.int64)

    def set_awake(self, awake: np.ndarray | None) -> None:
        """Evaluate only the elements with ``awake`` True ((n,) bool, topology order) in
        :meth:`add_forces`; ``None``: all live elements. The elements left out are those between
        two sleeping regions (:mod:`fdem.solve.sleeping`): their nodes do not move, so their
        forces do not change, and the caller adds them from :meth:`add_element_forces`."""
        if awake is not None and self.scheme != "colour":
            raise ValueError("only the colour scheme evaluates a subset of the crack elements")
        self._awake = None if awake is None else np.ascontiguousarray(np.asarray(awake, dtype=bool)[self._perm])
        self._refresh_run()

    @property
    def n_evaluated(self) -> int:
        """Live elements that :meth:`add_forces` evaluates (all of them unless :meth:`set_awake` left some out)."""
        return int(self._run.shape[0])

    def bind_displacement(self, x: np.ndarray, u: np.ndarray) -> None:
        """Tell the set that the position array ``x`` (n_nodes, 2) comes with its displacement
        ``u = x - x0`` kept apart (:class:`fdem.solve.simulation.State`): the kernels then read
        ``u`` whenever they are handed ``x``, and a separation is resolved to the round-off of
        ``u`` instead of ``x``."""
        if np.shape(u) != np.shape(x):
            raise ValueError(f"displacement of shape {np.shape(u)} bound to positions of shape {np.shape(x)}")
        self._bound = (x, u)   # the latest simulation to take the set (bound_to tells an earlier one)

    def bound_to(self, x: np.ndarray) -> bool:
        """Whether the set reads the displacements that come with the position array ``x``: a
        simulation whose crack set another simulation took over since (:meth:`bind_displacement`)
        finds it is not, and refuses to step rather than act on the other's displacements."""
        return self._bound is not None and self._bound[0] is x

    def _positions_now(self) -> np.ndarray:
        """The positions of the last :meth:`add_forces`, else the bound state's, else the
        reference ones."""
        if self._x_last is not None:
            return self._x_last
        return self._bound[0] if self._bound is not None else self.topology.x0

    def displacement(self, x: np.ndarray) -> np.ndarray:
        """(n_nodes, 2) displacements [m] the kernels read for positions ``x``: the bound
        displacement (:meth:`bind_displacement`) when ``x`` is the bound position array, else
        ``x - x0`` (resolved only to the round-off of ``x``)."""
        if self._bound is not None and x is self._bound[0]:
            return self._bound[1]
        return np.ascontiguousarray(np.asarray(x, dtype=np.float64) - self._x0)

    def add_element_forces(self, x: np.ndarray, f: np.ndarray, ids: np.ndarray, step: int) -> None:
        """Update the live elements among ``ids`` (topology order) at ``x`` and add their forces
        into ``f`` (n_nodes, 2) [N/m], as :meth:`add_forces` does for the others. An element that
        breaks is registered here and handed to contact by the next :meth:`add_forces`."""
        ids = np.asarray(ids, dtype=np.int64)
        internal = self._inv[ids]
        live = np.zeros(self.n_cracks, dtype=bool)
        live[self._active] = True
        internal = np.ascontiguousarray(np.sort(internal[live[internal]]))
        if internal.size == 0:
            return
        nb = K.crack_forces_serial(self.displacement(x), self._ref, f, self._nodes, self._const, self._status,
                                   self._state, self._diss, self._offset, self._dil, internal, self._broke_flag)
        if nb:
            self._register_breaks(x, step)
            self._carry_broken = np.union1d(self._carry_broken, self.newly_broken)

    @property
    def active(self) -> np.ndarray:
        """Topology ids of the live (unbroken) crack elements."""
        return self._perm[self._active]

    @property
    def n_active(self) -> int:
        return int(self._active.shape[0])

    @property
    def n_cracks(self) -> int:
        return int(self.tag.shape[0])

    @property
    def n_colours(self) -> int:
        return int(self._colour_ptr.shape[0] - 1)

    # ------------------------------------------------------------------ force provider
    def add_forces(self, x: np.ndarray, v: np.ndarray, f: np.ndarray, dt: float, step: int) -> None:
        """Add the crack forces on the nodes into ``f`` (n_nodes, 2) [N/m] and update damage.

        ``x`` (n_nodes, 2) current positions [m]; ``v`` is unused (the law is rate
        independent); ``dt`` [s] and ``step`` time-stamp fracture events (time advances by
        ``dt`` per new step number). Elements reaching ``D >= 1`` at both ends, or inelastic ones
        whose faces have turned more than 90 degrees apart, break: they add no force from this
        call on, leave the active list and are recorded in :attr:`events` (a folded element's
        damage may stay below 1 at its intact end).
        """
        self.tick(step, dt)
        self._x_last = x
        carry, self._carry_broken = self._carry_broken, self._carry_broken[:0]
        self._add_forces(x, f, step)
        if carry.size:
            self.newly_broken = np.union1d(carry, self.newly_broken)

    def tick(self, step: int, dt: float) -> None:
        """Advance the events' clock to step ``step`` (time advances by ``dt`` [s] per step
        number since the last call): every :meth:`add_forces` does it, and the GPU backend for
        each step of a batch that needed no crack work on the host."""
        if self._last_step is None:
            self._time = step * dt
        elif step != self._last_step:
            self._time += (step - self._last_step) * dt
        self._last_step = step

    def _add_forces(self, x: np.ndarray, f: np.ndarray, step: int) -> None:
        if self._run.size == 0:
            self.newly_broken = np.zeros(0, dtype=np.int64)
            return
        if self.device is not None:  # the same law on the GPU; breaks are registered here, on the host
            nb = self.device.crack_forces(self)
            if nb:
                x = self.device.host_x(with_u=True)  # the breaks' positions and released energies need x_n, u_n
        elif self._run.size < self.parallel_min:
            nb = K.crack_forces_serial(self.displacement(x), self._ref, f, self._nodes, self._const, self._status,
                                       self._state, self._diss, self._offset, self._dil, self._run, self._broke_flag)
        elif self.scheme == "colour":
            nb = K.crack_forces_coloured(self.displacement(x), self._ref, f, self._nodes, self._const, self._status,
                                         self._state, self._diss, self._offset, self._dil, self._run, self._run_ptr,
                                         self._broke_flag)
        else:
            nb = K.crack_forces_store(self.displacement(x), self._ref, self._nodes, self._const, self._status,
                                      self._state, self._diss, self._offset, self._dil, self._active, self._fe,
                                      self._broke_flag)
            K.gather_node_forces(f, self._node_list, self._node_map, self._fe)
        if nb:
            self._register_breaks(x, step)
        else:
            self.newly_broken = np.zeros(0, dtype=np.int64)

    def _register_breaks(self, x: np.ndarray, step: int) -> None:
        new = np.flatnonzero(self._broke_flag[self._active]).astype(np.int64)
        ids = self._active[new]
        self._broke_flag[ids] = 0
        topo_ids = self._perm[ids]
        self.broken[topo_ids] = True
        # Elastic energy still held at breakage (e.g. friction stress, closure) is released.
        self.released += K.crack_elastic_energy(self.displacement(x), self._ref, self._nodes, self._const, self._state,
                                                self._offset, ids)
        mid = 0.25 * x[self._nodes[ids]].sum(axis=1)
        wI, wII = self._diss[ids, K.CW_MODE_I], self._diss[ids, K.CW_MODE_II]
        # Mode from the elliptical damage at failure: share of xi_II^2 in D^2, averaged over ends.
        share = np.zeros(ids.size)
        for e in (0, 1):
            D = np.maximum(self._state[ids, K.CS_D0 + K.CS_END * e], 1e-300)
            xi2 = self._state[ids, K.CS_KAP0 + K.CS_END * e] * self._const[ids, K.CC_INV_DK]
            share += 0.5 * np.minimum((xi2 / D) ** 2, 1.0)
        mode = np.where(share < MODE_SHARE, "I", np.where(share > 1 - MODE_SHARE, "II", "mixed"))
        self.failure_mode[topo_ids] = np.where(share < MODE_SHARE, 1, np.where(share > 1 - MODE_SHARE, 2, 3))
        for k in np.argsort(topo_ids):
            c = int(topo_ids[k])
            self._events.append((c, int(step), self._time, mid[k, 0], mid[k, 1], mode[k],
                                 int(self.tag[c]), self.length0[c], wI[k] + wII[k], wI[k], wII[k]))
        self.newly_broken = np.sort(topo_ids)
        self._events_arr = None
        self._set_active(np.delete(self._active, new))

    @property
    def events(self) -> np.ndarray:
        """Fracture events so far, a structured array of :data:`EVENT_DTYPE`."""
        if self._events_arr is None:
            self._events_arr = np.array(self._events, dtype=EVENT_DTYPE)
        return self._events_arr

    def n_inelastic(self) -> int:
        """Number of elements that have left the elastic range (damaged or slid) so far."""
        return int(np.count_nonzero(self._status))

    def inelastic(self) -> np.ndarray:
        """Sorted topology ids of the elements that have left the elastic range (damaged, slid
        or broken). Contact watches these: once an element softens or slides, its triangles'
        vertex neighbours can interpenetrate, which only contact resists."""
        return np.sort(self._perm[np.flatnonzero(self._status)])

    @property
    def damage(self) -> np.ndarray:
        """(n,) element damage in [0, 1]: the larger of its two ends (1 for broken elements)."""
        return np.minimum(self._state[self._inv][:, [K.CS_D0, K.CS_D1]].max(axis=1), 1.0)

    @property
    def damage_ip(self) -> np.ndarray:
        """(n, 2) damage at the two integration points (element ends 0-3 and 1-2)."""
        return np.minimum(self._state[self._inv][:, [K.CS_D0, K.CS_D1]], 1.0)

    @property
    def dissipated(self) -> np.ndarray:
        """(n, 3) energy dissipated by each element [J/m]: mode I, cohesive mode II, friction."""
        return self._diss[self._inv]

    def tractions(self, x: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(normal, shear)``, (n,) each [Pa], topology order: the tractions the elements carry
        at positions ``x`` (default: those of the last :meth:`add_forces`, the simulation's
        current ones), mean of the two ends.

        Evaluated by the step's own law (:func:`fdem.kernels.cracks.point_law`, through
        :func:`fdem.kernels.crack_output.crack_tractions`) on each element's stored state, which
        is read and not changed; the law's end forces carry the end weight ``w = L0/2``, so the
        traction of an end is its force divided by ``w``. Normal: tension positive, compression
        negative (a geostatic preload included: the law adds the offsets); shear: the traction
        resisting the slip. Broken elements carry none: 0."""
        if x is None:
            x = self._positions_now()
        u = self.displacement(x)
        ends = np.empty((self.n_cracks, 4))
        broken = np.ascontiguousarray(self.broken[self._perm])
        crack_tractions(u, self._ref, self._nodes, self._const, self._status, self._state, self._offset, self._dil, broken, ends)
        w = 0.5 * self.length0[self._perm]
        normal = np.empty(self.n_cracks)
        shear = np.empty(self.n_cracks)
        normal[self._perm] = 0.5 * (ends[:, 0] + ends[:, 2]) / w
        shear[self._perm] = 0.5 * (ends[:, 1] + ends[:, 3]) / w
        return normal, shear

    def break_time(self) -> np.ndarray:
        """(n,) time [s] at which each element broke (from :attr:`events`); NaN while intact."""
        t = np.full(self.n_cracks, np.nan)
        ev = self.events
        if ev.size:
            t[ev["element"]] = ev["time"]
        return t

    def crack_fields(self, x: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """(n,) arrays for the crack line cells of the output: ``damage``, ``broken`` (0/1),
        ``failure_mode`` (0 intact, 1 mode I, 2 mode II, 3 mixed), ``fracture_energy`` (mode I +
        II dissipated per element [J/m]), ``strength_multiplier``, ``normal_traction`` and
        ``shear_traction`` [Pa] (:meth:`tractions` at positions ``x``, default the last
        :meth:`add_forces`), ``break_time`` [s] (:meth:`break_time`, NaN while intact)."""
        d = self.dissipated
        normal, shear = self.tractions(x)
        return {
            "damage": self.damage,
            "broken": self.broken.astype(np.int8),
            "failure_mode": self.failure_mode,
            "fracture_energy": d[:, K.CW_MODE_I] + d[:, K.CW_MODE_II],
            "strength_multiplier": self.strength_multiplier,
            "normal_traction": normal,
            "shear_traction": shear,
            "break_time": self.break_time(),
        }

    def energy_terms(self) -> dict[str, float]:
        """Energy terms for the ledger [J per metre of thickness].

        ``crack_elastic``: stored in the live elements (configuration of the last
        :meth:`add_forces`; call it right after). Cumulative dissipation: ``fracture`` (mode I
        + cohesive mode II, the ``G`` areas), ``crack_friction`` (``sigma_n tan(phi)`` times
        plastic slip inside unbroken elements), ``crack_released`` (elastic energy the
        elements held when they broke, handed over with the faces).
        """
        el = 0.0
        if self._x_last is not None and self._active.size:
            el = float(K.crack_elastic_energy(self.displacement(self._x_last), self._ref, self._nodes, self._const,
                                              self._state, self._offset,
                                              self._active))
        return {
            "crack_elastic": el,
            "fracture": float(self._diss[:, K.CW_MODE_I].sum() + self._diss[:, K.CW_MODE_II].sum()),
            "crack_friction": float(self._diss[:, K.CW_FRICTION].sum()),
            "crack_released": float(self.released),
        }

    def stable_dt(self, mass: np.ndarray) -> float:
        """Critical time step of the crack penalties alone [s]: ``2 / omega_max`` with
        ``omega^2 <= K_a/m_a + K_b/m_b`` per node pair, ``K`` the summed end stiffness
        ``max(k_n, k_t, k_c) L0/2`` [N/m] on a node (``k_c``: the compression stiffness), ``m`` the node mass [kg/m]. Apply the time-step fraction
        in the solver (and take the minimum with the triangles' and contact's)."""
        mass = np.asarray(mass, dtype=np.float64)
        if mass.shape != (self.topology.n_nodes,):
            raise ValueError(f"mass must have shape ({self.topology.n_nodes},), got {mass.shape}")
        if self._active.size == 0:
            return math.inf
        return float(K.stable_dt_kernel(mass, self._nodes, self._const, self._active, self.topology.n_nodes))

    def nodal_stiffness(self, mass: np.ndarray | None = None) -> np.ndarray:
        """(n_nodes,) stiffness ``S`` [N/m] for which each node must carry mass: the crack springs
        alone are stable at a step ``dt`` when every node mass ``m >= S dt^2 / 4``.

        An end spring of stiffness ``k = max(k_n, k_t, k_c) L0/2`` between nodes ``a`` and ``b``
        has ``omega^2 = k (1/m_a + 1/m_b)``; giving each node a mass share ``2 k dt^2/4`` makes it
        ``(2/dt)^2``. Summing the shares of all springs on a node gives ``S = 2 sum k``, and by
        Irons' element eigenvalue theorem (the global ``omega_max`` is at most the largest
        element ``omega`` when the element masses add up to the nodal ones) the whole set is
        stable (Irons 1970; Belytschko et al. 2014, sec. 6.3). Density scaling
        (:mod:`fdem.solve.density_scaling`) adds it to the triangles' and contact's shares; ``mass``
        is not needed (the providers' common signature)."""
        if self._active.size == 0:
            return np.zeros(self.topology.n_nodes)
        return 2.0 * K.node_spring_stiffness(self._nodes, self._const, self._active, self.topology.n_nodes)

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self) -> dict:
        """Every piece of mutable state, copied: restored by :meth:`load_state_dict` into a crack
        set built the same way (same topology, property sets, heterogeneity, scheme), the
        elements continue bit for bit (:mod:`fdem.checkpoint`). Arrays are in internal
        (colour-major) order, saved with it as ``order`` (the topology id of each row), so that
        a crack set whose internal order differs still reads them right; ``events`` is the
        structured :data:`EVENT_DTYPE` array."""
        d = {
            "kind": type(self).__name__, "n_cracks": self.n_cracks, "scheme": self.scheme,
            "order": self._perm.copy(),
            "const": self._const.copy(), "status": self._status.copy(), "state": self._state.copy(),
            "diss": self._diss.copy(), "offset": self._offset.copy(), "dilation": self._dil.copy(),
            "broken": self.broken.copy(),
            "failure_mode": self.failure_mode.copy(), "broke_flag": self._broke_flag.copy(),
            "released": float(self.released), "newly_broken": self.newly_broken.copy(),
            "events": self.events.copy(), "time": float(self._time),
            "last_step": None if self._last_step is None else int(self._last_step),
            "elastic_only": bool(self._elastic_only), "active": self._active.copy(),
            "reduction": float(self.interfaces.reduction),
            "strength_multiplier": self.strength_multiplier.copy(),
            "x_last": None if self._x_last is None else np.array(self._x_last, dtype=np.float64),
            "carry_broken": self._carry_broken.copy(),
        }
        if self.scheme == "gather":
            d["fe"] = self._fe.copy()
        return d

    def load_state_dict(self, d: dict, x: np.ndarray | None = None) -> None:
        """Restore :meth:`state_dict` output. ``x`` (n_nodes, 2): the simulation's current
        position array, which later strength changes project at (default: a copy of the
        positions saved with the state). The reduction factor is set on the interfaces
        directly and the constant rows are restored exactly as saved (nothing is re-filled)."""
        if d.get("kind", type(self).__name__) != type(self).__name__ or int(d["n_cracks"]) != self.n_cracks:
            raise ValueError(f"crack state of a {d.get('kind')} with {d['n_cracks']} elements does not fit this "
                             f"{type(self).__name__} with {self.n_cracks} elements")
        if d["scheme"] != self.scheme:
            raise ValueError(f"crack state saved with scheme {d['scheme']!r}, this crack set uses {self.scheme!r}")
        internal, move = self._saved_rows(d)
        for name in ("const", "status", "diss", "offset", "broke_flag"):
            getattr(self, "_" + name)[:] = internal(d[name])
        state = internal(d["state"])
        if state.shape[1] == K.N_STATE_V1:  # saved before joint dilation: no sigma_prev, no d
            self._state[:] = 0.0
            self._state[:, :K.N_STATE_V1] = state
            self._state[:, K.CS_SIG0:K.CS_SIG1 + 1] = K.UNKNOWN_TRACTION
        else:
            self._state[:] = state
        if "dilation" in d:
            self._dil[:] = internal(d["dilation"])
        else:
            self._dil[:] = self._dilation_constants(self.props[self.tag, CP_TANPHI] / float(d["reduction"]))[self._perm]
        self.broken[:] = d["broken"]
        self.failure_mode[:] = d["failure_mode"]
        self.strength_multiplier = np.array(d["strength_multiplier"], dtype=np.float64)
        self.released = float(d["released"])
        self.newly_broken = np.array(d["newly_broken"], dtype=np.int64)
        ev = np.asarray(d["events"], dtype=EVENT_DTYPE)
        self._events = [tuple(r.item()) for r in ev]
        self._events_arr = None
        self._time = float(d["time"])
        self._last_step = None if d["last_step"] is None else int(d["last_step"])
        self._elastic_only = bool(d["elastic_only"])
        self.interfaces.restore_reduction(float(d["reduction"]))
        if self.scheme == "gather":
            self._fe[:] = internal(d["fe"])
        if x is not None:
            self._x_last = x
        else:
            self._x_last = None if d["x_last"] is None else np.array(d["x_last"], dtype=np.float64)
        self._carry_broken = np.array(d.get("carry_broken", np.zeros(0)), dtype=np.int64)
        active = np.array(d["active"], dtype=np.int64)
        self._set_active(active if move is None else np.sort(move[active]))

    def _saved_rows(self, d: dict):
        """``(internal, move)`` for a saved state: ``move[i]`` is this set's internal row of the
        saved row ``i`` (None when the orders agree) and ``internal(a)`` puts a saved per-row
        array in this set's order. States saved without ``order`` were written in the order
        of :func:`_legacy_colour_major_order` (colour scheme) or topology order (gather)."""
        n = self.n_cracks
        if "order" in d:
            saved = np.asarray(d["order"], dtype=np.int64)
        elif self.scheme == "colour":
            colour = np.empty(n, dtype=np.int32)
            colour[self._perm] = self._colour
            saved = _legacy_colour_major_order(colour)
        else:
            saved = np.arange(n, dtype=np.int64)
        if saved.shape != (n,) or not np.array_equal(np.sort(saved), np.arange(n)):
            raise ValueError(f"crack state's element order is not a permutation of this set's {n} elements")
        if np.array_equal(saved, self._perm):
            return np.asarray, None
        move = self._inv[saved]

        def internal(a):
            a = np.asarray(a)
            out = np.empty_like(a)
            out[move] = a
            return out

        return internal, move
