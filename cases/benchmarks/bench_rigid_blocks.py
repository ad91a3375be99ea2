"""Rigid blocks by second-order cone programming: checks and cost (docs/rigid_blocks.md).

* Static: factor of safety of every scene of ``fdem run rigid-blocks`` (blocks, interfaces,
  cone programs, seconds), the four-slope geometry at several joint spacings (cost against
  block count), and the screen of the planar DFN ensemble against its FDEM factors of safety.
* Closed forms: Hoek-Bray planar slopes, Goodman-Bray regimes on a grid of plane angles and
  block shapes, Newmark's sliding block.
* Bonded blocks: the slopes with the intact rock cut into Voronoi cells (rock may break).
* Soft against hard: the same scenes stepped with hard and with soft contacts (answers and
  cost): a block sliding, a block toppling, and the demo slope's blocks below and above their
  factor of safety.

One thread (Clarabel's direct solver is sequential); the load average is recorded with every
figure (the machine is shared).

    python cases/benchmarks/bench_rigid_blocks.py            # about 5 minutes
    python cases/benchmarks/bench_rigid_blocks.py --quick    # skips bonded cells, spacing sweep, demo dynamics

Writes docs/benchmarks/rigid_blocks.json and pictures in docs/rigid_blocks/.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from records import record, save  # noqa: E402

from fdem.blocks.assembly import CONTACT, block_system  # noqa: E402
from fdem.blocks.dynamics import BlockDynamics  # noqa: E402
from fdem.blocks.limit import check_equilibrium, factor_of_safety, statics  # noqa: E402
from fdem.blocks.newmark import mechanism_newmark  # noqa: E402
from fdem.blocks.strength import Strength, strengths_from  # noqa: E402
from fdem.blocks.slope import MERGE_BELOW, analyse  # noqa: E402
from fdem.cases.rigid_blocks import SCENES, screen_ensemble  # noqa: E402
from fdem.geometry.polygons import rectangle  # noqa: E402
from fdem.geometry.section import Geometry  # noqa: E402
from fdem.reference.newmark import newmark_response  # noqa: E402
from fdem.reference.newmark import yield_acceleration as newmark_yield  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
PICTURES = ROOT / "docs" / "rigid_blocks"
G = 9.81


def load() -> float:
    return os.getloadavg()[0]


def static_scenes(records: list) -> dict:
    from fdem.blocks.pictures import save_mechanism

    out = {}
    for name, sc in SCENES.items():
        best = None
        for _ in range(2):       # best of two: the machine is shared
            t0 = time.perf_counter()
            r = analyse(sc.geometry(), sc.properties(), sc.unit_weight, residual=True)
            wall = time.perf_counter() - t0
            if best is None or wall < best[1]:
                best = (r, wall)
        r, wall = best
        ld = load()
        records.append(record(f"rigid-block FoS {name}: blocks, bisection, and the bisection with the joints' c and "
                              f"f_t spent", wall, "s", mesh_size=r["n_blocks"],
                              threads=1, n_free=r["n_free"], n_interfaces=r["n_interfaces"],
                              fos=r["fos"], bracket=r["bracket"], n_solves=r["n_solves"],
                              seconds_blocks=r["seconds_blocks"], seconds_fos=r["seconds_fos"],
                              residual_fos=r["residual"]["fos"], fdem_bracket=sc.fdem,
                              mechanism=(r["mechanism"] or {}).get("kind"),
                              n_moving=(r["mechanism"] or {}).get("n_moving"), load_average=ld))
        if r["fos_result"] is not None:
            save_mechanism(PICTURES / f"{name}_mechanism.png", r["system"], r["fos_result"].mechanism,
                           f"{name}: rigid blocks, F = {r['fos']:.3f}, {r['mechanism']['n_moving']} block(s) "
                           f"{r['mechanism']['kind']}")
        out[name] = r
        print(f"{name}: {r['n_blocks']} blocks, FoS {r['fos']}, {wall:.2f} s (load {ld:.1f})", flush=True)
    return out


def bonded_scenes(records: list, cell: float = 1.5) -> None:
    """The slopes again with the intact rock cut into bonded Voronoi cells of about ``cell`` m
    (rock-bridge strength): mechanisms may now break the rock between the joints."""
    from fdem.blocks.pictures import save_mechanism

    for name in ("demo", "four-slopes-low-fine", "four-slopes-low-coarse", "four-slopes-high-fine",
                 "four-slopes-high-coarse", "two-sets"):
        sc = SCENES[name]
        t0 = time.perf_counter()
        r = analyse(sc.geometry(), sc.properties(), sc.unit_weight, intact_cell_size=cell)
        wall = time.perf_counter() - t0
        records.append(record(f"rigid-block FoS {name}, intact rock in bonded cells of {cell:g} m", wall, "s",
                              mesh_size=r["n_blocks"], threads=1, n_interfaces=r["n_interfaces"], fos=r["fos"],
                              bracket=r["bracket"], n_solves=r["n_solves"], seconds_blocks=r["seconds_blocks"],
                              seconds_fos=r["seconds_fos"], fdem_bracket=sc.fdem,
                              n_moving=(r["mechanism"] or {}).get("n_moving"),
                              mechanism=(r["mechanism"] or {}).get("kind"), load_average=load()))
        if r["fos_result"] is not None:
            save_mechanism(PICTURES / f"{name}_cells_mechanism.png", r["system"], r["fos_result"].mechanism,
                           f"{name}, bonded cells {cell:g} m: F = {r['fos']:.3f}, "
                           f"{r['mechanism']['n_moving']} block(s) {r['mechanism']['kind']}")
        print(f"{name} cells: {r['n_blocks']} blocks, FoS {r['fos']}, {wall:.1f} s", flush=True)


def spacing_sweep(records: list) -> list:
    """Cost against block count: the low-angle four-slope geometry at joint spacings 5 ... 0.7 m."""
    from fdem.cases.four_slopes import four_slope_geometry, four_slope_property_sets

    rows = []
    for s in (5.0, 3.0, 2.0, 1.5, 1.0, 0.7):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = four_slope_geometry("low", s)
        t0 = time.perf_counter()
        r = analyse(g, four_slope_property_sets(), 2680.0 * G)
        wall = time.perf_counter() - t0
        per = r["seconds_fos"] / r["n_solves"]
        rows.append((r["n_blocks"], r["n_interfaces"], per, r["fos"]))
        records.append(record(f"rigid-block FoS, low-angle four-slope geometry, spacing {s:g} m", wall, "s",
                              mesh_size=r["n_blocks"], threads=1, n_interfaces=r["n_interfaces"],
                              seconds_per_cone_program=per, n_solves=r["n_solves"], fos=r["fos"],
                              seconds_blocks=r["seconds_blocks"], load_average=load()))
        print(f"spacing {s}: {r['n_blocks']} blocks, {per * 1e3:.1f} ms per cone program, FoS {r['fos']:.3f}",
              flush=True)
    n = np.array([r[0] for r in rows], float)
    t = np.array([r[2] for r in rows])
    slope = float(np.polyfit(np.log(n[n > 100]), np.log(t[n > 100]), 1)[0])
    records.append(record("rigid-block cone program: growth of its time with the block count (log-log slope)",
                          slope, "-", threads=1))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(4.5, 3.4))
    ax.loglog(n, t * 1e3, "o-")
    ax.set_xlabel("blocks")
    ax.set_ylabel("ms per cone program")
    ax.set_title(f"low-angle four-slope geometry, spacing 5 to 0.7 m\nslope {slope:.2f} (1 thread, shared 2-core VM)",
                 fontsize=8)
    fig.tight_layout()
    fig.savefig(PICTURES / "cost_vs_blocks.png", dpi=150)
    plt.close(fig)
    return rows


def closed_forms(records: list) -> None:
    from fdem.cases.planar_failure import GEOMETRIES, HEIGHT, UNIT_WEIGHT, analytic, planar_slope_geometry, property_sets

    for name, g in GEOMETRIES.items():
        st = statics(block_system(planar_slope_geometry(HEIGHT, **g)), UNIT_WEIGHT)
        r = factor_of_safety(st, strengths_from(property_sets()), rtol=1e-5)
        hb = analytic(**g).fos
        records.append(record(f"planar {name}: rigid-block FoS / Hoek-Bray - 1", r.fos / hb - 1, "-", mesh_size=2,
                              fos=r.fos, hoek_bray=hb, seconds=r.seconds, n_solves=len(r.trials)))
    # Goodman-Bray: a block b x h on a plane at psi with friction phi, over a grid
    n_ok = n_all = 0
    wrong = []
    for psi in (10.0, 20.0, 30.0, 40.0):
        for phi in (15.0, 25.0, 35.0, 45.0):
            for bh in (0.2, 0.4, 0.6, 0.8, 1.2):
                if abs(psi - phi) < 1 or abs(bh - math.tan(math.radians(psi))) < 0.02:
                    continue
                geo = Geometry([rectangle(0, 0, 8, 1, "base"), rectangle(2, 1, bh, 1.0, "block")])
                th = math.radians(psi)
                r = check_equilibrium(statics(block_system(geo), 26e3, (math.sin(th), -math.cos(th))),
                                      {CONTACT: Strength(0.0, phi, 0.0)})
                topple, slide = bh < math.tan(th), psi > phi
                # Goodman and Bray (1976): stable, sliding, toppling, or both (either mechanism is one)
                expect = {(False, False): {"stable"}, (True, False): {"sliding"}, (False, True): {"toppling"},
                          (True, True): {"sliding", "toppling"}}[(slide, topple)]
                got = "stable" if r.stable else r.mechanism.kind()
                n_all += 1
                n_ok += got in expect
                if got != expect:
                    wrong.append((psi, phi, bh, sorted(expect), got))
    records.append(record("Goodman-Bray regimes: rigid-block static answer right", n_ok, "cases", n_cases=n_all,
                          wrong=wrong))
    print(f"Goodman-Bray: {n_ok}/{n_all} right {wrong}")
    # Newmark: block on a 20 deg plane, phi 35, a 0.6 g one-sided sine pulse along the plane
    theta, phi = 20.0, 35.0
    t = np.linspace(0.0, 1.0, 401)
    a_base = -6.0 * np.sin(2 * math.pi * t) * (t < 0.5)
    _, d_ref, _ = newmark_response(t, a_base, theta, phi)
    geo = Geometry([rectangle(0, 0, 8, 1, "base"), rectangle(2, 1, 1.0, 1.0, "block")])
    bs = block_system(geo)
    th = math.radians(theta)
    g_hat = np.array([math.sin(th), -math.cos(th)])
    S = {CONTACT: Strength(0.0, phi, 0.0)}
    d, y = mechanism_newmark(statics(bs, 26e3, g_hat), S, t, np.column_stack([a_base, 0 * t]), direction=(1, 0))
    records.append(record("Newmark: pseudo-static yield acceleration / closed form - 1",
                          y.acceleration / newmark_yield(theta, phi)[0] - 1, "-"))
    records.append(record("Newmark: displacement of the rigid-block mechanism / closed form - 1", d / d_ref[-1] - 1,
                          "-", displacement_m=d, closed_form_m=float(d_ref[-1])))
    for dt in (2e-3, 1e-3, 5e-4):
        dyn = BlockDynamics(bs, 2650.0, S, gravity=G * g_hat,
                            base_acceleration=lambda tt: (float(np.interp(tt, t, a_base, right=0.0)), 0.0))
        h = dyn.run(1.2, dt, every=10 ** 6)
        i = bs.free[0]
        dd = float(h.x[-1][i, 0] - h.x[0][i, 0])
        records.append(record(f"Newmark: hard-block dynamics, dt {dt:g} s: displacement / closed form - 1",
                              dd / d_ref[-1] - 1, "-", displacement_m=dd, seconds=h.seconds, solves=h.solves,
                              steps=round(1.2 / dt)))


def incline_scene(theta, width, height):
    geo = Geometry([rectangle(0, 0, 8, 1, "base"), rectangle(2, 1, width, height, "block")])
    th = math.radians(theta)
    return block_system(geo), G * np.array([math.sin(th), -math.cos(th)])


def soft_vs_hard(records: list, quick: bool) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    k = 1e10   # Pa/m: a 1 m block on 1e10 Pa/m settles g rho h / k = 2.6 um
    scenes = [("block sliding, theta 30, phi 20", 30.0, 20.0, 1.0, 1.0, 0.4, 1e-3),
              ("block toppling, theta 30, phi 40, b/h 0.4", 30.0, 40.0, 0.4, 1.0, 0.3, 1e-3)]
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.2))
    for ax, (label, theta, phi, b, h, T, dt) in zip(axes, scenes):
        for contact in ("hard", "soft"):
            bs, g = incline_scene(theta, b, h)
            dyn = BlockDynamics(bs, 2650.0, {CONTACT: Strength(0.0, phi, 0.0)}, gravity=g, contact=contact,
                                k_n=k, k_t=k)
            hist = dyn.run(T, dt)
            t, x, th, _ = hist.arrays()
            i = bs.free[0]
            y = (x[:, i, 0] - x[0, i, 0]) if "sliding" in label else -th[:, i]
            ax.plot(t, y, "-" if contact == "hard" else "--", label=contact)
            records.append(record(f"{label}, {contact} contact: {'slide [m]' if 'sliding' in label else 'rotation [rad]'} "
                                  f"at {T:g} s", float(y[-1]), "m" if "sliding" in label else "rad", mesh_size=1,
                                  threads=1, steps=len(t) - 1, dt=dt, seconds=hist.seconds, solves=hist.solves,
                                  solves_per_step=hist.solves / (len(t) - 1), k_n=k if contact == "soft" else None,
                                  load_average=load()))
        ax.set_title(label, fontsize=8)
        ax.set_xlabel("t [s]")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("slide [m]")
    axes[1].set_ylabel("rotation [rad]")
    if not quick:
        sc = SCENES["demo"]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bs = block_system(sc.geometry(), merge_below=MERGE_BELOW)
        S = strengths_from(sc.properties())
        rho = sc.unit_weight / G
        fos = factor_of_safety(statics(bs, sc.unit_weight), S).fos
        for F in (0.9 * fos, 1.1 * fos):
            for contact in ("hard", "soft"):
                dyn = BlockDynamics(bs, rho, S, gravity=(0.0, -G), contact=contact, k_n=k, k_t=k, factor=F)
                hist = dyn.run(0.3, 2e-3)
                t, x, th, _ = hist.arrays()
                disp = np.linalg.norm(x - x[0], axis=2).max(axis=1)
                axes[2].plot(t, disp, "-" if contact == "hard" else "--", label=f"{contact}, F = {F:.2f}")
                records.append(record(f"demo slope blocks at F = {F:.3f} ({F / fos:.1f} x the rigid-block FoS), "
                                      f"{contact} contact: largest block displacement at 0.3 s", float(disp[-1]), "m",
                                      mesh_size=bs.n_blocks, threads=1, steps=len(t) - 1, dt=2e-3,
                                      seconds=hist.seconds, solves=hist.solves,
                                      solves_per_step=hist.solves / (len(t) - 1), load_average=load()))
                print(f"demo F {F:.3f} {contact}: {disp[-1]:.4g} m in {hist.seconds:.1f} s", flush=True)
        axes[2].set_title(f"demo slope, {bs.n_blocks} blocks, 0.9 and 1.1 x FoS", fontsize=8)
        axes[2].set_xlabel("t [s]")
        axes[2].set_ylabel("largest displacement [m]")
        axes[2].set_yscale("symlog", linthresh=1e-6)
        axes[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(PICTURES / "soft_vs_hard.png", dpi=150)
    plt.close(fig)


def newmark_demo(records: list) -> None:
    """The demo slope under a horizontal sine record (0.3 g, 2 Hz, 3 cycles): Newmark's
    one-degree-of-freedom displacement on the pseudo-static yield acceleration of the weakest
    mechanism, against the hard blocks stepped under the same base acceleration (Coulomb
    friction, every block free to move its own way)."""
    from fdem.cases.rigid_blocks import sine_record

    sc = SCENES["demo"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bs = block_system(sc.geometry(), merge_below=MERGE_BELOW)
    S = strengths_from(sc.properties())
    t, a = sine_record(0.3, 2.0, 3.0)
    d, y = mechanism_newmark(statics(bs, sc.unit_weight), S, t, a)
    dt = 2e-3
    dyn = BlockDynamics(bs, sc.unit_weight / G, S, gravity=(0.0, -G),
                        base_acceleration=lambda tt: (float(np.interp(tt, t, a, right=0.0)), 0.0))
    h = dyn.run(2.0, dt, every=100)
    dx = h.x[-1][:, 0] - h.x[0][:, 0]
    moved = np.abs(h.x[-1] - h.x[0]).max(axis=1) > 1e-3
    records.append(record("demo slope, 0.3 g 2 Hz 3 cycles: Newmark displacement on k_y of the weakest mechanism",
                          d, "m", mesh_size=bs.n_blocks, k_y=y.k_y, n_moving_pseudo_static=y.mechanism.n_moving))
    records.append(record("demo slope, 0.3 g 2 Hz 3 cycles: hard-block dynamics, largest permanent displacement "
                          "towards the face", float(-dx.min()), "m", mesh_size=bs.n_blocks, threads=1,
                          n_blocks_moved_over_1mm=int(moved.sum()), steps=round(2.0 / dt), dt=dt,
                          seconds=h.seconds, solves=h.solves, load_average=load()))


def ensemble_screen(records: list) -> None:
    table = ROOT / "docs" / "ensembles" / "realizations.csv"
    t0 = time.perf_counter()
    rows = screen_ensemble(table)
    wall = time.perf_counter() - t0
    err = np.array([r["rigid_fos"] / r["fdem_fos"] - 1 for r in rows])
    inside = sum(r["fdem_bracket"][0] - 0.005 <= r["rigid_fos"] <= r["fdem_bracket"][1] + 0.005 for r in rows)
    records.append(record("planar DFN ensemble screen: 20 rigid-block factors of safety", wall, "s", threads=1,
                          fdem_seconds=float(sum(r["fdem_seconds"] for r in rows)),
                          max_abs_relative_difference=float(np.abs(err).max()),
                          mean_relative_difference=float(err.mean()), n_within_fdem_bracket_pm_0_005=int(inside),
                          rows=rows, load_average=load()))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    PICTURES.mkdir(parents=True, exist_ok=True)
    records: list = []
    start_load = load()
    closed_forms(records)
    static_scenes(records)
    ensemble_screen(records)
    if not args.quick:
        bonded_scenes(records)
        spacing_sweep(records)
    soft_vs_hard(records, args.quick)
    if not args.quick:
        newmark_demo(records)
    save("rigid_blocks", records, load_average_start=start_load, load_average_end=load(),
         uptime=os.popen("uptime").read().strip(), note="2-core shared VM; Clarabel single-threaded")


if __name__ == "__main__":
    main()
