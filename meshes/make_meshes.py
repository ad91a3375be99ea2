"""Regenerate the small meshes in this folder that the tests and quick cases use.

    python meshes/make_meshes.py
"""
import warnings
from pathlib import Path

from fdem.geometry.joint_sets import BrickSet
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import rectangle, simple_slope
from fdem.mesh.triangulate import mesh_geometry

HERE = Path(__file__).resolve().parent


def main():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        slope = simple_slope(height=6, face_angle=45, crest_length=6, toe_length=6, base_depth=3)
        mesh_geometry(Geometry([slope], [BrickSet(dip=15, spacing=1.5)], min_joint_length=0.05), 0.5).save(
            HERE / "slope_brick_small.msh")
        base, block = rectangle(0, 0, 6, 1, "incline"), rectangle(2, 1, 1, 1, "block")
        mesh_geometry(Geometry([base, block]), 0.25).save(HERE / "block_on_base.msh")


if __name__ == "__main__":
    main()
