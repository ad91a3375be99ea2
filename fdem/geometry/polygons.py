"""Polygons: the outline of a slope section or a block, and the builders of common outlines.

A :class:`Polygon` is a simple, counter-clockwise ring of vertices (m); :func:`simple_slope`,
:func:`benched_slope`, :func:`rectangle` and :func:`disc` build the usual ones, and
:func:`slope_toe` and :func:`slope_crest` find the toe and crest of a slope outline (toe on the
left, crest on the right), :func:`ground_surface` its top as a function of x."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence
import numpy as np

__all__ = ["signed_area", "Polygon", "simple_slope", "benched_slope", "rectangle", "disc", "slope_toe", "slope_crest",
           "ground_surface"]


def _as_points(vertices, what: str) -> np.ndarray:
    pts = np.asarray(vertices, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{what}: vertices must be an (n, 2) array, got shape {pts.shape}")
    if len(pts) < 3:
        raise ValueError(f"{what}: a polygon needs at least 3 vertices, got {len(pts)}")
    if not np.all(np.isfinite(pts)):
        raise ValueError(f"{what}: vertices contain NaN or infinity")
    return pts


def signed_area(vertices: np.ndarray) -> float:
    """Shoelace area ``A = 1/2 sum(x_i y_{i+1} - x_{i+1} y_i)``, positive counter-clockwise [m^2]."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _segments_intersect_strictly(p, q, r, s, tol) -> bool:
    """True when segments pq and rs share a point other than a common endpoint."""
    d1, d2 = q - p, s - r
    denom = d1[0] * d2[1] - d1[1] * d2[0]
    rp = r - p
    if abs(denom) <= tol * (np.linalg.norm(d1) * np.linalg.norm(d2)):
        # Parallel: overlapping only if collinear and the projections overlap beyond a point.
        if abs(rp[0] * d1[1] - rp[1] * d1[0]) > tol * np.linalg.norm(d1) ** 2:
            return False
        L2 = float(d1 @ d1)
        t0, t1 = sorted(((r - p) @ d1 / L2, (s - p) @ d1 / L2))
        return min(t1, 1.0) - max(t0, 0.0) > tol
    t = (rp[0] * d2[1] - rp[1] * d2[0]) / denom
    u = (rp[0] * d1[1] - rp[1] * d1[0]) / denom
    return -tol <= t <= 1 + tol and -tol <= u <= 1 + tol


@dataclass(frozen=True)
class Polygon:
    """A simple (non-self-intersecting) polygon, stored counter-clockwise.

    Attributes
    ----------
    vertices : (n, 2) float64
        Corner coordinates [m], counter-clockwise, first vertex not repeated.
    name : str
        Used in error messages and as the body's name.
    """

    vertices: np.ndarray
    name: str = "body"

    def __post_init__(self):
        pts = _as_points(self.vertices, f"polygon {self.name!r}")
        # Drop a repeated closing vertex and consecutive duplicates.
        keep = np.r_[np.any(np.abs(np.diff(pts, axis=0)) > 0, axis=1), True]
        if np.allclose(pts[0], pts[-1]):
            keep[-1] = False
        pts = pts[keep]
        if len(pts) < 3:
            raise ValueError(f"polygon {self.name!r}: fewer than 3 distinct vertices")
        object.__setattr__(self, "vertices", pts)
        self._check_simple()
        area = signed_area(pts)
        if abs(area) <= 1e-12 * np.ptp(pts, axis=0).max() ** 2:
            raise ValueError(f"polygon {self.name!r}: zero area (collinear vertices)")
        if area < 0:
            object.__setattr__(self, "vertices", pts[::-1].copy())

    @property
    def area(self) -> float:
        return signed_area(self.vertices)

    @property
    def edges(self) -> np.ndarray:
        """(n, 2, 2) edges, edge i from vertex i to vertex i+1."""
        return np.stack([self.vertices, np.roll(self.vertices, -1, axis=0)], axis=1)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        (x0, y0), (x1, y1) = self.vertices.min(axis=0), self.vertices.max(axis=0)
        return float(x0), float(y0), float(x1), float(y1)

    @property
    def size(self) -> float:
        """Length of the bounding-box diagonal [m]: the scale of geometric tolerances."""
        x0, y0, x1, y1 = self.bounds
        return math.hypot(x1 - x0, y1 - y0)

    def _check_simple(self) -> None:
        e = self.edges
        n = len(e)
        tol = 1e-12
        for i in range(n):
            for j in range(i + 1, n):
                if j == i + 1 or (i == 0 and j == n - 1):
                    # Neighbouring edges may only share their common vertex (no fold-back).
                    a, b = (e[i], e[j]) if j == i + 1 else (e[j], e[i])
                    d1, d2 = a[1] - a[0], b[1] - b[0]
                    cross = d1[0] * d2[1] - d1[1] * d2[0]
                    if abs(cross) <= tol * np.linalg.norm(d1) * np.linalg.norm(d2) and d1 @ d2 < 0:
                        raise ValueError(
                            f"polygon {self.name!r} is self-intersecting: edges {i} and {j} fold back "
                            f"on each other at vertex {tuple(np.round(a[1], 9))}")
                    continue
                if _segments_intersect_strictly(e[i, 0], e[i, 1], e[j, 0], e[j, 1], tol):
                    raise ValueError(
                        f"polygon {self.name!r} is self-intersecting: edge {i} "
                        f"{tuple(np.round(e[i, 0], 6))}-{tuple(np.round(e[i, 1], 6))} crosses edge {j} "
                        f"{tuple(np.round(e[j, 0], 6))}-{tuple(np.round(e[j, 1], 6))}")

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Even-odd rule point-in-polygon test, vectorised over ``points`` (m, 2)."""
        pts = np.atleast_2d(points)
        x, y = pts[:, 0:1], pts[:, 1:2]
        a, b = self.vertices, np.roll(self.vertices, -1, axis=0)
        ay, by = a[:, 1][None, :], b[:, 1][None, :]
        ax, bx = a[:, 0][None, :], b[:, 0][None, :]
        straddles = (ay > y) != (by > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = ax + (y - ay) * (bx - ax) / (by - ay)
        return np.count_nonzero(straddles & (x < x_cross), axis=1) % 2 == 1


def simple_slope(height: float, face_angle: float, crest_length: float, toe_length: float,
                 base_depth: float, name: str = "slope") -> Polygon:
    """A single-face slope: toe floor on the left, face rising at ``face_angle`` [deg], crest on the right.

    The toe is at ``(toe_length, base_depth)``, the base at ``y = 0``; the model is
    ``toe_length + height/tan(face_angle) + crest_length`` wide and ``base_depth + height`` high.
    """
    return benched_slope([(height, face_angle, 0.0)], crest_length, toe_length, base_depth, name=name)


def benched_slope(benches: Sequence[tuple[float, float, float]], crest_length: float, toe_length: float,
                  base_depth: float, name: str = "slope") -> Polygon:
    """A benched slope: ``benches`` lists ``(bench height [m], face angle [deg], berm width [m])`` from the toe up.

    The berm width of the last bench is ignored (the crest plateau follows).
    """
    for label, value in (("crest_length", crest_length), ("toe_length", toe_length), ("base_depth", base_depth)):
        if not value > 0:
            raise ValueError(f"slope {name!r}: {label} must be positive, got {value}")
    if not benches:
        raise ValueError(f"slope {name!r}: at least one bench is needed")
    pts = [(0.0, 0.0)]
    x, y = toe_length, base_depth
    pts.append((0.0, y))
    pts.append((x, y))
    for k, (h, angle, berm) in enumerate(benches):
        if not h > 0:
            raise ValueError(f"slope {name!r}: bench {k} height must be positive, got {h}")
        if not 0 < angle <= 90:
            raise ValueError(f"slope {name!r}: bench {k} face angle must be in (0, 90] degrees, got {angle}")
        if berm < 0:
            raise ValueError(f"slope {name!r}: bench {k} berm width must be >= 0, got {berm}")
        x += h / math.tan(math.radians(angle)) if angle < 90 else 0.0
        y += h
        pts.append((x, y))
        if k < len(benches) - 1 and berm > 0:
            x += berm
            pts.append((x, y))
    x += crest_length
    pts.append((x, y))
    pts.append((x, 0.0))
    return Polygon(np.array(pts), name=name)


def rectangle(x0: float, y0: float, width: float, height: float, name: str = "block") -> Polygon:
    """An axis-aligned rectangle with lower-left corner ``(x0, y0)``."""
    if not (width > 0 and height > 0):
        raise ValueError(f"rectangle {name!r}: width and height must be positive, got {width}, {height}")
    return Polygon(np.array([[x0, y0], [x0 + width, y0], [x0 + width, y0 + height], [x0, y0 + height]]), name=name)


def disc(centre: tuple[float, float], radius: float, n_sides: int = 64, name: str = "disc") -> Polygon:
    """A regular ``n_sides``-gon inscribed in the circle of ``radius`` [m] (e.g. a Brazilian disc).

    Its area is ``n/2 r^2 sin(2 pi / n)``, within 0.2 % of ``pi r^2`` for 64 sides.
    """
    if not radius > 0:
        raise ValueError(f"disc {name!r}: radius must be positive, got {radius}")
    if n_sides < 8:
        raise ValueError(f"disc {name!r}: use at least 8 sides, got {n_sides}")
    a = 2 * np.pi * np.arange(n_sides) / n_sides
    return Polygon(np.column_stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)]), name=name)


def slope_toe(polygon) -> tuple[float, float]:
    """``(x, y)`` of the toe of a slope polygon whose toe is on the left (the project's
    convention): the floor in front of the toe is the lowest part of the ground surface (the
    vertices above the base), and the toe is its rightmost vertex."""
    v = np.asarray(getattr(polygon, "vertices", polygon), dtype=np.float64)
    above = v[v[:, 1] > v[:, 1].min()]
    if above.size == 0:
        raise ValueError("slope_toe: the polygon has no vertex above its base")
    floor_y = above[:, 1].min()
    return float(above[above[:, 1] == floor_y, 0].max()), float(floor_y)


def slope_crest(polygon) -> tuple[float, float]:
    """``(x, y)`` of the crest of a slope polygon whose toe is on the left: the leftmost vertex
    at the greatest height (where the face meets the crest plateau)."""
    v = np.asarray(getattr(polygon, "vertices", polygon), dtype=np.float64)
    top_y = v[:, 1].max()
    return float(v[v[:, 1] == top_y, 0].min()), float(top_y)


def ground_surface(slope):
    """``y_s(x)``: the top of a slope profile (the polygon's vertices above its base, left to
    right, linearly interpolated), for a geostatic stress or the cover depth ``y_s(x) - y``."""
    v = slope.vertices
    base = slope.bounds[1]
    top = v[v[:, 1] > base]
    top = top[np.argsort(top[:, 0], kind="stable")]
    return lambda x: np.interp(x, top[:, 0], top[:, 1])
