"""The command-line convention every case shares, and helpers the cases use to honour it.

Every case module in :mod:`fdem.cases` has ``main(argv) -> dict`` (the summary it also writes
to ``<out>/summary.json``) and accepts at least:

``--out DIR``        where everything goes (created)
``--size H``         target element size [m] (each case documents its default)
``--threads N``      Numba threads (default: all cores; set before the first kernel runs)
``--max-time T``     cap on the simulated time [s] of the whole run: every stage stops at ``T``
                     (the summary then says ``"time_capped": true``; a capped run is a smoke
                     run, its physical figures are not converged)
``--no-pictures``    no PNG files (VTU series, ``history.csv`` and ``summary.json`` still written)
``--density-scaling B``  added-mass budget of the density-scaled quasi-static stages, a fraction
                     of the model's mass (default 0.01; 0 runs every stage on the real masses;
                     :mod:`fdem.solve.density_scaling`)
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

__all__ = ["case_parser", "set_threads", "threads_for_mesh", "cap_simulated_time", "time_capped",
           "stop_cleanly_on_signals", "use_density_scaling"]

SMALL_MESH_TRIANGLES = 20_000
"""Below this many triangles a case runs on one Numba thread unless ``--threads`` (or
``NUMBA_NUM_THREADS``) says otherwise: a step of a small mesh lasts well under a millisecond,
the fork-join of each parallel kernel is a large part of it, and when another process shares
the cores the threads' spin-waiting collapses it (quick-start scene, 1,503 triangles, load
average 3 on 2 cores: 8.2 ms per damped step on 2 threads against 0.5-0.7 ms on 1;
``docs/benchmarks.md``)."""


def case_parser(doc: str | None, out: str, size: float | None, size_help: str,
                name: str | None = None) -> argparse.ArgumentParser:
    """An ``argparse`` parser with the shared options; a case adds its own after these.
    ``name``: the case's name in ``fdem run NAME`` (its usage line says so under ``fdem``)."""
    prog = f"fdem run {name}" if name and Path(sys.argv[0]).name == "fdem" else None
    parser = argparse.ArgumentParser(prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path(out), help=f"output folder (default {out})")
    parser.add_argument("--size", type=float, default=size, help=size_help)
    parser.add_argument("--threads", type=int, default=None,
                        help="Numba threads (default: all cores; NUMBA_NUM_THREADS caps them too)")
    parser.add_argument("--max-time", type=float, default=None, metavar="SECONDS",
                        help="cap on the simulated time of the whole run [s] (a smoke run)")
    parser.add_argument("--no-pictures", action="store_true", help="write no PNG pictures")
    parser.add_argument("--density-scaling", type=float, default=0.01, metavar="BUDGET",
                        help="added-mass budget of the density-scaled quasi-static stages, a fraction of the "
                             "model's mass (default 0.01; 0: real masses in every stage)")
    return parser


def check_common(parser: argparse.ArgumentParser, args) -> None:
    """Refuse bad values of the shared options before anything long starts (``--size`` may be
    one number or, for the cases that sweep sizes, a list)."""
    sizes = args.size if isinstance(args.size, list) else [] if args.size is None else [args.size]
    if any(not (math.isfinite(h) and h > 0) for h in sizes):
        parser.error(f"--size must be a positive number of metres, got {args.size}")
    if args.threads is not None and args.threads < 1:
        parser.error(f"--threads must be at least 1, got {args.threads}")
    if args.max_time is not None and not (math.isfinite(args.max_time) and args.max_time > 0):
        parser.error(f"--max-time must be a positive number of seconds, got {args.max_time}")
    budget = getattr(args, "density_scaling", 0.0)
    if not (math.isfinite(budget) and 0.0 <= budget <= 1.0):
        parser.error(f"--density-scaling must be a fraction of the model's mass in [0, 1], got {budget}")


def set_threads(n: int | None) -> None:
    """Run the Numba kernels on ``n`` threads: through ``NUMBA_NUM_THREADS`` when Numba is not
    imported yet (its thread pool is then never larger), else :func:`numba.set_num_threads`
    (at most the pool's size, ``numba.config.NUMBA_NUM_THREADS``)."""
    if n is None:
        return
    if "numba" not in sys.modules:
        os.environ["NUMBA_NUM_THREADS"] = str(int(n))
        return
    import numba

    numba.set_num_threads(min(int(n), numba.config.NUMBA_NUM_THREADS))


def threads_for_mesh(requested: int | None, n_triangles: int) -> int:
    """Numba threads for a case's mesh: ``requested`` (``--threads``) or ``NUMBA_NUM_THREADS``
    when given, else one thread below :data:`SMALL_MESH_TRIANGLES` triangles and all cores
    above. Returns the number of threads the kernels will use."""
    import numba

    if requested is None and "NUMBA_NUM_THREADS" not in os.environ and n_triangles < SMALL_MESH_TRIANGLES:
        numba.set_num_threads(1)
    return numba.get_num_threads()


def stop_cleanly_on_signals() -> None:
    """Make ``kill -TERM`` and ``kill -INT`` end a case as Ctrl-C does (the workflow keeps its
    stages, the case writes its summary, the solver ``interrupted_state.npz``). Needed because
    a run started in the background by a non-interactive shell ignores SIGINT, and SIGTERM
    would otherwise kill it without a word. Only in the main thread (signals go there)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"signal {signal.Signals(signum).name}")

    signal.signal(signal.SIGTERM, interrupt)
    signal.signal(signal.SIGINT, interrupt)


def cap_simulated_time(sim, t_max: float | None) -> None:
    """Stop every later :meth:`~fdem.solve.simulation.Simulation.run` of ``sim`` at simulated
    time ``t_max`` [s] (``None``: no cap): sets :attr:`Simulation.time_cap`. Stages end
    ``capped`` or ``completed`` at the cap; a factor-of-safety search restarts from its saved
    state, so each trial is capped alike."""
    if t_max is not None:
        sim.time_cap = float(t_max)


def time_capped(sim) -> bool:
    """True when ``sim`` ran up to its ``--max-time`` cap (:attr:`Simulation.time_capped`)."""
    return sim.time_capped


def use_density_scaling(sim, budget: float | None) -> None:
    """Run the quasi-static stages of ``sim`` density-scaled within ``budget`` (``--density-scaling``;
    0 or ``None``: on the real masses throughout)."""
    sim.density_scaling = budget or None
