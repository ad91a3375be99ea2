"""What a run says goes through ``logging``: progress at INFO on standard output, warnings
prefixed, ``--quiet`` leaving only warnings and the result; an embedding program's own handler
on the ``fdem`` logger is kept."""
from __future__ import annotations

import logging

from fdem.io import messages


def test_progress_warnings_and_quiet(capsys):
    messages.configure(quiet=False)
    messages.say("meshed 12 triangles")
    messages.warn("dropped 3 joint segments")
    out = capsys.readouterr().out.splitlines()
    assert out == ["meshed 12 triangles", "warning: dropped 3 joint segments"]
    messages.configure(quiet=True)
    messages.say("time step 1e-5 s")
    messages.warn("a penalty sets the step")
    assert capsys.readouterr().out.splitlines() == ["warning: a penalty sets the step"]
    messages.configure(quiet=False)


def test_an_embedding_programs_handler_is_kept(capsys):
    records = []

    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record.getMessage())

    own = Keep()
    logger = logging.getLogger("fdem")
    saved = list(logger.handlers)
    for h in saved:
        logger.removeHandler(h)
    logger.addHandler(own)
    try:
        messages.configure(quiet=False)
        messages.say("cost estimate")
        assert records == ["cost estimate"] and capsys.readouterr().out == ""
    finally:
        logger.removeHandler(own)
        for h in saved:
            logger.addHandler(h)


def test_every_case_takes_quiet():
    """``--quiet`` is accepted by every case's parser (the shared parser gives it; the cases with
    their own parsers add it)."""
    import argparse
    import contextlib
    import io

    import pytest

    from fdem.cases import CASES, case_module

    class Parsed(Exception):
        pass

    original = argparse.ArgumentParser.parse_args

    def parse_then_stop(self, args=None, namespace=None):
        ns = original(self, args, namespace)
        raise Parsed(ns)

    argparse.ArgumentParser.parse_args = parse_then_stop
    try:
        for name in CASES:
            argv = ["--quiet"] + (["x.toml"] if name == "scene" else [])
            with contextlib.redirect_stderr(io.StringIO()), pytest.raises(Parsed) as got:
                case_module(name).main(argv)
            assert got.value.args[0].quiet is True, name
    finally:
        argparse.ArgumentParser.parse_args = original
