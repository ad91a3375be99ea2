"""A stochastic ensemble of the planar-failure slope (:mod:`fdem.ensembles`, docs/ensembles.md).

The scene (:class:`PlanarDFNScene`) is the no-crack planar slope of ``cases/planar_failure.py``
(H = 10 m, face 60 deg, sliding plane 35 deg, gamma = 25 kN/m^3) with a
:class:`fdem.geometry.StochasticSet` of additional joints in the block above the plane. What
is uncertain, per realization:

* ``cohesion`` of the sliding plane: lognormal, mean 12 kPa, sd 4 kPa (the Hoek-Bray FoS at
  the means is 1.17; the verification case has 20 kPa, FoS 1.40);
* ``friction_angle`` of the plane and every joint: normal 30 +- 3 deg truncated to [20, 40];
* ``dfn_seed``: the seed of the additional joints' centres, lengths and dips;
* ``trace_length``: mean trace length of the additional joints, uniform 2-6 m (lognormal
  lengths around it, coefficient of variation 0.3);
* ``dip_scatter``: standard deviation of their dips about 90 deg (sub-vertical cross joints),
  uniform 5-25 deg;
* ``joints``: their number, fixed at 4.

The additional joints take the planar case's joint-set-2 properties (``c = 0``,
``f_t = 100 Pa``, the sampled friction angle): cohesionless cross joints. Each realization
meshes at ``--size``, starts in static equilibrium and finds its factor of safety by strength
reduction in ``[0.5, 2.5]`` to 0.05.

    python cases/ensemble.py --out runs/ensemble --n 20 --workers 2 --size 2.0
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fdem.ensembles import Distribution, Ensemble, run_ensemble, summarize  # noqa: E402

GEOMETRY = dict(face_angle=60.0, plane_angle=35.0, tension_crack_offset=None)


@dataclass(frozen=True)
class PlanarDFNScene:
    """Builds one realization: ``scene(**parameters)`` -> the planar scene in equilibrium.

    size : mesh size [m]
    region : ``(x0, y0, x1, y1)`` [m] where the additional joints' centres fall (default: the
        bounding box of the block above the plane)
    """

    size: float = 2.0
    region: tuple | None = None

    def block_box(self) -> tuple[float, float, float, float]:
        """Bounding box of the block: daylight point ``D`` to the plane's upper end (see
        :func:`fdem.scenes.planar_slope_model`: ``D = (0.3 H + 0.2 H cot psi_f, 0.5 H)``)."""
        import math

        from planar_failure import HEIGHT

        H = HEIGHT
        dx = 0.3 * H + 0.2 * H / math.tan(math.radians(GEOMETRY["face_angle"]))
        dy = 0.5 * H
        reach = H / math.tan(math.radians(GEOMETRY["plane_angle"]))
        return (dx, dy, dx + reach, dy + H)

    def geometry(self, dfn_seed: int = 0, trace_length: float = 3.0, dip_scatter: float = 10.0, joints: int = 4):
        """The slope model with the additional joints (joint set 2)."""
        from planar_failure import HEIGHT

        from fdem.geometry import Model, StochasticSet
        from fdem.scenes import planar_slope_model

        base = planar_slope_model(HEIGHT, **GEOMETRY)
        dfn = StochasticSet(count=int(joints), length=("lognormal", float(trace_length), 0.3 * float(trace_length)),
                            dip=("normal", 90.0, float(dip_scatter)), seed=int(dfn_seed),
                            region=self.region or self.block_box(), name="cross joints")
        return Model(base.bodies, (*base.joint_sets, dfn), min_joint_length=0.25 * self.size)

    def __call__(self, cohesion: float, friction_angle: float, dfn_seed: int = 0, trace_length: float = 3.0,
                 dip_scatter: float = 10.0, joints: int = 4):
        import warnings

        from planar_failure import planar_failure_simulation

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
    "joints": Distribution.fixed(4),
}


def ensemble(n: int = 20, seed: int = 0, method: str = "lhs", size: float = 2.0,
             fos: tuple = (0.5, 2.5, 0.05)) -> Ensemble:
    """The ensemble of this case (module docstring)."""
    return Ensemble(PlanarDFNScene(size=size), PARAMETERS, n=n, seed=seed, method=method, fos=fos, toe_x=3.0)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("runs/ensemble"))
    parser.add_argument("--n", type=int, default=20, help="realizations")
    parser.add_argument("--workers", type=int, default=2, help="local worker processes (one Numba thread each)")
    parser.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (default: local)")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for --scheduler")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--method", choices=("lhs", "mc"), default="lhs")
    parser.add_argument("--size", type=float, default=2.0, help="mesh size [m]")
    args = parser.parse_args(argv)
    ens = ensemble(args.n, args.seed, args.method, args.size)
    load = os.getloadavg()
    run = run_ensemble(ens, args.out, workers=args.workers, scheduler=args.scheduler, timeout=args.timeout)
    summary = summarize(args.out)
    timing = {"workers": args.workers if args.scheduler is None else None, "scheduler": args.scheduler,
              "n": args.n, "n_run": run.n_run, "n_skipped": run.n_skipped, "wall_seconds": run.wall_seconds,
              "load_average_before": load, "load_average_after": os.getloadavg(), "cpu_count": os.cpu_count(),
              "size_m": args.size, "date": time.strftime("%Y-%m-%d %H:%M")}
    (args.out / "timing.json").write_text(json.dumps(timing, indent=1))
    pf = summary["probability_of_failure"]
    print(f"{run.n_run} realizations run, {run.n_skipped} already in {run.table}, {run.wall_seconds:.1f} s; "
          f"FoS median {summary['fos']['p50']:.3f}, P(FoS < 1) = {pf['k']}/{pf['m']} "
          f"(95 % Wilson {pf['wilson'][0]:.3f}-{pf['wilson'][1]:.3f}); status {summary['status']}")
    return summary


if __name__ == "__main__":
    main()
