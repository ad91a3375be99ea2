"""The overburden above a point and the lithostatic stress it weighs: the yardstick of a geostatic state.

* :func:`depth_below_surface`: thickness of rock straight above each point [m], from the
  mesh's external edges (crossings of a vertical ray, signed by the edge's outward normal, so
  air gaps under an overhang and the shared faces of two stacked bodies count right).
* :func:`lithostatic_ratio`: ``-sigma_yy / (rho g d)`` [-], 1 where a column carries exactly
  its own weight (uniaxial strain, e.g. Jaeger, Cook & Zimmerman 2007, section 15.2).
"""
from __future__ import annotations

import numpy as np

__all__ = ["depth_below_surface", "lithostatic_ratio"]


def depth_below_surface(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Thickness of rock above each of ``points`` (n, 2) [m] along the vertical (+y).

    ``segments`` (m, 2, 2) are the external edges of the rock in the order of their triangle's
    counter-clockwise boundary (``Topology.boundary_edges`` at the reference positions, see
    :func:`fdem.io.pictures.boundary_segments`), so the outward normal of the edge ``a -> b`` is
    ``(b_y - a_y, a_x - b_x)/L``. Going up from a point ``p``, an edge whose normal points up is
    an exit from the rock and one whose normal points down an entry; the rock above is

        ``d(p) = sum_exits (y_e - y_p) - sum_entries (y_e - y_p)``

    over the edges crossed above ``p`` (``y_e`` the crossing's height). Two bodies resting on
    each other cancel at their shared face; an air gap is left out. Vertical edges are never
    crossed; an x equal to an edge's end counts on the edge with the larger x only, so a vertex
    is crossed once. Points that see no rock above get 0.
    """
    p = np.asarray(points, dtype=np.float64)
    s = np.asarray(segments, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got {p.shape}")
    if s.ndim != 3 or s.shape[1:] != (2, 2):
        raise ValueError(f"segments must have shape (m, 2, 2), got {s.shape}")
    order = np.argsort(p[:, 0], kind="stable")
    px = p[order, 0]
    depth = np.zeros(len(p))
    for (ax_, ay), (bx, by) in s:
        if ax_ == bx:
            continue
        lo, hi = min(ax_, bx), max(ax_, bx)
        i0, i1 = np.searchsorted(px, lo, side="left"), np.searchsorted(px, hi, side="left")  # [lo, hi)
        if i0 == i1:
            continue
        idx = order[i0:i1]
        ye = ay + (p[idx, 0] - ax_) * (by - ay) / (bx - ax_)
        above = ye > p[idx, 1]
        sign = 1.0 if ax_ > bx else -1.0  # normal y = a_x - b_x: up for an edge running toward -x
        depth[idx[above]] += sign * (ye[above] - p[idx[above], 1])
    return depth


def lithostatic_ratio(sigma_yy: np.ndarray, density, gravity: float, depth: np.ndarray,
                      min_depth: float = 0.0) -> np.ndarray:
    """``-sigma_yy / (rho g d)`` [-]: the vertical stress [Pa] (tension positive) over the weight
    of the rock above (``rho`` [kg/m^3], scalar or per point; ``g`` [m/s^2]; ``d`` [m] from
    :func:`depth_below_surface`). ``nan`` where ``d <= min_depth`` (no overburden to compare with:
    the top row of triangles has a depth of a third of its height and the ratio there is noise)."""
    syy = np.asarray(sigma_yy, dtype=np.float64)
    d = np.asarray(depth, dtype=np.float64)
    rho = np.broadcast_to(np.asarray(density, dtype=np.float64), syy.shape)
    if syy.shape != d.shape:
        raise ValueError(f"sigma_yy {syy.shape} and depth {d.shape} must have the same shape")
    if not gravity > 0:
        raise ValueError(f"gravity must be positive [m/s^2], got {gravity}")
    out = np.full(syy.shape, np.nan)
    ok = d > min_depth
    out[ok] = -syy[ok] / (rho[ok] * gravity * d[ok])
    return out
