"""The history table (``history.csv``): one row per ledger check, written as the run goes."""
from __future__ import annotations

import csv
import os
from pathlib import Path
import numpy as np

__all__ = ["HistoryWriter", "read_history"]


class HistoryWriter:
    """CSV history: header ``columns`` (default: the first row's keys); each row is appended
    and flushed, a column a row lacks left empty."""

    def __init__(self, path: str | os.PathLike, columns: list[str] | None = None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.columns: list[str] | None = None if columns is None else list(columns)
        self._fh = None
        self._writer = None
        self._started = False

    def write(self, row: dict) -> None:
        if self._fh is None:
            if self.columns is None:
                self.columns = list(row)
            # the first row writes the header; a row after close() appends, never truncates
            self._fh = open(self.path, "a" if self._started else "w", newline="")
            self._writer = csv.writer(self._fh)
            if not self._started:
                self._writer.writerow(self.columns)
            self._started = True
        extra = [k for k in row if k not in self.columns]
        if extra:
            raise ValueError(f"history row has columns {extra} that the header {self.columns} lacks")
        self._writer.writerow([_fmt(row.get(c, "")) for c in self.columns])
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            try:
                self._fh.close()
            except OSError:
                # every row is flushed as it is written, so what is left is a row whose write
                # already failed (a full disk) and ended the run as a write error: closing must not
                # raise again and lose the summary the run can still write
                pass
            self._fh = None


def _fmt(value) -> str:
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.10g}"
    return str(value)


def read_history(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Columns of a history CSV as arrays (numeric where possible; an empty cell, a row written
    before its monitor was added, is nan)."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    out = {}
    for j, name in enumerate(header):
        col = [r[j] for r in body]
        try:
            out[name] = np.array([float(c) if c != "" else np.nan for c in col])  # "": a row before the column began
        except ValueError:
            out[name] = np.array(col)
    return out
