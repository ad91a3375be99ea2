"""Plain JSON from numpy and dataclass values (``summary.json``, ``fos.json``): no encoder error after a run."""
from __future__ import annotations

import math
import numpy as np

__all__ = ["jsonable"]


def jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist() if obj.size <= 64 else f"array of shape {obj.shape}"
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None  # undefined (e.g. percentiles of an empty displaced set): JSON null
    return obj
