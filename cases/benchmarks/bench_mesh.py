"""Time to mesh and explode the fine low-angle four-slope geometry at about 180,000 triangles.

    python cases/benchmarks/bench_mesh.py            # size 0.18 m, ~180k triangles
    python cases/benchmarks/bench_mesh.py --size 0.5 # quick

Writes docs/benchmarks/mesh.json (timings and the quality report). Target: under 60 s.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from records import record, save  # noqa: E402

from fdem.mesh.triangulate import mesh_geometry
from fdem.mesh.quality import quality_report  # noqa: E402
from fdem.cases.four_slopes import four_slope_geometry  # noqa: E402
from fdem.mesh.topology import build_topology  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--size", type=float, default=0.18)
    parser.add_argument("--algorithm", default="delaunay")
    args = parser.parse_args(argv)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        model = four_slope_geometry("low", "fine")
        dfn = model.dfn()
        t1 = time.perf_counter()
        mesh = mesh_geometry(model, args.size, algorithm=args.algorithm)
        t2 = time.perf_counter()
        topo = build_topology(mesh)
        t3 = time.perf_counter()
    report = quality_report(mesh)
    n = mesh.n_triangles
    records = [
        record("DFN generation (clip, merge, split)", t1 - t0, "s", n, 1, n_joint_segments=len(dfn.segments)),
        record("Gmsh triangulation", t2 - t1, "s", n, 1, algorithm=args.algorithm, size_m=args.size),
        record("topology (explode + crack elements)", t3 - t2, "s", n, 1, n_crack_elements=topo.n_cracks),
        record("total mesh + topology", t3 - t0, "s", n, 1, target_s=60.0),
    ]
    print(report)
    save("mesh", records, scene="four slopes, low angle, fine (s = 1 m)", quality=report.as_dict(),
         warnings=[str(w.message) for w in caught])


if __name__ == "__main__":
    main()
