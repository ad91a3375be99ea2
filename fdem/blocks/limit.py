"""Static limit analysis of rigid blocks as a second-order cone program (docs/rigid_blocks.md).

Unknowns: at both end points ``e = 0, 1`` of every interface ``k`` a normal force ``n_ke``
(compression positive) and a shear force ``t_ke`` [N/m]; the point forces on block ``a`` are
``n nu + t tau`` (``nu`` the interface normal into ``a``, ``tau`` its tangent), equal and
opposite on ``b``. Two point forces per interface represent any normal force and moment the
interface can carry (the resultant may sit anywhere on it) and with them the rocking of a block
about either end.

    B x + w(k) = 0                                   equilibrium of every free block (3 rows)
    |t_ke| <= (tan(phi) n_ke + c L_k / 2) / F        Mohr-Coulomb cone, a second-order cone
    n_ke >= -f_t L_k / (2 F)                         tension cut-off

with ``w(k) = gamma A_i (g_hat + k)`` the weight of block ``i`` [N/m] plus the pseudo-static
seismic load (coefficient ``k`` of g). The program is a lower bound: a set of forces that
satisfies it proves the blocks can stand. Its dual is the upper bound: block velocities ``v``
(3 per block) such that the loads do more work ``w . v`` than the interfaces can dissipate;
when no admissible forces exist, the solver's certificate of infeasibility is such a ``v``: the
collapse mechanism. The flow rule implied is associated (sliding dilates at ``phi``), as in all
convex limit analysis; for a single plane daylighting in a free face it gives Hoek and Bray's
factor of safety exactly.

* :func:`check_equilibrium`: is there an admissible set of forces at F (and k)?
* :func:`factor_of_safety`: the smallest F at which there is none, by bisection of
  ``log F``, with the mechanism at the failing end.
* :func:`yield_acceleration`: the largest pseudo-static coefficient ``k_y`` along a direction
  the blocks can stand, the optimum of one cone program, with its mechanism (the duals).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
import scipy.sparse as sp

from fdem.blocks.assembly import BlockSystem
from fdem.blocks.cone import ConeProblem, ConeSolverError, solve_cone
from fdem.blocks.strength import Strength, interface_strength

__all__ = ["BlockSystemError", "StandsBeyondBracket", "Mechanism", "Statics", "EquilibriumResult", "RigidFoS", "YieldResult",
           "statics", "check_equilibrium", "factor_of_safety", "yield_acceleration", "cross2"]


class BlockSystemError(ValueError):
    """Bad input to a rigid-block analysis: a block with no support, a mechanism no strength
    resists, a bracket that holds no limit, or a solver that gave no answer."""


class StandsBeyondBracket(BlockSystemError):
    """The blocks still stand at the upper end of the factor-of-safety bracket (``upper``)."""

    def __init__(self, message: str, upper: float):
        super().__init__(message)
        self.upper = upper


def cross2(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """z-component of ``r x v`` for (..., 2) arrays."""
    return r[..., 0] * v[..., 1] - r[..., 1] * v[..., 0]


@dataclass(frozen=True)
class Statics:
    """The equilibrium matrix of a block system, scaled: forces by ``force_scale`` [N/m], moments
    by ``force_scale * length_scale``.

    B : (3 n_free, 4 k) sparse, columns ``(n_k0, t_k0, n_k1, t_k1)`` per active interface
    interfaces : (k,) the interfaces with at least one free block
    free : (n_free,) block indices of the rows (block ``free[i]`` owns rows 3i..3i+2)
    """

    system: BlockSystem
    B: sp.csc_matrix
    interfaces: np.ndarray
    free: np.ndarray
    length_scale: float
    force_scale: float
    unit_weight: float
    gravity: np.ndarray

    def loads(self, seismic=(0.0, 0.0)) -> np.ndarray:
        """Scaled load vector ``w`` (3 n_free,): weight and pseudo-static load of each free block."""
        s = self.system
        g = self.gravity + np.asarray(seismic, float)
        W = self.unit_weight * s.area[self.free] / self.force_scale
        w = np.zeros((len(self.free), 3))
        w[:, 0], w[:, 1] = W * g[0], W * g[1]
        return w.ravel()

    def block_velocity(self, z_rows: np.ndarray) -> np.ndarray:
        """(n_blocks, 3) velocities ``(vx, vy, omega)`` from the row multipliers (moment rows
        carry ``omega * length_scale``); fixed blocks zero."""
        v = np.zeros((self.system.n_blocks, 3))
        r = z_rows.reshape(-1, 3).copy()
        r[:, 2] /= self.length_scale
        v[self.free] = r
        return v


def statics(system: BlockSystem, unit_weight: float, gravity=(0.0, -1.0)) -> Statics:
    """Build the scaled equilibrium matrix of ``system`` (rows: free blocks; columns: the point
    forces of every interface touching a free block). ``unit_weight`` gamma [N/m^3];
    ``gravity`` the direction and size of gravity in g (tilt it to put a plane's dip into g).
    Raises :class:`BlockSystemError` for a free block that no interface touches or a group of
    free blocks with no path to a fixed one."""
    if not (math.isfinite(unit_weight) and unit_weight > 0):
        raise BlockSystemError(f"unit weight must be positive, got {unit_weight} N/m^3")
    _check_supported(system)
    fixed = system.fixed
    a, b = system.blocks[:, 0], system.blocks[:, 1]
    active = np.flatnonzero(~(fixed[a] & fixed[b]))
    free = system.free
    row = np.full(system.n_blocks, -1)
    row[free] = np.arange(len(free))
    Ls = float(np.sqrt(max(system.area[free].mean(), 1e-300)))
    Ws = float(unit_weight * system.area[free].mean())
    nu, tau = system.normal[active], system.tangent[active]
    rows, cols, vals = [], [], []
    for e in range(2):
        p = system.ends[active, e]
        for side, blk, sign in ((0, a[active], 1.0), (1, b[active], -1.0)):
            ok = ~fixed[blk]
            r = (p - system.centroid[blk]) / Ls
            for comp, dvec in ((0, nu), (1, tau)):  # n then t
                col = 4 * np.arange(len(active)) + 2 * e + comp
                moment = cross2(r, dvec)
                for k, val in ((0, dvec[:, 0]), (1, dvec[:, 1]), (2, moment)):
                    rows.append(3 * row[blk[ok]] + k)
                    cols.append(col[ok])
                    vals.append(sign * val[ok])
    B = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(3 * len(free), 4 * len(active)))
    return Statics(system, B, active, free, Ls, Ws, float(unit_weight), np.asarray(gravity, float))


def _check_supported(system: BlockSystem) -> None:
    """Every free block must be touched by an interface and joined to a fixed block through
    interfaces; otherwise no strength can hold it (an unbounded mechanism)."""
    from scipy.sparse.csgraph import connected_components

    n = system.n_blocks
    if n == 0:
        raise BlockSystemError("the geometry holds no block")
    if not system.fixed.any():
        raise BlockSystemError("no block is fixed: no block touches a support (the section's bottom and sides by "
                               "default); every block would fall freely")
    a, b = system.blocks.T
    touched = np.zeros(n, dtype=bool)
    touched[a] = touched[b] = True
    lone = np.flatnonzero(~touched & ~system.fixed)
    if lone.size:
        i = int(lone[0])
        raise BlockSystemError(f"{lone.size} block(s) have no support: block {i} (centroid "
                               f"{tuple(np.round(system.centroid[i], 3))} m, area {system.area[i]:.4g} m^2) touches "
                               f"no other block and no support, so nothing holds it")
    g = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, label = connected_components(g, directed=False)
    held = np.isin(label, np.unique(label[system.fixed]))
    if not held.all():
        i = int(np.flatnonzero(~held)[0])
        raise BlockSystemError(f"{int((~held).sum())} block(s) have no path to a support: block {i} (centroid "
                               f"{tuple(np.round(system.centroid[i], 3))} m) and its neighbours touch no fixed block")


def _cone_rows(st: Statics, strengths: Mapping[int, Strength], factor: float):
    """Tension cut-off and Mohr-Coulomb cone rows ``A x + s = b`` for the point forces."""
    s = st.system
    k = len(st.interfaces)
    mu, c, ft = interface_strength(s.tag[st.interfaces], strengths, factor)
    half = 0.5 * s.length[st.interfaces] / st.force_scale
    n_cols = 4 * np.arange(k)[:, None] + 2 * np.arange(2)[None, :]      # (k, 2): the n of each point
    n_cols = n_cols.ravel()
    t_cols = n_cols + 1
    m = 2 * k
    # tension cut-off: -n + s = f_t L/2, s >= 0
    A_t = sp.csc_matrix((-np.ones(m), (np.arange(m), n_cols)), shape=(m, 4 * k))
    b_t = np.repeat(ft * half, 2)
    # cone: (mu n + c L/2, t) in SOC(2): rows (-mu n) + s0 = c L/2 and (-t) + s1 = 0
    r0 = 2 * np.arange(m)
    A_c = sp.csc_matrix((np.r_[-np.repeat(mu, 2), -np.ones(m)], (np.r_[r0, r0 + 1], np.r_[n_cols, t_cols])),
                        shape=(2 * m, 4 * k))
    b_c = np.zeros(2 * m)
    b_c[r0] = np.repeat(c * half, 2)
    return A_t, b_t, A_c, b_c


@dataclass(frozen=True)
class Mechanism:
    """A collapse mechanism: ``velocity`` (n_blocks, 3) ``(vx, vy, omega)`` scaled so that the
    fastest block corner moves at 1 (m/s per unit, rad/s per unit); ``moving`` (n_blocks,)
    those whose corners move faster than 1e-3; ``slip`` and ``opening`` (k,) mean relative
    velocity of ``a`` against ``b`` along and across each interface; ``arm`` (n_blocks,) the
    distance from each block's centroid to its farthest corner [m]."""

    velocity: np.ndarray
    moving: np.ndarray
    slip: np.ndarray
    opening: np.ndarray
    arm: np.ndarray | None = None

    @property
    def n_moving(self) -> int:
        return int(self.moving.sum())

    def kind(self) -> str:
        """"toppling" when the moving blocks mostly turn (a block turns when its instantaneous
        centre of rotation lies within twice its farthest corner from its centroid,
        ``|v_c| < 2 r_max |omega|``; "mostly": over half the moving blocks' ``r_max^2``, a
        proxy of their area), else "sliding"; "none" without motion."""
        v = self.velocity[self.moving]
        if v.size == 0:
            return "none"
        arm = self.arm[self.moving]
        turns = np.linalg.norm(v[:, :2], axis=1) < 2 * arm * np.abs(v[:, 2])
        return "toppling" if (arm[turns] ** 2).sum() > 0.5 * (arm ** 2).sum() else "sliding"

    def as_dict(self) -> dict:
        return {"n_moving": self.n_moving, "moving_blocks": np.flatnonzero(self.moving).tolist(), "kind": self.kind(),
                "velocity_of_moving": self.velocity[self.moving].tolist()}


def _mechanism(st: Statics, z_rows: np.ndarray, along=None) -> Mechanism:
    s = st.system
    v = st.block_velocity(z_rows)
    corner = np.zeros(s.n_blocks)
    for i in st.free:
        r = s.polygons[i] - s.centroid[i]
        vc = v[i, :2] + v[i, 2] * np.column_stack([-r[:, 1], r[:, 0]])
        corner[i] = np.linalg.norm(vc, axis=1).max()
    top = corner.max()
    if not top > 0:
        raise BlockSystemError("the solver's certificate has no motion in it: no mechanism could be read")
    v, corner = v / top, corner / top
    if along is not None:
        w = (st.loads(along) - st.loads()).reshape(-1, 3)
        if float((w * v[st.free]).sum()) < 0:
            v = -v
    a, b = s.blocks.T
    slip, opening = np.zeros(s.n_interfaces), np.zeros(s.n_interfaces)
    mid = s.ends.mean(axis=1)
    ra, rb = mid - s.centroid[a], mid - s.centroid[b]
    va = v[a, :2] + v[a, 2:3] * np.column_stack([-ra[:, 1], ra[:, 0]])
    vb = v[b, :2] + v[b, 2:3] * np.column_stack([-rb[:, 1], rb[:, 0]])
    rel = va - vb
    slip = (rel * s.tangent).sum(axis=1)
    opening = (rel * s.normal).sum(axis=1)
    arm = np.array([np.linalg.norm(p - c, axis=1).max() for p, c in zip(s.polygons, s.centroid)])
    return Mechanism(v, corner > 1e-3, slip, opening, arm)


@dataclass(frozen=True)
class EquilibriumResult:
    """``stable``: admissible forces exist at ``factor``. Then ``normal``/``shear`` (k, 2) point
    forces [N/m] on every interface (0 where both blocks are fixed); else ``mechanism``."""

    stable: bool
    factor: float
    normal: np.ndarray | None
    shear: np.ndarray | None
    mechanism: Mechanism | None
    iterations: int
    seconds: float


def check_equilibrium(st: Statics, strengths: Mapping[int, Strength], factor: float = 1.0,
                      seismic=(0.0, 0.0), tol: float = 1e-8) -> EquilibriumResult:
    """Do admissible interface forces exist at strength-reduction ``factor`` F and pseudo-static
    coefficient ``seismic`` (kx, ky) [g]? Feasibility of the cone program in the module docstring."""
    k = len(st.interfaces)
    A_t, b_t, A_c, b_c = _cone_rows(st, strengths, factor)
    A = sp.vstack([st.B, A_t, A_c], format="csc")
    b = np.r_[-st.loads(seismic), b_t, b_c]
    t0 = time.perf_counter()
    r = solve_cone(ConeProblem(A, b, np.zeros(4 * k), st.B.shape[0], A_t.shape[0], A_c.shape[0] // 2), tol=tol,
                   what=f"equilibrium at F = {factor:.6g}")
    dt = time.perf_counter() - t0
    if r.status == "solved":
        n = np.zeros((st.system.n_interfaces, 2))
        t = np.zeros((st.system.n_interfaces, 2))
        x = r.x.reshape(-1, 2, 2) * st.force_scale
        n[st.interfaces], t[st.interfaces] = x[:, :, 0], x[:, :, 1]
        return EquilibriumResult(True, factor, n, t, None, r.iterations, dt)
    if r.status != "infeasible":
        raise ConeSolverError(f"equilibrium at F = {factor:.6g}: unexpected solver status {r.raw_status}")
    # certificate: A'z = 0, b'z < 0, z in K*: the rows of B carry the block velocities, and
    # w . v > 0 (the loads do more work than the interfaces can dissipate)
    return EquilibriumResult(False, factor, None, None, _mechanism(st, r.z[:st.B.shape[0]]), r.iterations, dt)


@dataclass(frozen=True)
class RigidFoS:
    """Factor of safety by strength reduction: ``fos`` (the geometric middle of ``bracket``),
    ``bracket`` = (largest F found stable, smallest F found failing), the ``mechanism`` at the
    failing end, every ``trials`` ``(F, stable)``, the solves' total ``seconds``."""

    fos: float
    bracket: tuple[float, float]
    mechanism: Mechanism
    trials: list = field(default_factory=list)
    seconds: float = 0.0
    iterations: int = 0

    def as_dict(self) -> dict:
        return {"fos": self.fos, "bracket": list(self.bracket), "n_solves": len(self.trials),
                "seconds": self.seconds, "mechanism": self.mechanism.as_dict(),
                "trials": [list(t) for t in self.trials]}


def factor_of_safety(st: Statics, strengths: Mapping[int, Strength], lower: float = 0.2, upper: float = 20.0,
                     rtol: float = 1e-3, seismic=(0.0, 0.0)) -> RigidFoS:
    """The smallest strength-reduction factor F at which no admissible forces exist, to a
    relative bracket width ``rtol``, by bisection of ``log F`` within ``[lower, upper]``
    (about ``log2(log(upper/lower)/rtol)`` cone programs: 13 for the defaults).

    Raises :class:`BlockSystemError` when the blocks fail already at ``lower`` (a mechanism
    that almost no strength resists: blocks resting on free faces, joints without friction or
    cohesion) or still stand at ``upper``."""
    if not 0 < lower < upper:
        raise BlockSystemError(f"factor of safety: need 0 < lower < upper, got [{lower}, {upper}]")
    t0 = time.perf_counter()
    trials, its = [], 0
    lo = check_equilibrium(st, strengths, lower, seismic)
    trials.append((lower, lo.stable))
    if not lo.stable:
        moving = np.flatnonzero(lo.mechanism.moving)
        raise BlockSystemError(
            f"the blocks fail already at F = {lower:g}: a mechanism of {moving.size} block(s) (first "
            f"{moving[:5].tolist()}, centroid {tuple(np.round(st.system.centroid[moving[0]], 3))} m) that the "
            f"strengths barely resist; check for blocks resting on a free face or joints without strength")
    hi = check_equilibrium(st, strengths, upper, seismic)
    trials.append((upper, hi.stable))
    if hi.stable:
        raise StandsBeyondBracket(f"the blocks still stand at F = {upper:g}: the factor of safety exceeds it "
                                  f"(give a larger upper bound)", upper)
    a, b, mech = lower, upper, hi.mechanism
    its += lo.iterations + hi.iterations
    while b / a - 1 > rtol:
        m = math.sqrt(a * b)
        try:
            r = check_equilibrium(st, strengths, m, seismic)
        except ConeSolverError:
            if b / a - 1 < 1e-2:    # at the limit the solver may not decide: keep the bracket
                break
            raise
        its += r.iterations
        trials.append((m, r.stable))
        if r.stable:
            a = m
        else:
            b, mech = m, r.mechanism
    return RigidFoS(math.sqrt(a * b), (a, b), mech, trials, time.perf_counter() - t0, its)


@dataclass(frozen=True)
class YieldResult:
    """Pseudo-static yield coefficient ``k_y`` [g] along ``direction`` (the block system stands
    under ``gravity + k direction`` for ``k <= k_y``), ``acceleration`` = k_y g [m/s^2], the
    ``mechanism`` at the yield (duals of equilibrium), ``seconds``."""

    k_y: float
    direction: tuple
    acceleration: float
    mechanism: Mechanism
    seconds: float
    iterations: int

    def as_dict(self) -> dict:
        return {"k_y": self.k_y, "direction": list(self.direction), "acceleration_m_s2": self.acceleration,
                "seconds": self.seconds, "mechanism": self.mechanism.as_dict()}


def yield_acceleration(st: Statics, strengths: Mapping[int, Strength], direction=(-1.0, 0.0), factor: float = 1.0,
                       g: float = 9.81, tol: float = 1e-9) -> YieldResult:
    """Largest pseudo-static coefficient ``k`` along the unit ``direction`` (default horizontal,
    towards a face on the left, the project's slope convention) at which admissible forces exist:
    ``max k  s.t.  B x + w_g + k w_d = 0``, cones as in :func:`check_equilibrium`; one cone
    program, its optimum ``k_y`` and the multipliers of the equilibrium rows the mechanism.
    Raises :class:`BlockSystemError` when the blocks fail under gravity alone or no load along
    ``direction`` can move them."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    A_t, b_t, A_c, b_c = _cone_rows(st, strengths, factor)
    k = len(st.interfaces)
    w_g, w_d = st.loads(), st.loads(d) - st.loads()
    n_eq = st.B.shape[0]
    A_eq = sp.hstack([st.B, sp.csc_matrix(w_d[:, None])])
    pad = lambda M: sp.hstack([M, sp.csc_matrix((M.shape[0], 1))])
    A = sp.vstack([A_eq, pad(A_t), pad(A_c)], format="csc")
    b = np.r_[-w_g, b_t, b_c]
    q = np.zeros(4 * k + 1)
    q[-1] = -1.0
    t0 = time.perf_counter()
    r = solve_cone(ConeProblem(A, b, q, n_eq, A_t.shape[0], A_c.shape[0] // 2), tol=tol,
                   what="pseudo-static yield acceleration")
    dt = time.perf_counter() - t0
    if r.status == "infeasible":
        raise BlockSystemError(f"the blocks fail under gravity alone at F = {factor:g}: no pseudo-static yield "
                               f"acceleration (compute the factor of safety first)")
    if r.status == "unbounded":
        raise BlockSystemError(f"no pseudo-static load along {tuple(d)} moves the blocks: no mechanism in that "
                               f"direction (an unbounded yield acceleration)")
    ky = float(r.x[-1])
    mech = _mechanism(st, r.z[:n_eq], along=tuple(d))
    return YieldResult(ky, tuple(d.tolist()), ky * g, mech, dt, r.iterations)
