"""Plain JSON from numpy, dataclass and path values, through one encoder for every file the
project writes (``summary.json``, ``fos.json``, ``run.json``, the cases' tables).

Two rules, so that results are never lost to an encoder after hours of work:

* :func:`jsonable` turns anything a run produces into plain JSON values: numpy scalars and
  booleans into Python ones, small arrays into lists (large ones into a note of their shape),
  dataclasses into dicts, paths into strings, and non-finite floats into ``null`` (JSON has no
  NaN; a NaN in a summary means "undefined", e.g. a percentile of an empty set).
* :func:`write_json` writes through :func:`jsonable` with ``allow_nan=False`` (strict JSON that
  every reader accepts) and atomically (a temporary file, then ``os.replace``), so a full disk
  or an interruption leaves the previous file whole rather than an empty one.
"""
from __future__ import annotations

import dataclasses
import errno
import json
import math
import os
from pathlib import Path, PurePath

import numpy as np

__all__ = ["jsonable", "dumps", "write_json"]

LARGEST_LISTED_ARRAY = 64
"""Arrays up to this many values are written as lists; larger ones as a note of their shape
(their values belong in ``.npz``, ``.csv`` or ``.vtu`` files, not in a summary)."""


def jsonable(obj):
    """A copy of ``obj`` made of dicts, lists, strings, finite floats, ints, booleans and ``None``."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist()) if obj.size <= LARGEST_LISTED_ARRAY else f"array of shape {obj.shape}"
    if isinstance(obj, np.generic):
        obj = obj.item()
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return jsonable(dataclasses.asdict(obj))
    if isinstance(obj, PurePath):
        return str(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    return repr(obj)  # an object with no JSON form: its description, never an encoder error


def dumps(obj, indent: int | None = 2) -> str:
    """Strict JSON text of :func:`jsonable` ``(obj)``."""
    return json.dumps(jsonable(obj), indent=indent, allow_nan=False)


def write_json(path, obj, indent: int | None = 2) -> Path:
    """Write ``obj`` as strict JSON to ``path`` atomically; returns the path. The text is made
    before the file is touched, so an object that cannot be encoded changes nothing on disk."""
    path = Path(path)
    text = dumps(obj, indent) + "\n"
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except BaseException as err:
        try:
            tmp.unlink()
        except OSError:
            pass
        if isinstance(err, OSError) and err.errno == errno.ENOSPC and path.is_file():
            # a full disk has no room for the temporary copy; rewritten in place, a small file
            # reuses its own blocks (a run's run.json after a full disk ended it)
            path.write_text(text)
            return path
        raise
    return path
