"""Look at a meshed model before running it: a PNG picture and a ParaView ``.vtu`` of the mesh
with its crack elements as line cells, tagged intact (0) or by joint set (1, 2, ...)."""
from __future__ import annotations

from pathlib import Path
import numpy as np
from fdem.mesh.topology import Topology

__all__ = ["write_mesh_vtu", "plot_mesh_png"]


def write_mesh_vtu(topology: Topology, path: str | Path) -> Path:
    """Write triangles and crack elements (as 2-node line cells on the shared mesh) to ``path``.

    Cell data: ``kind`` (0 triangle, 1 crack element), ``joint_set`` (crack tag; -1 on triangles),
    ``body``, ``min_angle_deg`` (triangles; 0 on lines).
    """
    import meshio

    from fdem.mesh.triangles import triangle_angles

    mesh = topology.mesh
    pts = np.column_stack([mesh.points, np.zeros(len(mesh.points))])
    crack_lines = topology.mesh_node[topology.crack_nodes[:, :2]]
    n_tri, n_crack = mesh.n_triangles, topology.n_cracks
    out = meshio.Mesh(
        pts,
        [("triangle", mesh.triangles), ("line", crack_lines)],
        cell_data={
            "kind": [np.zeros(n_tri, np.int32), np.ones(n_crack, np.int32)],
            "joint_set": [np.full(n_tri, -1, np.int32), topology.crack_tag.astype(np.int32)],
            "body": [mesh.triangle_body.astype(np.int32),
                     topology.triangle_body[topology.crack_triangles[:, 0]].astype(np.int32)],
            "min_angle_deg": [triangle_angles(mesh.points, mesh.triangles).min(axis=1), np.zeros(n_crack)],
        },
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meshio.write(str(path), out, binary=True)
    return path


def plot_mesh_png(topology: Topology, path: str | Path, title: str = "", dpi: int = 150,
                  show_mesh: bool | None = None) -> Path:
    """Draw the mesh (grey), the joints coloured by set and the outer boundary (black) to a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    mesh = topology.mesh
    fig, ax = plt.subplots(figsize=(12, 5))
    if show_mesh is None:
        show_mesh = mesh.n_triangles <= 60000
    if show_mesh:
        ax.triplot(mesh.points[:, 0], mesh.points[:, 1], mesh.triangles, lw=0.15, color="0.7")
    x = topology.x0
    cmap = plt.get_cmap("tab10")
    for j in np.unique(topology.crack_tag):
        if j == 0:
            continue
        c = topology.crack_nodes[topology.crack_tag == j]
        ax.add_collection(LineCollection(np.stack([x[c[:, 0]], x[c[:, 1]]], axis=1), colors=[cmap(j % 10)],
                                         linewidths=0.8, label=f"joint set {j}"))
    b = topology.boundary_edges
    ax.add_collection(LineCollection(np.stack([x[b[:, 0]], x[b[:, 1]]], axis=1), colors="k", linewidths=1.0))
    ax.set_aspect("equal")
    ax.autoscale()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or f"{mesh.n_triangles} triangles, {topology.n_cracks} crack elements")
    if np.any(topology.crack_tag > 0):
        ax.legend(loc="upper left", fontsize=8)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
