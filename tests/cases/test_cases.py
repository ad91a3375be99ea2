"""Every case script in ``cases/`` (not ``cases/benchmarks``) imports and runs end to end at a
coarse size for a tiny simulated time with its outputs on; what it writes exists and holds
finite numbers. Also the ``fdem`` command's ``list`` and ``run``, the shared options, and the
thin-wrapper rule (a script in ``cases/`` runs the package's case).

A script whose import fails (a case someone is still writing) is skipped with the error as the
reason; a script that imports but fails to run is a failure.
"""
from __future__ import annotations

import csv
import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT

SCRIPTS = sorted(p for p in (ROOT / "cases").glob("*.py") if not p.name.startswith("_"))

SMOKE = "--max-time"
"""Cases that follow the shared convention run with ``--max-time`` (a few hundred steps)."""

QUICK = {
    # script stem: (argv after --out, files that must exist, the JSON file to check)
    "quick_start": (["--size", "2.0", "--max-time", "0.02", "--no-pictures", "--quiet"],
                    ["summary.json", "history.csv", "events.csv", "slope.pvd", "slope_cracks.pvd"], "summary.json"),
    "four_slopes": (["--spacing", "coarse", "--size", "2.5", "--max-time", "0.01", "--no-pictures", "--quiet"],
                    ["summary.json", "history.csv", "events.csv", "slope.pvd", "low_coarse.msh"], "summary.json"),
    "block_on_incline": (["--size", "0.5", "--max-time", "0.01", "--no-pictures"],
                         ["summary.json", "history.csv", "incline.pvd"], "summary.json"),
    "brazilian_disc": (["--size", "0.01", "--max-time", "2e-4", "--no-pictures"],
                       ["summary.json", "brazilian.json", "D_over_10/disc.pvd", "D_over_10/history.csv"], "summary.json"),
    "muliashi": (["--size", "1.0", "--max-time", "0.005", "--no-pictures"], ["summary.json"], "summary.json"),
    # scripts with their own outputs: their --max-time caps each trial or run (a smoke run)
    "planar_failure": (["--size", "2.0", "--geometry", "no_crack", "--tol", "0.5", "--max-time", "0.01",
                        "--no-pictures"], ["planar_failure.json"], "planar_failure.json"),
    "newmark_block": (["--size", "1.0", "--max-time", "0.02", "--no-pictures"], ["newmark.json"], "newmark.json"),
    # the calibration scenes at their coarsest mesh, a few hundred steps (their verification rows
    # are tests/verification/test_calibration.py)
    "compression_test": (["--size", "0.008", "--max-time", "2e-4", "--no-pictures", "--quiet"],
                         ["summary.json", "stress_strain.csv"], "summary.json"),
    "direct_shear": (["--size", "0.0125", "--normal-stresses", "1e6", "2e6", "--max-time", "2e-4", "--no-pictures",
                      "--quiet"], ["summary.json", "shear_curves.csv"], "summary.json"),
    "ensemble": (["--n", "1", "--workers", "1", "--size", "3.0", "--max-time", "0.01", "--no-pictures"],
                 ["realizations.csv", "ensemble.json", "summary.json"], "summary.json"),
}
"""A script not listed here runs with ``--max-time 0.005 --no-pictures`` and must write summary.json."""

def load_script(path: Path):
    """Import ``cases/<name>.py`` as a module (skip the test if it does not import)."""
    name = f"case_script_{path.stem}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # before exec: dataclasses look their module up there
    try:
        spec.loader.exec_module(module)
    except Exception as err:  # a script another engineer is still writing
        del sys.modules[name]
        pytest.skip(f"cases/{path.name} does not import: {type(err).__name__}: {err}")
    return module


def finite_numbers(obj, where: str = "") -> list[str]:
    """Paths of the non-finite numbers in a JSON value (``null`` is allowed: "undefined")."""
    bad = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            bad += finite_numbers(v, f"{where}.{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            bad += finite_numbers(v, f"{where}[{i}]")
    elif isinstance(obj, float) and not math.isfinite(obj):
        bad.append(where)
    return bad


def check_json(path: Path) -> object:
    text = path.read_text()
    data = json.loads(text, parse_constant=lambda c: float(c))  # NaN / Infinity parse, then fail below
    bad = finite_numbers(data)
    assert not bad, f"{path.name}: non-finite numbers at {bad[:5]}"
    return data


LEDGER_TOLERANCE = 1e-3
"""Largest |balance error| / energy moved a smoke run may show: energy is conserved (the work of
gravity, supports and dissipation booked), so the ledger closes whatever the scene."""


def check_history(path: Path) -> int:
    """Every numeric cell of a history CSV is finite, and the energy ledger closes in every row
    (energy conservation, the one physical fact every scene shares); returns the number of rows."""
    with path.open() as f:
        rows = list(csv.DictReader(f))
    assert rows, f"{path} has no rows"
    values = []
    for row in rows:
        for key, cell in row.items():
            if key == "stage":
                continue
            values.append(float(cell))
    assert np.all(np.isfinite(values)), f"{path}: non-finite values"
    if "balance_error_relative" in rows[0]:
        worst = max(abs(float(r["balance_error_relative"])) for r in rows)
        assert worst < LEDGER_TOLERANCE, f"{path}: the energy ledger is off by {worst:.3g} of the energy moved"
    return len(rows)


@pytest.mark.parametrize("script", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_case_script_runs_and_writes_finite_outputs(script, tmp_path):
    module = load_script(script)
    assert callable(getattr(module, "main", None)), f"cases/{script.name} has no main(argv)"
    argv, files, json_name = QUICK.get(script.stem, (["--max-time", "0.005", "--no-pictures"],
                                                      ["summary.json"], "summary.json"))
    out = tmp_path / script.stem
    if script.stem == "ensemble":
        # as a user runs it: its Dask workers must import the scene's module by name, which a
        # module loaded from a file path under another name cannot offer them
        proc = subprocess.run([sys.executable, str(script), "--out", str(out), *argv], capture_output=True,
                              text=True, timeout=600, env={**os.environ, "NUMBA_NUM_THREADS": "1"})
        assert proc.returncode == 0, proc.stderr[-2000:]
        result = json.loads((out / "summary.json").read_text())
    else:
        result = module.main(["--out", str(out), *argv])
    for name in files:
        assert (out / name).is_file(), f"cases/{script.name} did not write {name}"
    if json_name is not None:
        check_json(out / json_name)
    for history in out.rglob("history.csv"):
        check_history(history)
    if script.stem in ("planar_failure", "newmark_block"):
        rows = result if isinstance(result, list) else result["runs"]
        assert rows and all(r["time_capped"] for r in rows), "a capped smoke run must say so"
    elif SMOKE in argv and script.stem != "ensemble":
        # the shared convention: main returns the summary it wrote, the cap is reported
        assert isinstance(result, dict)
        assert result == json.loads((out / "summary.json").read_text())
        assert not finite_numbers(result)


def test_quick_start_smoke_run_reports_its_cap_and_the_report_fields(tmp_path):
    from fdem.cases import quick_start

    summary = quick_start.main(["--out", str(tmp_path), "--size", "2.0", "--max-time", "0.02", "--no-pictures",
                                "--quiet"])
    # stopped by the cap, not by physics: said so, and the simulated time did not pass it
    assert summary["time_capped"] is True
    assert summary["simulated_time_s"] <= 0.02 + 2 * summary["dt_s"]
    assert summary["case"] == "quick-start"
    # the RunReport figures are there (runout measured from the slope's toe)
    toe_x, toe_y = summary["toe"]
    assert (toe_x, toe_y) == (quick_start.TOE_LENGTH, quick_start.BASE_DEPTH)
    for key in ("runout_distance_m", "runout_volume_m2", "max_displacement_m"):
        assert key in summary["runout"]
    assert summary["cracks"]["broken"] >= 0 and summary["n_triangles"] > 0
    assert not (tmp_path / "failure.png").exists()          # --no-pictures
    # history.csv: one row per check, time increasing, the last within two steps of the end
    with (tmp_path / "history.csv").open() as f:
        t = np.array([float(r["time"]) for r in csv.DictReader(f)])
    assert np.all(np.diff(t) >= 0)
    assert t[-1] == pytest.approx(summary["simulated_time_s"], abs=2 * summary["dt_s"])


def test_thin_wrappers_run_the_package_cases():
    """``cases/<x>.py`` of a packaged case exposes the package's main and its constants."""
    from fdem.cases import CASES

    for name, module_name in CASES.items():
        path = ROOT / "cases" / f"{name.replace('-', '_')}.py"
        if not path.exists():
            continue
        try:
            package = importlib.import_module(module_name)
        except Exception as err:
            pytest.skip(f"{module_name} does not import: {err}")
        wrapper = load_script(path)
        assert wrapper.main is package.main
        assert len(path.read_text().splitlines()) < 20, f"{path.name} should only wrap {module_name}"


def test_fdem_list_names_every_case(capsys):
    from fdem.cases import CASES
    from fdem.cli import main

    assert main(["list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in out] == list(CASES)
    assert any(line.startswith("quick-start") and "strength reduction" in line for line in out)


def test_fdem_run_refuses_an_unknown_case_and_bad_shared_options(capsys, tmp_path):
    from fdem.cli import main

    assert main(["run", "no-such-case"]) == 2
    assert "unknown case 'no-such-case'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["run", "quick-start", "--out", str(tmp_path), "--max-time", "-1"])
    assert "--max-time must be a positive number" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demo", "--size", "0"])
    assert "--size must be a positive number" in capsys.readouterr().err


def test_fdem_run_passes_options_to_the_case(tmp_path, monkeypatch):
    """``fdem run NAME ...`` and ``fdem demo ...`` call the case's main with the options as given."""
    import fdem.cases.quick_start as qs
    from fdem.cli import main

    seen = []
    monkeypatch.setattr(qs, "main", lambda argv: seen.append(list(argv)) or {})
    assert main(["run", "quick-start", "--out", str(tmp_path), "--size", "1.5"]) == 0
    assert main(["demo", "--out", str(tmp_path)]) == 0
    assert main(["run", "quick_start", "--no-pictures"]) == 0     # underscores work too
    assert seen == [["--out", str(tmp_path), "--size", "1.5"], ["--out", str(tmp_path)], ["--no-pictures"]]


def test_time_cap_stops_every_run_at_the_cap():
    """A case's --max-time sets Simulation.time_cap: run(t_end) and run(n_steps) both stop at
    the cap (within one step), and time_capped says so; no cap, no stop."""
    from fdem.cases.common import cap_simulated_time, time_capped
    from fdem.mesh.mesh import structured_rectangle
    from fdem.mesh.topology import build_topology
    from fdem.physics.elastic import ElasticMaterial
    from fdem.solve.model import Model
    from fdem.solve.simulation import Simulation

    topo = build_topology(structured_rectangle(2, 2, 1.0, 1.0))
    model = Model(topo, ElasticMaterial(young=1e9, poisson=0.25, density=2500.0))
    model.set_gravity(0.0, -9.81)
    model.fix("bottom")
    sim = Simulation(model, progress=False)
    cap_simulated_time(sim, 10.5 * sim.dt)
    sim.run(t_end=100 * sim.dt, energy_tolerance=None)
    assert sim.state.step == 11 and time_capped(sim)  # ceil(10.5): reaches the cap, overruns it by < 1 step
    sim.run(n_steps=100, energy_tolerance=None)
    assert sim.state.step == 11
    free = Simulation(model, progress=False)
    cap_simulated_time(free, None)
    free.run(n_steps=30, energy_tolerance=None)
    assert free.state.step == 30 and not time_capped(free)
