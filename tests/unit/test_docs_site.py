"""The documentation site (``mkdocs.yml``) is complete: its nav lists every Markdown page of
``docs/``, every nav entry exists, and every public subpackage of ``fdem`` has an API page that
renders it from its docstrings (``::: fdem.<name>``). Read as text, so mkdocs is not needed to
run the tests; ``mkdocs build --strict`` (the ``docs`` extra) builds the site itself."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def nav_pages() -> list[str]:
    """The pages the nav of mkdocs.yml names (``- Title: page.md`` lines)."""
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = text[text.index("\nnav:"):]
    nav = nav[:re.search(r"\n\S", nav[1:]).start() + 1] if re.search(r"\n\S", nav[1:]) else nav
    return re.findall(r"^\s*-\s*(?:[^:\n]+:\s*)?(\S+\.md)\s*$", nav, flags=re.M)


def test_nav_lists_every_page_of_docs_and_only_pages_that_exist():
    listed = nav_pages()
    assert len(listed) == len(set(listed)), f"pages listed twice: {sorted(p for p in listed if listed.count(p) > 1)}"
    missing = [p for p in listed if not (DOCS / p).is_file()]
    assert not missing, f"mkdocs.yml nav names pages that do not exist: {missing}"
    pages = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md"))
    unlisted = [p for p in pages if p not in listed]
    assert not unlisted, f"docs pages missing from the nav of mkdocs.yml: {unlisted}"


def test_every_public_subpackage_has_an_api_page():
    packages = sorted(d.name for d in (ROOT / "fdem").iterdir()
                      if (d / "__init__.py").is_file() and not d.name.startswith("_"))
    assert {"geometry", "mesh", "kernels", "physics", "solve", "workflow"} <= set(packages)
    listed = nav_pages()
    for name in packages:
        page = DOCS / "api" / f"{name}.md"
        assert page.is_file(), f"fdem.{name} has no API page docs/api/{name}.md"
        assert re.search(rf"^::: fdem\.{name}\s*$", page.read_text(encoding="utf-8"), flags=re.M), \
            f"docs/api/{name}.md does not render fdem.{name} (a line '::: fdem.{name}')"
        assert f"api/{name}.md" in listed, f"docs/api/{name}.md is not in the nav of mkdocs.yml"
    stale = [p.stem for p in (DOCS / "api").glob("*.md") if p.stem not in packages]
    assert not stale, f"API pages of packages that do not exist: {stale}"
