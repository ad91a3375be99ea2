"""Compression test: the uniaxial (or biaxial) strength and Young's modulus of an intact rock specimen.

A rectangle of width ``W`` and height ``2 W`` (plane strain, unit thickness), meshed at element
size ``h`` with crack elements on every interior edge (tag 0, the rock-bridge property set), is
squeezed between two frictionless platens: the bottom one is held (``v_y = 0``), the top one
moves down at ``v_platen`` (ramped up over the first tenth of the loading so that the start
sends no stress wave). With ``--confinement P`` both sides carry the pressure ``P`` and the test
starts from the static state under ``P`` on all four sides (``fdem.solve.geostatic``): a biaxial
test, ``sigma_3 = P``. The axial stress is the top platen's load over ``W``,

    sigma_1 = -(R_y + F_y) / W,   epsilon_1 = (platen approach) / H,

(``R`` the reaction of the prescribed velocities, ``F`` the dead load ``P W`` on the top edge),
the peak of ``sigma_1`` is the UCS (``P = 0``) or the biaxial strength, and Young's modulus is
the secant of ``sigma_1 - P`` against ``epsilon_1`` between 10 and 50 % of the peak deviator:
``E_2D = d sigma / d epsilon`` is the plane-strain modulus ``E / (1 - nu^2)``, reported with
the ``E`` it means.

What to expect (``docs/calibration.md``): the modulus lies between the Reuss bound of the
exploded mesh, ``1 / (1 / E_2D + S / p)`` with ``S = sum_e L_e^2 n_y^2 / A`` (every crack
element a spring ``p / L`` in series with the triangles), and ``E_2D``; the peak is set by the
crack law (``f_t``, ``c``, ``phi``) and the mesh fabric, bounded below by the Mohr-Coulomb
strength of the element law, ``UCS_MC = 2 c cos(phi) / (1 - sin(phi))``, and it scales
exactly with ``f_t`` and ``c`` when the fracture energies scale with their square.

    fdem run compression-test --out runs/ucs                            # 50 x 100 mm, h = 5 mm
    fdem run compression-test --confinement 5e6 --out runs/biaxial_5MPa
    fdem run compression-test --width 10 --size 1.0 --young 5.96e9 --poisson 0.15 --density 2560 \\
        --f-t 3.1e6 --cohesion 7.4e6 --phi 30 --g-i 400 --g-ii 4000 --out runs/ucs_muliashi

(``python cases/compression_test.py ...`` is the same.) Writes ``summary.json`` (peak, modulus,
bounds, broken elements by mode), ``stress_strain.csv``, ``stress_strain.png`` and
``failure_pattern.png``; ``--check-rate`` runs the test again at half the platen speed and
reports the change of the peak (the quasi-static check).
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

__all__ = ["NAME", "Specimen", "DEFAULTS", "check_specimen", "calibrate", "mohr_coulomb_ucs", "mohr_coulomb_strength",
           "reuss_modulus", "fabric_compliance", "specimen_mesh", "run", "secant_modulus", "parse_args", "main",
           "write_curve", "stress_strain_plot", "failure_plot", "MIN_DIVISIONS", "V_PLATEN_FRACTION"]

NAME = "compression-test"

DEFAULTS = dict(width=0.05, size=0.005, young=10e9, poisson=0.2, density=2700.0, f_t=5e6, cohesion=15e6, phi=30.0,
                g_i=20.0, g_ii=200.0, penalty_ratio=10.0, tangential_ratio=1.0, confinement=0.0, strength_cov=0.0,
                seed=1)
"""A generic hard rock at laboratory size: 50 x 100 mm, h = 5 mm (about 900 triangles)."""

MIN_DIVISIONS = 6
"""Fewest elements across the width ``W / h``: a shear band across the specimen needs several
edges to zig-zag through; coarser specimens measure the mesh, not the rock."""

V_PLATEN_FRACTION = 1e-4
"""Default platen speed as a fraction of the P-wave speed ``c_p = sqrt(E / rho)``: the platen
approach per wave transit of the specimen is then ``1e-4 H``, so a peak at 0.6 % strain takes
about 60 transits. Quasi-static (measured at the defaults, h = W/8): 2e-4, 1e-4, 5e-5, 2e-5 gave
peaks 53.22, 52.91, 52.71, 52.56 MPa; halving the speed from the default moves the peak by 0.4 %
(``docs/calibration.md``)."""


class Specimen(argparse.Namespace):
    """The test's inputs by name (the keys of :data:`DEFAULTS`), SI units: ``width`` [m],
    ``size`` [m], ``young`` [Pa], ``poisson`` [-], ``density`` [kg/m^3], ``f_t``, ``cohesion`` [Pa],
    ``phi`` [deg], ``g_i``, ``g_ii`` [J/m^2] (``None``: the snap-back-free rule at ``size``,
    :mod:`fdem.physics.calibration`), ``penalty_ratio`` (``p_n = ratio E``),
    ``tangential_ratio`` (``p_t = ratio p_n``), ``confinement`` [Pa, compression positive],
    ``strength_cov``: coefficient of variation of normally distributed element strengths (0: none;
    :class:`fdem.physics.heterogeneity.Heterogeneity`, drawn with ``seed``)."""

    def __init__(self, **kw):
        unknown = sorted(set(kw) - set(DEFAULTS))
        if unknown:
            raise TypeError(f"compression test: unknown input(s) {unknown}; known: {sorted(DEFAULTS)}")
        super().__init__(**{**DEFAULTS, **kw})

    @property
    def height(self) -> float:
        return 2.0 * self.width

    @property
    def penalty(self) -> float:
        return self.penalty_ratio * self.young

    @property
    def young_2d(self) -> float:
        """Plane-strain modulus of a uniaxial in-plane stress, ``E / (1 - nu^2)`` [Pa]."""
        return self.young / (1.0 - self.poisson ** 2)

    def energies(self) -> tuple[float, float]:
        """``(G_I, G_II)`` [J/m^2]: the given ones, or where ``None`` the snap-back-free rule at the
        element size (:class:`fdem.physics.calibration.SizeScaledEnergies`)."""
        from fdem.physics.calibration import SizeScaledEnergies

        rule = SizeScaledEnergies.rule(self.f_t, self.cohesion, self.penalty, self.tangential_ratio * self.penalty)
        g_i, g_ii = rule.at(self.size)
        return (g_i if self.g_i is None else self.g_i), (g_ii if self.g_ii is None else self.g_ii)

    def crack_properties(self):
        from fdem.physics.crack_properties import CrackProperties

        g_i, g_ii = self.energies()
        return CrackProperties(f_t=self.f_t, c=self.cohesion, phi=self.phi, G_I=g_i, G_II=g_ii,
                               p_n=self.penalty, p_t=self.tangential_ratio * self.penalty, name="rock bridges")


def mohr_coulomb_strength(c: float, phi: float, confinement: float = 0.0) -> float:
    """Mohr-Coulomb major principal stress at failure [Pa],
    ``sigma_1 = sigma_3 (1 + sin phi) / (1 - sin phi) + 2 c cos phi / (1 - sin phi)``
    (compression positive; ``phi`` in degrees; Jaeger, Cook & Zimmerman 2007, sec. 4.5). A tension
    cut-off does not enter while ``sigma_3 >= 0``."""
    s = math.sin(math.radians(phi))
    return confinement * (1 + s) / (1 - s) + 2 * c * math.cos(math.radians(phi)) / (1 - s)


def mohr_coulomb_ucs(c: float, phi: float) -> float:
    """``UCS_MC = 2 c cos(phi) / (1 - sin(phi))`` [Pa]: :func:`mohr_coulomb_strength` at ``sigma_3 = 0``."""
    return mohr_coulomb_strength(c, phi, 0.0)


def check_specimen(s: Specimen, v_platen: float | None = None) -> None:
    """A ``ValueError`` naming the first input the test cannot honour: a non-finite or
    non-positive size, modulus, density, strength or fracture energy; ``poisson`` outside
    [0, 0.5); ``phi`` outside [0, 90); a penalty ratio below 1; ``confinement`` negative or at
    least ``UCS_MC`` (the specimen would fail before the axial load); fewer than
    :data:`MIN_DIVISIONS` elements across the width; ``v_platen`` not positive or above 1 % of
    the P-wave speed (an impact, not a compression test). Snap-back of the crack law is checked
    when the crack set is built (:class:`fdem.physics.cracks.CrackSet`), before any step."""
    def finite(name, value, low=0.0, strict=True):
        ok = isinstance(value, (int, float)) and math.isfinite(value) and (value > low if strict else value >= low)
        if not ok:
            raise ValueError(f"compression test: {name} must be a finite number {'>' if strict else '>='} {low:g}, "
                             f"got {value!r}")

    for name in ("width", "size", "young", "density", "f_t"):
        finite(name, getattr(s, name))
    for name in ("cohesion", "confinement"):
        finite(name, getattr(s, name), strict=False)
    if s.g_i is not None:
        finite("g_i", s.g_i)
    if s.g_ii is not None:
        finite("g_ii", s.g_ii, strict=False)
    finite("penalty_ratio", s.penalty_ratio, 1.0, strict=False)
    finite("tangential_ratio", s.tangential_ratio)
    finite("strength_cov", s.strength_cov, strict=False)
    if s.strength_cov >= 0.5:
        raise ValueError(f"compression test: strength_cov must lie in [0, 0.5), got {s.strength_cov!r}")
    if not (isinstance(s.poisson, (int, float)) and 0.0 <= s.poisson < 0.5):
        raise ValueError(f"compression test: poisson must lie in [0, 0.5), got {s.poisson!r}")
    if not (isinstance(s.phi, (int, float)) and 0.0 <= s.phi < 90.0):
        raise ValueError(f"compression test: phi must lie in [0, 90) deg, got {s.phi!r}")
    if s.cohesion > 0 and s.g_ii is not None and s.g_ii <= 0:
        raise ValueError(f"compression test: g_ii must be positive when the cohesion is, got {s.g_ii!r}")
    if s.width / s.size < MIN_DIVISIONS * (1 - 1e-9):
        raise ValueError(f"compression test: element size {s.size:g} m is coarser than the largest allowed, "
                         f"{s.width / MIN_DIVISIONS:.4g} m (width / {MIN_DIVISIONS}): a shear band needs at least "
                         f"{MIN_DIVISIONS} elements across the {s.width:g} m specimen")
    ucs = mohr_coulomb_ucs(s.cohesion, s.phi)
    if s.confinement >= ucs:
        raise ValueError(f"compression test: confinement {s.confinement:g} Pa is not below the Mohr-Coulomb UCS "
                         f"of the crack law, {ucs:.4g} Pa: the specimen would fail under the confinement alone")
    if v_platen is not None:
        v_max = 0.01 * math.sqrt(s.young / s.density)
        if not (isinstance(v_platen, (int, float)) and math.isfinite(v_platen) and 0.0 < v_platen <= v_max):
            raise ValueError(f"compression test: v_platen must be a positive speed of at most {v_max:.3g} m/s (1 % of "
                             f"the P-wave speed: faster is an impact, not a compression test), got {v_platen!r} m/s")


def specimen_mesh(width: float, size: float, algorithm: str = "delaunay"):
    """The ``width x 2 width`` rectangle (lower-left corner at the origin) meshed at ``size`` [m].
    Gmsh "delaunay": irregular edge orientations, so that a shear band can form at any angle
    (a regular pattern offers cracks only its own directions, as on the Brazilian disc)."""
    from fdem.geometry.polygons import rectangle
    from fdem.geometry.section import Geometry
    from fdem.mesh.triangulate import mesh_geometry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return mesh_geometry(Geometry([rectangle(0.0, 0.0, width, 2.0 * width, name="specimen")]), size,
                             algorithm=algorithm)


def fabric_compliance(topology) -> float:
    """``S = sum_e L_e^2 n_y^2 / A`` [-] over the crack elements (``n`` the unit normal of edge
    ``e``, ``A`` the specimen area): with ``p_t = p_n = p`` the uniform stress ``sigma_yy``
    stores ``sigma^2 S / (2 p)`` per unit area in the crack elements (each end carries half the
    edge's traction through a spring ``p / 2``)."""
    x0 = topology.x0
    a, b = x0[topology.crack_nodes[:, 0]], x0[topology.crack_nodes[:, 1]]
    d = b - a
    L2 = np.einsum("ij,ij->i", d, d)
    ny2 = d[:, 0] ** 2 / np.maximum(L2, 1e-300)  # n = (-d_y, d_x) / L
    area = float(np.abs(topology.triangle_area0).sum())
    return float(np.sum(L2 * ny2) / area)


def reuss_modulus(young_2d: float, penalty: float, fabric: float, tangential_ratio: float = 1.0) -> float:
    """Lower bound [Pa] of the exploded mesh's uniaxial modulus, ``1 / (1 / E_2D + S / p)``.

    The uniform stress ``sigma_yy`` is statically admissible (every node in equilibrium with the
    frictionless platens), so by the principle of minimum complementary energy its compliance,
    that of the triangles ``1 / E_2D`` plus that of the crack elements ``S / p``
    (:func:`fabric_compliance`), bounds the assembly's from above. The continuous uniform strain
    (no jumps) is kinematically admissible: ``E_2D`` bounds it from below. ``tangential_ratio``
    other than 1 is not covered (the bound then uses the softer of the two penalties)."""
    p = penalty * min(1.0, tangential_ratio)
    return 1.0 / (1.0 / young_2d + fabric / p)


def secant_modulus(strain: np.ndarray, deviator: np.ndarray, low: float = 0.1, high: float = 0.5) -> float:
    """Least-squares slope [Pa] of the deviator against the axial strain over the first rise
    from ``low`` to ``high`` times the peak deviator (the elastic part)."""
    strain, deviator = np.asarray(strain, float), np.asarray(deviator, float)
    ipk = int(np.argmax(deviator))
    peak = deviator[ipk]
    sel = np.flatnonzero((deviator[:ipk + 1] >= low * peak) & (deviator[:ipk + 1] <= high * peak))
    if sel.size < 3:
        return float("nan")
    return float(np.polyfit(strain[sel], deviator[sel], 1)[0])


def run(spec: Specimen | None = None, v_platen: float | None = None, out_dir: Path | None = None,
        check_every: int = 40, progress: bool = False, max_time: float | None = None, drop: float = 0.7,
        contact: bool = True, algorithm: str = "delaunay") -> dict:
    """Load the specimen past its peak; return the curve, the peak and the modulus.

    ``v_platen`` [m/s]: top platen speed (default :data:`V_PLATEN_FRACTION` ``sqrt(E / rho)``).
    The run stops once the axial deviator has fallen below ``drop`` times its peak, or the
    strain has reached 5 times that of the Mohr-Coulomb strength on the Reuss modulus (a
    ductile specimen), or at ``max_time`` [s] simulated (a smoke run: ``time_capped``).
    ``contact``: hand broken faces to contact (friction ``phi``, penalty ``p_n``), so that a
    broken element in compression still carries its load; needed past the first breaks.
    Bad inputs raise a ``ValueError`` before meshing (:func:`check_specimen`)."""
    from fdem.mesh.topology import build_topology
    from fdem.physics.contact import ContactSet
    from fdem.physics.cracks import CrackSet
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.geostatic import geostatic_start
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    s = spec or Specimen()
    c_p = math.sqrt(s.young / s.density)
    v = V_PLATEN_FRACTION * c_p if v_platen is None else v_platen
    check_specimen(s, v)
    props = s.crack_properties()
    W, H, P = s.width, s.height, s.confinement
    topo = build_topology(specimen_mesh(W, s.size, algorithm))
    model = Model(topo, ElasticMaterial(young=s.young, poisson=s.poisson, density=s.density))
    model.set_element_damping()
    from fdem.physics.heterogeneity import Heterogeneity

    het = Heterogeneity("normal", cov=s.strength_cov, seed=int(s.seed), tags=(0,)) if s.strength_cov > 0 else None
    cracks = CrackSet(topo, {0: props}, heterogeneity=het)  # snap-back is refused here, before any step
    tol = 1e-6 * W
    x0 = topo.x0
    model.fix(lambda x, y: y < tol, x=False, y=True)
    mid = np.flatnonzero(np.abs(x0[:, 1]) < tol)
    centre = x0[mid[np.argmin(np.abs(x0[mid, 0] - W / 2))], 0]
    model.fix(lambda x, y: (y < tol) & (np.abs(x - centre) < tol), x=True, y=False)  # no rigid drift
    top_sel = lambda x, y: y > H - tol  # noqa: E731
    dead_top = 0.0
    if P > 0:
        # pressure P on the sides and the top as edge loads, P L / 2 at each end of a boundary edge
        e = topo.boundary_edges
        a, b = x0[e[:, 0]], x0[e[:, 1]]
        t = b - a
        normal = np.column_stack([t[:, 1], -t[:, 0]])  # outward for counter-clockwise edges, length L
        force = np.zeros_like(x0)
        loaded = ~((a[:, 1] < tol) & (b[:, 1] < tol))  # not the bottom platen
        for end in (0, 1):
            np.add.at(force, e[loaded, end], -0.5 * P * normal[loaded])
        model.external_force += force
        dead_top = float(force[topo.nodes_where(top_sel), 1].sum())
        geostatic_start(model, cracks)
    ramp = 0.1 * mohr_coulomb_ucs(s.cohesion, s.phi) / reuss_modulus(s.young_2d, s.penalty, 3.5) * H / v
    top = model.prescribe_velocity(top_sel, vx=None, vy=-v, history=lambda t: min(1.0, t / ramp))
    providers = [cracks]
    if contact:
        providers.append(ContactSet(topo, s.penalty, friction_angle=s.phi, mass=model.node_mass(), cracks=cracks))
    sim = Simulation(model, providers=providers, out_dir=out_dir, name="specimen", progress=progress)
    fabric = fabric_compliance(topo)
    e_reuss = reuss_modulus(s.young_2d, s.penalty, fabric, s.tangential_ratio)
    strain_cap = 5.0 * mohr_coulomb_strength(s.cohesion, s.phi, P) / e_reuss
    t0 = time.perf_counter()
    times, strain, sigma1 = [0.0], [0.0], [P]
    y_top0 = x0[top, 1].mean()
    peak_dev = 0.0
    capped = False
    while True:
        sim.run(n_steps=check_every, energy_tolerance=None, output_every=10**9, final_output=False)
        R = sim.reaction_force(top)
        sig = -(R[1] + dead_top) / W
        eps = (y_top0 - sim.state.x[top, 1].mean()) / H
        times.append(sim.state.time)
        strain.append(eps)
        sigma1.append(sig)
        peak_dev = max(peak_dev, sig - P)
        if peak_dev > 0 and sig - P < drop * peak_dev and eps > 0:
            break
        if eps > strain_cap:
            break
        if max_time is not None and sim.state.time >= max_time:
            capped = True
            break
    elapsed = time.perf_counter() - t0
    if out_dir is not None:
        sim.write_output()
    sim.close()
    strain, sigma1 = np.array(strain), np.array(sigma1)
    ipk = int(np.argmax(sigma1))
    e_2d = secant_modulus(strain, sigma1 - P)
    modes = cracks.failure_mode[cracks.broken]
    return {
        "width_m": W, "height_m": H, "element_size_m": s.size, "n_triangles": topo.n_triangles,
        "n_cracks": topo.n_cracks, "dt_s": sim.dt, "steps": sim.state.step, "seconds": elapsed,
        "v_platen_m_per_s": v, "confinement_Pa": P,
        "peak_stress_Pa": float(sigma1[ipk]), "peak_deviator_Pa": float(sigma1[ipk] - P),
        "strain_at_peak": float(strain[ipk]),
        "mohr_coulomb_strength_Pa": mohr_coulomb_strength(s.cohesion, s.phi, P),
        "peak_over_mohr_coulomb": float(sigma1[ipk] / mohr_coulomb_strength(s.cohesion, s.phi, P)),
        "modulus_2d_Pa": e_2d, "young_Pa": e_2d * (1 - s.poisson ** 2),
        "input_young_Pa": s.young, "input_young_2d_Pa": s.young_2d, "fabric_S": fabric,
        "reuss_modulus_2d_Pa": e_reuss, "modulus_over_reuss": e_2d / e_reuss,
        "n_broken": int(cracks.broken.sum()),
        "broken_by_mode": {m: int(np.sum(modes == k)) for k, m in ((1, "I"), (2, "II"), (3, "mixed"))},
        "simulated_time_s": sim.state.time, "time_capped": capped,
        "inputs": {k: getattr(s, k) for k in DEFAULTS}, "G_I_J_per_m2": props.G_I, "G_II_J_per_m2": props.G_II,
        "time_s": times, "strain": strain.tolist(), "sigma1_Pa": sigma1.tolist(),
        "_sim": sim, "_cracks": cracks,
    }


def calibrate(spec: Specimen, target: float, tol: float = 0.003, max_iter: int = 8, v_platen: float | None = None,
              progress: bool = False, cohesion0: float | None = None) -> tuple[Specimen, list[dict]]:
    """The cohesion that makes the test's peak ``target`` [Pa] within ``tol`` (relative), the
    other inputs kept; returns the calibrated :class:`Specimen` and the runs tried.

    Starts from the cohesion of Mohr-Coulomb, ``c_0 = (target - sigma_3 N) (1 - sin phi) /
    (2 cos phi)``, ``N = (1 + sin phi) / (1 - sin phi)``, corrected by the measured ratio, then
    by secant steps on ``c`` (the peak is close to linear in ``c`` while shear failure governs);
    ``cohesion0`` [Pa] replaces that start (a calibration at a neighbouring size).
    ``g_i = g_ii = None`` (the size rule) is advised: a fixed ``G_II`` may snap back at the
    larger ``c``. A ``ValueError`` when ``max_iter`` runs do not reach ``tol``."""
    if not (math.isfinite(target) and target > spec.confinement):
        raise ValueError(f"compression test: target peak must exceed the confinement {spec.confinement:g} Pa, got {target!r}")
    sphi = math.sin(math.radians(spec.phi))
    n_phi = (1 + sphi) / (1 - sphi)
    c = (target - spec.confinement * n_phi) * (1 - sphi) / (2 * math.cos(math.radians(spec.phi)))
    c = c if cohesion0 is None else cohesion0
    tried: list[dict] = []
    cs, peaks = [], []
    for _ in range(max_iter):
        trial = Specimen(**{**{k: getattr(spec, k) for k in DEFAULTS}, "cohesion": c})
        r = run(trial, v_platen, progress=progress)
        tried.append({"cohesion_Pa": c, "peak_stress_Pa": r["peak_stress_Pa"], "young_Pa": r["young_Pa"],
                      "G_I_J_per_m2": r["G_I_J_per_m2"], "G_II_J_per_m2": r["G_II_J_per_m2"], "steps": r["steps"]})
        cs.append(c)
        peaks.append(r["peak_stress_Pa"])
        if abs(peaks[-1] / target - 1) <= tol:
            return trial, tried
        if len(cs) == 1 or peaks[-1] == peaks[-2]:
            c = c * (target - spec.confinement) / (peaks[-1] - spec.confinement)
        else:
            slope = (peaks[-1] - peaks[-2]) / (cs[-1] - cs[-2])
            c = cs[-1] + (target - peaks[-1]) / slope if slope > 0 else c * target / peaks[-1]
    raise ValueError(f"compression test: {max_iter} runs did not bring the peak within {100 * tol:g} % of "
                     f"{target:g} Pa (last: c = {cs[-1]:.6g} Pa, peak {peaks[-1]:.6g} Pa)")


def _energy(text: str):
    """A fracture energy option: a number [J/m^2] or ``auto`` (the size rule)."""
    if text.strip().lower() == "auto":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of J/m^2 or 'auto', got {text!r}") from None


def _add_options(parser: argparse.ArgumentParser) -> None:
    d = DEFAULTS
    parser.add_argument("--width", type=float, default=d["width"], help=f"specimen width W [m]; height 2 W "
                                                                        f"(default {d['width']:g})")
    add_number_options(parser, d, (("--young", "young", "Pa", "Young's modulus E of the triangles"),
                                 ("--poisson", "poisson", "-", "Poisson's ratio"),
                                 ("--density", "density", "kg/m^3", "density"),
                                 ("--f-t", "f_t", "Pa", "tensile strength f_t of the crack elements"),
                                 ("--cohesion", "cohesion", "Pa", "cohesion c of the crack elements"),
                                 ("--phi", "phi", "deg", "friction angle of the crack elements"),
                                 ("--penalty-ratio", "penalty_ratio", "-", "normal penalty p_n / E"),
                                 ("--tangential-ratio", "tangential_ratio", "-", "tangential penalty p_t / p_n"),
                                 ("--confinement", "confinement", "Pa", "lateral pressure sigma_3 (0: uniaxial)"),
                                 ("--strength-cov", "strength_cov", "-",
                                  "coefficient of variation of normal element strengths (0: uniform)")))
    for opt, key, what in (("--g-i", "g_i", "mode-I"), ("--g-ii", "g_ii", "mode-II")):
        parser.add_argument(opt, type=_energy, default=d[key],
                            help=f"{what} fracture energy [J/m^2], or 'auto': the snap-back-free rule at the element "
                                 f"size, fdem.physics.calibration (default {d[key]:g})")
    parser.add_argument("--seed", type=int, default=d["seed"], help="seed of the strength draws (default 1)")
    parser.add_argument("--target-peak", type=float, default=None, metavar="PA",
                        help="calibrate: find the cohesion that gives this peak [Pa] (UCS, or the biaxial peak), "
                             "then report the test at it (use --g-i auto --g-ii auto)")
    parser.add_argument("--v-platen", type=float, default=None,
                        help=f"top platen speed [m/s] (default {V_PLATEN_FRACTION:g} sqrt(E / rho))")
    parser.add_argument("--check-rate", action="store_true",
                        help="run again at half the platen speed and report the change of the peak")
    parser.add_argument("--fields", action="store_true", help="write VTU frames (first and last) of the specimen")


def parse_args(argv=None) -> argparse.Namespace:
    """The options, every one checked before meshing (``parser.error``, exit status 2)."""
    parser = case_parser(__doc__, name=NAME, out="runs/compression_test", size=DEFAULTS["size"],
                         size_help=f"element size h [m] (default {DEFAULTS['size']:g}; at most width / {MIN_DIVISIONS})")
    _add_options(parser)
    args = parser.parse_args(argv)
    check_common(parser, args)
    args.spec = Specimen(**{k: getattr(args, k) for k in DEFAULTS})
    try:
        check_specimen(args.spec, args.v_platen)
        args.spec.crack_properties()
        if args.target_peak is not None and not (math.isfinite(args.target_peak) and args.target_peak > args.confinement):
            raise ValueError(f"--target-peak must be a number of Pa above the confinement, got {args.target_peak}")
    except ValueError as err:
        parser.error(str(err).replace("compression test: ", ""))
    from fdem.solve.cost import check_mesh_budget, estimate_triangles

    try:
        check_mesh_budget(estimate_triangles(2 * args.width ** 2, args.size))
    except ValueError as err:
        parser.error(f"--size {args.size:g} m: {err}")
    return args


def _public(r: dict) -> dict:
    return {k: v for k, v in r.items() if not k.startswith("_") and k not in ("time_s", "strain", "sigma1_Pa")}


def main(argv=None) -> dict:
    args = parse_args(argv)
    args = prepare_run(None, args, argv, NAME, open_now=False)
    open_run(None, args, NAME)
    set_threads(args.threads)
    out = args.out
    tried = None
    if args.target_peak is not None:
        try:
            args.spec, tried = calibrate(args.spec, args.target_peak, v_platen=args.v_platen)
        except ValueError as err:
            raise SystemExit(f"fdem run {NAME}: {err}")
        say(f"calibrated: c = {args.spec.cohesion / 1e6:.5g} MPa after {len(tried)} runs")
    r = run(args.spec, args.v_platen, out_dir=out / "fields" if args.fields else None, progress=not args.quiet,
            max_time=args.max_time)
    kind = "UCS" if args.spec.confinement == 0 else f"biaxial peak at sigma_3 = {args.spec.confinement / 1e6:g} MPa"
    print(f"{r['n_triangles']} triangles, h = {args.size:g} m: {kind} = {r['peak_stress_Pa'] / 1e6:.4g} MPa "
          f"({r['peak_over_mohr_coulomb']:.3f} x Mohr-Coulomb {r['mohr_coulomb_strength_Pa'] / 1e6:.4g} MPa); "
          f"E = {r['young_Pa'] / 1e9:.4g} GPa (input {args.spec.young / 1e9:.4g}; E_2D {r['modulus_2d_Pa'] / 1e9:.4g} "
          f"GPa = {r['modulus_over_reuss']:.3f} x the Reuss bound); {r['n_broken']} broken {r['broken_by_mode']}; "
          f"{r['steps']} steps, {r['seconds']:.1f} s"
          + (" (SMOKE RUN: stopped at --max-time before the peak was passed)" if r["time_capped"] else ""))
    summary = {"case": NAME, **_public(r)}
    if tried is not None:
        summary["calibration"] = {"target_peak_Pa": args.target_peak, "cohesion_Pa": args.spec.cohesion, "runs": tried}
    if args.check_rate:
        half = run(args.spec, r["v_platen_m_per_s"] / 2, max_time=None if args.max_time is None else 2 * args.max_time)
        change = half["peak_stress_Pa"] / r["peak_stress_Pa"] - 1
        summary["half_rate"] = {"v_platen_m_per_s": half["v_platen_m_per_s"], "peak_stress_Pa": half["peak_stress_Pa"],
                                "young_Pa": half["young_Pa"], "peak_change": change}
        print(f"half the platen speed: peak {half['peak_stress_Pa'] / 1e6:.4g} MPa ({100 * change:+.2f} %)")
    write_curve(out / "stress_strain.csv", r)
    written = [out / "summary.json", out / "stress_strain.csv"]
    if not args.no_pictures:
        written.append(stress_strain_plot(r, out / "stress_strain.png"))
        written.append(failure_plot(r, out / "failure_pattern.png"))
    write_json(out / "summary.json", summary, indent=1)
    say("wrote " + ", ".join(map(str, written)))
    finish_run(out, summary)
    return summary


def write_curve(path: Path, r: dict) -> Path:
    """``time_s, axial_strain, sigma1_Pa`` of a run, one row per check."""
    rows = np.column_stack([r["time_s"], r["strain"], r["sigma1_Pa"]])
    np.savetxt(path, rows, delimiter=",", header="time_s,axial_strain,sigma1_Pa", comments="", fmt="%.9g")
    return path


def stress_strain_plot(r: dict, path: Path) -> Path:
    """Axial stress [MPa] against axial strain [%], with the peak, the Mohr-Coulomb strength of
    the crack law and the line of the Reuss-bound modulus."""
    from fdem.io.pictures import new_figure, save_figure

    fig = new_figure((6.0, 4.2))
    ax = fig.add_subplot(111)
    eps = np.array(r["strain"]) * 100
    ax.plot(eps, np.array(r["sigma1_Pa"]) / 1e6, color="k", label="model")
    ax.axhline(r["mohr_coulomb_strength_Pa"] / 1e6, color="tab:red", ls="--",
               label=f"Mohr-Coulomb of the crack law, {r['mohr_coulomb_strength_Pa'] / 1e6:.3g} MPa")
    ax.plot(r["strain_at_peak"] * 100, r["peak_stress_Pa"] / 1e6, "o", color="tab:blue",
            label=f"peak {r['peak_stress_Pa'] / 1e6:.4g} MPa")
    e = np.linspace(0, r["strain_at_peak"], 2)
    ax.plot(e * 100, (r["confinement_Pa"] + r["reuss_modulus_2d_Pa"] * e) / 1e6, color="tab:green", ls=":",
            label=f"Reuss bound E_2D = {r['reuss_modulus_2d_Pa'] / 1e9:.3g} GPa")
    ax.set_xlabel("axial strain [%]")
    ax.set_ylabel("axial stress sigma_1 [MPa]")
    ax.set_title(f"W = {r['width_m']:g} m, h = {r['element_size_m']:g} m, sigma_3 = {r['confinement_Pa'] / 1e6:g} MPa")
    ax.legend(fontsize=8)
    return save_figure(fig, path, 150)


def failure_plot(r: dict, path: Path) -> Path:
    """The specimen at the end of the test: displacement magnitude, broken crack elements by mode."""
    from fdem.io.pictures import failure_frame

    sim, cracks = r["_sim"], r["_cracks"]
    x = sim.state.x
    u = np.linalg.norm(x - sim.model.topology.x0, axis=1)
    return failure_frame(path, x, sim.model.topology, u, crack_segments=sim.crack_geometry()["points"],
                         broken=cracks.broken, failure_mode=cracks.failure_mode,
                         title=f"broken crack elements at the end ({r['n_broken']})", figsize=(5.8, 8.0))


if __name__ == "__main__":
    main()
