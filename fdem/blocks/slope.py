"""A slope's rigid-block analysis in one call: blocks, factor of safety and mechanism, and on
request the factor with the joints' cohesion spent, the yield acceleration and the Newmark
displacement of its mechanism (:func:`analyse`); the line and the file the slope cases print
and write with ``--rigid-blocks`` (:func:`print_rigid_blocks`). docs/rigid_blocks.md."""
from __future__ import annotations

import time
import warnings
from pathlib import Path

__all__ = ["MERGE_BELOW", "analyse", "rigid_block_line", "print_rigid_blocks"]

MERGE_BELOW = 0.01
"""Blocks smaller than this fraction of the median block are glued to a neighbour: the slivers
that joints cut where they meet the ground surface at a small angle
(:func:`fdem.blocks.assembly.merge_small_faces`)."""


def analyse(geometry, properties: dict, unit_weight: float, lower: float = 0.2, upper: float = 100.0,
            rtol: float = 1e-3, record=None, contact_friction: float | None = None, residual: bool = False,
            merge_below: float = MERGE_BELOW, intact_cell_size: float | None = None) -> dict:
    """Blocks, factor of safety and mechanism (and, with ``record = (t, a)``, the yield
    acceleration towards the face and the Newmark displacement of its mechanism; with
    ``residual``, the factor of safety with the joints' cohesion and tensile strength spent;
    with ``intact_cell_size`` [m], the intact rock cut into bonded Voronoi cells that may break)
    of a slope. Returns a plain dict; ``"system"``, ``"fos_result"`` and ``"yield_result"`` hold
    the objects."""
    from fdem.blocks.assembly import block_system
    from fdem.blocks.limit import BlockSystemError, StandsBeyondBracket, factor_of_safety, statics
    from fdem.blocks.newmark import mechanism_newmark
    from fdem.blocks.strength import strengths_from

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # the DFN's dropped short pieces: the mesher's concern
        system = block_system(geometry, merge_below=merge_below, intact_cell_size=intact_cell_size)
    st = statics(system, unit_weight)
    strengths = strengths_from(properties, contact_friction)
    t1 = time.perf_counter()
    try:
        fos = factor_of_safety(st, strengths, lower, upper, rtol)
    except StandsBeyondBracket as err:   # a result, not a failure: F > upper
        out = {**system.summary(), "seconds_blocks": t1 - t0, "seconds_fos": time.perf_counter() - t1,
               "fos": None, "fos_above": err.upper, "bracket": [err.upper, None], "n_solves": 2,
               "seconds": time.perf_counter() - t1, "mechanism": None, "system": system, "fos_result": None}
        if residual:
            out["residual"] = _residual_fos(st, strengths, lower, upper, rtol)
        return out
    t2 = time.perf_counter()
    out = {**system.summary(), "seconds_blocks": t1 - t0, "seconds_fos": t2 - t1, **fos.as_dict(),
           "system": system, "fos_result": fos}
    if residual:
        out["residual"] = _residual_fos(st, strengths, lower, upper, rtol)
    if record is not None:
        try:
            d, y = mechanism_newmark(st, strengths, record[0], record[1])
            out.update({"yield": y.as_dict(), "newmark_displacement_m": d, "yield_result": y})
        except BlockSystemError as err:
            out.update({"yield": None, "newmark_displacement_m": None, "yield_error": str(err)})
    return out


def _residual_fos(st, strengths: dict, lower: float, upper: float, rtol: float) -> dict:
    """Factor of safety with ``c = f_t = 0`` on every joint set (tags >= 1; bridges and contacts
    keep theirs): the joints after the FDEM crack elements have softened (brittle joints),
    against the peak strength the rigid blocks keep."""
    from dataclasses import replace

    from fdem.blocks.limit import BlockSystemError, factor_of_safety

    spent = {k: (replace(s, c=0.0, f_t=0.0) if k >= 1 else s) for k, s in strengths.items()}
    try:
        r = factor_of_safety(st, spent, min(lower, 0.05), upper, rtol)
    except BlockSystemError as err:
        return {"fos": None, "error": str(err)}
    return {"fos": r.fos, "bracket": list(r.bracket), "seconds": r.seconds, "mechanism": r.mechanism.as_dict()}


def rigid_block_line(r: dict) -> str:
    """One line: blocks, factor of safety, mechanism, cost."""
    m = r["mechanism"]
    if r["fos"] is None:
        return (f"rigid blocks: {r['n_blocks']} blocks ({r['n_free']} free) still stand at F = {r['fos_above']:g}: "
                f"factor of safety above it")
    return (f"rigid blocks: {r['n_blocks']} blocks ({r['n_free']} free), factor of safety {r['fos']:.3f} "
            f"[{r['bracket'][0]:.3f}, {r['bracket'][1]:.3f}], mechanism: {m['n_moving']} block(s) {m['kind']}; "
            f"{r['n_solves']} cone programs in {r['seconds']:.2f} s")


def print_rigid_blocks(geometry, properties: dict, unit_weight: float, out: Path | None = None,
                       upper: float = 100.0) -> dict:
    """For the slope cases' ``--rigid-blocks``: print the rigid-block factor of safety and
    mechanism of ``geometry`` (before the FDEM run, whose factor of safety follows) and write
    ``<out>/rigid_blocks.json``; a failure is printed, not raised (the FDEM run goes on)."""
    from fdem.blocks.limit import BlockSystemError
    from fdem.blocks.cone import ConeSolverError
    from fdem.io.jsonable import write_json

    try:
        r = analyse(geometry, properties, unit_weight, upper=upper)
    except (BlockSystemError, ConeSolverError) as err:
        print(f"rigid blocks: no factor of safety: {err}")
        return {"error": str(err)}
    print(rigid_block_line(r))
    plain = {k: v for k, v in r.items() if k not in ("system", "fos_result", "yield_result")}
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        write_json(Path(out) / "rigid_blocks.json", plain)
    return plain
