"""A stochastic ensemble of the planar-failure slope (:mod:`fdem.workflow.ensembles`, docs/ensembles.md).

The scene (:class:`PlanarDFNScene`) is the no-crack planar slope of ``cases/planar_failure.py``
(H = 10 m, face 60 deg, sliding plane 35 deg, gamma = 25 kN/m^3) with a
:class:`fdem.geometry.joint_sets.StochasticSet` of additional joints in the block above the plane. What
is uncertain, per realization:

* ``cohesion`` of the sliding plane: lognormal, mean 12 kPa, sd 4 kPa (the Hoek-Bray FoS at
  the means is 1.17; the verification case has 20 kPa, FoS 1.40);
* ``friction_angle`` of the plane and every joint: normal 30 +- 3 deg truncated to [20, 40];
* ``dfn_seed``: the seed of the additional joints' centres, lengths and dips;
* ``trace_length``: mean trace length of the additional joints, uniform 2-6 m (lognormal
  lengths around it, coefficient of variation 0.3);
* ``dip_scatter``: standard deviation of their dips about 90 deg (sub-vertical cross joints),
  uniform 5-25 deg;
* ``joints``: their number before clipping to the block, fixed at 8.

The additional (cross) joints are clipped to the block and stop ``0.25 size`` short of the
sliding plane (:meth:`PlanarDFNScene.cross_joints`), so the plane stays whole; they take the
planar case's joint-set-2 properties (``c = 0``, ``f_t = 100 Pa``, the sampled friction
angle): cohesionless cross joints. Each realization
meshes at ``--size``, starts in static equilibrium and finds its factor of safety by strength
reduction in ``[0.5, 2.5]`` to 0.05.

    python cases/ensemble.py --out runs/ensemble --n 20 --workers 2 --size 2.0
    fdem run ensemble --scheduler-file ~/scheduler.json --n 200 --out runs/ensemble   # on a cluster

Needs Dask (``pip install "fdem[ensembles]"``); without it the case stops before anything else
with that command in its message.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path


import numpy as np

from fdem.workflow.ensembles import (DASK_MISSING, Distribution, Ensemble, check_scheduler_file, require_dask,
                                     run_ensemble)
from fdem.results.ensemble_summary import summarize
from fdem.io.jsonable import write_json

__all__ = ["GEOMETRY", "PlanarDFNScene", "PARAMETERS", "ensemble", "parse_args", "main"]

GEOMETRY = dict(face_angle=60.0, plane_angle=35.0, tension_crack_offset=None)


@dataclass(frozen=True)
class PlanarDFNScene:
    """Builds one realization: ``scene(**parameters)`` -> the planar scene in equilibrium.

    size : mesh size [m]
    region : ``(x0, y0, x1, y1)`` [m] where the cross joints' centres fall (default: the
        bounding box of the block above the plane); the joints are then clipped to the block
    """

    size: float = 2.0
    region: tuple | None = None

    def block_corners(self) -> np.ndarray:
        """(3, 2) corners of the block above the plane [m], counter-clockwise: the daylight point
        ``D = (0.3 H + 0.2 H cot psi_f, 0.5 H)`` (:func:`fdem.cases.planar_failure.planar_slope_geometry`), the
        plane's upper end ``E = D + H (cot psi_p, 1)`` and the crest ``D + H (cot psi_f, 1)``."""
        from fdem.cases.planar_failure import HEIGHT

        H = HEIGHT
        cot_f = 1.0 / math.tan(math.radians(GEOMETRY["face_angle"]))
        cot_p = 1.0 / math.tan(math.radians(GEOMETRY["plane_angle"]))
        d = np.array([0.3 * H + 0.2 * H * cot_f, 0.5 * H])
        return np.array([d, d + H * np.array([cot_p, 1.0]), d + H * np.array([cot_f, 1.0])])

    def cross_joints(self, dfn_seed: int = 0, trace_length: float = 3.0, dip_scatter: float = 10.0,
                     joints: int = 4) -> np.ndarray:
        """(k, 2, 2) cross-joint segments [m]: a :class:`fdem.geometry.joint_sets.StochasticSet` (centres
        uniform in the block's bounding box, lognormal lengths of mean ``trace_length`` and
        coefficient of variation 0.3, dips normal about 90 deg with sd ``dip_scatter``) clipped
        to the block, with the ends that reach the sliding plane pulled back along the joint to
        ``0.25 size`` above it (a rock bridge).

        Why: a joint crossing the plane splits it, and two crossings closer than the model's
        ``min_joint_length`` drop the piece between them, an intact bridge in the sliding plane
        that raised the FoS by up to 6 % above the plane-only Hoek-Bray value. Pieces left
        shorter than ``0.25 size`` are dropped.
        """
        from fdem.geometry.polygons import Polygon
        from fdem.geometry.joint_sets import StochasticSet
        from fdem.geometry.dfn import clip_segments

        corners = self.block_corners()
        box = self.region or (*corners.min(axis=0), *corners.max(axis=0))
        dfn = StochasticSet(count=int(joints), length=("lognormal", float(trace_length), 0.3 * float(trace_length)),
                            dip=("normal", 90.0, float(dip_scatter)), seed=int(dfn_seed), region=tuple(box),
                            name="cross joints")
        pieces, _ = clip_segments(dfn.raw_segments(box), Polygon(corners, name="block"), 1e-9)
        t = corners[1] - corners[0]
        n = np.array([-t[1], t[0]]) / np.linalg.norm(t)          # unit normal of the plane, into the block
        margin = 0.25 * self.size
        kept = []
        for a, b in pieces:
            ha, hb = (a - corners[0]) @ n, (b - corners[0]) @ n
            if max(ha, hb) <= margin:
                continue
            if ha < margin:
                a = a + (b - a) * (margin - ha) / (hb - ha)
            if hb < margin:
                b = b + (a - b) * (margin - hb) / (ha - hb)
            if np.linalg.norm(b - a) >= margin:
                kept.append([a, b])
        return np.array(kept, dtype=np.float64).reshape(-1, 2, 2)

    def geometry(self, dfn_seed: int = 0, trace_length: float = 3.0, dip_scatter: float = 10.0, joints: int = 4):
        """The slope model with the cross joints (joint set 2; none if all were dropped)."""
        from fdem.cases.planar_failure import HEIGHT

        from fdem.geometry.section import Geometry
        from fdem.geometry.joint_sets import SegmentSet
        from fdem.cases.planar_failure import planar_slope_geometry

        base = planar_slope_geometry(HEIGHT, **GEOMETRY)
        segs = self.cross_joints(dfn_seed, trace_length, dip_scatter, joints)
        sets = (*base.joint_sets, SegmentSet(segs.reshape(-1, 4), name="cross joints")) if len(segs) else \
            base.joint_sets
        return Geometry(base.bodies, sets, min_joint_length=0.25 * self.size)

    def __call__(self, cohesion: float, friction_angle: float, dfn_seed: int = 0, trace_length: float = 3.0,
                 dip_scatter: float = 10.0, joints: int = 4):
        import warnings

        from fdem.cases.planar_failure import planar_failure_simulation

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")          # dropped short joint pieces are expected in a DFN
            scene = planar_failure_simulation(self.geometry(dfn_seed, trace_length, dip_scatter, joints), self.size,
                                              cohesion=cohesion, friction_angle=friction_angle)
        return scene


PARAMETERS = {
    "cohesion": Distribution.lognormal(12e3, 4e3),
    "friction_angle": Distribution.normal(30.0, 3.0, low=20.0, high=40.0),
    "dfn_seed": Distribution.seed(),
    "trace_length": Distribution.uniform(2.0, 6.0),
    "dip_scatter": Distribution.uniform(5.0, 25.0),
    "joints": Distribution.fixed(8),
}


def ensemble(n: int = 20, seed: int = 0, method: str = "lhs", size: float = 2.0,
             fos: tuple = (0.5, 2.5, 0.05), max_time: float | None = None) -> Ensemble:
    """The ensemble of this case (module docstring); ``max_time`` [s] caps each trial (smoke run)."""
    return Ensemble(PlanarDFNScene(size=size), PARAMETERS, n=n, seed=seed, method=method, fos=fos, toe_x=3.0,
                    max_time=max_time)


def parse_args(argv=None) -> tuple[argparse.Namespace, Ensemble]:
    """The command line's options, checked before anything is meshed (``parser.error``, exit
    status 2), and the ensemble they describe (:class:`fdem.workflow.ensembles.Ensemble`
    validates ``--n``, ``--seed``, ``--method`` and ``--max-time``)."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("runs/ensemble"))
    parser.add_argument("--scene", type=Path, default=None, metavar="FILE",
                        help="vary a scene file instead of the planar slope: its [ensemble] table names the keys "
                             "and their distributions (docs/scenes.md, Ensembles)")
    parser.add_argument("--n", type=int, default=None, help="realizations (default 20, or the scene's)")
    parser.add_argument("--workers", type=int, default=2, help="local worker processes (one Numba thread each)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (default: local)")
    where.add_argument("--scheduler-file", type=Path, default=None, metavar="PATH",
                       help="the file a running Dask scheduler wrote (dask scheduler --scheduler-file PATH): "
                            "a cluster started by a batch system or dask-jobqueue")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for --scheduler")
    parser.add_argument("--seed", type=int, default=None, help="sampling seed (default 0, or the scene's)")
    parser.add_argument("--method", choices=("lhs", "mc"), default=None, help="default lhs, or the scene's")
    parser.add_argument("--size", type=float, default=None, help="mesh size [m] of the planar slope (default 2)")
    parser.add_argument("--max-time", type=float, default=None, metavar="SECONDS",
                        help="cap on each trial's simulated time [s] (a smoke run: realizations end below_bracket)")
    parser.add_argument("--no-pictures", action="store_true", help="no PNG pictures")
    parser.add_argument("--quiet", action="store_true", help="only warnings and the result")
    args = parser.parse_args(argv)
    from fdem.io.messages import configure

    configure(quiet=args.quiet)
    try:
        require_dask()
    except ImportError:
        parser.exit(1, f"fdem run ensemble: {DASK_MISSING}\n")
    if args.scheduler_file is not None:
        try:
            check_scheduler_file(args.scheduler_file)
        except (OSError, ValueError) as err:
            parser.error(f"--scheduler-file: {err}")
    if args.scene is not None and args.size is not None:
        parser.error("--size: a scene's element size is its [scene] size")
    if args.size is not None and not (math.isfinite(args.size) and args.size > 0):
        parser.error(f"--size must be a positive number of metres, got {args.size}")
    if args.workers < 1:
        parser.error(f"--workers must be at least 1, got {args.workers}")
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        parser.error(f"--timeout must be a positive number of seconds, got {args.timeout}")
    try:
        if args.scene is not None:
            from fdem.scene.ensemble import scene_ensemble

            ens = scene_ensemble(args.scene, args.n, args.seed, args.method, max_time=args.max_time)
        else:
            ens = ensemble(20 if args.n is None else args.n, 0 if args.seed is None else args.seed,
                           args.method or "lhs", 2.0 if args.size is None else args.size, max_time=args.max_time)
    except ValueError as err:
        parser.error(str(err))
    if args.no_pictures:
        ens = dataclasses.replace(ens, pictures=False)
    return args, ens


def main(argv=None) -> dict:
    args, ens = parse_args(argv)
    load = os.getloadavg()
    run = run_ensemble(ens, args.out, workers=args.workers, scheduler=args.scheduler, timeout=args.timeout,
                       scheduler_file=args.scheduler_file)
    summary = summarize(args.out, pictures=not args.no_pictures)
    remote = args.scheduler is not None or args.scheduler_file is not None
    timing = {"workers": None if remote else args.workers, "scheduler": args.scheduler,
              "scheduler_file": None if args.scheduler_file is None else str(args.scheduler_file),
              "n": ens.n, "n_run": run.n_run, "n_skipped": run.n_skipped, "wall_seconds": run.wall_seconds,
              "load_average_before": load, "load_average_after": os.getloadavg(), "cpu_count": os.cpu_count(),
              "size_m": (2.0 if args.size is None else args.size) if args.scene is None else None, "scene": None if args.scene is None else str(args.scene), "date": time.strftime("%Y-%m-%d %H:%M")}
    write_json(args.out / "timing.json", timing, indent=1)
    pf = summary["probability_of_failure"]
    print(f"{run.n_run} realizations run, {run.n_skipped} already in {run.table}, {run.wall_seconds:.1f} s; "
          f"FoS median {summary['fos']['p50']:.3f}, P(FoS < 1) = {pf['k']}/{pf['m']} "
          f"(95 % Wilson {pf['wilson'][0]:.3f}-{pf['wilson'][1]:.3f}); status {summary['status']}")
    return summary


if __name__ == "__main__":
    main()
