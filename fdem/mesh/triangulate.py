"""Gmsh triangulation of a :class:`fdem.geometry.section.Geometry` conforming to its DFN (:func:`mesh_geometry`).

The geometry module has already clipped the joints, merged their overlaps and split them at
every crossing, so the model reaches Gmsh as a planar straight-line graph: boundary pieces form
each body's curve loop, joint pieces are embedded curves sharing points at the junctions. No
boolean operations are needed, which keeps meshing fast and deterministic.
"""
from __future__ import annotations

import math
import warnings
import numpy as np
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import Polygon
from fdem.geometry.dfn import cluster_points
from fdem.mesh.mesh import JOINT_GROUP_PREFIX, Mesh
from fdem.mesh.order import ORDERS, renumber
from fdem.mesh.triangles import check_triangles
from fdem.mesh.quality import quality_report

__all__ = ["BOUNDARY_GROUPS", "ALGORITHMS", "mesh_geometry"]


BOUNDARY_GROUPS = ("bottom", "right", "left", "surface")


ALGORITHMS = {"meshadapt": 1, "delaunay": 5, "frontal-delaunay": 6}


def _unique_points(points: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge points closer than ``tol``; returns (unique points, index of each input point)."""
    roots, index = np.unique(cluster_points(points, tol), return_inverse=True)
    return points[roots], index


def _boundary_pieces(body: Polygon, extra_points: np.ndarray, tol: float) -> np.ndarray:
    """The body's boundary, counter-clockwise, split at every ``extra_points`` lying on it."""
    pieces = []
    for a, b in body.edges:
        d = b - a
        L2 = float(d @ d)
        if len(extra_points):
            s = (extra_points - a) @ d / L2
            closest = a + s[:, None] * d
            on = (np.linalg.norm(extra_points - closest, axis=1) <= tol) & (s > 0) & (s < 1)
            ts = np.unique(np.r_[0.0, s[on], 1.0])
        else:
            ts = np.array([0.0, 1.0])
        for t0, t1 in zip(ts[:-1], ts[1:]):
            if (t1 - t0) * math.sqrt(L2) > tol:
                pieces.append([a + t0 * d, a + t1 * d])
    return np.array(pieces)


def _classify_boundary(pieces: np.ndarray, bounds, tol: float) -> list[str]:
    """Name each boundary piece ``bottom``, ``left``, ``right`` (on the model's extreme lines) or ``surface``."""
    x0, y0, x1, y1 = bounds
    names = []
    for (ax, ay), (bx, by) in pieces:
        if abs(ay - y0) <= tol and abs(by - y0) <= tol:
            names.append("bottom")
        elif abs(ax - x0) <= tol and abs(bx - x0) <= tol:
            names.append("left")
        elif abs(ax - x1) <= tol and abs(bx - x1) <= tol:
            names.append("right")
        else:
            names.append("surface")
    return names


def mesh_geometry(geometry: Geometry, size: float, refine_near_joints: float | None = None,
               refine_distance: float | None = None, algorithm: str = "delaunay",
               min_angle_warning: float = 10.0, verbose: bool = False, order: str | None = "hilbert") -> Mesh:
    """Triangulate ``geometry`` with Gmsh at target element ``size`` [m], conforming to every joint.

    Parameters
    ----------
    size : target edge length [m].
    refine_near_joints : optional factor < 1: element size on the joints is ``factor * size``,
        growing back to ``size`` over ``refine_distance`` (default ``5 * size``).
    algorithm : ``"delaunay"`` (default: fastest, and its irregular edge orientations let cracks
        run in any direction), ``"frontal-delaunay"`` (better angles, but a regular pattern that
        biases crack paths: the Brazilian disc over-predicts f_t by 50 % on it) or ``"meshadapt"``.
    min_angle_warning : warn (with count and worst angle) when triangles are sharper than this [deg].
    order : memory order of the result (:func:`fdem.mesh.order.renumber`): ``"hilbert"``
        (default) numbers the triangles along a Hilbert curve through their centroids and the
        points by first use, so that neighbouring triangles, hence the nodes a crack element
        reads, lie close in memory; ``"morton"``; ``None`` keeps Gmsh's numbering (patches,
        front after front). Gmsh's numbering is no one's input, so renumbering changes no result
        beyond round-off (the order of floating-point sums), with one exception: random
        per-element strengths (:class:`fdem.physics.heterogeneity.Heterogeneity`) are drawn in
        element order, so a seed gives another, equally likely, realisation in another order.

    Physical groups: curves ``bottom``, ``left``, ``right``, ``surface`` and ``joint_set_<j>``;
    each body's triangles carry its index in ``Mesh.triangle_body``. Same input, same mesh.
    """
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"mesh size must be positive, got {size}")
    if refine_near_joints is not None and not (0 < refine_near_joints <= 1):
        raise ValueError(f"refine_near_joints must be in (0, 1], got {refine_near_joints}")
    if algorithm not in ALGORITHMS:
        raise ValueError(f"unknown meshing algorithm {algorithm!r}; choose from {sorted(ALGORITHMS)}")
    if order is not None and order not in ORDERS:
        raise ValueError(f"unknown mesh order {order!r}; choose from {list(ORDERS)} or None")
    if size > 0.5 * geometry.size:
        raise ValueError(f"mesh size {size} m is larger than half the geometry size {geometry.size:.3g} m")
    dfn = geometry.dfn()
    tol = max(geometry.tolerance * 1e3, 1e-12)  # vertex-merging tolerance: 1e-6 of the geometry size

    import gmsh

    own_session = not gmsh.isInitialized()
    if own_session:
        gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 1 if verbose else 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.clear()
        gmsh.model.add("fdem")
        geo = gmsh.model.geo
        group_curves: dict[str, list[int]] = {}
        surfaces = []
        joint_curve_all = []
        for b, body in enumerate(geometry.bodies):
            mine = dfn.body == b
            segs, sets = dfn.segments[mine], dfn.set_id[mine]
            ends = segs.reshape(-1, 2)
            boundary = _boundary_pieces(body, ends, tol)
            pts, index = _unique_points(np.vstack([boundary.reshape(-1, 2), ends]), tol)
            point_tags = [geo.addPoint(px, py, 0.0, size) for px, py in pts]
            nb = len(boundary)
            b_idx = index[: 2 * nb].reshape(-1, 2)
            j_idx = index[2 * nb:].reshape(-1, 2)
            loop = [geo.addLine(point_tags[i], point_tags[j]) for i, j in b_idx]
            for tag, name in zip(loop, _classify_boundary(boundary, geometry.bounds, tol)):
                group_curves.setdefault(name, []).append(tag)
            surf = geo.addPlaneSurface([geo.addCurveLoop(loop)])
            surfaces.append(surf)
            joint_curves = []
            for (i, j), s in zip(j_idx, sets):
                if i == j:
                    continue
                tag = geo.addLine(point_tags[i], point_tags[j])
                joint_curves.append(tag)
                group_curves.setdefault(f"{JOINT_GROUP_PREFIX}{s}", []).append(tag)
            joint_curve_all += joint_curves
            geo.synchronize()
            if joint_curves:
                gmsh.model.mesh.embed(1, joint_curves, 2, surf)
        geo.synchronize()
        for name in sorted(group_curves, key=_group_order):
            gmsh.model.addPhysicalGroup(1, group_curves[name], name=name)
        for b, surf in enumerate(surfaces):
            gmsh.model.addPhysicalGroup(2, [surf], tag=1000 + b, name=f"body_{b}")

        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0 if refine_near_joints else 1)
        if refine_near_joints is not None and joint_curve_all:
            fd = gmsh.model.mesh.field.add("Distance")
            gmsh.model.mesh.field.setNumbers(fd, "CurvesList", joint_curve_all)
            gmsh.model.mesh.field.setNumber(fd, "Sampling", 20)
            ft = gmsh.model.mesh.field.add("Threshold")
            gmsh.model.mesh.field.setNumber(ft, "InField", fd)
            gmsh.model.mesh.field.setNumber(ft, "SizeMin", refine_near_joints * size)
            gmsh.model.mesh.field.setNumber(ft, "SizeMax", size)
            gmsh.model.mesh.field.setNumber(ft, "DistMin", 0.0)
            gmsh.model.mesh.field.setNumber(ft, "DistMax", refine_distance or 5 * size)
            gmsh.model.mesh.field.setAsBackgroundMesh(ft)
            gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.Algorithm", ALGORITHMS[algorithm])
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.model.mesh.generate(2)
        mesh = renumber(_extract_mesh(gmsh, surfaces), order)
    finally:
        if own_session:
            gmsh.finalize()

    check_triangles(mesh.points, mesh.triangles)
    report = quality_report(mesh, worst=1)
    if report.min_angle_deg < min_angle_warning:
        warnings.warn(
            f"{report.n_below_warning(min_angle_warning)} triangle(s) have an angle below "
            f"{min_angle_warning:g} deg (worst {report.min_angle_deg:.2f} deg at "
            f"({float(report.worst[0][2][0]):.3f}, {float(report.worst[0][2][1]):.3f})), usually near sharp joint "
            "crossings", stacklevel=2)
    return mesh


def _group_order(name: str):
    if name in BOUNDARY_GROUPS:
        return (0, BOUNDARY_GROUPS.index(name))
    return (1, int(name[len(JOINT_GROUP_PREFIX):]))


def _extract_mesh(gmsh, surfaces) -> Mesh:
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    order = np.argsort(node_tags)
    node_tags = np.asarray(node_tags)[order]
    points = np.asarray(coords).reshape(-1, 3)[order, :2]

    def ids(tags):
        return np.searchsorted(node_tags, np.asarray(tags, dtype=np.uint64)).astype(np.int64)

    tris, bodies = [], []
    for b, surf in enumerate(surfaces):
        types, _, enodes = gmsh.model.mesh.getElements(2, surf)
        for etype, nodes in zip(types, enodes):
            if etype != 2:
                raise ValueError(f"unexpected element type {etype} in body {b}: only 3-node triangles are supported")
            t = ids(nodes).reshape(-1, 3)
            tris.append(t)
            bodies.append(np.full(len(t), b, dtype=np.int32))
    triangles = np.concatenate(tris)
    # Gmsh orients triangles with the surface normal; make every one counter-clockwise in x-y.
    p0, p1, p2 = points[triangles[:, 0]], points[triangles[:, 1]], points[triangles[:, 2]]
    cw = ((p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0])) < 0
    triangles[cw] = triangles[cw][:, [0, 2, 1]]

    names, lines, groups = [], [], []
    for dim, ptag in gmsh.model.getPhysicalGroups(1):
        g = len(names)
        names.append(gmsh.model.getPhysicalName(dim, ptag))
        for curve in gmsh.model.getEntitiesForPhysicalGroup(dim, ptag):
            _, _, enodes = gmsh.model.mesh.getElements(1, curve)
            for nodes in enodes:
                seg = ids(nodes).reshape(-1, 2)
                lines.append(seg)
                groups.append(np.full(len(seg), g, dtype=np.int32))
    # Drop nodes no triangle uses (e.g. geometry points Gmsh kept unattached).
    used = np.zeros(len(points), dtype=bool)
    used[triangles.ravel()] = True
    renum = np.cumsum(used) - 1
    lines = np.concatenate(lines) if lines else np.zeros((0, 2), np.int64)
    return Mesh(
        points=np.ascontiguousarray(points[used]),
        triangles=renum[triangles],
        triangle_body=np.concatenate(bodies),
        lines=renum[lines],
        line_group=np.concatenate(groups) if groups else np.zeros(0, np.int32),
        group_names=tuple(names),
    )
