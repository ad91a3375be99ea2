"""Dynamics of rigid blocks, hard or soft contacts, one cone program per implicit step
(docs/rigid_blocks.md, "Dynamics").

Per step ``dt`` the unknowns are the contact impulses ``p = (p_n, p_t)`` at both end points of
every interface; the blocks' velocities after the step follow from them,
``v+ = v_free + M^-1 G' p`` with ``v_free = v + dt M^-1 f`` (gravity, pseudo-force of a base
acceleration). The impulses solve

    min_p  1/2 p' W p + b' p     s.t.  |p_t| <= mu p_n + c L dt / 2,  p_n >= -f_t L dt / 2

    W = G M^-1 G' + C / dt^2,   b = G v_free + (g / dt + s, -q_t / (k_t dt))

whose optimality conditions are the contact laws: the modified relative velocity
``u~ = W p + b`` lies in the dual cone (``u~_n >= mu |u~_t|``) and is orthogonal to ``p``.

* *Hard blocks* (``C = 0``): ``u~_n = u_n + g/dt + s`` is the gap at the end of the step over
  dt: no overlap, implicit (backward Euler in the velocities, positions updated with ``v+``).
* *Soft blocks*: contact springs ``k_n``, ``k_t`` [Pa/m] per unit length, ``C = diag(1 / (k L/2))``:
  the normal force is ``k_n`` times the overlap at the end of the step, the tangential one the
  spring force ``q_t`` carried over plus ``k_t`` times the elastic slip; the same program, one
  diagonal more.
* *Coulomb friction* (no dilation): the cone program alone gives the associated law (sliding
  lifts the block by ``mu |u_t| dt``). The shift ``s = mu |u~_t|`` of the previous solve
  turns it into Coulomb's (De Saxce and Feng 1991); the step repeats the solve until ``s``
  settles (a fixed point), starting from the last step's ``s``.

Contacts are the interfaces of the initial configuration, each end point riding on one block
(``a``) and measured against the line of the other (``b``) as it moves and turns: right for
sliding, rocking and toppling over distances small against the blocks, not for blocks that
tumble away and meet new neighbours.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np
import scipy.sparse as sp

from fdem.blocks.assembly import BlockSystem
from fdem.blocks.cone import ConeProblem, solve_cone
from fdem.blocks.limit import BlockSystemError, cross2
from fdem.blocks.strength import Strength, interface_strength

__all__ = ["BlockDynamics", "StepInfo", "History"]


def _rot(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]])


@dataclass
class StepInfo:
    """What one step cost: cone programs ``solves``, interior-point ``iterations``, ``seconds``;
    ``converged``: the Coulomb fixed point settled within ``max_fixed_point`` solves (else the
    step used the last solve, an associated-flow error of the size of the last change)."""

    solves: int
    iterations: int
    seconds: float
    converged: bool = True


@dataclass
class History:
    """Recorded every ``every`` steps: ``t`` (m,), ``x`` (m, n, 2) centroids, ``theta`` (m, n),
    ``v`` (m, n, 3); cost totals ``solves``, ``iterations``, ``seconds``; ``unconverged``: steps
    whose Coulomb fixed point did not settle."""

    t: list = field(default_factory=list)
    x: list = field(default_factory=list)
    theta: list = field(default_factory=list)
    v: list = field(default_factory=list)
    solves: int = 0
    iterations: int = 0
    seconds: float = 0.0
    unconverged: int = 0

    def arrays(self):
        return np.array(self.t), np.array(self.x), np.array(self.theta), np.array(self.v)


class BlockDynamics:
    """Rigid blocks of ``system`` with ``density`` [kg/m^3], interface ``strengths`` (by tag),
    ``gravity`` [m/s^2] (a vector: tilt it to incline a plane), ``contact`` ``"hard"`` or
    ``"soft"`` (then ``k_n``, ``k_t`` [Pa/m]), and an optional ``base_acceleration(t) -> (ax, ay)``
    [m/s^2] of the supports: motion is computed relative to them (the free blocks feel
    ``-m a_base``). ``factor``: strength-reduction factor F on ``c``, ``tan(phi)``, ``f_t``."""

    def __init__(self, system: BlockSystem, density: float, strengths: Mapping[int, Strength],
                 gravity=(0.0, -9.81), contact: str = "hard", k_n: float | None = None, k_t: float | None = None,
                 base_acceleration: Callable[[float], tuple] | None = None, fixed_point_tol: float = 1e-6,
                 max_fixed_point: int = 25, factor: float = 1.0):
        if contact not in ("hard", "soft"):
            raise BlockSystemError(f"contact must be 'hard' or 'soft', got {contact!r}")
        if contact == "soft" and not (k_n and k_n > 0 and k_t and k_t > 0):
            raise BlockSystemError(f"soft contact needs positive spring stiffnesses k_n, k_t [Pa/m], got {k_n}, {k_t}")
        if not density > 0:
            raise BlockSystemError(f"density must be positive, got {density}")
        self.system, self.contact = system, contact
        self.gravity = np.asarray(gravity, float)
        self.base_acceleration = base_acceleration
        self.tol, self.max_fp = fixed_point_tol, max_fixed_point
        s = system
        free = s.free
        self.free = free
        self.mass = density * s.area
        self.inertia = density * s.polar_moment
        a, b = s.blocks[:, 0].copy(), s.blocks[:, 1].copy()
        keep = ~(s.fixed[a] & s.fixed[b])
        a, b, nrm = a[keep], b[keep], s.normal[keep].copy()
        # the contact points ride on a free block where one is free
        swap = s.fixed[a] & ~s.fixed[b]
        a[swap], b[swap] = b[swap], a[swap]
        nrm[swap] *= -1
        iface = np.flatnonzero(keep)
        self.a, self.b = np.repeat(a, 2), np.repeat(b, 2)
        p0 = s.ends[iface].reshape(-1, 2)
        self.nu0 = np.repeat(nrm, 2, axis=0)
        self.ra0 = p0 - s.centroid[self.a]       # point in a's frame
        self.rb0 = p0 - s.centroid[self.b]       # the same point in b's frame
        L = np.repeat(s.length[iface], 2)
        mu, c, ft = interface_strength(np.repeat(s.tag[iface], 2), strengths, factor)
        self.mu, self.coh, self.ten = mu, c * L / 2, ft * L / 2      # [-], [N/m], [N/m] per point
        self.half_length = L / 2
        if contact == "soft":
            self.k_n, self.k_t = k_n * L / 2, k_t * L / 2          # [N/m per m] per point
        self.q_t = np.zeros(len(L))                                 # tangential spring forces [N/m]
        self.shift = np.zeros(len(L))                               # Coulomb shift of the last step
        self.x = s.centroid.copy()
        self.theta = np.zeros(s.n_blocks)
        self.v = np.zeros((s.n_blocks, 3))
        self.t = 0.0
        self.x0 = s.centroid.copy()
        self.row = np.full(s.n_blocks, -1)
        self.row[free] = np.arange(len(free))

    # ----------------------------------------------------------------- geometry of the contacts
    def _contacts(self):
        """Current gap ``g`` (m,), normal, tangent and the (2m, 3 n_free) velocity map G."""
        a, b = self.a, self.b
        ra = _rot(self.theta[a], self.ra0)
        rb = _rot(self.theta[b], self.rb0)
        pa, pb = self.x[a] + ra, self.x[b] + rb
        nu = _rot(self.theta[b], self.nu0)
        tau = np.column_stack([-nu[:, 1], nu[:, 0]])
        gap = ((pa - pb) * nu).sum(axis=1)
        rb_now = pa - self.x[b]   # b's material point under a's point
        m = len(a)
        rows, cols, vals = [], [], []
        for k, d in ((0, nu), (1, tau)):
            for blk, r, sign in ((a, ra, 1.0), (b, rb_now, -1.0)):
                ok = self.row[blk] >= 0
                rr = 2 * np.flatnonzero(ok) + k
                cc = 3 * self.row[blk[ok]]
                # u = v + omega x r: d . u = d_x v_x + d_y v_y + omega (r x d)
                for j, val in ((0, d[ok, 0]), (1, d[ok, 1]), (2, cross2(r[ok], d[ok]))):
                    rows.append(rr)
                    cols.append(cc + j)
                    vals.append(sign * val)
        G = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(2 * m, 3 * len(self.free)))
        return gap, G

    # ----------------------------------------------------------------- one step
    def step(self, dt: float) -> StepInfo:
        """Advance by ``dt`` [s]: the cone program of the module docstring, repeated on the
        Coulomb shift until it settles; then ``v = v+``, ``x += dt v+``."""
        t0 = time.perf_counter()
        free = self.free
        m_, J_ = self.mass[free], self.inertia[free]
        Minv = np.column_stack([1 / m_, 1 / m_, 1 / J_]).ravel()
        f = np.zeros((len(free), 3))
        acc = self.gravity.copy()
        if self.base_acceleration is not None:
            acc = acc - np.asarray(self.base_acceleration(self.t + dt), float)
        f[:, 0], f[:, 1] = m_ * acc[0], m_ * acc[1]
        v_free = self.v[free].ravel() + dt * Minv * f.ravel()
        gap, G = self._contacts()
        m = len(gap)
        # scales: impulses by m_s V_s, velocities by V_s
        m_s = float(m_.mean())
        V_s = max(float(np.linalg.norm(self.gravity)) * dt, 1e-12)
        P_s = m_s * V_s
        W = (G @ sp.diags(Minv) @ G.T).tocsc() * m_s
        n_idx, t_idx = 2 * np.arange(m), 2 * np.arange(m) + 1
        if self.contact == "soft":
            comp = np.zeros(2 * m)
            comp[n_idx] = 1 / (self.k_n * dt * dt)
            comp[t_idx] = 1 / (self.k_t * dt * dt)
            W = W + sp.diags(comp * m_s)
        base = G @ v_free
        base[n_idx] += gap / dt
        if self.contact == "soft":
            base[t_idx] -= self.q_t / (self.k_t * dt)
        # cones on p/P_s: SOC (mu p_n + c dt, p_t), and p_n >= -f_t dt
        A_t = sp.csc_matrix((-np.ones(m), (np.arange(m), n_idx)), shape=(m, 2 * m))
        r0 = 2 * np.arange(m)
        A_c = sp.csc_matrix((np.r_[-self.mu, -np.ones(m)], (np.r_[r0, r0 + 1], np.r_[n_idx, t_idx])),
                            shape=(2 * m, 2 * m))
        b_c = np.zeros(2 * m)
        b_c[r0] = self.coh * dt / P_s
        b_t = self.ten * dt / P_s
        A = sp.vstack([A_t, A_c], format="csc")
        bb = np.r_[b_t, b_c]
        # start from the last step's shift: while blocks keep sliding it is nearly the answer
        shift = self.shift.copy()
        solves = its = 0
        while True:
            q = base.copy()
            q[n_idx] += shift
            r = solve_cone(ConeProblem(A, bb, q / V_s, 0, m, m, P=W), tol=1e-10, what=f"dynamic step at t = {self.t:.6g} s")
            solves += 1
            its += r.iterations
            if r.status != "solved":
                raise BlockSystemError(f"dynamic step at t = {self.t:.6g} s: the cone program is {r.status} "
                                       f"(status {r.raw_status}): no contact impulses satisfy the laws")
            p = r.x * P_s
            u = (W @ r.x) * V_s + base           # modified relative velocity without the shift
            new = self.mu * np.abs(u[t_idx])
            done = np.max(np.abs(new - shift), initial=0.0) <= self.tol * max(1.0, np.max(np.abs(base), initial=0.0))
            shift = new
            if done or solves >= self.max_fp:
                break
        dv = Minv * (G.T @ p)
        v_new = v_free + dv
        self.v[free] = v_new.reshape(-1, 3)
        self.x[free] += dt * self.v[free, :2]
        self.theta[free] += dt * self.v[free, 2]
        if self.contact == "soft":
            self.q_t = p[t_idx] / dt
        self.shift = shift
        self.t += dt
        return StepInfo(solves, its, time.perf_counter() - t0, bool(done))

    def run(self, t_end: float, dt: float, every: int = 1) -> History:
        """Step to ``t_end`` [s] with ``dt`` [s], recording every ``every`` steps."""
        if not (dt > 0 and t_end >= self.t):
            raise BlockSystemError(f"need dt > 0 and t_end >= t = {self.t}, got dt = {dt}, t_end = {t_end}")
        h = History()
        self._record(h)
        n = int(round((t_end - self.t) / dt))
        for i in range(n):
            info = self.step(dt)
            h.solves += info.solves
            h.iterations += info.iterations
            h.seconds += info.seconds
            h.unconverged += not info.converged
            if (i + 1) % every == 0 or i == n - 1:
                self._record(h)
        return h

    def _record(self, h: History) -> None:
        h.t.append(self.t)
        h.x.append(self.x.copy())
        h.theta.append(self.theta.copy())
        h.v.append(self.v.copy())
