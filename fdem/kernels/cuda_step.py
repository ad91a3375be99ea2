"""GPU loops of the step (numba-cuda): the CPU's scalar laws, one thread per item.

Only the loops live here. Every law is the CPU's own ``@njit`` function, compiled a second
time for the device when a kernel calls it (numba-cuda turns a CPU dispatcher called from
device code into a device function), so a change to a law changes both paths:

* :func:`step_kernel`: one thread per triangle runs :func:`fdem.kernels.stepping.triangle_step`
  (CST forces, central-difference update of the triangle's own three nodes on an exploded mesh,
  damping, supports, gravity and the ledger's sums);
* :func:`crack_kernel`: one thread per live crack element runs
  :func:`fdem.kernels.cracks.element_update` (elastic fast path, softening, breakage) and adds
  its forces with atomics (the CPU colours the elements instead);
* :func:`contact_kernel`: one thread per contactor triangle runs
  :func:`fdem.kernels.contact_pairs._pair_range` over that contactor's pairs (the CPU runs
  the same function over chunks of contactors), with per-thread work arrays in local memory;
  :func:`gather_kernel` adds the target-side forces (:func:`~fdem.kernels.contact_pairs._gather_one`);
* :func:`moved_kernel`: the contact search's trigger (:func:`~fdem.kernels.contact_search.triangle_moved2`).

Sums (energies, counts) are reduced per thread block in shared memory and added once per
block with an atomic: atomics reorder the additions, so GPU sums equal the CPU's to round-off,
not bit for bit. Forces added with atomics (crack elements) likewise.

This module imports ``numba.cuda``; the solver imports it only when a simulation asks for the
``cuda`` backend (:mod:`fdem.solve.cuda_backend`). Under ``NUMBA_ENABLE_CUDASIM=1`` the kernels
run on numba-cuda's simulator (the tests), calling the CPU-compiled laws.
"""
from __future__ import annotations

import os

from numba import cuda, float64, int64

from fdem.kernels.contact_pairs import MAX_VERT, N_COL, N_IWORK, N_WORK, _gather_one, _pair_range
from fdem.kernels.contact_search import triangle_moved2
from fdem.kernels.cracks import element_update
from fdem.kernels.stepping import LEDGER_FIELDS, damping_factors, triangle_step

__all__ = ["THREADS", "N_STEP_SUMS", "N_CONTACT_SUMS", "blocks_for", "step_kernel", "crack_kernel",
           "contact_kernel", "gather_kernel", "moved_kernel", "zero_kernel"]

THREADS = int(os.environ.get("FDEM_CUDA_THREADS", "128"))
"""Threads per block of every kernel: a power of two (the shared-memory reduction halves it),
a multiple of the 32-thread warp, at most 256 (the step's block sums take 104 bytes a thread of
the 48 KiB of static shared memory). ``FDEM_CUDA_THREADS`` sets it at import (the simulator
tests take 32: the simulator runs every thread as a Python thread)."""
if THREADS not in (32, 64, 128, 256):  # 13 sums of 8 bytes a thread: 512 would pass 48 KiB of shared memory
    raise ValueError(f"FDEM_CUDA_THREADS must be 32, 64, 128 or 256, got {THREADS}")
N_STEP_SUMS = len(LEDGER_FIELDS)
N_CONTACT_SUMS = 4  # E_normal, E_tangential, W_friction, W_damping


def blocks_for(n: int) -> int:
    """Blocks of :data:`THREADS` threads covering ``n`` items (at least one)."""
    return max(1, -(-int(n) // THREADS))


@cuda.jit(device=True)
def _reduce_block(shared, tid, n_values, sums):
    """Tree-sum ``shared[:, k]`` (THREADS, n_values) over the block, then thread 0 adds the
    block's totals to ``sums[k]`` with one atomic each."""
    width = THREADS // 2
    while width > 0:
        cuda.syncthreads()
        if tid < width:
            for k in range(n_values):
                shared[tid, k] += shared[tid + width, k]
        width //= 2
    cuda.syncthreads()
    if tid == 0:
        for k in range(n_values):
            cuda.atomic.add(sums, k, shared[0, k])


@cuda.jit
def step_kernel(x, u, v, tc, inertia, f_int, use_int, f_ext, use_ext, flags, v_prescribed, gx, gy, dt, alpha,
                local, use_viscous, ledger, sums):
    """One step of every triangle (:func:`fdem.kernels.stepping.triangle_step`); adds the
    ledger's sums (:data:`fdem.kernels.stepping.LEDGER_FIELDS`) into ``sums`` (13,).

    ``inertia`` (n_nodes, 2) always holds the inertial masses and their inverses (the lumped
    masses outside density-scaled stages): one kernel signature for every stage.
    """
    shared = cuda.shared.array((THREADS, N_STEP_SUMS), float64)
    tid = cuda.threadIdx.x
    t = cuda.grid(1)
    for k in range(N_STEP_SUMS):
        shared[tid, k] = 0.0
    if t < tc.shape[0]:
        c_keep, c_div = damping_factors(alpha, dt)
        damped = alpha != 0.0 or local != 0.0
        s = triangle_step(x, u, v, tc, t, inertia, f_int, use_int, f_ext, use_ext, flags, v_prescribed, gx, gy, dt,
                          alpha, c_keep, c_div, local, damped, use_viscous, ledger)
        for k in range(N_STEP_SUMS):
            shared[tid, k] = s[k]
    _reduce_block(shared, tid, N_STEP_SUMS, sums)


@cuda.jit
def crack_kernel(u, ref, f, nodes, const, status, state, diss, offset, dil, run, broke_flag, counts):
    """Crack elements ``run`` (live element ids): :func:`fdem.kernels.cracks.element_update`,
    forces added into ``f`` with atomics (``+F_i`` on the A node of end ``i``, ``-F_i`` on the B
    node). ``counts[0]`` counts the elements that broke (``broke_flag[c] = 1``), ``counts[1]``
    those that left the elastic range in this call (the host then reads ``status``)."""
    j = cuda.grid(1)
    if j >= run.shape[0]:
        return
    c = run[j]
    was_elastic = status[c] == 0
    broke, F0x, F0y, F1x, F1y = element_update(c, u, ref, nodes, const, status, state, diss, offset, dil)
    i0 = nodes[c, 0]
    i1 = nodes[c, 1]
    i2 = nodes[c, 2]
    i3 = nodes[c, 3]
    cuda.atomic.add(f, (i0, 0), F0x)
    cuda.atomic.add(f, (i0, 1), F0y)
    cuda.atomic.add(f, (i3, 0), -F0x)
    cuda.atomic.add(f, (i3, 1), -F0y)
    cuda.atomic.add(f, (i1, 0), F1x)
    cuda.atomic.add(f, (i1, 1), F1y)
    cuda.atomic.add(f, (i2, 0), -F1x)
    cuda.atomic.add(f, (i2, 1), -F1y)
    if broke:
        broke_flag[c] = 1
        cuda.atomic.add(counts, 0, 1)
    if was_elastic and status[c] != 0:
        cuda.atomic.add(counts, 1, 1)


@cuda.jit
def contact_kernel(x, v, pair_i, pair_j, starts, penalty, mu_base, face_mu, inv_f, kt_pair, damp, dt, spring, f_t,
                   touching, witness, f, sums):
    """Contact pairs, one thread per contactor: thread ``g`` runs
    :func:`fdem.kernels.contact_pairs._pair_range` over pairs ``[starts[g], starts[g+1])``
    (all pairs of one contactor, ``pair_i`` sorted), so it alone writes that contactor's nodes
    in ``f``. Adds ``(E_normal, E_tangential, W_friction, W_damping)`` into ``sums`` (4,)."""
    shared = cuda.shared.array((THREADS, N_CONTACT_SUMS), float64)
    tid = cuda.threadIdx.x
    g = cuda.grid(1)
    for k in range(N_CONTACT_SUMS):
        shared[tid, k] = 0.0
    if g < starts.shape[0] - 1:
        w = cuda.local.array(N_WORK, float64)
        iw = cuda.local.array(N_IWORK, int64)
        pool = cuda.local.array((MAX_VERT, N_COL), float64)
        e_n, e_t, w_f, w_d = _pair_range(starts[g], starts[g + 1], x, v, pair_i, pair_j, penalty, mu_base, face_mu,
                                         inv_f, kt_pair, damp, dt, spring, f_t, touching, witness, f, w, iw, pool)
        shared[tid, 0] = e_n
        shared[tid, 1] = e_t
        shared[tid, 2] = w_f
        shared[tid, 3] = w_d
    _reduce_block(shared, tid, N_CONTACT_SUMS, sums)


@cuda.jit
def gather_kernel(f, active, inc_ptr, inc_pair, f_t, touching):
    """Target-side contact forces, one thread per active triangle
    (:func:`fdem.kernels.contact_pairs._gather_one`: each writes only its own three nodes)."""
    a = cuda.grid(1)
    if a < active.shape[0]:
        _gather_one(f, active[a], inc_ptr[a], inc_ptr[a + 1], inc_pair, f_t, touching)


@cuda.jit
def moved_kernel(x, x_ref, active, out):
    """``out[0] = max(out[0], largest |x - x_ref|^2 over the active triangles' nodes)`` [m^2]."""
    a = cuda.grid(1)
    if a < active.shape[0]:
        cuda.atomic.max(out, 0, triangle_moved2(x, x_ref, active[a]))


@cuda.jit
def zero_kernel(a):
    """``a[:] = 0`` for a 2-D array (one thread per row)."""
    i = cuda.grid(1)
    if i < a.shape[0]:
        for k in range(a.shape[1]):
            a[i, k] = 0.0
