"""Scene files written back: :func:`scene_text` and :func:`write_scene`.

The standard library reads TOML (``tomllib``) but does not write it; a scene needs only tables,
arrays of tables, numbers, strings, booleans and (nested) lists of numbers or strings, so a
small writer does it. Numbers are written with ``repr``, which round-trips a float exactly:
reading the written file gives the same model bit for bit. Each key carries its unit and
meaning from :data:`fdem.scene.schema.SCHEMA` as a comment, so a written scene documents itself.
"""
from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

from fdem.scene.schema import ARRAYS, BY_TAG, FREE_KEYS, OWN_CHECK, SCHEMA

__all__ = ["scene_text", "write_scene"]

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(name) -> str:
    name = str(name)
    return name if _BARE.match(name) else json.dumps(name)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"a scene file holds finite numbers only, got {v!r}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # JSON's escapes are TOML basic-string escapes
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    if hasattr(v, "item"):  # a numpy scalar
        return _value(v.item())
    raise TypeError(f"cannot write {type(v).__name__} {v!r} to a scene file")


def _table(lines: list[str], header: str, table: dict, section: str) -> None:
    keys = SCHEMA.get(section, {})
    lines.append(header)
    for name, v in table.items():
        if v is None:
            continue
        help_ = keys[name].help if name in keys else ""
        text = f"{_key(name)} = {_value(v)}"
        lines.append(f"{text:<40s} # {help_}" if help_ else text)
    lines.append("")


def scene_text(scene: dict, title: str | None = None) -> str:
    """TOML text of ``scene`` (a raw or checked scene ``dict``; ``None`` values are left out),
    sections in the order of :data:`SCHEMA`, with ``title`` as a leading comment."""
    lines = [f"# {line}" for line in (title or "").splitlines()] + ([""] if title else [])
    unknown = set(scene) - set(SCHEMA)
    if unknown:
        raise ValueError(f"unknown scene section(s) {sorted(unknown)}")
    for section in SCHEMA:
        value = scene.get(section)
        if not value:
            continue
        if section in ARRAYS:
            for table in value:
                _table(lines, f"[[{section}]]", table, section)
        elif section in BY_TAG:
            for tag, table in value.items():
                _table(lines, f"[{section}.{tag}]", table, section)
        elif section in OWN_CHECK:  # its own keys, nested tables inline
            _table(lines, f"[{section}]", value, section)
        elif section in FREE_KEYS:
            lines.append(f"[{section}]")
            lines += [f"{_key(k)} = {_value(v)}" for k, v in value.items()]
            lines.append("")
        else:
            _table(lines, f"[{section}]", value, section)
    return "\n".join(lines).rstrip() + "\n"


def write_scene(path: str | os.PathLike, scene: dict, title: str | None = None) -> Path:
    """Write :func:`scene_text` to ``path`` (atomically: a temporary file renamed)."""
    path = Path(path)
    text = scene_text(scene, title)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path
