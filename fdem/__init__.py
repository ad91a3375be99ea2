"""fdem: hybrid finite-discrete element solver for jointed rock slopes.

The names a run needs, in one place (``import fdem`` or ``from fdem import ...``); each is
imported on first use (PEP 562), so ``import fdem`` and ``fdem list`` stay fast and the solver
core loads without Gmsh, meshio or pyvista. The package, bottom up (``docs/architecture.md``):
geometry -> mesh -> kernels -> physics -> solve -> results -> workflow -> cases, with io and
reference on the ground floor.
"""
from __future__ import annotations

import importlib

from fdem.kernels.cache import refresh_kernel_cache as _refresh_kernel_cache
from fdem.kernels.threading_layer import preload_tbb as _preload_tbb

__version__ = "0.1.0"

_FACADE = {
    # the section: outline and joints
    "Geometry": "fdem.geometry.section",
    "simple_slope": "fdem.geometry.polygons",
    "benched_slope": "fdem.geometry.polygons",
    "rectangle": "fdem.geometry.polygons",
    "slope_toe": "fdem.geometry.polygons",
    "PersistentSet": "fdem.geometry.joint_sets",
    "IntermittentSet": "fdem.geometry.joint_sets",
    "BrickSet": "fdem.geometry.joint_sets",
    "SegmentSet": "fdem.geometry.joint_sets",
    "StochasticSet": "fdem.geometry.joint_sets",
    # triangles and crack elements
    "mesh_geometry": "fdem.mesh.triangulate",
    "quality_report": "fdem.mesh.quality",
    "build_topology": "fdem.mesh.topology",
    # laws
    "ElasticMaterial": "fdem.physics.elastic",
    "CrackProperties": "fdem.physics.crack_properties",
    "CrackSet": "fdem.physics.cracks",
    "ContactSet": "fdem.physics.contact",
    # the time loop
    "Model": "fdem.solve.model",
    "Simulation": "fdem.solve.simulation",
    "Damping": "fdem.solve.damping",
    "geostatic_start": "fdem.solve.geostatic",
    "save_checkpoint": "fdem.solve.checkpoint",
    "load_checkpoint": "fdem.solve.checkpoint",
    # reading a run
    "RunReport": "fdem.results.report",
    # stages and workflows
    "Stage": "fdem.workflow.stages",
    "Convergence": "fdem.workflow.stages",
    "run_stage": "fdem.workflow.stages",
    "factor_of_safety": "fdem.workflow.fos",
    "SlopeWorkflow": "fdem.workflow.slope",
    "run_slope_workflow": "fdem.workflow.slope",
}
"""Facade name -> the module that defines it."""

__all__ = sorted(_FACADE)


def __getattr__(name: str):
    module = _FACADE.get(name)
    if module is None:
        raise AttributeError(f"module 'fdem' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(_FACADE))


# Numba's cache does not notice a changed helper in another file (fdem/kernels/cache.py):
# start from a clean kernel cache whenever any kernel source changed.
_refresh_kernel_cache()
_preload_tbb()  # before the first parallel kernel: Numba's TBB layer, where pip installed TBB
