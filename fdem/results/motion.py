"""When each part of a failing slope moved: the locked part of the failed mass and the
mid-failure snapshot.

:class:`MotionRecord` is a history monitor (``Simulation.add_monitor``): at every history row it
compares each triangle's centroid with where it last *moved*, and books the row's time when the
centroid has travelled ``move_distance`` from there. At the end of a run this tells

* the **locked part** of the failed mass (:meth:`MotionRecord.locked`): triangles that moved more
  than ``threshold`` and then stopped while the rest of the mass ran on. A failed triangle is
  locked when, at the last row it moved, the failed mass's 90th area percentile of displacement
  ``D90`` was still below ``locked_share`` (one half) of its final value: it came to rest before
  the mass had run half its way, and it is joined to the mass that ran on through displaced
  triangles (the crack elements between them, broken or not). The paper's "kinematically
  locked" blocks of a wedge that jams against the toe while the blocks above it run out are such
  a part. A slab that slipped and stopped with unmoved rock between it and the running mass (a
  joint slipping beside a roller or a side band) took no part in the mechanism: it is counted
  apart (``stopped_apart_m2``), not as locked. Nor is ground *dragged* by the mass without
  moving with it (``dragged_m2``): a stopped triangle whose own displacement, when it last moved,
  was under ``with_mass_share`` (a half) of the mass's ``D90`` then. Behind the collapsing face
  of the high-angle coarse slope (its run with the damped steps, at t = 32.5 s) 159 m^2 of
  ground settled 0.1-1 m, 0.02-0.25 of the mass's D90 when it stopped (median 0.07; D90 then
  0.5-10 m), and was counted locked, 29 % of the failed mass, before this split. A block that
  jams in the mass has moved with it, its displacement near the mass's when it stops (1.0 in
  ``tests/unit/test_motion.py``); the half leaves a factor of two to the dragged ground;
* the **mid-failure state** (:meth:`MotionRecord.mid_failure`): positions and the crack elements'
  status (intact, activated, broken) kept each time ``D90`` grows by ``sqrt(2)``, so the one
  nearest half the final ``D90`` can be drawn after the run (the paper's Fig. 3 shows a slope
  mid-failure and at rest). Snapshots below a quarter of the present ``D90`` are dropped (they
  can no longer be the nearest to half the final one), so at most five are kept. The picture is
  of the failure the run ended in: when the reduction carries on after a runout (a creep or a
  block off the face that came to rest, :func:`fdem.workflow.slope._run_stages`), the snapshots
  start again from the state it carries on from, their ``D90`` measured from there, once a
  triangle has moved ``threshold`` since (until then, and in a run that stands to the end, the
  last failure's are kept; the locked part keeps the whole run's displacement). The high-angle
  coarse slope lost a 2.7 m^2 toe block at F = 1.43 (D90 9.1 m) and collapsed at F = 3.33 (D90
  15.3 m): measured from the start, the toe block's fall was the snapshot nearest half the
  collapse's D90.

``move_distance`` (default a quarter of ``threshold``, 2.5 cm) is a distance, not a speed: an
elastic ringing of millimetres never counts as motion, a block sliding at any speed re-anchors
within a row or a few. The time a triangle stopped is known to within the time it takes to
move ``move_distance``. Rows of factor-of-safety trials (stage names ``trial...``), which start
from a restored state, book no motion and take no snapshot. The record is saved with a
checkpoint (:meth:`state_dict`) and restored with it.
"""
from __future__ import annotations

import math

import numpy as np

from fdem.results.analysis import fragments, weighted_percentile

__all__ = ["MotionRecord", "INTACT", "ACTIVATED", "BROKEN", "ACTIVATED_OFFSET", "crack_status"]

INTACT, ACTIVATED, BROKEN = 0, 1, 2
"""Crack element status codes of a snapshot: intact, activated (past its elastic range and
slipped or opened visibly) but unbroken, broken."""

ACTIVATED_OFFSET = 1e-3
"""Slip or opening [m] above which an inelastic, unbroken element counts as activated in the
mechanism picture. An element that yielded by micrometres (the static start's over-strength
joints put on their envelope, or deep joints yielding a little as the strength is reduced) is
past its elastic range but takes no part in the mechanism: on the demo slope 334 of 390 joint
and rock elements are inelastic at the end, most of them under the floor, far from the slide."""


def crack_status(cracks, x: np.ndarray | None = None, min_offset: float = ACTIVATED_OFFSET) -> np.ndarray:
    """(n_cracks,) int8 status of a :class:`fdem.physics.cracks.CrackSet`'s elements in topology
    order: :data:`BROKEN`; :data:`ACTIVATED`, past the elastic range and, given the positions
    ``x`` [m], slipped or opened more than ``min_offset`` [m] (the element's geometric
    discontinuity: mean of its two ends, ``Simulation.crack_geometry``); else :data:`INTACT`."""
    status = np.zeros(len(cracks.broken), np.int8)
    active = np.zeros(len(status), bool)
    active[cracks.inelastic()] = True
    if x is not None:
        cn = cracks.nodes
        x = np.asarray(x, dtype=np.float64)
        t = 0.5 * (x[cn[:, 1]] + x[cn[:, 2]]) - 0.5 * (x[cn[:, 0]] + x[cn[:, 3]])
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
        gap = 0.5 * ((x[cn[:, 3]] - x[cn[:, 0]]) + (x[cn[:, 2]] - x[cn[:, 1]]))
        slip = np.abs((gap * t).sum(axis=1))
        opening = gap[:, 0] * t[:, 1] - gap[:, 1] * t[:, 0]
        active &= np.maximum(slip, opening) > min_offset
    status[active] = ACTIVATED
    status[np.asarray(cracks.broken, bool)] = BROKEN
    return status


class MotionRecord:
    """History monitor of the failed mass's motion (see the module docstring).

    Parameters
    ----------
    topology : the model's :class:`fdem.mesh.topology.Topology`
    cracks : the :class:`fdem.physics.cracks.CrackSet` whose status the snapshots keep (or None)
    threshold : displacement [m] above which a triangle belongs to the failed mass (0.1 m, as
        :func:`fdem.results.analysis.runout`)
    move_distance : travel [m] that counts as a move (default ``threshold / 4``)
    locked_share : a failed triangle is locked when it last moved while ``D90`` was below this
        share of its final value (default 0.5)
    with_mass_share : and when its own displacement then was at least this share of that ``D90``
        (default 0.5; below it the triangle was dragged, not carried)
    """

    LADDER = math.sqrt(2.0)

    def __init__(self, topology, cracks=None, threshold: float = 0.1, move_distance: float | None = None,
                 locked_share: float = 0.5, with_mass_share: float = 0.5):
        if not threshold > 0:
            raise ValueError(f"threshold must be > 0 m, got {threshold}")
        move_distance = threshold / 4.0 if move_distance is None else float(move_distance)
        if not move_distance > 0:
            raise ValueError(f"move_distance must be > 0 m, got {move_distance}")
        if not 0 < locked_share < 1:
            raise ValueError(f"locked_share must lie in (0, 1), got {locked_share}")
        if not 0 <= with_mass_share <= 1:
            raise ValueError(f"with_mass_share must lie in [0, 1], got {with_mass_share}")
        self.with_mass_share = float(with_mass_share)
        self.topology, self.cracks = topology, cracks
        self.threshold, self.move_distance, self.locked_share = float(threshold), move_distance, float(locked_share)
        self._tri = np.asarray(topology.triangles)
        self._area = np.asarray(topology.triangle_area0, dtype=np.float64)
        self._c0 = self._centroids(topology.x0)
        n = len(self._tri)
        self.anchor = None  # (n, 2) centroid where each triangle last moved; set at the first row
        self.moved_time = np.full(n, np.nan)  # time of that row [s]
        self.moved_d90 = np.full(n, np.nan)  # the failed mass's D90 then [m]
        self.since_step: int | None = None  # the row the record began at (a resume of an older run: later)
        self.snapshots: list[dict] = []
        self._next_level = self.threshold
        self.origin = self._c0  # centroids the snapshots' D90 is measured from: the state the present failure began at
        self.pending_origin = None  # the state the reduction carried on from, until something moves from it
        self.last_stage: str | None = ""  # the stage of the last row booked (trial rows are not); None: unknown

    def _centroids(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x)[self._tri].mean(axis=1)

    def d90(self, x: np.ndarray) -> float:
        """90th area percentile of the displacement of the triangles displaced more than
        ``threshold`` [m] (0 when none is), measured from :attr:`origin`: the start, or the state
        the reduction last carried on from after a runout (the present failure's ``D90``)."""
        return self._d90_from(self._centroids(x), self.origin)

    def _d90_from(self, c: np.ndarray, origin: np.ndarray) -> float:
        d = np.linalg.norm(c - origin, axis=1)
        failed = d > self.threshold
        return weighted_percentile(d[failed], self._area[failed], 90.0) if failed.any() else 0.0

    def __call__(self, sim) -> float:
        """Book the row: the monitor's value is the failed mass's ``D90`` [m]."""
        x = sim.state.x
        c = self._centroids(x)
        d = np.linalg.norm(c - self._c0, axis=1)
        failed = d > self.threshold
        d90 = weighted_percentile(d[failed], self._area[failed], 90.0) if failed.any() else 0.0
        stage = str(getattr(sim, "stage", ""))
        if stage.startswith("trial"):
            return d90  # a trial restarts from a restored state: its motion is not the run's
        if self.last_stage is None:  # loaded from a checkpoint that did not keep it: the row before this one's
            history = getattr(sim, "history", None)
            self.last_stage = str(history[-1].get("stage", "")) if history else ""
        if stage.startswith("reduction") and self.last_stage.startswith("runout"):
            # the reduction carries on after a runout that came to rest: a new failure, if any,
            # is measured and pictured from here, once it has moved
            self.pending_origin = c.copy()
        self.last_stage = stage
        if self.pending_origin is not None and self._d90_from(c, self.pending_origin) > 0.0:
            self.origin, self.pending_origin = self.pending_origin, None
            self.snapshots, self._next_level = [], self.threshold
        if self.anchor is None:
            self.anchor = c.copy()
            self.since_step = int(sim.state.step)
            return d90
        moved = np.linalg.norm(c - self.anchor, axis=1) > self.move_distance
        self.anchor[moved] = c[moved]
        self.moved_time[moved] = sim.state.time
        self.moved_d90[moved] = d90
        present = d90 if self.origin is self._c0 else self._d90_from(c, self.origin)
        if present >= self._next_level:
            self._snapshot(sim, present)
        return d90

    def _snapshot(self, sim, d90: float) -> None:
        status = crack_status(self.cracks, sim.state.x) if self.cracks is not None else np.zeros(0, np.int8)
        self.snapshots.append({"time": float(sim.state.time), "step": int(sim.state.step), "d90": float(d90),
                               "x": np.asarray(sim.state.x, np.float32).copy(), "status": status})
        while self._next_level <= d90:
            self._next_level *= self.LADDER
        self.snapshots = [s for s in self.snapshots if s["d90"] >= d90 / 4.0]

    # ------------------------------------------------------------------ results
    def mid_failure(self, final_d90: float) -> dict | None:
        """The snapshot whose ``D90`` is nearest (by ratio) half ``final_d90``, or None."""
        if not self.snapshots or not final_d90 > 0:
            return None
        return min(self.snapshots, key=lambda s: abs(math.log(s["d90"] / (0.5 * final_d90))))

    def locked(self, x: np.ndarray) -> dict:
        """The locked part of the failed mass at positions ``x`` (see the module docstring):
        ``mask`` (n_tri,) bool and the figures ``area_m2``, ``share_of_failed``, ``n_triangles``,
        ``mean_displacement_m``, ``stopped_s`` (first and last time one of them moved), the final
        ``d90_m`` and the ``criterion``; ``stopped_apart_m2`` and ``stopped_apart_triangles``:
        failed triangles that stopped as early but are not joined to the mass that ran on (not
        locked); ``dragged_m2`` and ``dragged_triangles``: failed triangles that stopped as early,
        having moved less than ``with_mass_share`` of the mass's D90 when they last moved (not
        locked). A mass whose D90 did not exceed twice ``threshold`` ran nowhere: nothing is
        locked."""
        d = np.linalg.norm(self._centroids(x) - self._c0, axis=1)
        failed = d > self.threshold
        final = weighted_percentile(d[failed], self._area[failed], 90.0) if failed.any() else 0.0
        stopped = failed & (self.moved_d90 < self.locked_share * final) if final > 2.0 * self.threshold \
            else np.zeros(len(d), bool)
        dragged = np.zeros(len(d), bool)
        if self.anchor is not None:  # its own displacement where it last moved, against the mass's D90 then
            own = np.linalg.norm(self.anchor - self._c0, axis=1)
            dragged = stopped & (own < self.with_mass_share * self.moved_d90)
        stopped &= ~dragged
        # the displaced triangles fall into bodies linked by crack elements with displaced
        # triangles on both sides; a stopped triangle is locked in a body that also ran on
        pairs = self.topology.crack_triangles
        _, body = fragments(self.topology, ~(failed[pairs[:, 0]] & failed[pairs[:, 1]]))
        joined = np.isin(body, body[failed & ~stopped & ~dragged])  # joined to triangles that ran on
        mask, apart = stopped & joined, stopped & ~joined
        area_failed = float(self._area[failed].sum())
        out = {"mask": mask, "n_triangles": int(mask.sum()), "area_m2": float(self._area[mask].sum()),
               "stopped_apart_m2": float(self._area[apart].sum()), "stopped_apart_triangles": int(apart.sum()),
               "dragged_m2": float(self._area[dragged].sum()), "dragged_triangles": int(dragged.sum()),
               "share_of_failed": float(self._area[mask].sum() / area_failed) if area_failed > 0 else 0.0,
               "failed_area_m2": area_failed, "d90_m": float(final),
               "mean_displacement_m": float(np.average(d[mask], weights=self._area[mask])) if mask.any() else 0.0,
               "stopped_s": ([float(np.nanmin(self.moved_time[mask])), float(np.nanmax(self.moved_time[mask]))]
                             if mask.any() else None),
               "since_step": self.since_step,
               "criterion": (f"displaced more than {self.threshold:g} m and last moved ({self.move_distance:g} m of "
                             f"travel) while the failed mass's D90 was below {self.locked_share:g} of its final "
                             f"{final:.3g} m, having moved at least {self.with_mass_share:g} of that D90 by then, "
                             f"joined to the mass that ran on through displaced triangles")}
        return out

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self) -> dict:
        return {"anchor": None if self.anchor is None else self.anchor.copy(), "moved_time": self.moved_time.copy(),
                "moved_d90": self.moved_d90.copy(), "since_step": self.since_step,
                "next_level": float(self._next_level), "snapshots": [dict(s) for s in self.snapshots],
                "origin": None if self.origin is self._c0 else self.origin.copy(), "last_stage": self.last_stage,
                "pending_origin": None if self.pending_origin is None else self.pending_origin.copy()}

    def load_state_dict(self, d: dict) -> None:
        n = len(self._tri)
        if np.shape(d["moved_time"]) != (n,):
            raise ValueError(f"motion record of {np.shape(d['moved_time'])} triangles, this model has {n}")
        self.anchor = None if d["anchor"] is None else np.array(d["anchor"], dtype=np.float64)
        self.moved_time = np.array(d["moved_time"], dtype=np.float64)
        self.moved_d90 = np.array(d["moved_d90"], dtype=np.float64)
        self.since_step = None if d["since_step"] is None else int(d["since_step"])
        self._next_level = float(d["next_level"])
        # a record saved before the origin was kept measured every failure from the start
        origin = d.get("origin")
        self.origin = self._c0 if origin is None else np.array(origin, dtype=np.float64)
        self.last_stage = d.get("last_stage")  # None: asked of the history at the next row
        pending = d.get("pending_origin")
        self.pending_origin = None if pending is None else np.array(pending, dtype=np.float64)
        self.snapshots = [{"time": float(s["time"]), "step": int(s["step"]), "d90": float(s["d90"]),
                           "x": np.asarray(s["x"], np.float32), "status": np.asarray(s["status"], np.int8)}
                          for s in d["snapshots"]]
