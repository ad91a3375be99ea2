"""The kernel cache is dropped when any kernel source changes (fdem/_kernel_cache.py): Numba's
own check looks only at the file of the function it loads, not at helpers in other files."""
import pytest

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


_FRAGMENTED_BLOCK = """
import hashlib, json
import numpy as np
from numba.core.registry import CPUDispatcher
from fdem.kernels import contact_pairs, stepping, triangles
from fdem.mesh.mesh import structured_rectangle
from fdem.physics.contact import ContactSet
from fdem.physics.elastic import ElasticMaterial
from fdem.solve.damping import Damping
from fdem.solve.model import Model
from fdem.solve.simulation import Simulation

mesh = structured_rectangle(30, 30, 10.0, 10.0)
model = Model.from_mesh(mesh, ElasticMaterial(0.59e9, 0.29, 2680.0), exploded=True)
model.set_gravity(0.0, -9.81)
model.fix("bottom")
contact = ContactSet(model.topology, penalty=5.9e9, friction_angle=30.0, damping_ratio=0.1, mass=model.node_mass())
contact.activate_cracks(np.arange(model.topology.n_cracks))   # every face free: a heap of triangles
sim = Simulation(model, providers=[contact], progress=False)
sim.monitors.clear()
for _ in range(400):
    sim.step(Damping(mass_proportional=50.0))
results = {"heap": {"x": hashlib.sha1(sim.state.x.tobytes()).hexdigest(),
                    "v": hashlib.sha1(sim.state.v.tobytes()).hexdigest()}}
"""


_BREAKING_BLOCK = """
from fdem.kernels import cracks as crack_kernels
from fdem.mesh.topology import build_topology
from fdem.physics.cracks import CrackProperties, CrackSet

topo = build_topology(structured_rectangle(16, 16, 4.0, 4.0))
model = Model(topo, ElasticMaterial(0.59e9, 0.29, 2680.0))
rng = np.random.default_rng(7)
model.initial_velocity[:] = rng.standard_normal(model.initial_velocity.shape) * 0.3   # m/s
# weak rock: the random velocity field opens and shears crack elements past their strength,
# so they soften (mode I, II, mixed) and break, and the broken faces come into contact
cracks = CrackSet(topo, {0: CrackProperties(f_t=2e4, c=4e4, phi=30.0, G_I=5.0, G_II=20.0, p_n=5.9e9)})
contact = ContactSet(topo, 5.9e9, friction_angle=30.0, mass=model.node_mass(), cracks=cracks)
sim = Simulation(model, providers=[cracks, contact], progress=False)
sim.monitors.clear()
for _ in range(300):
    sim.step()
results["block"] = {"x": hashlib.sha1(sim.state.x.tobytes()).hexdigest(),
                    "v": hashlib.sha1(sim.state.v.tobytes()).hexdigest(),
                    "broken": int(np.count_nonzero(cracks.broken)), "inelastic": int(len(cracks.inelastic()))}
kernels = [k for m in (contact_pairs, crack_kernels, stepping, triangles) for k in vars(m).values()
           if isinstance(k, CPUDispatcher)]
results["hits"] = sum(sum(k.stats.cache_hits.values()) for k in kernels)
results["misses"] = sum(sum(k.stats.cache_misses.values()) for k in kernels)
print(json.dumps(results))
"""


@pytest.fixture(scope="module")
def fresh_and_cached(tmp_path_factory):
    """Both scenes (the heap, then the breaking block) in one script, run twice against an empty
    Numba cache on one thread: (compiled, loaded). One script, so that each process compiles the
    shared triangle and contact kernels once."""
    import json
    import os
    import subprocess
    import sys

    script = _FRAGMENTED_BLOCK + _BREAKING_BLOCK
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path_factory.mktemp("numba_cache")), NUMBA_NUM_THREADS="1")
    runs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                             check=True, timeout=600)
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    fresh, cached = runs
    assert fresh["misses"] > 0 and fresh["hits"] == 0, fresh      # compiled in the run
    assert cached["hits"] > 0 and cached["misses"] == 0, cached    # every kernel loaded from the cache
    return fresh, cached


def test_kernels_compiled_in_the_run_and_loaded_from_the_cache_give_the_same_bits(fresh_and_cached):
    """A heap of 1,800 free triangles under gravity, 400 damped steps with contact on one thread,
    run twice against an empty Numba cache: the first run compiles the kernels, the second loads
    them. The two end states must agree to the bit, or a resumed run (which loads) is not the run
    it resumes (which compiled). With the fast-math flag ``reassoc`` beside ``contract`` (the
    flags before 2026-11-25) the two parted in both the triangle and the contact-pair kernels."""
    fresh, cached = (run["heap"] for run in fresh_and_cached)
    assert (cached["x"], cached["v"]) == (fresh["x"], fresh["v"])


def test_crack_kernels_compiled_and_loaded_give_the_same_bits(fresh_and_cached):
    """The same for the crack-element kernels (cohesive law, softening, breakage) with contact
    between broken faces: a bonded block of 512 triangles shaken apart by a random velocity
    field, 300 steps on one thread. Fresh and cached runs must agree to the bit, softened and
    broken elements included (the scene must break some, or the law's branches go untested)."""
    fresh, cached = (run["block"] for run in fresh_and_cached)
    assert fresh["broken"] > 10 and fresh["inelastic"] > fresh["broken"], fresh
    assert (cached["x"], cached["v"], cached["broken"]) == (fresh["x"], fresh["v"], fresh["broken"])
