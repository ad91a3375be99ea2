"""The four jointed slopes of cases.md A (seed 002): mesh a 15 m slope with its brick-pattern DFN,
bring it to geostatic equilibrium, reduce the strength of crack elements and joints by 10 % per
stage down to 30 %, and follow the failure and runout.

Writes to ``--out``: the mesh (``.msh``, a PNG and a ``.vtu`` with crack elements as line cells),
``slope.pvd`` and ``slope_cracks.pvd`` (open them in ParaView), ``history.csv`` (energy ledger
and monitors per stage), PNG snapshots and ``summary.json`` (runout distance and volume, peak
kinetic energy, fracture events by mode).

    python cases/four_slopes.py --out runs/demo --max-steps 3000      # quick look, coarse mesh
    python cases/four_slopes.py --angle high --spacing coarse --size 0.3 --out runs/high_coarse
    python cases/four_slopes.py --max-steps 0 --out runs/mesh_only     # mesh and pictures only

Paper (seed 002): about 180,000 triangles (``--size 0.18``), geostatic equilibrium over 500,000
steps of 2 us, then 10 % strength reduction per 10,000 steps. Defaults here are scaled for a
laptop; every stage length is a parameter.
"""
from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from fdem.analysis import fragments, released_kinetic_energy, runout
from fdem.cohesive import CrackSet, four_slope_property_sets
from fdem.contact import ContactSet
from fdem.materials import ElasticMaterial
from fdem.meshing import mesh_model, quality_report
from fdem.model import Model, geostatic_stress
from fdem.preview import plot_mesh_png, write_mesh_vtu
from fdem.scenes import four_slope_model
from fdem.solver import Damping, Simulation
from fdem.topology import build_topology

# Table 1 of the paper (cases.md A): finite elements
YOUNG, POISSON, DENSITY = 0.59e9, 0.29, 2680.0
CONTACT_PENALTY = 10 * YOUNG  # Pa; Munjiza p = alpha E, alpha = 10 (verification.md guidance)
GRAVITY = 9.81


def build(angle: str = "low", spacing="fine", size: float = 0.5, refine: float | None = None):
    """Geometry, mesh and topology of one of the four slopes."""
    model = four_slope_model(angle, spacing)
    mesh = mesh_model(model, size, refine_near_joints=refine)
    return model, mesh, build_topology(mesh)


def ground_surface(slope) -> callable:
    """``y_s(x)``: the top of the slope profile, for the geostatic initial stress."""
    v = slope.vertices
    x0, _, x1, _ = slope.bounds
    top = v[(v[:, 1] > 0) & ~(((v[:, 0] == x0) | (v[:, 0] == x1)) & (v[:, 1] == 0))]
    top = top[np.argsort(top[:, 0], kind="stable")]
    return lambda x: np.interp(x, top[:, 0], top[:, 1])


def simulation(geometry, topology, out_dir: Path | None, pictures: bool = True) -> tuple[Simulation, CrackSet]:
    """The slope model: rock triangles, crack elements (intact + DFN), contact, supports, gravity."""
    model = Model(topology, ElasticMaterial(young=YOUNG, poisson=POISSON, density=DENSITY))
    model.set_gravity(0.0, -GRAVITY)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    model.set_initial_stress(geostatic_stress(DENSITY, GRAVITY, surface=ground_surface(geometry.bodies[0]),
                                              poisson=POISSON))
    cracks = CrackSet(topology, four_slope_property_sets(), contact_penalty=CONTACT_PENALTY)
    contact = ContactSet(topology, CONTACT_PENALTY, friction_angle=30.0, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], out_dir=out_dir, name="slope", pictures=pictures)
    return sim, cracks


def run_stages(sim: Simulation, cracks: CrackSet, geostatic_steps: int, reduction_steps: int,
               runout_steps: int, max_steps: int | None, final_factor: float = 0.3) -> list[tuple[str, int]]:
    """Geostatic equilibrium (local damping 0.8), strength reduction 10 % per stage down to
    ``final_factor`` (no damping), then runout (no damping). ``max_steps`` caps the total."""
    plan = [("geostatic", geostatic_steps, 1.0, Damping.quasi_static())]
    factor = 1.0
    while factor > final_factor + 1e-9:
        factor = round(factor - 0.1, 10)
        plan.append((f"reduction_{int(round(100 * factor))}pct", reduction_steps, factor, Damping()))
    plan.append(("runout", runout_steps, factor, Damping()))
    budget = max_steps if max_steps is not None else sum(p[1] for p in plan)
    done = []
    for name, steps, strength, damping in plan:
        steps = min(steps, budget)
        if steps <= 0:
            break
        cracks.scale_strength(strength)
        # Geostatic equilibrium with elastic crack elements, as the paper's initial FEM stage.
        cracks.hold_elastic(name == "geostatic")
        sim.run(n_steps=steps, damping=damping, stage=name, output_every=max(1, steps // 4))
        budget -= steps
        done.append((name, steps))
    return done


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--angle", choices=["low", "high"], default="low")
    parser.add_argument("--spacing", default="fine", help="'fine' (s = 1 m), 'coarse' (s = 5 m) or metres")
    parser.add_argument("--size", type=float, default=0.5, help="element size [m] (0.18 gives ~180k triangles)")
    parser.add_argument("--refine", type=float, default=None, help="element size factor on joints, e.g. 0.5")
    parser.add_argument("--out", type=Path, default=Path("runs/four_slopes"))
    parser.add_argument("--geostatic-steps", type=int, default=20_000)
    parser.add_argument("--reduction-steps", type=int, default=10_000, help="steps per 10 %% strength reduction")
    parser.add_argument("--runout-steps", type=int, default=100_000)
    parser.add_argument("--max-steps", type=int, default=None, help="cap on the total steps (0: mesh only)")
    parser.add_argument("--no-pictures", action="store_true", help="skip PNG snapshots of each output frame")
    args = parser.parse_args(argv)
    try:
        spacing = args.spacing if args.spacing in ("fine", "coarse") else float(args.spacing)
    except ValueError:
        parser.error(f"--spacing must be 'fine', 'coarse' or a number of metres, got {args.spacing!r}")

    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            geometry, mesh, topo = build(args.angle, spacing, args.size, args.refine)
        except ValueError as err:  # bad input: say what is wrong, no traceback
            parser.error(str(err))
    for w in caught:
        print(f"warning: {w.message}")
    elapsed = time.perf_counter() - t0
    report = quality_report(mesh)
    print(f"meshed and exploded in {elapsed:.2f} s: {topo.n_triangles} triangles, {topo.n_cracks} crack elements "
          f"({int((topo.crack_tag > 0).sum())} on joints)")
    print(report)
    args.out.mkdir(parents=True, exist_ok=True)
    name = f"{args.angle}_{args.spacing}"
    mesh.save(args.out / f"{name}.msh")
    vtu = write_mesh_vtu(topo, args.out / f"{name}_mesh.vtu")
    png = plot_mesh_png(topo, args.out / f"{name}_mesh.png",
                        title=f"{args.angle}-angle {args.spacing} slope: {topo.n_triangles} triangles")
    print(f"wrote {vtu} and {png}")
    summary = {"case": name, "size_m": args.size, "n_triangles": topo.n_triangles,
               "seconds_mesh_and_topology": elapsed, "n_crack_elements": topo.n_cracks,
               "n_joint_crack_elements": int((topo.crack_tag > 0).sum()), "quality": report.as_dict()}

    if args.max_steps != 0:
        sim, cracks = simulation(geometry, topo, args.out, pictures=not args.no_pictures)
        print(f"time step {sim.dt:.3g} s (critical limits: "
              + ", ".join(f"{k} {v:.3g} s" for k, v in sim.critical_dt()[1].items()) + ")")
        t1 = time.perf_counter()
        try:
            stages = run_stages(sim, cracks, args.geostatic_steps, args.reduction_steps, args.runout_steps,
                                args.max_steps)
        finally:
            sim.close()
        v = geometry.bodies[0].vertices
        toe_y = v[v[:, 1] > 0, 1].min()  # the toe floor is the lowest part of the ground surface
        toe_x = float(v[v[:, 1] == toe_y, 0].max())
        n_frag, _ = fragments(topo, cracks.broken)
        modes = cracks.events["mode"] if len(cracks.events) else np.array([])
        summary.update({
            "stages": stages, "steps": sim.state.step, "simulated_time_s": sim.state.time, "dt_s": sim.dt,
            "seconds_simulation": time.perf_counter() - t1,
            "runout": runout(topo, sim.state.x, toe_x=toe_x),
            "peak_kinetic_energy_J_per_m": released_kinetic_energy(sim.history),
            "n_broken": int(cracks.broken.sum()), "n_fragments": int(n_frag),
            "events_by_mode": {m: int((modes == m).sum()) for m in ("I", "II", "mixed")},
        })
        print(f"ran {sim.state.step} steps ({sim.state.time:.4g} s) in {summary['seconds_simulation']:.1f} s; "
              f"{summary['n_broken']} crack elements broken; max displacement "
              f"{summary['runout']['max_displacement_m']:.3g} m; see {args.out / 'slope.pvd'}")
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"wrote {args.out / 'summary.json'}")
    return summary


if __name__ == "__main__":
    main()
