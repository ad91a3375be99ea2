"""Conforming triangle meshes: the Mesh dataclass, meshio read/write, structured test meshes.

Gmsh meshing of a :class:`fdem.geometry.section.Geometry` lives in :mod:`fdem.mesh.triangulate`,
the quality report in :mod:`fdem.mesh.quality`; this module needs
neither Gmsh nor the geometry, so the solver and the tests can build meshes without them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
import numpy as np

__all__ = ["JOINT_GROUP_PREFIX", "Mesh", "structured_rectangle", "jittered_rectangle"]


JOINT_GROUP_PREFIX = "joint_set_"
"""Physical groups named ``joint_set_<j>`` (j >= 1) mark the curves of DFN joint set ``j``."""


@dataclass(frozen=True)
class Mesh:
    """A conforming, counter-clockwise triangle mesh with tagged curves.

    Attributes
    ----------
    points : (n_points, 2) float64
        Node coordinates [m].
    triangles : (n_tri, 3) int64
        Node ids of each triangle, counter-clockwise.
    triangle_body : (n_tri,) int32
        Body id of each triangle; separate bodies share no nodes.
    lines : (n_lines, 2) int64
        Node ids of the 1D elements on tagged curves (boundaries, joints).
    line_group : (n_lines,) int32
        Index into ``group_names`` of each line element.
    group_names : tuple[str, ...]
        Physical-group names of curves: ``bottom``, ``left``, ``right``, ``surface``,
        ``joint_set_1``, ... .
    """

    points: np.ndarray
    triangles: np.ndarray
    triangle_body: np.ndarray
    lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    line_group: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))
    group_names: tuple[str, ...] = ()

    @property
    def n_triangles(self) -> int:
        return self.triangles.shape[0]

    def group_nodes(self, name: str) -> np.ndarray:
        """Sorted mesh-node ids on the curves of physical group ``name``."""
        if name not in self.group_names:
            raise KeyError(f"no physical group named {name!r}; this mesh has {list(self.group_names)}")
        gid = self.group_names.index(name)
        return np.unique(self.lines[self.line_group == gid])

    def joint_set_ids(self) -> np.ndarray:
        """(n_lines,) joint-set id of each line element: ``j`` on ``joint_set_j``, else 0."""
        ids = np.zeros(len(self.group_names), dtype=np.int32)
        for g, name in enumerate(self.group_names):
            if name.startswith(JOINT_GROUP_PREFIX):
                ids[g] = int(name[len(JOINT_GROUP_PREFIX):])
        return ids[self.line_group] if self.line_group.size else np.zeros(0, dtype=np.int32)

    def joint_edge_keys(self) -> tuple[np.ndarray, np.ndarray]:
        """Sorted edge keys ``min(i,j) * n_points + max(i,j)`` of joint line elements, and their set ids."""
        sets = self.joint_set_ids()
        on_joint = sets > 0
        a, b = self.lines[on_joint, 0], self.lines[on_joint, 1]
        keys = np.minimum(a, b) * self.points.shape[0] + np.maximum(a, b)
        order = np.argsort(keys, kind="stable")
        return keys[order], sets[on_joint][order]

    def area(self) -> float:
        """Total triangle area [m^2]."""
        from fdem.mesh.triangles import triangle_areas

        return float(triangle_areas(self.points, self.triangles).sum())

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | Path) -> None:
        """Write the mesh (triangles, tagged lines, bodies, group names) to a Gmsh ``.msh`` file,
        or, for a path ending in ``.npz``, to a NumPy archive: the form that carries a scene
        meshed elsewhere to a machine with only the numerical stack (a GPU node without Gmsh
        or meshio), read back by :meth:`load` with NumPy alone."""
        if Path(path).suffix == ".npz":
            np.savez_compressed(path, points=self.points, triangles=self.triangles, triangle_body=self.triangle_body,
                                lines=self.lines, line_group=self.line_group,
                                group_names=np.array(self.group_names, dtype=str))
            return
        import meshio

        pts3 = np.column_stack([self.points, np.zeros(len(self.points))])
        cells = [("triangle", self.triangles.astype(np.int64))]
        tri_phys = (1000 + self.triangle_body).astype(np.int32)
        cell_phys = [tri_phys]
        cell_geom = [tri_phys.copy()]
        if self.lines.size:
            cells.insert(0, ("line", self.lines.astype(np.int64)))
            line_phys = (self.line_group + 1).astype(np.int32)
            cell_phys.insert(0, line_phys)
            cell_geom.insert(0, line_phys.copy())
        field_data = {name: np.array([g + 1, 1]) for g, name in enumerate(self.group_names)}
        for b in np.unique(self.triangle_body):
            field_data[f"body_{b}"] = np.array([1000 + b, 2])
        m = meshio.Mesh(
            pts3, cells,
            cell_data={"gmsh:physical": cell_phys, "gmsh:geometrical": cell_geom},
            field_data=field_data,
        )
        meshio.write(str(path), m, file_format="gmsh22", binary=False)

    @classmethod
    def load(cls, path: str | Path) -> "Mesh":
        """Read a ``.msh`` written by :meth:`save` or by Gmsh with the same group conventions.

        The file's numbering is kept (a user's mesh is theirs); :func:`fdem.mesh.order.renumber`
        puts it in memory order when asked. A ``.npz`` written by :meth:`save` is read with
        NumPy alone."""
        if Path(path).suffix == ".npz":
            with np.load(path, allow_pickle=False) as d:
                missing = {"points", "triangles", "triangle_body", "lines", "line_group", "group_names"} - set(d.files)
                if missing:
                    raise ValueError(f"{path}: not a mesh saved by fdem (missing {', '.join(sorted(missing))})")
                return cls(points=np.ascontiguousarray(d["points"], dtype=np.float64),
                           triangles=d["triangles"].astype(np.int64), triangle_body=d["triangle_body"].astype(np.int32),
                           lines=d["lines"].astype(np.int64), line_group=d["line_group"].astype(np.int32),
                           group_names=tuple(str(n) for n in d["group_names"]))
        import meshio

        m = meshio.read(str(path))
        points = np.ascontiguousarray(m.points[:, :2], dtype=np.float64)
        phys = m.cell_data.get("gmsh:physical")
        if phys is None:
            raise ValueError(f"{path}: mesh has no physical groups (gmsh:physical cell data)")
        names_by_tag_line = {int(v[0]): k for k, v in m.field_data.items() if int(v[1]) == 1}
        body_by_tag = {int(v[0]): k for k, v in m.field_data.items() if int(v[1]) == 2}
        tri_blocks, body_blocks, line_blocks, line_tag_blocks = [], [], [], []
        for block, tags in zip(m.cells, phys):
            if block.type == "triangle":
                tri_blocks.append(block.data)
                bodies = np.array(
                    [int(body_by_tag[t].split("_")[1]) if t in body_by_tag and body_by_tag[t].startswith("body_") else 0
                     for t in tags], dtype=np.int32)
                body_blocks.append(bodies)
            elif block.type == "line":
                line_blocks.append(block.data)
                line_tag_blocks.append(np.asarray(tags))
        if not tri_blocks:
            raise ValueError(f"{path}: mesh has no triangles")
        group_names = tuple(names_by_tag_line[t] for t in sorted(names_by_tag_line))
        tag_to_group = {t: g for g, t in enumerate(sorted(names_by_tag_line))}
        if line_blocks:
            lines = np.concatenate(line_blocks).astype(np.int64)
            line_group = np.array([tag_to_group.get(int(t), -1) for t in np.concatenate(line_tag_blocks)],
                                  dtype=np.int32)
            keep = line_group >= 0
            lines, line_group = lines[keep], line_group[keep]
        else:
            lines, line_group = np.zeros((0, 2), np.int64), np.zeros(0, np.int32)
        return cls(
            points=points,
            triangles=np.concatenate(tri_blocks).astype(np.int64),
            triangle_body=np.concatenate(body_blocks),
            lines=lines,
            line_group=line_group,
            group_names=group_names,
        )


def structured_rectangle(nx: int, ny: int, width: float, height: float, origin=(0.0, 0.0),
                         diagonal: str = "alternate") -> Mesh:
    """A rectangle split into ``nx * ny`` cells of two triangles each, without Gmsh.

    Boundary groups ``bottom``, ``right``, ``top``, ``left``. ``diagonal`` is ``"right"``
    (all cells cut the same way) or ``"alternate"`` (union-jack-like, less anisotropic).
    Used by tests and benchmarks that need a mesh of known size fast.
    """
    if nx < 1 or ny < 1:
        raise ValueError(f"structured_rectangle needs nx, ny >= 1, got nx={nx}, ny={ny}")
    if width <= 0 or height <= 0:
        raise ValueError(f"structured_rectangle needs positive width and height, got {width}, {height}")
    xs = origin[0] + np.linspace(0.0, width, nx + 1)
    ys = origin[1] + np.linspace(0.0, height, ny + 1)
    X, Y = np.meshgrid(xs, ys)
    points = np.column_stack([X.ravel(), Y.ravel()])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    i, j = i.ravel(), j.ravel()
    n00 = j * (nx + 1) + i
    n10, n01, n11 = n00 + 1, n00 + nx + 1, n00 + nx + 2
    flip = ((i + j) % 2 == 1) if diagonal == "alternate" else np.zeros_like(i, dtype=bool)
    t1 = np.where(flip[:, None], np.column_stack([n00, n10, n01]), np.column_stack([n00, n10, n11]))
    t2 = np.where(flip[:, None], np.column_stack([n10, n11, n01]), np.column_stack([n00, n11, n01]))
    triangles = np.vstack([t1, t2]).astype(np.int64)

    def side(nodes):
        return np.column_stack([nodes[:-1], nodes[1:]])

    grid = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    sides = [side(grid[0, :]), side(grid[:, -1]), side(grid[-1, ::-1]), side(grid[::-1, 0])]
    lines = np.vstack(sides).astype(np.int64)
    line_group = np.repeat(np.arange(4, dtype=np.int32), [len(s) for s in sides])
    return Mesh(points=points, triangles=triangles, triangle_body=np.zeros(len(triangles), np.int32),
                lines=lines, line_group=line_group, group_names=("bottom", "right", "top", "left"))


def jittered_rectangle(nx: int, ny: int, width: float, height: float, amount: float = 0.25,
                       seed: int = 0) -> Mesh:
    """:func:`structured_rectangle` with its interior nodes moved at random by up to ``amount``
    cell sizes in x and y (boundary nodes stay put): an irregular mesh of known extent for patch
    tests and verification. ``amount < 0.5`` keeps every triangle valid."""
    if not 0 <= amount < 0.5:
        raise ValueError(f"jittered_rectangle: amount must lie in [0, 0.5) cells, got {amount}")
    mesh = structured_rectangle(nx, ny, width, height)
    p = mesh.points.copy()
    tol = 1e-12 * max(width, height)
    interior = (p[:, 0] > tol) & (p[:, 0] < width - tol) & (p[:, 1] > tol) & (p[:, 1] < height - tol)
    rng = np.random.default_rng(seed)
    p[interior] += amount * rng.uniform(-1, 1, (int(interior.sum()), 2)) * [width / nx, height / ny]
    return Mesh(points=p, triangles=mesh.triangles, triangle_body=mesh.triangle_body, lines=mesh.lines,
                line_group=mesh.line_group, group_names=mesh.group_names)
