"""State files (``.npz``): positions, velocities and any named arrays of one state."""
from __future__ import annotations

import os
from pathlib import Path
import numpy as np

__all__ = ["save_state", "load_state"]


def save_state(path: str | os.PathLike, **arrays) -> Path:
    """Save named arrays / scalars to a ``.npz`` (atomically: written to a temporary file first)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)
    return path


def load_state(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Arrays of a state file written by :func:`save_state`."""
    with np.load(path) as data:
        return {k: data[k] for k in data.files}
