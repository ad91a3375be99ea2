"""What the pictures show, checked on their arrays and artists rather than their pixels: stage labels
that never overlap, a unit on every axis, the geostatic stress map's ratio on a gravity column
(exactly the weight of the rock above), the overburden depth against closed forms, cracks
coloured by their event times, and an animation with the frames it should have."""
import re

import numpy as np
import pytest

from fdem.io.animation import animate_series, pick_frames
from fdem.io.pictures import (arrow_sample, boundary_segments, crack_count_plot, crack_segments_at, crack_time_map,
                              failure_frame, mechanism_frames,
                              fragment_size_plot, geostatic_stress_map, group_label, group_stages, kinetic_energy_plot,
                              stage_label_rows,
                              stage_spans, trial_histories_plot)
from fdem.io.vtk import PvdSeries, VTK_LINE, VTK_TRIANGLE, read_pvd
from fdem.mesh.mesh import structured_rectangle
from fdem.mesh.topology import build_topology
from fdem.results.ensemble_summary import fos_distribution_figure, runout_figure, sensitivity_figure
from fdem.results.events import MULIASHI, magnitude_plot
from fdem.results.overburden import depth_below_surface, lithostatic_ratio

TOPO = build_topology(structured_rectangle(20, 10, 20.0, 10.0))
UNIT = re.compile(r"\[[^\]]+\]\s*$")


def wedge_scene():
    """A wedge above the line y = x - 5 moved by (-1.5, -1) m: its edges broken by mode."""
    x = TOPO.x0.copy()
    c0 = x[TOPO.triangles].mean(axis=1)
    wedge = c0[:, 1] > c0[:, 0] - 5.0
    x[TOPO.triangles[wedge].ravel()] += [-1.5, -1.0]
    a, b = TOPO.crack_triangles.T
    broken = wedge[a] != wedge[b]
    mode = np.where(broken, 1 + np.arange(TOPO.n_cracks) % 3, 0)
    segs = x[TOPO.crack_nodes[:, :2]]
    return x, broken, mode, segs


def wedge_mask():
    c0 = TOPO.x0[TOPO.triangles].mean(axis=1)
    return c0[:, 1] > c0[:, 0] - 5.0


def mechanism_panels(x, broken):
    """Mid-failure (half the wedge's travel, its rim activated) and the end (its rim broken)."""
    status = np.where(broken, 2, 0).astype(np.int8)
    half = TOPO.x0 + 0.5 * (x - TOPO.x0)
    return [{"x": half, "displacement": np.linalg.norm(half - TOPO.x0, axis=1), "status": np.where(broken, 1, 0),
             "title": "mid-failure"},
            {"x": x, "displacement": np.linalg.norm(x - TOPO.x0, axis=1), "status": status, "title": "end"}]


def many_stages(n=40, seed=1):
    """A history of ``n`` stages of random, mostly very short, lengths and long names."""
    rng = np.random.default_rng(seed)
    lengths = rng.choice([1, 2, 3, 60], size=n, p=[0.4, 0.3, 0.2, 0.1])
    stage = np.repeat([f"reduction_F{1 + 0.01 * k:.3f}" for k in range(n)], lengths)
    return np.linspace(0.0, 10.0, stage.size), stage


# ----------------------------------------------------------------------------- stage labels
def overlaps(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_stage_label_rows_never_overlap_for_many_short_stages():
    rng = np.random.default_rng(0)
    for n in (1, 2, 5, 30, 200):
        centres = np.sort(rng.uniform(0.0, 600.0, n))
        widths = rng.uniform(20.0, 90.0, n)
        boxes = stage_label_rows(centres, widths, 0.0, 600.0, gap=3.0)
        assert boxes.shape == (n, 3)
        np.testing.assert_allclose(boxes[:, 1] - boxes[:, 0], widths)
        assert boxes[:, 0].min() >= 0.0 and boxes[:, 1].max() <= 600.0  # inside the axes
        for i in range(n):
            for j in range(i):
                if boxes[i, 2] == boxes[j, 2]:
                    assert boxes[i, 1] + 3.0 <= boxes[j, 0] or boxes[j, 1] + 3.0 <= boxes[i, 0], (n, i, j)
    # short stages are named in ranges that their span holds; long ones alone
    width = lambda text: 6.0 * len(text)  # noqa: E731  (a fixed-pitch font, 6 units a character)
    names = [f"step_{k}" for k in range(12)]
    edges = np.r_[0.0, 100.0, 103.0, 106.0, 109.0, 112.0, 115.0, 118.0, 121.0, 124.0, 127.0, 300.0, 500.0]
    groups = group_stages(edges[:-1], edges[1:], names, width)
    assert [(i, j) for i, j, _ in groups] == [(0, 0), (1, 9), (10, 10), (11, 11)]
    assert groups[1][2] == "step_1 ... 9 (9 stages)"
    assert group_label(["reduction_F1.000", "x", "reduction_F1.220"], 0, 2) == "reduction_F1.000 ... F1.220 (3 stages)"
    # stages long enough for their labels stay on one row, centred on their stage
    boxes = stage_label_rows([50.0, 250.0, 450.0], [60.0, 60.0, 60.0], 0.0, 600.0)
    np.testing.assert_array_equal(boxes[:, 2], 0)
    np.testing.assert_allclose(0.5 * (boxes[:, 0] + boxes[:, 1]), [50.0, 250.0, 450.0])


@pytest.mark.parametrize("n", [2, 7, 40])
def test_drawn_stage_labels_never_overlap_and_name_each_stage_once(n):
    t, stage = many_stages(n)
    ke = 1e3 * np.exp(-((t - 5.0) / 1.0) ** 2)
    spans = stage_spans(t, stage)
    names = [s[0] for s in spans]
    assert names == list(dict.fromkeys(stage.tolist()))
    assert spans[0][1] == 0.0 and spans[-1][2] == 10.0
    assert all(spans[k][2] == spans[k + 1][1] for k in range(len(spans) - 1))  # stages tile the time axis
    for fig in (kinetic_energy_plot(None, t, ke, stage),
                fragment_size_plot(None, 10 ** np.linspace(-2, 1, 50), time=t, count=np.arange(t.size), stage=stage)):
        fig.canvas.draw()
        r = fig.canvas.get_renderer()
        labels = [a for a in fig.findobj(lambda a: a.get_gid() == "stage-label")]
        labels.sort(key=lambda lab: names.index(lab.get_text().split(" ... ")[0]))
        # each stage named once: alone, or as a range "first ... last (n stages)"; in time order
        named = []
        for lab in labels:
            m = re.fullmatch(r"(\S+) \.\.\. (\S+) \((\d+) stages\)", lab.get_text())
            k = names.index(m.group(1) if m else lab.get_text())
            named += names[k:k + (int(m.group(3)) if m else 1)]
            if m:
                assert names[k + int(m.group(3)) - 1].endswith(m.group(2))
        assert named == names
        boxes = [lab.get_window_extent(r) for lab in labels]
        for i in range(len(boxes)):
            for j in range(i):
                assert not overlaps(boxes[i], boxes[j]), (labels[i].get_text(), labels[j].get_text())
        # nor do they run into the title or out of the figure
        ax = [a for a in fig.axes if any(lab.axes is a for lab in labels)][0]
        title = ax.title.get_window_extent(r)
        assert all(not overlaps(b, title) for b in boxes)
        assert all(b.y1 <= fig.bbox.y1 and b.x0 >= 0 and b.x1 <= fig.bbox.x1 for b in boxes)


# ----------------------------------------------------------------------------- units
def all_figures():
    x, broken, mode, segs = wedge_scene()
    u = np.linalg.norm(x - TOPO.x0, axis=1)
    outline = boundary_segments(TOPO.x0, TOPO.boundary_edges)
    rng = np.random.default_rng(0)
    t, stage = many_stages(5)
    ev_el = np.flatnonzero(broken)
    summary = {"probability_of_failure": {"k": 2, "m": 20, "pf": 0.1, "confidence": 0.95, "wilson": [0.03, 0.3]},
               "status": {"error": 0, "below_bracket": 0, "above_bracket": 0}}
    ok = [{"p_cohesion": c, "p_friction_angle": f, "p_new_thing": 1.0 + c}
          for c, f in zip(rng.uniform(5e3, 2e4, 20), rng.normal(30, 3, 20))]
    fos = rng.normal(1.2, 0.2, 20)
    return {
        "failure_frame": failure_frame(None, x, TOPO, u, segs, broken, mode, outline=outline,
                                       joint=TOPO.crack_tag >= 0, vectors=x - TOPO.x0, title="wedge"),
        "mechanism_frames": mechanism_frames(None, TOPO, TOPO.crack_nodes, mechanism_panels(x, broken),
                                             joint=TOPO.crack_tag >= 0, outline=outline,
                                             locked=wedge_mask(), crack_triangles=TOPO.crack_triangles),
        "geostatic_stress_map": geostatic_stress_map(None, TOPO.x0, TOPO, -1e4 * (10 - TOPO.x0[TOPO.triangles].mean(1)[:, 1]),
                                                     np.ones(TOPO.n_triangles), outline=outline),
        "crack_time_map": crack_time_map(None, TOPO.x0, TOPO, TOPO.x0[TOPO.crack_nodes[:, :2]], ev_el,
                                         rng.uniform(0, 3, ev_el.size), outline=outline),
        "kinetic_energy_plot": kinetic_energy_plot(None, t, np.exp(-t), stage),
        "kinetic_energy_plot_log": kinetic_energy_plot(None, t, np.exp(-t) + 1e-9, stage, log=True),
        "crack_count_plot": crack_count_plot(None, rng.random(50), rng.choice(["I", "II", "mixed"], 50)),
        "fragment_size_plot": fragment_size_plot(None, 10 ** rng.uniform(-2, 2, 100)),
        "fragment_size_plot_time": fragment_size_plot(None, 10 ** rng.uniform(-2, 2, 100), time=t,
                                                      count=np.arange(t.size), stage=stage),
        "magnitude_plot": magnitude_plot(None, -4.0 + rng.exponential(0.4, 300), reference=MULIASHI),
        "magnitude_plot_empty": magnitude_plot(None, np.zeros(0)),
        "fos_distribution": fos_distribution_figure(fos, summary),
        "sensitivity": sensitivity_figure(ok, fos, ["cohesion", "friction_angle", "new_thing"],
                                          {p: {"rho": 0.5} for p in ("cohesion", "friction_angle", "new_thing")}),
        "runout_distribution": runout_figure(rng.uniform(0, 10, 20), rng.uniform(0, 50, 20)),
        "trial_histories_plot": trial_histories_plot(
            None, [{"factor": f, "stable": f < 1.3, "time": t, "ratio": np.exp(-t) * f,
                    "displacement": 1e-3 * t * f} for f in (1.1, 1.2, 1.4)], limit=1e-4, hold=0.4),
    }


def test_every_axis_of_every_picture_has_a_unit():
    for name, fig in all_figures().items():
        fig.canvas.draw()
        for ax in fig.axes:
            for axis in (ax.xaxis, ax.yaxis):
                ticked = axis.get_visible() and ax.axison and any(
                    lab.get_visible() and lab.get_text() for lab in axis.get_ticklabels())
                if ticked:
                    assert UNIT.search(axis.get_label_text()), f"{name}: axis label {axis.get_label_text()!r}"


# ----------------------------------------------------------------------------- geostatic stress
def test_depth_below_surface_matches_closed_forms():
    # a column [0, 2] x [0, 10]: depth = 10 - y everywhere inside, exactly
    topo = build_topology(structured_rectangle(4, 20, 2.0, 10.0))
    c = topo.x0[topo.triangles].mean(axis=1)
    d = depth_below_surface(c, boundary_segments(topo.x0, topo.boundary_edges))
    np.testing.assert_allclose(d, 10.0 - c[:, 1], rtol=0, atol=1e-12)

    def square(x0, y0, s):  # counter-clockwise boundary of a square
        p = np.array([[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]])
        return np.stack([p, np.roll(p, -1, axis=0)], axis=1)

    pts = np.array([[0.5, 0.5], [0.25, 1.5], [0.75, 2.5]])
    # two squares resting on each other: the shared face cancels, rock above = 2 - y
    np.testing.assert_allclose(depth_below_surface(pts[:2], np.r_[square(0, 0, 1), square(0, 1, 1)]), [1.5, 0.5])
    # an air gap between y = 1 and 2 is not overburden: 0.5 + 1 above the first point
    np.testing.assert_allclose(depth_below_surface(pts, np.r_[square(0, 0, 1), square(0, 2, 1)]), [1.5, 1.0, 0.5])
    # a slope face y = x: rock above (x, y) under the crest y = 1 of the triangle (0,0) (1,0) (1,1)
    tri = np.array([[[0, 0], [1, 0]], [[1, 0], [1, 1]], [[1, 1], [0, 0]]], float)
    np.testing.assert_allclose(depth_below_surface(np.array([[0.6, 0.2], [0.9, 0.1]]), tri), [0.4, 0.8])


def test_stress_map_ratio_is_one_inside_a_gravity_column(tmp_path):
    """A geostatic start of a laterally confined column: sigma_yy = -rho g (H - y), so the
    map's ratio -sigma_yy / (rho g d) is 1 within 1 % wherever the column has rock above."""
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.geostatic import geostatic_start
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    E, NU, RHO, G, H, W = 0.59e9, 0.29, 2680.0, 9.81, 10.0, 2.0
    model = Model.from_mesh(structured_rectangle(4, 40, W, H), ElasticMaterial(E, NU, RHO), exploded=True)
    model.set_gravity(0.0, -G)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    geostatic_start(model)
    sim = Simulation(model, progress=False)
    topo = model.topology
    c = topo.x0[topo.triangles].mean(axis=1)
    outline = boundary_segments(topo.x0, topo.boundary_edges)
    depth = depth_below_surface(c, outline)
    syy = sim.stresses()["yy"]
    ratio = lithostatic_ratio(syy, model.property_array("density"), G, depth, min_depth=0.5)
    inner = depth > 0.5
    assert inner.sum() > 0.9 * topo.n_triangles
    np.testing.assert_allclose(ratio[inner], 1.0, atol=0.01)
    assert np.isnan(ratio[~inner]).all()
    fig = geostatic_stress_map(None, sim.state.x, topo, syy, ratio, outline=outline)
    mapped = fig.axes[2].collections[0].get_array()  # the ratio panel's triangles, in order
    np.testing.assert_array_equal(np.ma.filled(mapped, np.nan), ratio)
    assert geostatic_stress_map(tmp_path / "g.png", sim.state.x, topo, syy, ratio).stat().st_size > 10_000
    with pytest.raises(ValueError, match="triangles: 320, sigma_yy: 319"):
        geostatic_stress_map(None, sim.state.x, topo, syy[:-1], ratio)


# ----------------------------------------------------------------------------- crack time map
def test_crack_time_map_colours_each_broken_element_by_its_first_event_time():
    rng = np.random.default_rng(3)
    element = rng.integers(0, TOPO.n_cracks, 60)
    time = rng.uniform(0.0, 4.0, 60)
    segs = TOPO.x0[TOPO.crack_nodes[:, :2]]
    fig = crack_time_map(None, TOPO.x0, TOPO, segs, element, time)
    lc = [c for c in fig.axes[0].collections if c.get_gid() == "break-time"][0]
    first = {}
    for e, t in zip(element, time):
        first[e] = min(t, first.get(e, np.inf))
    order = sorted(first, key=first.get)
    np.testing.assert_array_equal(lc.get_array(), [first[e] for e in order])
    np.testing.assert_array_equal(np.array(lc.get_segments()), segs[order])
    assert lc.get_clim() == (min(first.values()), max(first.values()))
    with pytest.raises(ValueError, match="element ids must lie in 0.."):
        crack_time_map(None, TOPO.x0, TOPO, segs, np.array([TOPO.n_cracks]), np.array([1.0]))


# ----------------------------------------------------------------------------- failure frame
def test_failure_frame_draws_outline_intact_joints_and_a_readable_number_of_arrows():
    x, broken, mode, segs = wedge_scene()
    joint = np.arange(TOPO.n_cracks) % 5 == 0
    outline = boundary_segments(TOPO.x0, TOPO.boundary_edges)
    fig = failure_frame(None, x, TOPO, np.linalg.norm(x - TOPO.x0, axis=1), segs, broken, mode, outline=outline,
                        joint=joint, vectors=x - TOPO.x0, max_arrows=50)
    ax = fig.axes[0]
    by_gid = {c.get_gid(): c for c in ax.collections}
    np.testing.assert_array_equal(np.array(by_gid["outline"].get_segments()), outline)
    np.testing.assert_array_equal(np.array(by_gid["intact"].get_segments()), segs[joint & ~broken])
    assert max(by_gid["intact"].get_linewidths()) < min(by_gid["broken-1"].get_linewidths())
    arrows = by_gid["arrows"]  # on the moved wedge only (1.8 m each), the rock at rest has none
    assert 10 <= len(arrows.U) <= 50
    np.testing.assert_allclose(np.hypot(arrows.U, arrows.V), np.hypot(1.5, 1.0))
    with pytest.raises(ValueError, match="joint must have shape"):
        failure_frame(None, x, TOPO, np.zeros(TOPO.n_triangles), segs, broken, mode, joint=joint[:-1])


def test_mechanism_frames_draw_activated_and_broken_elements_in_black_and_the_locked_rim():
    x, broken, mode, segs = wedge_scene()
    panels = mechanism_panels(x, broken)
    fig = mechanism_frames(None, TOPO, TOPO.crack_nodes, panels, joint=np.zeros(TOPO.n_cracks, bool),
                           locked=wedge_mask(), crack_triangles=TOPO.crack_triangles)
    mid, end = (ax for ax in fig.axes if ax.get_title())
    for ax, panel, code in ((mid, panels[0], "status-1"), (end, panels[1], "status-2")):
        by_gid = {c.get_gid(): c for c in ax.collections}
        np.testing.assert_allclose(np.array(by_gid[code].get_segments()),
                                   crack_segments_at(panel["x"], TOPO.crack_nodes)[broken])
        assert {tuple(c) for c in by_gid[code].get_colors()[:, :3]} == {(0.0, 0.0, 0.0)}  # black
        np.testing.assert_allclose(np.array(by_gid["locked"].get_segments()),  # the wedge's rim is its outline
                                   crack_segments_at(panel["x"], TOPO.crack_nodes)[broken])
    assert max({c.get_gid(): c for c in mid.collections}["status-1"].get_linewidths()) < \
        min({c.get_gid(): c for c in end.collections}["status-2"].get_linewidths())
    with pytest.raises(ValueError, match="status must have shape"):
        mechanism_frames(None, TOPO, TOPO.crack_nodes, [{**panels[0], "status": panels[0]["status"][:-1]}])
    with pytest.raises(ValueError, match="crack_triangles"):
        mechanism_frames(None, TOPO, TOPO.crack_nodes, panels, locked=wedge_mask())


def test_arrow_sample_spreads_at_most_the_asked_number_of_points():
    rng = np.random.default_rng(2)
    pts = rng.uniform(0, 1, (20000, 2)) * [40.0, 10.0]
    pts = pts[pts[:, 1] < 0.25 * pts[:, 0]]  # a slope: part of its bounding box is empty
    for cap in (10, 100, 400):
        pick = arrow_sample(pts, cap)
        assert 0.5 * cap <= pick.size <= cap and np.unique(pick).size == pick.size
        # evenly spread: no two picked points nearer than a fifth of the mean spacing
        p = pts[pick]
        spacing = np.sqrt(0.125 * 40 * 10 * 40 / 40 / pick.size)
        d = np.sqrt(((p[:, None] - p[None]) ** 2).sum(-1)) + np.eye(len(p)) * 1e9
        assert d.min() > 0.2 * spacing
    np.testing.assert_array_equal(arrow_sample(pts[:5], 10), np.arange(5))


# ----------------------------------------------------------------------------- animation
def write_series(folder, n_frames, compression=None):
    topo = build_topology(structured_rectangle(12, 4, 12.0, 4.0))
    series = PvdSeries(folder, "slope", compression=compression)
    cracks = PvdSeries(folder, "slope_cracks", compression=compression)
    for k in range(n_frames):
        x = topo.x0 + [-0.2 * k, 0.0] * (topo.x0[:, 1:] > 2.0)
        series.write(0.1 * k, x, topo.triangles, VTK_TRIANGLE, {"displacement": x - topo.x0}, None)
        pts = x[topo.crack_nodes[:, :2]].reshape(-1, 2)
        cracks.write(0.1 * k, pts, np.arange(pts.shape[0]).reshape(-1, 2), VTK_LINE, None, None)
    return topo, series.pvd_path, cracks.pvd_path


@pytest.mark.parametrize("n_frames, max_frames", [(5, 60), (9, 4)])
def test_animation_writes_a_gif_with_one_frame_per_picked_output_frame(tmp_path, n_frames, max_frames):
    from PIL import Image

    topo, pvd, crack_pvd = write_series(tmp_path, n_frames, compression="zlib")
    events = np.zeros(3, dtype=[("element", np.int64), ("time", np.float64), ("mode", "U5")])
    events["element"], events["time"], events["mode"] = [0, 5, 9], [0.05, 0.15, 0.35], ["I", "II", "mixed"]
    p = animate_series(tmp_path / "a.gif", pvd, crack_pvd, events=events,
                       outline=boundary_segments(topo.x0, topo.boundary_edges), max_frames=max_frames, width_px=400)
    expected = pick_frames(n_frames, max_frames)
    assert expected.size == min(n_frames, max_frames) and expected[0] == 0 and expected[-1] == n_frames - 1
    with Image.open(p) as im:
        assert im.format == "GIF" and im.n_frames == expected.size
        assert im.size[0] == 400
    with pytest.raises(ValueError, match="3 frames, .* has 2"):
        _, short, _ = write_series(tmp_path / "short", 2)
        animate_series(tmp_path / "b.gif", short, write_series(tmp_path / "long", 3)[2])


# ----------------------------------------------------------------------------- the report
def test_report_maps_the_state_at_the_end_of_the_equilibrium_stage_and_animates_the_frames(tmp_path):
    """A gravity column with crack elements, geostatic start, 40 steps of an ``equilibrium``
    stage and 30 of a ``runout``: the stress map is of the state the equilibrium stage ended in
    (positions bit for bit), its ratio is 1 inside, and the GIF has one frame per output frame."""
    from PIL import Image

    from fdem.physics.crack_properties import CrackProperties
    from fdem.physics.cracks import CrackSet
    from fdem.physics.elastic import ElasticMaterial
    from fdem.results.report import RunReport
    from fdem.solve.geostatic import geostatic_start
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    model = Model.from_mesh(structured_rectangle(4, 40, 2.0, 10.0), ElasticMaterial(1e9, 0.25, 2000.0), exploded=True)
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    model.roller("left", "x")
    model.roller("right", "x")
    cs = CrackSet(model.topology, {0: CrackProperties(f_t=1e6, c=2e6, phi=30.0, G_I=100.0, G_II=300.0, k_n=1e12,
                                                      k_t=5e11)})
    geostatic_start(model, cs)
    sim = Simulation(model, providers=[cs], out_dir=tmp_path, name="col", progress=False)
    report = RunReport(sim, toe_x=0.0)
    assert report.geostatic_state()[2].startswith("start state")  # a geostatic start before any stage
    sim.run(n_steps=40, stage="equilibrium", history_every=10, output_every=20)
    x_eq, t_eq = sim.state.x.copy(), sim.state.time
    sim.run(n_steps=30, stage="runout", history_every=10, output_every=10)
    sim.close()
    state, g, label = report.geostatic_state()
    last = [r for r in sim.history if r["stage"] == "equilibrium"][-1]  # stamped with its step's start
    assert state.time == t_eq == pytest.approx(last["time"] + last["dt"], rel=1e-12)
    np.testing.assert_array_equal(state.x, x_eq)
    assert g == 9.81 and label.startswith("end of the equilibrium stage")
    topo = model.topology
    d = depth_below_surface(topo.x0[topo.triangles].mean(1), boundary_segments(topo.x0, topo.boundary_edges))
    ratio = lithostatic_ratio(sim.stresses(state)["yy"], 2000.0, g, d, min_depth=0.5)
    np.testing.assert_allclose(ratio[d > 0.5], 1.0, atol=0.01)
    written = {p.name for p in report.pictures(tmp_path)}
    assert {"kinetic_energy.png", "failure.png", "geostatic_stress.png", "failure.gif"} <= written
    with Image.open(tmp_path / "failure.gif") as im:
        assert im.n_frames == len(read_pvd(tmp_path / "col.pvd"))
