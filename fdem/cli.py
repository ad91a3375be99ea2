"""The ``fdem`` command.

``fdem list``                       the cases it can run, one line each
``fdem run NAME [options]``         run a case (``fdem run NAME --help`` lists its options)
``fdem run FILE.toml [options]``    run a scene file (``docs/scenes.md``; ``fdem run scene --help``)
``fdem demo [options]``             the same as ``fdem run quick-start``
``fdem info FILE.msh``              quality report and crack-element counts of a mesh
``fdem --version``                  the installed version (``python -m fdem`` is the same command)

Every case takes ``--out``, ``--size``, ``--threads``, ``--max-time`` and ``--no-pictures``
(:mod:`fdem.cases.common`).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["main"]


def _list(args) -> int:
    from fdem.cases import CASES, describe

    width = max(len(n) for n in CASES)
    for name in CASES:
        print(f"{name:{width}s}  {describe(name)}")
    return 0


def _run_case(name: str, argv: list[str]) -> int:
    # --threads must reach NUMBA_NUM_THREADS before any kernel module imports numba
    from fdem.cases import case_module
    from fdem.cases.common import set_threads

    if name.endswith(".toml"):  # fdem run my_slope.toml: the scene runner
        name, argv = "scene", [name, *argv]

    for i, a in enumerate(argv):
        # (0 is left to the case's own check, which names the option)
        if a == "--threads" and i + 1 < len(argv) and argv[i + 1].isdigit() and int(argv[i + 1]) > 0:
            set_threads(int(argv[i + 1]))
        elif a.startswith("--threads=") and a.split("=", 1)[1].isdigit() and int(a.split("=", 1)[1]) > 0:
            set_threads(int(a.split("=", 1)[1]))
    try:
        module = case_module(name)
    except KeyError as err:
        print(f"fdem run: {err.args[0]}", file=sys.stderr)
        return 2
    return _ending(name, module.main, argv)


def _ending(name: str, main, argv: list[str]) -> int:
    """Run a case's ``main`` and turn how it ended into one message and an exit code
    (:func:`fdem.cases.common.exit_code`): a finished run by its summary's outcome; an
    interruption outside the time loop 130 / 143; a file that could not be written (a full
    disk, a folder made read-only) or an unstable run that the case did not catch, one line
    and 1; a ``--resume`` checkpoint of another mesh, model or contact law, one line and 2;
    never a chain of tracebacks. Anything else is a defect and keeps its traceback."""
    import signal

    from fdem.cases.common import exit_code
    from fdem.solve.checkpoint import CheckpointMismatch
    from fdem.solve.simulation import STOP, InstabilityError

    try:
        return exit_code(main(argv))
    except CheckpointMismatch as err:  # --resume of another scene, model or contact law: nothing was run
        print(f"fdem run {name}: cannot resume: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as stop:
        sig = STOP.received or "SIGINT"
        print(f"fdem run {name}: interrupted ({stop.args[0] if stop.args else sig}) before the run could "
              "write its summary", file=sys.stderr)
        return 128 + int(getattr(signal, sig, signal.SIGINT))
    except InstabilityError as err:
        print(f"fdem run {name}: the run went unstable: {err}", file=sys.stderr)
        return 1
    except OSError as err:
        what = f"{err.strerror} ({err.filename})" if err.strerror and err.filename else str(err)
        print(f"fdem run {name}: could not write: {what}; the files written before this one are kept", file=sys.stderr)
        return 1


def _run(args) -> int:
    return _run_case(args.case, args.options)


def _demo(args) -> int:
    return _run_case("quick-start", args.options)


def _info(args) -> int:
    from fdem.mesh.mesh import Mesh
    from fdem.mesh.quality import quality_report
    from fdem.mesh.topology import build_topology

    if not Path(args.mesh).is_file():
        print(f"fdem info: no mesh file {args.mesh}", file=sys.stderr)
        return 2
    mesh = Mesh.load(args.mesh)
    topo = build_topology(mesh)
    print(quality_report(mesh))
    print(f"crack elements {topo.n_cracks} ({int((topo.crack_tag > 0).sum())} on joints), "
          f"external edges {len(topo.boundary_edges)}, groups {list(mesh.group_names)}")
    return 0


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fdem")
    except PackageNotFoundError:  # run from a source tree that is not installed
        return "(not installed)"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="fdem", description="Hybrid finite-discrete element solver for rock slopes",
                                     epilog="fdem run NAME --help lists a case's options")
    parser.add_argument("--version", action="version", version=f"fdem {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="the cases fdem can run").set_defaults(func=_list)
    run = sub.add_parser("run", help="run a case: fdem run NAME [--out DIR --size H --threads N --max-time T "
                                     "--no-pictures ...]")
    run.add_argument("case", help="case name (fdem list)")
    run.add_argument("options", nargs=argparse.REMAINDER, help="the case's options")
    run.set_defaults(func=_run)
    demo = sub.add_parser("demo", help="run the quick-start slope (fdem run quick-start)", add_help=False)
    demo.add_argument("options", nargs=argparse.REMAINDER, help="options of the quick-start case")
    demo.set_defaults(func=_demo)
    info = sub.add_parser("info", help="quality report and crack-element counts of a .msh file")
    info.add_argument("mesh", type=Path)
    info.set_defaults(func=_info)
    argv = list(sys.argv[1:] if argv is None else argv)
    # a case parses its own options (argparse's REMAINDER would swallow none that start with --)
    if argv[:1] == ["demo"]:
        return _run_case("quick-start", argv[1:])
    if argv[:1] == ["run"] and len(argv) > 1 and not argv[1].startswith("-"):
        return _run_case(argv[1], argv[2:])
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except BrokenPipeError:  # `fdem list | head`: the reader left; end quietly, as a Unix tool does
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + 13  # SIGPIPE


if __name__ == "__main__":
    sys.exit(main())
