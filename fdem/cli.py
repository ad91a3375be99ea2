"""The ``fdem`` command: ``fdem demo`` meshes the demo slope, ``fdem info FILE.msh`` reports a mesh."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _demo(args) -> int:
    import runpy

    case = Path(__file__).resolve().parents[1] / "cases" / "four_slopes.py"
    if not case.exists():
        print("the demo case script cases/four_slopes.py is not next to this installation; "
              "run it from a checkout: python cases/four_slopes.py --out runs/demo", file=sys.stderr)
        return 2
    sys.argv = [str(case), "--out", str(args.out), "--size", str(args.size), "--max-steps", str(args.max_steps)]
    runpy.run_path(str(case), run_name="__main__")
    return 0


def _info(args) -> int:
    from .mesh import Mesh
    from .meshing import quality_report
    from .topology import build_topology

    mesh = Mesh.load(args.mesh)
    topo = build_topology(mesh)
    print(quality_report(mesh))
    print(f"crack elements {topo.n_cracks} ({int((topo.crack_tag > 0).sum())} on joints), "
          f"external edges {len(topo.boundary_edges)}, groups {list(mesh.group_names)}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="fdem", description="Hybrid finite-discrete element solver for rock slopes")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="mesh the low-angle four-slope scene, write a picture and a .vtu, run the first steps")
    demo.add_argument("--out", type=Path, default=Path("runs/demo"))
    demo.add_argument("--size", type=float, default=0.5)
    demo.add_argument("--max-steps", type=int, default=3000, help="time steps to run after meshing (0: mesh only)")
    demo.set_defaults(func=_demo)
    info = sub.add_parser("info", help="quality report and crack-element counts of a .msh file")
    info.add_argument("mesh", type=Path)
    info.set_defaults(func=_info)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
