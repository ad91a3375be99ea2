"""The ``cuda`` backend: a simulation's state on an NVIDIA GPU between host round trips.

``Simulation(model, ..., backend="cuda")`` (or ``fdem run CASE --backend cuda``) steps with the
GPU loops of :mod:`fdem.kernels.cuda_step`, which call the CPU's own scalar laws: the triangle
step, the crack element law and the contact pair law are each written once.

What stays on the device, and what comes back
---------------------------------------------
:meth:`CudaBackend.attach` (at the start of every :meth:`~fdem.solve.simulation.Simulation.run`)
copies the state to the device: positions, velocities, masses, supports, the crack elements'
arrays and the contact pairs with their friction history. Each step then runs on the device:

1. zero the interaction forces; the crack kernel; the contact search's displacement trigger;
2. **round trip 1** (3 numbers): how many elements broke or left the elastic range, how far the
   contactors moved. Breaks are rare; when one happens the host reads the element arrays,
   registers the break (events, the active list, contact faces: the CPU's own code in
   :class:`~fdem.physics.cracks.CrackSet` and :class:`~fdem.physics.contact.ContactSet`) and
   sends back what changed. A due contact search likewise runs on the host
   (:meth:`ContactSet.search`) with the pairs' history read back first;
3. the contact pair and gather kernels; the fused triangle step;
4. **round trip 2** (17 numbers): the ledger's sums and the contact energies.

Positions and velocities come back on history rows (the ledger's state energies, monitors,
stop rules), for the in-memory good state, output frames and checkpoints
(:meth:`CudaBackend.pull`), and :meth:`CudaBackend.detach` brings everything back at the end
of each run, so that the workflow between stages, checkpoints and restarts work on host arrays
exactly as on the CPU: a checkpoint written by one backend resumes on the other. Anything that
changes the state between runs (a new strength, a switch of density scaling, zeroed
velocities) is on the device at the next attach.

Round trips, not launches, bound the speed of small models: two synchronising copies and six
launches per step (see ``docs/benchmarks.md`` for what was measured on a device).

Force providers other than the crack and contact sets (boundaries, shaking) run on the host:
the positions and velocities come back every step for them and their forces go out, which is
correct and slow. Sleeping regions and conforming (not exploded) meshes are CPU-only and
refused at construction.

Availability: :func:`require_cuda` raises :class:`BackendError` at once when numba-cuda is
missing or finds no GPU (under ``NUMBA_ENABLE_CUDASIM=1`` the simulator counts as one).
"""
from __future__ import annotations

import numpy as np

from fdem.kernels.stepping import StepSums
from fdem.kernels.triangles import TC_MASS

__all__ = ["BACKENDS", "BackendError", "require_cuda", "check_backend", "HostPositions", "CudaBackend"]

BACKENDS = ("cpu", "cuda")
"""The names :class:`~fdem.solve.simulation.Simulation` takes as ``backend``."""

_SCALARS = 20  # one device buffer: step sums 0:13, contact sums 13:17, crack counts 17:19, moved 19
_STEP, _CONTACT, _COUNTS, _MOVED = slice(0, 13), slice(13, 17), slice(17, 19), 19


class BackendError(RuntimeError):
    """The backend asked for cannot run here (no GPU, numba-cuda missing, a CPU-only feature)."""


def _numpy_aliases_for_numba_cuda() -> None:
    """Give NumPy back the names that numba-cuda registers at its first kernel compilation.

    numba-cuda 0.30 registers an overload for ``np.row_stack``, which NumPy 2.5 removed (it was
    an alias of ``np.vstack`` since NumPy 1.0); with that pair the first GPU compilation fails
    with ``AttributeError: module 'numpy' has no attribute 'row_stack'``. Seen on an H100 node
    with numpy 2.5.2 and numba-cuda 0.30.4 (docs/gpu.md). The alias is restored only where it is
    missing, and to the function it always stood for."""
    if not hasattr(np, "row_stack"):
        np.row_stack = np.vstack


def require_cuda():
    """The ``numba.cuda`` module, or :class:`BackendError` saying what is missing.

    Checked before any work: a run that asks for the GPU on a machine without one stops at once."""
    _numpy_aliases_for_numba_cuda()
    try:
        from numba import cuda
    except ImportError as exc:  # numba without the CUDA target
        raise BackendError("backend 'cuda' needs the numba-cuda package: pip install numba-cuda "
                           f"(import failed: {exc})") from None
    try:
        available = cuda.is_available()
    except Exception as exc:  # a broken driver install raises instead of answering
        raise BackendError(f"backend 'cuda': the CUDA driver did not answer ({exc})") from None
    if not available:
        raise BackendError("backend 'cuda' needs an NVIDIA GPU and its driver, and none was found "
                           "(numba.cuda.is_available() is False); run with backend 'cpu'")
    return cuda


def check_backend(name: str) -> str:
    """``name`` if it is a known backend and can run here, else :class:`BackendError` /
    ``ValueError`` naming the choices."""
    if name not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {name!r}")
    if name == "cuda":
        require_cuda()
    return name


class HostPositions:
    """The positions ``x_n`` of the current step, read back from the device on first use.

    Handed to the host code of a provider (``ContactSet._watch_inelastic`` indexes it) so that
    the copy is made only when that code needs it."""

    def __init__(self, backend: "CudaBackend"):
        self._backend = backend

    def __getitem__(self, key):
        return self._backend.host_x()[key]

    def __array__(self, dtype=None, copy=None):
        x = self._backend.host_x()
        return x if dtype is None else x.astype(dtype)


class CudaBackend:
    """Device copies of a :class:`~fdem.solve.simulation.Simulation`'s arrays and its GPU step.

    Made by the simulation for ``backend="cuda"``; the simulation calls :meth:`attach`,
    :meth:`step`, :meth:`pull` and :meth:`detach`. The crack and contact sets call back
    :meth:`crack_forces`, :meth:`contact_moved`, :meth:`contact_forces`, :meth:`pull_contact`
    and :meth:`host_x` (their ``device`` attribute is this object while attached).
    """

    def __init__(self, sim, max_batch: int = 64):
        self.cuda = require_cuda()
        from fdem.kernels import cuda_search, cuda_step  # compiles nothing yet: kernels compile at first launch

        self.k = cuda_step
        self.ks = cuda_search
        if not sim.exploded:
            raise BackendError("backend 'cuda' steps exploded meshes only (every triangle owns its three "
                               "nodes, as the crack elements need); this model's mesh is conforming")
        self.sim = sim
        self.attached = False
        self._x_fresh = self._u_fresh = False  # the host's x (u) equals the device's x_n (u_n) of this step
        self._pending_contact = False  # contact sums of this step still on the device
        self._moved_read = False  # the contact trigger of this step has come back
        self._after_breaks = False  # the host cleared break flags that the device must get
        self.round_trips = 0  # synchronising copies so far (for the benchmarks)
        self.batches_run = 0  # speculative batches that stood, and those refused (try_batch)
        self.batches_refused = 0
        self.device_searches = 0  # contact searches run on the device (the rest ran on the host)
        self.in_batch = False  # inside try_batch: the device's state is not that of any step yet
        self._contact_in_batch = False
        self._kept_shapes = None
        self._kept: list = []
        if max_batch < 1:
            raise ValueError(f"max_batch must be at least 1 (1: no batches), got {max_batch}")
        self.max_batch = max_batch  # longest speculative batch (try_batch); 1 turns batches off
        self.batch_limit = min(8, max_batch)  # the next batch's length: doubled when one stands, halved when refused
        self._singles = 0

    # ------------------------------------------------------------------ transfers
    def _to(self, a):
        return self.cuda.to_device(np.ascontiguousarray(a))

    def attach(self) -> None:
        """Copy the whole state to the device (the start of a run)."""
        sim, cuda = self.sim, self.cuda
        st = sim.state
        sim._check_positions_kept()  # positions written by hand without u are refused before the run
        sim._check_cracks_bound()
        self.x = self._to(st.x)
        self.u = self._to(st.u)  # the displacements the crack kernel reads (State.u)
        self.v = self._to(st.v)
        self.tc = self._to(sim.tc)
        inertia = sim._inertia_kernel
        if inertia is None:  # the lumped masses: one kernel signature for every stage
            m = np.repeat(sim.tc[:, TC_MASS], 3)
            inertia = np.column_stack([m, 1.0 / m])
        self.inertia = self._to(inertia)
        self.flags = self._to(sim.flags)
        self.v_prescribed = self._to(sim.v_prescribed)
        self.f_ext = self._to(sim.f_external if sim.use_external else np.zeros((1, 2)))
        self.f = cuda.device_array((sim.model.n_nodes, 2), np.float64)
        self.scalars = cuda.device_array(_SCALARS, np.float64)
        self._zero_scalars = np.zeros(_SCALARS)
        self.host_scalars = np.zeros(_SCALARS)
        self.host_providers = [p for p in sim.providers if p is not sim.cracks and p is not sim.contact]
        if sim.cracks is not None:
            self._push_cracks(sim.cracks)
            sim.cracks.device = self
        if sim.contact is not None:
            co = sim.contact
            self._pair_key = None
            self._contact_stale = False  # the host's pair arrays are older than the device's
            self._push_contact(co)
            self.s_crack_keys = self._to(co._crack_keys if co._crack_keys.size else np.full(1, -1, np.int64))
            self.s_crack_order = self._to(co._crack_order if co._crack_order.size else np.zeros(1, np.int64))
            self.s_kt_tri = self._to(co._kt_tri)
            self.s_mass_tri = self._to(co.mass_tri if co.mass_tri is not None else np.zeros(1))
            self.s_face_mu = self._to(co.face_friction)  # sent again when it changes (face_version)
            self._face_version = co.face_version
            # the grid's cell: the contact set's, else taken from the boxes of the first device search
            self._cell_size = co.cell_size or getattr(self, "_cell_size", None)
            co.device = self
        self.attached = True

    def pull(self, state_only: bool = False) -> None:
        """Copy positions and velocities back to the host; unless ``state_only``, also the
        interaction forces of the last step and the providers' mutable arrays."""
        if not self.attached:
            return
        st = self.sim.state
        self.x.copy_to_host(st.x)
        self.u.copy_to_host(st.u)
        self.v.copy_to_host(st.v)
        self._x_fresh = self._u_fresh = True
        self.round_trips += 1
        if state_only:
            return
        if self.sim.providers:
            self.f.copy_to_host(self.sim.f_interaction)
        if self.sim.cracks is not None:
            self._pull_cracks(self.sim.cracks)
        if self.sim.contact is not None:
            self.pull_contact(self.sim.contact)

    def detach(self) -> None:
        """Bring everything back (the end of a run); the providers compute on the host again."""
        if not self.attached:
            return
        self.pull()
        for p in (self.sim.cracks, self.sim.contact):
            if p is not None:
                p.device = None
        self.attached = False

    def host_x(self, with_u: bool = False) -> np.ndarray:
        """The host's position array, made equal to the device's ``x_n`` (one copy per step at
        most); ``with_u`` brings the displacements ``u_n`` too (the crack set's host code reads
        them: energies, breaks), which contact's reads of the positions do not need."""
        if not self._x_fresh:
            self.x.copy_to_host(self.sim.state.x)
            self._x_fresh = True
            self.round_trips += 1
        if with_u and not self._u_fresh:
            self.u.copy_to_host(self.sim.state.u)
            self._u_fresh = True
        return self.sim.state.x

    # ------------------------------------------------------------------ crack elements
    def _push_cracks(self, cs) -> None:
        self.c_nodes = self._to(cs._nodes)
        self.c_ref = self._to(cs._ref)
        self.c_const = self._to(cs._const)
        self.c_status = self._to(cs._status)
        self.c_state = self._to(cs._state)
        self.c_diss = self._to(cs._diss)
        self.c_offset = self._to(cs._offset)
        self.c_dil = self._to(cs._dil)
        self.c_broke = self._to(cs._broke_flag)
        self._push_run(cs)

    def _push_run(self, cs) -> None:
        self._run_host = cs._run
        self.c_run = self._to(cs._run if cs._run.size else np.zeros(1, np.int64))
        self._n_run = int(cs._run.size)

    def _pull_cracks(self, cs) -> None:
        self.c_status.copy_to_host(cs._status)
        self.c_state.copy_to_host(cs._state)
        self.c_diss.copy_to_host(cs._diss)
        self.c_broke.copy_to_host(cs._broke_flag)

    def crack_forces(self, cs) -> int:
        """The crack kernel into the device's force array; returns how many elements broke.

        Launches the contact search's trigger in the same round trip. When elements broke, the
        host's element arrays are brought up to date for :meth:`CrackSet._register_breaks`,
        and after it the live list and the cleared flags go back."""
        self._launch_cracks(cs, self.scalars)
        self._launch_moved(self.scalars)
        self._read_scalars()
        self._moved_read = True
        n_broke = int(self.host_scalars[_COUNTS][0])
        n_left_elastic = int(self.host_scalars[_COUNTS][1])
        if n_broke:
            self._pull_cracks(cs)
            self._after_breaks = True
        elif n_left_elastic:  # contact watches the inelastic elements through the status
            self.c_status.copy_to_host(cs._status)
        return n_broke

    def _launch_cracks(self, cs, row) -> None:
        """The crack kernel, its counts into ``row`` (a device row of :data:`_SCALARS`)."""
        k = self.k
        if cs._run is not self._run_host:
            self._push_run(cs)
        if self._n_run:
            k.crack_kernel[k.blocks_for(self._n_run), k.THREADS](
                self.u, self.c_ref, self.f, self.c_nodes, self.c_const, self.c_status, self.c_state, self.c_diss,
                self.c_offset, self.c_dil, self.c_run, self.c_broke, row[_COUNTS])

    def _sync_after_breaks(self, cs) -> None:
        if self._after_breaks:
            self.c_broke.copy_to_device(cs._broke_flag)
            self._after_breaks = False

    # ------------------------------------------------------------------ contact
    def _push_contact(self, co) -> None:
        self._pair_key = co.pairs
        n_pairs = len(co.pairs)
        pair_i = co._pair_i if n_pairs else np.zeros(1, np.int64)
        # one thread per contactor: the pairs of a contactor are contiguous (pair_i sorted)
        starts = np.flatnonzero(np.diff(co._pair_i)) + 1 if n_pairs else np.zeros(0, np.int64)
        self.p_starts = self._to(np.concatenate([[0], starts, [n_pairs]]).astype(np.int64))
        self._n_contactors = len(starts) + 1 if n_pairs else 0
        self.p_i = self._to(pair_i)
        self.p_j = self._to(co._pair_j if n_pairs else np.zeros(1, np.int64))
        one = np.zeros(1)
        self.p_mu_base = self._to(co._mu_base_pair if n_pairs else one)
        self.p_kt = self._to(co._kt_pair if n_pairs else one)
        self.p_damp = self._to(co._damp_pair if n_pairs else one)
        self.p_hist = self._to(co._history if n_pairs else np.zeros((1, co._history.shape[1])))
        self.p_ft = self._to(co._f_target if n_pairs else np.zeros((1, 6)))
        self.p_touch = self._to(co._touching if n_pairs else np.zeros(1, np.uint8))
        self.p_witness = self._to(co._witness if n_pairs else np.zeros(1, np.uint8))
        self.p_active = self._to(co._active if co._active.size else np.zeros(1, np.int64))
        self._n_active = int(co._active.size)
        self.p_inc_ptr = self._to(co._inc_ptr)
        self.p_inc_pair = self._to(co._inc_pair if co._inc_pair.size else np.zeros(1, np.int64))
        self.p_x_search = self._to(co._x_search if co._x_search is not None else self.sim.state.x)
        self.p_keys = self._to(co._keys if n_pairs else np.full(1, -1, np.int64))
        self._n_pairs = n_pairs

    def pull_contact(self, co) -> None:
        """The pairs' history (friction springs, touching flags, separating axes) back to the host;
        after a search on the device, the whole pair list with its constants."""
        if self._contact_stale:
            self._pull_pair_list(co)
            return
        if self._pair_key is co.pairs and self._n_pairs:
            self.p_hist.copy_to_host(co._history)
            self.p_touch.copy_to_host(co._touching)
            self.p_witness.copy_to_host(co._witness)
            self.p_ft.copy_to_host(co._f_target)

    def _pull_pair_list(self, co) -> None:
        """The device's pair list (a search ran there) into the contact set's host arrays."""
        from fdem.kernels import contact_pairs as kc

        n = self._n_pairs
        host = (lambda d: d.copy_to_host()[:n]) if n else (lambda d: d.copy_to_host()[:0])
        pi, pj = host(self.p_i), host(self.p_j)
        co.pairs = np.column_stack([pi, pj])
        co._pair_i, co._pair_j = np.ascontiguousarray(pi), np.ascontiguousarray(pj)
        co._keys = host(self.p_keys)
        co._history = host(self.p_hist)
        co._touching = host(self.p_touch)
        co._witness = host(self.p_witness)
        co._f_target = host(self.p_ft)
        co._mu_base_pair = host(self.p_mu_base)
        co._kt_pair = host(self.p_kt)
        co._damp_pair = host(self.p_damp)
        co._inc_ptr = self.p_inc_ptr.copy_to_host()
        co._inc_pair = host(self.p_inc_pair) if n else np.zeros(0, np.int64)
        co._bounds = kc.chunk_bounds(co._pair_i, min(1024, max(1, n // 128)))
        co._x_search = self.p_x_search.copy_to_host()
        self._pair_key = co.pairs
        self._contact_stale = False
        self.round_trips += 1

    def contact_search(self, co) -> None:
        """:meth:`ContactSet.search` on the device (full grid search): the pair list, its carried
        history and constants are made there; the host's copy is brought back when needed."""
        from fdem.kernels.contact_search import grid_shape

        cuda, ks, T = self.cuda, self.ks, self.k.THREADS
        blocks = self.k.blocks_for
        n_act = int(co._active.size)
        n_tri = self.sim.model.n_triangles
        active = self._to(co._active if n_act else np.zeros(1, np.int64))
        bond = self._to(co._bond)
        slot = self._to(co._slot)
        broken = self._to(co._broken.view(np.uint8))
        crack_mu = self._to(co._crack_mu if co._crack_mu.size else np.zeros(1))
        n_pairs = 0
        if n_act >= 2:
            box = cuda.device_array((n_act, 4), np.float64)
            extent = self._to(np.full(4, np.inf))
            ks.boxes_kernel[blocks(n_act), T](self.x, active, 0.5 * co.skin, box, extent)
            e = extent.copy_to_host()
            if self._cell_size is None:  # as the CPU takes it; it changes the search's cost, not its pairs
                from fdem.physics.contact import grid_cell_size

                self._cell_size = grid_cell_size(box.copy_to_host())
            cell, nx, ny = grid_shape(e[0], e[1], -e[2], -e[3], self._cell_size, max(1024.0, 4.0 * n_act))
            cell_cnt = self._to(np.zeros(nx * ny + 1, np.int64))
            ks.bin_count_kernel[blocks(n_act), T](box, e[0], e[1], cell, nx, cell_cnt)
            cell_ptr = np.cumsum(cell_cnt.copy_to_host())
            d_ptr = self._to(cell_ptr)
            items = cuda.device_array(max(1, int(cell_ptr[-1])), np.int64)
            ks.bin_fill_kernel[blocks(n_act), T](box, e[0], e[1], cell, nx, d_ptr, self._to(np.zeros(nx * ny, np.int64)),
                                                 items)
            counts = self._to(np.zeros(n_act + 1, np.int64))
            dummy = self._to(np.zeros(1, np.int64))
            ks.partner_count_kernel[blocks(n_act), T](box, active, bond, self.x, co.skin, e[0], e[1], cell, nx, d_ptr,
                                                      items, dummy, counts)
            offsets = np.cumsum(counts.copy_to_host())
            n_pairs = int(offsets[-1])
            self.round_trips += 4
        if n_pairs:
            d_off = self._to(offsets)
            pi = cuda.device_array(n_pairs, np.int64)
            pj = cuda.device_array(n_pairs, np.int64)
            ks.partner_fill_kernel[blocks(n_act), T](box, active, bond, self.x, co.skin, e[0], e[1], cell, nx, d_ptr,
                                                     items, d_off, pi, pj)
            keys = cuda.device_array(n_pairs, np.int64)
            hist = cuda.device_array((n_pairs, co._history.shape[1]), np.float64)
            touching = cuda.device_array(n_pairs, np.uint8)
            mu_base = cuda.device_array(n_pairs, np.float64)
            kt = cuda.device_array(n_pairs, np.float64)
            damp = cuda.device_array(n_pairs, np.float64)
            old_hist = self.p_hist if self._n_pairs else self._to(np.zeros((1, co._history.shape[1])))
            ks.pair_kernel[blocks(n_pairs), T](pi, pj, n_tri, self.p_keys, old_hist, keys, hist, touching,
                                               self.s_crack_keys, self.s_crack_order, broken, crack_mu,
                                               bool(co._any_broken), self.s_kt_tri, self.s_mass_tri,
                                               float(co.damping_ratio), mu_base, kt, damp)
            inc_ptr = self._to(np.zeros(n_act + 1, np.int64))
            ks.incidence_count_kernel[blocks(n_pairs), T](pj, slot, inc_ptr)
            inc_ptr = self._to(np.cumsum(inc_ptr.copy_to_host()))
            inc = cuda.device_array(n_pairs, np.int64)
            ks.incidence_fill_kernel[blocks(n_pairs), T](pj, slot, inc_ptr, self._to(np.zeros(n_act, np.int64)), inc)
            ks.incidence_sort_kernel[blocks(n_act), T](inc_ptr, inc)
            self.round_trips += 1
            self.p_i, self.p_j, self.p_keys, self.p_hist, self.p_touch = pi, pj, keys, hist, touching
            self.p_mu_base, self.p_kt, self.p_damp = mu_base, kt, damp
            self.p_ft = self._to(np.zeros((n_pairs, 6)))
            self.p_witness = self._to(np.zeros(n_pairs, np.uint8))
            self.p_inc_ptr, self.p_inc_pair = inc_ptr, inc
            self.p_starts = d_off
            self._n_contactors = n_act
        else:
            self._n_contactors = 0
            self.p_keys = self._to(np.full(1, -1, np.int64))
            self.p_inc_ptr = self._to(np.zeros(n_act + 1, np.int64))
        self.p_active = active
        self._n_active = n_act
        self._n_pairs = n_pairs
        self.p_x_search = self.cuda.device_array_like(self.x)
        self.p_x_search.copy_to_device(self.x)
        self._contact_stale = True
        # the search positions live on the device (p_x_search) and come back with the pair list;
        # the host's must only stop saying "never searched"
        if co._x_search is None:
            co._x_search = self.sim.state.x
        co._needs_search = False
        co.n_searches += 1
        self.device_searches += 1

    def _launch_moved(self, row) -> None:
        co = self.sim.contact
        if co is None or co.device is None or self._pair_key is not co.pairs or not self._n_active:
            return
        k = self.k
        k.moved_kernel[k.blocks_for(self._n_active), k.THREADS](self.x, self.p_x_search, self.p_active,
                                                               row[_MOVED:_MOVED + 1])

    def n_pairs(self, co) -> int:
        """Candidate pairs of ``co`` now: the device's count after a search there, else the host's."""
        return self._n_pairs if self._contact_stale or self._pair_key is co.pairs else len(co.pairs)

    def contact_moved(self) -> float:
        """Largest displacement of an active contact node since the last search [m] (this step's
        trigger, read back with the crack counts)."""
        if not self._moved_read:  # no crack kernel ran: the trigger has its own round trip
            self._launch_moved(self.scalars)
            self._read_scalars()
            self._moved_read = True
        return float(np.sqrt(self.host_scalars[_MOVED]))

    def contact_forces(self, co, dt: float) -> None:
        """The pair and gather kernels into the device's force array (the pairs are sent again
        when a search has changed them); the sums are booked after the step's round trip."""
        if self._pair_key is not co.pairs:
            self._push_contact(co)
        self._launch_contact(co, dt, self.scalars)
        self._pending_contact = True

    def _launch_contact(self, co, dt: float, row) -> None:
        k = self.k
        if self._n_contactors:
            if self._face_version != co.face_version:  # faces broke or were given a friction since
                self.s_face_mu = self._to(co.face_friction)
                self._face_version = co.face_version
            k.contact_kernel[k.blocks_for(self._n_contactors), k.THREADS](
                self.x, self.v, self.p_i, self.p_j, self.p_starts, co.penalty, self.p_mu_base, self.s_face_mu,
                1.0 / float(co.reduction), self.p_kt, self.p_damp, dt, self.p_hist, self.p_ft, self.p_touch,
                self.p_witness, self.f, row[_CONTACT])
            k.gather_kernel[k.blocks_for(self._n_active), k.THREADS](
                self.f, self.p_active, self.p_inc_ptr, self.p_inc_pair, self.p_ft, self.p_touch)

    # ------------------------------------------------------------------ the step
    def _read_scalars(self) -> None:
        self.scalars.copy_to_host(self.host_scalars)
        self.round_trips += 1

    def step(self, damping, ledger: bool) -> StepSums:
        """One step on the device; the same sums as the CPU step (:class:`StepSums`)."""
        sim, k = self.sim, self.k
        st = sim.state
        dt = sim.dt
        self._x_fresh = self._u_fresh = False
        self._moved_read = False
        self.scalars.copy_to_device(self._zero_scalars)
        self.host_scalars[:] = 0.0
        use_int = bool(sim.providers)
        if use_int:
            k.zero_kernel[k.blocks_for(sim.model.n_nodes), k.THREADS](self.f)
            if ledger:  # the providers' energies are those of x_n (the crack elements' of u_n)
                self.host_x(with_u=True)
            hx = HostPositions(self)
            for p in sim.providers:
                if p is sim.cracks:
                    p.add_forces(st.x, None, None, dt, st.step)
                    self._sync_after_breaks(p)
                elif p is sim.contact:
                    p.add_forces(hx, None, None, dt, st.step)
                else:
                    self._host_provider(p, dt, st.step)
        if sim.model.has_time_dependent_velocity:
            sim.model.update_prescribed_velocity(sim.v_prescribed, st.time + 0.5 * dt)
            self.v_prescribed.copy_to_device(sim.v_prescribed)
        self._launch_step(damping, ledger, use_int, self.scalars)
        self._read_scalars()
        s = self.host_scalars
        if self._pending_contact:
            sim.contact.book_pair_sums(*(float(e) for e in s[_CONTACT]))
            self._pending_contact = False
        if ledger:
            if use_int:  # the providers' energies at x_n (the host's x still holds it)
                if sim.cracks is not None:
                    self._pull_cracks(sim.cracks)
                sim._provider_terms = sim._collect_provider_terms()
            self._x_fresh = self._u_fresh = False
            self.pull()  # monitors and stop rules read the state after the step
        self._x_fresh = self._u_fresh = False
        sums = s[_STEP]
        return StepSums(*(float(e) for e in sums[:12]), int(round(sums[12])))

    def _launch_step(self, damping, ledger: bool, use_int: bool, row) -> None:
        sim, k = self.sim, self.k
        gx, gy = float(sim.gravity[0]), float(sim.gravity[1])
        k.step_kernel[k.blocks_for(sim.model.n_triangles), k.THREADS](
            self.x, self.u, self.v, self.tc, self.inertia, self.f, use_int, self.f_ext, bool(sim.use_external), self.flags,
            self.v_prescribed, gx, gy, sim.dt, float(damping.mass_proportional), float(damping.local),
            bool(sim.use_viscous), bool(ledger), row[_STEP])

    # ------------------------------------------------------------------ speculative batches
    def _batchable(self) -> bool:
        """Whether the host would do nothing between the next steps unless the device's counts
        say so: no provider without a GPU loop, no time-dependent supports, no break handed on,
        no search asked for, no crack element under contact's watch (its gap is checked on the
        host every few steps)."""
        sim = self.sim
        if self.host_providers or sim.model.has_time_dependent_velocity:
            return False
        cs, co = sim.cracks, sim.contact
        if cs is not None and (cs._carry_broken.size or cs._run is not self._run_host):
            return False
        if co is not None:
            # elements under contact's watch have their gaps checked on the host every few steps,
            # dormant or not (that check loosens the first vertices)
            if co.cracks is not None and co.softening != "all" and (co._watch is None or co._watch.size):
                return False
            if not co.dormant and (co._needs_search or co._x_search is None or self._pair_key is not co.pairs):
                return False
        return True

    def _state_arrays(self) -> list:
        """The device arrays a batch changes (restored when it is refused)."""
        arrays = [self.x, self.u, self.v]
        if self.sim.cracks is not None:
            arrays += [self.c_status, self.c_state, self.c_diss, self.c_broke]
        if self.sim.contact is not None and self._n_pairs:
            arrays += [self.p_hist, self.p_ft, self.p_touch, self.p_witness]
        return arrays

    def _kept_copies(self) -> list:
        """Device buffers shaped like :meth:`_state_arrays`, allocated again only when a shape
        changed (a search changes the pair arrays)."""
        shapes = [(a.shape, a.dtype) for a in self._state_arrays()]
        if self._kept_shapes != shapes:
            self._kept = [self.cuda.device_array(shape, dtype) for shape, dtype in shapes]
            self._kept_shapes = shapes
        return self._kept

    def try_batch(self, damping, n_steps: int) -> np.ndarray | None:
        """Run ``n_steps`` plain steps (no history row among them) with one round trip instead of
        two a step, speculatively: the state is kept on the device, the steps run, and their rows
        come back at once. The batch stands when the host would have done nothing in any of
        its steps (no element broke or left the elastic range, the contactors stayed within
        half the skin, no triangle inverted); then the rows (n_steps, 20) are returned, for
        :meth:`book_row` step by step. Otherwise the kept state is put back and ``None``
        returned: the caller steps one by one, and the next batch is half as long."""
        sim = self.sim
        n_steps = min(n_steps, self.batch_limit)
        if n_steps < 2:
            self._singles += 1
            if self.max_batch > 1 and self._singles >= 32:  # a quiet spell may have begun: try again
                self.batch_limit, self._singles = 2, 0
            return None
        if not self._batchable():
            return None
        self.in_batch = True
        try:
            return self._run_batch(damping, n_steps)
        finally:
            self.in_batch = False

    def _run_batch(self, damping, n_steps: int) -> np.ndarray | None:
        sim = self.sim
        kept = self._kept_copies()
        for dst, src in zip(kept, self._state_arrays()):
            dst.copy_to_device(src)
        rows = self.cuda.to_device(np.zeros((n_steps, _SCALARS)))
        use_int = bool(sim.providers)
        cs, co = sim.cracks, sim.contact
        contact_on = co is not None and not co.dormant and self.n_pairs(co) > 0
        for j in range(n_steps):
            row = rows[j]
            if use_int:
                self.k.zero_kernel[self.k.blocks_for(sim.model.n_nodes), self.k.THREADS](self.f)
                if cs is not None and cs._run.size:
                    self._launch_cracks(cs, row)
                if contact_on:
                    self._launch_moved(row)
                    self._launch_contact(co, sim.dt, row)
            self._launch_step(damping, False, use_int, row)
        host = rows.copy_to_host()
        self.round_trips += 1
        limit = (0.5 * co.skin) ** 2 if contact_on and co.full_search else np.inf
        clean = (not host[:, _COUNTS].any() and not host[:, _STEP][:, 12].any()
                 and bool((host[:, _MOVED] <= limit).all()))
        if not clean:
            for dst, src in zip(self._state_arrays(), kept):
                dst.copy_to_device(src)
            self.batches_refused += 1
            self.batch_limit = max(1, self.batch_limit // 2)
            return None
        self.batches_run += 1
        self.batch_limit = min(self.max_batch, 2 * self.batch_limit)
        self._contact_in_batch = contact_on
        return host

    def book_row(self, row: np.ndarray) -> StepSums:
        """One step of a batch that stood (before the simulation's clock moves on): the crack set's
        clock, its contact sums booked; its step sums returned."""
        sim = self.sim
        if sim.cracks is not None:  # what the crack set's host code does in a step without breaks
            sim.cracks.tick(sim.state.step, sim.dt)
            sim.cracks.newly_broken = np.zeros(0, dtype=np.int64)
        if self._contact_in_batch:
            sim.contact.book_pair_sums(*(float(e) for e in row[_CONTACT]))
        sums = row[_STEP]
        return StepSums(*(float(e) for e in sums[:12]), int(round(sums[12])))

    def _host_provider(self, p, dt: float, step: int) -> None:
        """A provider without a GPU loop: positions and velocities to the host, its forces back."""
        st = self.sim.state
        self.host_x()
        self.v.copy_to_host(st.v)
        f = self.f.copy_to_host()
        p.add_forces(st.x, st.v, f, dt, step)
        self.f.copy_to_device(f)
        self.round_trips += 2
