"""GPU contact search (numba-cuda): the CPU's binned grid, its pair test and its pair constants.

The steps of :meth:`fdem.physics.contact.ContactSet.search` on the device, one thread per item,
each calling the CPU's own ``@njit`` function (:mod:`fdem.kernels.contact_search`,
:mod:`fdem.kernels.contact_pairs`):

1. :func:`boxes_kernel`: each active triangle's box grown by half the skin (``triangle_box``),
   and the boxes' extent (atomic min / max);
2. :func:`bin_count_kernel`, :func:`bin_fill_kernel`: the counting sort of boxes into the grid
   cells they cover (``box_cells``; the cell offsets are a prefix sum taken on the host);
3. :func:`partner_count_kernel`, :func:`partner_fill_kernel`: each triangle's partners ``j > i``
   (``_query``: box overlap, reported from one cell, not bonded, not separated by more than the
   skin), written sorted (``_fill_partners``) at the offsets of a prefix sum, so that the pairs
   come out sorted by ``(i, j)`` as on the CPU, whatever order the cells were filled in;
4. :func:`pair_kernel`: each pair's key, friction history carried from the old pair list
   (``carry_history_one``) and constants (``pair_constants_one``);
5. :func:`incidence_count_kernel`, :func:`incidence_fill_kernel`, :func:`incidence_sort_kernel`:
   the pairs by target triangle, in pair order (the CPU's ``target_incidence``).

Prefix sums run on the host over the counts (one integer per cell or triangle): a short copy
each way, against bringing every position back and searching on the host.
"""
from __future__ import annotations

from numba import cuda

from fdem.kernels.contact_pairs import carry_history_one, crack_between, lower_bound, pair_constants_one
from fdem.kernels.contact_search import _fill_partners, _query, box_cells, triangle_box

__all__ = ["boxes_kernel", "bin_count_kernel", "bin_fill_kernel", "partner_count_kernel", "partner_fill_kernel",
           "pair_kernel", "incidence_count_kernel", "incidence_fill_kernel", "incidence_sort_kernel"]


@cuda.jit
def boxes_kernel(x, active, margin, box, extent):
    """``box[a]`` of triangle ``active[a]`` grown by ``margin``; ``extent`` = (min x, min y,
    -max x, -max y) of all boxes (atomic minima; start it at +inf)."""
    a = cuda.grid(1)
    if a < active.shape[0]:
        triangle_box(x, active[a], margin, box, a)
        cuda.atomic.min(extent, 0, box[a, 0])
        cuda.atomic.min(extent, 1, box[a, 1])
        cuda.atomic.min(extent, 2, -box[a, 2])
        cuda.atomic.min(extent, 3, -box[a, 3])


@cuda.jit
def bin_count_kernel(box, x0, y0, cell, nx, cell_cnt):
    """``cell_cnt[c + 1]`` += the boxes covering cell ``c``."""
    a = cuda.grid(1)
    if a < box.shape[0]:
        ix0, ix1, iy0, iy1 = box_cells(box, a, x0, y0, cell)
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                cuda.atomic.add(cell_cnt, iy * nx + ix + 1, 1)


@cuda.jit
def bin_fill_kernel(box, x0, y0, cell, nx, cell_ptr, fill, cell_items):
    """Box ids into ``cell_items[cell_ptr[c]:cell_ptr[c + 1]]`` (in any order: the partners are
    sorted afterwards)."""
    a = cuda.grid(1)
    if a < box.shape[0]:
        ix0, ix1, iy0, iy1 = box_cells(box, a, x0, y0, cell)
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                c = iy * nx + ix
                slot = cuda.atomic.add(fill, c, 1)
                cell_items[cell_ptr[c] + slot] = a


@cuda.jit
def partner_count_kernel(box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, dummy, counts):
    """``counts[a + 1]``: how many partners triangle ``active[a]`` has (``_query``)."""
    a = cuda.grid(1)
    if a < box.shape[0]:
        counts[a + 1] = _query(a, box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, dummy, False)


@cuda.jit
def partner_fill_kernel(box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, offsets, pair_i, pair_j):
    """Triangle ``active[a]``'s partners, sorted, into ``pair_j[offsets[a]:offsets[a + 1]]``."""
    a = cuda.grid(1)
    if a < box.shape[0]:
        _fill_partners(a, offsets[a], offsets[a + 1], box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr,
                       cell_items, pair_i, pair_j)


@cuda.jit
def pair_kernel(pair_i, pair_j, n_tri, old_keys, old_hist, keys, hist, touching, crack_keys, crack_order,
                broken, crack_mu, any_broken, kt_tri, mass_tri, damping_ratio, mu_base, kt_pair, damp_pair):
    """Pair ``q``: its key ``i n_tri + j``, its history carried from the old list, its constants."""
    q = cuda.grid(1)
    if q < pair_i.shape[0]:
        key = pair_i[q] * n_tri + pair_j[q]
        keys[q] = key
        carry_history_one(q, old_keys, old_hist, keys, hist, touching)
        crack = -1
        if any_broken:  # one thread a pair: bisection, then the merge's step
            crack, _ = crack_between(key, crack_keys, crack_order, lower_bound(crack_keys, key))
        pair_constants_one(q, pair_i, pair_j, crack, broken, crack_mu, kt_tri, mass_tri, damping_ratio,
                           mu_base, kt_pair, damp_pair)


@cuda.jit
def incidence_count_kernel(pair_j, slot, ptr):
    """``ptr[slot[j] + 1]`` += the pairs whose target is triangle ``j``."""
    q = cuda.grid(1)
    if q < pair_j.shape[0]:
        cuda.atomic.add(ptr, slot[pair_j[q]] + 1, 1)


@cuda.jit
def incidence_fill_kernel(pair_j, slot, ptr, fill, inc):
    """Pair ids into ``inc[ptr[s]:ptr[s + 1]]`` by target slot ``s`` (in any order)."""
    q = cuda.grid(1)
    if q < pair_j.shape[0]:
        s = slot[pair_j[q]]
        inc[ptr[s] + cuda.atomic.add(fill, s, 1)] = q


@cuda.jit
def incidence_sort_kernel(ptr, inc):
    """Each target's pair ids in ascending order (insertion sort: a triangle has few), so that
    the gather adds them in the CPU's order."""
    s = cuda.grid(1)
    if s < ptr.shape[0] - 1:
        lo = ptr[s]
        for r in range(lo + 1, ptr[s + 1]):
            val = inc[r]
            k = r - 1
            while k >= lo and inc[k] > val:
                inc[k + 1] = inc[k]
                k -= 1
            inc[k + 1] = val
