"""Contact between free triangle faces: broad phase, pair bookkeeping, the ``ContactSet`` force provider.

Which triangles take part
-------------------------
Only *contactors* can touch anything: triangles with an external edge (``boundary_triangle``)
and triangles on either side of a broken crack element (added by :meth:`ContactSet.activate_cracks`).
Two triangles still joined by an intact crack element never form a pair (the crack element
carries their interaction); once it breaks they do.

Broad phase
-----------
Boxes of the contactors, grown by half the skin, are binned into a uniform grid by a counting
sort (O(n)); each pair is reported once (from the cell holding the lower-left corner of the
two boxes' intersection), so the result equals the brute-force all-pairs search for any cell
size (:func:`fdem.kernels.contact.brute_force_pairs` is kept as the reference). Box pairs
that an edge normal of either triangle separates by more than the skin are dropped: they
cannot touch before the next re-search (:func:`fdem.kernels.contact._far_apart`). The search is
re-run only when some contactor node has moved more than half the skin since the last one:
until then no pair missing from the list can have come into touch.

Narrow phase and friction
-------------------------
Distributed-potential penalty (Munjiza & Andrews 2000; Munjiza 2004 ch. 3): see
:mod:`fdem.kernels.contact`. Friction is a tangential penalty per pair, capped by Coulomb
``mu |F_n|`` (incremental, return mapping), acting at the centroid of the overlap on both
triangles (equal and opposite, at the same point: no spurious torque). Its stiffness is constant
per pair, ``k_t = tangential_ratio * 6 p L / h`` of the smaller of the two triangles (see
:class:`ContactSet`). The tangential force (the slip history)
is kept per pair across steps and across re-searches (keyed by the triangle pair) and dropped
when the pair separates. Optional normal viscous damping ``c_n = 2 xi sqrt(k m_eff)`` with the
pair's current secant stiffness ``k = F_n^2 / (2 E_pair)`` and ``m_eff`` the reduced mass of the
two triangles (never attractive beyond the elastic push).

Use
---
::

    topo = build_topology(mesh)
    contact = ContactSet(topo, penalty=50 * E, friction_angle=35.0, mass=nodal_mass,
                         damping_ratio=0.0)
    # the solver combines the limits as 1 / sqrt(sum 1/dt_i^2), times its time-step fraction
    dt = dt_fraction * (dt_elements**-2 + dt_cracks**-2 + contact.stable_dt(nodal_mass)**-2) ** -0.5
    # each step (forces ON nodes, added into f):
    contact.add_forces(x, v, f, dt, step)
    # when crack elements break:
    contact.activate_cracks(broken_ids, friction_angle=joint_phi_of_those_cracks)
    ledger.update(contact.energy_terms())

Softening crack elements
------------------------
An element that has started to soften or slide (the crack set's status flags) still ties its
two triangles, but no longer keeps the *vertex neighbours* around its two mesh vertices (the
triangles of the fan around a vertex that share no edge) from passing into each other: only
contact resists that. Two ways to hand them to contact (``softening=``):

* ``"vertex"`` (default): a mesh vertex becomes *loose* once an inelastic (or broken) crack
  element ending there has opened or slid, at either end, by more than ``loose_fraction``
  (default :data:`LOOSE_FRACTION`) of the smaller altitude of its two triangles; the
  candidate pairs it adds are the vertex-neighbour pairs of the fan around it (topology, no
  search). Loose vertices stay loose. While nothing has broken and the mesh is one body,
  these fan pairs are the whole pair list: no broad phase runs and nothing is re-searched
  when nodes move (the list does not depend on positions). Once an element breaks (or with
  several bodies) the fan triangles join the contactors of the binned-grid search.
  Below the threshold a fan's vertex neighbours overlap only at their shared corner, by the
  elastic compression of the crack elements around it, as they do while every element is
  elastic (when contact is dormant); ``tests/test_contact_skip.py`` checks the pairs and the
  forces against ``"all"``.
* ``"all"``: every triangle of every inelastic element becomes a contactor at once and is
  searched against every other contactor (boundary triangles included).

Friction belongs to the faces in touch
--------------------------------------
Every triangle face has a base friction (``face_friction``, (n_triangles, 3), face ``k`` from
corner ``k`` to ``k + 1``): the faces a triangle is built with (external faces, and internal
ones while their crack element holds) have ``friction_angle`` or what :meth:`ContactSet.set_friction`
gave them (``face_mu``, a parameter of the model); the two faces of a
broken crack element take that element's residual friction (its joint set's ``phi_res``, from
:class:`fdem.interfaces.Interfaces`), never raising a face broken earlier. A pair of triangles
across a broken crack element uses that element's residual friction; any other pair uses
``min(mu_i, mu_j)`` of the two faces in touch, picked every step by the contact normal
(:func:`fdem.kernels.contact_pairs.pair_friction`): a block with a smooth joint face (phi = 11
deg) and a face broken through rock slides on the floor with the friction of the face it lies
on, not with the lowest of its three. All of these are base values: the pair friction is
``mu_base / F`` with the current strength-reduction factor ``F`` (the crack set's
:class:`~fdem.interfaces.Interfaces`, or ``ContactSet.interfaces.set_reduction`` without crack
elements), whatever broke when.
"""
from __future__ import annotations

from typing import Callable, Iterable
import numpy as np
from fdem.physics.interfaces import Interfaces
from fdem.kernels import contact_pairs as kc
from fdem.kernels import contact_search as ks
from fdem.mesh.topology import Topology
from fdem.mesh.triangles import triangle_areas

__all__ = ["CONTACT_LAW", "pair_energy_force", "grid_cell_size", "candidate_pairs", "brute_force_candidate_pairs", "INELASTIC_CHECK_EVERY",
           "LOOSE_FRACTION", "SOFTENING_MODES", "ContactSet"]


CONTACT_LAW = "penalty overlap, Coulomb friction of the faces in touch"
"""What a checkpoint records of the contact law (:func:`fdem.solve.checkpoint.model_fingerprint`):
runs are carried on under the law they began with. Before 2026-11-25 a pair's friction was the
lowest of all six faces of its two triangles; checkpoints of then carry no law and are refused."""


# ----------------------------------------------------------------------------- small helpers
def pair_energy_force(xc: np.ndarray, xt: np.ndarray, penalty: float) -> tuple[float, np.ndarray, np.ndarray, float]:
    """Energy and nodal forces of one triangle pair (the per-pair law, for tests and tools).

    ``xc``, ``xt``: (3, 2) corners of the two triangles, counter-clockwise [m]; ``penalty`` [Pa].
    Returns ``(E [J/m], f_c (3, 2), f_t (3, 2) [N/m], overlap area [m^2])``.
    """
    x = np.ascontiguousarray(np.vstack([np.asarray(xc, dtype=np.float64), np.asarray(xt, dtype=np.float64)]))
    w = np.zeros(kc.N_WORK)
    res = kc.pair_normal(x, 0, 1, float(penalty), w, np.empty(kc.N_IWORK, np.int64),
                         np.empty((kc.MAX_VERT, kc.N_COL)))
    e, area = float(res[0]), float(res[1])
    if not area > 0.0:
        return 0.0, np.zeros((3, 2)), np.zeros((3, 2)), 0.0
    return e, w[0:6].reshape(3, 2).copy(), w[6:12].reshape(3, 2).copy(), area


def _bond_table(topology: Topology, intact: np.ndarray) -> np.ndarray:
    """(n_tri, 3) triangle bonded to each triangle across its edge k by an intact crack, else -1."""
    bond = np.full((topology.n_triangles, 3), -1, dtype=np.int64)
    cn = topology.crack_nodes[intact]
    ct = topology.crack_triangles[intact]
    # crack_nodes = [A_p, A_q, B_q, B_p]: A_p = 3A + k is the start of A's edge k, B_q of B's.
    bond[ct[:, 0], cn[:, 0] % 3] = ct[:, 1]
    bond[ct[:, 1], cn[:, 2] % 3] = ct[:, 0]
    return bond


def grid_cell_size(box: np.ndarray) -> float:
    """The broad phase's cell side [m] for boxes ``box`` (n, 4): the 90th percentile of their
    extents, about one box per cell for most boxes (the few large ones register in several)."""
    if len(box) == 0:
        return 1.0
    ext = np.maximum(box[:, 2] - box[:, 0], box[:, 3] - box[:, 1])
    return max(float(np.percentile(ext, 90)), 1e-12)


def candidate_pairs(x: np.ndarray, active: np.ndarray, bond: np.ndarray, skin: float,
                    cell_size: float | None = None, max_cells_per_box: float = 4.0) -> np.ndarray:
    """(n_pairs, 2) candidate pairs ``i < j`` by the binned grid, sorted (see module docstring)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    active = np.ascontiguousarray(np.sort(np.asarray(active, dtype=np.int64)))
    box = ks.triangle_boxes(x, active, 0.5 * skin)
    if cell_size is None:
        cell_size = grid_cell_size(box)
    max_cells = max(1024.0, max_cells_per_box * len(active))
    pi, pj = ks.grid_pairs(box, active, bond, x, float(skin), float(cell_size), max_cells)
    return np.column_stack([pi, pj])


def brute_force_candidate_pairs(x: np.ndarray, active: np.ndarray, bond: np.ndarray, skin: float) -> np.ndarray:
    """Reference all-pairs search (O(n^2)) with the same criterion as :func:`candidate_pairs`."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    active = np.ascontiguousarray(np.sort(np.asarray(active, dtype=np.int64)))
    box = ks.triangle_boxes(x, active, 0.5 * skin)
    pi, pj = ks.brute_force_pairs(box, active, bond, x, float(skin))
    return np.column_stack([pi, pj])


def _check_penalty(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"contact {name} must be a positive finite number [Pa], got {value:g}")
    return value


def _friction_to_mu(friction_angle, n: int, what: str) -> np.ndarray:
    phi = np.asarray(friction_angle, dtype=np.float64)
    if phi.ndim == 0:
        phi = np.full(n, float(phi))
    if phi.shape != (n,):
        raise ValueError(f"friction_angle must be a scalar or have one value per {what} ({n}), got shape {phi.shape}")
    bad = np.flatnonzero(~np.isfinite(phi) | (phi < 0.0) | (phi >= 90.0))
    if bad.size:
        raise ValueError(
            f"friction angle must lie in [0, 90) degrees; {bad.size} {what}(s) out of range, "
            f"first: {what} {int(bad[0])} has {float(phi[bad[0]]):g} deg")
    return np.tan(np.radians(phi))


def _mu_from(friction_angle, mu, n: int, what: str) -> np.ndarray | None:
    """Friction coefficients from angles [deg] or from ``mu`` directly (exactly one, or none)."""
    if friction_angle is not None and mu is not None:
        raise ValueError("give friction_angle or mu, not both")
    if friction_angle is not None:
        return _friction_to_mu(friction_angle, n, what)
    if mu is None:
        return None
    m = np.asarray(mu, dtype=np.float64)
    if m.ndim == 0:
        m = np.full(n, float(m))
    if m.shape != (n,):
        raise ValueError(f"mu must be a scalar or have one value per {what} ({n}), got shape {m.shape}")
    bad = np.flatnonzero(~np.isfinite(m) | (m < 0.0))
    if bad.size:
        raise ValueError(f"friction coefficient mu = tan(phi) must be finite and >= 0; {what} {int(bad[0])} "
                         f"has {float(m[bad[0]]):g}")
    return m.copy()


# ----------------------------------------------------------------------------- the force provider
INELASTIC_CHECK_EVERY = 16
"""Steps between looks at which crack elements have started to soften or slide (a count of
the crack set's status flags; a few steps of delay let no overlap grow that matters)."""


LOOSE_FRACTION = 1e-3
"""Default relative motion at which a softening crack element loosens its two mesh vertices:
an end of the element has opened or slid by more than this fraction of the smaller altitude
of its two triangles (see "Softening crack elements" in the module docstring)."""


SOFTENING_MODES = ("vertex", "all")


class ContactSet:
    """Triangle-triangle contact of an exploded mesh, called by the solver every step.

    Parameters
    ----------
    topology : Topology
        Exploded mesh (:func:`fdem.topology.build_topology`).
    penalty : float
        Normal penalty ``p`` [Pa] (``p = alpha E``, ``alpha`` about 10 to 100; verification.md).
    friction_angle : float or (n_tri,) array
        Friction angle ``phi`` [deg] in ``[0, 90)`` of the external faces, per triangle (see
        "Friction belongs to the interface" in the module docstring). 0 on every face that can
        touch switches friction off (the branch is skipped). Divided (as ``tan``) by the
        strength-reduction factor like every interface friction.
    tangential_ratio : float
        Tangential stiffness of a pair as a fraction of the normal stiffness of a face-to-face
        contact, ``k_t = tangential_ratio * 6 p L / h`` with ``L`` the longest edge and ``h``
        the altitude on it, the smaller of the pair's two triangles. It is constant while the
        pair exists, so the tangential spring's stored energy matches the work done on it and
        the ledger closes when the normal force varies under a loaded spring. The elastic
        pre-slip before sliding, ``mu F_n / k_t``, vanishes as the penalty grows. Default 1;
        values above 1 shorten :meth:`stable_dt`.
    damping_ratio : float
        Normal viscous damping ratio ``xi >= 0`` of a pair (``c_n = 2 xi sqrt(k m_eff)``, ``k`` the
        pair's current secant stiffness, ``m_eff`` the reduced mass of its two triangles); needs
        ``mass``. 0 (default) skips the branch.
    mass : (n_nodes,) array, optional
        Lumped nodal masses [kg/m]; required for damping.
    skin : float, optional
        Verlet buffer [m]: boxes grow by ``skin/2``; re-search when a node has moved ``skin/2``.
        Default: 0.3 times the mean edge length.
    cell_size : float, optional
        Grid cell [m]; default the 90th percentile of the grown boxes' sizes. Any value gives
        the same pairs (only the cost changes).
    x : (n_nodes, 2) array, optional
        Positions to check for overlap in the reference state (default ``topology.x0``).
    check_overlap : bool
        Raise ``ValueError`` if bodies overlap in the reference state (default True).
    cracks : CrackSet, optional
        The crack elements of the same topology. Elements it breaks (``cracks.newly_broken``)
        are handed to contact at the start of the next :meth:`add_forces`, with the residual
        friction of their joint set (``cracks.interfaces``), reduced by the same factor ``F``
        as the crack elements; register the crack set before the contact set.
    softening : {"vertex", "all"}
        How softening and sliding crack elements hand their triangles to contact (module
        docstring, "Softening crack elements"); default ``"vertex"``.
    loose_fraction : float
        Relative motion that loosens a softening element's vertices (``softening="vertex"``).

    The solver calls :meth:`add_forces`, :meth:`energy_terms` and :meth:`stable_dt`.
    """

    def __init__(self, topology: Topology, penalty: float, friction_angle=0.0, *,
                 tangential_ratio: float = 1.0, damping_ratio: float = 0.0,
                 mass: np.ndarray | None = None, skin: float | None = None,
                 cell_size: float | None = None, x: np.ndarray | None = None,
                 check_overlap: bool = True, cracks=None, softening: str = "vertex",
                 loose_fraction: float = LOOSE_FRACTION) -> None:
        self.topology = topology
        self.cracks = cracks
        if softening not in SOFTENING_MODES:
            raise ValueError(f"softening must be one of {SOFTENING_MODES}, got {softening!r}")
        self.softening = softening
        loose_fraction = float(loose_fraction)
        if not (np.isfinite(loose_fraction) and loose_fraction >= 0.0):
            raise ValueError(f"loose_fraction must be >= 0 and finite, got {loose_fraction!r}")
        self.loose_fraction = loose_fraction
        n_tri = topology.n_triangles
        self.penalty = _check_penalty("penalty", penalty)
        tangential_ratio = float(tangential_ratio)
        if not np.isfinite(tangential_ratio) or tangential_ratio <= 0.0:
            raise ValueError(f"tangential_ratio must be positive and finite, got {tangential_ratio!r}")
        self.tangential_ratio = tangential_ratio
        # each triangle's face friction as built or set (a parameter: checkpoints fingerprint it);
        # face_friction, one value per face, is what breakage lowers (derived: face_mu and the
        # broken elements' residual friction, _rebuild_face_friction)
        self.face_mu = np.repeat(_friction_to_mu(friction_angle, n_tri, "triangle")[:, None], 3, axis=1)
        self.face_friction = self.face_mu.copy()
        self.face_version = 0  # counts changes of face_friction (a device copy follows it)
        # the one home of the strength-reduction factor F: the crack elements' when there are any
        self.interfaces = cracks.interfaces if cracks is not None else Interfaces({})
        # broken crack element between two triangles: sorted keys i * n_tri + j (i < j)
        ct = np.sort(np.asarray(topology.crack_triangles, dtype=np.int64), axis=1)
        ckeys = ct[:, 0] * n_tri + ct[:, 1]
        self._crack_order = np.argsort(ckeys, kind="stable")
        self._crack_keys = ckeys[self._crack_order]
        self._crack_mu = np.zeros(topology.n_cracks)  # base residual friction of broken elements
        damping_ratio = float(damping_ratio)
        if not np.isfinite(damping_ratio) or damping_ratio < 0.0:
            raise ValueError(f"damping_ratio must be >= 0, got {damping_ratio!r}")
        self.damping_ratio = damping_ratio
        self.mass_tri = None
        if mass is not None:
            mass = np.asarray(mass, dtype=np.float64)
            if mass.shape != (topology.n_nodes,) or np.any(~(mass > 0.0)):
                raise ValueError(f"mass must be ({topology.n_nodes},) positive nodal masses, got shape {mass.shape}")
            self.mass_tri = mass.reshape(-1, 3).sum(axis=1)
        if damping_ratio > 0.0 and self.mass_tri is None:
            raise ValueError("contact damping_ratio > 0 needs the nodal masses: pass mass=...")

        x0 = topology.x0
        tri = topology.triangles
        edges = np.linalg.norm(x0[np.roll(tri, -1, axis=1)] - x0[tri], axis=2)  # (n_tri, 3)
        self._edge_max = edges.max(axis=1)
        self._altitude = 2.0 * np.abs(topology.triangle_area0) / self._edge_max
        # Face-to-face normal stiffness of each triangle, 6 p L / h (see stable_dt).
        self._kt_tri = tangential_ratio * 6.0 * self.penalty * self._edge_max / self._altitude
        self._loose_gap2 = None  # (n_cracks,) squared end motion that loosens an element's vertices
        self._kt_pair = np.zeros(0)
        if skin is None:
            skin = 0.3 * float(edges.mean()) if edges.size else 1.0
        skin = float(skin)
        if not np.isfinite(skin) or skin <= 0.0:
            raise ValueError(f"contact skin must be positive, got {skin!r}")
        self.skin = skin
        if cell_size is not None and not (np.isfinite(cell_size) and cell_size > 0.0):
            raise ValueError(f"contact cell_size must be positive, got {cell_size!r}")
        self.cell_size = cell_size

        self._broken = np.zeros(topology.n_cracks, dtype=bool)
        self._any_broken = False
        self._bond = _bond_table(topology, ~self._broken)
        self._is_contactor = np.zeros(n_tri, dtype=bool)
        self._is_contactor[topology.boundary_triangle] = True
        self._any_extra_contactor = False
        self._n_inelastic_seen = 0
        self._n_bodies = int(np.unique(topology.triangle_body).size)
        # loose mesh vertices (softening="vertex") and the fans around them
        mesh_node = np.asarray(topology.mesh_node, dtype=np.int64)
        self._n_vertex = int(mesh_node.max()) + 1 if mesh_node.size else 0
        self._loose = np.zeros(self._n_vertex, dtype=bool)
        self._any_loose = False
        self._fan = None            # (vertex ptr, triangles) CSR, built on first need
        self._watch = None          # inelastic elements whose vertices are not both loose yet
        self._refresh_active()

        # pair state
        self.pairs = np.zeros((0, 2), np.int64)
        self._keys = np.zeros(0, np.int64)
        self._history = np.zeros((0, kc.N_HIST))
        self._mu_base_pair = np.zeros(0)
        self._damp_pair = np.zeros(0)
        self._pair_i = np.zeros(0, np.int64)       # contiguous copies of the pair columns
        self._pair_j = np.zeros(0, np.int64)
        self._bounds = np.zeros(2, np.int64)        # chunks of the pair loop
        self._f_target = np.zeros((0, 6))           # target-side forces, stored per pair
        self._touching = np.zeros(0, np.uint8)
        self._witness = np.zeros(0, np.uint8)       # separating axis of each pair (a cache)
        self._inc_ptr = np.zeros(1, np.int64)       # pairs by target triangle
        self._inc_pair = np.zeros(0, np.int64)
        self._x_search = None
        self._needs_search = True
        self.n_searches = 0
        # the GPU's copy of the pair arrays while a simulation runs on one
        # (fdem.solve.cuda_backend); None on the CPU
        self.device = None

        # energy ledger [J/m]
        self._e_normal = 0.0
        self._e_tangential = 0.0
        self._w_tangential = 0.0  # work done on the bodies by the tangential contact forces
        self._w_damping = 0.0

        if check_overlap:
            self.check_reference_overlap(topology.x0 if x is None else np.asarray(x, dtype=np.float64))
        if cracks is not None:
            if cracks.topology is not topology:
                raise ValueError("contact and crack elements must share one topology")
            already = np.flatnonzero(cracks.broken)
            if already.size:
                self.activate_cracks(already)
            self._watch_inelastic()

    # ------------------------------------------------------------------ state
    @property
    def active(self) -> np.ndarray:
        """(n_act,) sorted ids of the contactor triangles."""
        return self._active

    @property
    def n_pairs(self) -> int:
        """Candidate pairs in the current list."""
        return len(self.pairs)

    @property
    def n_touching(self) -> int:
        """Pairs that overlapped at the last :meth:`add_forces`."""
        return int(self._touching.sum())

    @property
    def dormant(self) -> bool:
        """True while there is nothing that can touch: one body, no broken crack element, no
        contactor beyond the external boundary and no loose vertex."""
        return (self._n_bodies <= 1 and not self._any_broken and not self._any_extra_contactor
                and not self._any_loose)

    @property
    def full_search(self) -> bool:
        """True when the pairs come from the binned-grid search (several bodies, a broken
        element, or contactors added); False while only fans of loose vertices can touch."""
        return self._n_bodies > 1 or self._any_broken or self._any_extra_contactor

    @property
    def loose_vertices(self) -> np.ndarray:
        """Sorted mesh-vertex ids loosened by softening crack elements (``softening="vertex"``)."""
        return np.flatnonzero(self._loose)

    def _fan_csr(self) -> tuple[np.ndarray, np.ndarray]:
        """Triangles around each mesh vertex: ``tri[ptr[v]:ptr[v+1]]`` (sorted)."""
        if self._fan is None:
            mesh_node = np.asarray(self.topology.mesh_node, dtype=np.int64)
            order = np.lexsort((np.arange(mesh_node.size) // 3, mesh_node))
            ptr = np.zeros(self._n_vertex + 1, np.int64)
            np.add.at(ptr, mesh_node + 1, 1)
            self._fan = (np.cumsum(ptr), (order // 3).astype(np.int64))
        return self._fan

    def fan_pairs(self) -> np.ndarray:
        """(n, 2) sorted vertex-neighbour pairs ``i < j`` around the loose vertices that no intact
        crack element bonds: the candidates while nothing has broken (module docstring)."""
        if not self._any_loose:
            return np.zeros((0, 2), np.int64)
        ptr, tri = self._fan_csr()
        pi, pj = ks.fan_pairs(ptr, tri, np.flatnonzero(self._loose).astype(np.int64), self._bond)
        n_tri = self.topology.n_triangles
        keys = np.unique(pi * n_tri + pj)
        return np.column_stack([keys // n_tri, keys % n_tri])

    def _refresh_active(self) -> None:
        member = self._is_contactor
        if self._any_loose:
            member = member | self._loose[self.topology.mesh_node].reshape(-1, 3).any(axis=1)
        self._active = np.flatnonzero(member).astype(np.int64)
        self._slot = np.full(self.topology.n_triangles, -1, dtype=np.int64)
        self._slot[self._active] = np.arange(self._active.size)

    def activate_cracks(self, crack_ids: Iterable[int], friction_angle=None, mu=None) -> None:
        """Hand broken crack elements to contact.

        Triangles A and B of each crack become contactors, and their bond is dropped so that they
        can push each other (they could not while the crack element was intact). The base
        (unreduced) friction of the broken faces is ``friction_angle`` [deg] or ``mu = tan(phi)``
        when given (a scalar or one value per crack), else the residual friction of the crack's
        joint set from the crack set's interfaces, else the lower built friction of its two
        faces. The two faces of the element (one on each triangle) take the lower of what
        they had and this; the triangles' other faces keep theirs (see the module docstring).
        Triggers a re-search on the next :meth:`add_forces`.
        """
        ids = np.atleast_1d(np.asarray(crack_ids, dtype=np.int64))
        if ids.size == 0:
            return
        if ids.min() < 0 or ids.max() >= self.topology.n_cracks:
            raise ValueError(f"crack ids must lie in [0, {self.topology.n_cracks}), got {ids.min()}..{ids.max()}")
        tri = self.topology.crack_triangles[ids]
        cn = self.topology.crack_nodes[ids]
        coef = _mu_from(friction_angle, mu, ids.size, "crack")
        if coef is None:
            if self.cracks is not None:
                coef = self.cracks.interfaces.tan_phi_res_base[self.cracks.tag[ids]]
            else:
                coef = np.minimum(self.face_mu[tri[:, 0], cn[:, 0] % 3], self.face_mu[tri[:, 1], cn[:, 2] % 3])
        self._crack_mu[ids] = coef
        self._broken[ids] = True
        self._any_broken = True
        self._lower_broken_faces(tri, cn, coef)
        self._bond[tri[:, 0], cn[:, 0] % 3] = -1
        self._bond[tri[:, 1], cn[:, 2] % 3] = -1
        self._is_contactor[tri.ravel()] = True
        if self.softening == "vertex" and self.cracks is not None:
            # a broken element frees the fans around both its vertices
            self._loosen(self.topology.mesh_node[cn[:, :2]].ravel())
        self._refresh_active()
        self._needs_search = True

    def _loosen(self, vertices: np.ndarray) -> bool:
        """Mark mesh vertices loose; True if any was not yet."""
        vertices = np.asarray(vertices, dtype=np.int64)
        new = vertices[~self._loose[vertices]]
        if new.size == 0:
            return False
        self._loose[new] = True
        self._any_loose = True
        return True

    def add_contactors(self, triangles) -> None:
        """Let ``triangles`` touch anything they are not bonded to (their bonds are kept)."""
        tris = np.unique(np.asarray(triangles, dtype=np.int64))
        new = tris[~self._is_contactor[tris]]
        if new.size == 0:
            return
        self._is_contactor[new] = True
        self._any_extra_contactor = True
        self._refresh_active()
        self._needs_search = True

    def _watch_inelastic(self, x: np.ndarray | None = None) -> None:
        """Hand crack elements that have started to soften or slide to contact.

        A sliding or opening element lets the vertex neighbours of its two triangles, which no
        crack element ties, pass into each other; only contact resists that. Waiting until the
        element breaks would let the overlap grow unresisted (by the element's slip, up to
        centimetres) and then push it apart at once, creating energy. ``softening="all"``:
        every triangle of such an element becomes a contactor. ``"vertex"``: its two mesh
        vertices become loose once an end has moved ``loose_fraction`` of the altitude
        (module docstring), checked at positions ``x``.
        """
        n = self.cracks.n_inelastic()
        if self.softening == "all":
            if n != self._n_inelastic_seen:
                self._n_inelastic_seen = n
                self.add_contactors(self.topology.crack_triangles[self.cracks.inelastic()].ravel())
            return
        if n != self._n_inelastic_seen or self._watch is None:
            self._n_inelastic_seen = n
            ids = self.cracks.inelastic() if n else np.zeros(0, np.int64)
            ends = self.topology.mesh_node[self.topology.crack_nodes[ids, :2]]
            self._watch = ids[~(self._loose[ends[:, 0]] & self._loose[ends[:, 1]])]
        if self._watch.size == 0 or x is None:
            return
        ids = self._watch
        cn = self.topology.crack_nodes[ids]            # [A_p, A_q, B_q, B_p]
        gp = x[cn[:, 0]] - x[cn[:, 3]]
        gq = x[cn[:, 1]] - x[cn[:, 2]]
        gap2 = np.maximum((gp * gp).sum(axis=1), (gq * gq).sum(axis=1))
        if self._loose_gap2 is None:
            alt = self._altitude[self.topology.crack_triangles].min(axis=1)
            self._loose_gap2 = (self.loose_fraction * alt) ** 2
        moved = gap2 > self._loose_gap2[ids]
        if not moved.any():
            return
        ends = self.topology.mesh_node[cn[moved, :2]]
        self._watch = ids[~moved]
        if self._loosen(ends.ravel()):
            self._refresh_active()
            self._needs_search = True

    def set_friction(self, friction_angle=None, mu=None, triangles: np.ndarray | None = None,
                     faces: np.ndarray | None = None) -> None:
        """Set the base friction of the faces of ``triangles`` (default all), as
        ``friction_angle`` [deg] or ``mu = tan(phi)``, scalar or one per triangle (new joint or
        surface properties; a strength reduction goes through ``interfaces.set_reduction``
        instead): all three faces of each, or with ``faces`` only face ``faces[k]`` (0, 1, 2:
        the face from corner ``f`` to corner ``f + 1``) of ``triangles[k]``, e.g. the top of a
        floor. A face of a broken crack element has the lower of this and its element's residual
        friction. The pairs use it from the next step, their slip history is kept."""
        tris = np.arange(self.topology.n_triangles) if triangles is None else np.asarray(triangles, np.int64)
        if tris.ndim != 1 or (tris.size and (tris.min() < 0 or tris.max() >= self.topology.n_triangles)):
            raise ValueError(f"triangles must be ids in [0, {self.topology.n_triangles}), got {tris}")
        coef = _mu_from(friction_angle, mu, tris.size, "triangle")
        if coef is None:
            raise ValueError("set_friction needs friction_angle or mu")
        if faces is None:
            self.face_mu[tris] = coef[:, None]
        else:
            k = np.asarray(faces, np.int64)
            if k.shape != tris.shape or (k.size and (k.min() < 0 or k.max() > 2)):
                raise ValueError(f"faces must give one face (0, 1 or 2) per triangle ({tris.size}), got {faces}")
            self.face_mu[tris, k] = coef
        self._rebuild_face_friction()

    @property
    def reduction(self) -> float:
        """The strength-reduction factor ``F`` dividing every friction coefficient; it is set
        through ``interfaces.set_reduction(F)`` (shared with the crack elements)."""
        return self.interfaces.reduction

    def _pair_constants(self, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(mu_base, kt_pair, damp_pair)`` of ``pairs`` (:func:`fdem.kernels.contact_pairs.pair_constants_one`,
        the law the GPU search uses too)."""
        pi = np.ascontiguousarray(pairs[:, 0], dtype=np.int64)
        pj = np.ascontiguousarray(pairs[:, 1], dtype=np.int64)
        mass = self.mass_tri if self.mass_tri is not None else np.zeros(0)
        return kc.pair_constants(pi, pj, self.topology.n_triangles, self._crack_keys, self._crack_order,
                                 self._broken, self._crack_mu, self._any_broken, self._kt_tri, mass,
                                 self.damping_ratio)

    def _lower_broken_faces(self, tri: np.ndarray, cn: np.ndarray, coef: np.ndarray) -> None:
        """Faces of broken elements (triangles ``tri`` (k, 2), their crack nodes ``cn`` (k, 4))
        take the lower of their friction and ``coef`` (k,): ``A``'s face starts at node
        ``cn[:, 0]``, ``B``'s at ``cn[:, 2]``."""
        flat = self.face_friction.reshape(-1)
        np.minimum.at(flat, 3 * tri[:, 0] + cn[:, 0] % 3, coef)
        np.minimum.at(flat, 3 * tri[:, 1] + cn[:, 2] % 3, coef)
        self.face_version += 1

    def _rebuild_face_friction(self) -> None:
        """``face_friction`` from its sources: ``face_mu`` on every face, lowered on the faces of
        the broken elements to their residual friction."""
        self.face_friction[:] = self.face_mu
        ids = np.flatnonzero(self._broken)
        if ids.size:
            self._lower_broken_faces(self.topology.crack_triangles[ids], self.topology.crack_nodes[ids],
                                     self._crack_mu[ids])
        self.face_version += 1

    # ------------------------------------------------------------------ search
    def search(self, x: np.ndarray) -> None:
        """Re-run the broad phase at positions ``x`` (while only fans of loose vertices can
        touch, take their pairs instead); carry the friction history of surviving pairs."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        if self.full_search:
            pairs = candidate_pairs(x, self._active, self._bond, self.skin, self.cell_size)
        else:
            pairs = self.fan_pairs()
        n_tri = self.topology.n_triangles
        keys = pairs[:, 0] * n_tri + pairs[:, 1]
        history = np.empty((len(pairs), kc.N_HIST))
        # touching = 1 where a carried pair has history (the pair loop zeroes it if the pair has
        # separated; it reads no history of pairs that stay apart)
        touching = np.empty(len(pairs), np.uint8)
        kc.carry_history(self._keys, self._history, keys, history, touching)
        self.pairs, self._keys, self._history = pairs, keys, history
        self._mu_base_pair, self._kt_pair, self._damp_pair = self._pair_constants(pairs)
        self._pair_i = np.ascontiguousarray(pairs[:, 0])
        self._pair_j = np.ascontiguousarray(pairs[:, 1])
        self._bounds = kc.chunk_bounds(self._pair_i, min(1024, max(1, len(pairs) // 128)))
        self._f_target = np.zeros((len(pairs), 6))
        self._touching = touching
        self._witness = np.zeros(len(pairs), np.uint8)
        self._inc_ptr, self._inc_pair = kc.target_incidence(self._pair_j, self._slot, self._active.size)
        self._x_search = x.copy()
        self._needs_search = False
        self.n_searches += 1

    def search_due(self, moved: Callable[[], float]) -> bool:
        """Whether the pair list must be searched again: asked for (new contactors, loose
        vertices), never searched, or ``moved()`` (the largest displacement of an active node
        since the last search [m], asked for only when needed) above half the skin. Fan pairs do
        not depend on positions: they are never re-searched for motion."""
        if self._needs_search or self._x_search is None:
            return True
        return self.full_search and moved() > 0.5 * self.skin

    def _maybe_search(self, x: np.ndarray) -> None:
        if self.search_due(lambda: ks.max_displacement(x, self._x_search, self._active)):
            self.search(x)

    # ------------------------------------------------------------------ the solver's interface
    def add_forces(self, x: np.ndarray, v: np.ndarray, f: np.ndarray, dt: float, step: int) -> None:
        """Add contact forces on the nodes into ``f`` (n_nodes, 2) [N/m].

        ``x`` positions [m] and ``v`` velocities [m/s] of the exploded nodes (the velocity used
        for slip and damping increments ``v dt``), ``dt`` [s], ``step`` the step number (unused
        by the physics; kept for the interface). Updates the energy ledger.
        """
        if self.cracks is not None:
            # Faces of crack elements broken by this step's crack pass become contact faces.
            ids = self.cracks.newly_broken
            if ids.size:
                self.activate_cracks(ids)
            if step % INELASTIC_CHECK_EVERY == 0:
                self._watch_inelastic(x)
        if self.dormant:
            return
        if self.device is not None:  # the same pair law on the GPU (fdem.solve.cuda_backend)
            if self.search_due(self.device.contact_moved):
                if self.full_search:  # the grid search, on the device
                    self.device.contact_search(self)
                else:  # fan pairs: on the host, with the pairs' history carried
                    self.device.pull_contact(self)
                    self.search(self.device.host_x())
            if self.device.n_pairs(self) == 0:  # the device's list: a search there leaves the host's behind
                self.book_pair_sums(0.0, 0.0, 0.0, 0.0)
            else:
                self.device.contact_forces(self, float(dt))  # books its sums when the step's come back
            return
        if v is None:  # no velocities: no slip or damping increments this step
            v = np.zeros_like(x)
        self._maybe_search(x)
        if len(self.pairs) == 0:
            self.book_pair_sums(0.0, 0.0, 0.0, 0.0)
            return
        self.book_pair_sums(*kc.pair_forces(x, v, self._pair_i, self._pair_j, self._bounds, self.penalty,
                                            self._mu_base_pair, self.face_friction, 1.0 / self.reduction,
                                            self._kt_pair, self._damp_pair, float(dt),
                                            self._history, self._f_target, self._touching, self._witness, f))
        kc.gather_forces(f, self._active, self._inc_ptr, self._inc_pair, self._f_target, self._touching)

    def book_pair_sums(self, e_normal: float, e_tangential: float, w_friction: float, w_damping: float) -> None:
        """Book one step's pair sums (:func:`fdem.kernels.contact_pairs.pair_forces`): the normal
        and tangential energies now, the friction and damping work of the step [J/m]."""
        self._e_normal = e_normal
        self._e_tangential = e_tangential
        self._w_tangential += w_friction
        self._w_damping += w_damping

    def pair_forces(self) -> dict[str, np.ndarray]:
        """Forces of the touching pairs at the last :meth:`add_forces`, for output (force chains).

        ``pairs`` (k, 2) triangle ids ``(i, j)``; ``force`` (k, 2) total force on ``i`` [N/m]
        (``j`` gets minus it: the pair law is equal and opposite); ``normal`` (k,) and ``shear``
        (k,) its magnitudes [N/m]: the shear part is the pair's tangential (friction) spring
        force, kept with the pair's history, the normal part the rest (penalty push plus normal
        damping). The force on ``i`` is minus the sum of the stored forces on ``j``'s corners.
        Empty arrays when nothing touches (no work then)."""
        touching = np.flatnonzero(self._touching) if len(self.pairs) else np.zeros(0, np.int64)
        if touching.size == 0:
            z = np.zeros(0)
            return {"pairs": np.zeros((0, 2), np.int64), "force": np.zeros((0, 2)), "normal": z, "shear": z.copy()}
        ft = self._f_target[touching]
        force = -np.column_stack([ft[:, 0] + ft[:, 2] + ft[:, 4], ft[:, 1] + ft[:, 3] + ft[:, 5]])
        tangential = self._history[touching, 0:2]
        return {"pairs": self.pairs[touching].copy(), "force": force,
                "normal": np.linalg.norm(force - tangential, axis=1), "shear": np.linalg.norm(tangential, axis=1)}

    def energy_terms(self) -> dict[str, float]:
        """Energy ledger [J/m] after the last :meth:`add_forces`.

        ``contact_elastic``: stored normal penalty energy plus tangential spring energy (now);
        ``friction``: frictional work dissipated so far; ``contact_damping``: viscous work
        dissipated so far.
        """
        return {
            "contact_elastic": float(self._e_normal + self._e_tangential),
            "friction": float(-self._w_tangential - self._e_tangential),
            "contact_damping": float(self._w_damping),
        }

    def stable_dt(self, mass: np.ndarray) -> float:
        """Critical central-difference step of the contact springs [s]: ``2 / omega_max``.

        For a triangle with longest edge ``L``, altitude ``h`` on it and smallest nodal mass
        ``m``, a face-to-face contact against an equal triangle has normal stiffness
        ``k_n = 3 p L (2 / h)``, shared by two nodes on each side; the relative mode gives
        ``omega^2 = k_n / m = 6 p L / (h m)``. The tangential spring (``tangential_ratio * k_n``
        acting at the overlap centroid, half on each of those nodes) gives
        ``tangential_ratio`` times that, so ``omega^2 = 6 p L / (h m) * max(1, tangential_ratio)``.
        For a regular mesh (``m = rho L h / 6``) this is ``dt = (h / 3) sqrt(rho / p)``: the
        ``h sqrt(rho/p)`` of verification.md with the constant worked out. Taken over every
        triangle (any may become a contactor), so it does not change as cracks break. The
        solver applies its own time-step fraction (dt_fraction).
        """
        mass = np.asarray(mass, dtype=np.float64)
        if mass.shape != (self.topology.n_nodes,):
            raise ValueError(f"mass must have shape ({self.topology.n_nodes},), got {mass.shape}")
        m = mass.reshape(-1, 3).min(axis=1)
        if np.any(~(m > 0.0)):
            t = int(np.flatnonzero(~(m > 0.0))[0])
            raise ValueError(f"triangle {t} has a non-positive nodal mass {m[t]!r}")
        omega2 = 6.0 * self.penalty * self._edge_max / self._altitude * max(1.0, self.tangential_ratio) / m
        return float(2.0 / np.sqrt(omega2.max()))

    def nodal_stiffness(self, mass: np.ndarray) -> np.ndarray:
        """(n_nodes,) stiffness ``S`` [N/m] for which each node must carry mass: contact alone is
        stable at a step ``dt`` when every node mass ``m >= S dt^2 / 4``.

        The per-triangle bound of :meth:`stable_dt`, ``omega^2 = 6 p L / (h m_min) max(1, r_t)``,
        written as the stiffness ``S = omega^2 m_min`` on each of the triangle's three nodes (at
        the lightest node it gives back :meth:`stable_dt`)."""
        mass = np.asarray(mass, dtype=np.float64)
        if mass.shape != (self.topology.n_nodes,):
            raise ValueError(f"mass must have shape ({self.topology.n_nodes},), got {mass.shape}")
        s = 6.0 * self.penalty * self._edge_max / self._altitude * max(1.0, self.tangential_ratio)
        return np.repeat(s, 3)

    # ------------------------------------------------------------------ checks
    def check_reference_overlap(self, x: np.ndarray, rel_tol: float = 1e-8) -> None:
        """Raise ``ValueError`` if any two contactor triangles overlap at positions ``x``
        (area above ``rel_tol`` times the smaller triangle), naming bodies, triangles and place."""
        if len(self._active) < 2:
            return
        pairs = candidate_pairs(x, self._active, self._bond, 0.0, self.cell_size)
        if len(pairs) == 0:
            return
        overlap = kc.overlap_areas(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(pairs[:, 0]),
                                   np.ascontiguousarray(pairs[:, 1]))
        area = np.abs(triangle_areas(x, self.topology.triangles))
        bad = np.flatnonzero(overlap > rel_tol * np.minimum(area[pairs[:, 0]], area[pairs[:, 1]]))
        if bad.size:
            i, j = (int(t) for t in pairs[bad[0]])
            a = overlap[bad[0]]
            body = self.topology.triangle_body
            xi = x[3 * i:3 * i + 3].mean(axis=0)
            xj = x[3 * j:3 * j + 3].mean(axis=0)
            raise ValueError(
                f"bodies {body[i]} and {body[j]} overlap in the reference state: triangle {i} "
                f"(body {body[i]}, centroid ({xi[0]:.6g}, {xi[1]:.6g})) and triangle {j} "
                f"(body {body[j]}, centroid ({xj[0]:.6g}, {xj[1]:.6g})) share {a:.3g} m^2; "
                f"move the bodies apart or mesh them as one ({bad.size} overlapping pair(s) in all)")

    # ------------------------------------------------------------------ checkpoint
    _PAIR_STATE = ("pairs", "_keys", "_history", "_mu_base_pair", "_kt_pair", "_damp_pair", "_pair_i",
                   "_pair_j", "_bounds", "_f_target", "_touching", "_inc_ptr", "_inc_pair")

    def state_dict(self) -> dict:
        """Every piece of mutable state, copied: restored by :meth:`load_state_dict` into a
        contact set built the same way (same topology and parameters), contact continues bit
        for bit (:mod:`fdem.checkpoint`): broken faces, bonds, contactors, face friction, the
        pair list with its slip history and everything derived from it, the search reference
        positions, the energy sums."""
        d = {
            "kind": type(self).__name__, "n_triangles": int(self.topology.n_triangles),
            "broken": self._broken.copy(), "any_broken": bool(self._any_broken), "bond": self._bond.copy(),
            "is_contactor": self._is_contactor.copy(), "any_extra_contactor": bool(self._any_extra_contactor),
            "n_inelastic_seen": int(self._n_inelastic_seen),
            "crack_mu": self._crack_mu.copy(), "reduction": float(self.interfaces.reduction),
            "x_search": None if self._x_search is None else self._x_search.copy(),
            "needs_search": bool(self._needs_search), "n_searches": int(self.n_searches),
            "e_normal": float(self._e_normal), "e_tangential": float(self._e_tangential),
            "w_tangential": float(self._w_tangential), "w_damping": float(self._w_damping),
            "loose": self._loose.copy(),
        }
        for name in self._PAIR_STATE:
            d["pair" + name if name[0] == "_" else name] = np.array(getattr(self, name), copy=True)
        return d

    def load_state_dict(self, d: dict, x=None) -> None:
        """Restore :meth:`state_dict` output (the active contactor list and slots are rebuilt)."""
        n_tri = self.topology.n_triangles
        if d.get("kind", type(self).__name__) != type(self).__name__ or int(d["n_triangles"]) != n_tri:
            raise ValueError(f"contact state of a {d.get('kind')} with {d['n_triangles']} triangles does not fit this "
                             f"{type(self).__name__} with {n_tri} triangles")
        self._broken[:] = d["broken"]
        self._any_broken = bool(d["any_broken"])
        self._bond[:] = d["bond"]
        self._is_contactor[:] = d["is_contactor"]
        self._any_extra_contactor = bool(d["any_extra_contactor"])
        self._n_inelastic_seen = int(d["n_inelastic_seen"])
        self._crack_mu[:] = d["crack_mu"]
        self._rebuild_face_friction()  # from face_mu (built here) and the broken elements restored
        if self.cracks is None:  # else the crack set restores the factor they share
            self.interfaces.restore_reduction(float(d["reduction"]))
        for name in self._PAIR_STATE:
            setattr(self, name, np.array(d["pair" + name if name[0] == "_" else name], copy=True))
        self._witness = np.zeros(len(self.pairs), np.uint8)   # a cache: zeros are valid
        self._x_search = None if d["x_search"] is None else np.array(d["x_search"], dtype=np.float64)
        self._needs_search = bool(d["needs_search"])
        self.n_searches = int(d["n_searches"])
        self._e_normal = float(d["e_normal"])
        self._e_tangential = float(d["e_tangential"])
        self._w_tangential = float(d["w_tangential"])
        self._w_damping = float(d["w_damping"])
        self._loose[:] = d.get("loose", False)
        self._any_loose = bool(self._loose.any())
        self._watch = None   # rebuilt from the crack set's flags at the next look
        self._refresh_active()
