"""The ensemble's files: the realizations table (``realizations.csv``, one row per
realization, headed by the ensemble's SHA-256 so that a resumed run never mixes two ensembles)
and its description (``ensemble.json``)."""
from __future__ import annotations

import csv
import math
from pathlib import Path

__all__ = ["TABLE", "DESCRIPTION", "finite_number", "read_table"]


TABLE = "realizations.csv"


DESCRIPTION = "ensemble.json"


_HEADER = "# fdem ensemble sha256="


# ----------------------------------------------------------------------------- distributions
def finite_number(value) -> bool:
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def read_table(path) -> tuple[str | None, list[dict]]:
    """``(sha256, rows)`` of a results table; numbers parsed, the last row of an index wins."""
    path = Path(path)
    with path.open(newline="") as fh:
        first = fh.readline()
        digest = first.strip()[len(_HEADER):] if first.startswith(_HEADER) else None
        if digest is None:
            fh.seek(0)
        rows = {}
        for r in csv.DictReader(fh):
            out = {}
            for k, v in r.items():
                if k in ("status", "error", "outcome"):
                    out[k] = v
                else:
                    try:
                        out[k] = float(v) if v != "" else math.nan
                    except ValueError:
                        out[k] = v
            out["index"] = int(out["index"])
            rows[out["index"]] = out
    return digest, [rows[i] for i in sorted(rows)]
