"""Sleeping regions: parts of the scene at rest stop being stepped until something reaches them.

In a failing slope most triangles sit still (the base, the far crest, the settled deposit). A
*region* is ``region_size`` consecutive triangles of the exploded mesh (Hilbert-numbered, so a
compact patch; :mod:`fdem.mesh.order`). Sleeping acts in dynamic (undamped) stages, the runout:
a damped stage is a relaxation whose answer is the equilibrium it reaches, and a frozen region
would keep its residual force (the unbalanced-force ratio would never fall), so a damped step
wakes every region and none falls asleep (``SleepPolicy(damped_stages=True)`` overrides).

Every ``check_interval`` of simulated time the solver asks each awake region whether it is at
rest: whether any of its nodes has moved farther than

    ``delta = acceleration_ratio |g| t_q^2 / 2``

from where it was when the region's quiet window began (:func:`fdem.kernels.sleeping.node_drifted`),
``t_q = quiet_time`` (default one response time ``T = 4 H / c_s`` of the model,
:func:`fdem.workflow.stages.response_time`). A node that rings about its rest position by less
than ``delta`` is at rest; one whose unbalanced force accelerates it at more than
``acceleration_ratio |g|``, or that creeps faster than ``2 delta / t_q``, leaves it within the
window. A drifted region starts a new window. A region at rest for ``t_q`` falls asleep:

* its nodes' velocities are set to exactly zero; the kinetic energy ``sum 1/2 m' |v|^2`` this
  removes is booked in the ledger as ``sleep_dissipation`` (:class:`fdem.solve.ledger.EnergyLedger`);
* its triangles are no longer stepped (:func:`fdem.kernels.stepping.step_exploded_elastic`
  takes the awake triangles as ranges), and crack elements between two sleeping regions are no
  longer evaluated: their forces, frozen with the nodes, are kept in ``f_frozen`` (n_nodes, 2)
  and copied into the interaction forces at every step, so ``f_interaction`` stays the whole
  force on every node (the unbalanced-force ratio reads it). Crack elements with one awake side
  and all contact pairs are evaluated every step;
* its frozen strain energy and potential moments enter the ledger rows unchanged.

A region wakes (velocities zero, stepped again) when

* the interaction force on one of its watched nodes changes from the force it fell asleep
  with (:func:`fdem.kernels.sleeping.force_changed`): in any one step by more than
  ``wake_ratio m |g|`` (an impact: a block that lands wakes the region in the step its force
  arrives, before the nodes move), or on average over the steps since the last check by more
  than ``2 m delta / t_q^2 = acceleration_ratio m |g|`` (a load that persists: the rest test's
  own bound, a change that would carry the free node farther than ``delta`` within ``t_q``).
  The mean lets a neighbour ring without waking the region (its force swings about zero), as
  the rest test lets a region ring. The watched nodes are the sleeping nodes of crack elements
  with an awake side and of contact's contactor triangles;
* the load changes: gravity (:meth:`~fdem.solve.simulation.Simulation.set_gravity`), the
  strengths (a strength-reduction factor, holding the crack elements elastic: the crack set's
  ``constants_version``) or the inertial masses (density scaling): every region wakes; and
  :meth:`~fdem.solve.simulation.Simulation.wake` for changes made by hand.

Regions with a prescribed non-zero or time-dependent velocity never sleep. The state (which
regions sleep, since when they are quiet, the frozen and reference forces, the frozen energies)
is part of :meth:`~fdem.solve.simulation.Simulation.state_dict`, so a restart continues bit for
bit.

References: sleeping ("deactivation") of bodies at rest is standard in rigid-body and discrete
element engines (e.g. Erleben 2005, *Stable, robust and versatile multibody dynamics
animation*, ch. 3; Bullet and PhysX "sleeping"); here it is applied to regions of a deformable
mesh, with the wake test on the force (the physical cause) rather than on a neighbour's state.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np
from fdem.kernels import sleeping as ks
from fdem.kernels.stepping import BLOCK

__all__ = ["SleepPolicy", "Sleeping", "awake_ranges"]


@dataclass(frozen=True)
class SleepPolicy:
    """When regions sleep and wake (see the module docstring).

    region_size : triangles per region [-] (consecutive, Hilbert-ordered: a compact patch)
    acceleration_ratio : the largest unbalanced acceleration of a node at rest, as a fraction of ``|g|`` [-]
    wake_ratio : the force change in one step that wakes a sleeping node, as a fraction of its weight [-]
    quiet_time : how long [s] a region must stay at rest before it sleeps (default one response time ``T``)
    check_interval : simulated time [s] between rest checks (default ``quiet_time / 4``)
    damped_stages : let regions sleep in damped (quasi-static) stages too (default False)
    """

    region_size: int = 128
    acceleration_ratio: float = 1e-3
    wake_ratio: float = 1.0
    quiet_time: float | None = None
    check_interval: float | None = None
    damped_stages: bool = False

    def __post_init__(self):
        if int(self.region_size) < 1:
            raise ValueError(f"SleepPolicy.region_size must be >= 1, got {self.region_size!r}")
        for name in ("acceleration_ratio", "wake_ratio"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"SleepPolicy.{name} must be a positive finite number, got {value!r}")
        for name in ("quiet_time", "check_interval"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"SleepPolicy.{name} must be a positive finite number or None, got {value!r}")


def awake_ranges(awake: np.ndarray, region_size: int, n_tri: int, block: int = BLOCK) -> np.ndarray:
    """(n_items, 2) int64 half-open triangle ranges ``[start, end)`` covering the awake regions,
    runs of consecutive awake regions split into items of at most ``block`` triangles (one
    parallel work item each)."""
    awake = np.asarray(awake, dtype=bool)
    if not awake.any():
        return np.zeros((1, 2), dtype=np.int64)  # one empty item: the kernel steps nothing
    edge = np.diff(np.r_[0, awake.astype(np.int8), 0])
    starts = np.flatnonzero(edge == 1) * region_size
    ends = np.minimum(np.flatnonzero(edge == -1) * region_size, n_tri)
    items = []
    for a, b in zip(starts.tolist(), ends.tolist()):
        cuts = list(range(a, b, block)) + [b]
        items.extend(zip(cuts[:-1], cuts[1:]))
    return np.ascontiguousarray(np.array(items, dtype=np.int64).reshape(-1, 2))


class Sleeping:
    """The sleeping state of one simulation and its decisions (module docstring).

    The simulation calls :meth:`before_forces` before its providers add their forces,
    :meth:`after_forces` after them (the wake test), :meth:`ranges` for the kernel and
    :meth:`after_step` after the nodes moved (the quiet test on check steps).

    Attributes
    ----------
    awake : (n_regions,) bool
    quiet_since : (n_regions,) float, the time [s] since which a region has been at rest (NaN: no window)
    x_ref : (n_nodes, 2) positions [m] at the start of each region's quiet window
    f_frozen : (n_nodes, 2) forces [N/m] of the crack elements no longer evaluated
    f_sleep : (n_nodes, 2) interaction force [N/m] a sleeping node fell asleep with
    stepped : triangle-steps taken (sum over steps of the triangles stepped)
    """

    def __init__(self, sim, policy: SleepPolicy):
        if not sim.exploded:
            raise ValueError("sleeping needs an exploded mesh (node 3t + k is corner k of triangle t)")
        g = float(np.linalg.norm(sim.gravity))
        if not g > 0:
            raise ValueError("sleeping sets its limits from gravity; this model has none")
        if sim.cracks is not None and sim.cracks.scheme != "colour":
            raise ValueError("sleeping needs a crack set with the colour scheme")
        model = sim.model
        topo = model.topology
        self.policy = policy
        self.rs = int(policy.region_size)
        self.n_tri = int(model.n_triangles)
        self.n_regions = -(-self.n_tri // self.rs)
        y = topo.x0[:, 1]
        height = float(y.max() - y.min())
        _, mu = model.lame_arrays()
        cs = float(np.sqrt(mu / model.property_array("density")).min())
        response = 4.0 * height / cs  # fdem.workflow.stages.response_time, the shear-beam period
        self.quiet_time = float(policy.quiet_time or response)
        self.check_interval = float(policy.check_interval or self.quiet_time / 4.0)
        self.delta = 0.5 * policy.acceleration_ratio * g * self.quiet_time ** 2
        weight = sim.state.mass * g
        self.f_tol2 = np.ascontiguousarray((policy.wake_ratio * weight) ** 2)  # one step
        self.f_mean_tol2 = np.ascontiguousarray((2.0 * sim.state.mass * self.delta / self.quiet_time ** 2) ** 2)
        self.f_sum = np.zeros((model.n_nodes, 2))  # sum of the watched nodes' force changes since the last check
        self.sum_steps = 0
        # regions with a moving support never sleep
        moving = (sim.flags != 0) & (np.abs(sim.v_prescribed).sum(1) > 0)
        if model.has_time_dependent_velocity:
            moving = moving | (sim.flags != 0)
        self.can_sleep = np.ones(self.n_regions, dtype=bool)
        self.can_sleep[np.unique(np.flatnonzero(moving) // (3 * self.rs))] = False
        self.crack_regions = (np.asarray(topo.crack_triangles, dtype=np.int64) // self.rs
                              if topo.n_cracks else np.zeros((0, 2), dtype=np.int64))
        self.awake = np.ones(self.n_regions, dtype=bool)
        self.quiet_since = np.full(self.n_regions, np.nan)
        self.x_ref = np.zeros((model.n_nodes, 2))  # positions at the start of each region's quiet window
        self.f_frozen = np.zeros((model.n_nodes, 2))
        self.f_sleep = np.zeros((model.n_nodes, 2))
        self.frozen_sums = np.zeros((self.n_regions, 3))  # strain, sum m g.x, sum f_ext.x of each region
        self.need_reference = np.zeros(self.n_regions, dtype=bool)  # take f_sleep at the next force pass
        self.stepped = 0
        self._skipped = np.zeros(topo.n_cracks, dtype=bool)  # crack elements between sleeping regions
        self._ranges: np.ndarray | None = None
        self._watch: np.ndarray | None = None
        self._n_contactors = -1
        self._signature = self._load_signature(sim)
        self._partial = np.zeros((sim._partial.shape[0] + self.n_regions + 1, sim._partial.shape[1]))

    # ------------------------------------------------------------------ state
    @property
    def any_asleep(self) -> bool:
        return not self._all_awake

    @property
    def _all_awake(self) -> bool:
        return bool(self.awake.all())

    @property
    def fraction_asleep(self) -> float:
        """Fraction of the triangles asleep [-]."""
        if self._all_awake:
            return 0.0
        sizes = np.full(self.n_regions, self.rs)
        sizes[-1] = self.n_tri - self.rs * (self.n_regions - 1)
        return float(sizes[~self.awake].sum() / self.n_tri)

    def _load_signature(self, sim) -> tuple:
        cracks = sim.cracks
        return (float(sim.gravity[0]), float(sim.gravity[1]),
                None if cracks is None else int(cracks.constants_version), sim.inertia is None,
                None if sim.inertia is None else float(sim._scaled_dt))

    def ranges(self) -> np.ndarray | None:
        """The awake triangles as kernel work items, or ``None`` when every region is awake."""
        if self._all_awake:
            return None
        if self._ranges is None:
            self._ranges = awake_ranges(self.awake, self.rs, self.n_tri)
        return self._ranges

    def partial(self, n_items: int) -> np.ndarray:
        """A work array of ``n_items`` rows for the kernel's per-item sums."""
        return self._partial[:max(1, n_items)]

    def asleep_sums(self) -> tuple[float, float, float]:
        """Frozen strain energy, ``sum m g . x`` and ``sum f_ext . x`` of the sleeping regions [J/m]."""
        if self._all_awake:
            return 0.0, 0.0, 0.0
        s = self.frozen_sums[~self.awake].sum(axis=0)
        return float(s[0]), float(s[1]), float(s[2])

    # ------------------------------------------------------------------ changes
    def wake_all(self, sim) -> None:
        """Every region awake: the crack set evaluates every element again."""
        if not self._all_awake and sim.cracks is not None:
            sim.cracks.set_awake(None)
        self.awake[:] = True
        self.quiet_since[:] = np.nan
        self.need_reference[:] = False
        self.f_sum[:] = 0.0
        self.sum_steps = 0
        self.f_frozen[:] = 0.0
        self._skipped[:] = False
        self._changed()

    def _changed(self) -> None:
        self._ranges = None
        self._watch = None

    def _update_cracks(self, sim) -> None:
        """Move crack elements between evaluated and frozen after regions changed state: an
        element is frozen when both its regions sleep. Positions have not moved since the
        elements were last evaluated, so the forces taken out of (or put into) ``f_frozen`` are
        those they had (re-evaluating an element at the same positions changes nothing)."""
        cracks = sim.cracks
        if cracks is None or cracks.n_cracks == 0:
            return
        cr = self.crack_regions
        skipped = ~(self.awake[cr[:, 0]] | self.awake[cr[:, 1]]) & ~cracks.broken
        woken = np.flatnonzero(self._skipped & ~skipped)
        frozen = np.flatnonzero(skipped & ~self._skipped)
        step = sim.state.step
        if woken.size:
            f = np.zeros_like(self.f_frozen)
            cracks.add_element_forces(sim.state.x, f, woken, step)
            self.f_frozen -= f
        if frozen.size:
            cracks.add_element_forces(sim.state.x, self.f_frozen, frozen, step)
        self._skipped = skipped
        cracks.set_awake(None if not skipped.any() else ~skipped)

    def _watched_nodes(self, sim) -> np.ndarray:
        """Sleeping nodes that an evaluated force reaches: nodes of sleeping triangles on crack
        elements with an awake side, and of contactor triangles."""
        if self._watch is not None:
            return self._watch
        asleep_tri = np.zeros(self.n_tri, dtype=bool)
        asleep_tri[:] = ~np.repeat(self.awake, self.rs)[:self.n_tri]
        mark = np.zeros(self.n_tri, dtype=bool)
        if sim.cracks is not None and sim.cracks.n_cracks:
            ct = np.asarray(sim.model.topology.crack_triangles, dtype=np.int64)
            border = ~self._skipped & ~sim.cracks.broken
            mark[ct[border].ravel()] = True
        if sim.contact is not None:
            mark[np.asarray(sim.contact.active, dtype=np.int64)] = True
        tris = np.flatnonzero(mark & asleep_tri)
        self._watch = np.ascontiguousarray((3 * tris[:, None] + np.arange(3)[None, :]).ravel().astype(np.int64))
        return self._watch

    # ------------------------------------------------------------------ the step
    def before_forces(self, sim, f_int: np.ndarray | None) -> None:
        """Wake everything if the load changed; set ``f_int`` to the frozen forces (zero when
        nothing sleeps), before the providers add theirs (``None``: no providers)."""
        sig = self._load_signature(sim)
        if sig != self._signature:
            self._signature = sig
            if not self._all_awake:
                self.wake_all(sim)
        if f_int is None:
            return
        if self._all_awake:
            f_int.fill(0.0)
        else:
            np.copyto(f_int, self.f_frozen)

    def after_forces(self, sim, f_int: np.ndarray) -> None:
        """The wake test: take the reference forces of regions that fell asleep at the last
        check; wake the regions whose watched nodes' force changed (before the nodes move, so
        they respond in this step)."""
        if self._all_awake:
            return
        if sim.contact is not None and len(sim.contact.active) != self._n_contactors:
            self._n_contactors = len(sim.contact.active)
            self._watch = None
        if self.need_reference.any():
            nodes = (3 * self.rs * np.flatnonzero(self.need_reference)[:, None]
                     + np.arange(3 * self.rs)[None, :]).ravel()
            nodes = nodes[nodes < 3 * self.n_tri]
            self.f_sleep[nodes] = f_int[nodes]
            self.need_reference[:] = False
        watch = self._watched_nodes(sim)
        if watch.size == 0:
            return
        wake = np.zeros(self.n_regions, dtype=bool)
        n = ks.changed_force_regions(f_int, self.f_sleep, watch, self.f_tol2, self.rs, self.f_sum, wake)
        self.sum_steps += 1
        if sim.state.step % self.check_steps(sim.dt) == 0:  # the mean change since the last check
            n += ks.persistent_force_regions(self.f_sum, self.sum_steps, watch, self.f_mean_tol2, self.rs, wake)
            self.sum_steps = 0
        if n:
            self._wake(sim, wake)

    def _wake(self, sim, wake: np.ndarray) -> None:
        wake &= ~self.awake
        if wake.any():
            self.awake[wake] = True
            self.quiet_since[wake] = np.nan
            nodes = (3 * self.rs * np.flatnonzero(wake)[:, None] + np.arange(3 * self.rs)[None, :]).ravel()
            self.f_sum[nodes[nodes < 3 * self.n_tri]] = 0.0
            self._update_cracks(sim)
            self._changed()

    def after_step(self, sim, check: bool) -> None:
        """Count the stepped triangles; on a check step, put the regions at rest for
        ``quiet_time`` to sleep (module docstring)."""
        r = self.ranges()
        self.stepped += self.n_tri if r is None else int((r[:, 1] - r[:, 0]).sum())
        if not check:
            return
        st = sim.state
        candidates = np.flatnonzero(self.awake & self.can_sleep).astype(np.int64)
        if candidates.size == 0:
            return
        quiet = np.zeros(candidates.size, dtype=np.bool_)
        restart = np.isnan(self.quiet_since[candidates])
        ks.region_drift(st.x, self.x_ref, candidates, self.rs, self.n_tri, self.delta ** 2, restart, quiet)
        self.quiet_since[candidates[restart | ~quiet]] = st.time
        calm = candidates[quiet & ~restart]
        ready = calm[st.time - self.quiet_since[calm] >= self.quiet_time - 0.5 * sim.dt]
        if ready.size == 0:
            return
        nodes = (3 * self.rs * ready[:, None] + np.arange(3 * self.rs)[None, :]).ravel()
        nodes = nodes[nodes < 3 * self.n_tri]
        mass = st.mass if sim.inertia is None else sim.inertia
        sim.ledger.sleep_dissipation += 0.5 * float((mass[nodes] * (st.v[nodes] ** 2).sum(1)).sum())
        st.v[nodes] = 0.0
        out = np.zeros((ready.size, 3))
        f_ext = sim.f_external if sim.use_external else sim._empty
        ks.region_sums(st.x, sim.tc, ready, self.rs, self.n_tri, float(sim.gravity[0]), float(sim.gravity[1]),
                       f_ext, bool(sim.use_external), out)
        self.frozen_sums[ready] = out
        self.awake[ready] = False
        self.need_reference[ready] = True
        self._update_cracks(sim)
        self._changed()

    def check_steps(self, dt: float) -> int:
        """Steps between quiet checks at the step ``dt`` [s]."""
        return max(1, int(round(self.check_interval / dt)))

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self) -> dict:
        return {"awake": self.awake.copy(), "quiet_since": self.quiet_since.copy(), "x_ref": self.x_ref.copy(),
                "f_frozen": self.f_frozen.copy(),
                "f_sleep": self.f_sleep.copy(), "frozen_sums": self.frozen_sums.copy(),
                "f_sum": self.f_sum.copy(), "sum_steps": int(self.sum_steps),
                "need_reference": self.need_reference.copy(), "skipped": self._skipped.copy(),
                "stepped": int(self.stepped), "signature": list(self._signature)}

    def load_state_dict(self, d: dict, sim) -> None:
        self.awake[:] = d["awake"]
        self.quiet_since[:] = d["quiet_since"]
        self.x_ref[:] = d["x_ref"]
        self.f_frozen[:] = d["f_frozen"]
        self.f_sleep[:] = d["f_sleep"]
        self.frozen_sums[:] = d["frozen_sums"]
        self.f_sum[:] = d["f_sum"]
        self.sum_steps = int(d["sum_steps"])
        self.need_reference[:] = d["need_reference"]
        self._skipped[:] = d["skipped"]
        self.stepped = int(d["stepped"])
        self._signature = tuple(d["signature"])
        if sim.cracks is not None:
            sim.cracks.set_awake(None if not self._skipped.any() else ~self._skipped)
        self._changed()
        self._n_contactors = -1
