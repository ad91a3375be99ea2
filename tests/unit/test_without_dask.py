"""Dask is an optional dependency (``pip install "fdem[ensembles]"``): the package, ``fdem list``
and every case module import without it, and ``fdem run ensemble`` stops at once with the pip
command. Each check runs in a fresh interpreter where importing dask fails
(``sys.modules["dask"] = None``, as if it were not installed)."""
from __future__ import annotations

import subprocess
import sys
import time

BLOCK = "import sys; sys.modules['dask'] = None; sys.modules['distributed'] = None\n"


def run_without_dask(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCK + code], capture_output=True, text=True, timeout=120,
                          env={**__import__("os").environ, "NUMBA_NUM_THREADS": "1"})


def test_package_cases_and_fdem_list_import_without_dask():
    done = run_without_dask(
        "import importlib, io, contextlib\n"
        "import fdem\n"
        "from fdem.cases import CASES\n"
        "for name, module in CASES.items():\n"
        "    importlib.import_module(module)\n"
        "from fdem.cli import main\n"
        "out = io.StringIO()\n"
        "with contextlib.redirect_stdout(out):\n"
        "    assert main(['list']) == 0\n"
        "assert 'does not import' not in out.getvalue(), out.getvalue()\n"
        "assert 'dask' not in sys.modules or sys.modules['dask'] is None\n"
        "print(len(CASES), 'cases')\n")
    assert done.returncode == 0, done.stderr
    assert "cases" in done.stdout


def test_ensemble_without_dask_stops_at_once_with_the_pip_command(tmp_path):
    out = tmp_path / "run"
    t = time.perf_counter()
    done = run_without_dask(f"from fdem.cli import main; sys.exit(main(['run', 'ensemble', '--out', {str(out)!r}]))")
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert 'pip install "fdem[ensembles]"' in done.stderr
    assert "Traceback" not in done.stderr
    assert not out.exists()                                              # nothing was started or written
    assert time.perf_counter() - t < 60
