"""The time loop (:class:`Simulation`): force providers, automatic stable time step, output frames, guard.

One step (:meth:`Simulation.step`) reads like the algorithm:

1. zero the interaction force array ``f_interaction`` (n_nodes, 2);
2. every registered force provider (crack elements, contact, ...) adds its forces at
   ``x_n``: ``provider.add_forces(x, v, f_interaction, dt, step)``;
3. one fused kernel computes every triangle's internal force and advances its own nodes
   (central differences with gravity, external loads, supports, prescribed velocities,
   damping): :func:`fdem.kernels.stepping.step_exploded` (a conforming mesh takes the
   two-pass :func:`~fdem.kernels.stepping.triangle_pass` + :func:`~fdem.kernels.stepping.node_pass`).

Force providers
---------------
Any object with ``add_forces(x, v, f_interaction, dt, step) -> None`` (add, never assign,
forces [N/m] into ``f_interaction``; ``x`` (n_nodes, 2) are positions at step ``n``, ``v``
velocities at ``n - 1/2``). Optional methods the solver uses when present:

* ``energy_terms() -> dict[str, float]``: energies [J/m] the provider holds or has dissipated
  (e.g. ``{"crack_elastic": ..., "fracture": ...}``), each a column of the ledger and a
  term of its balance;
* ``stable_dt(mass) -> float``: the critical step [s] of the provider's own stiffness on the
  lumped node masses ``mass`` (n_nodes,) [kg/m], e.g. ``min h sqrt(rho / p)`` for a penalty
  ``p``; combined with the triangles' as ``1 / sqrt(sum 1 / dt_i^2)``;
* ``crack_fields() -> dict[str, ndarray]``: (n_crack,) arrays (``damage``, ``broken``, ...)
  written on the crack line cells.
* ``state_dict() -> dict`` and ``load_state_dict(d, x)``: what a checkpoint holds of the
  provider, and its restore (``x`` the restored positions, for providers that keep a
  reference to them).

Energy ledger
-------------
Every history row holds ``kinetic``, ``strain``, ``gravity_potential`` ``-sum m g.(x - x_0)``,
``load_potential`` ``-sum f_ext.(x - x_0)``, ``damping_dissipation``, ``viscous_dissipation``,
``boundary_work`` (work done on the body by supports and prescribed velocities),
``interaction_work`` (work done on the body by the providers' forces, a cross-check),
one column per provider energy term, ``total = kinetic + strain + potentials + provider
terms + dissipations - boundary_work`` and ``balance_error = total - total at the first
record``. With the half-step bookkeeping of :mod:`fdem.kernels.stepping` the balance is
exact for linear forces; what remains measures nonlinearity, round-off and provider errors.
If a provider has no ``energy_terms``, its energy is taken as ``-interaction_work``.
"""
from __future__ import annotations

import math
import sys
from time import perf_counter as _clock  # a clock for the output accounting (``time`` is a state variable here)
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Protocol, runtime_checkable
import numpy as np
from fdem.kernels.stepping import (LEDGER_FIELDS, StepSums, n_blocks, node_pass, step_exploded, step_exploded_elastic, triangle_pass, viscous_power)
from fdem.kernels.triangles import assemble_triangle_forces, deformation_gradients, triangle_stress_state
from fdem.physics.elastic import PLANE_STRAIN
from fdem.physics.stability import combine_stable_dt
from fdem.physics.contact import ContactSet
from fdem.physics.cracks import CrackSet
from fdem.solve.model import Model
from fdem.solve.monitors import MONITOR_QUANTITIES, PointMonitor
from fdem.io import vtk as out
from fdem.io import npz as npz
from fdem.io import history as history_file
from fdem.physics import elastic as elastic
from fdem.solve.damping import Damping, NO_DAMPING
from fdem.solve import density_scaling
from fdem.solve.sleeping import SleepPolicy, Sleeping
from fdem.solve.ledger import EnergyLedger, work_halves
from fdem.solve.cuda_backend import BackendError, CudaBackend, check_backend

__all__ = ["ForceProvider", "State", "InstabilityError", "provider_crack_fields", "Simulation", "StopRequest",
           "STOP", "MONITOR_QUANTITIES", "PointMonitor", "set_default_backend", "default_backend"]

_DEFAULT_BACKEND = "cpu"


def set_default_backend(name: str) -> None:
    """The backend of every later :class:`Simulation` that names none (``fdem run ... --backend``
    sets it for the whole run, as ``--threads`` sets Numba's threads); checked here, so a GPU
    asked for on a machine without one stops before any work."""
    global _DEFAULT_BACKEND
    _DEFAULT_BACKEND = check_backend(name)


def default_backend() -> str:
    """The backend a :class:`Simulation` gets when it names none (``"cpu"`` unless set)."""
    return _DEFAULT_BACKEND


class StopRequest:
    """A stop asked for from outside the time loop (a signal handler), honoured at the next step
    boundary so that the state a checkpoint saves is a whole step, never half of one (the crack
    elements updated and the nodes not yet moved).

    ``pending``: the name of the signal waiting to be honoured, or ``None``; ``received``: the
    last signal asked for (the exit code of the command says which); ``running``: how many
    :meth:`Simulation.run` loops are going (a request with none going cannot wait for a step
    boundary, and :meth:`ask` says so)."""

    def __init__(self):
        self.pending: str | None = None
        self.received: str | None = None
        self.running = 0
        self.forced = False  # a second signal stopped the loop mid-step: its state is no checkpoint

    def ask(self, signal_name: str) -> bool:
        """Ask the running loop to stop; False when no loop is running or a stop was already
        asked for (the caller stops now: then :attr:`forced` says the state may be mid-step)."""
        self.received = signal_name
        if self.running and self.pending is None:
            self.pending = signal_name
            return True
        self.forced = self.forced or bool(self.running)
        return False

    def honour(self) -> None:
        """Raise the requested stop as ``KeyboardInterrupt`` (called between steps)."""
        name, self.pending = self.pending, None
        raise KeyboardInterrupt(f"signal {name}")


STOP = StopRequest()
"""The process's stop request (:func:`fdem.cases.common.stop_cleanly_on_signals` sets it)."""


@runtime_checkable
class ForceProvider(Protocol):
    """Anything that adds interaction forces (crack elements, contact); see the module docstring."""

    def add_forces(self, x: np.ndarray, v: np.ndarray, f_interaction: np.ndarray, dt: float, step: int) -> None:
        ...


@dataclass
class State:
    """The solver state, a struct of arrays.

    Attributes
    ----------
    x : (n_nodes, 2) float64
        Positions at ``time`` [m].
    v : (n_nodes, 2) float64
        Velocities at ``time - dt/2`` (leapfrog) [m/s].
    mass : (n_nodes,) float64
        Lumped masses [kg/m].
    time : float
        [s].
    step : int
        Steps taken.
    u : (n_nodes, 2) float64
        Displacements from the reference positions ``x0`` [m], advanced by the same ``dt v`` as
        ``x`` (:func:`fdem.kernels.stepping.constrain_and_move`) and kept apart from it for the
        crack elements, which read separations from ``u`` (resolved to the round-off of ``u``,
        not of ``x``; see :mod:`fdem.kernels.cracks`). ``x`` and ``x0 + u`` are rounded apart, by
        at most half a spacing of ``x`` a step (:meth:`Simulation._check_positions_kept`).
        ``None`` is taken as zero (a state at its reference positions).
    """

    x: np.ndarray
    v: np.ndarray
    mass: np.ndarray
    time: float = 0.0
    step: int = 0
    u: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.u is None:
            self.u = np.zeros_like(self.x, dtype=np.float64)

    def copy(self) -> "State":
        return State(self.x.copy(), self.v.copy(), self.mass, self.time, self.step, self.u.copy())


class InstabilityError(RuntimeError):
    """The run went unstable; the message says where, when, and what time step to try.

    Attributes: ``step``, ``time``, ``triangle``, ``reason``, ``suggested_dt``, ``state_path``,
    and ``kind``: ``"time step"`` or ``"crushing"``, which the evidence points to
    (:meth:`Simulation._instability_kind`).
    """

    kind = "time step"

    def __init__(self, message: str, step: int, time: float, triangle: int, reason: str,
                 suggested_dt: float, state_path: Path | None):
        super().__init__(message)
        self.step, self.time, self.triangle, self.reason = step, time, triangle, reason
        self.suggested_dt, self.state_path = suggested_dt, state_path


def provider_crack_fields(provider, n_cracks: int) -> dict[str, np.ndarray]:
    """(n_crack,) arrays a provider supplies for the crack line cells: ``crack_fields()`` if it
    has one, else its ``damage`` and ``broken`` attributes when they have one value per crack."""
    fn = getattr(provider, "crack_fields", None)
    if fn is not None:
        return dict(fn())
    found = {}
    for name in ("damage", "broken"):
        try:
            value = getattr(provider, name, None)
        except Exception:  # a property that cannot be evaluated yet
            value = None
        if isinstance(value, np.ndarray) and value.shape == (n_cracks,):
            found[name] = value
    return found


class Simulation:
    """An explicit FDEM simulation of a :class:`~fdem.solve.model.Model`, run in stages.

    Parameters
    ----------
    model : Model
    dt : float, optional
        Time step [s]; default ``dt_fraction`` times the critical step. A value above the critical
        step is refused with a ``ValueError`` that states the stable value.
    dt_fraction : float
        Fraction of the critical step used when ``dt`` is automatic (default 0.8): the
        time-step factor, not to be read as a factor of safety.
    out_dir : path, optional
        Where ``<name>.pvd``, ``<name>_cracks.pvd``, ``<name>_contacts.pvd`` (with a contact
        set), ``history.csv``, pictures and state files go; ``None`` writes nothing.
    name : str
        Base name of the output series.
    progress : bool
        Show a tqdm progress bar in :meth:`run`.
    pictures : bool
        Render a PNG with every output frame: displacement magnitude on the deformed mesh and
        the broken crack elements by failure mode (:func:`fdem.io.pictures.failure_frame`).
    providers : sequence of force providers (see the module docstring).
    output_fields : sequence of str, optional
        Point/cell arrays written to the triangle frames (default all of :meth:`fields`:
        ``displacement``, ``velocity``, the stress tensor, principal stresses and directions,
        von Mises stress, strain, ``property``, ``body``); fewer fields, smaller frames.
    time_cap : float, optional
        A cap [s] on the simulated time of every later :meth:`run` (a smoke run: a case's
        ``--max-time``); a run asked to go beyond it stops at it, and :attr:`time_capped` says so.
    compression : ``"zlib"`` (default), ``None`` (raw) or ``"lzma"``
        Block compression of every VTU frame (sizes and times in ``docs/outputs.md``).
    output_precision : ``"float32"`` (default) or ``"float64"``
        Floating type of the frames' points and fields: float32 halves them and keeps 7
        significant digits, enough to look at; checkpoints keep float64 whatever this says.
    density_scaling : float or None
        Added-mass budget of density-scaled quasi-static stages, a fraction of the model's mass
        (default 0.01, :mod:`fdem.solve.density_scaling`); ``None`` or 0 keeps the real masses
        in every stage. Stages switch scaling on and off (:func:`fdem.workflow.stages.run_stage`,
        :meth:`set_density_scaling`); an exploded mesh and an automatic time step are needed.
    sleeping : bool or :class:`~fdem.solve.sleeping.SleepPolicy`, optional
        Regions at rest stop being stepped until a force reaches them or the load changes
        (:mod:`fdem.solve.sleeping`); ``True`` takes the default policy. Default off. Needs an
        exploded mesh and gravity. :attr:`sleeping` holds the state (``None`` when off).
    backend : ``"cpu"`` or ``"cuda"``, optional
        Default :func:`default_backend` (``"cpu"`` unless a case's ``--backend`` set it). Where the steps run: Numba's CPU loops, or an NVIDIA GPU through numba-cuda
        (:mod:`fdem.solve.cuda_backend`: the same laws, the state on the device during each
        :meth:`run`). ``"cuda"`` without a GPU raises :class:`~fdem.solve.cuda_backend.BackendError`
        here, before any work.
    """

    def __init__(self, model: Model, dt: float | None = None, dt_fraction: float = 0.8, out_dir=None,
                 name: str = "fdem", progress: bool = True, pictures: bool = False, providers=(),
                 output_fields=None, compression: str | None = "zlib", time_cap: float | None = None,
                 density_scaling: float | None = density_scaling.DEFAULT_MASS_BUDGET,
                 sleeping: bool | SleepPolicy | None = None, output_precision: str = "float32",
                 backend: str | None = None):
        if not 0.0 < dt_fraction <= 1.0:
            raise ValueError(f"dt_fraction (fraction of the critical time step) must lie in (0, 1], got {dt_fraction}")
        if density_scaling is not None and not (math.isfinite(density_scaling) and 0.0 <= density_scaling <= 1.0):
            raise ValueError(f"density_scaling (added-mass budget, a fraction of the model's mass) must lie in "
                             f"[0, 1] or be None, got {density_scaling!r}")
        self.backend = check_backend(backend or _DEFAULT_BACKEND)  # before any work: no GPU, no run
        self._device: CudaBackend | None = None
        self.density_scaling = density_scaling or None
        self.inertia: np.ndarray | None = None  # inertial node masses while density-scaled, else None
        self._inertia_kernel: np.ndarray | None = None  # (n_nodes, 2): inertia and its inverse, for the kernels
        self._triangle_stiffness: np.ndarray | None = None  # the triangles' share of S, fixed: computed once
        self._scaled_dt = math.inf
        self.model = model
        self.dt_fraction = dt_fraction
        self.time_cap = time_cap
        self.user_dt = dt
        # the critical step measured on the model (fdem.solve.step_probe) that a stage stepping
        # from it sets for its length (fdem.workflow.stages.Stage.step_from), else None: the bounds
        self.measured_critical: float | None = None
        self.out_dir = Path(out_dir) if out_dir is not None else None
        # set by a caller that writes its own resumable checkpoint when a run is interrupted (a
        # journaled workflow stage): the run then leaves the interrupted state to it, so that
        # the file a resume needs is written first and the state is not written twice
        self.caller_checkpoints_interrupts = False
        self.name = name
        self.progress = progress
        self.pictures = pictures
        self.providers: list = []
        self.cracks: CrackSet | None = None  # the crack-element set among the providers, if any
        self.contact: ContactSet | None = None  # the contact set among the providers, if any
        self.monitors: dict[str, Callable[["Simulation"], float]] = {}
        self.point_monitors: dict[str, PointMonitor] = {}
        topo = model.topology
        self.x0 = np.ascontiguousarray(topo.x0, dtype=np.float64)
        self.triangles = np.ascontiguousarray(topo.triangles, dtype=np.int64)
        self.tc = model.triangle_constants()
        self.state = State(x=self.x0.copy(), v=np.ascontiguousarray(model.initial_velocity, dtype=np.float64).copy(),
                           mass=model.node_mass(), u=np.zeros_like(self.x0))
        self._positions_set_at = 0  # the step at which x and x0 + u were last set together
        self.flags = model.flags.copy()
        self.v_prescribed = model.v_prescribed.copy()
        self.f_interaction = np.zeros((model.n_nodes, 2))
        self.f_external = np.ascontiguousarray(model.external_force, dtype=np.float64)
        self.use_external = model.has_external_force
        self.gravity = model.gravity.astype(float).copy()
        self.use_viscous = bool(np.any(model.viscosity_array() > 0))
        self.exploded = model.is_exploded
        if not self.exploded:
            self._csr = model.node_corner_csr()
            self._corner_force = np.zeros((3 * model.n_triangles, 2))
            self._viscous_stress = np.zeros((model.n_triangles, 4))
        self._empty = np.zeros((1, 2))
        self._partial = np.zeros((n_blocks(model.n_triangles), len(LEDGER_FIELDS)))
        self.triangle_dt = float(model.triangle_critical_dt().min())
        grav_moment = self.state.mass[:, None] * self.gravity * self.x0
        ext_moment = self.f_external * self.x0
        # the potentials are differences of sums over absolute positions: their round-off
        # sets a floor under the energy scale
        roundoff = 1e-13 * float(np.abs(grav_moment).sum() + np.abs(ext_moment).sum())
        self.ledger = EnergyLedger(float(grav_moment.sum()), float(ext_moment.sum()), roundoff)
        self.history: list[dict] = []
        self._history_writer = history_file.HistoryWriter(self.out_dir / "history.csv") if self.out_dir else None
        if compression not in (None, "zlib", "lzma"):
            raise ValueError(f"compression must be None, 'zlib' or 'lzma', got {compression!r}")
        if output_precision not in ("float32", "float64"):
            raise ValueError(f"output_precision must be 'float32' or 'float64', got {output_precision!r}")
        self.compression, self.output_precision = compression, output_precision
        self._series = (out.PvdSeries(self.out_dir, name, compression=compression,
                                      fields=None if output_fields is None else list(output_fields),
                                      precision=output_precision)
                        if self.out_dir else None)
        self._crack_series = (out.PvdSeries(self.out_dir, f"{name}_cracks", compression=compression,
                                            precision=output_precision)
                              if self.out_dir and topo.n_cracks > 0 else None)
        self._contact_series: out.PvdSeries | None = None  # made at the first frame with a contact set
        self._frames = 0
        self._stage = ""
        self._good = self.state.copy()
        self._provider_terms: tuple[dict[str, float], bool] = ({}, True)
        self.last_row: dict | None = None
        self.kinetic_peak = 0.0  # largest kinetic energy of any step since the last history row
        # wall seconds spent on what users read rather than on physics: output frames, history
        # rows (ledger, monitors, history.csv) and checkpoints (fdem.workflow.journal adds those)
        self.output_seconds = {"frames": 0.0, "history": 0.0, "checkpoints": 0.0}
        for p in providers:
            self.add_provider(p)
        self.dt = self._choose_dt()
        self.add_monitor("max_speed", lambda s: float(np.sqrt((s.state.v ** 2).sum(1)).max()))
        self.add_monitor("max_displacement", lambda s: float(np.sqrt(((s.state.x - s.x0) ** 2).sum(1)).max()))
        self.sleeping: Sleeping | None = None
        if self.backend == "cuda":
            self._device = CudaBackend(self)
        self.set_sleeping(sleeping)

    # ------------------------------------------------------------------ setup
    def add_provider(self, provider) -> None:
        """Register a force provider (called in registration order every step)."""
        if not callable(getattr(provider, "add_forces", None)):
            raise TypeError(f"{provider!r} has no add_forces(x, v, f_interaction, dt, step) method")
        if isinstance(provider, CrackSet):
            if self.cracks is not None:
                raise ValueError("a simulation takes one CrackSet; this one already has one")
            if self.contact is not None:
                raise ValueError("register the CrackSet before the ContactSet: contact reads the faces "
                                 "that the crack elements break in the same step")
            self.cracks = provider
        elif isinstance(provider, ContactSet):
            if self.contact is not None:
                raise ValueError("a simulation takes one ContactSet; this one already has one")
            self.contact = provider
        bind = getattr(provider, "bind_displacement", None)
        if callable(bind):  # the crack elements read the state's displacements (State.u)
            bind(self.state.x, self.state.u)
        self.providers.append(provider)
        if hasattr(self, "dt"):
            self.dt = self._choose_dt()

    def add_monitor(self, name: str, fn: Callable[["Simulation"], float]) -> None:
        """Record ``fn(sim)`` as column ``name`` of every history row. A monitor that keeps
        its own record between rows (``fn`` with ``state_dict()`` and ``load_state_dict(d)``,
        e.g. :class:`fdem.results.motion.MotionRecord`) is saved with a checkpoint and restored
        with it."""
        self.monitors[name] = fn

    @property
    def stage(self) -> str:
        """Name of the stage the simulation is running or last ran (the history's ``stage``)."""
        return self._stage

    def add_point_monitor(self, name: str, x: float, y: float) -> "PointMonitor":
        """Watch the material point at ``(x, y)`` [m] of the reference configuration.

        Every history row (``history.csv``) gets the columns ``<name>_ux``, ``<name>_uy`` [m]
        (displacement), ``<name>_vx``, ``<name>_vy`` [m/s] (velocity) and ``<name>_sxx``,
        ``<name>_syy``, ``<name>_sxy`` [Pa] (Cauchy stress, compression negative) of the point,
        displacement and velocity interpolated linearly over the triangle that contains it
        (its barycentric weights), stress that triangle's (constant-strain). The monitor is
        saved with a checkpoint and restored with it (:meth:`state_dict`). A point outside the
        mesh, a name already used or a monitor added after the first history row (its columns
        would be missing from the header) is refused with a ``ValueError``.
        """
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"point monitor name must be a non-empty string, got {name!r}")
        if name in self.point_monitors:
            raise ValueError(f"a point monitor named {name!r} already exists (at "
                             f"({self.point_monitors[name].x:.6g}, {self.point_monitors[name].y:.6g}) m)")
        if self.history:
            raise ValueError(f"point monitor {name!r}: add point monitors before the first history row (this run "
                             f"has {len(self.history)} rows; history.csv's header is fixed by its first row)")
        mon = PointMonitor.locate(name, x, y, self.x0, self.triangles)
        taken = [c for c in mon.columns if c in self.monitors]
        if taken:
            raise ValueError(f"point monitor {name!r}: history column(s) {taken} are already monitors")
        self.point_monitors[name] = mon
        for column, k in zip(mon.columns, range(len(MONITOR_QUANTITIES))):
            self.monitors[column] = (lambda s, m=mon, k=k: m.values(s)[k])
        return mon

    def critical_dt(self) -> tuple[float, dict[str, float]]:
        """The critical (stability limit) step [s] and the limits it combines, by source (while
        density-scaled: the step the scaled masses were chosen for; while a stage steps from a
        measured step, :attr:`measured_critical`)."""
        if self.measured_critical is not None:
            return self.measured_critical, {"measured on the model": self.measured_critical}
        if self.inertia is not None:
            return self._scaled_dt, {"density-scaled nodes": self._scaled_dt}
        limits = {"triangles": self.triangle_dt}
        for p in self.providers:
            fn = getattr(p, "stable_dt", None)
            if fn is not None:
                limits[type(p).__name__] = float(fn(self.state.mass))
        return combine_stable_dt(*limits.values()), limits

    def _choose_dt(self) -> float:
        crit, limits = self.critical_dt()
        if self.user_dt is None:
            return self.dt_fraction * crit
        if not self.user_dt > 0:
            raise ValueError(f"time step must be positive, got {self.user_dt}")
        if self.user_dt > crit:
            parts = ", ".join(f"{k} {v:.6g} s" for k, v in limits.items())
            raise ValueError(
                f"time step {self.user_dt:.6g} s exceeds the stable time step {crit:.6g} s "
                f"(critical step combining: {parts}); use dt <= {crit:.6g} s, or dt=None for the "
                f"automatic {self.dt_fraction * crit:.6g} s (dt_fraction {self.dt_fraction})")
        return float(self.user_dt)

    def set_gravity(self, gx: float, gy: float) -> None:
        """Change gravity [m/s^2] during a run (a gravity-increase trigger), keeping the ledger closed.

        The potential energy ``-sum m g . (x - x0)`` jumps at fixed positions by
        ``-sum m (g_new - g_old) . (x - x0)``: that is work done on the system by the change,
        booked in the ledger as ``gravity_change_work`` (like the work of supports). Masses do not
        change: a gravity factor ``k`` loads the slope as a density factor ``k`` would in statics,
        with the dynamics of the real mass.
        """
        g_new = np.array([gx, gy], dtype=float)
        if not np.all(np.isfinite(g_new)):
            raise ValueError(f"gravity must be finite, got ({gx}, {gy}) m/s^2")
        dg = g_new - self.gravity
        m = self.state.mass[:, None]
        self.ledger.gravity_change_work += -float((m * dg * (self.state.x - self.x0)).sum())
        self.ledger.gravity_moment0 = float((m * g_new * self.x0).sum())
        self.gravity = g_new

    # ------------------------------------------------------------------ density scaling
    @property
    def density_scaled(self) -> bool:
        """True while the nodes carry density-scaled inertial masses."""
        return self.inertia is not None

    @property
    def period_stretch(self) -> float:
        """How much longer the fundamental period is on the current inertial masses [-]
        (1 unscaled; :func:`fdem.solve.density_scaling.period_stretch`)."""
        if self.inertia is None:
            return 1.0
        return density_scaling.period_stretch(self.state.mass, self.inertia)

    def set_density_scaling(self, on: bool, book: bool = True) -> bool:
        """Switch density scaling on (a quasi-static stage) or off (a dynamic one); returns
        whether it is on. Switched on, the nodes get the inertial masses
        :func:`~fdem.solve.density_scaling.inertial_masses` of the largest critical step whose
        added mass stays within the :attr:`density_scaling` budget, and the time step follows
        (``dt_fraction`` of that step). It stays off without a budget, with a user time step or
        on a conforming mesh. The kinetic-energy change at fixed velocities is booked in the
        ledger as ``mass_change_work`` (``book=False``: a restart that restores it instead)."""
        old = self.inertia
        if on and self.density_scaling and self.user_dt is None and self.exploded:
            mass = self.state.mass
            if self._triangle_stiffness is None:
                self._triangle_stiffness = density_scaling.triangle_nodal_stiffness(self.model)
            stiffness = density_scaling.nodal_stiffness(self.model, self.providers, mass, self._triangle_stiffness)
            self._scaled_dt = density_scaling.scaled_critical_step(mass, stiffness, self.density_scaling)
            self.inertia = density_scaling.inertial_masses(mass, stiffness, self._scaled_dt)
            self._inertia_kernel = np.ascontiguousarray(np.column_stack([self.inertia, 1.0 / self.inertia]))
        else:
            self.inertia = self._inertia_kernel = None
        if book and (old is not None or self.inertia is not None):
            before = self.state.mass if old is None else old
            after = self.state.mass if self.inertia is None else self.inertia
            self.ledger.mass_change_work += 0.5 * float(((after - before) * (self.state.v ** 2).sum(1)).sum())
        self.dt = self._choose_dt()
        return self.inertia is not None

    def steps_to(self, t_end: float) -> int:
        """Steps of the current ``dt`` from the current time to ``t_end`` [s], within the time cap
        (what :meth:`run` takes for ``t_end``)."""
        if self.time_cap is not None:
            t_end = min(t_end, self.time_cap)
        return max(0, int(math.ceil((t_end - self.state.time) / self.dt - 1e-9)))

    # ------------------------------------------------------------------ sleeping
    def set_sleeping(self, sleeping: bool | SleepPolicy | None) -> None:
        """Switch region sleeping on (``True`` or a :class:`~fdem.solve.sleeping.SleepPolicy`) or
        off (every region awake again); on, the history gets an ``asleep_fraction`` column."""
        if self.sleeping is not None:
            self.sleeping.wake_all(self)
            self.sleeping = None
        if sleeping and self._device is not None:
            raise BackendError("sleeping regions run on the CPU only; drop sleeping or use backend 'cpu'")
        if sleeping:
            self.sleeping = Sleeping(self, sleeping if isinstance(sleeping, SleepPolicy) else SleepPolicy())
            self.add_monitor("asleep_fraction", lambda s: s.sleeping.fraction_asleep if s.sleeping else 0.0)

    def set_positions(self, x: np.ndarray | None = None, *, displace: np.ndarray | None = None) -> None:
        """Move the nodes by hand: to the positions ``x`` (n_nodes, 2) [m], or by ``displace``
        [m] from where they are, keeping the displacements ``State.u`` beside the positions (the
        crack elements read ``u``; writing ``state.x`` alone would leave them where they were,
        which the next history row or output frame refuses). ``x`` sets ``u = x - x0``, to the
        round-off of ``x``; ``displace`` adds to both."""
        st = self.state
        if (x is None) == (displace is None):
            raise ValueError("set_positions takes the positions x or a displacement displace, one of them")
        if x is not None:
            x = np.asarray(x, dtype=np.float64)
            if x.shape != st.x.shape or not np.isfinite(x).all():
                raise ValueError(f"set_positions: x must be finite, of shape {st.x.shape}, got {x.shape}")
            st.x[:] = x
            st.u[:] = x - self.x0
        else:
            du = np.asarray(displace, dtype=np.float64)
            if du.shape != st.x.shape or not np.isfinite(du).all():
                raise ValueError(f"set_positions: displace must be finite, of shape {st.x.shape}, got {du.shape}")
            st.x[:] += du
            st.u[:] += du
        self._positions_set_at = st.step

    def _check_cracks_bound(self) -> None:
        """Refuse to step a simulation whose crack set another simulation has taken since: the
        set reads the displacements of one state (:meth:`fdem.physics.cracks.CrackSet.bind_displacement`)."""
        if self.cracks is not None and not self.cracks.bound_to(self.state.x):
            raise RuntimeError("this simulation's CrackSet was handed to another Simulation since, and reads that "
                               "one's displacements now; step the newer simulation, or give each simulation a "
                               "CrackSet of its own")

    def _check_positions_kept(self) -> None:
        """Refuse a state whose positions were written without their displacements (a script
        that set ``state.x`` by hand): the crack elements would act on the old ones. Without a
        provider that reads ``u`` it is set to ``x - x0`` instead.

        ``x`` and ``x0 + u`` are advanced by the same ``dt v`` and rounded apart: each step
        rounds ``x`` by at most half the spacing ``eps`` of float64 numbers at its size (and
        ``u`` by far less), and the roundings need not cancel (a constant velocity rounds the
        same way every step; an increment under ``eps/2`` moves ``u`` and not ``x``). The gap
        allowed is ``(1000 + n/2) eps`` after ``n`` steps since they were last set together
        (start, :meth:`set_positions`, a restored state), so a long run is never refused for
        its own round-off: 3.5e6 steps 165 m from the origin allow 1e-7 m."""
        st = self.state
        if not any(callable(getattr(p, "bind_displacement", None)) for p in self.providers):
            st.u[:] = st.x - self.x0  # nothing reads u: it follows whatever was done to x
            return
        gap = np.abs(st.x - self.x0 - st.u)
        eps = float(np.spacing(max(np.abs(st.x).max(), np.abs(self.x0).max())))
        tol = (1e3 + 0.5 * max(st.step - self._positions_set_at, 0)) * eps
        worst = int(np.argmax(gap.max(axis=1)))
        if gap[worst].max() > tol:
            raise ValueError(f"the positions were changed without the displacements: node {worst} at "
                             f"({st.x[worst, 0]:.6g}, {st.x[worst, 1]:.6g}) m is {gap[worst].max():.3g} m from x0 + u; "
                             f"move nodes with Simulation.set_positions, which keeps State.u beside State.x")

    def wake(self) -> None:
        """Wake every sleeping region (:mod:`fdem.solve.sleeping`): call it after changing supports,
        prescribed velocities or loads by hand (gravity, strengths and masses wake by themselves)."""
        if self.sleeping is not None:
            self.sleeping.wake_all(self)

    @property
    def time_capped(self) -> bool:
        """True when the run has reached its :attr:`time_cap`: a stage that ended there says
        nothing about stability."""
        return self.time_cap is not None and self.state.time >= self.time_cap - 0.5 * self.dt

    # ------------------------------------------------------------------ stepping
    def step(self, damping: Damping = NO_DAMPING, ledger: bool = False) -> StepSums:
        """Advance one step; returns the kernel sums by name (:class:`fdem.kernels.stepping.StepSums`).

        With ``ledger=True`` the step also records a history row (energies at the state
        before the step, monitors after it) in :attr:`history` and ``history.csv``.
        """
        st = self.state
        if self._device is not None:
            return self._device_step(damping, ledger)
        if ledger:  # a history row: positions written without displacements are caught here
            self._check_positions_kept()
        self._check_cracks_bound()
        x, u, v, dt = st.x, st.u, st.v, self.dt
        use_int = bool(self.providers)
        sl = self.sleeping
        if sl is not None and (damping.mass_proportional != 0.0 or damping.local != 0.0) \
                and not sl.policy.damped_stages:  # a relaxation: every region awake (fdem.solve.sleeping)
            if sl.any_asleep:
                sl.wake_all(self)
            sl.stepped += self.model.n_triangles
            sl = None
        if use_int:
            f_int = self.f_interaction
            if sl is None:
                f_int.fill(0.0)
            else:  # the frozen forces of sleeping regions' crack elements (zero when none sleeps)
                sl.before_forces(self, f_int)
            for p in self.providers:
                p.add_forces(x, v, f_int, dt, st.step)
            if sl is not None:
                sl.after_forces(self, f_int)  # wakes the regions a changed force reaches
            if ledger:  # provider energies at x_n, before the kernel moves the nodes
                self._provider_terms = self._collect_provider_terms()
        else:
            f_int = self._empty
            if sl is not None:
                sl.before_forces(self, None)
        ranges = None
        if sl is not None:
            ranges = sl.ranges()  # None: every region awake
        partial = self._partial if ranges is None else sl.partial(len(ranges))
        if self.model.has_time_dependent_velocity:
            self.model.update_prescribed_velocity(self.v_prescribed, st.time + 0.5 * dt)
        f_ext = self.f_external if self.use_external else self._empty
        gx, gy = self.gravity
        alpha, local = damping.mass_proportional, damping.local
        damped = alpha != 0.0 or local != 0.0
        if self.exploded and not (ledger or self.use_viscous or self.use_external):
            # fast path (most steps of a dynamic or damped stage): no state energies needed
            r_e, r_l, i_e, i_l, d_e, d_l, n_bad, kin = step_exploded_elastic(
                x, u, v, self.tc, f_int if use_int else None, np.array([alpha, local]) if damped else None,
                self.flags, self.v_prescribed, gx, gy, dt, partial, self._inertia_kernel, ranges)
            sums = StepSums(strain=0.0, kinetic=kin, gravity_moment=0.0, external_moment=0.0,
                            damping_early=d_e, damping_late=d_l, viscous_early=0.0, viscous_late=0.0,
                            reaction_early=r_e, reaction_late=r_l, interaction_early=i_e, interaction_late=i_l,
                            n_inverted=n_bad)
        elif self.exploded:
            sums = StepSums._make(step_exploded(x, u, v, self.tc, f_int, use_int, f_ext, self.use_external, self.flags,
                                                self.v_prescribed, gx, gy, dt, alpha, local, self.use_viscous,
                                                ledger, partial, self._inertia_kernel, ranges))
            if ranges is not None and ledger:  # the sleeping regions' frozen energies
                s_strain, s_grav, s_ext = sl.asleep_sums()
                sums = sums._replace(strain=sums.strain + s_strain, gravity_moment=sums.gravity_moment + s_grav,
                                     external_moment=sums.external_moment + s_ext)
        else:
            ptr, corners = self._csr
            strain, rate, n_bad = triangle_pass(x, v, self.triangles, self.tc, self._corner_force,
                                                self._viscous_stress, self.use_viscous)
            kin, gm, em, d_e, d_l, r_e, r_l, i_e, i_l = node_pass(
                x, u, v, st.mass, ptr, corners, self._corner_force, f_int, use_int, f_ext, self.use_external,
                self.flags, self.v_prescribed, gx, gy, dt, alpha, local, ledger)
            v_e = v_l = 0.0
            if self.use_viscous:
                v_e = 0.5 * dt * rate
                v_l = 0.5 * dt * viscous_power(v, self.triangles, self.tc, self._viscous_stress)
            sums = StepSums(strain=strain, kinetic=kin, gravity_moment=gm, external_moment=em,
                            damping_early=d_e, damping_late=d_l, viscous_early=v_e, viscous_late=v_l,
                            reaction_early=r_e, reaction_late=r_l, interaction_early=i_e, interaction_late=i_l,
                            n_inverted=n_bad)
        self._book_step(sums, ledger)
        if sl is not None:  # after the books of this step: what sleeping removes counts from the next
            sl.after_step(self, st.step % sl.check_steps(dt) == 0)
        return sums

    def _book_step(self, sums: StepSums, ledger: bool) -> None:
        """Advance the clock and book a step's sums (a history row when ``ledger``)."""
        st = self.state
        step_before, time_before = st.step, st.time
        if self.exploded or ledger:  # the exploded kernels sum the kinetic energy every step
            self.kinetic_peak = max(self.kinetic_peak, float(sums.kinetic))
        st.step += 1
        st.time += self.dt
        if ledger:
            self.last_row = self._record(sums, step_before, time_before)
        else:
            self.ledger.add_step(*work_halves(sums))

    def _device_step(self, damping: Damping, ledger: bool) -> StepSums:
        """:meth:`step` on the GPU backend; a step outside :meth:`run` brings its state back."""
        dev = self._device
        alone = not dev.attached
        if alone:
            dev.attach()
        try:
            sums = dev.step(damping, ledger)
            self._book_step(sums, ledger)
        finally:
            if alone:
                dev.detach()
        return sums

    @contextmanager
    def device_session(self):
        """``with sim.device_session(): sim.step(); ...``: keep the GPU backend's state on the
        device across bare :meth:`step` calls (as :meth:`run` does) and bring it back at the end;
        a no-op on the CPU. Without it, each bare step copies the whole state both ways."""
        dev = self._device
        if dev is None or dev.attached:
            yield self
            return
        dev.attach()
        try:
            yield self
        finally:
            dev.detach()

    def sync_host(self, state_only: bool = False) -> None:
        """Bring the GPU's state to the host arrays during a run (no-op on the CPU):
        positions and velocities, and unless ``state_only`` the providers' arrays too."""
        if self._device is not None:
            self._device.pull(state_only)

    # ------------------------------------------------------------------ running
    def run(self, n_steps: int | None = None, t_end: float | None = None, damping: Damping | None = None,
            output_every: int | None = None, history_every: int | None = None, stage: str | None = None,
            energy_tolerance: float | None = 0.05, checkpoint_every: int = 100,
            stop_when: Callable[["Simulation"], bool] | None = None, progress: bool | None = None,
            final_output: bool = True, phase: int = 0) -> "Simulation":
        """Run one stage: ``n_steps`` steps, or until time ``t_end`` [s].

        Parameters
        ----------
        damping : Damping, optional
            Quasi-static damping of this stage; default none (dynamic).
        output_every : int, optional
            Steps between output frames (VTU, crack VTU, PNG); default: 10 frames per stage.
        history_every : int, optional
            Steps between ledger/history rows; default ``output_every``.
        energy_tolerance : float or None
            The run stops as unstable when the balance error exceeds this fraction of the
            energy scale (energy created without work); ``None`` disables the check.
        checkpoint_every : int
            Steps between in-memory copies of the last good state (written on failure).
        stop_when : callable, optional
            ``stop_when(sim) -> bool`` checked on history steps; True ends the stage early. The
            stage runner (:mod:`fdem.workflow.stages`) checks its end rules through it.
        progress : bool, optional
            Override the simulation's progress-bar setting for this call.
        final_output : bool
            Write an output frame when the call ends (default True).
        phase : int
            Steps of this stage already taken before the call (a stage resumed from a
            checkpoint): history rows, frames and good-state copies fall on the same steps as
            in an uninterrupted run, which makes the resumed run bit-identical (history steps
            use the ledger kernel, equal to the plain one only up to round-off).
        """
        damping = damping or NO_DAMPING
        self._stage = stage or f"stage{len({r['stage'] for r in self.history}) + 1}"
        self.dt = self._choose_dt()
        if (n_steps is None) == (t_end is None):
            raise ValueError("run: give exactly one of n_steps and t_end")
        if self.time_cap is not None:  # a smoke run: no stage goes beyond the cap
            if t_end is not None:
                t_end = min(t_end, self.time_cap)
            else:
                n_steps = min(n_steps, max(0, math.ceil((self.time_cap - self.state.time) / self.dt - 1e-9)))
        if n_steps is None:
            n_steps = max(0, int(math.ceil((t_end - self.state.time) / self.dt - 1e-9)))
        output_every = max(1, output_every or max(1, n_steps // 10))
        history_every = max(1, history_every or output_every)
        if self._frames == 0:
            self.write_output()
        bar = None
        # a bar only for a person at a terminal: in a log file it is thousands of lines of noise
        if (self.progress if progress is None else progress) and sys.stderr.isatty():
            from tqdm import tqdm

            bar = tqdm(total=n_steps, desc=self._stage, unit="step", mininterval=0.5)
        bar_chunk = 0
        STOP.running += 1
        attached_here = self._device is not None and not self._device.attached
        if attached_here:
            self._device.attach()
        queued: list = []  # rows of a GPU batch that stood, booked one step at a time
        try:
            for k in range(phase, phase + n_steps):
                is_ledger = (k % history_every == 0) or k == phase + n_steps - 1
                step_before, time_before = self.state.step, self.state.time
                if not queued and self._device is not None and not is_ledger:
                    rows = self._device.try_batch(damping, self._plain_steps_ahead(
                        k, phase + n_steps, history_every, checkpoint_every, output_every))
                    queued = [] if rows is None else list(rows)
                if queued:
                    sums = self._device.book_row(queued.pop(0))
                    self._book_step(sums, False)
                else:
                    sums = self.step(damping, ledger=is_ledger)
                self._check(sums, step_before, time_before, is_ledger, energy_tolerance)
                if is_ledger:
                    row = self.last_row
                    if energy_tolerance is not None and row["balance_error"] > energy_tolerance * max(
                            self.ledger.scale, 1e-300) and row["balance_error"] > 0 and step_before > 0:
                        self._fail(step_before, time_before, "energy growing without work "
                                   f"(balance error {row['balance_error']:.3g} J/m, "
                                   f"{100 * row['balance_error_relative']:.2g} % of the energy scale)", None)
                    if stop_when is not None:
                        if stop_when(self):
                            break
                        if self._device is not None:  # what a stop rule changed (a strength ramp) goes out
                            self._device.attach()
                if (k + 1) % checkpoint_every == 0:
                    self.sync_host(state_only=True)
                    self._good = self.state.copy()
                if (k + 1) % output_every == 0 and k + 1 < phase + n_steps:
                    self.write_output()
                if STOP.pending is not None and not queued:  # a batch's state is that of its end
                    STOP.honour()
                if bar is not None:
                    bar_chunk += 1
                    if bar_chunk >= 64:
                        bar.update(bar_chunk)
                        bar_chunk = 0
            if final_output:
                self.write_output()
        except KeyboardInterrupt:
            # a whole step is worth keeping; a GPU batch in flight or half booked is no step's state
            mid_batch = queued or (self._device is not None and self._device.in_batch)
            if not STOP.forced and not mid_batch and not self.caller_checkpoints_interrupts:
                self.write_interrupted()
            raise
        finally:
            STOP.running -= 1
            if attached_here:
                self._device.detach()
            if bar is not None:
                bar.update(bar_chunk)
                bar.close()
        return self

    @staticmethod
    def _plain_steps_ahead(k: int, end: int, history_every: int, checkpoint_every: int, output_every: int) -> int:
        """How many steps from loop index ``k`` on are plain in :meth:`run` (no history row among
        them, and no good-state copy or frame before the last): what a GPU batch may cover."""
        n = 0
        while k + n < end and n < 1024:
            j = k + n
            if j % history_every == 0 or j == end - 1:
                break
            n += 1
            if (j + 1) % checkpoint_every == 0 or (j + 1) % output_every == 0:
                break
        return n

    def _record(self, sums, step: int, time: float) -> dict:
        t0 = _clock()
        try:
            return self._record_row(sums, step, time)
        finally:
            self.output_seconds["history"] += _clock() - t0

    def _record_row(self, sums, step: int, time: float) -> dict:
        early, late = work_halves(sums)
        terms, complete = self._provider_terms if self.providers else ({}, True)
        ledger = self.ledger.record(sums.kinetic, sums.strain, sums.gravity_moment, sums.external_moment,
                                    early, terms, complete)
        self.ledger.add_step(early, late)
        row = {"stage": self._stage, "step": int(step), "time": float(time), "dt": float(self.dt)}
        row.update(ledger)
        # kinetic energy's peak over the steps since the previous row (every step is summed):
        # the history's peak is right even when rows are sparse
        row["kinetic_peak"] = max(self.kinetic_peak, float(row["kinetic"]))
        self.kinetic_peak = 0.0
        for name, fn in self.monitors.items():
            row[name] = fn(self)
        self.history.append(row)
        if self._history_writer is not None:
            self._history_writer.write(row)
        return row

    def _collect_provider_terms(self) -> tuple[dict[str, float], bool]:
        terms: dict[str, float] = {}
        complete = True
        for p in self.providers:
            fn = getattr(p, "energy_terms", None)
            if fn is None:
                complete = False
                continue
            for name, value in fn().items():
                terms[name] = terms.get(name, 0.0) + float(value)
        return terms, complete

    # ------------------------------------------------------------------ guard
    def _check(self, sums, step: int, time: float, is_ledger: bool, energy_tolerance) -> None:
        n_bad = sums.n_inverted
        if n_bad > 0:
            self._fail(step, time, f"{n_bad} inverted or non-finite triangle(s)", None)
        if is_ledger and not (math.isfinite(sums.strain) and math.isfinite(sums.kinetic)):
            self._fail(step, time, "non-finite energy (NaN or infinity in the state)", None)

    def _fail(self, step: int, time: float, reason: str, triangle: int | None) -> None:
        self.sync_host()  # the GPU backend's state, mid-run
        x = self.state.x
        stress = np.empty((self.model.n_triangles, 6))
        with np.errstate(all="ignore"):
            triangle_stress_state(x, self.state.v, self.triangles, self.tc, stress)
            jac = stress[:, 4]
            bad = np.flatnonzero(~(jac > 0))
            if triangle is None:
                if bad.size:  # the most inverted (NaN counts as most)
                    triangle = int(bad[np.argmin(np.nan_to_num(jac[bad], nan=-np.inf))])
                else:
                    speed = np.nan_to_num(np.sqrt((self.state.v ** 2).sum(1)), nan=np.inf)
                    node = int(np.argmax(speed))
                    triangle = int(np.flatnonzero((self.triangles == node).any(1))[0])
        where = self.x0[self.triangles[triangle]].mean(0)
        crit, _ = self.critical_dt()
        suggested = 0.5 * min(self.dt, self.dt_fraction * crit)
        path = self._write_state("last_good_state", self._good)
        saved = (f"; last good state (step {self._good.step}, t = {self._good.time:.6g} s) written to {path}"
                 if path else "")
        kind, evidence = self._instability_kind(reason, triangle)
        msg = (f"unstable at step {step}, t = {time:.6g} s: {reason}; first bad triangle {triangle} "
               f"near reference point ({where[0]:.4g}, {where[1]:.4g}) m{saved}. ")
        if kind == "crushing":
            msg += (f"It looks like crushing, not the time step: {evidence}. The load squeezes the triangle flat "
                    f"faster than anything resists it (a load far above what the rock can carry, a gravity or "
                    f"density factor too high, a penalty too soft for the load), and a smaller step is "
                    f"unlikely to change when and where it fails (a run with dt <= {suggested:.4g} s that fails "
                    f"at the same time and place confirms it)")
        else:
            msg += (f"It looks like a time-step instability: {evidence}. Time step {self.dt:.4g} s; try "
                    f"dt <= {suggested:.4g} s, check the stable_dt of the force providers and the penalties")
        err = InstabilityError(msg, step, time, triangle, reason, suggested, path)
        err.kind = kind
        raise err

    def _instability_kind(self, reason: str, triangle: int) -> tuple[str, str]:
        """``("crushing" | "time step", evidence)`` for a failed step, from what the failure
        leaves: a step above the stable one makes the highest mode grow geometrically, so the
        ledger books energy created without work and the nodes reach speeds above the P-wave
        speed ``c_p = sqrt((lambda + 2 mu) / rho)`` within a few steps; a triangle crushed by its
        load inverts while the ledger stays balanced and its nodes move slower than ``c_p``
        (measured: a column under 10^4 g inverts the same triangle at t = 3.41 ms with dt and
        dt / 4, its nodes at 259 m/s against c_p = 693 m/s and a balance error of 1e-5; a step
        1.05x and 1.5x critical blows up with balance errors of 100 % or speeds far above c_p)."""
        if reason.startswith("energy growing"):
            return "time step", "the energy ledger grew without work"
        lam, mu = self.model.lame_arrays()
        rho = self.model.property_array("density")
        c_p = float(np.sqrt((lam + 2.0 * mu) / rho)[triangle])
        with np.errstate(all="ignore"):
            speed = float(np.sqrt((self.state.v[self.triangles[triangle]] ** 2).sum(1)).max())
        balance = float(self.history[-1]["balance_error_relative"]) if self.history else math.nan
        if math.isfinite(speed) and speed < c_p and (not self.history or abs(balance) < 0.01):
            return "crushing", (f"its nodes move at {speed:.3g} m/s, below the P-wave speed {c_p:.3g} m/s, and the "
                                f"energy ledger was balanced ({abs(balance) if self.history else 0.0:.2g} of its scale "
                                "at the last history row)")
        return "time step", (f"its nodes move at {speed:.3g} m/s against a P-wave speed of {c_p:.3g} m/s"
                             + (f", and the ledger's balance error was {balance:.2g} of its scale" if self.history else ""))

    def write_interrupted(self, checkpoint: bool = True) -> Path | None:
        """``interrupted_state.npz``: a full checkpoint of the state the run stopped in (loadable
        with :func:`fdem.solve.checkpoint.load_checkpoint`), and ``interrupted_state.vtu`` to look
        at. ``checkpoint=False`` writes the ``.vtu`` alone, for a caller whose own checkpoint of
        the same state was just written (:attr:`caller_checkpoints_interrupts`): at 326,755
        triangles each copy of the state is over 100 MB and seconds of writing, time in which a
        supervisor's SIGKILL may follow its SIGTERM. Returns the ``.npz`` path, or None."""
        self.sync_host()  # the GPU backend's state, mid-run
        if self.out_dir is None:
            return None
        from fdem.solve.checkpoint import save_checkpoint

        path = save_checkpoint(self, self.out_dir / "interrupted_state.npz") if checkpoint else None
        fields = self.fields()
        out.write_vtu(self.out_dir / "interrupted_state.vtu", self.state.x, self.triangles,
                      point_data=fields["point"], cell_data=fields["cell"])
        return path

    def continue_outputs(self) -> None:
        """After a restart into the output folder of the run that wrote the checkpoint: keep that
        run's frames up to the checkpoint in the ``.pvd`` series (later ones, written after the
        checkpoint, are dropped and will be written again) and rewrite ``history.csv`` with the
        checkpoint's rows, so the series and the history read as one uninterrupted run."""
        if self.out_dir is None:
            return
        from fdem.io.vtk import read_pvd

        series_list = [self._series, self._crack_series]
        if self.contact is not None:
            series_list.append(self._contacts())
        for series in series_list:
            if series is not None and series.pvd_path.exists():
                series.frames = [(t, p.name) for t, p in read_pvd(series.pvd_path)][: self._frames]
        if self._history_writer is not None:
            self._history_writer.close()
            # the header is the saved rows' columns and this run's monitors: a monitor added
            # since the checkpoint was written gets its column, empty in the rows before it
            columns = list(dict.fromkeys([k for row in self.history for k in row] + list(self.monitors)))
            self._history_writer = history_file.HistoryWriter(self.out_dir / "history.csv",
                                                              columns=columns if self.history else None)
            for row in self.history:
                self._history_writer.write(row)

    def write_history_rows(self, rows: list[dict]) -> None:
        """Write ``rows``, history rows this simulation made before a restart dropped them from
        :attr:`history`, into ``history.csv`` again, as they were when made; :attr:`history` is
        not changed. A factor-of-safety search replayed from a run's journal
        (:func:`fdem.workflow.fos.factor_of_safety`) writes its finished trials' rows so, and
        the file reads as that of a search never cut."""
        if self._history_writer is not None:
            for row in rows:
                self._history_writer.write(row)

    def _write_state(self, stem: str, state: State) -> Path | None:
        if self.out_dir is None:
            return None
        path = npz.save_state(self.out_dir / f"{stem}.npz", x=state.x, v=state.v, mass=state.mass, x0=self.x0,
                              triangles=self.triangles, time=state.time, step=state.step, dt=self.dt)
        fields = self.fields(state)
        out.write_vtu(self.out_dir / f"{stem}.vtu", state.x, self.triangles,
                      point_data=fields["point"], cell_data=fields["cell"])
        return path

    # ------------------------------------------------------------------ results
    def stresses(self, state: State | None = None) -> dict[str, np.ndarray]:
        """(n_tri,) Cauchy stresses [Pa]: ``xx, yy, xy, zz`` (plane strain ``lambda tr(E) + s0_zz``),
        principal ``s1 >= s2`` (in plane), ``von_mises``, ``J`` and strain-energy density [J/m^3]."""
        state = state or self.state
        s = np.empty((self.model.n_triangles, 6))
        triangle_stress_state(state.x, state.v, self.triangles, self.tc, s)
        lam, _ = self.model.lame_arrays()
        szz = (lam * s[:, 3] if self.model.plane == PLANE_STRAIN else 0.0) + self.model.out_of_plane_initial_stress()
        szz = np.broadcast_to(szz, (self.model.n_triangles,))
        s1, s2 = elastic.principal_stresses(s[:, 0], s[:, 1], s[:, 2])
        return {"xx": s[:, 0], "yy": s[:, 1], "xy": s[:, 2], "zz": np.array(szz), "principal_1": s1,
                "principal_2": s2, "von_mises": elastic.von_mises(s[:, 0], s[:, 1], s[:, 2], szz),
                "J": s[:, 4], "energy_density": s[:, 5]}

    def reaction_force(self, nodes: np.ndarray) -> np.ndarray:
        """Total force (2,) [N/m] that supports or prescribed velocities exert on ``nodes``.

        For a node held at zero acceleration the support supplies ``R = -(f_triangle +
        f_interaction + f_ext + m g)``; triangle forces are evaluated at the current positions,
        interaction forces are those of the last step. The platen load of a test is minus the
        reaction summed over the platen's nodes.
        """
        nodes = np.asarray(nodes, dtype=np.int64)
        st = self.state
        if self.exploded:
            tris = np.unique(nodes // 3)
            corner = np.zeros((3 * len(tris), 2))
            sub_tc = np.ascontiguousarray(self.tc[tris])
            sub_tri = np.arange(3 * len(tris), dtype=np.int64).reshape(-1, 3)
            assemble_triangle_forces(st.x[self.triangles[tris]].reshape(-1, 2),
                                     st.v[self.triangles[tris]].reshape(-1, 2), sub_tri, sub_tc, corner)
            pos = np.searchsorted(self.triangles[tris].ravel(), nodes)
            f_tri = corner[pos]
        else:
            corner = np.zeros((3 * self.model.n_triangles, 2))
            assemble_triangle_forces(st.x, st.v, self.triangles, self.tc, corner)
            f_all = np.zeros_like(st.x)
            np.add.at(f_all, self.triangles.ravel(), corner)
            f_tri = f_all[nodes]
        f = f_tri + st.mass[nodes, None] * self.gravity
        if self.providers:
            f = f + self.f_interaction[nodes]
        if self.use_external:
            f = f + self.f_external[nodes]
        return -f.sum(axis=0)

    def fields(self, state: State | None = None) -> dict[str, dict[str, np.ndarray]]:
        """Point and cell arrays written to the triangle frames (``docs/outputs.md`` lists them).

        Point: ``displacement`` ``x - X`` [m], ``velocity`` [m/s] (2-vectors, written with a zero
        third component: VTK draws and warps by 3-component vectors only). Cell: ``stress``, the
        Cauchy stress [Pa] as a symmetric tensor ``[xx, yy, zz, xy, yz, xz]`` (VTK's 6-component
        order; ``yz = xz = 0`` in plane strain), ``stress_principal_1 >= stress_principal_2``
        [Pa] (in plane), their unit directions ``stress_direction_1`` ``(cos a, sin a, 0)`` with
        ``tan 2a = 2 s_xy / (s_xx - s_yy)`` and ``stress_direction_2`` (normal to it),
        ``stress_von_mises`` [Pa], ``strain``, the Green-Lagrange strain ``(F^T F - I)/2`` [-] as
        a symmetric tensor (same order, ``zz = 0``: plane strain; the small strain for small
        rotations), ``property`` and ``body`` (ids), ``held`` (1 where the run itself has held
        every corner in place since it began: fly-rock stopped beyond the model's end,
        :attr:`fdem.workflow.stages.Stage.escape_share`; 0 elsewhere, supports included)."""
        state = state or self.state
        s = self.stresses(state)
        n = self.model.n_triangles
        zero = np.zeros(n)
        point = {"displacement": state.x - self.x0, "velocity": state.v}
        angle = 0.5 * np.arctan2(2.0 * s["xy"], s["xx"] - s["yy"])
        cos, sin = np.cos(angle), np.sin(angle)
        F = np.empty((n, 4))
        deformation_gradients(state.x, self.triangles, self.tc, F)
        exx = 0.5 * (F[:, 0] ** 2 + F[:, 2] ** 2 - 1.0)
        eyy = 0.5 * (F[:, 1] ** 2 + F[:, 3] ** 2 - 1.0)
        exy = 0.5 * (F[:, 0] * F[:, 1] + F[:, 2] * F[:, 3])
        cell = {"stress": np.column_stack([s["xx"], s["yy"], s["zz"], s["xy"], zero, zero]),
                "stress_principal_1": s["principal_1"], "stress_principal_2": s["principal_2"],
                "stress_direction_1": np.column_stack([cos, sin, zero]),
                "stress_direction_2": np.column_stack([-sin, cos, zero]),
                "stress_von_mises": s["von_mises"],
                "strain": np.column_stack([exx, eyy, zero, exy, zero, zero]),
                "property": self.model.triangle_property,
                "body": np.asarray(self.model.topology.triangle_body, np.int32),
                "held": (self.flags != self.model.flags)[self.triangles].all(axis=1).astype(np.int8)}
        return {"point": point, "cell": cell}

    def contact_geometry(self, state: State | None = None) -> dict[str, np.ndarray]:
        """Line cells of the touching contact pairs, for force chains: ``points`` (2k, 2), the
        current centroids of the two triangles of each pair [m]; ``normal_force`` and
        ``shear_force`` (k,) [N/m], magnitudes of the pair's force at the last step
        (:meth:`fdem.physics.contact.ContactSet.pair_forces`). Empty without a contact set or
        when nothing touches."""
        state = state or self.state
        if self.contact is None:
            return {"points": np.zeros((0, 2)), "normal_force": np.zeros(0), "shear_force": np.zeros(0)}
        pf = self.contact.pair_forces()
        centroid = state.x[self.triangles[pf["pairs"]]].mean(axis=2)  # (k, 2, 2)
        return {"points": centroid.reshape(-1, 2), "normal_force": pf["normal"], "shear_force": pf["shear"]}

    def crack_geometry(self, state: State | None = None) -> dict[str, np.ndarray]:
        """Line-cell points (2 per crack element, midpoints of its coincident node pairs), mean
        normal opening and slip [m] of every crack element (see :mod:`fdem.mesh.topology` for the order).

        The frame is the crack law's: the tangent of the mid-line ``t = (m1 - m0)/|m1 - m0|``
        with ``m0 = (x0 + x3)/2``, ``m1 = (x1 + x2)/2``. These are the geometric opening and slip
        of the element; the law also subtracts the preload offsets of a static start."""
        state = state or self.state
        cn = self.model.topology.crack_nodes
        x = state.x
        a = 0.5 * (x[cn[:, 0]] + x[cn[:, 3]])
        b = 0.5 * (x[cn[:, 1]] + x[cn[:, 2]])
        t = b - a
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
        n = np.column_stack([t[:, 1], -t[:, 0]])
        gap = 0.5 * ((x[cn[:, 3]] - x[cn[:, 0]]) + (x[cn[:, 2]] - x[cn[:, 1]]))
        return {"points": np.stack([a, b], axis=1).reshape(-1, 2), "opening": (gap * n).sum(1),
                "slip": (gap * t).sum(1)}

    def write_output(self) -> None:
        """Write one output frame of the current state: triangles VTU, crack VTU (with crack
        elements), contact VTU (with a contact set), optional PNG (``docs/outputs.md``)."""
        t0 = _clock()
        if self._device is None:
            self._check_positions_kept()
        try:
            self._write_frame()
        finally:
            self.output_seconds["frames"] += _clock() - t0

    def _write_frame(self) -> None:
        self.sync_host()  # the GPU backend's state, mid-run
        if self.out_dir is None:
            self._frames += 1
            return
        f = self.fields()
        self._series.write(self.state.time, self.state.x, self.triangles, out.VTK_TRIANGLE, f["point"], f["cell"])
        if self._crack_series is not None:
            topo = self.model.topology
            g = self.crack_geometry()
            cell = {"crack_tag": topo.crack_tag, "opening": g["opening"], "slip": g["slip"]}
            for p in self.providers:
                # the crack set's tractions at the frame's positions (a frame written before any
                # step, or after positions were set by hand, is not at its last add_forces)
                cell.update(p.crack_fields(self.state.x) if p is self.cracks
                            else provider_crack_fields(p, topo.n_cracks))
            lines = np.arange(2 * topo.n_cracks, dtype=np.int64).reshape(-1, 2)
            self._crack_series.write(self.state.time, g["points"], lines, out.VTK_LINE, None, cell)
        if self.contact is not None:
            self._write_contact_frame()
        if self.pictures:
            self._picture()
        self._frames += 1

    def _contacts(self) -> "out.PvdSeries":
        """The ``<name>_contacts.pvd`` series (made on first use: the contact set may be
        registered after the simulation is built)."""
        if self._contact_series is None:
            self._contact_series = out.PvdSeries(self.out_dir, f"{self.name}_contacts", compression=self.compression,
                                                 precision=self.output_precision)
        return self._contact_series

    def _write_contact_frame(self) -> None:
        """One frame of contact force lines; with no touching pair a frame of zero cells (about
        1 kB), so the series keeps one frame per output time."""
        g = self.contact_geometry()
        k = len(g["normal_force"])
        lines = np.arange(2 * k, dtype=np.int64).reshape(-1, 2)
        self._contacts().write(self.state.time, g["points"], lines, out.VTK_LINE, None,
                               {"normal_force": g["normal_force"], "shear_force": g["shear_force"]})

    def _picture(self) -> None:
        """PNG of the frame: displacement magnitude on the deformed mesh with the broken crack
        elements coloured by failure mode (how a rock engineer reads a failure)."""
        from fdem.io.pictures import failure_frame

        topo = self.model.topology
        disp = np.linalg.norm(self.state.x - self.x0, axis=1)
        segments = broken = mode = None
        if topo.n_cracks:
            fields: dict = {}
            for p in self.providers:
                fields.update(provider_crack_fields(p, topo.n_cracks))
            if "broken" in fields:
                segments = self.crack_geometry()["points"]
                broken = np.asarray(fields["broken"], bool)
                mode = fields.get("failure_mode")
        failure_frame(self.out_dir / f"{self.name}_{self._frames:05d}.png", self.state.x, self.triangles, disp,
                      segments, broken, mode, title=f"{self._stage} t = {self.state.time:.4g} s")

    def close(self) -> None:
        if self._history_writer is not None:
            self._history_writer.close()

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self) -> dict:
        """Everything a restart needs, copied (:mod:`fdem.solve.checkpoint` saves it to disk).

        The state (``x``, ``v``, ``time``, ``step``; the masses are derived), support flags,
        prescribed velocities, gravity, the last interaction forces, the energy ledger, the
        history rows, the output frame count, stage name, provider energies of the last
        ledger step, the last history row, the time step, the last good state (written on
        failure) and each provider's ``state_dict()`` in registration order. A provider
        without ``state_dict`` is an error naming it."""
        self.sync_host()  # the GPU backend's state, mid-run
        missing = [f"{i}: {type(p).__name__}" for i, p in enumerate(self.providers)
                   if not callable(getattr(p, "state_dict", None))]
        if missing:
            raise TypeError(f"force provider(s) without state_dict() cannot be checkpointed: {', '.join(missing)}")
        led = self.ledger
        terms, complete = self._provider_terms
        return {
            "x": self.state.x.copy(), "u": self.state.u.copy(), "v": self.state.v.copy(),
            "positions_set_at": int(self._positions_set_at),
            "time": float(self.state.time),
            "step": int(self.state.step), "flags": self.flags.copy(), "v_prescribed": self.v_prescribed.copy(),
            "gravity": self.gravity.copy(), "f_interaction": self.f_interaction.copy(),
            "ledger": {"done": dict(led.done), "first_early": None if led.first_early is None else dict(led.first_early),
                       "total0": led.total0, "scale": float(led.scale), "last": dict(led.last),
                       "gravity_moment0": float(led.gravity_moment0),
                       "external_moment0": float(led.external_moment0),
                       "gravity_change_work": float(led.gravity_change_work),
                       "mass_change_work": float(led.mass_change_work),
                       "sleep_dissipation": float(led.sleep_dissipation)},
            "density_scaled": self.inertia is not None,
            # the scaled masses of the stage in progress: recomputed from a crack set that has
            # broken since the stage began they would differ, and a resumed stage would not
            # repeat the uninterrupted one
            "inertia": None if self.inertia is None else self.inertia.copy(),
            "scaled_dt": float(self._scaled_dt) if self.inertia is not None else None,
            "kinetic_peak": float(self.kinetic_peak),
            "history": [dict(r) for r in self.history], "frames": int(self._frames), "stage": self._stage,
            "provider_terms": [dict(terms), bool(complete)],
            "last_row": None if self.last_row is None else dict(self.last_row), "dt": float(self.dt),
            "good": {"x": self._good.x.copy(), "u": self._good.u.copy(), "v": self._good.v.copy(),
                     "time": float(self._good.time),
                     "step": int(self._good.step)},
            "providers": [p.state_dict() for p in self.providers],
            "sleeping": None if self.sleeping is None else self.sleeping.state_dict(),
            "point_monitors": [m.state_dict() for m in self.point_monitors.values()],
            "monitor_records": {name: fn.state_dict() for name, fn in self.monitors.items()
                                if callable(getattr(fn, "state_dict", None))},
        }

    def _restore_point_monitors(self, saved: list) -> None:
        """Add the checkpoint's point monitors this simulation lacks (before the history rows,
        which hold their columns, come back); one of the same name here must watch the same
        point, else its column would join two points' records."""
        for m in saved:
            name, x, y = str(m["name"]), float(m["x"]), float(m["y"])
            here = self.point_monitors.get(name)
            if here is None:
                history, self.history = self.history, []
                try:
                    self.add_point_monitor(name, x, y)
                finally:
                    self.history = history
            elif (here.x, here.y) != (x, y):
                raise ValueError(f"point monitor {name!r} watches ({here.x:.6g}, {here.y:.6g}) m here, the checkpoint's "
                                 f"watched ({x:.6g}, {y:.6g}) m: rename one of them")

    def load_state_dict(self, d: dict) -> None:
        """Restore :meth:`state_dict` output into a simulation of the same model and providers.

        Arrays are written into the existing ones (providers keep their references to
        ``state.x``); the history list is replaced by the saved rows (truncated or extended
        to them); rows already written to ``history.csv`` stay there."""
        n = self.model.n_nodes
        if np.shape(d["x"]) != (n, 2):
            raise ValueError(f"saved state has positions of shape {np.shape(d['x'])}, this model has ({n}, 2)")
        saved = d["providers"]
        if len(saved) != len(self.providers):
            raise ValueError(f"saved state has {len(saved)} force provider(s), this simulation {len(self.providers)}")
        for i, (p, s) in enumerate(zip(self.providers, saved)):
            kind = s.get("kind") if isinstance(s, dict) else None
            if kind is not None and kind != type(p).__name__:
                raise ValueError(f"force provider {i} was a {kind} when saved, here it is a {type(p).__name__}")
        st = self.state
        st.x[:] = d["x"]
        # older checkpoints kept no displacement: x - x0 (resolved to the round-off of x)
        st.u[:] = d["u"] if d.get("u") is not None else st.x - self.x0
        st.v[:] = d["v"]
        # the drift the check allows counts from the step the restored state reached it at
        self._positions_set_at = int(d.get("positions_set_at", 0))
        st.time = float(d["time"])
        st.step = int(d["step"])
        self.flags[:] = d["flags"]
        self.v_prescribed[:] = d["v_prescribed"]
        self.gravity[:] = d["gravity"]
        self.f_interaction[:] = d["f_interaction"]
        led, s = self.ledger, d["ledger"]
        led.done = dict(s["done"])
        led.first_early = None if s["first_early"] is None else dict(s["first_early"])
        led.total0 = None if s["total0"] is None else float(s["total0"])
        led.scale = float(s["scale"])
        led.last = dict(s["last"])
        led.gravity_moment0 = float(s["gravity_moment0"])
        led.external_moment0 = float(s["external_moment0"])
        led.gravity_change_work = float(s.get("gravity_change_work", 0.0))
        led.mass_change_work = float(s.get("mass_change_work", 0.0))
        led.sleep_dissipation = float(s.get("sleep_dissipation", 0.0))
        self.kinetic_peak = float(d.get("kinetic_peak", 0.0))
        self._restore_point_monitors(d.get("point_monitors") or [])  # older checkpoints: none
        self.history[:] = [dict(r) for r in d["history"]]
        self._frames = int(d["frames"])
        self._stage = str(d["stage"])
        terms, complete = d["provider_terms"]
        self._provider_terms = (dict(terms), bool(complete))
        self.last_row = None if d["last_row"] is None else dict(d["last_row"])
        self.dt = float(d["dt"])
        g = d["good"]
        gx = np.array(g["x"], dtype=np.float64)
        self._good = State(gx, np.array(g["v"], dtype=np.float64), st.mass, float(g["time"]), int(g["step"]),
                           np.array(g["u"], dtype=np.float64) if g.get("u") is not None else gx - self.x0)
        for p, s in zip(self.providers, saved):  # every provider: load_state_dict(d, x), x the restored positions
            p.load_state_dict(s, x=st.x)
        for name, record in (d.get("monitor_records") or {}).items():  # older checkpoints: none
            fn = self.monitors.get(name)
            if callable(getattr(fn, "load_state_dict", None)):  # a monitor added here and not then starts afresh
                fn.load_state_dict(record)
        if d.get("inertia") is not None and self.density_scaling and self.user_dt is None and self.exploded:
            self.inertia = np.array(d["inertia"], dtype=np.float64)
            self._scaled_dt = float(d["scaled_dt"])
            self._inertia_kernel = np.ascontiguousarray(np.column_stack([self.inertia, 1.0 / self.inertia]))
        else:  # older checkpoints: the scaled masses follow from the restored crack set
            self.set_density_scaling(bool(d.get("density_scaled", False)), book=False)
        self.dt = float(d["dt"])
        if self.sleeping is not None:  # a state saved without sleeping: every region awake
            if d.get("sleeping") is not None:
                self.sleeping.load_state_dict(d["sleeping"], self)
            else:
                self.sleeping.wake_all(self)
                self.sleeping._signature = self.sleeping._load_signature(self)
