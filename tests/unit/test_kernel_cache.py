"""The kernel cache is dropped when any kernel source changes (fdem/_kernel_cache.py): Numba's
own check looks only at the file of the function it loads, not at helpers in other files."""
from fdem.kernels.cache import STAMP, kernel_sources_digest, refresh_kernel_cache


def _package(tmp_path):
    root = tmp_path / "pkg"
    (root / "kernels" / "__pycache__").mkdir(parents=True)
    (root / "__pycache__").mkdir()
    (root / "kernels" / "helpers.py").write_text("from numba import njit\n@njit(cache=True)\ndef f(x):\n    return x\n")
    (root / "kernels" / "callers.py").write_text("from numba import njit\nfrom .helpers import f\n@njit(cache=True)\n"
                                                 "def g(x):\n    return f(x)\n")
    (root / "workflow.py").write_text("import numba\ndef stage():\n    return numba.get_num_threads()\n")
    return root


def _cached(root):
    for name in ("callers.g-3.py311.nbi", "callers.g-3.py311.1.nbc"):
        (root / "kernels" / "__pycache__" / name).write_bytes(b"cached")
    return sorted(p.name for p in root.rglob("__pycache__/*.nb?"))


def test_a_changed_helper_in_another_file_drops_every_cached_kernel(tmp_path):
    root = _package(tmp_path)
    assert refresh_kernel_cache(root) is True            # first import: stamps
    assert (root / "__pycache__" / STAMP).read_text().strip() == kernel_sources_digest(root)
    cached = _cached(root)
    assert refresh_kernel_cache(root) is False           # nothing changed: the cache stays
    assert sorted(p.name for p in root.rglob("__pycache__/*.nb?")) == cached
    # the helper changes; the caller's file (whose cache Numba would trust) does not
    (root / "kernels" / "helpers.py").write_text("from numba import njit\n@njit(cache=True)\ndef f(x):\n    return 2 * x\n")
    assert refresh_kernel_cache(root) is True
    assert list(root.rglob("__pycache__/*.nb?")) == []
    assert (root / "__pycache__" / STAMP).read_text().strip() == kernel_sources_digest(root)


def test_a_change_outside_the_kernels_keeps_the_cache(tmp_path):
    root = _package(tmp_path)
    refresh_kernel_cache(root)
    cached = _cached(root)
    (root / "workflow.py").write_text("import numba\ndef stage():\n    return 2\n")   # uses Numba, defines no kernel
    assert refresh_kernel_cache(root) is False
    assert sorted(p.name for p in root.rglob("__pycache__/*.nb?")) == cached
