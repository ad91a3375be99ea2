"""What a slope run reports: ``summary.json``, time series, the event catalogue and pictures.

:class:`RunReport` watches a running :class:`~fdem.solve.simulation.Simulation` through monitors (one
value per history row: cracks broken by mode, fragments) and, at the end, writes

* ``summary.json``: stages, factor of safety, runout distance and volume, displacement
  percentiles, peak and released kinetic energy, cracks by mode and by tag (intact rock against
  joints: activated and broken), the locked part of the failed mass
  (:mod:`fdem.results.motion`), fragments and their sizes,
  micro-seismic event statistics, the ledger error;
* ``events.csv``: the micro-seismic catalogue (:func:`fdem.results.events.cluster_events`; a
  "no events" line when nothing broke);
* ``kinetic_energy.png``, ``cracks_by_mode.png``, ``magnitudes.png`` (when there are events),
  ``fragments.png``, ``failure.png`` (displacement on the deformed mesh over the outline before
  failure, intact joints thin, broken crack elements by mode, displacement arrows,
  :func:`fdem.io.pictures.failure_frame`), ``mechanism.png`` (the paper's Fig. 3: activated and
  broken crack elements in black at mid-failure and at the end, the locked part of the failed
  mass outlined, :meth:`RunReport.mechanism_picture`), ``crack_times.png`` (broken elements by time of
  breakage), ``geostatic_stress.png`` (sigma_yy against the overburden weight ``rho g d`` at the
  end of the equilibrium stage, or at the start of a run that began from a geostatic start) and
  ``failure.gif`` (the run's ``.pvd`` frames animated, :mod:`fdem.io.animation`).

The definitions (runout distance as the 99th area percentile of the reach beyond the toe,
fragments, events) are in ``docs/outputs.md``; the pictures in ``docs/pictures.md``.
"""
from __future__ import annotations

from fdem.io.jsonable import jsonable, write_json
import math
from pathlib import Path
import numpy as np
from fdem.results import analysis, events, overburden
from fdem.results.motion import MotionRecord, crack_status
from fdem.io import animation, pictures
from fdem.solve.simulation import Simulation

__all__ = ["EQUILIBRIUM_STAGES", "RunReport", "fixed_body_triangles", "output_cost"]


EQUILIBRIUM_STAGES = ("equilibrium", "geostatic")
"""Stage names whose last state is the geostatic state the stress map shows."""


def fixed_body_triangles(model) -> np.ndarray:
    """(n_tri,) bool: the triangles of bodies (``topology.triangle_body``) whose every node is
    fixed in x and y, e.g. a rigid wall the debris meets. They are supports, not rock: the
    fragment counts leave them out."""
    from fdem.solve.model import FIX_X, FIX_Y

    topo = model.topology
    body = np.asarray(topo.triangle_body)
    fixed_node = (model.flags & (FIX_X | FIX_Y)) == (FIX_X | FIX_Y)
    free_body = np.zeros(int(body.max(initial=-1)) + 1, bool)
    np.logical_or.at(free_body, body, ~fixed_node[topo.triangles].all(axis=1))
    return ~free_body[body]


def output_cost(workflow: dict) -> dict:
    """What a workflow's stages (and factor-of-safety trials) spent on output frames, history
    rows and checkpoints, against their wall time: ``seconds`` by kind, ``wall_seconds`` and
    ``share`` (the output's fraction of the wall time; None before any stage)."""
    stages = list(workflow.get("stages") or []) + list((workflow.get("fos") or {}).get("trials") or [])
    seconds = {"frames": 0.0, "history": 0.0, "checkpoints": 0.0}
    wall = 0.0
    for st in stages:
        wall += float(st.get("wall_seconds") or 0.0)
        for k, v in (st.get("output_seconds") or {}).items():
            seconds[k] = seconds.get(k, 0.0) + float(v)
    return {"seconds": seconds, "wall_seconds": wall, "share": sum(seconds.values()) / wall if wall > 0 else None}


class RunReport:
    """Collect and write what a slope run reports.

    Parameters
    ----------
    sim : the simulation (with a crack set among its providers)
    toe_x : x of the slope toe [m] (runout is measured beyond it, toward ``toward``)
    toward : -1 if the slope faces -x (toe on the left, the project's convention), +1 otherwise
    floor_y : y of the floor in front of the toe [m] (deposit profile)
    threshold : displacement [m] above which a triangle counts as displaced (default 0.1 m)
    stress_drop : stress drop [Pa] of the micro-seismic moment (default: the mean tensile
        strength of the crack property sets, the traction a breaking element releases)
    fragments_every : monitor the fragment count on every history row (connected components
        of the still-bonded triangles; about 50 ms at 1e5 triangles)
    reference_events : magnitude statistics of a reference catalogue to compare with
        (e.g. :data:`fdem.results.events.MULIASHI` for that scene), or ``None``: no comparison
    """

    def __init__(self, sim: Simulation, toe_x: float, toward: float = -1.0, floor_y: float | None = None,
                 threshold: float = 0.1, stress_drop: float | None = None, fragments_every: bool = True,
                 reference_events: dict | None = None):
        self.sim = sim
        self.cracks = sim.cracks
        if self.cracks is None:
            raise ValueError("RunReport needs a simulation with crack elements")
        if not math.isfinite(toe_x):
            raise ValueError(f"toe_x must be finite, got {toe_x}")
        self.toe_x, self.toward, self.threshold = float(toe_x), float(toward), float(threshold)
        self.floor_y = floor_y
        self.reference_events = reference_events
        self.fixed = fixed_body_triangles(sim.model)  # a fixed wall is no fragment
        if stress_drop is None:  # the sets that can break: an elastic side band's never does
            from fdem.physics.side_bands import can_break

            stress_drop = float(np.mean([p.f_t for p in self.cracks.property_sets.values() if can_break(p)]))
        self.stress_drop = float(stress_drop)
        topo = sim.model.topology
        cracks = self.cracks
        sim.add_monitor("broken_I", lambda s: float(np.count_nonzero(cracks.failure_mode == 1)))
        sim.add_monitor("broken_II", lambda s: float(np.count_nonzero(cracks.failure_mode == 2)))
        sim.add_monitor("broken_mixed", lambda s: float(np.count_nonzero(cracks.failure_mode == 3)))
        # the state the stress map shows: the start, when it is a geostatic start (an initial
        # stress), replaced by the last state of an equilibrium stage when the run has one
        self._geostatic = ((sim.state.copy(), float(np.linalg.norm(sim.gravity)), "start state (geostatic start)")
                           if np.any(sim.model.initial_stress != 0.0) and sim.state.step == 0 else None)
        self._latest = None

        def inelastic(s):
            # a monitor is the report's one view of the run while it runs: this one also keeps
            # the state of every history row, and the previous row's when that was the last of
            # an equilibrium stage (history[-1] is the row before the one being written)
            prev = s.history[-1]["stage"] if s.history else None
            if prev in EQUILIBRIUM_STAGES and self._latest is not None:
                self._geostatic = self._latest + (f"end of the {prev} stage, t = {self._latest[0].time:.3g} s",)
            self._latest = (s.state.copy(), float(np.linalg.norm(s.gravity)))
            return float(cracks.n_inelastic())

        sim.add_monitor("inelastic", inelastic)
        # when each triangle last moved: the locked part of the failed mass, and the
        # mid-failure state of the mechanism picture; the column is the failed mass's D90 [m]
        self.motion = MotionRecord(topo, cracks, threshold=self.threshold)
        sim.add_monitor("failed_d90", self.motion)
        if fragments_every:
            self._frag_cache = (-1, 0)

            def n_fragments(s):
                n_broken = int(cracks.broken.sum())
                if n_broken != self._frag_cache[0]:  # recount only when something broke
                    n = analysis.fragment_statistics(topo, cracks.broken, exclude=self.fixed)["n_fragments"]
                    self._frag_cache = (n_broken, n)
                return float(self._frag_cache[1])

            sim.add_monitor("fragments", n_fragments)

    # ------------------------------------------------------------------ writing
    def catalogue(self) -> events.EventCatalogue:
        model = self.sim.model
        _, mu = model.lame_arrays()
        return events.cluster_events(self.cracks.events, shear_modulus=float(np.mean(mu)),
                                     stress_drop=self.stress_drop,
                                     density=float(np.mean(model.property_array("density"))))

    def summary(self, extra: dict | None = None) -> dict:
        """The figures of the run so far (a JSON-able dict)."""
        sim, topo, cracks = self.sim, self.sim.model.topology, self.cracks
        x = sim.state.x
        run = analysis.runout(topo, x, self.toe_x, threshold=self.threshold, toward=self.toward)
        frag = analysis.fragment_statistics(topo, cracks.broken, exclude=self.fixed)
        hist = sim.history
        peak = max((max(r.get("kinetic_peak", 0.0), r.get("kinetic", 0.0)) for r in hist), default=0.0)
        cat = self.catalogue()
        mags = cat.magnitudes if not cat.empty else np.zeros(0)
        modes = cracks.events["mode"] if len(cracks.events) else np.array([])
        out = {
            "simulated_time_s": sim.state.time, "steps": sim.state.step, "dt_s": sim.dt,
            "n_triangles": topo.n_triangles, "n_crack_elements": topo.n_cracks,
            "runout": run,
            "displaced_area_m2": analysis.displaced_areas(topo, x),
            "displacement": analysis.displacement_statistics(topo, x),
            "boundaries": analysis.boundary_motion(topo.x0, x),
            "kinetic_energy": {"peak_J_per_m": peak,
                               "final_J_per_m": float(hist[-1]["kinetic"]) if hist else 0.0,
                               "released_gravity_J_per_m": float(-hist[-1]["gravity_potential"]) if hist else 0.0,
                               "fracture_J_per_m": float(hist[-1].get("fracture", 0.0)) if hist else 0.0},
            "cracks": {"broken": int(cracks.broken.sum()), "inelastic": int(cracks.n_inelastic()),
                       "by_mode": {m: int((modes == m).sum()) for m in ("I", "II", "mixed")}},
            "cracks_by_tag": analysis.crack_breakdown(topo.crack_tag, crack_status(cracks, x) > 0, cracks.broken,
                                                      cracks.failure_mode),
            "locked": {k: v for k, v in self.motion.locked(x).items() if k != "mask"},
            "mid_failure": self._mid_failure_figures(),
            "fragments": {k: frag[k] for k in ("n_fragments", "n_single_triangles", "n_blocks", "largest_share")},
            "events": cat.summary() if not cat.empty else {"n_events": 0, "note": "no events: nothing broke"},
            "magnitudes": (None if mags.size < 2 else events.magnitude_statistics(mags)
                           if self.reference_events is None
                           else events.compare_with_reference(mags, self.reference_events)),
            "ledger_error_relative": float(hist[-1]["balance_error_relative"]) if hist else 0.0,
        }
        off = run["off_model_area_m2"]
        if off > 0.0 and off < 0.01 * run["displaced_area_m2"]:  # fly-rock, held beyond the floor's end
            out["caveats"] = [f"{off:.3g} m^2 of fragments ran off the end of the model, beyond its initial x range "
                              f"(fly-rock, under 1 % of the displaced area): the front distance is a lower bound, "
                              f"the runout distance (99th percentile by area) is not"]
        elif off > 0.0:  # the floor ended under the debris: the distance is cut
            out["caveats"] = [f"{off:.3g} m^2 of the failed mass ran off the end of the model, "
                              f"beyond its initial x range: the runout distance is a lower bound; lengthen the "
                              f"floor in front of the toe"]
        if extra:
            out.update(extra)
            if isinstance(extra.get("workflow"), dict):
                out["output_cost"] = output_cost(extra["workflow"])
        return jsonable(out)

    def _mid_failure_figures(self) -> dict | None:
        snap = self.motion.mid_failure(self.motion.d90(self.sim.state.x))
        return None if snap is None else {"time_s": snap["time"], "step": snap["step"], "d90_m": snap["d90"]}

    def mechanism_picture(self, path) -> Path:
        """``mechanism.png``: displacement with the activated and broken crack elements in black
        at mid-failure (when the run has a snapshot of it) and at the end, the locked part of the
        failed mass outlined (:func:`fdem.io.pictures.mechanism_frames`)."""
        sim, topo = self.sim, self.sim.model.topology
        x = sim.state.x
        final = self.motion.d90(x)
        locked = self.motion.locked(x)
        panels = []
        snap = self.motion.mid_failure(final)
        if snap is not None and snap["d90"] < final:
            xs = np.asarray(snap["x"], np.float64)
            panels.append({"x": xs, "displacement": analysis.triangle_displacement(topo, xs), "status": snap["status"],
                           "title": f"mid-failure, t = {snap['time']:.3g} s: the failed mass's D90 "
                                    f"{snap['d90']:.3g} m of its final {final:.3g} m"})
        panels.append({"x": x, "displacement": analysis.triangle_displacement(topo, x), "status": crack_status(self.cracks, x),
                       "title": (f"end of the run, t = {sim.state.time:.3g} s"
                                 + (f"; locked part {locked['area_m2']:.3g} m$^2$ "
                                    f"({100 * locked['share_of_failed']:.0f} % of the failed mass)"
                                    if locked["n_triangles"] else ""))})
        return pictures.mechanism_frames(path, topo.triangles, topo.crack_nodes, panels, joint=topo.crack_tag > 0,
                                         outline=pictures.boundary_segments(topo.x0, topo.boundary_edges),
                                         locked=locked["mask"] if locked["n_triangles"] else None,
                                         crack_triangles=topo.crack_triangles)

    def write(self, out_dir, extra: dict | None = None, pictures_on: bool = True) -> dict:
        """Write ``summary.json``, ``events.csv`` and (``pictures_on``) the PNG plots into ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        summary = self.summary(extra)
        write_json(out / "summary.json", summary)
        cat = self.catalogue()
        events.write_catalogue_csv(out / "events.csv", cat)
        if pictures_on:
            self.pictures(out, cat)
        return summary

    def geostatic_state(self):
        """``(state, g [m/s^2], label)`` of the geostatic state the run went through, or None:
        the last state of its equilibrium stage, else its start when that was a geostatic start."""
        hist = self.sim.history
        if hist and hist[-1]["stage"] in EQUILIBRIUM_STAGES and self._latest is not None:
            st = self._latest[0]  # the run ended in its equilibrium stage
            return self._latest + (f"end of the {hist[-1]['stage']} stage, t = {st.time:.3g} s",)
        return self._geostatic

    def pictures(self, out: Path, cat=None, animate: bool = True) -> list[Path]:
        """Write the PNG pictures (and, ``animate`` with frames on disk, ``failure.gif``) into
        ``out``; returns their paths."""
        sim, topo, cracks = self.sim, self.sim.model.topology, self.cracks
        written = []
        t, kin = analysis.history_columns(sim.history, "time", "kinetic_peak")
        if t.size:
            stage = np.array([r["stage"] for r in sim.history])
            written.append(pictures.kinetic_energy_plot(out / "kinetic_energy.png", t, kin, stage=stage))
        ev = cracks.events
        written.append(pictures.crack_count_plot(out / "cracks_by_mode.png", ev["time"] if len(ev) else np.zeros(0),
                                                 ev["mode"] if len(ev) else np.zeros(0, "U5"), t_end=sim.state.time))
        cat = cat if cat is not None else self.catalogue()
        if not cat.empty and len(cat.events) >= 2:
            written.append(events.magnitude_plot(out / "magnitudes.png", cat.magnitudes,
                                                   reference=self.reference_events))
        frag = analysis.fragment_statistics(topo, cracks.broken, exclude=self.fixed)
        if len(frag["areas"]):
            t_f, n_f = (analysis.history_columns(sim.history, "time", "fragments")
                        if sim.history and "fragments" in sim.history[0] else (None, None))
            written.append(pictures.fragment_size_plot(out / "fragments.png", frag["areas"], time=t_f, count=n_f,
                                                       stage=stage if t.size else None))
        outline = pictures.boundary_segments(topo.x0, topo.boundary_edges)
        joint = topo.crack_tag > 0
        g = sim.crack_geometry()
        disp = sim.state.x - sim.x0
        written.append(pictures.failure_frame(out / "failure.png", sim.state.x, topo.triangles,
                                              np.linalg.norm(disp, axis=1), g["points"], cracks.broken,
                                              cracks.failure_mode, outline=outline, joint=joint, vectors=disp,
                                              title=f"t = {sim.state.time:.3g} s: displacement and crack elements"))
        written.append(self.mechanism_picture(out / "mechanism.png"))
        if len(ev):
            written.append(pictures.crack_time_map(out / "crack_times.png", topo.x0, topo.triangles,
                                                   topo.x0[topo.crack_nodes[:, :2]],
                                                   ev["element"], ev["time"], outline=outline,
                                                   title=f"{len(np.unique(ev['element']))} crack elements by time "
                                                         "of breakage (reference positions)"))
        geo = self.geostatic_state()
        if geo is not None:
            st, gravity, label = geo
            if gravity > 0:
                centroids = topo.x0[topo.triangles].mean(axis=1)
                depth = overburden.depth_below_surface(centroids, outline)
                syy = sim.stresses(st)["yy"]
                # the top row of triangles sits a third of its height below the surface: no
                # meaningful ratio there
                h = np.sqrt(2.0 * np.median(topo.triangle_area0))
                ratio = overburden.lithostatic_ratio(syy, sim.model.property_array("density"), gravity, depth,
                                                     min_depth=h)
                written.append(pictures.geostatic_stress_map(out / "geostatic_stress.png", st.x, topo.triangles,
                                                             syy, ratio, outline=outline,
                                                             title=f"geostatic state ({label})"))
        names = list(getattr(sim, "point_monitors", {}))
        if names and sim.history:  # the point histories of the scene's [[monitors]] (or add_point_monitor)
            from fdem.io.monitor_plots import monitor_plot

            written.append(monitor_plot(out / "monitors.png", sim.history, names))
        if animate and sim.out_dir is not None:
            pvd = sim.out_dir / f"{sim.name}.pvd"
            crack_pvd = sim.out_dir / f"{sim.name}_cracks.pvd"
            if pvd.exists():
                written.append(animation.animate_series(out / "failure.gif", pvd,
                                                        crack_pvd if crack_pvd.exists() else None, events=ev,
                                                        outline=outline, joint=joint, title="displacement"))
        return written
