"""Mesh quality report: angles, areas, altitudes and the worst triangles of a :class:`~fdem.mesh.mesh.Mesh`."""
from __future__ import annotations

from dataclasses import dataclass
import numpy as np
from fdem.mesh.mesh import Mesh
from fdem.mesh.triangles import triangle_angles

__all__ = ["QualityReport", "quality_report"]


@dataclass(frozen=True)
class QualityReport:
    """Mesh quality figures.

    ``min_angle_deg`` is the smallest interior angle of any triangle; ``edge_min`` and
    ``edge_max`` bound the edge lengths [m]; ``worst`` lists ``(triangle, min angle [deg],
    centroid)`` of the sharpest triangles.
    """

    n_triangles: int
    n_nodes: int
    area: float
    min_angle_deg: float
    mean_min_angle_deg: float
    edge_min: float
    edge_max: float
    edge_mean: float
    min_angles: np.ndarray
    worst: list

    def n_below_warning(self, angle: float) -> int:
        return int(np.count_nonzero(self.min_angles < angle))

    def as_dict(self) -> dict:
        return {
            "n_triangles": self.n_triangles,
            "n_nodes": self.n_nodes,
            "area_m2": self.area,
            "min_angle_deg": self.min_angle_deg,
            "mean_min_angle_deg": self.mean_min_angle_deg,
            "fraction_min_angle_below_20deg": float(np.mean(self.min_angles < 20.0)),
            "edge_min_m": self.edge_min,
            "edge_max_m": self.edge_max,
            "edge_mean_m": self.edge_mean,
            "worst": [{"triangle": int(t), "min_angle_deg": float(a), "centroid": [float(c[0]), float(c[1])]}
                      for t, a, c in self.worst],
        }

    def __str__(self) -> str:
        lines = [
            f"triangles {self.n_triangles}, nodes {self.n_nodes}, area {self.area:.6g} m^2",
            f"min angle {self.min_angle_deg:.2f} deg (mean of per-triangle minima {self.mean_min_angle_deg:.2f} deg, "
            f"{100 * np.mean(self.min_angles < 20):.2f} % below 20 deg)",
            f"edge length {self.edge_min:.4g} .. {self.edge_max:.4g} m (mean {self.edge_mean:.4g} m)",
            "worst: " + "; ".join(f"#{t} {a:.1f} deg at ({c[0]:.3f}, {c[1]:.3f})" for t, a, c in self.worst),
        ]
        return "\n".join(lines)


def quality_report(mesh: Mesh, worst: int = 5) -> QualityReport:
    """Element count, minimum angle, edge-length range and the ``worst`` sharpest triangles."""
    min_angles = triangle_angles(mesh.points, mesh.triangles).min(axis=1)
    p = mesh.points[mesh.triangles]
    edges = np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2)
    k = np.argsort(min_angles, kind="stable")[:worst]
    centroids = p.mean(axis=1)
    return QualityReport(
        n_triangles=mesh.n_triangles,
        n_nodes=len(mesh.points),
        area=mesh.area(),
        min_angle_deg=float(min_angles.min()),
        mean_min_angle_deg=float(min_angles.mean()),
        edge_min=float(edges.min()),
        edge_max=float(edges.max()),
        edge_mean=float(edges.mean()),
        min_angles=min_angles,
        worst=[(int(t), float(min_angles[t]), centroids[t]) for t in k],
    )
