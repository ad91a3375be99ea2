"""Direct shear test of a joint: peak and residual shear strength at several normal stresses, fitted c and phi.

Two blocks of length ``L`` and height ``L / 4`` each (plane strain, unit thickness) are cut by
one joint along their common face (crack elements of tag 1, the joint property set); the other
interior edges carry an intact set (tag 0) far stronger than the loads, so that only the joint
can fail. The lower block is held; the normal stress ``sigma_n`` is a dead load on the top edge,
the test starting from the static state under it (``fdem.solve.geostatic``); then every node of
the upper block is moved in x at ``v_shear`` (ramped up over the first tenth of the peak slip)
while it stays free in y. The slip is uniform along the joint, so that the joint elements fail
together and the test reads the law, not a progressive failure. The shear stress is the x
reaction of the upper block over ``L``,

    tau = R_x / L,   u = (x displacement of the upper block),

its peak before the first joint element breaks (``c + sigma_n tan(phi)`` of the crack law;
the handover of a broken element's preload to contact kicks ``tau`` for a few steps, which is
reported apart as ``max_tau_after_breaking_Pa``) and its residual (the mean over the last
fifth of the displacement: the broken joint's faces in contact with friction ``phi_res``,
``sigma_n tan(phi_res)``) at each ``sigma_n``; a least-squares line through the peaks gives
the fitted ``c`` and ``phi`` (the verification row: they must be the inputs).

    fdem run direct-shear --out runs/shear                                   # c = 200 kPa, phi = 30
    fdem run direct-shear --cohesion 149.33e3 --phi 12.35 --normal-stresses 0.25e6 0.5e6 1e6 \\
        --out runs/shear_muliashi

(``python cases/direct_shear.py ...`` is the same.) Writes ``summary.json`` (peaks, residuals,
fits), ``shear_curves.csv`` and ``shear_curves.png`` (shear stress against shear displacement,
one line per normal stress).
"""
from __future__ import annotations

from fdem.io.messages import say

import argparse
import math
import time
import warnings
from pathlib import Path

import numpy as np

from fdem.cases.common import (add_number_options, case_parser, check_common, finish_run, open_run, prepare_run,
                               set_threads)
from fdem.io.jsonable import write_json

__all__ = ["NAME", "Joint", "DEFAULTS", "NORMAL_STRESSES", "check_joint", "shear_box_mesh", "run", "run_series",
           "fit_mohr_coulomb", "parse_args", "main", "write_curves", "shear_plot", "MIN_DIVISIONS", "V_SHEAR_FRACTION",
           "ZBAR"]

NAME = "direct-shear"
ZBAR = 0.38631
"""Area under the Munjiza softening curve (:func:`fdem.physics.crack_properties.softening_integral`)."""

DEFAULTS = dict(length=0.1, size=0.005, young=10e9, poisson=0.2, density=2700.0, f_t=20e3, cohesion=200e3, phi=30.0,
                phi_res=None, g_i=20e3 * ZBAR * 1e-3, g_ii=200e3 * ZBAR * 1e-3, penalty_ratio=10.0,
                tangential_ratio=1.0)
"""A generic joint at laboratory size: 100 mm long, h = 5 mm; ``f_t = c / 10``; fracture
energies ``G = strength x Zbar x 1 mm`` (the cohesion lost over about 1 mm of slip)."""

NORMAL_STRESSES = (0.5e6, 1e6, 2e6)
"""Default normal stresses [Pa]."""

MIN_DIVISIONS = 8
"""Fewest elements along the joint ``L / h``."""

V_SHEAR_FRACTION = 1e-3
"""Default shear speed as a fraction of the P-wave speed ``sqrt(E / rho)``. The upper block's x
motion is prescribed at every node, so no wave has to cross it; the speed only needs to be slow
against the vertical response (measured: halving it moves the peaks by < 0.1 %,
``docs/calibration.md``)."""


class Joint(argparse.Namespace):
    """The test's inputs by name (the keys of :data:`DEFAULTS`), SI units: ``length`` [m],
    ``size`` [m], ``young`` [Pa], ``poisson``, ``density`` [kg/m^3]; the joint's ``f_t``,
    ``cohesion`` [Pa], ``phi``, ``phi_res`` [deg] (``None``: ``phi``), ``g_i``, ``g_ii`` [J/m^2],
    ``penalty_ratio`` (``p_n = ratio E``), ``tangential_ratio`` (``p_t = ratio p_n``)."""

    def __init__(self, **kw):
        unknown = sorted(set(kw) - set(DEFAULTS))
        if unknown:
            raise TypeError(f"direct shear: unknown input(s) {unknown}; known: {sorted(DEFAULTS)}")
        super().__init__(**{**DEFAULTS, **kw})

    @property
    def penalty(self) -> float:
        return self.penalty_ratio * self.young

    def joint_properties(self):
        from fdem.physics.crack_properties import CrackProperties

        return CrackProperties(f_t=self.f_t, c=self.cohesion, phi=self.phi, G_I=self.g_i, G_II=self.g_ii,
                               p_n=self.penalty, p_t=self.tangential_ratio * self.penalty, phi_res=self.phi_res,
                               name="joint")

    def block_properties(self, sigma_max: float):
        """Tag 0 inside the blocks: strengths 100 times the largest joint traction of the test and
        fracture energies twice the snap-back limit of the longest element, so nothing but the
        joint breaks."""
        from fdem.physics.crack_properties import CrackProperties

        s = 100.0 * (self.cohesion + self.f_t + sigma_max * (1 + math.tan(math.radians(self.phi))))
        k = self.penalty / (2.0 * self.size)  # softest element: about twice the target size
        return CrackProperties(f_t=s, c=s, phi=0.0, G_I=2 * s * s / (2 * k), G_II=4 * s * s / k, p_n=self.penalty,
                               name="intact blocks")


def check_joint(j: Joint, normal_stresses, v_shear: float | None = None) -> None:
    """A ``ValueError`` naming the first input the test cannot honour: a non-finite or non-positive
    size, modulus, density, strength or fracture energy; ``poisson`` outside [0, 0.5); ``phi`` or
    ``phi_res`` outside [0, 90); fewer than :data:`MIN_DIVISIONS` elements along the joint; no
    normal stress, or one not positive and finite; fewer than two distinct normal stresses (no
    line to fit); ``v_shear`` not positive or above 1 % of the P-wave speed. Snap-back of the
    joint law is checked when the crack set is built, before any step."""
    def finite(name, value, low=0.0, strict=True):
        ok = isinstance(value, (int, float)) and math.isfinite(value) and (value > low if strict else value >= low)
        if not ok:
            raise ValueError(f"direct shear: {name} must be a finite number {'>' if strict else '>='} {low:g}, "
                             f"got {value!r}")

    for name in ("length", "size", "young", "density", "f_t", "g_i", "tangential_ratio"):
        finite(name, getattr(j, name))
    for name in ("cohesion", "g_ii"):
        finite(name, getattr(j, name), strict=False)
    finite("penalty_ratio", j.penalty_ratio, 1.0, strict=False)
    if not (isinstance(j.poisson, (int, float)) and 0.0 <= j.poisson < 0.5):
        raise ValueError(f"direct shear: poisson must lie in [0, 0.5), got {j.poisson!r}")
    for name in ("phi", "phi_res"):
        v = getattr(j, name)
        if v is not None and not (isinstance(v, (int, float)) and 0.0 <= v < 90.0):
            raise ValueError(f"direct shear: {name} must lie in [0, 90) deg, got {v!r}")
    if j.length / j.size < MIN_DIVISIONS * (1 - 1e-9):
        raise ValueError(f"direct shear: element size {j.size:g} m is coarser than the largest allowed, "
                         f"{j.length / MIN_DIVISIONS:.4g} m (length / {MIN_DIVISIONS})")
    sig = list(normal_stresses)
    if not sig:
        raise ValueError("direct shear: give at least two normal stresses")
    for i, s in enumerate(sig):
        if not (isinstance(s, (int, float)) and math.isfinite(s) and s > 0):
            raise ValueError(f"direct shear: normal stress {i} must be a positive number of Pa, got {s!r}")
    if len(set(sig)) < 2:
        raise ValueError(f"direct shear: give at least two distinct normal stresses to fit c and phi, got {sig}")
    if v_shear is not None:
        v_max = 0.01 * math.sqrt(j.young / j.density)
        if not (isinstance(v_shear, (int, float)) and math.isfinite(v_shear) and 0.0 < v_shear <= v_max):
            raise ValueError(f"direct shear: v_shear must be a positive speed of at most {v_max:.3g} m/s (1 % of the "
                             f"P-wave speed), got {v_shear!r} m/s")


def shear_box_mesh(length: float, size: float, algorithm: str = "delaunay"):
    """Both blocks, ``[0, L] x [-L/4, L/4]``, with the joint along ``y = 0`` (joint set 1)."""
    from fdem.geometry.joint_sets import SegmentSet
    from fdem.geometry.polygons import rectangle
    from fdem.geometry.section import Geometry
    from fdem.mesh.triangulate import mesh_geometry

    joint = SegmentSet(np.array([[-0.1 * length, 0.0, 1.1 * length, 0.0]]), name="joint")
    geometry = Geometry([rectangle(0.0, -length / 4, length, length / 2, name="shear box")], [joint])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return mesh_geometry(geometry, size, algorithm=algorithm)


def _softening_slip(j: Joint) -> float:
    """Slip [m] over which the joint loses its cohesion, ``G_II / (c Zbar)`` (0 without cohesion)."""
    return j.g_ii / (j.cohesion * ZBAR) if j.cohesion > 0 else 0.0


def run(joint: Joint | None = None, sigma_n: float = 1e6, v_shear: float | None = None, check_every: int = 20,
        topology=None, displacement: float | None = None, max_time: float | None = None,
        progress: bool = False) -> dict:
    """Shear the joint under ``sigma_n`` [Pa]; return the curve, the peak and the residual.

    The upper block moves ``displacement`` [m] (default: the peak slip plus three times the
    cohesion's softening slip ``G_II / (c Zbar)``, at least 1 % of ``L``). ``topology``: a mesh
    built once for several normal stresses (:func:`run_series`)."""
    from fdem.mesh.topology import build_topology
    from fdem.physics.contact import ContactSet
    from fdem.physics.cracks import CrackSet
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.geostatic import geostatic_start
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    j = joint or Joint()
    v = V_SHEAR_FRACTION * math.sqrt(j.young / j.density) if v_shear is None else v_shear
    check_joint(j, [sigma_n, 2 * sigma_n], v)
    topo = topology if topology is not None else build_topology(shear_box_mesh(j.length, j.size))
    props = j.joint_properties()
    model = Model(topo, ElasticMaterial(young=j.young, poisson=j.poisson, density=j.density))
    model.set_element_damping()
    cracks = CrackSet(topo, {0: j.block_properties(sigma_n), 1: props})
    L = j.length
    centroid_y = model.centroids0[:, 1]
    lower = topo.triangles[centroid_y < 0].ravel()
    upper = topo.triangles[centroid_y > 0].ravel()
    model.fix(lower)
    # the normal stress as a dead load on the top edge, sigma_n L_e / 2 at each end of an edge
    x0 = topo.x0
    e = topo.boundary_edges
    a, b = x0[e[:, 0]], x0[e[:, 1]]
    on_top = (a[:, 1] > L / 4 * (1 - 1e-6)) & (b[:, 1] > L / 4 * (1 - 1e-6))
    for end in (0, 1):
        np.add.at(model.external_force[:, 1], e[on_top, end], -0.5 * sigma_n * np.abs(b[on_top, 0] - a[on_top, 0]))
    geostatic_start(model, cracks)
    k_t = props.stiffness(np.array([j.size]))[1][0]
    tau_peak = j.cohesion + sigma_n * props.tan_phi
    slip_peak = tau_peak / k_t
    u_end = displacement if displacement is not None else max(slip_peak + 3 * _softening_slip(j), 0.01 * L)
    ramp = 0.1 * slip_peak / v
    model.prescribe_velocity(upper, vx=v, history=lambda t: min(1.0, t / ramp))
    contact = ContactSet(topo, j.penalty, friction_angle=props.phi if j.phi_res is None else j.phi_res,
                         mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=progress)
    t0 = time.perf_counter()
    u, tau, opening = [0.0], [0.0], [0.0]
    joint = cracks.tag == 1
    n_intact = []  # joint elements not yet broken, per sample
    y_up0 = x0[upper, 1].mean()
    capped = False
    fine_until = slip_peak + 0.05 * _softening_slip(j)  # every step about the peak: it lies between checks
    while u[-1] < u_end:
        sim.run(n_steps=1 if u[-1] < fine_until else check_every, energy_tolerance=None, output_every=10**9,
                final_output=False)
        R = sim.reaction_force(upper)
        u.append(float((sim.state.x[upper, 0] - x0[upper, 0]).mean()))
        tau.append(float(R[0] / L))
        opening.append(float(sim.state.x[upper, 1].mean() - y_up0))
        n_intact.append(int(np.count_nonzero(joint & ~cracks.broken)))
        if max_time is not None and sim.state.time >= max_time:
            capped = True
            break
    elapsed = time.perf_counter() - t0
    sim.close()
    u, tau = np.array(u), np.array(tau)
    tail = u >= 0.8 * u[-1]
    # The peak is read before the first joint element breaks: a broken element's preload (the
    # static start's compression at zero separation) goes to contact, which needs an overlap to
    # carry it; the upper block drops into it and tau kicks for a few steps (measured: 811 kPa
    # against the law's 777 kPa at 1 MPa, generic joint), a handover transient, not strength.
    intact = np.concatenate([[True], np.array(n_intact) == np.count_nonzero(joint)])
    ipk = int(np.argmax(np.where(intact, tau, -np.inf)))
    broken_joint = cracks.broken & (cracks.tag == 1)
    return {
        "sigma_n_Pa": sigma_n, "peak_tau_Pa": float(tau[ipk]), "u_at_peak_m": float(u[ipk]),
        "max_tau_after_breaking_Pa": float(tau[~intact].max()) if (~intact).any() else None,
        "residual_tau_Pa": float(tau[tail].mean()), "expected_peak_Pa": tau_peak,
        "expected_residual_Pa": sigma_n * props.tan_phi_res,
        "joint_broken_fraction": float(broken_joint.sum() / max(1, np.count_nonzero(cracks.tag == 1))),
        "blocks_broken": int((cracks.broken & (cracks.tag == 0)).sum()),
        "n_triangles": topo.n_triangles, "steps": sim.state.step, "dt_s": sim.dt, "seconds": elapsed,
        "v_shear_m_per_s": v, "time_capped": capped,
        "u_m": u.tolist(), "tau_Pa": tau.tolist(), "normal_displacement_m": opening,
    }


def fit_mohr_coulomb(sigma_n, tau) -> tuple[float, float]:
    """Least-squares line ``tau = c + sigma_n tan(phi)``: returns ``(c [Pa], phi [deg])``."""
    slope, intercept = np.polyfit(np.asarray(sigma_n, float), np.asarray(tau, float), 1)
    return float(intercept), float(math.degrees(math.atan(slope)))


def run_series(joint: Joint | None = None, normal_stresses=NORMAL_STRESSES, v_shear: float | None = None,
               max_time: float | None = None, progress: bool = False) -> dict:
    """:func:`run` at each normal stress on one mesh, and the Mohr-Coulomb fits of the peaks and
    of the residuals."""
    from fdem.mesh.topology import build_topology

    j = joint or Joint()
    check_joint(j, normal_stresses, v_shear)
    topo = build_topology(shear_box_mesh(j.length, j.size))
    runs = [run(j, s, v_shear, topology=topo, max_time=max_time, progress=progress) for s in normal_stresses]
    c, phi = fit_mohr_coulomb(normal_stresses, [r["peak_tau_Pa"] for r in runs])
    c_res, phi_res = fit_mohr_coulomb(normal_stresses, [r["residual_tau_Pa"] for r in runs])
    return {"runs": runs, "fitted_c_Pa": c, "fitted_phi_deg": phi, "residual_c_Pa": c_res,
            "residual_phi_deg": phi_res, "input_c_Pa": j.cohesion, "input_phi_deg": j.phi,
            "input_phi_res_deg": j.phi if j.phi_res is None else j.phi_res,
            "inputs": {k: getattr(j, k) for k in DEFAULTS}}


def parse_args(argv=None) -> argparse.Namespace:
    """The options, every one checked before meshing (``parser.error``, exit status 2)."""
    d = DEFAULTS
    parser = case_parser(__doc__, name=NAME, out="runs/direct_shear", size=d["size"],
                         size_help=f"element size h [m] (default {d['size']:g}; at most length / {MIN_DIVISIONS})")
    parser.add_argument("--length", type=float, default=d["length"], help=f"joint length L [m] (default {d['length']:g})")
    add_number_options(parser, d, (("--young", "young", "Pa", "Young's modulus E of the blocks"),
                                 ("--poisson", "poisson", "-", "Poisson's ratio"),
                                 ("--density", "density", "kg/m^3", "density"),
                                 ("--f-t", "f_t", "Pa", "tensile strength f_t of the joint"),
                                 ("--cohesion", "cohesion", "Pa", "cohesion c of the joint"),
                                 ("--phi", "phi", "deg", "friction angle of the joint"),
                                 ("--g-i", "g_i", "J/m^2", "mode-I fracture energy G_I of the joint"),
                                 ("--g-ii", "g_ii", "J/m^2", "mode-II fracture energy G_II of the joint"),
                                 ("--penalty-ratio", "penalty_ratio", "-", "normal penalty p_n / E"),
                                 ("--tangential-ratio", "tangential_ratio", "-", "tangential penalty p_t / p_n")))
    parser.add_argument("--phi-res", type=float, default=None, help="residual friction angle [deg] (default --phi)")
    parser.add_argument("--normal-stresses", type=float, nargs="+", default=list(NORMAL_STRESSES), metavar="PA",
                        help="normal stresses [Pa], one test each (default 0.5e6 1e6 2e6)")
    parser.add_argument("--v-shear", type=float, default=None,
                        help=f"shear speed [m/s] (default {V_SHEAR_FRACTION:g} sqrt(E / rho))")
    args = parser.parse_args(argv)
    check_common(parser, args)
    args.joint = Joint(**{k: getattr(args, k) for k in DEFAULTS})
    try:
        check_joint(args.joint, args.normal_stresses, args.v_shear)
        args.joint.joint_properties()
    except ValueError as err:
        parser.error(str(err).replace("direct shear: ", ""))
    from fdem.solve.cost import check_mesh_budget, estimate_triangles

    try:
        check_mesh_budget(estimate_triangles(0.5 * args.length ** 2, args.size))
    except ValueError as err:
        parser.error(f"--size {args.size:g} m: {err}")
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    args = prepare_run(None, args, argv, NAME, open_now=False)
    open_run(None, args, NAME)
    set_threads(args.threads)
    out = args.out
    series = run_series(args.joint, args.normal_stresses, args.v_shear, max_time=args.max_time, progress=True)
    for r in series["runs"]:
        print(f"sigma_n = {r['sigma_n_Pa'] / 1e6:g} MPa: peak {r['peak_tau_Pa'] / 1e3:.4g} kPa (law "
              f"{r['expected_peak_Pa'] / 1e3:.4g}), residual {r['residual_tau_Pa'] / 1e3:.4g} kPa (law "
              f"{r['expected_residual_Pa'] / 1e3:.4g}); {r['steps']} steps, {r['seconds']:.1f} s"
              + (" (SMOKE RUN: stopped at --max-time)" if r["time_capped"] else ""))
    print(f"fitted peak: c = {series['fitted_c_Pa'] / 1e3:.4g} kPa, phi = {series['fitted_phi_deg']:.4g} deg (input "
          f"{args.joint.cohesion / 1e3:.4g} kPa, {args.joint.phi:.4g} deg); residual: c = "
          f"{series['residual_c_Pa'] / 1e3:.3g} kPa, phi = {series['residual_phi_deg']:.4g} deg")
    summary = {"case": NAME, **{k: v for k, v in series.items() if k != "runs"},
               "runs": [{k: v for k, v in r.items() if k not in ("u_m", "tau_Pa", "normal_displacement_m")}
                        for r in series["runs"]]}
    write_json(out / "summary.json", summary, indent=1)
    written = [out / "summary.json", write_curves(out / "shear_curves.csv", series)]
    if not args.no_pictures:
        written.append(shear_plot(series, out / "shear_curves.png"))
    say("wrote " + ", ".join(map(str, written)))
    finish_run(out, summary)
    return summary


def write_curves(path: Path, series: dict) -> Path:
    """``sigma_n_Pa, shear_displacement_m, tau_Pa, normal_displacement_m``, one block of rows per test."""
    rows = [np.column_stack([np.full(len(r["u_m"]), r["sigma_n_Pa"]), r["u_m"], r["tau_Pa"],
                             r["normal_displacement_m"]]) for r in series["runs"]]
    np.savetxt(path, np.vstack(rows), delimiter=",", header="sigma_n_Pa,shear_displacement_m,tau_Pa,"
               "normal_displacement_m", comments="", fmt="%.9g")
    return path


def shear_plot(series: dict, path: Path) -> Path:
    """Shear stress [kPa] against shear displacement [mm], one line per normal stress, with the
    law's peak ``c + sigma_n tan(phi)`` and residual ``sigma_n tan(phi_res)`` dashed."""
    from fdem.io.pictures import new_figure, save_figure

    fig = new_figure((6.5, 4.2))
    ax = fig.add_subplot(111)
    for r in series["runs"]:
        line, = ax.plot(np.array(r["u_m"]) * 1e3, np.array(r["tau_Pa"]) / 1e3,
                        label=f"sigma_n = {r['sigma_n_Pa'] / 1e6:g} MPa")
        ax.axhline(r["expected_peak_Pa"] / 1e3, color=line.get_color(), ls="--", lw=0.8)
        ax.axhline(r["expected_residual_Pa"] / 1e3, color=line.get_color(), ls=":", lw=0.8)
    ax.set_xlabel("shear displacement [mm]")
    ax.set_ylabel("shear stress tau [kPa]")
    ax.set_title(f"fitted c = {series['fitted_c_Pa'] / 1e3:.4g} kPa, phi = {series['fitted_phi_deg']:.4g} deg "
                 f"(input {series['input_c_Pa'] / 1e3:.4g} kPa, {series['input_phi_deg']:.4g} deg)", fontsize=9)
    ax.legend(fontsize=8)
    return save_figure(fig, path, 150)


if __name__ == "__main__":
    main()
