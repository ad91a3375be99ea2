"""Block on an inclined plane (verification.md; seed 000's first validation case).

A deformable block rests on a fixed base; the plane is inclined by tilting gravity by
``theta``: ``g = 9.81 (sin theta, -cos theta)``, so "down the slope" is ``+x``. Contact carries
the block with Coulomb friction ``mu = tan(phi)``; crack elements that never break hold each
body together. Exact answers:

* sliding (``phi < theta``): ``s(t) = g t^2 (sin theta - mu cos theta) / 2``;
* sticking (``phi > theta``): no slip;
* toppling (Goodman and Bray, ``phi > theta``): a block of width ``b`` and height ``h`` topples
  when ``b / h < tan theta``.

Dynamic stage: element damping (a fraction of critical of each triangle's highest mode,
:meth:`fdem.solve.model.Model.set_element_damping`, default ``DEFAULT_ELEMENT_DAMPING``) keeps the
constant-strain triangles from ringing; ``--element-damping 0`` runs undamped
(``docs/damping.md``).

    fdem run block-on-incline --theta 30 --phi 20 --out runs/incline
    python cases/block_on_incline.py --theta 30 --phi 20 --out runs/incline   # the same

Writes ``--out/summary.json`` (slide against the exact answer, rotation, energies),
``incline.pvd`` and ``history.csv``.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from fdem.cases.common import case_parser, check_common, finish_run, prepare_run, set_threads
from fdem.physics.crack_properties import CrackProperties
from fdem.physics.cracks import CrackSet
from fdem.physics.contact import ContactSet
from fdem.geometry.section import Geometry
from fdem.geometry.polygons import rectangle
from fdem.physics.elastic import ElasticMaterial
from fdem.mesh.triangulate import mesh_geometry
from fdem.solve.model import DEFAULT_ELEMENT_DAMPING, Model
from fdem.solve.simulation import Simulation
from fdem.mesh.topology import build_topology
from fdem.io.jsonable import dumps, write_json

__all__ = ["NAME", "G", "CONTACT_PENALTY", "unbreakable", "sliding_distance", "check_scene", "build", "incline_model",
           "run", "parse_args",
           "STUDY_SIZES", "STUDY_FRACTIONS", "STUDY_CASES", "damping_study", "plot_study", "main", "YOUNG", "POISSON", "DENSITY"]

NAME = "block-on-incline"
G = 9.81
YOUNG, POISSON, DENSITY = 1e9, 0.25, 2700.0
CONTACT_PENALTY = 20 * YOUNG  # Pa: p = alpha E with alpha = 20


def unbreakable(young: float) -> CrackProperties:
    """Crack elements that stay elastic: strengths far above any stress in these scenes."""
    from fdem.physics.side_bands import ELASTIC_FRACTURE_ENERGY as G, ELASTIC_STRENGTH as S

    return CrackProperties(f_t=S, c=S, phi=45.0, G_I=G, G_II=G, p_n=10 * young)


def sliding_distance(theta_deg: float, phi_deg: float, t: float) -> float:
    """``s = g t^2 (sin theta - tan phi cos theta) / 2``, zero when friction holds [m]."""
    th = math.radians(theta_deg)
    a = G * (math.sin(th) - math.tan(math.radians(phi_deg)) * math.cos(th))
    return max(a, 0.0) * t * t / 2


def check_scene(theta_deg: float, phi_deg: float, t_end: float = 1.0, block_width: float = 1.0,
                block_height: float = 1.0, size: float | None = None,
                element_damping: float = DEFAULT_ELEMENT_DAMPING) -> None:
    """A ``ValueError`` naming the first setting the scene cannot honour, before any meshing.

    ``theta_deg`` in (0, 90): the plane is made by turning gravity, ``g (sin theta, -cos theta)``;
    at 90 deg and beyond gravity leaves the plane (at 95 deg it pulls the block off the base,
    at 200 deg up through it) while the "exact" slide formula still returns a number.
    ``phi_deg`` in [0, 90) (``mu = tan(phi)``). ``t_end`` > 0 [s]. Block sides > 0 [m].
    ``size`` > 0 [m] and no larger than the block's smaller side (coarser, the block is two
    triangles whose crack element stands for the whole body). ``element_damping`` in [0, 1]
    (fraction of critical, ``docs/damping.md``: the study spans 0-1; above critical the
    viscosity only shortens the stable step, by about ``sqrt(1 + xi^2) - xi``)."""
    finite = all(map(math.isfinite, (theta_deg, phi_deg, t_end, block_width, block_height, element_damping)))
    if not finite:
        raise ValueError(f"block on incline: every setting must be a finite number, got theta {theta_deg}, "
                         f"phi {phi_deg}, t_end {t_end}, width {block_width}, height {block_height}, "
                         f"element_damping {element_damping}")
    if not 0.0 < theta_deg < 90.0:
        raise ValueError(f"block on incline: theta (the incline) must lie in (0, 90) deg, got {theta_deg}: the plane "
                         f"is made by turning gravity, which leaves the plane at 90 deg and beyond")
    if not 0.0 <= phi_deg < 90.0:
        raise ValueError(f"block on incline: phi (the contact's friction angle) must lie in [0, 90) deg, got {phi_deg}")
    if not t_end > 0:
        raise ValueError(f"block on incline: t_end must be a positive simulated time [s], got {t_end}")
    if not (block_width > 0 and block_height > 0):
        raise ValueError(f"block on incline: the block's width and height (--width, --height) must be positive [m], got "
                         f"{block_width} x {block_height}")
    if size is not None and not (math.isfinite(size) and 0 < size <= min(block_width, block_height)):
        raise ValueError(f"block on incline: the element size (--size) must be positive and at most the block's smaller side, "
                         f"{min(block_width, block_height):g} m, got {size}")
    if not 0.0 <= element_damping <= 1.0:
        raise ValueError(f"block on incline: element_damping (a fraction of critical) must lie in [0, 1], got "
                         f"{element_damping}")


def build(theta_deg: float, phi_deg: float, block_width: float = 1.0, block_height: float = 1.0,
          size: float | None = None, base_length: float = 8.0,
          element_damping: float = DEFAULT_ELEMENT_DAMPING):
    """Model, crack set, contact set and the block's node ids.

    ``size`` [m]: target element size (default half the block's smaller side);
    ``element_damping``: fraction of critical viscosity of each triangle (0: none). Settings
    the scene cannot honour raise a ``ValueError`` before meshing (:func:`check_scene`).
    """
    check_scene(theta_deg, phi_deg, 1.0, block_width, block_height, size, element_damping)
    size = size or min(block_width, block_height) / 2
    model, base_nodes, block_nodes = incline_model(theta_deg, 0.25 * base_length, block_width, block_height, size,
                                                   base_length, element_damping)
    model.fix(base_nodes)
    cracks = CrackSet(model.topology, {0: unbreakable(YOUNG)})
    contact = ContactSet(model.topology, CONTACT_PENALTY, friction_angle=phi_deg, mass=model.node_mass(),
                         cracks=cracks)
    return model, cracks, contact, block_nodes


def incline_model(theta_deg: float, block_x: float, block_width: float, block_height: float, size: float,
                  base_length: float, element_damping: float):
    """A block (body 1, lower-left corner at ``(block_x, 0.5)``) on a 0.5 m thick base plate
    (body 0) of ``base_length`` [m], meshed at ``size`` [m]; the plane is tilted by turning
    gravity, ``g (sin theta, -cos theta)``. Returns ``(model, base_nodes, block_nodes)``; the
    caller supports or shakes the base."""
    base = rectangle(0.0, 0.0, base_length, 0.5, name="incline")
    block = rectangle(block_x, 0.5, block_width, block_height, name="block")
    topo = build_topology(mesh_geometry(Geometry([base, block]), size))
    model = Model(topo, ElasticMaterial(young=YOUNG, poisson=POISSON, density=DENSITY))
    if element_damping > 0:
        model.set_element_damping(element_damping)
    th = math.radians(theta_deg)
    model.set_gravity(G * math.sin(th), -G * math.cos(th))
    base_nodes = np.flatnonzero(np.repeat(topo.triangle_body == 0, 3))
    block_nodes = np.flatnonzero(np.repeat(topo.triangle_body == 1, 3))
    return model, base_nodes, block_nodes


def run(theta_deg: float, phi_deg: float, t_end: float = 1.0, block_width: float = 1.0, block_height: float = 1.0,
        out_dir: Path | None = None, energy_tolerance: float | None = 0.05, size: float | None = None,
        element_damping: float = DEFAULT_ELEMENT_DAMPING) -> dict:
    """Release the block from rest; return its mean slide along the plane and its rotation at ``t_end``."""
    check_scene(theta_deg, phi_deg, t_end, block_width, block_height, size, element_damping)
    model, cracks, contact, block = build(theta_deg, phi_deg, block_width, block_height, size=size,
                                          element_damping=element_damping)
    sim = Simulation(model, providers=[cracks, contact], out_dir=out_dir, name="incline", progress=False)
    wall = time.perf_counter()
    x0 = sim.state.x[block].copy()
    sim.run(t_end=t_end, output_every=10**9 if out_dir is None else None, energy_tolerance=energy_tolerance)
    sim.close()
    wall = time.perf_counter() - wall
    x = sim.state.x[block]
    slide = float((x[:, 0] - x0[:, 0]).mean())
    # Rigid rotation of the block: angle of the best-fit rotation of its nodes about their centroid.
    a, b = x0 - x0.mean(axis=0), x - x.mean(axis=0)
    rotation = math.degrees(math.atan2(float((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum()),
                                       float((a * b).sum())))
    row = sim.history[-1] if sim.history else {}
    return {"theta_deg": theta_deg, "phi_deg": phi_deg, "t": sim.state.time, "slide_m": slide,
            "exact_m": sliding_distance(theta_deg, phi_deg, sim.state.time),
            "frictionless_m": sliding_distance(theta_deg, 0.0, sim.state.time),
            "rotation_deg": rotation, "steps": sim.state.step, "dt_s": sim.dt,
            "triangle_dt_s": sim.triangle_dt, "n_block_triangles": int(len(block) // 3),
            "element_damping": element_damping, "wall_s": wall,
            "viscous_dissipation_J_per_m": float(row.get("viscous_dissipation", 0.0)),
            "friction_work_J_per_m": float(row.get("friction", 0.0)),
            "balance_error_relative": float(row.get("balance_error_relative", float("nan")))}


STUDY_SIZES = (0.5, 0.25, 0.125)
STUDY_FRACTIONS = (0.0, 0.05, 0.1, 0.2, 0.5, 1.0)
STUDY_CASES = ((30.0, 20.0), (40.0, 25.0))


def damping_study(path: Path, sizes=STUDY_SIZES, fractions=STUDY_FRACTIONS, cases=STUDY_CASES) -> list[dict]:
    """Slide at 1 s against the rigid-block answer for each case, mesh size and damping fraction.

    Writes the rows to ``path`` (JSON) after every run, so a partial study is kept; rows
    already in ``path`` are not run again. Run with ``NUMBA_NUM_THREADS=1`` for comparable
    wall times.
    """
    rows = json.loads(path.read_text())["runs"] if path.exists() else []
    done = {(r["theta_deg"], r["phi_deg"], r["size_m"], r["element_damping"]) for r in rows}
    for theta, phi in cases:
        for size in sizes:
            for fraction in fractions:
                if (theta, phi, size, fraction) in done:
                    continue
                r = run(theta, phi, 1.0, size=size, element_damping=fraction)
                r["size_m"] = size
                r["slide_error"] = r["slide_m"] / r["exact_m"] - 1.0
                rows.append(r)
                print(f"theta {theta:g} phi {phi:g} size {size:g} damping {fraction:g}: "
                      f"error {100 * r['slide_error']:+.3f} %, dt {r['dt_s']:.4g} s, wall {r['wall_s']:.1f} s",
                      flush=True)
                path.parent.mkdir(parents=True, exist_ok=True)
                write_json(path, {"description": "block on incline, slide at 1 s vs rigid block, "
                                  "element damping as a fraction of critical", "runs": rows}, indent=1)
    return rows


def plot_study(path: Path, png: Path) -> None:
    """Slide error against mesh size, one line per damping fraction, one panel per case (matplotlib PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = json.loads(path.read_text())["runs"]
    cases = sorted({(r["theta_deg"], r["phi_deg"]) for r in rows})
    fig, axes = plt.subplots(1, len(cases), figsize=(5.2 * len(cases), 4.2), squeeze=False)
    for ax, (theta, phi) in zip(axes[0], cases):
        mine = [r for r in rows if (r["theta_deg"], r["phi_deg"]) == (theta, phi)]
        for fraction in sorted({r["element_damping"] for r in mine}):
            pts = sorted((r["size_m"], 100 * r["slide_error"]) for r in mine if r["element_damping"] == fraction)
            label = "undamped" if fraction == 0 else f"{fraction:g} of critical"
            style = dict(lw=2.5, color="k") if fraction == DEFAULT_ELEMENT_DAMPING else dict(lw=1.2)
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=label, **style)
        ax.axhspan(-1, 1, color="0.9", zorder=0)
        ax.axhline(0, color="0.5", lw=0.8)
        ax.set_xscale("log", base=2)
        ax.invert_xaxis()
        ax.set_xlabel("element size [m] (block 1 m x 1 m)")
        ax.set_ylabel("slide at 1 s / rigid block - 1 [%]")
        ax.set_title(f"theta {theta:g} deg, phi {phi:g} deg")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


_OPTIONS = {"theta": "--theta", "phi": "--phi", "t_end": "--t-end", "width": "--width", "height": "--height",
            "element size": "--size", "element_damping": "--element-damping"}


def parse_args(argv=None) -> argparse.Namespace:
    """The command line's options, checked (:func:`check_scene`; ``parser.error``, exit status
    2) before anything is meshed."""
    parser = case_parser(__doc__, name=NAME, out="runs/incline", size=None,
                         size_help="element size [m] (default: half the block's smaller side)")
    parser.add_argument("--theta", type=float, default=30.0, help="incline angle [deg]")
    parser.add_argument("--phi", type=float, default=20.0, help="friction angle of the contact [deg]")
    parser.add_argument("--width", type=float, default=1.0, help="block width along the plane [m]")
    parser.add_argument("--height", type=float, default=1.0, help="block height [m]")
    parser.add_argument("--t-end", type=float, default=1.0, help="simulated time of the slide [s]")
    parser.add_argument("--element-damping", type=float, default=DEFAULT_ELEMENT_DAMPING,
                        help="fraction of critical viscosity of each triangle's highest mode (0: undamped; "
                             f"default {DEFAULT_ELEMENT_DAMPING})")
    parser.add_argument("--damping-study", type=Path, default=None, metavar="JSON",
                        help="run the mesh-size x damping-fraction study (docs/damping.md) into this file")
    args = parser.parse_args(argv)
    check_common(parser, args)
    try:
        check_scene(args.theta, args.phi, args.t_end, args.width, args.height, args.size, args.element_damping)
    except ValueError as err:
        message = str(err).replace("block on incline: ", "")
        for name, option in _OPTIONS.items():
            message = message.replace(name, f"{option}", 1) if message.startswith(name) else message
        parser.error(message)
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    if args.damping_study is None:
        args = prepare_run(None, args, argv, NAME)
    set_threads(args.threads)
    if args.damping_study is not None:
        damping_study(args.damping_study)
        if not args.no_pictures:
            plot_study(args.damping_study, args.damping_study.with_suffix(".png"))
        return {"case": NAME, "study": str(args.damping_study)}
    t_end = args.t_end if args.max_time is None else min(args.t_end, args.max_time)
    args.out.mkdir(parents=True, exist_ok=True)
    r = run(args.theta, args.phi, t_end, args.width, args.height, out_dir=args.out, size=args.size,
            element_damping=args.element_damping)
    r = {"case": NAME, **r, "time_capped": t_end < args.t_end}
    print(dumps(r, indent=1))
    write_json(args.out / "summary.json", r, indent=1)
    finish_run(args.out, r)
    return r


if __name__ == "__main__":
    main()
