"""Stochastic ensembles on Dask (fdem.ensembles): sampling, refusal of bad input, a tiny ensemble
of the planar-failure slope on a local cluster (reproducible, a failing realization recorded,
resume), the probability-of-failure interval and the report."""
from __future__ import annotations

import csv
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from fdem.io.ensemble_table import TABLE, read_table
from fdem.workflow.ensembles import Distribution, Ensemble, local_cluster, run_ensemble
from fdem.results.ensemble_summary import summarize, wilson_interval

HEIGHT = 10.0
GEOMETRY = dict(face_angle=60.0, plane_angle=35.0, tension_crack_offset=None)
FOS = (1.0, 2.0, 0.5)           # lower (stable), upper (failing), tolerance: three trials per realization


@dataclass(frozen=True)
class CountingPlanarScene:
    """The planar-failure slope (cases/planar_failure.py) at mesh size ``size``; every call leaves
    a marker file in ``marker_dir`` (so a test counts the realizations that really ran) and a
    call with ``cohesion > fail_above`` raises."""

    size: float
    marker_dir: str
    fail_above: float = math.inf

    def __call__(self, cohesion: float, friction_angle: float):
        from planar_failure import planar_failure_simulation

        from fdem.cases.planar_failure import planar_slope_geometry

        Path(self.marker_dir, f"{os.getpid()}_{time.time_ns()}").touch()
        if cohesion > self.fail_above:
            raise RuntimeError(f"injected failure at cohesion {cohesion:.1f} Pa")
        return planar_failure_simulation(planar_slope_geometry(HEIGHT, **GEOMETRY), self.size, cohesion=cohesion,
                                         friction_angle=friction_angle)


def scene_function(cohesion: float):
    """A module-level scene function (never run here)."""
    raise NotImplementedError


PARAMETERS = {"cohesion": Distribution.uniform(12e3, 28e3),
              "friction_angle": Distribution.normal(30.0, 2.0, low=25.0, high=35.0)}


def hoek_bray(cohesion: float, friction_angle: float) -> float:
    """Hoek-Bray factor of safety of the dry planar slope (gamma = 25 kN/m^3)."""
    from fdem.reference.hoek_bray import planar_fos

    return planar_fos(HEIGHT, GEOMETRY["face_angle"], GEOMETRY["plane_angle"], cohesion, friction_angle,
                      25e3).fos


def markers(path) -> int:
    return len(os.listdir(path))


# ----------------------------------------------------------------------------- input and sampling
@pytest.mark.parametrize("dist, message", [
    (Distribution.normal(30.0, -1.0), "standard deviation > 0"),
    (Distribution.lognormal(20e3, 0.0), "standard deviation > 0"),
    (Distribution.lognormal(-1.0, 1.0), "mean > 0"),
    (Distribution.uniform(5.0, 5.0), "low < high"),
    (Distribution.uniform(float("nan"), 1.0), "finite"),
    (Distribution.fixed(float("nan")), "finite"),
    (Distribution.normal(30.0, 3.0, low=40.0, high=20.0), "low < high"),
    (Distribution("weibull", 1.0, 2.0), "unknown distribution"),
])
def test_invalid_distribution_is_refused_naming_the_parameter(dist, message):
    with pytest.raises(ValueError, match=message) as err:
        Ensemble(scene_function, {"cohesion": dist}, n=4)
    assert "'cohesion'" in str(err.value)


def test_invalid_ensemble_settings_are_refused():
    with pytest.raises(ValueError, match="n must be a positive integer"):
        Ensemble(scene_function, {}, n=0)
    with pytest.raises(ValueError, match="'lhs' or 'mc'"):
        Ensemble(scene_function, {}, n=2, method="sobol")
    with pytest.raises(ValueError, match="module-level function or a dataclass"):
        Ensemble(lambda cohesion: None, {}, n=2)
    with pytest.raises(ValueError, match="lower < upper"):
        Ensemble(scene_function, {}, n=2, fos=(2.0, 1.0, 0.1))


def test_a_realizations_capped_trial_is_followed_to_rest_unless_the_search_says_cap():
    """Every realization runs a strength search, so its capped trials are followed to rest by
    default, also when the scene's own workflow increases gravity (whose own trials end at their
    cap), and judged at the cap when the search says so; the rule is part of the description."""
    from fdem.workflow.slope import SlopeWorkflow

    plain = Ensemble(scene_function, {}, n=2)
    gravity = Ensemble(scene_function, {}, n=2, search=SlopeWorkflow(trigger="gravity", fos=(1.0, 2.0, 0.1)))
    capped = Ensemble(scene_function, {}, n=2, search=SlopeWorkflow(trial_end="cap"))
    assert plain.trial_rule == gravity.trial_rule == "rest" and capped.trial_rule == "cap"
    assert plain.describe()["trial_end"] == "rest" and "trial_end" not in capped.describe()


def test_sampling_is_seeded_stratified_and_respects_bounds():
    params = {"c": Distribution.uniform(0.0, 10.0), "phi": Distribution.normal(30.0, 10.0, low=25.0, high=35.0),
              "L": Distribution.lognormal(3.0, 1.0), "k": Distribution.fixed(4), "s": Distribution.seed()}
    e = Ensemble(scene_function, params, n=10, seed=7)
    a, b = e.sample(), e.sample()
    assert a == b                                                        # same seed, same parameters
    assert Ensemble(scene_function, params, n=10, seed=8).sample() != a
    c = np.array([r["c"] for r in a])
    assert sorted(np.floor(c).astype(int)) == list(range(10))            # Latin hypercube: one per tenth
    phi = np.array([r["phi"] for r in a])
    assert phi.min() >= 25.0 and phi.max() <= 35.0                      # truncated
    assert all(r["k"] == 4 for r in a)
    assert all(isinstance(r["s"], int) and 0 <= r["s"] < 2 ** 31 for r in a) and len({r["s"] for r in a}) == 10
    # Monte Carlo: realization i does not depend on n.
    mc5 = Ensemble(scene_function, params, n=5, seed=7, method="mc").sample()
    mc3 = Ensemble(scene_function, params, n=3, seed=7, method="mc").sample()
    assert mc5[:3] == mc3
    # Lognormal parameters are the variable's own mean and sd: check on a large sample.
    big = Ensemble(scene_function, {"L": Distribution.lognormal(3.0, 1.0)}, n=4000, seed=1).sample()
    L = np.array([r["L"] for r in big])
    assert L.mean() == pytest.approx(3.0, rel=0.02) and L.std() == pytest.approx(1.0, rel=0.05)


def test_wilson_interval_matches_the_closed_form_and_scipy():
    from scipy.stats import binomtest

    # 5 / 20 at 95 %: centre (0.25 + 1.96^2/40) / (1 + 1.96^2/20) = 0.29029, half-width 0.17843.
    lo, hi = wilson_interval(5, 20)
    assert lo == pytest.approx(0.11186, abs=2e-5) and hi == pytest.approx(0.46871, abs=2e-5)
    ci = binomtest(5, 20).proportion_ci(0.95, method="wilson")
    assert (lo, hi) == pytest.approx((ci.low, ci.high), rel=1e-9)
    # No failure in 20: the upper bound is z^2 / (n + z^2) = 0.16113.
    assert wilson_interval(0, 20) == pytest.approx((0.0, 3.8415 / 23.8415), abs=1e-4)


# ----------------------------------------------------------------------------- on a local cluster
@pytest.fixture(scope="module")
def client():
    from dask.distributed import Client

    cluster = local_cluster(2)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="module")
def finished(client, tmp_path_factory):
    """Four realizations, the one with the largest cohesion raising."""
    base = tmp_path_factory.mktemp("ensemble")
    marker_dir = base / "markers"
    marker_dir.mkdir()
    probe = Ensemble(CountingPlanarScene(3.0, str(marker_dir)), PARAMETERS, n=4, seed=3, fos=FOS)
    samples = probe.sample()
    worst = max(range(4), key=lambda i: samples[i]["cohesion"])
    threshold = 0.5 * (samples[worst]["cohesion"] + max(s["cohesion"] for i, s in enumerate(samples) if i != worst))
    ens = Ensemble(CountingPlanarScene(3.0, str(marker_dir), fail_above=threshold), PARAMETERS, n=4, seed=3,
                   fos=FOS)
    out = base / "run"
    run = run_ensemble(ens, out, client=client, progress=False)
    return dict(ens=ens, out=out, run=run, markers=marker_dir, samples=samples, worst=worst)


def test_every_realization_gets_a_row_and_a_failing_one_does_not_stop_the_others(finished):
    run, samples = finished["run"], finished["samples"]
    assert run.n_run == 4 and run.n_skipped == 0
    assert markers(finished["markers"]) == 4
    digest, rows = read_table(finished["out"] / TABLE)
    assert digest == finished["ens"].fingerprint()
    assert [r["index"] for r in rows] == [0, 1, 2, 3]
    bad = rows[finished["worst"]]
    assert bad["status"] == "error" and "RuntimeError: injected failure" in bad["error"]
    for r in rows:
        assert r["p_cohesion"] == samples[r["index"]]["cohesion"]        # parameters in the table, exactly
        if r is bad:
            continue
        assert r["status"] == "ok" and r["error"] == ""
        assert r["numba_threads"] == 1                                   # one Numba thread per worker
        assert r["peak_rss_mb"] > 50 and r["wall_s"] > 0
        # Strength reduction brackets the Hoek-Bray value of the sampled c and phi (within 2 %).
        F = hoek_bray(r["p_cohesion"], r["p_friction_angle"])
        assert r["fos_lower"] <= 1.02 * F and 0.98 * F <= r["fos_upper"]
        assert r["fos_upper"] - r["fos_lower"] <= FOS[2]
    assert len({r["worker_pid"] for r in rows}) >= 1


def test_resume_runs_only_missing_realizations_and_reproduces_them(finished, client):
    out, marker_dir = finished["out"], finished["markers"]
    _, before = read_table(out / TABLE)
    again = run_ensemble(finished["ens"], out, client=client, progress=False)
    assert again.n_run == 0 and again.n_skipped == 4
    assert markers(marker_dir) == 4                                      # nothing ran
    # Drop the last two rows of the table: a rerun runs exactly those two.
    lines = (out / TABLE).read_text().splitlines(keepends=True)
    (out / TABLE).write_text("".join(lines[:-2]))
    dropped = [int(line.split(",")[0]) for line in lines[-2:]]
    resumed = run_ensemble(finished["ens"], out, client=client, progress=False)
    assert resumed.n_run == 2 and resumed.n_skipped == 2
    assert markers(marker_dir) == 6
    _, after = read_table(out / TABLE)
    assert len(after) == 4
    for i in dropped:                                                    # same parameters, same FoS, bit for bit
        for key in ("status", "p_cohesion", "p_friction_angle", "fos", "fos_lower", "fos_upper", "n_trials"):
            a, b = before[i][key], after[i][key]
            assert a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b)), (i, key, a, b)


def test_report_gives_probability_of_failure_sensitivity_and_pictures(finished):
    s = summarize(finished["out"])
    _, rows = read_table(finished["out"] / TABLE)
    ok = [r for r in rows if r["status"] == "ok"]
    k = sum(r["fos"] < 1 for r in ok)
    pf = s["probability_of_failure"]
    assert (pf["k"], pf["m"]) == (k, len(ok)) and s["status"]["error"] == 1
    assert pf["wilson"] == pytest.approx(list(wilson_interval(k, len(ok))))
    assert pf["clopper_pearson"][0] <= pf["pf"] <= pf["clopper_pearson"][1]
    assert set(s["spearman"]) == {"cohesion", "friction_angle"}
    assert s["fos"]["min"] == min(r["fos"] for r in ok)
    assert s["least_stable"] == min(ok, key=lambda r: r["fos"])["index"]
    for name in ("fos_distribution.png", "sensitivity.png", "least_stable.png", "most_stable.png"):
        path = finished["out"] / name
        assert path.stat().st_size > 10_000 and path.read_bytes()[:4] == b"\x89PNG"


def test_results_of_another_description_are_refused_before_anything_runs(finished):
    other = Ensemble(finished["ens"].scene, PARAMETERS, n=4, seed=4, fos=FOS)   # another seed
    n = markers(finished["markers"])
    size = (finished["out"] / TABLE).stat().st_size
    t = time.perf_counter()
    with pytest.raises(ValueError, match="another ensemble description"):
        run_ensemble(other, finished["out"], workers=1, progress=False)
    assert time.perf_counter() - t < 2.0                                  # refused before a cluster starts
    assert markers(finished["markers"]) == n and (finished["out"] / TABLE).stat().st_size == size


def test_unreachable_scheduler_is_refused_within_the_timeout(tmp_path):
    marker_dir = tmp_path / "markers"
    marker_dir.mkdir()
    ens = Ensemble(CountingPlanarScene(3.0, str(marker_dir)), PARAMETERS, n=2, fos=FOS)
    t = time.perf_counter()
    with pytest.raises(ConnectionError, match="127.0.0.1:9"):
        run_ensemble(ens, tmp_path / "run", scheduler="tcp://127.0.0.1:9", timeout=2.0, progress=False)
    assert time.perf_counter() - t < 10.0
    assert markers(marker_dir) == 0 and not (tmp_path / "run" / TABLE).exists()


def test_table_header_names_parameters_and_carries_the_hash(finished):
    with (finished["out"] / TABLE).open() as fh:
        first = fh.readline()
        header = next(csv.reader(fh))
    assert first.strip() == f"# fdem ensemble sha256={finished['ens'].fingerprint()}"
    assert header[:4] == ["index", "status", "p_cohesion", "p_friction_angle"]
    assert {"fos", "fos_lower", "fos_upper", "wall_s", "peak_rss_mb", "error"} <= set(header)


def test_case_cross_joints_stay_in_the_block_and_leave_the_sliding_plane_whole():
    import warnings

    from ensemble import PlanarDFNScene, ensemble

    scene = PlanarDFNScene(size=2.0)
    d, e, crest = scene.block_corners()
    t = (e - d) / np.linalg.norm(e - d)
    n = np.array([-t[1], t[0]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for p in ensemble(n=8).sample():
            segs = scene.cross_joints(p["dfn_seed"], p["trace_length"], p["dip_scatter"], p["joints"])
            ends = segs.reshape(-1, 2)
            assert np.all((ends - d) @ n >= 0.5 - 1e-9)                  # 0.25 size above the plane
            dfn = scene.geometry(p["dfn_seed"], p["trace_length"], p["dip_scatter"], p["joints"]).dfn()
            plane = dfn.segments[dfn.set_id == 1]
            # The sliding plane keeps its whole length H / sin(psi_p) = 17.434 m: no bridge in it.
            assert np.linalg.norm(plane[:, 1] - plane[:, 0], axis=1).sum() == pytest.approx(
                10.0 / math.sin(math.radians(35.0)), rel=1e-9)


# ----------------------------------------------------------------------------- beyond the laptop
def test_worker_plugin_holds_a_worker_started_with_more_threads_to_one():
    """A worker started with NUMBA_NUM_THREADS=2 (a cluster node's default) runs on one thread once
    the plugin is registered: in its environment, in Numba, and in the thread that runs a task."""
    from dask.distributed import Client

    from fdem.workflow.dask_workers import register_single_thread
    from fdem.workflow.ensembles import realize

    def threads():
        import numba

        return os.environ.get("NUMBA_NUM_THREADS"), numba.get_num_threads()

    with local_cluster(1, env={"NUMBA_NUM_THREADS": "2"}) as cluster, Client(cluster) as c:
        assert list(c.run(threads).values()) == [("2", 2)]              # as started
        register_single_thread(c)
        assert list(c.run(threads).values()) == [("1", 1)]              # read back on the worker
        ens = Ensemble(scene_function, {"cohesion": Distribution.fixed(1.0)}, n=1)
        row = c.submit(realize, ens, 0, {"cohesion": 1.0}, pure=False).result()
    assert row["numba_threads"] == 1 and "NotImplementedError" in row["error"]   # the task's own thread


def test_scheduler_file_runs_a_realization_on_that_cluster(client, tmp_path):
    marker_dir = tmp_path / "markers"
    marker_dir.mkdir()
    path = tmp_path / "scheduler.json"
    client.write_scheduler_file(str(path))
    ens = Ensemble(CountingPlanarScene(3.0, str(marker_dir)), PARAMETERS, n=1, seed=5, fos=FOS)
    run = run_ensemble(ens, tmp_path / "run", scheduler_file=path, progress=False)
    assert run.n_run == 1 and markers(marker_dir) == 1
    (row,) = run.rows
    assert row["status"] == "ok" and row["numba_threads"] == 1
    assert row["worker_pid"] in {p for p in client.run(os.getpid).values()}   # ran on that cluster's workers
    F = hoek_bray(row["p_cohesion"], row["p_friction_angle"])
    assert row["fos_lower"] <= 1.02 * F and 0.98 * F <= row["fos_upper"]


def test_missing_scheduler_file_is_refused_before_any_work(tmp_path, capsys):
    from ensemble import parse_args

    marker_dir = tmp_path / "markers"
    marker_dir.mkdir()
    missing = tmp_path / "nowhere" / "scheduler.json"
    ens = Ensemble(CountingPlanarScene(3.0, str(marker_dir)), PARAMETERS, n=2, fos=FOS)
    t = time.perf_counter()
    with pytest.raises(FileNotFoundError, match=str(missing)):
        run_ensemble(ens, tmp_path / "run", scheduler_file=missing, progress=False)
    assert time.perf_counter() - t < 2.0
    assert markers(marker_dir) == 0 and not (tmp_path / "run").exists()
    with pytest.raises(SystemExit) as stop:                             # the case: a usage error naming the file
        parse_args(["--scheduler-file", str(missing), "--out", str(tmp_path / "case")])
    assert stop.value.code == 2 and str(missing) in capsys.readouterr().err
    not_json = tmp_path / "scheduler.txt"
    not_json.write_text("tcp://127.0.0.1:8786")
    with pytest.raises(ValueError, match="not a scheduler's JSON file"):
        run_ensemble(ens, tmp_path / "run", scheduler_file=not_json, progress=False)
