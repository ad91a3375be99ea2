"""Rigid blocks: the static factor of safety and collapse mechanism of a slope's joint blocks in
seconds, by second-order cone programming (:mod:`fdem.blocks`, docs/rigid_blocks.md).

The blocks are cut out of the same :class:`~fdem.geometry.section.Geometry` as the FDEM model
(same joint sets, same clipping); the interfaces take the crack-element strengths of the scene
(``c``, ``phi``, ``f_t`` of each tag; rock bridges take the intact rock's). Printed per scene:
blocks, factor of safety by strength reduction with its bracket, the mechanism (how many blocks
move, sliding or toppling), the pseudo-static yield acceleration of the slope towards its face
and the Newmark displacement of that mechanism under a sine record, beside the FDEM bracket
already measured (docs/cases.md, docs/failure_workflow.md; not rerun here).

    fdem run rigid-blocks --scene demo --out runs/rigid
    fdem run rigid-blocks --scene all --out runs/rigid       # every scene, about a minute
    fdem run rigid-blocks --scene four-slopes-low-fine --pga 0.3 --frequency 2 --cycles 3
    fdem run rigid-blocks --ensemble docs/ensembles/realizations.csv   # screen an ensemble
    fdem run rigid-blocks --scene four-slopes-high-fine --intact-cells 1.5   # rock may break (bonded cells)

Writes ``summary.json`` and, per scene, ``<scene>_mechanism.png`` (fixed blocks grey, moving
ones coloured by speed, arrows their velocities, rock bridges red).
"""
from __future__ import annotations

from fdem.io.messages import say

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from fdem.blocks.slope import MERGE_BELOW, analyse, print_rigid_blocks, rigid_block_line
from fdem.cases.common import case_parser, check_common, finish_run, prepare_run

__all__ = ["NAME", "MERGE_BELOW", "analyse", "rigid_block_line", "print_rigid_blocks", "Scene", "SCENES", "two_set_geometry", "two_set_property_sets", "sine_record",
           "screen_ensemble", "main"]

NAME = "rigid-blocks"
G = 9.81


@dataclass(frozen=True)
class Scene:
    """A scene: ``geometry()``, ``properties()`` (crack-element property sets by tag),
    ``unit_weight`` [N/m^3], the FDEM ``fdem`` bracket (lower, upper) with where it is from, and
    an optional closed form ``reference()`` of the factor of safety."""

    geometry: Callable
    properties: Callable
    unit_weight: float
    fdem: tuple | None = None
    fdem_source: str = ""
    reference: Callable | None = None
    fdem_picture: str | None = None


def _demo():
    from fdem.cases import quick_start
    return quick_start.geometry()


def _demo_props():
    from fdem.cases import quick_start
    return quick_start.property_sets()


def _planar(name):
    def geometry():
        from fdem.cases.planar_failure import GEOMETRIES, HEIGHT, planar_slope_geometry
        return planar_slope_geometry(HEIGHT, **GEOMETRIES[name])

    def reference():
        from fdem.cases.planar_failure import GEOMETRIES, analytic
        return analytic(**GEOMETRIES[name]).fos
    return geometry, reference


def _planar_props():
    from fdem.cases.planar_failure import property_sets
    return property_sets()


def _four(angle, spacing):
    def geometry():
        from fdem.cases.four_slopes import four_slope_geometry
        return four_slope_geometry(angle, spacing)
    return geometry


def _four_props():
    from fdem.cases.four_slopes import four_slope_property_sets
    return four_slope_property_sets()


def two_set_geometry(height: float = 12.0, face_angle: float = 60.0):
    """A slope with two sets of non-persistent joints (the seed paper's last example, our own
    numbers): set 1 dips 35 deg out of the face, traces 4 m, bridges 1 m, rows 2 m apart,
    staggered 1.5 m; set 2 dips 80 deg into the slope (trace angle 100 deg), traces 3 m,
    bridges 1.5 m, rows 3 m apart. Toe floor 10 m, crest 12 m, base 4 m."""
    from fdem.geometry.joint_sets import IntermittentSet
    from fdem.geometry.polygons import simple_slope
    from fdem.geometry.section import Geometry

    slope = simple_slope(height, face_angle, crest_length=12.0, toe_length=10.0, base_depth=4.0, name="slope")
    s1 = IntermittentSet(dip=35.0, trace_length=4.0, bridge_length=1.0, row_spacing=2.0, stagger=1.5,
                         offset=0.3, name="bedding, non-persistent")
    s2 = IntermittentSet(dip=100.0, trace_length=3.0, bridge_length=1.5, row_spacing=3.0, stagger=1.0,
                         offset=0.7, name="cross joints, non-persistent")
    return Geometry([slope], [s1, s2], min_joint_length=0.3)


def two_set_property_sets() -> dict:
    """The demo slope's strengths (:func:`fdem.cases.quick_start.property_sets`) for both sets
    and its intact rock for the bridges."""
    p = _demo_props()
    return {0: p[0], 1: p[1], 2: p[1]}


_PLANAR_NC, _PLANAR_NC_REF = _planar("no_crack")
_PLANAR_TC, _PLANAR_TC_REF = _planar("tension_crack")

SCENES = {
    "demo": Scene(_demo, _demo_props, 2600.0 * G, (1.25, 1.43), "docs/cases.md, quick start (931 triangles)",
                  fdem_picture="quick_start/failure.png"),
    "planar-no-crack": Scene(_PLANAR_NC, _planar_props, 25e3, (1.394, 1.400),
                             "docs/verification/planar_failure.json: 1.397 on 780-2,956 triangles", _PLANAR_NC_REF),
    "planar-tension-crack": Scene(_PLANAR_TC, _planar_props, 25e3, (1.300, 1.306),
                                  "docs/verification/planar_failure.json: 1.303 (522, 1,921 triangles), 1.291 (1,075)", _PLANAR_TC_REF),
    "four-slopes-low-fine": Scene(_four("low", "fine"), _four_props, 2680.0 * G, (1.11, 1.25),
                                  "docs/cases.md A, size 1.0", fdem_picture="cases/four_slopes_low_fine_failure.png"),
    "four-slopes-low-coarse": Scene(_four("low", "coarse"), _four_props, 2680.0 * G, (1.43, 1.67),
                                    "docs/cases.md A, joint offset 0.5",
                                    fdem_picture="cases/four_slopes_low_coarse_failure.png"),
    "four-slopes-high-fine": Scene(_four("high", "fine"), _four_props, 2680.0 * G, (1.67, 2.0),
                                   "docs/cases.md A (F = 2.0 capped at 5 T)",
                                   fdem_picture="cases/four_slopes_high_fine_F2_frame.png"),
    "four-slopes-high-coarse": Scene(_four("high", "coarse"), _four_props, 2680.0 * G, (1.43, 1.67),
                                     "docs/cases.md A (creep, no collapse)",
                                     fdem_picture="cases/four_slopes_high_coarse_failure.png"),
    "two-sets": Scene(two_set_geometry, two_set_property_sets, 2600.0 * G, None, "not run with FDEM"),
}
"""The scenes: the README's demo, the planar slopes of ``planar-failure``, the four slopes of
cases.md A and a slope with two sets of non-persistent joints."""


def sine_record(pga: float, frequency: float, cycles: float, samples_per_cycle: int = 200):
    """``(t, a)``: a horizontal base acceleration ``pga g sin(2 pi f t)`` [m/s^2] of ``cycles``
    cycles, then rest."""
    T = cycles / frequency
    t = np.linspace(0.0, T, int(math.ceil(cycles * samples_per_cycle)) + 1)
    return t, pga * G * np.sin(2 * math.pi * frequency * t)


def screen_ensemble(table: Path, size: float = 2.0, rtol: float = 1e-3) -> list[dict]:
    """Rigid-block factor of safety of every realization of an ensemble of the planar DFN scene
    (:class:`fdem.cases.ensemble.PlanarDFNScene`) listed in ``table`` (its ``realizations.csv``,
    parameters in the ``p_*`` columns), beside the FDEM factor of safety the table holds: the
    fast screen of an ensemble (seconds for all, where FDEM took minutes each)."""
    from fdem.cases.ensemble import PlanarDFNScene
    from fdem.cases.planar_failure import UNIT_WEIGHT, property_sets
    from fdem.io.ensemble_table import read_table

    scene = PlanarDFNScene(size=size)
    rows = []
    for row in read_table(table)[1]:
        p = {k[2:]: row[k] for k in row if k.startswith("p_")}
        geo = scene.geometry(int(p["dfn_seed"]), p["trace_length"], p["dip_scatter"], int(p["joints"]))
        t0 = time.perf_counter()
        r = analyse(geo, property_sets(p["cohesion"], p["friction_angle"]), UNIT_WEIGHT, rtol=rtol)
        rows.append({"index": int(row["index"]), "cohesion_Pa": p["cohesion"], "friction_deg": p["friction_angle"],
                     "n_blocks": r["n_blocks"], "n_bridges": r["n_bridges"], "rigid_fos": r["fos"],
                     "fdem_fos": row.get("fos"), "fdem_bracket": [row.get("fos_lower"), row.get("fos_upper")],
                     "fdem_seconds": row.get("fos_s"), "seconds": time.perf_counter() - t0,
                     "mechanism_blocks": r["mechanism"]["n_moving"] if r["mechanism"] else None})
    return rows


def main(argv=None) -> dict:
    parser = case_parser(__doc__, name=NAME, out="runs/rigid_blocks", size=None,
                         size_help="unused (rigid blocks are not meshed)")
    parser.add_argument("--scene", nargs="+", default=["demo"], choices=[*SCENES, "all"])
    parser.add_argument("--lower", type=float, default=0.2, help="factor the blocks must stand at (default 0.2)")
    parser.add_argument("--upper", type=float, default=100.0,
                        help="largest factor tried (default 100; a slope standing there is reported as such)")
    parser.add_argument("--rtol", type=float, default=1e-3, help="relative width of the final bracket")
    parser.add_argument("--merge-below", type=float, default=MERGE_BELOW, metavar="FRACTION",
                        help=f"glue blocks smaller than this fraction of the median block to a neighbour "
                             f"(default {MERGE_BELOW}; 0: keep every sliver)")
    parser.add_argument("--intact-cells", type=float, default=None, metavar="SIZE",
                        help="also cut the intact rock into bonded Voronoi cells of about SIZE m (rock-bridge "
                             "strength), so that a mechanism may break the rock between the joints")
    parser.add_argument("--ensemble", type=Path, default=None, metavar="CSV",
                        help="screen an ensemble instead: the rigid-block factor of safety of every realization "
                             "of the planar DFN ensemble in this realizations.csv, beside its FDEM one")
    parser.add_argument("--pga", type=float, default=0.3, help="peak base acceleration of the sine record [g]")
    parser.add_argument("--frequency", type=float, default=2.0, help="its frequency [Hz]")
    parser.add_argument("--cycles", type=float, default=3.0, help="its number of cycles")
    args = parser.parse_args(argv)
    check_common(parser, args)      # the shared options (--threads, --max-time: no use here, but checked)
    if not 0 < args.lower < args.upper:
        parser.error(f"need 0 < --lower < --upper, got {args.lower}, {args.upper}")
    if args.intact_cells is not None and not (math.isfinite(args.intact_cells) and args.intact_cells > 0):
        parser.error(f"--intact-cells must be a positive size in metres, got {args.intact_cells}")
    if not 0 <= args.merge_below < 1:
        parser.error(f"--merge-below must be a fraction in [0, 1), got {args.merge_below}")
    if not 1e-8 <= args.rtol < 1:
        parser.error(f"--rtol must lie in [1e-8, 1), got {args.rtol}")
    if not (args.pga >= 0 and args.frequency > 0 and args.cycles > 0):
        parser.error("--pga must be >= 0, --frequency and --cycles positive")
    from fdem.blocks.cone import ConeSolverError
    from fdem.blocks.limit import BlockSystemError
    from fdem.blocks.pictures import save_mechanism
    from fdem.io.jsonable import jsonable, write_json

    args = prepare_run(parser, args, argv, NAME)
    out = args.out
    if args.ensemble is not None:
        if not args.ensemble.is_file():
            parser.error(f"--ensemble: no file {args.ensemble}")
        rows = screen_ensemble(args.ensemble, rtol=args.rtol)
        for r in rows:
            print(f"realization {r['index']:3d}: {r['n_blocks']} blocks, rigid-block FoS {r['rigid_fos']:.3f} "
                  f"({r['seconds']:.2f} s), FDEM {r['fdem_fos']:.3f} ({r['fdem_seconds']:.0f} s)")
        summary = jsonable({"case": NAME, "ensemble": str(args.ensemble), "realizations": rows})
        write_json(out / "summary.json", summary)
        finish_run(out, summary)
        say(f"wrote {out / 'summary.json'}")
        return summary
    names = list(SCENES) if "all" in args.scene else args.scene
    record = sine_record(args.pga, args.frequency, args.cycles) if args.pga > 0 else None
    summary = {"case": NAME, "record": {"pga_g": args.pga, "frequency_hz": args.frequency, "cycles": args.cycles},
               "scenes": {}}
    for name in names:
        sc = SCENES[name]
        try:
            r = analyse(sc.geometry(), sc.properties(), sc.unit_weight, args.lower, args.upper, args.rtol, record,
                        residual=True, merge_below=args.merge_below, intact_cell_size=args.intact_cells)
        except (BlockSystemError, ConeSolverError) as err:
            print(f"{name}: {err}")
            summary["scenes"][name] = {"error": str(err)}
            continue
        plain = {k: v for k, v in r.items() if k not in ("system", "fos_result", "yield_result")}
        plain["fdem_bracket"], plain["fdem_source"] = sc.fdem, sc.fdem_source
        if sc.reference is not None:
            plain["reference_fos"] = sc.reference()
        summary["scenes"][name] = plain
        fdem = f"; FDEM [{sc.fdem[0]:.3g}, {sc.fdem[1]:.3g}] ({sc.fdem_source})" if sc.fdem else ""
        ref = f"; Hoek-Bray {plain['reference_fos']:.3f}" if sc.reference is not None else ""
        res = r["residual"]
        res = (f"; with the joints' c and f_t spent {res['fos']:.3f} ({res['mechanism']['n_moving']} block(s))"
               if res["fos"] is not None else f"; residual: {res['error']}")
        print(f"{name}: {rigid_block_line(r)}{res}{ref}{fdem}")
        if r.get("yield"):
            y = r["yield"]
            print(f"{'':{len(name)}}  yield acceleration towards the face k_y = {y['k_y']:.3f} g "
                  f"({y['mechanism']['n_moving']} block(s) {y['mechanism']['kind']}); Newmark displacement "
                  f"{r['newmark_displacement_m']:.3g} m under {args.pga:g} g, {args.frequency:g} Hz, "
                  f"{args.cycles:g} cycles")
        if not args.no_pictures and r["fos_result"] is not None:
            save_mechanism(out / f"{name}_mechanism.png", r["system"], r["fos_result"].mechanism,
                           f"{name}: F = {r['fos']:.3f}, {r['mechanism']['n_moving']} blocks "
                           f"{r['mechanism']['kind']}")
    failed = [n for n, r in summary["scenes"].items() if "error" in r]
    summary["outcome"] = "error" if failed else "finished"   # a scene without an answer fails the command
    summary = jsonable(summary)     # what summary.json holds, returned as such
    write_json(out / "summary.json", summary)
    finish_run(out, summary)
    say(f"wrote {out / 'summary.json'}" + (f"; no answer for {', '.join(failed)}" if failed else ""))
    return summary
