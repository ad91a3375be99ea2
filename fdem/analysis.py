"""Results of a run: fragments, runout distance and volume, released kinetic energy.

All functions take plain arrays (positions, topology, broken flags) so they work on a live
simulation or on a saved state.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .topology import Topology, triangle_areas


def fragments(topology: Topology, broken: np.ndarray) -> tuple[int, np.ndarray]:
    """Clusters of triangles still bonded by intact crack elements.

    Returns ``(n_fragments, label)`` with ``label`` (n_tri,) the fragment of each triangle
    (connected components of the graph whose edges are the unbroken crack elements).
    """
    intact = ~np.asarray(broken, dtype=bool)
    a, b = topology.crack_triangles[intact, 0], topology.crack_triangles[intact, 1]
    n = topology.n_triangles
    graph = coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)


def fragment_areas(topology: Topology, label: np.ndarray) -> np.ndarray:
    """Area of each fragment [m^2 per metre of thickness], indexed by fragment label."""
    return np.bincount(label, weights=topology.triangle_area0)


def runout(topology: Topology, x: np.ndarray, toe_x: float, threshold: float = 0.1,
           toward: float = -1.0) -> dict[str, float]:
    """Runout of the failed mass of a slope whose toe is at ``x = toe_x``.

    Triangles whose centroid moved more than ``threshold`` [m] count as displaced. With the toe
    on the left (``toward = -1``) the runout distance is how far the farthest displaced
    triangle's centroid lies beyond the toe, ``max(toe_x - x_c)`` [m] (0 if none passed it);
    the runout volume is the reference area of displaced triangles [m^2 per metre].
    """
    x0c = topology.x0[topology.triangles].mean(axis=1)
    xc = x[topology.triangles].mean(axis=1)
    moved = np.linalg.norm(xc - x0c, axis=1) > threshold
    beyond = toward * (xc[moved, 0] - toe_x)
    return {
        "displaced_area_m2": float(topology.triangle_area0[moved].sum()),
        "runout_distance_m": float(max(beyond.max(), 0.0)) if beyond.size else 0.0,
        "max_displacement_m": float(np.linalg.norm(x - topology.x0, axis=1).max()),
        "n_displaced_triangles": int(moved.sum()),
        "deformed_area_m2": float(triangle_areas(x, topology.triangles).sum()),
    }


def released_kinetic_energy(history: list[dict]) -> float:
    """Peak kinetic energy reached during the rows of ``history`` [J per metre]."""
    return float(max((row.get("kinetic", 0.0) for row in history), default=0.0))
