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
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

__all__ = ["case_parser", "set_threads", "cap_simulated_time", "time_capped"]


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
    return parser


def check_common(parser: argparse.ArgumentParser, args) -> None:
    """Refuse bad values of the shared options before anything long starts."""
    if args.size is not None and not (math.isfinite(args.size) and args.size > 0):
        parser.error(f"--size must be a positive number of metres, got {args.size}")
    if args.threads is not None and args.threads < 1:
        parser.error(f"--threads must be at least 1, got {args.threads}")
    if args.max_time is not None and not (math.isfinite(args.max_time) and args.max_time > 0):
        parser.error(f"--max-time must be a positive number of seconds, got {args.max_time}")


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


def cap_simulated_time(sim, t_max: float | None) -> None:
    """Stop every later :meth:`~fdem.solver.Simulation.run` of ``sim`` at simulated time
    ``t_max`` [s] (``None``: no cap). Stages end ``capped`` or ``completed`` at the cap; a
    factor-of-safety search restarts from its saved state, so each trial is capped alike."""
    if t_max is None:
        return
    run = sim.run

    def capped(n_steps=None, t_end=None, **kwargs):
        if t_end is not None:
            t_end = min(t_end, t_max)
        elif n_steps is not None:
            n_steps = min(n_steps, max(0, math.ceil((t_max - sim.state.time) / sim.dt - 1e-9)))
        return run(n_steps=n_steps, t_end=t_end, **kwargs)

    sim.run = capped
    sim.time_cap = float(t_max)


def time_capped(sim) -> bool:
    """True when ``sim`` ran up to its ``--max-time`` cap."""
    cap = getattr(sim, "time_cap", None)
    return cap is not None and sim.state.time >= cap - 0.5 * sim.dt
