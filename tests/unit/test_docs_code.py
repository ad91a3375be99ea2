"""Every fenced code block of the README and ``docs/*.md`` is checked, so the docs cannot drift
from the code.

* ``python`` blocks run, in the order of their page, in one namespace per page (a later block
  continues an earlier one, as a reader types them), in a temporary working directory, on one
  Numba thread;
* ``bash`` (or ``sh``, ``console``, or unlabelled) blocks: every ``fdem ...`` command and every
  ``python cases/<case>.py ...`` is parsed by the case's own parser without running anything
  (the parser's ``parse_args`` is stopped right after it accepts the options, so an unknown
  option, a wrong choice or a missing value fails here); ``fdem list`` and ``fdem --version``
  run, ``fdem info FILE`` needs FILE in the repository;
* ``text`` blocks (and unlabelled blocks with no command in them) are formulas, not run;
* a block that is deliberately not run carries ``<!-- no-test: reason -->`` on the line before
  it; it is reported as skipped with its reason (``pytest -ra`` lists them).

A shell block with no command this file can check must carry the marker, so nothing is left
unchecked silently.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import shlex
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})[ \t]*(?P<info>[^\s`]*)")
NO_TEST = re.compile(r"<!--\s*no-test:\s*(?P<reason>.*?)\s*-->")
SHELL = {"bash", "sh", "shell", "console", ""}
NOT_CODE = {"text", "math", "none", "plain", "csv", "json", "toml", "ini", "yaml"}


@dataclass(frozen=True)
class Block:
    doc: str         # path relative to the repository
    line: int        # line of the opening fence (1-based)
    lang: str
    code: str
    skip: str | None  # the no-test reason, if marked

    @property
    def id(self) -> str:
        return f"{self.doc}:{self.line}"


def fenced_blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown file, with the no-test marker of the line before each."""
    lines = path.read_text(encoding="utf-8").splitlines()
    rel = path.relative_to(ROOT).as_posix()
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, info = m["indent"], m["fence"], m["info"].lower()
        prev = next((lines[k] for k in range(i - 1, -1, -1) if lines[k].strip()), "")
        marker = NO_TEST.search(prev)
        body, j = [], i + 1
        while j < len(lines) and not (lines[j].strip().startswith(fence[0] * len(fence))
                                      and lines[j].strip().strip(fence[0]) == ""):
            text = lines[j]
            body.append(text[len(indent):] if text.startswith(indent) else text.lstrip())
            j += 1
        if j == len(lines):
            raise AssertionError(f"{rel}:{i + 1}: code fence never closed")
        out.append(Block(rel, i + 1, info, "\n".join(body) + "\n", marker["reason"] if marker else None))
        i = j + 1
    return out


BLOCKS = [b for doc in DOCS for b in fenced_blocks(doc)]
PYTHON = [b for b in BLOCKS if b.lang in ("python", "py", "python3")]


# ----------------------------------------------------------------------------- shell commands
def commands(code: str) -> list[list[str]]:
    """The simple commands of a shell block: lines split at ``&&``, ``||``, ``;`` and ``|``,
    comments dropped, a leading ``$ `` prompt dropped."""
    found = []
    for line in code.splitlines():
        line = line.strip()
        if line.startswith("$ "):
            line = line[2:]
        if not line or line.startswith("#"):
            continue
        lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|")
        lexer.whitespace_split = True
        lexer.commenters = "#"
        part = []
        for tok in lexer:
            if tok and set(tok) <= set(";&|"):
                if part:
                    found.append(part)
                part = []
            else:
                part.append(tok)
        if part:
            found.append(part)
    return found


class _Parsed(Exception):
    """Raised by the patched ``parse_args`` once the case's parser accepted its options."""


def parse_case_options(name: str, argv: list[str]) -> str:
    """Parse ``argv`` with case ``name``'s own parser and stop before any work. Returns what was
    checked; fails the test with the parser's message if the options are refused."""
    from fdem.cases import case_module

    module = case_module(name)
    original = argparse.ArgumentParser.parse_args

    def parse_then_stop(self, args=None, namespace=None):
        original(self, args, namespace)
        raise _Parsed

    err = io.StringIO()
    argparse.ArgumentParser.parse_args = parse_then_stop
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            module.main(list(argv))
    except _Parsed:
        return f"fdem run {name}: options accepted"
    except SystemExit as stop:
        if stop.code in (0, None):  # --help
            return f"fdem run {name}: help"
        pytest.fail(f"fdem run {name} {' '.join(argv)}: the case's parser refuses it: {err.getvalue().strip().splitlines()[-1]}")
    finally:
        argparse.ArgumentParser.parse_args = original
    pytest.fail(f"fdem run {name}: main() returned without parsing its options")


def check_command(tokens: list[str]) -> str | None:
    """Check one command; ``None`` if it is not one this file can check (pip, venv, pytest...)."""
    from fdem.cases import CASES

    if tokens[0] == "fdem":
        args = tokens[1:]
        if args[:1] == ["demo"]:
            return parse_case_options("quick-start", args[1:])
        if args[:1] == ["run"] and len(args) > 1 and args[1].endswith(".toml"):
            # a scene file: the one in the repository must check; a user's own (my_slope.toml) is a name
            if (ROOT / args[1]).is_file():
                from fdem.scene.schema import read_scene

                read_scene(ROOT / args[1])
            return parse_case_options("scene", args[1:])
        if args[:1] == ["run"]:
            assert len(args) > 1, "fdem run needs a case name"
            assert args[1].replace("_", "-") in CASES, f"fdem run {args[1]}: no such case ({', '.join(CASES)})"
            return parse_case_options(args[1], args[2:])
        if args in (["list"], ["--version"]):
            from fdem.cli import main

            out = io.StringIO()
            with contextlib.redirect_stdout(out):
                try:
                    code = main(args)
                except SystemExit as stop:
                    code = stop.code
            assert code in (0, None), f"fdem {args[0]} exited {code}"
            if args == ["list"]:
                assert all(name in out.getvalue() for name in CASES)
            return f"fdem {args[0]}: ran"
        if args[:1] == ["info"]:
            assert len(args) == 2, "fdem info takes one mesh file"
            if args[1].upper() == "FILE.MSH":
                return "fdem info: placeholder file name"
            assert (ROOT / args[1]).is_file(), f"fdem info {args[1]}: no such file in the repository"
            return "fdem info: file exists"
        pytest.fail(f"unknown fdem command {' '.join(tokens)}")
    if tokens[0] in ("python", "python3") and len(tokens) > 1 and tokens[1].startswith("cases/"):
        script = ROOT / tokens[1]
        assert script.is_file(), f"{tokens[1]}: no such script"
        stem = script.stem.replace("_", "-")
        if script.parent == ROOT / "cases" and stem in CASES:
            return parse_case_options(stem, tokens[2:])
        return f"{tokens[1]}: exists"
    return None


@pytest.fixture
def one_thread():
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


def _has_command(block: Block) -> bool:
    first = {line.strip().removeprefix("$ ").split(" ", 1)[0] for line in block.code.splitlines()}
    return bool(first & {"fdem", "python", "python3", "pip"})


# an unlabelled block is a shell block when a line of it is a command, formulas otherwise
SHELL_BLOCKS = [b for b in BLOCKS if b.lang in SHELL and (b.lang or _has_command(b))]


@pytest.mark.parametrize("block", SHELL_BLOCKS, ids=[b.id for b in SHELL_BLOCKS])
def test_shell_block_commands_are_accepted(block, one_thread):
    cmds = commands(block.code)
    if block.skip is not None:
        pytest.skip(f"{block.id}: no-test: {block.skip}")
    checked = [r for r in (check_command(c) for c in cmds) if r is not None]
    assert checked, (f"{block.id}: a shell block with no fdem command to check; mark it "
                     "<!-- no-test: reason --> on the line before")


# ----------------------------------------------------------------------------- python
class _Page:
    """One page's python blocks, run in order in one namespace and one temporary directory."""

    def __init__(self, doc: str):
        self.blocks = [b for b in PYTHON if b.doc == doc]
        self.namespace = {"__name__": "__docs__"}
        self.done = 0
        self.dir = tempfile.mkdtemp(prefix="fdem_docs_")

    def run_through(self, block: Block) -> None:
        k = self.blocks.index(block)
        while self.done <= k:
            b = self.blocks[self.done]
            self.done += 1
            if b.skip is not None:
                continue
            cwd = os.getcwd()
            os.chdir(self.dir)
            try:
                exec(compile(b.code, b.id, "exec"), self.namespace)
            finally:
                os.chdir(cwd)


_PAGES: dict[str, _Page] = {}


@pytest.mark.parametrize("block", PYTHON, ids=[b.id for b in PYTHON])
def test_python_block_runs(block, one_thread, monkeypatch):
    if block.skip is not None:
        pytest.skip(f"{block.id}: no-test: {block.skip}")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    page = _PAGES.setdefault(block.doc, _Page(block.doc))
    page.run_through(block)


def test_every_block_is_run_checked_or_marked_with_a_reason():
    """The inventory: blocks by kind; a marker must give a reason."""
    kinds: dict[str, int] = {}
    for b in BLOCKS:
        kinds[b.lang or "unlabelled"] = kinds.get(b.lang or "unlabelled", 0) + 1
        if b.skip is not None:
            assert b.skip, f"{b.id}: a no-test marker needs a reason"
    skipped = [f"{b.id} ({b.skip})" for b in BLOCKS if b.skip is not None]
    print(f"{len(BLOCKS)} blocks {kinds}; {len(skipped)} not run: " + "; ".join(skipped))
    assert PYTHON and SHELL_BLOCKS
