"""A checked scene made into a mesh and a simulation in static equilibrium.

:func:`scene_mesh` triangulates the scene's outline and joints with Gmsh, or reads the user's
own Gmsh mesh (:func:`load_user_mesh`); :func:`build_simulation` puts rock, supports, gravity,
crack elements, contact and monitors on it, in the order the built-in cases use, so that a
case's written scene builds the same model bit for bit.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fdem.scene.objects import crack_property_sets, geometry, heterogeneity, material
from fdem.scene.schema import SceneError

__all__ = ["load_user_mesh", "scene_mesh", "build_simulation", "scene_toe"]


def load_user_mesh(path: str | Path, joints: dict[str, int], order: str | None = "hilbert"):
    """A user's Gmsh ``.msh`` as a :class:`fdem.mesh.mesh.Mesh` ready for the crack elements.

    The file needs named physical groups: a physical curve per support (``bottom``, ``sides``,
    ... as the scene's ``[supports]`` names them) and per joint set (``joints = {bedding = 1}``
    in the scene's ``[mesh]`` table maps a group to its joint-set tag), and a physical surface
    for the rock. Joint groups are renamed ``joint_set_<tag>``, the project's convention; triangles
    given clockwise are turned counter-clockwise; the mesh is put in memory ``order``."""
    from fdem.mesh.mesh import Mesh
    from fdem.mesh.order import renumber

    path = Path(path)
    try:
        mesh = Mesh.load(path)
    except (ValueError, KeyError, OSError) as err:
        raise SceneError(f"{path}: cannot read the mesh: {err}") from None
    except Exception as err:  # meshio raises its own ReadError for a file that is not a mesh
        raise SceneError(f"{path}: cannot read the mesh: {type(err).__name__}: {err}") from None
    names = list(mesh.group_names)
    for group, tag in joints.items():
        if group not in names:
            raise SceneError(f"{path}: no physical curve named {group!r} for joint set {tag}; the mesh's "
                             f"groups are {names}")
    renamed = tuple(f"joint_set_{joints[n]}" if n in joints else n for n in names)
    clash = [n for n in names if n.startswith("joint_set_") and n not in joints]
    if clash:
        raise SceneError(f"{path}: group name(s) {clash} are reserved for joint sets; rename them in the mesh "
                         "or list them in [mesh] joints")
    tri = mesh.triangles.copy()
    p = mesh.points
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    twice_area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    if np.any(twice_area == 0):
        t = int(np.flatnonzero(twice_area == 0)[0])
        raise SceneError(f"{path}: triangle {t} has zero area (nodes {tri[t].tolist()})")
    cw = twice_area < 0
    tri[cw] = tri[cw][:, [0, 2, 1]]
    mesh = Mesh(points=mesh.points, triangles=tri, triangle_body=mesh.triangle_body, lines=mesh.lines,
                line_group=mesh.line_group, group_names=renamed)
    return renumber(mesh, order) if order is not None else mesh


def scene_mesh(s: dict):
    """``(geometry, mesh)``: the Gmsh mesh of the scene's outline and joints (``geometry`` the
    :class:`fdem.geometry.section.Geometry`), or ``(None, mesh)`` of the scene's own mesh file.
    Warnings of the mesher (dropped short joint pieces, sharp crossings) are passed on."""
    from fdem.mesh.triangulate import mesh_geometry

    sc = s["scene"]
    order = None if sc["order"] == "none" else sc["order"]
    if sc["mesh"] is not None:
        return None, load_user_mesh(sc["mesh"], s["mesh"]["joints"], order)
    geo = geometry(s)
    return geo, mesh_geometry(geo, sc["size"], refine_near_joints=sc["refine_near_joints"], order=order)


def scene_toe(s: dict, geo) -> tuple[float, float]:
    """``(x, y)`` of the slope's toe: ``[outputs] toe`` if given, else from the outline."""
    from fdem.geometry.polygons import slope_toe

    if s["outputs"]["toe"] is not None:
        return tuple(s["outputs"]["toe"])
    return slope_toe(geo.bodies[0])


def build_simulation(s: dict, topology, out_dir=None, pictures: bool = True, progress: bool = True,
                     where: str = "scene"):
    """``(sim, cracks, start)``: the scene's simulation on ``topology``, in static equilibrium
    (``start`` the :class:`fdem.solve.geostatic.GeostaticReport`, ``None`` for ``kind = "none"``).

    Supports, crack tags and monitors are checked against the mesh first (a
    :class:`SceneError` naming the group, the tag or the point), before the static solve."""
    from fdem.physics.contact import ContactSet
    from fdem.physics.cracks import CrackSet
    from fdem.solve.geostatic import geostatic_start
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    groups = list(topology.mesh.group_names)
    for group in s["supports"]:
        if group not in groups:
            raise SceneError(f"{where}: [supports] {group}: the mesh has no boundary group of that name; its "
                             f"groups are {groups}")
    tags_in_mesh = set(np.unique(topology.crack_tag).tolist())
    absent = sorted(set(s["cracks"]) - tags_in_mesh - {0})
    if absent:
        raise SceneError(f"{where}: [cracks.{absent[0]}]: no crack element of the mesh carries tag {absent[0]} "
                         "(no joint of that set survived clipping to the slope and min_joint_length)")

    model = Model(topology, material(s))
    if s["rock"]["damping"] is not None:
        model.set_element_damping(s["rock"]["damping"])
    model.set_gravity(0.0, -s["gravity"]["g"])
    for group, kind in s["supports"].items():
        if kind == "fixed":
            model.fix(group)
        elif kind == "fix-x":
            model.roller(group, "x")
        elif kind == "fix-y":
            model.roller(group, "y")
    c = s["contact"]
    sets, tags = crack_property_sets(s), None
    if s["rock"].get("elastic_side_bands") is not None:  # [cracks.0], which the bands copy, is required
        from fdem.physics.side_bands import with_elastic_side_bands

        try:
            tags, sets, _ = with_elastic_side_bands(topology, sets, s["rock"]["elastic_side_bands"])
        except ValueError as err:
            raise SceneError(f"{where}: [rock] elastic_side_bands: {err}") from None
    try:  # the crack laws' checks that need the mesh (snap-back with each element's length)
        cracks = CrackSet(topology, sets, heterogeneity=heterogeneity(s), contact_penalty=c["penalty"], tags=tags)
    except ValueError as err:
        raise SceneError(f"{where}: [cracks]: {err}") from None
    w = s["workflow"]
    cracks.interfaces.reduce_tensile = (w["reduce_tensile"] if w["reduce_tensile"] is not None
                                        else w["reduction"] != "rate")
    start = geostatic_start(model, cracks) if s["start"]["kind"] == "static" else None
    contact = ContactSet(topology, c["penalty"], friction_angle=c["friction_angle"], mass=model.node_mass(),
                         cracks=cracks, damping_ratio=c["damping_ratio"])
    sim = Simulation(model, providers=[cracks, contact], out_dir=out_dir, name="slope", pictures=pictures,
                     progress=progress, dt_fraction=s["workflow"]["dt_fraction"])
    for m in s["monitors"]:
        add = getattr(sim, "add_point_monitor", None)
        if add is None:  # pragma: no cover - the point monitors arrive with the output work
            raise SceneError(f"{where}: [[monitors]] {m['name']}: this version has no point monitors")
        try:
            add(m["name"], m["x"], m["y"])
        except ValueError as err:
            raise SceneError(f"{where}: [[monitors]] {m['name']}: {err}") from None
    return sim, cracks, start

