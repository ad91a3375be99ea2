"""fdem: hybrid finite-discrete element solver for jointed rock slopes."""
__version__ = "0.1.0"

from fdem.kernels.cache import refresh_kernel_cache as _refresh_kernel_cache

# Numba's cache does not notice a changed helper in another file (fdem/_kernel_cache.py):
# start from a clean kernel cache whenever any kernel source changed.
_refresh_kernel_cache()
