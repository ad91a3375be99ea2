"""A geostatic start in static equilibrium: a static solve, crack preloads, and the unbalanced-force ratio.

An exploded FDEM slope whose triangles carry an initial stress while its crack elements start
at zero traction is out of equilibrium at every interior node: an undamped run jolts. This
module builds a start that is in equilibrium to round-off:

1. :func:`conforming_static_stress` solves the linear-elastic constant-strain-triangle (CST)
   problem of the *intact* (conforming) mesh under gravity and the constant external loads,

   ``K u = f``,  ``K = sum_e A_e B_e^T D_e B_e``,  ``f = sum_e rho_e A_e g / 3`` (each corner)
   ``+ f_ext``,

   with ``D = [[lam + 2 mu, lam, 0], [lam, lam + 2 mu, 0], [0, 0, mu]]`` (the model's 2D Lame
   constants, plane strain or plane stress) and engineering shear strain; the element stress
   is ``sigma_e = D_e B_e u_e`` [Pa] (Zienkiewicz, Taylor & Zhu 2013, *The Finite Element
   Method: Its Basis and Fundamentals*, 7th ed., ch. 6; Hughes 2000, *The Finite Element
   Method*, sec. 3.10).
2. :func:`crack_preload_forces` finds the crack-element end forces that cancel, at every free
   exploded node, the residual of gravity, external load and the triangle force of the initial
   stress ``S0 = sigma`` at the reference positions (``F = I``).
3. :func:`geostatic_start` writes both into the model and the crack set (before the
   :class:`~fdem.solver.Simulation` is built).
4. :func:`unbalanced_force_ratio` measures how far a running simulation is from equilibrium.

Units: SI, per metre of thickness (forces N/m, stresses Pa).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components, reverse_cuthill_mckee
from numba import njit, prange
from fdem.kernels.triangles import (FASTMATH, TC_MASS, assemble_triangle_forces, triangle_constants, triangle_response)
from fdem.physics.cracks import CP_C, CP_FT, CP_TANPHI
from fdem.solve.density_scaling import nodal_stiffness, provider_stiffness
from fdem.solve.model import FIX_X, FIX_Y

__all__ = ["GeostaticSolution", "GeostaticReport", "conforming_static_stress", "nodal_residual",
           "preload_residual", "crack_preload_forces", "crack_strength_check", "geostatic_start",
           "rayleigh_frequency", "unbalanced_forces", "unbalanced_ratio_floor",
           "unbalanced_force_ratio"]


# --------------------------------------------------------------------------- results
@dataclass
class GeostaticSolution:
    """The static linear-elastic state of the intact (conforming) mesh.

    Attributes
    ----------
    stress : (n_tri, 3) float64
        ``[s_xx, s_yy, s_xy]`` of every triangle [Pa], compression negative, in the model's
        triangle order.
    displacement : (n_mesh_points, 2) float64
        Displacement of every point of ``model.topology.mesh`` [m] (0 for a point in no triangle).
    seconds : float
        Wall time of assembly + solve [s].
    residual : float
        ``max |K u - f|`` over the free degrees of freedom divided by the mean nodal gravity
        (or load) force ``mean |f|`` [-].
    n_dofs : int
        Free degrees of freedom solved for.
    reaction : (2,) float64
        Total support reaction ``-(sum f)`` over the fixed degrees of freedom [N/m]; with the
        loads it sums to zero (global equilibrium).
    """

    stress: np.ndarray
    displacement: np.ndarray
    seconds: float
    residual: float
    n_dofs: int
    reaction: np.ndarray = field(default_factory=lambda: np.zeros(2))


@dataclass
class GeostaticReport:
    """What :func:`geostatic_start` did.

    Attributes
    ----------
    solution : GeostaticSolution
    preload : (n_crack, 2, 2) float64 or None
        Force on the A node of each crack-element end at zero separation [N/m].
    preload_residual : float
        ``max |sum of crack forces + g_n|`` over free exploded node components divided by the
        mean nodal gravity force ``mean |m g|`` [-] (round-off when the start is static).
    seconds_solve, seconds_preload : float
        Wall times [s] of the static solve and of the preload solve.
    over_strength : dict
        Crack elements whose preload traction exceeds their strength at the current strength
        factor: ``{"tensile": ids, "shear": ids, "by_tag": {tag: count}}`` (topology ids).
    """

    solution: GeostaticSolution
    preload: np.ndarray | None
    preload_residual: float
    seconds_solve: float
    seconds_preload: float
    over_strength: dict

    @property
    def seconds(self) -> float:
        return self.seconds_solve + self.seconds_preload


# --------------------------------------------------------------------------- helpers
def _check_zero_prescribed(model) -> None:
    """Only zero prescribed velocities describe a static support; name the first node that is not."""
    fixed = np.column_stack([(model.flags & FIX_X) != 0, (model.flags & FIX_Y) != 0])
    moving = fixed & (model.v_prescribed != 0.0)
    for c in model._velocity_conditions:  # time-dependent conditions are zero only if their value is
        if c.value != 0.0 and c.nodes.size:
            moving[c.nodes, c.component] = True
    if moving.any():
        node, comp = (int(i) for i in np.argwhere(moving)[0])
        x, y = model.topology.x0[node]
        raise ValueError(
            f"a static start needs zero prescribed velocities, but node {node} at ({x:.6g}, {y:.6g}) m has "
            f"a prescribed {'xy'[comp]} velocity {model.v_prescribed[node, comp]:.6g} m/s "
            f"({int(moving.sum())} such node direction(s)); start with zero velocities and prescribe "
            f"the motion in a later stage")


def _mesh_layout(model):
    """Mesh points, triangles on mesh points, and the mesh point of each model node."""
    topo = model.topology
    points = np.ascontiguousarray(topo.mesh.points, dtype=np.float64)
    node_point = np.asarray(topo.mesh_node, dtype=np.int64)
    tri = node_point[np.asarray(topo.triangles, dtype=np.int64)]
    return points, tri, node_point


def _shape_gradients(points, tri):
    """(n, 3, 2) gradients of the three linear shape functions and (n,) signed areas."""
    p0, p1, p2 = points[tri[:, 0]], points[tri[:, 1]], points[tri[:, 2]]
    area2 = (p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0])
    # grad N_a = (y_b - y_c, x_c - x_b) / (2 A) for (a, b, c) cyclic
    grad = np.empty((len(tri), 3, 2))
    for a, (b, c) in enumerate(((1, 2), (2, 0), (0, 1))):
        pb, pc = points[tri[:, b]], points[tri[:, c]]
        grad[:, a, 0] = (pb[:, 1] - pc[:, 1]) / area2
        grad[:, a, 1] = (pc[:, 0] - pb[:, 0]) / area2
    return grad, 0.5 * area2


def _strain_matrices(grad):
    """(n, 3, 6) CST strain-displacement matrices, dof order ``[u0, v0, u1, v1, u2, v2]``,
    strain ``[e_xx, e_yy, gamma_xy]``."""
    n = grad.shape[0]
    Bm = np.zeros((n, 3, 6))
    Bm[:, 0, 0::2] = grad[:, :, 0]
    Bm[:, 1, 1::2] = grad[:, :, 1]
    Bm[:, 2, 0::2] = grad[:, :, 1]
    Bm[:, 2, 1::2] = grad[:, :, 0]
    return Bm


def _support_mask(model, node_point, n_points):
    """(n_points, 2) bool: a mesh point is fixed in a direction if any of its node copies is
    (the crack elements tie the copies, so one held copy holds the point)."""
    fixed = np.zeros((n_points, 2), bool)
    for comp, bit in ((0, FIX_X), (1, FIX_Y)):
        held = (model.flags & bit) != 0
        fixed[node_point[held], comp] = True
    return fixed


def _check_rigid_modes(model, points, tri, fixed) -> None:
    """Raise if a connected body of the mesh keeps a rigid-body mode (two translations and the
    rotation) under its supports: the 3 x 3 Gram matrix of the fixed dofs' rigid-mode rows must
    have full rank."""
    n_pts = len(points)
    rows = np.repeat(tri, 3, axis=1).ravel()
    cols = np.tile(tri, (1, 3)).ravel()
    graph = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n_pts, n_pts)).tocsr()
    n_comp, label = connected_components(graph, directed=False)
    tri_label = label[tri[:, 0]]
    bodies = np.asarray(model.topology.triangle_body)
    scale = float(np.ptp(points, axis=0).max()) or 1.0
    for k in range(n_comp):
        pts_k = np.flatnonzero(label == k)
        tris_k = np.flatnonzero(tri_label == k)
        if tris_k.size == 0:  # a point in no triangle
            continue
        centre = points[pts_k].mean(axis=0)
        fx = pts_k[fixed[pts_k, 0]]
        fy = pts_k[fixed[pts_k, 1]]
        # rigid modes (ux, uy, rotation) seen by each fixed dof
        rx = (points[fx] - centre) / scale
        ry = (points[fy] - centre) / scale
        rows_x = np.column_stack([np.ones(fx.size), np.zeros(fx.size), -rx[:, 1]])
        rows_y = np.column_stack([np.zeros(fy.size), np.ones(fy.size), ry[:, 0]])
        R = np.vstack([rows_x, rows_y])
        sv = np.linalg.svd(R, compute_uv=False) if R.shape[0] else np.zeros(0)
        rank = int(np.sum(sv > 1e-9 * max(sv.max(initial=0.0), 1.0)))
        if rank < 3:
            body = int(bodies[tris_k[0]])
            lo, hi = points[pts_k].min(axis=0), points[pts_k].max(axis=0)
            missing = ("no support at all" if R.shape[0] == 0
                       else f"supports on {fx.size} x- and {fy.size} y-direction(s) leave {3 - rank} rigid-body mode(s)")
            raise ValueError(
                f"static start: body {body} ({tris_k.size} triangles, extent ({lo[0]:.4g}, {lo[1]:.4g}) - "
                f"({hi[0]:.4g}, {hi[1]:.4g}) m) has {missing}; fix or roller enough of its nodes "
                f"(two directions and a moment) before a static solve")


def _spd_solve(A, b):
    """Solve ``A x = b`` for a sparse symmetric positive-definite ``A`` with SuperLU in symmetric
    mode: minimum-degree ordering of ``A^T + A`` and no row pivoting (``diag_pivot_thresh=0``),
    so the fill stays that of a Cholesky factor. With the default partial pivoting SuperLU
    destroys the symmetric ordering: 30x slower on a 2e4-triangle slope, superlinear beyond.

    The unknowns are first put in reverse Cuthill-McKee order (Cuthill & McKee 1969; George &
    Liu 1981, ch. 4): the minimum-degree ordering's fill hardly depends on the order it is
    handed, but its own run time does. On the 179,243-unknown CST matrix of the fine four-slope
    scene at size 0.18 it took 13.5 s in the Hilbert-curve numbering of :mod:`fdem.mesh.order`
    and 1.0 s after RCM (1.0 s in Gmsh's numbering; fill 22.3-22.5 M entries in all three)."""
    A = sp.csr_matrix(A)
    p = reverse_cuthill_mckee(A, symmetric_mode=True)
    lu = spla.splu(A[p][:, p].tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    y = lu.solve(np.asarray(b, dtype=np.float64)[p])
    x = np.empty_like(y)
    x[p] = y
    return x


# --------------------------------------------------------------------------- 1. static solve
def conforming_static_stress(model) -> GeostaticSolution:
    """Linear-elastic CST stress of the intact slope under gravity and constant nodal loads.

    Solves ``K u = f`` on the conforming mesh ``model.topology.mesh`` (a mesh point per exploded
    node, ``topology.mesh_node``), with

    * ``K = sum_e A_e B_e^T D_e B_e`` [N/m^2 per m], ``D_e`` from ``model.lame_arrays()``
      (2D constants, plane strain or stress as the model),
    * ``f = sum_e rho_e A_e g / 3`` on each corner [N/m] ``+ model.external_force`` (summed
      over a point's node copies),
    * zero displacement in every direction in which a copy of the point is supported
      (``model.flags``; only zero prescribed velocities are accepted),

    assembled as one vectorised COO matrix and solved with ``scipy.sparse.linalg.splu``
    (symmetric mode, minimum-degree ordering, no pivoting).
    Returns the triangle stresses ``sigma_e = D_e B_e u_e`` [Pa] in the model's triangle order.

    Raises ``ValueError`` naming the node if a prescribed velocity is nonzero, and naming the
    body if its supports leave a rigid-body mode. Works for exploded and conforming topologies.
    Reference: Zienkiewicz, Taylor & Zhu (2013), ch. 6 (plane elasticity with linear triangles).
    """
    t0 = time.perf_counter()
    _check_zero_prescribed(model)
    points, tri, node_point = _mesh_layout(model)
    n_pts = len(points)
    fixed = _support_mask(model, node_point, n_pts)
    _check_rigid_modes(model, points, tri, fixed)

    grad, area = _shape_gradients(points, tri)
    if np.any(area <= 0):
        t = int(np.flatnonzero(area <= 0)[0])
        raise ValueError(f"triangle {t} is inverted or degenerate on the mesh (area {area[t]:.3g} m^2)")
    lam, mu = model.lame_arrays()
    D = np.zeros((len(tri), 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = lam + 2.0 * mu
    D[:, 0, 1] = D[:, 1, 0] = lam
    D[:, 2, 2] = mu
    Bm = _strain_matrices(grad)
    Ke = np.einsum("e,eki,ekl,elj->eij", area, Bm, D, Bm, optimize=True)
    dof = np.empty((len(tri), 6), np.int64)
    dof[:, 0::2] = 2 * tri
    dof[:, 1::2] = 2 * tri + 1
    n_dof = 2 * n_pts
    K = sp.coo_matrix((Ke.ravel(), (np.repeat(dof, 6, axis=1).ravel(), np.tile(dof, (1, 6)).ravel())),
                      shape=(n_dof, n_dof)).tocsr()

    f = np.zeros((n_pts, 2))
    share = model.property_array("density") * area / 3.0
    np.add.at(f, tri.ravel(), np.repeat(share, 3)[:, None] * model.gravity[None, :])
    np.add.at(f, node_point, model.external_force)
    f = f.ravel()

    used = np.zeros(n_pts, bool)
    used[tri.ravel()] = True
    free = ~fixed.ravel() & np.repeat(used, 2)
    idx = np.flatnonzero(free)
    u = np.zeros(n_dof)
    if idx.size:
        Kff = K[idx][:, idx].tocsc()
        u[idx] = _spd_solve(Kff, f[idx])
    r = K @ u - f
    f_scale = float(np.abs(f.reshape(-1, 2)[used]).sum(axis=1).mean()) or 1.0
    residual = float(np.abs(r[idx]).max(initial=0.0)) / f_scale
    reaction = r.reshape(-1, 2)[:, :].copy()
    reaction[~fixed] = 0.0
    ue = u[dof]
    stress = np.einsum("eij,ejk,ek->ei", D, Bm, ue, optimize=True)
    return GeostaticSolution(stress=stress, displacement=u.reshape(-1, 2), seconds=time.perf_counter() - t0,
                             residual=residual, n_dofs=int(idx.size), reaction=reaction.sum(axis=0))


# --------------------------------------------------------------------------- 2. crack preloads
def rayleigh_frequency(model, solution: GeostaticSolution | None = None) -> float:
    """Rayleigh's estimate [rad/s] of the fundamental angular frequency of the intact slope, from
    its static deflection ``u`` under its own loads ``f`` (gravity and constant nodal loads):

    ``omega_R^2 = sum_p f_p . u_p / sum_p m_p |u_p|^2``

    over the conforming mesh points ``p`` (``m_p`` the lumped mass, ``sum_e rho_e A_e / 3``).
    The static deflection is the classical trial shape of Rayleigh's method (Clough & Penzien
    1993, *Dynamics of Structures*, sec. 8-3); the estimate lies above the true lowest frequency
    by the error of the shape squared. It is the mode that a quasi-static stage under gravity
    has to settle: its critical mass-proportional damping is ``alpha = 2 omega_R``. On the
    four-slope scene ``omega_R`` is 2.0 times the shear-beam ``2 pi / (4 H / c_s)``
    (:func:`fdem.workflow.stages.response_time`): gravity deflects the slope mostly in vertical
    compression, which rings at the P-wave speed, and the slope above the toe is shorter than ``H``.

    ``solution``: a :func:`conforming_static_stress` already computed (else it is solved here).
    Raises ``ValueError`` when the loads do no work (no gravity, no load)."""
    sol = conforming_static_stress(model) if solution is None else solution
    points, tri, node_point = _mesh_layout(model)
    area = np.abs(_shape_gradients(points, tri)[1])
    m = np.zeros(len(points))
    np.add.at(m, tri.ravel(), np.repeat(model.property_array("density") * area / 3.0, 3))
    f = m[:, None] * model.gravity[None, :]
    np.add.at(f, node_point, model.external_force)
    u = sol.displacement
    work = float((f * u).sum())
    inertia = float((m[:, None] * u * u).sum())
    if not (work > 0.0 and inertia > 0.0):
        raise ValueError(f"rayleigh_frequency: the loads do no work on the static deflection (work {work:.3g} J/m); "
                         "give the model gravity or a load")
    return math.sqrt(work / inertia)


def _crack_frame(x0, crack_nodes):
    """(n, 2) unit normal of each crack element from A into B, as the crack kernel computes it:
    ``t = (m1 - m0)/|m1 - m0|``, ``m0 = (x0 + x3)/2``, ``m1 = (x1 + x2)/2``, ``n = (t_y, -t_x)``."""
    m = 0.5 * (x0[crack_nodes[:, 1]] + x0[crack_nodes[:, 2]] - x0[crack_nodes[:, 0]] - x0[crack_nodes[:, 3]])
    t = m / np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-300)
    return np.column_stack([t[:, 1], -t[:, 0]]), t


def nodal_residual(model, stress) -> np.ndarray:
    """(n_nodes, 2) ``g_n = m_n g + f_ext,n + f_tri,n`` [N/m] at the reference positions with every
    triangle carrying the initial stress ``S0 = stress`` (the solver's triangle force at
    ``F = I``: ``f_a = -A0 S0 grad N_a``, :func:`fdem.kernels.triangles.corner_forces`)."""
    topo = model.topology
    lam, mu = model.lame_arrays()
    tc = triangle_constants(topo.x0, topo.triangles, lam, mu, model.property_array("viscosity"),
                            model.property_array("density"), np.asarray(stress, float))
    x0 = np.ascontiguousarray(topo.x0, dtype=np.float64)
    tris = np.ascontiguousarray(topo.triangles, dtype=np.int64)
    corner = np.zeros((3 * topo.n_triangles, 2))
    assemble_triangle_forces(x0, np.zeros_like(x0), tris, tc, corner)
    g = model.node_mass()[:, None] * model.gravity[None, :] + model.external_force
    np.add.at(g, tris.ravel(), corner)
    return g


def _end_incidence(crack_nodes, n_nodes):
    """Sparse (n_nodes, 2 n_crack) incidence: column ``2c + e`` has +1 at the A node and -1 at
    the B node of end ``e`` of element ``c`` (end 0: columns 0, 3; end 1: columns 1, 2)."""
    n = crack_nodes.shape[0]
    a = np.column_stack([crack_nodes[:, 0], crack_nodes[:, 1]]).ravel()
    b = np.column_stack([crack_nodes[:, 3], crack_nodes[:, 2]]).ravel()
    col = np.arange(2 * n)
    return sp.csr_matrix((np.r_[np.ones(2 * n), -np.ones(2 * n)], (np.r_[a, b], np.r_[col, col])),
                         shape=(n_nodes, 2 * n))


def preload_residual(model, stress, forces) -> float:
    """``max |B F + g|`` over the free node components divided by the mean ``|m g|`` [-]:
    how far the exploded nodes are from equilibrium with crack-end forces ``forces``."""
    g = nodal_residual(model, stress)
    Bi = _end_incidence(np.asarray(model.topology.crack_nodes, np.int64), model.n_nodes)
    F = np.asarray(forces, float).reshape(-1, 2)
    r = Bi @ F + g
    r[(model.flags & FIX_X) != 0, 0] = 0.0
    r[(model.flags & FIX_Y) != 0, 1] = 0.0
    return float(np.abs(r).max(initial=0.0)) / _gravity_scale(model)


def _gravity_scale(model) -> float:
    """Mean nodal gravity force ``mean |m g|`` [N/m] (mean ``|f_ext|`` without gravity)."""
    s = float(np.linalg.norm(model.gravity)) * float(model.node_mass().mean())
    if s == 0.0:
        s = float(np.linalg.norm(model.external_force, axis=1).mean())
    return s or 1.0


def crack_preload_forces(model, stress) -> np.ndarray:
    """(n_crack, 2, 2) crack-end forces [N/m] that hold every free exploded node in equilibrium.

    With every triangle at its reference position carrying ``S0 = stress`` (n_tri, 3) [Pa],
    node ``n`` has the residual ``g_n = m_n g + f_ext,n + f_tri,n`` (:func:`nodal_residual`).
    ``F[c, e]`` is the force on the A node of end ``e`` of element ``c`` (end 0 = columns
    (0, 3) of ``crack_nodes``, end 1 = columns (1, 2)); the B node gets ``-F[c, e]``. With the
    incidence ``B`` (+1 on A, -1 on B) the equations are ``(B F)_n = -g_n`` for every node and
    direction not fixed by ``model.flags``.

    The system is underdetermined (a ring of node copies around each mesh point), so the
    solution closest to the traction of the stress field is taken: prior
    ``F_sigma[c, e] = (sigma_A + sigma_B)/2 . n  L0/2`` (``n`` from A into B as in the crack
    kernel, ``L0`` the reference length), and ``F = F_sigma + B_r^T lambda`` the
    minimum-norm correction, ``B_r B_r^T lambda = -g_r - B_r F_sigma`` (``B_r``: free rows),
    per force component. ``B_r B_r^T`` is a graph Laplacian, block-diagonal over mesh points,
    grounded where a node copy is fixed; each floating block (no fixed copy, a singular but
    consistent system when the stress is in equilibrium) is pinned at one node, which leaves
    ``B^T lambda`` unchanged. Solved with ``scipy.sparse.linalg.splu`` in symmetric mode
    (a direct solve, exact to round-off; the blocks are tiny, so there is almost no fill).

    For a stress field in static equilibrium (:func:`conforming_static_stress`) the result is
    exact; for any other stress the least-squares remainder shows in :func:`preload_residual`.
    """
    topo = model.topology
    cn = np.asarray(topo.crack_nodes, dtype=np.int64)
    n_crack = cn.shape[0]
    stress = np.asarray(stress, dtype=float)
    if stress.shape != (topo.n_triangles, 3):
        raise ValueError(f"stress must have shape ({topo.n_triangles}, 3), got {stress.shape}")
    if n_crack == 0:
        return np.zeros((0, 2, 2))
    _check_zero_prescribed(model)
    n_nodes = topo.n_nodes
    g = nodal_residual(model, stress)

    normal, _ = _crack_frame(np.asarray(topo.x0, float), cn)
    ta, tb = topo.crack_triangles[:, 0], topo.crack_triangles[:, 1]
    s = 0.5 * (stress[ta] + stress[tb])
    traction = np.column_stack([s[:, 0] * normal[:, 0] + s[:, 2] * normal[:, 1],
                                s[:, 2] * normal[:, 0] + s[:, 1] * normal[:, 1]])
    F_sigma = np.repeat((0.5 * np.asarray(topo.crack_length0, float))[:, None] * traction, 2, axis=0)  # (2n, 2)

    Bi = _end_incidence(cn, n_nodes)
    F = F_sigma.copy()
    for comp, bit in ((0, FIX_X), (1, FIX_Y)):
        free = (model.flags & bit) == 0
        rows = np.flatnonzero(free)
        Br = Bi[rows]
        rhs = -g[rows, comp] - Br @ F_sigma[:, comp]
        L = (Br @ Br.T).tocsr()
        # floating blocks: no end ties them to a fixed node (every column of the block has
        # both its nodes free); pin one node of each
        ends_fixed = np.asarray(abs(Bi).T @ (~free).astype(float)).ravel() > 0  # end touches a fixed node
        grounded = np.zeros(n_nodes, bool)
        touched = Bi[:, ends_fixed]
        grounded[np.unique(touched.nonzero()[0])] = True
        grounded_r = grounded[rows]
        n_comp, label = connected_components(L, directed=False)
        has_ground = np.zeros(n_comp, bool)
        has_ground[label[grounded_r]] = True
        first = np.full(n_comp, -1, np.int64)
        order = np.arange(rows.size)[::-1]
        first[label[order]] = order  # smallest index of each block
        pin = first[~has_ground]
        L = L + sp.csr_matrix((np.ones(pin.size), (pin, pin)), shape=L.shape)
        lam = _spd_solve(L.tocsc(), rhs)
        F[:, comp] += Br.T @ lam
    return F.reshape(n_crack, 2, 2)


def _crack_strengths(cracks, reduction: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n,) ``f_t`` [Pa], ``c`` [Pa], ``tan(phi)`` of every element as its law uses them now
    (strength multiplier and strength reduction applied), or under the reduction factor
    ``reduction`` when it is given."""
    interfaces = getattr(cracks, "interfaces", None)
    if interfaces is not None:  # the crack set's own per-element strengths under the reduction F
        ft, c, tanphi = cracks._element_strengths(interfaces.reduction if reduction is None else reduction)[:3]
        return ft, c, tanphi
    if reduction is not None:
        raise ValueError(f"crack_strength_check: {type(cracks).__name__} has no strength reduction "
                         f"(interfaces) to evaluate at F = {reduction:g}")
    factor = cracks.strength_factor
    P = cracks.props[cracks.tag]
    h = cracks.strength_multiplier
    return P[:, CP_FT] * h * factor, P[:, CP_C] * h * factor, P[:, CP_TANPHI] * factor


def crack_strength_check(cracks, forces, reduction: float | None = None) -> dict:
    """Crack-element ends whose preload traction is above strength at the current strength
    factor, or at the strength-reduction factor ``reduction`` when it is given (what a schedule
    that ends there does to the start's stress, before it runs).

    Per end: ``T = F / (L0/2)`` [Pa], ``sigma_n = T . n`` (tension positive), ``tau = T . t``;
    tensile failure if ``sigma_n > f_t``, shear if ``|tau| > c + max(-sigma_n, 0) tan(phi)``
    (tension cut-off), with ``f_t`` and ``c`` times the element's strength multiplier and the
    strength factor. Returns ``{"tensile": ids, "shear": ids, "by_tag": {tag: n_elements},
    "max_ratio": max(traction / strength)}`` (topology ids of elements with an end over).
    """
    topo = cracks.topology
    cn = np.asarray(topo.crack_nodes, np.int64)
    normal, tangent = _crack_frame(np.asarray(topo.x0, float), cn)
    F = np.asarray(forces, float)
    T = F / (0.5 * np.asarray(topo.crack_length0, float))[:, None, None]
    sig = (T * normal[:, None, :]).sum(-1)
    tau = (T * tangent[:, None, :]).sum(-1)
    ft, c, tanphi = (a[:, None] for a in _crack_strengths(cracks, reduction))
    shear_strength = c + np.maximum(-sig, 0.0) * tanphi
    tensile = np.flatnonzero((sig > ft).any(axis=1))
    shear = np.flatnonzero((np.abs(tau) > shear_strength).any(axis=1))
    over = np.union1d(tensile, shear)
    tags, counts = np.unique(cracks.tag[over], return_counts=True)
    ratio = np.maximum(sig / ft, np.abs(tau) / np.maximum(shear_strength, 1e-300))
    return {"tensile": tensile, "shear": shear, "by_tag": {int(t): int(n) for t, n in zip(tags, counts)},
            "max_ratio": float(ratio.max(initial=0.0))}


# --------------------------------------------------------------------------- 3. the start
def geostatic_start(model, cracks=None, replace: bool = False) -> GeostaticReport:
    """Put ``model`` (and its crack set) in static equilibrium under gravity and its loads.

    Computes :func:`conforming_static_stress`, sets it as the triangles' initial stress
    (``model.set_initial_stress(stress)``, array form) and, when ``cracks`` is given, the
    crack-end forces of :func:`crack_preload_forces` as the elements' preload
    (``cracks.set_preload(forces)``: the force at zero separation [N/m]). Every free exploded
    node then starts with ``m a = 0`` to round-off, so an undamped run stays at rest.

    Call it **before** building :class:`fdem.solver.Simulation`: the simulation copies the
    triangle constants (initial stress included) when it is constructed. A model that already
    carries a nonzero initial stress is refused unless ``replace=True``.
    """
    if np.any(model.initial_stress != 0.0) and not replace:
        raise ValueError("geostatic_start: the model already has a nonzero initial stress; pass replace=True "
                         "to overwrite it with the static one")
    if cracks is not None and not callable(getattr(cracks, "set_preload", None)):
        raise TypeError(f"geostatic_start: {type(cracks).__name__} has no set_preload(end_forces) method")
    if cracks is not None and cracks.topology is not model.topology:
        raise ValueError("geostatic_start: the crack set was built on a different topology than the model")
    t0 = time.perf_counter()
    sol = conforming_static_stress(model)
    t1 = time.perf_counter()
    forces, res, over = None, 0.0, {"tensile": np.zeros(0, np.int64), "shear": np.zeros(0, np.int64),
                                    "by_tag": {}, "max_ratio": 0.0}
    if model.topology.n_cracks:
        forces = crack_preload_forces(model, sol.stress)
    t2 = time.perf_counter()
    if forces is not None:
        res = preload_residual(model, sol.stress, forces)
        if cracks is not None:
            over = crack_strength_check(cracks, forces)
    model.set_initial_stress(sol.stress)
    if cracks is not None and forces is not None:
        cracks.set_preload(forces)
    return GeostaticReport(solution=sol, preload=forces, preload_residual=res, seconds_solve=t1 - t0,
                           seconds_preload=t2 - t1, over_strength=over)


# --------------------------------------------------------------------------- 4. convergence measure
@njit(fastmath=FASTMATH, cache=True, inline="always")
def _net_force(r, k, n, m, gx, gy, f_int, f_ext, flags):
    """``(fx, fy)`` [N/m]: the unbalanced force of corner ``k`` (node ``n``) of a triangle of
    mass share ``m``: its response ``r`` at the current state, gravity on the real mass,
    interaction and external force; a supported component is zero. The one statement of the
    net force for the ratio (:func:`unbalanced_force_ratio`) and its map (:func:`unbalanced_forces`)."""
    fx = r[2 * k] + m * gx + f_int[n, 0] + f_ext[n, 0]
    fy = r[2 * k + 1] + m * gy + f_int[n, 1] + f_ext[n, 1]
    if flags[n] & 1:
        fx = 0.0
    if flags[n] & 2:
        fy = 0.0
    return fx, fy


@njit(parallel=True, fastmath=FASTMATH, cache=True)
def _unbalanced_nodal_exploded(x, v, tc, f_int, f_ext, flags, gx, gy, use_viscous, out):
    """``out[n] = f_net`` [N/m] of every node of an exploded mesh (node ``3t+k``): triangle force at
    ``x``, gravity on the real mass, interaction and external force; supported components zero."""
    for t in prange(tc.shape[0]):
        i = 3 * t
        r = triangle_response(tc, t, x[i, 0], x[i, 1], x[i + 1, 0], x[i + 1, 1], x[i + 2, 0], x[i + 2, 1],
                              v[i, 0], v[i, 1], v[i + 1, 0], v[i + 1, 1], v[i + 2, 0], v[i + 2, 1], use_viscous)
        m = tc[t, TC_MASS]
        for k in range(3):
            out[i + k, 0], out[i + k, 1] = _net_force(r, k, i + k, m, gx, gy, f_int, f_ext, flags)


@njit(parallel=True, fastmath=FASTMATH, cache=True)
def _unbalanced_exploded(x, v, tc, f_int, f_ext, flags, gx, gy, use_viscous):
    """Sums ``(sum |f_net| over free components, sum |m g|)`` on an exploded mesh (node ``3t+k``)."""
    num = 0.0
    den = 0.0
    g = math.sqrt(gx * gx + gy * gy)
    for t in prange(tc.shape[0]):
        i = 3 * t
        r = triangle_response(tc, t, x[i, 0], x[i, 1], x[i + 1, 0], x[i + 1, 1], x[i + 2, 0], x[i + 2, 1],
                              v[i, 0], v[i, 1], v[i + 1, 0], v[i + 1, 1], v[i + 2, 0], v[i + 2, 1], use_viscous)
        m = tc[t, TC_MASS]
        for k in range(3):
            fx, fy = _net_force(r, k, i + k, m, gx, gy, f_int, f_ext, flags)
            num += math.sqrt(fx * fx + fy * fy)
            den += m * g
    return num, den


def unbalanced_forces(sim) -> np.ndarray:
    """(n_nodes, 2) unbalanced force ``f_net`` [N/m] of every node: the terms of
    :func:`unbalanced_force_ratio`'s numerator, node by node (supported components zero), to map
    where a stage's residual sits (crack elements in softening, contact, supports, scaled nodes)."""
    st = sim.state
    if sim.exploded:
        out = np.empty_like(st.x)
        _unbalanced_nodal_exploded(st.x, st.v, sim.tc, sim.f_interaction, sim.f_external, sim.flags,
                                   float(sim.gravity[0]), float(sim.gravity[1]), sim.use_viscous, out)
        return out
    corner = np.zeros((3 * sim.model.n_triangles, 2))
    assemble_triangle_forces(st.x, st.v, sim.triangles, sim.tc, corner)
    f = st.mass[:, None] * sim.gravity[None, :] + sim.f_external + sim.f_interaction
    np.add.at(f, sim.triangles.ravel(), corner)
    f[(sim.flags & FIX_X) != 0, 0] = 0.0
    f[(sim.flags & FIX_Y) != 0, 1] = 0.0
    return f


def unbalanced_ratio_floor(sim) -> float:
    """Round-off floor of :func:`unbalanced_force_ratio` [-]:

    ``R_eps = (sum_n S_x,n eps(x_n) + sum_n S_u,n eps(u_n)) / sum_n |m_n g|``

    with ``S_x,n`` [N/m] the stiffness on node ``n`` of what reads positions (its triangles,
    contact: :func:`fdem.solve.density_scaling.nodal_stiffness`), ``S_u,n`` that of the providers
    that read the displacements ``u = x - x0`` kept apart in the state (the crack elements:
    their ``bind_displacement``), and ``eps`` the spacing of float64 numbers at the magnitude of
    the coordinate read (``numpy.spacing``). Each force is known only to about ``S eps``; the
    ratio cannot fall much below ``R_eps`` however long a stage runs.

    The crack penalties are most of the stiffness (91-97 % on the four-slope scenes) and grow
    against a node's weight as the mesh refines (about as ``1 / dt^2``). Read from positions,
    100 m from the origin, they set a floor of 9.3e-6, 1.8e-5 and 2.8e-5 at sizes 1.0, 0.5 and
    0.35 m (the low-angle coarse slope with the run extents); read from displacements, the floor
    is the contact's and the triangles' (``docs/benchmarks.md``, "The floor and the origin")."""
    mass = sim.state.mass
    tri = getattr(sim, "_triangle_stiffness", None)
    reads_u = [p for p in sim.providers if callable(getattr(p, "bind_displacement", None))]
    reads_x = [p for p in sim.providers if p not in reads_u]
    num = float(nodal_stiffness(sim.model, reads_x, mass, tri) @ np.spacing(np.abs(sim.state.x)).max(axis=1))
    if reads_u:
        num += float(provider_stiffness(reads_u, mass) @ np.spacing(np.abs(sim.state.u)).max(axis=1))
    den = float(mass.sum() * np.linalg.norm(sim.gravity))
    if den == 0.0:
        den = float(np.linalg.norm(sim.f_external, axis=1).sum())
    if den == 0.0:
        raise ValueError("unbalanced_ratio_floor: no gravity and no external load to compare with")
    return num / den


def unbalanced_force_ratio(sim) -> float:
    """The unbalanced-force ratio of a quasi-static explicit run [-]:

    ``R = sum_n |f_net,n| / sum_n |m_n g|``,  ``f_net = f_triangle(x) + f_interaction + m g + f_ext``

    with the triangle forces at the current positions, ``f_interaction`` the crack and contact
    forces of the last step (``sim.f_interaction``), and supported components (``sim.flags``)
    left out of the numerator (a support takes them). Without gravity the denominator is
    ``sum |f_ext|``. The usual stop rule of explicit quasi-static analysis (Cundall 1987; e.g.
    ``R < 1e-5`` for equilibrium). One fused Numba pass on an exploded mesh.
    """
    st = sim.state
    f_ext = sim.f_external
    if sim.exploded:
        f_int = sim.f_interaction
        num, den = _unbalanced_exploded(st.x, st.v, sim.tc, f_int, f_ext, sim.flags, float(sim.gravity[0]),
                                        float(sim.gravity[1]), sim.use_viscous)
    else:
        corner = np.zeros((3 * sim.model.n_triangles, 2))
        assemble_triangle_forces(st.x, st.v, sim.triangles, sim.tc, corner)
        f = st.mass[:, None] * sim.gravity[None, :] + f_ext + sim.f_interaction
        np.add.at(f, sim.triangles.ravel(), corner)
        f[(sim.flags & FIX_X) != 0, 0] = 0.0
        f[(sim.flags & FIX_Y) != 0, 1] = 0.0
        num = float(np.linalg.norm(f, axis=1).sum())
        den = float(st.mass.sum() * np.linalg.norm(sim.gravity))
    if den == 0.0:
        den = float(np.linalg.norm(f_ext, axis=1).sum())
    if den == 0.0:
        raise ValueError("unbalanced_force_ratio: no gravity and no external load to compare with")
    return float(num / den)
