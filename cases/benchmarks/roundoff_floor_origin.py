"""How much of the unbalanced-ratio round-off floor is the origin's doing?

The equilibrium rule raises its limit to 10 times the model's round-off floor
(:func:`fdem.solve.geostatic.unbalanced_ratio_floor`, ``R_eps = sum_n S_n eps(x_n) / sum_n
|m_n g|``): positions are float64, stored to the spacing ``eps(x)`` of numbers at their
magnitude, so each force is known to about ``S eps``. On the four-slope scenes with the run
extents the origin sits at the left end of the model (x up to 165 m), so most nodes lie where
``eps`` is 1.4e-14 to 2.8e-14 m; at 0.35 m the floor (2.8e-5) lifts the limit to 2.8e-4, above
the strict 1e-4 ("The coarse slopes against element size", docs/cases.md A).

This script builds a scene (``--angle``, ``--spacing``, ``--size``, ``--joint-offset``, the run
extents) and prints the floor as the model stands and with its positions translated: to the
centre of its bounding box, and to the toe. The stiffness ``S_n`` is translation-invariant, so
only ``eps`` changes: what centring the solver's coordinates would gain. It also prints the floor
as the solver computes it since the crack elements read displacements (``floor_solver``): their
stiffness, 91-97 % of the floor read from positions, drops out. Saves ``docs/benchmarks/roundoff_floor_origin.json`` (records merged by label):

    NUMBA_NUM_THREADS=1 python cases/benchmarks/roundoff_floor_origin.py --angle low --spacing coarse \\
        --joint-offset 0 --size 1.0 0.5 0.35
"""
from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

from fdem.io.jsonable import write_json

OUT = Path(__file__).resolve().parents[2] / "docs" / "benchmarks" / "roundoff_floor_origin.json"


def floors(angle: str, spacing: str, size: float, joint_offset: float | None) -> dict:
    """The floor at the model's own origin, at its bounding box's centre and at its toe."""
    from fdem.cases.four_slopes import RUN_EXTENTS, build, simulation
    from fdem.geometry.polygons import slope_toe
    from fdem.solve.geostatic import unbalanced_ratio_floor

    t0 = time.perf_counter()
    extents = {k: v for k, v in RUN_EXTENTS[angle].items()}
    geometry, _, topology = build(angle, spacing, size, joint_offset=joint_offset, extents=extents)
    sim, _ = simulation(geometry, topology, None, pictures=False, start="k0", progress=False)
    x = sim.state.x.copy()
    toe = np.asarray(slope_toe(geometry.bodies[0]), float)
    centre = 0.5 * (x.min(axis=0) + x.max(axis=0))
    out = {"size_m": size, "n_triangles": int(topology.n_triangles), "x_min_m": x.min(axis=0).tolist(),
           "x_max_m": x.max(axis=0).tolist(), "floors": {}}
    for name, origin in (("as built", np.zeros(2)), ("bounding-box centre", centre), ("toe", toe)):
        sim.state.x[:] = x - origin
        out["floors"][name] = {"origin_m": origin.tolist(), "floor": unbalanced_ratio_floor(sim),
                               "largest_coordinate_m": float(np.abs(sim.state.x).max())}
    sim.state.x[:] = x
    # the floor as the solver computes it: the crack elements read the displacements kept
    # apart from the positions (State.u, zero here), so their stiffness drops out
    out["floor_solver"] = unbalanced_ratio_floor(sim)
    # whose stiffness the floor is: the triangles' against each force provider's (crack
    # elements, contact), at the positions as built; a state that kept the displacement apart
    # for the crack elements alone would remove their share
    from fdem.solve.density_scaling import triangle_nodal_stiffness

    eps = np.spacing(np.abs(x)).max(axis=1)
    weight = float(sim.state.mass.sum() * np.linalg.norm(sim.gravity))
    shares = {"triangles": float(triangle_nodal_stiffness(sim.model) @ eps) / weight}
    for p in sim.providers:
        fn = getattr(p, "nodal_stiffness", None)
        if fn is not None:
            shares[type(p).__name__] = float(np.asarray(fn(sim.state.mass), float) @ eps) / weight
    out["floor_by_source"] = shares
    out["wall_s"] = time.perf_counter() - t0
    sim.close()
    return out


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--angle", choices=("low", "high"), default="low")
    p.add_argument("--spacing", choices=("fine", "coarse"), default="coarse")
    p.add_argument("--joint-offset", type=float, default=None)
    p.add_argument("--size", type=float, nargs="+", default=[1.0, 0.5])
    p.add_argument("--label", default=None)
    args = p.parse_args(argv)
    records = {}
    if OUT.is_file():
        import json

        records = json.loads(OUT.read_text())
    label = args.label or f"{args.angle}_{args.spacing}_offset{args.joint_offset}"
    rows = []
    for size in args.size:
        r = floors(args.angle, args.spacing, size, args.joint_offset)
        rows.append(r)
        base = r["floors"]["as built"]["floor"]
        print(f"size {size:g} m, {r['n_triangles']:,} triangles, x in [{r['x_min_m'][0]:.0f}, {r['x_max_m'][0]:.0f}] m:")
        for name, f in r["floors"].items():
            print(f"  origin at {name:20s} largest |x| {f['largest_coordinate_m']:6.1f} m  floor {f['floor']:.3g}"
                  f"  (x{f['floor'] / base:.2f}; limit 10 x floor {10 * f['floor']:.3g})")
        print("  floor by source (origin as built): " + ", ".join(f"{k} {v:.3g}" for k, v in r["floor_by_source"].items()))
        print(f"  floor as the solver computes it (crack elements read displacements): {r['floor_solver']:.3g}"
              f"  (limit 10 x floor {10 * r['floor_solver']:.3g})")
    records[label] = {"command": "python cases/benchmarks/roundoff_floor_origin.py " + " ".join(argv or __import__("sys").argv[1:]),
                      "machine": platform.processor() or platform.machine(), "rows": rows}
    OUT.parent.mkdir(parents=True, exist_ok=True)
    write_json(OUT, records)
    print(f"saved {OUT}")
    return records


if __name__ == "__main__":
    main()
