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
``--overwrite``      replace the run already in ``--out`` (without it such a folder is refused)

The slope cases (their workflow is resumable, :mod:`fdem.workflow.journal`) also take

``--resume DIR``     continue the run in ``DIR`` from its ``checkpoint.npz``, with the options it
                     started with (``run.json``); only ``--threads``, ``--quiet``,
                     ``--no-pictures``, ``--checkpoint-every``, ``--yes``, ``--backend`` (a
                     run checkpointed on the CPU resumes on the GPU and back) and the time-step
                     factors ``--dt-fraction`` / ``--runout-dt-fraction`` (after an unstable
                     run: a smaller step) may be given again
``--backend cpu|cuda``  where the steps run: Numba on the CPU (default) or an NVIDIA GPU
                     through numba-cuda (:mod:`fdem.solve.cuda_backend`); ``cuda`` on a machine
                     without a GPU is a bad option (exit code 2)
``--dt-fraction F``   time-step factor of the quasi-static stages, a fraction of the critical step
                     (default 0.8)
``--checkpoint-every S``  wall-clock seconds between periodic checkpoints inside a stage
                     (default 600; a checkpoint is also written at every stage end and on every
                     interruption)

Every run writes ``run.json`` (the case, its options, when it started and how it ended) before
any meshing, after checking that ``--out`` can be written. The command's exit code says how the
run ended (:func:`exit_code`): 0 finished (whatever the slope did), 1 error or unstable run,
2 bad options, 130 / 143 interrupted by SIGINT / SIGTERM (resumable).
"""
from __future__ import annotations

from fdem.io.messages import say, warn

import argparse
import math
import os
import sys
from pathlib import Path

from fdem.solve.cuda_backend import BACKENDS, BackendError
from fdem.solve.simulation import set_default_backend

__all__ = ["case_parser", "set_threads", "threads_for_mesh", "cap_simulated_time", "time_capped",
           "stop_cleanly_on_signals", "use_density_scaling", "check_common", "add_resume_options",
           "prepare_run", "other_writer", "sign_journal", "open_run", "start_journal", "finish_run", "exit_code", "RUN_FILE", "OUTPUT_SUFFIXES",
           "check_mesh_size", "report_cost", "report_runout_cost", "CONFIRM_ABOVE_HOURS", "write_report",
           "add_write_scene_option", "write_case_scene", "add_number_options"]

CONFIRM_ABOVE_HOURS = 12.0
"""A run whose estimated wall time is above this asks for ``--yes`` (refused without it when no
one is at a terminal to answer)."""

RUN_FILE = "run.json"
"""The file in a run's output folder that says which case ran it, with which options, and how it ended."""

OUTPUT_SUFFIXES = (".vtu", ".pvd", ".png", ".npz", ".csv", ".json", ".msh", ".gif", ".tmp")
"""What ``--overwrite`` removes from the top of an output folder that holds an earlier run."""

RESUME_OPTIONS = ("--threads", "--quiet", "--no-pictures", "--checkpoint-every", "--yes", "--dt-fraction",
                  "--runout-dt-fraction", "--backend")
"""The options that ``--resume`` accepts beside it (the others come from the run's ``run.json``)."""

CARRY_ON_OPTION = "--runout-time"
"""The option that ``--resume`` accepts for a *finished* run whose runout ran to its cap while
still moving: the longer cap it is carried on to (:meth:`fdem.workflow.journal.RunJournal.carry_on`).
A run to rest is hours at paper scale; started again with a longer cap it would repeat them."""

SMALL_MESH_TRIANGLES = 20_000
"""Below this many triangles a case runs on one Numba thread unless ``--threads`` (or
``NUMBA_NUM_THREADS``) says otherwise: a step of a small mesh lasts well under a millisecond,
the fork-join of each parallel kernel is a large part of it, and when another process shares
the cores the threads' spin-waiting collapses it (quick-start scene, 1,503 triangles, load
average 3 on 2 cores: 8.2 ms per damped step on 2 threads against 0.5-0.7 ms on 1, GNU
OpenMP). Under TBB (the layer ``import fdem`` sets up, :mod:`fdem.kernels.threading_layer`) a
second thread gains 1.87x at 22,600 triangles on an idle machine and loses 13 % beside another
job, and gains 1.75x and 1.46x at 180,000 (``cases/benchmarks/bench_threads.py``,
``docs/benchmarks.md``, "Threads on a shared machine")."""


def case_parser(doc: str | None, out: str, size: float | None, size_help: str,
                name: str | None = None) -> argparse.ArgumentParser:
    """An ``argparse`` parser with the shared options; a case adds its own after these.
    ``name``: the case's name in ``fdem run NAME`` (its usage line says so under ``fdem``)."""
    prog = f"fdem run {name}" if name and Path(sys.argv[0]).name in ("fdem", "__main__.py") else None
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
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the earlier run in --out (its frames, pictures, checkpoints and summary)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars, only warnings and the result")
    parser.add_argument("--backend", choices=BACKENDS, default="cpu",
                        help="where the steps run: cpu (Numba, default) or cuda (an NVIDIA GPU through numba-cuda; "
                             "the same laws, docs/gpu.md)")
    return parser


def add_number_options(parser: argparse.ArgumentParser, defaults: dict, rows) -> None:
    """One ``--option`` (a float) per row ``(option, key, unit, meaning)``, defaulting to
    ``defaults[key]``, its help saying the meaning, the unit and the default: the material and
    strength options of the calibration scenes."""
    for opt, key, unit, what in rows:
        parser.add_argument(opt, type=float, default=defaults[key], help=f"{what} [{unit}] (default {defaults[key]:g})")


def add_write_scene_option(parser: argparse.ArgumentParser) -> None:
    """``--write-scene FILE``: a slope case writes its scene as a scene file and stops
    (:func:`write_case_scene`); ``fdem run FILE`` then runs the same model."""
    parser.add_argument("--write-scene", type=Path, default=None, metavar="FILE",
                        help="write this case, with the options given, as a scene file (fdem run FILE runs it) "
                             "and stop")


def write_case_scene(parser: argparse.ArgumentParser, name: str, scene: dict, path: Path, argv) -> dict:
    """Check the case's ``scene`` (a raw scene ``dict`` as a TOML file holds it; ``None`` values
    are left out) with :func:`fdem.scene.schema.check_scene` and write it to ``path``; returns
    the summary of that ending (outcome ``scene written``). A scene the schema refuses is a
    defect of the case and raises."""
    from fdem.scene.schema import check_scene
    from fdem.scene.write import write_scene

    def drop_none(v):
        if isinstance(v, dict):
            return {k: drop_none(x) for k, x in v.items() if x is not None}
        if isinstance(v, list):
            return [drop_none(x) for x in v]
        return v

    scene = drop_none(scene)
    check_scene(scene, path)
    argv = list(sys.argv[1:] if argv is None else argv)
    shown = " ".join(a for i, a in enumerate(argv) if a != "--write-scene" and not a.startswith("--write-scene=")
                     and not (i and argv[i - 1] == "--write-scene"))
    title = (f"fdem run {name} {shown}".rstrip() + f", written as a scene file.\nRun it with: fdem run {path}\n"
             "Every key, its unit and range: docs/scenes.md")
    try:
        write_scene(path, scene, title=title)
    except OSError as err:
        parser.error(f"--write-scene {path}: {err.strerror or err}")
    print(f"wrote {path}; run it with: fdem run {path}")
    return {"case": name, "outcome": "scene written", "scene_file": str(path)}


def add_resume_options(parser: argparse.ArgumentParser) -> None:
    """``--resume``, ``--checkpoint-every`` and ``--yes``: the options of a resumable case."""
    parser.add_argument("--resume", type=Path, default=None, metavar="DIR",
                        help="continue the run in DIR from its checkpoint.npz with the options it started with "
                             f"(only {', '.join(RESUME_OPTIONS)} may be given again)")
    parser.add_argument("--checkpoint-every", type=float, default=600.0, metavar="SECONDS",
                        help="wall-clock seconds between periodic checkpoints inside a stage (default 600; "
                             "checkpoints are also written at every stage end and interruption)")
    parser.add_argument("--dt-fraction", type=float, default=0.8, metavar="FACTOR",
                        help="time-step factor of the quasi-static stages, a fraction of the critical step "
                             "(default 0.8; resume an unstable run with a smaller one)")
    parser.add_argument("--yes", action="store_true", help="run even when the cost estimate is above the threshold")


def check_common(parser: argparse.ArgumentParser, args) -> None:
    """Refuse bad values of the shared options before anything long starts (``--size`` may be
    one number or, for the cases that sweep sizes, a list), and set how much the run says
    (:func:`fdem.io.messages.configure`: ``--quiet`` leaves only warnings and the result)."""
    from fdem.io.messages import configure

    configure(quiet=getattr(args, "quiet", False))
    try:  # a GPU asked for where there is none stops here, before any meshing
        set_default_backend(getattr(args, "backend", "cpu"))
    except BackendError as err:
        parser.error(f"--backend {args.backend}: {err}")
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
    fraction = getattr(args, "dt_fraction", 0.8)
    if not (math.isfinite(fraction) and 0.0 < fraction <= 1.0):
        parser.error(f"--dt-fraction (time-step factor) must lie in (0, 1], got {fraction}")
    every = getattr(args, "checkpoint_every", None)
    if every is not None and not (math.isfinite(every) and every >= 0):
        parser.error(f"--checkpoint-every must be a number of seconds >= 0 (0: only at stage ends), got {every}")


# ----------------------------------------------------------------------------- run folder
def _option_names(argv) -> list[str]:
    return [a.split("=", 1)[0] for a in argv if a.startswith("--")]


def _check_carry_on(parser, folder: Path, argv) -> None:
    """Refuse ``--resume DIR --runout-time T`` (before any meshing) unless the run's last stage is
    a runout that ran to its cap, and ``T`` is longer than the time it ran."""
    import json

    i = [a.split("=", 1)[0] for a in argv].index(CARRY_ON_OPTION)
    text = argv[i].split("=", 1)[1] if "=" in argv[i] else (argv[i + 1] if i + 1 < len(argv) else "")
    try:
        cap = float(text)
    except ValueError:
        cap = float("nan")
    if not (math.isfinite(cap) and cap > 0):  # before run.json is touched: a bad cap must not leave it "running"
        parser.error(f"{CARRY_ON_OPTION} must be a positive number of simulated seconds, got {text!r}")
    try:
        stages = json.loads((folder / "summary.json").read_text())["workflow"]["stages"]
    except (OSError, ValueError, KeyError, TypeError):
        parser.error(f"--resume {folder} {CARRY_ON_OPTION}: no summary.json with the run's stages there")
    from fdem.workflow.journal import CARRIED_ENDINGS

    last = stages[-1] if stages else {}
    if not str(last.get("name", "")).startswith("runout") or last.get("reason") not in CARRIED_ENDINGS:
        parser.error(f"--resume {folder} {CARRY_ON_OPTION}: the run's last stage is {last.get('name')!r}, which "
                     f"ended {last.get('reason')!r}; only a runout that ran to its cap (or off the model) can be "
                     f"carried on")
    ran = float(last["t_end"]) - float(last["t_start"])
    if not cap > ran:
        parser.error(f"--resume {folder} {CARRY_ON_OPTION} {text}: the runout already ran {ran:.4g} s; give a "
                     f"longer cap")


def _read_run_file(folder: Path) -> dict:
    import json

    try:
        return json.loads((folder / RUN_FILE).read_text())
    except (OSError, ValueError):
        return {}


def prepare_run(parser: argparse.ArgumentParser, args, argv, name: str, open_now: bool = True):
    """Check the output folder before any work and write ``run.json``; returns ``args``.

    ``open_now=False`` only resolves ``--resume`` (the options it restores) and leaves the
    folder and ``run.json`` to :func:`open_run`, for a case that checks more of its own options
    first: a refused option must not leave a ``run.json`` behind.

    With ``--resume DIR`` the options come from ``DIR/run.json`` (the run must be this case's,
    not finished, with its ``checkpoint.npz``), plus the few a resume may change
    (:data:`RESUME_OPTIONS`). Otherwise ``--out`` must be a folder that can be created and
    written, and must not hold another run unless ``--overwrite`` (which removes that run's
    outputs first, so that old frames never mix with new ones). Every refusal is a
    ``parser.error`` (exit code 2) naming the folder and what to do. ``parser=None``: the case
    checked its options itself (a ``parse_args`` function); errors then name ``fdem run NAME``."""
    import sys as _sys

    argv = list(_sys.argv[1:] if argv is None else argv)
    if parser is None:
        parser = argparse.ArgumentParser(prog=f"fdem run {name}")
    else:
        check_common(parser, args)  # the options first: a bad one is named before the folder is looked at
    resume = getattr(args, "resume", None)
    if resume is not None:
        folder = Path(resume)
        record = _read_run_file(folder)
        if not record:
            parser.error(f"--resume {folder}: no readable {RUN_FILE} there; is it the --out folder of a run?")
        if record.get("case") != name:
            parser.error(f"--resume {folder}: that folder holds a run of {record.get('case')!r}, not {name!r}")
        # checkpoint.npz, or a search's own (search_checkpoint.npz, a run stopped in its search)
        if not any(folder.glob("*checkpoint.npz")) and not any(folder.glob("*/*checkpoint.npz")):
            parser.error(f"--resume {folder}: no checkpoint.npz there (the run wrote none before it stopped)")
        finished = record.get("outcome") not in (None, "interrupted", "unstable", "running", "error", "write_error")
        carry_on = CARRY_ON_OPTION in _option_names(argv)
        if finished and not carry_on:
            parser.error(f"--resume {folder}: that run has finished (outcome {record['outcome']!r}); nothing to resume"
                         f" (a runout that ran to its cap still moving is carried on with {CARRY_ON_OPTION} SECONDS)")
        if carry_on and not finished:
            parser.error(f"--resume {folder} {CARRY_ON_OPTION}: a longer runout cap carries a finished run's capped "
                         f"runout on; this run has not finished (outcome {record.get('outcome')!r}): resume it as it is")
        if carry_on and record.get("outcome") == "time_capped":
            parser.error(f"--resume {folder} {CARRY_ON_OPTION}: that run ended by its own --max-time, not by its "
                         f"runout cap; run it again without --max-time")
        if carry_on:
            _check_carry_on(parser, folder, argv)
        others = [o for o in _option_names(argv)
                  if o not in RESUME_OPTIONS + ("--resume",) + ((CARRY_ON_OPTION,) if carry_on else ())]
        if others:
            parser.error(f"--resume takes the run's own options from {folder / RUN_FILE}; only "
                         f"{', '.join(RESUME_OPTIONS)} may be given again, not {', '.join(others)}")
        again = [a for i, a in enumerate(argv) if not (a == "--resume" or a.startswith("--resume=")
                                                      or (i and argv[i - 1] == "--resume"))]
        args = parser.parse_args(list(record.get("argv", [])) + again)
        args.resume, args.out, args.overwrite = folder, folder, False
        args.carry_on = carry_on
        if carry_on:  # the new cap is the run's own from now on (a later resume takes it from run.json)
            kept = list(record.get("argv", []))
            if CARRY_ON_OPTION in kept:
                i = kept.index(CARRY_ON_OPTION)
                del kept[i:i + 2]
            record["argv"] = kept + [CARRY_ON_OPTION, repr(float(getattr(args, "runout_time")))]
        check_common(parser, args)
        record.update(status="running", outcome="running", resumed=record.get("resumed", 0) + 1,
                      resumed_with=again, resumed_at=_now())
        record["resumed_sources"] = record.get("resumed_sources", []) + [_source()]
        args.run_record = record
    else:
        args.run_record = {"case": name, "argv": [a for a in argv if a != "--overwrite"]}
    if open_now:
        open_run(parser, args, name)
    return args


def other_writer(wrote: dict | None, now: dict | None) -> str | None:
    """What to tell a resume whose code (``now``, :func:`_source`) is not the commit that wrote
    the checkpoint (``wrote``, the source the checkpoint itself names:
    :attr:`fdem.workflow.journal.RunJournal.written_by`), or ``None`` when both are the same
    commit or either is unknown (a checkpoint written before it named its writer, an installed
    package). A commit that changed what a checkpoint holds (a search's key, a stage's runtime)
    refuses it or reads it wrongly; the writer is named so that a pinned checkout of it can go on."""
    now, wrote = (now or {}).get("commit"), (wrote or {}).get("commit")
    if not now or not wrote or now == wrote:
        return None
    return (f"this is commit {now[:10]}, the checkpoint was written by {wrote[:10]}; if the code between them "
            f"changed what a checkpoint holds, resume from a checkout of {wrote[:10]} (PYTHONPATH=<checkout>)")


def open_run(parser: argparse.ArgumentParser | None, args, name: str) -> None:
    """The folder part of :func:`prepare_run`: probe ``--out``, refuse or clear an earlier run,
    write ``run.json`` (or, resuming, update it)."""
    if parser is None:
        parser = argparse.ArgumentParser(prog=f"fdem run {name}")
    record = args.run_record
    if getattr(args, "resume", None) is not None:
        _write_run_file(parser, Path(args.out), record)
        return
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        parser.error(f"--out {out} is a file, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".fdem_write_probe"
        probe.write_bytes(b"0")
        probe.unlink()
    except OSError as err:
        parser.error(f"--out {out} cannot be written: {err.strerror or err}")
    earlier = _read_run_file(out)
    held = earlier or (out / "summary.json").exists() or any(out.glob("*.pvd"))
    ours = bool(earlier.get("case")) or _summary_case(out) is not None
    if held and not getattr(args, "overwrite", False):
        what = (f"a run of {earlier.get('case')!r} started {earlier.get('started')} (outcome {earlier.get('outcome')})"
                if earlier else "the outputs of an earlier run")
        parser.error(f"--out {out} holds {what}; give --overwrite to replace it"
                     + (f", --resume {out} to continue it" if earlier.get("outcome") in ("interrupted", "unstable",
                                                                                            "running") else "")
                     + ", or another --out")
    if held and not ours:
        # --overwrite deletes files: only in a folder that an fdem run made, never in a user's own
        parser.error(f"--out {out} holds a summary.json or .pvd series that fdem did not write (no run.json, no "
                     "case in the summary); --overwrite clears only fdem's own run folders: choose another --out")
    if held:
        for f in out.iterdir():
            if f.is_file() and (f.suffix in OUTPUT_SUFFIXES or f.name.endswith(".tmp.npz")):
                f.unlink()
    _write_run_file(parser, out, {**record, "started": _now(), "outcome": "running", "fdem_version": _version(),
                                  "source": _source(), "pid": os.getpid()})


def _summary_case(folder: Path):
    """The ``case`` of ``folder/summary.json`` (runs written before ``run.json`` existed), or ``None``."""
    import json

    try:
        case = json.loads((folder / "summary.json").read_text()).get("case")
    except (OSError, ValueError, AttributeError):
        return None
    return case if isinstance(case, str) else None


def _now() -> str:
    import time as _time

    return _time.strftime("%Y-%m-%dT%H:%M:%S%z")


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("fdem")
    except Exception:  # not installed (run from a source tree)
        return "unknown"


def _source() -> dict:
    """Which code this process runs: the ``path`` of the imported ``fdem`` package and, when it
    lies in a Git checkout, its ``commit`` and whether ``fdem/`` differs from it (``modified``),
    with the contact law (:data:`fdem.physics.contact.CONTACT_LAW`). A row of a results table is
    then traced to the build that made it, also when runs are carried on from pinned checkouts
    of older commits; ``commit`` is ``None`` for an installed package."""
    import subprocess

    from fdem.physics.contact import CONTACT_LAW

    package = Path(__file__).resolve().parents[1]
    out = {"path": str(package), "commit": None, "modified": None, "contact_law": CONTACT_LAW}
    # only the checkout the package itself lies in (a package installed into a virtual
    # environment inside some checkout is not that checkout's code); no index lock taken, so a
    # commit made meanwhile in the same checkout is never refused
    env = {k: v for k, v in os.environ.items() if k not in ("GIT_DIR", "GIT_WORK_TREE", "GIT_INDEX_FILE")}
    git = ["git", "--no-optional-locks", "-C", str(package.parent)]

    def ask(*args) -> str | None:
        done = subprocess.run(git + list(args), capture_output=True, text=True, timeout=10, env=env)
        return done.stdout.strip() if done.returncode == 0 else None

    try:
        top = ask("rev-parse", "--show-toplevel")
        if top is not None and Path(top).resolve() == package.parent:
            out["commit"] = ask("rev-parse", "HEAD")
            changes = ask("status", "--porcelain", "--", "fdem")
            out["modified"] = None if changes is None else bool(changes)
    except (OSError, subprocess.SubprocessError):
        pass  # no git: the path and the law are still worth keeping
    return out


ROOM_FILE = ".fdem_room"
ROOM_BYTES = 64 * 1024
"""A run keeps this much room in its folder from its start (``ROOM_FILE``) and gives it back
when the disk fills, so that the ``summary.json`` and ``run.json`` of a run stopped by a full
disk (at most about 20 KB) are still written; the file goes when the run ends."""


def _write_run_file(parser, folder: Path, record: dict) -> None:
    from fdem.io.jsonable import write_json

    try:
        write_json(folder / RUN_FILE, record)
    except OSError as err:
        parser.error(f"cannot write {folder / RUN_FILE}: {err.strerror or err}")
    try:
        (folder / ROOM_FILE).write_bytes(bytes(ROOM_BYTES))
    except OSError:
        _give_room_back(folder)  # a disk that cannot take it now fails the run's first write anyway


def _give_room_back(folder) -> None:
    """Delete the room a run kept in ``folder`` (:data:`ROOM_FILE`), for its last words."""
    try:
        (Path(folder) / ROOM_FILE).unlink(missing_ok=True)
    except OSError:
        pass


def check_mesh_size(parser: argparse.ArgumentParser, geometry, size: float) -> int:
    """Refuse, before meshing, an element size whose mesh would not fit in the free memory
    (:func:`fdem.solve.cost.check_mesh_budget`); returns the estimated triangle count."""
    from fdem.geometry.polygons import signed_area
    from fdem.solve.cost import check_mesh_budget, estimate_triangles

    area = sum(abs(signed_area(b.vertices)) for b in geometry.bodies)
    n = estimate_triangles(area, size)
    try:
        check_mesh_budget(n)
    except ValueError as err:
        parser.error(f"--size {size}: {err}")
    return n


def report_runout_cost(parser: argparse.ArgumentParser, sim, args, workflow) -> dict:
    """:func:`report_cost` for the slope workflow's runout stage at its cap and its own step
    (the longest stage by far: the quasi-static stages run density-scaled at a larger step); for
    a run whose analysis is the factor-of-safety search (``reduction = "none"``), the equilibrium
    at F = 1 (capped at :attr:`fdem.workflow.slope.StageRules.equilibrium_time`, 10 response
    times unless the trials are longer) and the
    search at its most (:func:`fdem.workflow.fos.most_trials` trials, each capped at ``step_time``,
    default 5 response times)."""
    import numpy as np

    from fdem.workflow.slope import runout_stage, stage_rules
    from fdem.workflow.stages import response_time

    height = float(np.ptp(sim.model.topology.x0[:, 1]))
    g = float(np.linalg.norm(sim.gravity)) or 9.81
    runout_cap = runout_stage(workflow, response_time(sim.model), height, g).max_time
    if workflow.reduction == "none":
        from fdem.workflow.fos import most_trials

        trials = most_trials(*workflow.fos)
        rules = stage_rules(sim, workflow)
        cap, equilibrium = rules.step_time, rules.equilibrium_time
        # a trial followed to rest goes on, undamped, for at most the runout's cap
        follow = runout_cap if workflow.trial_rule == "rest" else 0.0
        return report_cost(parser, sim, args, equilibrium + trials * (cap + follow),
                           f"the equilibrium at F = 1 and the factor-of-safety search, at most {equilibrium:.3g} s "
                           f"and {trials} trials of up to {cap:.3g} s simulated"
                           + (f", each followed to rest for up to {follow:.3g} s more" if follow else ""))
    cap = runout_cap
    return report_cost(parser, sim, args, cap, f"the runout stage, up to {cap:.3g} s simulated",
                       dt_fraction=workflow.runout_dt_fraction, step_from=workflow.runout_step)


def report_cost(parser: argparse.ArgumentParser, sim, args, simulated_seconds: float, what: str,
                dt_fraction: float | None = None, step_from: str = "bound") -> dict:
    """Print (and return, for the summary) the cost estimate of ``sim`` before any stepping:
    the step and what sets it, steps and wall time for ``simulated_seconds`` of ``what``, the
    memory (:func:`fdem.solve.cost.estimate_cost`), and a warning when a penalty cuts the step
    far below the triangles'. Above :data:`CONFIRM_ABOVE_HOURS` of wall time the run needs
    ``--yes`` (or a "y" at the terminal), so that an option mistaken by 10x is found now.

    ``dt_fraction``: the stage's factor on its critical step; ``step_from="measured"``: that
    step is the one measured on the model now (:func:`fdem.solve.step_probe.critical_or_bounds`,
    the probe the stage makes when it starts: on three four-slope scenes the limit at the start
    was the one at rest to 1e-4, on the fourth 1.57x under it, its limiting element having
    broken, ``docs/benchmarks/stable_step_margin.json``; so this prices a runout at or above its
    cost), the bounds when the probe fails."""
    from fdem.solve.cost import dt_warning, estimate_cost

    step, held = sim.dt, sim.measured_critical
    try:
        if dt_fraction is not None:  # the stage's own step
            sim.dt = dt_fraction * sim.critical_dt()[0]
        estimate = warned = estimate_cost(sim, simulated_seconds=simulated_seconds)  # the bounds, by source
        if dt_fraction is not None and step_from == "measured" and sim.user_dt is None:
            from fdem.solve.step_probe import critical_or_bounds

            sim.measured_critical, why = critical_or_bounds(sim)
            if sim.measured_critical is not None:
                what += ", stepped from the critical step measured now"
                sim.dt = dt_fraction * sim.critical_dt()[0]
                estimate = estimate_cost(sim, simulated_seconds=simulated_seconds)
            else:
                what += f" ({why})"
    finally:
        sim.dt, sim.measured_critical = step, held
    say(f"cost estimate ({what}):\n  " + estimate.describe().replace("\n", "\n  "))
    warning = dt_warning(warned)  # a penalty far stiffer than the rock: read off the bounds' sources
    if warning:
        warn(warning)
    hours = (estimate.wall_seconds or 0.0) / 3600.0
    if hours > CONFIRM_ABOVE_HOURS and not getattr(args, "yes", False) and getattr(args, "resume", None) is None:
        question = (f"the estimate is {hours:.1f} h of wall time (above {CONFIRM_ABOVE_HOURS:g} h)")
        if sys.stdin.isatty():
            if input(f"{question}; run it? [y/N] ").strip().lower() not in ("y", "yes"):
                parser.error(f"{question}; not started")
        else:
            parser.error(f"{question}; give --yes to run it anyway")
    return {**estimate.as_dict(), "for": what, "warning": warning}


def start_journal(sim, args, folder=None):
    """The run's :class:`fdem.workflow.journal.RunJournal` in ``folder`` (default ``--out``):
    loaded from ``--resume``'s checkpoint into ``sim`` (its frames and history continued) when
    the folder has one, else a new one writing ``checkpoint.npz`` there every
    ``--checkpoint-every`` seconds. Sets the simulation's ``--dt-fraction``."""
    from fdem.workflow.journal import CHECKPOINT_NAME, RunJournal

    every = getattr(args, "checkpoint_every", None) or None
    path = Path(folder if folder is not None else args.out) / CHECKPOINT_NAME
    sim.dt_fraction = getattr(args, "dt_fraction", sim.dt_fraction)
    if getattr(args, "resume", None) is not None and path.is_file():
        journal = sign_journal(RunJournal.resume_from(sim, path, every), path)
        if getattr(args, "carry_on", False):  # checked against summary.json by prepare_run
            from fdem.solve.checkpoint import read_checkpoint

            last = journal.carry_on(sim, "runout", lambda: read_checkpoint(path.with_name("runout_start.npz"))["state"]["x"])
            # on disk at once: a carry-on stopped before its first periodic checkpoint (an
            # instability, a signal) resumes as a carry-on, not as the capped run it began from
            runtime = dict(journal.resume)
            journal.current = lambda: runtime
            journal.write(sim, "carried on")
            journal.current = None
            say(f"carrying the {last['name']} stage on from t = {sim.state.time:.6g} s to a cap of "
                f"{args.runout_time:g} s (it ran {last['t_end'] - last['t_start']:.4g} s to its cap)")
        sim.continue_outputs()
        say(f"resumed from {path} at step {sim.state.step} (t = {sim.state.time:.6g} s): "
              f"{len(journal.done)} stage(s) done" + (f", {journal.resume['name']} in progress" if journal.resume else ""))
        return journal
    return sign_journal(RunJournal(path, every))


def sign_journal(journal, resumed: Path | None = None):
    """``journal`` with this code (:func:`_source`) as the writer its checkpoints name, for a
    resume to compare; when it was ``resumed`` from the checkpoint at that path, warns if
    another commit wrote it (:func:`other_writer`). Returns the journal."""
    source = _source()
    journal.writer = source
    if resumed is not None:
        note = other_writer(journal.written_by, source)
        if note:
            warn(f"--resume {Path(resumed).parent}: {note}")
    return journal


def save_final_state(sim, out, outcome: str) -> Path | None:
    """``final_state.npz`` in ``out``: the end state of a slope run, to restart from or look at
    (:func:`fdem.solve.checkpoint.save_checkpoint`). Not written where there is no state worth
    keeping (``unstable``: the journal's ``checkpoint.npz`` holds the last good one;
    ``write_error``: no room) nor where another file already holds it (``interrupted``:
    ``checkpoint.npz``, a factor-of-safety trial cut short included): at
    326,755 triangles each copy is over 100 MB and seconds of writing, time in which a
    supervisor's SIGKILL may follow its SIGTERM. Returns the path written, or None."""
    if outcome in ("unstable", "write_error", "interrupted"):
        return None
    from fdem.solve.checkpoint import save_checkpoint

    return save_checkpoint(sim, Path(out) / "final_state.npz")


def failing_factor_words(summary: dict) -> str:
    """``", failed at F = 1.430"`` for the result line of a slope case; an ``undecided`` run (its
    stage at F did not settle and its runout was capped before it told a creep from a collapse)
    says ``", did not settle at F = 1.430"``; nothing when no factor failed."""
    F = summary.get("failed_at_factor")
    if not F:
        return ""
    return f", {'did not settle' if summary.get('outcome') == 'undecided' else 'failed'} at F = {F:.3f}"


def exit_code(summary) -> int:
    """The command's exit code for a case's summary: 130 / 143 interrupted by SIGINT / SIGTERM,
    1 unstable (or any outcome ``error``), 0 otherwise (the run finished, whatever the slope did)."""
    outcome = summary.get("outcome") if isinstance(summary, dict) else None
    if outcome == "interrupted":
        import signal

        from fdem.solve.simulation import STOP

        name = STOP.received or "SIGINT"
        return 128 + int(getattr(signal, name, signal.SIGINT))
    return 1 if outcome in ("unstable", "error", "write_error") else 0


def write_report(report, out, extra: dict, pictures_on: bool) -> dict:
    """``report.write(out, extra=..., pictures_on=...)`` (:class:`fdem.results.report.RunReport`),
    or, when a file cannot be written (a full disk, a folder gone read-only), the summary the run
    still has, with outcome ``write_error`` and the reason, written if the disk takes it."""
    from fdem.io.jsonable import write_json

    try:
        return report.write(out, extra=extra, pictures_on=pictures_on)
    except OSError as err:
        what = f"{err.strerror} ({err.filename})" if err.strerror and err.filename else str(err)
        summary = {**extra, "outcome": "write_error", "ending": f"could not write the outputs: {what}"}
        print(f"could not write the outputs: {what}", file=sys.stderr)
        _give_room_back(out)
        try:
            write_json(Path(out) / "summary.json", summary)
        except OSError:
            pass
        return summary


def finish_run(out, summary: dict) -> None:
    """Say in ``run.json`` how the run ended (outcome, ending, exit code, when), and, for an
    ending that is not a finish, print why and how to resume."""
    from fdem.io.jsonable import write_json

    _give_room_back(out)
    if summary.get("outcome") in ("interrupted", "unstable", "write_error"):
        record = _read_run_file(Path(out))
        print(f"{summary['outcome']}: {summary.get('ending')}\nresume with: fdem run {record.get('case', 'NAME')} "
              f"--resume {out}" + (" --dt-fraction 0.4 (a smaller step)" if summary["outcome"] == "unstable" else ""),
              file=sys.stderr)
    folder = Path(out)
    record = _read_run_file(folder)
    record.update(outcome=summary.get("outcome", "finished"), ending=summary.get("ending"),
                  exit_code=exit_code(summary), ended=_now())
    try:
        write_json(folder / RUN_FILE, record)
    except OSError as err:
        print(f"could not update {folder / RUN_FILE}: {err.strerror or err}", file=sys.stderr)


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
    """Make ``kill -TERM`` and ``kill -INT`` (Ctrl-C) end a case cleanly: a running time loop
    stops at the next whole step (:class:`fdem.solve.simulation.StopRequest`), the workflow
    writes its checkpoint and keeps its stages, the case writes its summary and pictures, and
    the command exits 130 / 143. A second signal stops at once. Needed because a run started
    in the background by a non-interactive shell ignores SIGINT, and SIGTERM would otherwise
    kill it without a word. Only in the main thread (signals go there)."""
    import signal
    import threading

    from fdem.solve.simulation import STOP

    if threading.current_thread() is not threading.main_thread():
        return
    STOP.__init__()  # a new run in this process: no stop asked, none received, none forced

    def interrupt(signum, frame):
        name = signal.Signals(signum).name
        if not STOP.ask(name):  # no time loop to stop at a step boundary, or asked twice
            raise KeyboardInterrupt(f"signal {name}")

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
