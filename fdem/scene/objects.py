"""The library objects a checked scene describes: outline, joint sets, geometry, rock, crack
property sets, heterogeneity and workflow (no meshing, no simulation: :mod:`fdem.scene.build`).

Each function takes the checked scene ``dict`` of :func:`fdem.scene.schema.check_scene` and
builds exactly what the built-in cases build from their constants, so that a case's written
scene (``fdem run CASE --write-scene FILE``) runs the same model.
"""
from __future__ import annotations

import math

__all__ = ["slope_polygon", "joint_offset_through_toe", "joint_sets", "geometry", "material", "crack_property_sets",
           "heterogeneity", "workflow"]


def slope_polygon(s: dict):
    """The slope's outline (:mod:`fdem.geometry.polygons`), toe on the left."""
    from fdem.geometry.polygons import Polygon, benched_slope, simple_slope

    sl = s["slope"]
    if sl["kind"] == "simple":
        return simple_slope(sl["height"], sl["face_angle"], crest_length=sl["crest_length"],
                            toe_length=sl["toe_length"], base_depth=sl["base_depth"], name="slope")
    if sl["kind"] == "benched":
        return benched_slope([tuple(b) for b in sl["benches"]], crest_length=sl["crest_length"],
                             toe_length=sl["toe_length"], base_depth=sl["base_depth"], name="slope")
    import numpy as np

    return Polygon(np.asarray(sl["vertices"], dtype=np.float64), name="slope")


def joint_offset_through_toe(toe: tuple[float, float], dip: float, spacing: float, fraction: float) -> float:
    """Normal offset ``n . x`` of the joint lines of angle ``dip`` [deg] that puts one line at
    ``fraction`` of the ``spacing`` [m] above the toe (0: through the toe), ``n = (-sin, cos)``."""
    a = math.radians(dip)
    return toe[0] * -math.sin(a) + toe[1] * math.cos(a) + fraction * spacing


def joint_sets(s: dict, polygon) -> list:
    """The ``[[joints]]`` tables as joint sets (:mod:`fdem.geometry.joint_sets`), in order: the
    ``j``-th is joint set ``j`` (crack tag ``j``)."""
    import numpy as np

    from fdem.geometry.joint_sets import (BandedSet, BrickSet, IntermittentSet, PersistentSet, SegmentSet,
                                          StochasticSet)
    from fdem.geometry.polygons import slope_toe

    out = []
    for j, js in enumerate(s["joints"], start=1):
        kind, name = js["kind"], js.get("name") or f"joint set {j}"
        offset = js.get("offset") if js.get("offset") is not None else 0.0
        if js.get("through_toe") is not None:
            spacing = js["row_spacing"] if kind == "intermittent" else js["spacing"]
            offset = joint_offset_through_toe(slope_toe(polygon), js["dip"], spacing, js["through_toe"])
        if kind == "persistent":
            out.append(PersistentSet(dip=js["dip"], spacing=js["spacing"], offset=offset, name=name))
        elif kind == "brick":
            out.append(BrickSet(dip=js["dip"], spacing=js["spacing"], cross_spacing=js["cross_spacing"],
                                cross_dip=js["cross_dip"], offset=offset, phase=js["phase"], name=name))
        elif kind == "intermittent":
            rows = None if js["rows"] is None else (int(js["rows"][0]), int(js["rows"][1]))
            out.append(IntermittentSet(dip=js["dip"], trace_length=js["trace_length"],
                                       bridge_length=js["bridge_length"], row_spacing=js["row_spacing"],
                                       stagger=js["stagger"], offset=offset, phase=js["phase"], rows=rows, name=name))
        elif kind == "segments":
            out.append(SegmentSet(np.asarray(js["segments"], dtype=np.float64), name=name))
        else:
            out.append(StochasticSet(count=js["count"], length=tuple(js["length"]), dip=tuple(js["dip"]),
                                     seed=js["seed"], region=None if js["region"] is None else tuple(js["region"]),
                                     name=name))
        if js.get("side_band") is not None:
            out[-1] = BandedSet(out[-1], js["side_band"])
    return out


def geometry(s: dict):
    """The section Gmsh meshes (:class:`fdem.geometry.section.Geometry`)."""
    from fdem.geometry.section import Geometry

    polygon = slope_polygon(s)
    return Geometry([polygon], joint_sets(s, polygon), min_joint_length=s["scene"]["min_joint_length"])


def material(s: dict):
    """The rock of the triangles (:class:`fdem.physics.elastic.ElasticMaterial`, plane strain)."""
    from fdem.physics.elastic import ElasticMaterial

    r = s["rock"]
    return ElasticMaterial(young=r["young"], poisson=r["poisson"], density=r["density"])


def crack_property_sets(s: dict) -> dict:
    """``{tag: CrackProperties}`` of ``[cracks.<tag>]`` (keys left out take the class defaults)."""
    from fdem.physics.crack_properties import CrackProperties

    return {tag: CrackProperties(**{k: v for k, v in table.items() if v is not None})
            for tag, table in s["cracks"].items()}


def heterogeneity(s: dict):
    """The strength multipliers (:class:`fdem.physics.heterogeneity.Heterogeneity`)."""
    from fdem.physics.heterogeneity import Heterogeneity

    h = dict(s["heterogeneity"])
    if h["tags"] is not None:
        if any(t != int(t) or t < 0 for t in h["tags"]):
            raise ValueError(f"tags must be whole numbers >= 0, got {h['tags']}")
        h["tags"] = tuple(int(t) for t in h["tags"])
    return Heterogeneity(**h)


def workflow(s: dict):
    """The slope workflow's settings (:class:`fdem.workflow.slope.SlopeWorkflow`)."""
    from fdem.workflow.slope import SlopeWorkflow

    w = s["workflow"]
    fields = {k: w[k] for k in ("reduction", "reduction_rate", "final_strength", "equilibrium_ratio",
                                "equilibrium_hold", "step_time",
                                "fail_displacement", "runout_time", "rest_kinetic_ratio", "runout_dt_fraction",
                                "local_fall_area", "runout_step", "trial_end")}
    if w["factors"] is not None:
        fields["factors"] = tuple(w["factors"])
    if w["fos"] is not None:
        fields["fos"] = tuple(w["fos"])
    fields["trigger"] = "gravity" if w["kind"] == "gravity-increase" else "strength"
    return SlopeWorkflow(**fields)
