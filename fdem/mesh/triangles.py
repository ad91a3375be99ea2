"""Triangle geometry, the one home: areas, validity, shape gradients, altitudes, angles.

Every other module computes a triangle's area, its gradients or its angles through these
functions. ``points`` (n, 2) [m]; ``triangles`` (n_tri, 3) counter-clockwise node indices."""
from __future__ import annotations

import numpy as np

__all__ = ["triangle_angles", "triangle_areas", "check_triangles", "triangle_shape_gradients",
           "smallest_altitude"]


def triangle_angles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(n_tri, 3) interior angles [deg] at each corner, from the law of cosines on edge vectors."""
    p = points[triangles]
    angles = np.empty(triangles.shape)
    for k in range(3):
        a = p[:, (k + 1) % 3] - p[:, k]
        b = p[:, (k + 2) % 3] - p[:, k]
        cross = np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
        angles[:, k] = np.degrees(np.arctan2(cross, (a * b).sum(axis=1)))
    return angles


def triangle_areas(x: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Signed areas ``A = ((x1-x0) x (x2-x0))/2`` of triangles; positive when counter-clockwise."""
    p0, p1, p2 = x[triangles[:, 0]], x[triangles[:, 1]], x[triangles[:, 2]]
    return 0.5 * ((p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0]))


def check_triangles(points: np.ndarray, triangles: np.ndarray, rel_tol: float = 1e-12) -> None:
    """Raise ``ValueError`` naming the first degenerate or inverted triangle and its corners."""
    area = triangle_areas(points, triangles)
    scale = np.ptp(points, axis=0).max() if len(points) else 1.0
    bad = np.flatnonzero(area <= rel_tol * scale**2)
    if bad.size:
        t = int(bad[0])
        kind = "inverted" if area[t] < 0 else "degenerate"
        corners = ", ".join(f"({px:.6g}, {py:.6g})" for px, py in points[triangles[t]])
        raise ValueError(
            f"{bad.size} degenerate or inverted triangle(s); first: triangle {t} is {kind} "
            f"(signed area {area[t]:.3g} m^2) with corners {corners}"
        )


def triangle_shape_gradients(x0: np.ndarray, triangles: np.ndarray):
    """Inverse reference shape matrices and areas of triangles.

    ``Dm = [X1 - X0, X2 - X0]`` (columns), ``B = Dm^-1`` (n_tri, 2, 2) [1/m], ``A0 = det(Dm)/2``
    (n_tri,) [m^2]. Shape-function gradients: ``grad N1 = B[0]``, ``grad N2 = B[1]``,
    ``grad N0 = -(B[0] + B[1])``.
    """
    p0, p1, p2 = x0[triangles[:, 0]], x0[triangles[:, 1]], x0[triangles[:, 2]]
    dm = np.empty((len(triangles), 2, 2))
    dm[:, :, 0] = p1 - p0
    dm[:, :, 1] = p2 - p0
    det = dm[:, 0, 0] * dm[:, 1, 1] - dm[:, 0, 1] * dm[:, 1, 0]
    inv = np.empty_like(dm)
    inv[:, 0, 0] = dm[:, 1, 1] / det
    inv[:, 0, 1] = -dm[:, 0, 1] / det
    inv[:, 1, 0] = -dm[:, 1, 0] / det
    inv[:, 1, 1] = dm[:, 0, 0] / det
    return inv, 0.5 * det


def smallest_altitude(x0: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(n_tri,) smallest altitude ``h = 2 A / L_max`` of each triangle [m]."""
    p = x0[triangles]
    edges = np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2)
    area = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                        - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    return 2.0 * area / edges.max(axis=1)
