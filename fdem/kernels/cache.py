"""Drop Numba's on-disk kernel cache when any kernel source changes.

Numba's ``cache=True`` checks only the source file of the function it loads: a cached kernel
that inlined a helper from *another* file keeps the old helper after that file changes (seen
in practice, ``docs/benchmarks.md``). A clean clone (CI) never sees this; an editable install
or a checkout that is edited does.

The rule here is coarse and safe: a SHA-256 of every package file that defines Numba kernels
(contains ``njit(``)
is kept in ``fdem/__pycache__/kernel_sources.sha256``; when it differs on import, every cached
kernel of the package (``__pycache__/*.nbi``, ``*.nbc``) is deleted, so the next call compiles
from the current sources. A read-only install cannot change, so nothing is done where the
package folder cannot be written.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["STAMP", "kernel_sources_digest", "refresh_kernel_cache"]


STAMP = "kernel_sources.sha256"


_MARKERS = (b"njit(",)


def kernel_sources_digest(root: Path) -> str:
    """SHA-256 over the relative paths and contents of the ``.py`` files under ``root`` that
    define Numba kernels (contain ``njit(``), in sorted order: a module that only sets Numba's
    thread count does not count."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        data = path.read_bytes()
        if any(m in data for m in _MARKERS):
            h.update(str(path.relative_to(root)).encode())
            h.update(b"\0")
            h.update(data)
    return h.hexdigest()


def refresh_kernel_cache(root: Path | None = None) -> bool:
    """Delete the package's cached kernels if the kernel sources changed since they were
    cached; returns True when it deleted (or would have, on a first run it only stamps)."""
    root = Path(__file__).resolve().parents[1] if root is None else Path(root)  # the package: fdem/
    stamp = root / "__pycache__" / STAMP
    try:
        digest = kernel_sources_digest(root)
        if stamp.exists() and stamp.read_text().strip() == digest:
            return False
        for pattern in ("*.nbi", "*.nbc"):
            for f in root.rglob(f"__pycache__/{pattern}"):
                try:
                    f.unlink()
                except FileNotFoundError:  # another process got there first
                    pass
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{STAMP}.{os.getpid()}.tmp")
        tmp.write_text(digest + "\n")
        os.replace(tmp, stamp)  # atomic: concurrent imports see the old or the new stamp
        return True
    except OSError:  # a read-only install: its sources cannot change under its cache
        return False
