"""Contact broad phase (Numba): bounding boxes, a binned grid and a brute-force reference.

Candidate pairs are triangles whose boxes, grown by the search buffer (skin), overlap and that
are not bonded by an intact crack element; a separating-axis test drops pairs that are
farther apart than the buffer. :func:`grid_pairs` runs in linear time; :func:`brute_force_pairs`
is its O(n^2) check. :func:`max_displacement` tells when the accumulated motion exceeds the
buffer and the search must run again."""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from fdem.kernels.contact_pairs import PARALLEL_MIN_PAIRS, _corners, _max3

__all__ = ["triangle_box", "triangle_boxes", "grid_shape", "box_cells", "brute_force_pairs", "grid_pairs", "fan_pairs", "triangle_moved2", "max_displacement"]


# ----------------------------------------------------------------------------- broad phase
@njit(cache=True, error_model="numpy", inline="always")
def triangle_box(x, t, margin, box, a):
    """Row ``a`` of ``box``: the axis-aligned box ``[xmin, ymin, xmax, ymax]`` of exploded
    triangle ``t``, grown by ``margin`` [m] (the CPU's and the GPU's broad phase)."""
    x0, x1, x2 = x[3 * t, 0], x[3 * t + 1, 0], x[3 * t + 2, 0]
    y0, y1, y2 = x[3 * t, 1], x[3 * t + 1, 1], x[3 * t + 2, 1]
    box[a, 0] = min(x0, min(x1, x2)) - margin
    box[a, 1] = min(y0, min(y1, y2)) - margin
    box[a, 2] = max(x0, max(x1, x2)) + margin
    box[a, 3] = max(y0, max(y1, y2)) + margin


@njit(cache=True, error_model="numpy")
def triangle_boxes(x, active, margin):
    """(n_act, 4) axis-aligned boxes ``[xmin, ymin, xmax, ymax]`` of triangles, grown by ``margin``."""
    n = active.shape[0]
    box = np.empty((n, 4))
    for a in range(n):
        triangle_box(x, active[a], margin, box, a)
    return box


@njit(cache=True, error_model="numpy")
def grid_shape(x0, y0, x1, y1, cell, max_cells):
    """``(cell, nx, ny)``: the binning grid over ``[x0, x1] x [y0, y1]`` with cells of side
    ``cell`` [m], enlarged when that would make more than ``max_cells`` cells."""
    w = max(x1 - x0, 1e-300)
    h = max(y1 - y0, 1e-300)
    if (w / cell + 1.0) * (h / cell + 1.0) > max_cells:
        cell = max(cell, math.sqrt(w * h / max_cells), w / max_cells, h / max_cells) * 1.0001
    return cell, int(w / cell) + 1, int(h / cell) + 1


@njit(cache=True, error_model="numpy", inline="always")
def box_cells(box, a, x0, y0, cell):
    """``(ix0, ix1, iy0, iy1)``: the grid cells box ``a`` covers (inclusive)."""
    return (int((box[a, 0] - x0) / cell), int((box[a, 2] - x0) / cell),
            int((box[a, 1] - y0) / cell), int((box[a, 3] - y0) / cell))


@njit(cache=True, error_model="numpy")
def _boxes_overlap(box, a, b):
    return (box[a, 0] <= box[b, 2] and box[b, 0] <= box[a, 2]
            and box[a, 1] <= box[b, 3] and box[b, 1] <= box[a, 3])


@njit(cache=True, error_model="numpy")
def _bonded(bond, i, j):
    return bond[i, 0] == j or bond[i, 1] == j or bond[i, 2] == j


@njit(cache=True, error_model="numpy", inline="always")
def _axis_gap(nx, ny, c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y):
    """Gap between the projections of c and t on the (unnormalised) direction ``n``:
    ``max(min n.c - max n.t, min n.t - max n.c)`` (negative when the projections overlap)."""
    pc0 = nx * c0x + ny * c0y
    pc1 = nx * c1x + ny * c1y
    pc2 = nx * c2x + ny * c2y
    pt0 = nx * t0x + ny * t0y
    pt1 = nx * t1x + ny * t1y
    pt2 = nx * t2x + ny * t2y
    return max(min(pc0, min(pc1, pc2)) - _max3(pt0, pt1, pt2), min(pt0, min(pt1, pt2)) - _max3(pc0, pc1, pc2))


@njit(cache=True, error_model="numpy")
def _far_apart(x, i, j, gap):
    """True when an edge normal of triangle ``i`` or ``j`` separates them by more than ``gap`` [m].

    A fixed direction stays separating while every node moves less than ``gap / 2``: the
    projections then move less than ``gap`` relative to each other. So such a pair cannot touch
    before the next re-search (every node within half the skin) and need not be a candidate;
    this drops the pairs whose grown boxes overlap only across a corner (a third of a
    structured mesh's box pairs). Edge normal ``n = (e_y, -e_x)``: gap > ``gap |e|``.
    """
    c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y = _corners(x, i, j)
    for k in range(6):
        if k == 0:
            ex, ey = c1x - c0x, c1y - c0y
        elif k == 1:
            ex, ey = c2x - c1x, c2y - c1y
        elif k == 2:
            ex, ey = c0x - c2x, c0y - c2y
        elif k == 3:
            ex, ey = t1x - t0x, t1y - t0y
        elif k == 4:
            ex, ey = t2x - t1x, t2y - t1y
        else:
            ex, ey = t0x - t2x, t0y - t2y
        g = _axis_gap(ey, -ex, c0x, c0y, c1x, c1y, c2x, c2y, t0x, t0y, t1x, t1y, t2x, t2y)
        if g > 0.0 and g * g > gap * gap * (ex * ex + ey * ey):
            return True
    return False


@njit(cache=True, error_model="numpy")
def brute_force_pairs(box, active, bond, x, gap):
    """Reference broad phase, O(n^2): all ``(i, j)``, ``i < j``, of active triangles whose grown
    boxes overlap, that no edge normal separates by more than ``gap`` (:func:`_far_apart`) and
    that are not bonded by an intact crack element, sorted by ``(i, j)``.

    ``active`` must be sorted ascending; ``bond[t]`` lists the (up to 3) triangles bonded to t, -1
    padded.
    """
    n = active.shape[0]
    cnt = 0
    for a in range(n):
        for b in range(a + 1, n):
            if (_boxes_overlap(box, a, b) and not _bonded(bond, active[a], active[b])
                    and not _far_apart(x, active[a], active[b], gap)):
                cnt += 1
    pi = np.empty(cnt, np.int64)
    pj = np.empty(cnt, np.int64)
    cnt = 0
    for a in range(n):
        for b in range(a + 1, n):
            if (_boxes_overlap(box, a, b) and not _bonded(bond, active[a], active[b])
                    and not _far_apart(x, active[a], active[b], gap)):
                pi[cnt] = active[a]
                pj[cnt] = active[b]
                cnt += 1
    return pi, pj


@njit(cache=True, error_model="numpy")
def _grid_bin(box, cell, max_cells):
    """Grid geometry and the counting sort of boxes into every cell they cover.

    Returns ``(x0, y0, cell, nx, ny, cell_ptr, cell_items)``; ``cell`` is enlarged when the
    requested one would make more than ``max_cells`` cells.
    """
    n = box.shape[0]
    x0 = np.inf
    y0 = np.inf
    x1 = -np.inf
    y1 = -np.inf
    for a in range(n):
        x0 = min(x0, box[a, 0])
        y0 = min(y0, box[a, 1])
        x1 = max(x1, box[a, 2])
        y1 = max(y1, box[a, 3])
    cell, nx, ny = grid_shape(x0, y0, x1, y1, cell, max_cells)
    cell_cnt = np.zeros(nx * ny + 1, np.int64)
    for a in range(n):
        ix0, ix1, iy0, iy1 = box_cells(box, a, x0, y0, cell)
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                cell_cnt[iy * nx + ix + 1] += 1
    for c in range(nx * ny):
        cell_cnt[c + 1] += cell_cnt[c]
    cell_ptr = cell_cnt.copy()
    cell_items = np.empty(cell_ptr[nx * ny], np.int64)
    fill = cell_cnt[:-1].copy()
    for a in range(n):
        ix0, ix1, iy0, iy1 = box_cells(box, a, x0, y0, cell)
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                c = iy * nx + ix
                cell_items[fill[c]] = a
                fill[c] += 1
    return x0, y0, cell, nx, ny, cell_ptr, cell_items


@njit(cache=True, error_model="numpy")
def _query(a, box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, outj, write):
    """Partners ``b`` of box ``a`` with ``active[b] > active[a]``: each pair is reported once, from
    the cell holding the lower-left corner of the two boxes' intersection. Returns the count."""
    ix0, ix1, iy0, iy1 = box_cells(box, a, x0, y0, cell)
    ta = active[a]
    cnt = 0
    for iy in range(iy0, iy1 + 1):
        for ix in range(ix0, ix1 + 1):
            c = iy * nx + ix
            for r in range(cell_ptr[c], cell_ptr[c + 1]):
                b = cell_items[r]
                tb = active[b]
                if tb <= ta or not _boxes_overlap(box, a, b):
                    continue
                cx = int((max(box[a, 0], box[b, 0]) - x0) / cell)
                cy = int((max(box[a, 1], box[b, 1]) - y0) / cell)
                if cx != ix or cy != iy or _bonded(bond, ta, tb) or _far_apart(x, ta, tb, gap):
                    continue
                if write:
                    outj[cnt] = tb
                cnt += 1
    return cnt


@njit(cache=True, error_model="numpy")
def _fill_partners(a, lo, hi, box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, pi, pj):
    """Write box ``a``'s partners into ``pj[lo:hi]`` sorted (insertion sort: they are few)."""
    if hi == lo:
        return
    seg = pj[lo:hi]
    _query(a, box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, seg, True)
    for r in range(1, hi - lo):
        val = seg[r]
        s = r - 1
        while s >= 0 and seg[s] > val:
            seg[s + 1] = seg[s]
            s -= 1
        seg[s + 1] = val
    for r in range(lo, hi):
        pi[r] = active[a]


@njit(parallel=True, cache=True, error_model="numpy")
def _grid_query_parallel(box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, counts):
    n = box.shape[0]
    dummy = np.empty(0, np.int64)
    for a in prange(n):
        counts[a + 1] = _query(a, box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, dummy, False)
    for a in range(n):
        counts[a + 1] += counts[a]
    pi = np.empty(counts[n], np.int64)
    pj = np.empty(counts[n], np.int64)
    for a in prange(n):
        _fill_partners(a, counts[a], counts[a + 1], box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items,
                       pi, pj)
    return pi, pj


@njit(cache=True, error_model="numpy")
def grid_pairs(box, active, bond, x, gap, cell, max_cells):
    """Linear-time broad phase on a uniform grid (counting sort of boxes into cells).

    Same result as :func:`brute_force_pairs` (same box test, same edge-normal pruning by ``gap``,
    same bond exclusion), for any cell size. Pairs come out sorted by ``(i, j)`` because ``active`` is sorted and each triangle's
    partners are sorted. Cost O(n) for a cell about the size of a box. The queries run in
    parallel for large sets (two passes: count, then fill).
    """
    n = box.shape[0]
    if n < 2:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    x0, y0, cell, nx, ny, cell_ptr, cell_items = _grid_bin(box, cell, max_cells)
    counts = np.zeros(n + 1, np.int64)
    if n >= PARALLEL_MIN_PAIRS // 4:
        return _grid_query_parallel(box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, counts)
    dummy = np.empty(0, np.int64)
    for a in range(n):
        counts[a + 1] = counts[a] + _query(a, box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items, dummy,
                                           False)
    pi = np.empty(counts[n], np.int64)
    pj = np.empty(counts[n], np.int64)
    for a in range(n):
        _fill_partners(a, counts[a], counts[a + 1], box, active, bond, x, gap, x0, y0, cell, nx, cell_ptr, cell_items,
                       pi, pj)
    return pi, pj


@njit(cache=True, error_model="numpy")
def fan_pairs(ptr, tri, vertices, bond):
    """Vertex-neighbour pairs ``(i, j)``, ``i < j``, of the triangles around each of ``vertices``
    (``tri[ptr[v]:ptr[v+1]]``) that no intact crack element bonds (``bond``, -1 padded); a pair
    around two of the vertices comes twice (the caller removes duplicates)."""
    cnt = 0
    for r in range(vertices.shape[0]):
        v = vertices[r]
        for a in range(ptr[v], ptr[v + 1]):
            for b in range(a + 1, ptr[v + 1]):
                i = min(tri[a], tri[b])
                j = max(tri[a], tri[b])
                if i != j and not _bonded(bond, i, j):
                    cnt += 1
    pi = np.empty(cnt, np.int64)
    pj = np.empty(cnt, np.int64)
    cnt = 0
    for r in range(vertices.shape[0]):
        v = vertices[r]
        for a in range(ptr[v], ptr[v + 1]):
            for b in range(a + 1, ptr[v + 1]):
                i = min(tri[a], tri[b])
                j = max(tri[a], tri[b])
                if i != j and not _bonded(bond, i, j):
                    pi[cnt] = i
                    pj[cnt] = j
                    cnt += 1
    return pi, pj


@njit(cache=True, inline="always")
def triangle_moved2(x, x_ref, t):
    """Largest squared displacement ``|x - x_ref|^2`` [m^2] of the three nodes of exploded
    triangle ``t`` (the contact search's trigger, on the CPU and the GPU)."""
    m = 0.0
    for k in range(3):
        dx = x[3 * t + k, 0] - x_ref[3 * t + k, 0]
        dy = x[3 * t + k, 1] - x_ref[3 * t + k, 1]
        m = max(m, dx * dx + dy * dy)
    return m


@njit(cache=True, error_model="numpy")
def max_displacement(x, x_ref, active):
    """Largest ``|x - x_ref|`` over the nodes of the active triangles [m] (serial: memory-bound,
    one pass, cheaper than waking threads)."""
    m = 0.0
    for a in range(active.shape[0]):
        m = max(m, triangle_moved2(x, x_ref, active[a]))
    return np.sqrt(m)
