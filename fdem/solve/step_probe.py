"""The critical time step measured on the model itself, against the bound the solver steps with.

The solver's step (:meth:`fdem.solve.simulation.Simulation.critical_dt`) combines each force
provider's own bound, ``1 / dt^2 = sum_p 1 / dt_p^2``: the exact per-element limit of the
triangles, a Gershgorin bound on the crack springs and a face-to-face bound on the contact
penalty. Every one of them is an upper bound on a frequency, so the step is safe; how much
smaller it is than the model's true limit is what this module measures.

The central-difference step is stable while ``dt <= 2 / omega_max``, ``omega_max^2`` the largest
eigenvalue of ``M^-1 K`` (Belytschko et al. 2014, sec. 6.3). ``K`` is the tangent stiffness of
the current state, reached through the step itself: with ``v = 0`` one explicit step gives
``v_{n+1/2} = dt M^-1 f(x)``, so for a small displacement ``u`` of the free nodes

    M^-1 K u = -(a(x + eps u) - a(x)) / eps,      a(x) = v_{n+1/2} / dt,

every provider's law evaluated exactly as the run evaluates it (one source for each law).
The largest eigenvalue of its symmetric form ``M^-1/2 K M^-1/2`` on the free degrees of freedom
is found by implicitly restarted Lanczos (ARPACK through :func:`scipy.sparse.linalg.eigsh`: a
few dozen products where power iteration needs thousands, the top of a mesh's spectrum being
crowded). The state is restored after every product (:meth:`Simulation.state_dict`), so a probe
changes nothing in the run.

What the probe does not see: forces that load on velocities, above all the contact's tangential
springs (they load on slip increments ``v dt``), and the stiffness of contacts that have not
formed yet. The springs can be loaded by giving the step ``v = u / dt`` as well, but the response
is then one-sided wherever a contact slides at its friction cap, not a matrix; measured so
(``cases/benchmarks/stable_step_margin.py``, power iteration), they lowered the critical step of
the four-slope runouts by 0 to 3 % (``docs/benchmarks.md``, "How far the step is below the
critical one"). Both are why the solver keeps its bounds.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh

from fdem.solve.model import FIX_X, FIX_Y

__all__ = ["StepProbe", "measured_critical_dt", "element_size", "velocity_readers", "unmeasurable"]


@dataclass(frozen=True)
class StepProbe:
    """What :func:`measured_critical_dt` found.

    ``critical_dt`` [s] ``2 / omega_max`` of the model at the probed state; ``omega_max``
    [rad/s]; ``bound_dt`` [s] the solver's combined critical step and ``limits`` its parts by
    provider [s]; ``step_dt`` [s] the step the run takes (``dt_fraction`` of the bound);
    ``steps`` the model steps the eigensolver took; ``converged`` whether it met its
    tolerance (else the best estimate it had, a lower bound on ``omega_max``); ``mode_nodes``
    the five nodes where the highest mode is largest (where the limit lives)."""
    critical_dt: float
    omega_max: float
    bound_dt: float
    limits: dict = field(default_factory=dict)
    step_dt: float = float("nan")
    steps: int = 0
    converged: bool = False
    mode_nodes: tuple = ()

    @property
    def margin(self) -> float:
        """How many times the solver's bound the measured critical step is (>= 1: the bound is safe)."""
        return self.critical_dt / self.bound_dt

    @property
    def step_share(self) -> float:
        """The run's step as a fraction of the measured critical step."""
        return self.step_dt / self.critical_dt

    def as_dict(self) -> dict:
        return {"critical_dt_s": self.critical_dt, "omega_max_rad_s": self.omega_max, "bound_dt_s": self.bound_dt,
                "limits_s": {k: float(v) for k, v in self.limits.items()}, "step_dt_s": self.step_dt,
                "margin": self.margin, "step_share": self.step_share, "steps": self.steps,
                "converged": self.converged, "mode_nodes": [int(n) for n in self.mode_nodes]}


def _free_dofs(sim) -> np.ndarray:
    """(n_nodes, 2) mask of the degrees of freedom the step moves freely; a supported one has
    its velocity prescribed (:data:`fdem.solve.model.FIX_X`, ``FIX_Y``), so it is held at zero
    in the probe (the eigenproblem of the free part, ``P M^-1 K P``)."""
    return np.column_stack([(sim.flags & FIX_X) == 0, (sim.flags & FIX_Y) == 0])


def element_size(x: np.ndarray, triangles: np.ndarray) -> float:
    """The mean element size [m], ``sqrt(2 A)`` of the mean triangle area ``A``."""
    a = x[triangles[:, 1]] - x[triangles[:, 0]]
    b = x[triangles[:, 2]] - x[triangles[:, 0]]
    return float(np.sqrt(np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).mean()))


def velocity_readers(sim) -> list[str]:
    """What in ``sim`` reads velocities besides the contact's tangential springs (which the probe
    leaves out, "What the probe does not see" above), by name: viscous triangles (element
    damping), contact damping, and any force provider but crack elements and contact (a viscous
    boundary). Each lowers the critical step of central differences (Belytschko et al. 2014,
    eq. 6.3.22), and none is in a probe at rest."""
    from fdem.physics.contact import ContactSet
    from fdem.physics.cracks import CrackSet

    readers = ["viscous triangles (element damping)"] if sim.use_viscous else []
    for p in sim.providers:
        if isinstance(p, ContactSet):
            if p.damping_ratio > 0.0:
                readers.append(f"contact damping (ratio {p.damping_ratio:g})")
        elif not isinstance(p, CrackSet):
            readers.append(type(p).__name__)
    return readers


def unmeasurable(sim) -> str:
    """Why a probe at rest cannot measure ``sim``'s limit (``""``: it can): it steps on the GPU
    (the probe runs on the host), or forces read velocities (:func:`velocity_readers`), which
    lower the critical step where the probe does not see them. The one check the probe, a
    stage stepping from it and the workflow that asks for it make."""
    if sim._device is not None:
        return "it steps on the GPU (backend 'cuda'), and the probe runs on the host"
    readers = velocity_readers(sim)
    if readers:
        return (f"forces read velocities ({', '.join(readers)}) and lower the critical step, which a probe at rest "
                "does not see")
    return ""


def critical_or_bounds(sim) -> tuple[float | None, str]:
    """The measured critical step of ``sim`` [s] (:func:`measured_critical_dt`), or ``None``
    and why when the probe failed or did not converge: the caller then steps, or prices, from
    the bounds rather than end a run hours in. The model must be measurable
    (:func:`unmeasurable`); the probe reports against the bounds, so a measured step already
    set on ``sim`` is left out while it runs and put back after."""
    held, sim.measured_critical = sim.measured_critical, None
    try:
        probe = measured_critical_dt(sim)
    except (ValueError, ArithmeticError, RuntimeError) as err:  # ARPACK's errors are RuntimeErrors
        return None, f"the step probe failed ({err}): stepped from the bounds"
    finally:
        sim.measured_critical = held
    if probe.converged:
        return probe.critical_dt, ""
    return None, f"the step probe did not converge in {probe.steps} steps: stepped from the bounds"


def measured_critical_dt(sim, max_iterations: int = 400, rtol: float = 1e-6, eps: float | None = None,
                         seed: int = 0) -> StepProbe:
    """Measure the critical central-difference step of ``sim`` at its current state [s].

    ``max_iterations`` Lanczos restarts at most, ``rtol`` the relative accuracy asked of
    ``omega_max^2``; ``eps`` [m] the finite-difference displacement of the node that moves most
    (default ``1e-10`` of the mean element size :func:`element_size`, at least 1000 times the
    round-off of the largest coordinate); ``seed`` the random start
    vector's. Stability asks for the stiffness of infinitesimal motion, and the contact law has
    two scales that bracket ``eps``: a pair counts as touching, not overlapping, until it reaches
    past the other's edges by ``1e-12`` of an altitude
    (:data:`fdem.kernels.contact_pairs.TOUCH_EPS`), a step in force that a smaller ``eps`` reads
    as a huge stiffness; and the overlaps of a pile are micrometres, which a larger ``eps`` opens
    or closes (on a debris pile of 1 m elements 10 um measured a step 2.5 times too long, 0.1 um
    5 % too long, 1e-10 and 1e-11 m agree to 2e-5). Regions asleep (:mod:`fdem.solve.sleeping`)
    are woken for the probe. Each product costs one step of the model plus a restore of its
    state. Returns a :class:`StepProbe`; the simulation's state, crack damage, contact history and
    ledger are as they were."""
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be at least 1, got {max_iterations}")
    if not 0.0 < rtol < 1.0:
        raise ValueError(f"rtol must lie in (0, 1), got {rtol}")
    why = unmeasurable(sim)
    if why:
        raise ValueError(f"the step probe cannot measure this model: {why}")
    bound, limits = sim.critical_dt()
    saved = sim.state_dict()
    x0 = saved["x"]
    if eps is None:  # above the round-off of the coordinates, however far from the origin they lie
        eps = max(1e-10 * element_size(x0, sim.triangles), 1e3 * float(np.spacing(np.abs(x0).max())))
    if not eps > 0.0:
        raise ValueError(f"eps must be positive, got {eps}")
    mass = (sim.inertia if sim.inertia is not None else sim.state.mass)[:, None] * np.ones((1, 2))
    free = _free_dofs(sim)
    sqrt_m = np.sqrt(mass[free])
    matvecs = [0]

    def acceleration(u):
        """``M^-1 f`` at rest after displacing by ``u``."""
        sim.load_state_dict(saved)
        sim.wake()  # a sleeping region's frozen forces would read as no stiffness
        if u is not None:
            sim.set_positions(displace=u)
        sim.state.v[:] = 0.0
        sim.step()
        return sim.state.v / sim.dt

    def symmetric_product(y):
        """``M^-1/2 K M^-1/2 y`` on the free degrees of freedom (symmetric where ``K`` is)."""
        u = np.zeros_like(x0)
        u[free] = np.ravel(y) / sqrt_m
        scale = eps / np.abs(u).max()  # the node that moves most moves eps
        matvecs[0] += 1
        w = -(acceleration(scale * u) - a0) / scale
        return sqrt_m * w[free]

    n = int(free.sum())
    try:
        a0 = acceleration(None).copy()
        v0 = np.random.default_rng(seed).standard_normal(n)
        op = LinearOperator((n, n), matvec=symmetric_product, dtype=np.float64)
        converged = True
        try:
            lam_all, vec = eigsh(op, k=1, which="LA", tol=rtol, maxiter=max_iterations, v0=v0)
        except ArpackNoConvergence as e:
            converged = e.eigenvalues.size > 0
            if not converged:
                raise ValueError(f"the step probe did not converge in {max_iterations} iterations "
                                 f"({matvecs[0]} steps): raise max_iterations") from e
            lam_all, vec = e.eigenvalues, e.eigenvectors
            converged = False
        lam = float(lam_all[0])
    finally:
        sim.load_state_dict(saved)
    if not lam > 0.0:
        raise ValueError(f"the probed model has no positive stiffness (omega_max^2 = {lam!r}): nothing holds it")
    mode = np.zeros_like(x0)
    mode[free] = vec[:, 0] / sqrt_m
    omega = float(np.sqrt(lam))
    nodes = tuple(int(k) for k in np.argsort(-np.abs(mode).sum(axis=1))[:5])
    return StepProbe(critical_dt=2.0 / omega, omega_max=omega, bound_dt=float(bound), limits=dict(limits),
                     step_dt=float(sim.dt), steps=matvecs[0], converged=converged, mode_nodes=nodes)
