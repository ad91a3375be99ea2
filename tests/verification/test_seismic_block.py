"""Base shaking as a bisection trigger: the critical amplitude of a block on a frictional plane.

A rigid block on a plane at ``theta`` with friction ``phi`` starts to slip under a horizontal
inertial drive ``a_h`` (towards the down-slope side) at the pseudo-static yield acceleration

    k_y = (tan phi - tan theta) / (1 + tan phi tan theta) = tan(phi - theta)      [g]

and then slips along the plane with ``s'' = (cos theta + tan phi sin theta) (a_h - k_y g)``
(the along-plane balance of gravity, the drive and friction on the normal force
``m (g cos theta - a_h sin theta)``; Newmark 1965, Kramer 1996 sec. 10.6). A pulse of finite
length must exceed ``k_y`` long enough for the slip to reach the failure threshold, so the
critical amplitude of the bisection lies above ``k_y``: the test compares it with the
amplitude at which Newmark's rigid block, integrated exactly for the same record
(:func:`fdem.blocks.newmark.one_way_slip`), slips the threshold, and checks both exceed ``k_y``.

Scene: a 1 m block (h = 0.5 m) on a 4 m x 0.5 m plate, the plane tilted by turning gravity
(:func:`fdem.cases.block_on_incline.incline_model`'s convention), the plate shaken horizontally
in the real frame, i.e. along ``(cos theta, sin theta)`` in the model's frame. A soft rock
(E = 200 MPa) keeps the step long (5e-5 s); the block's lowest own frequency (about c_s / 4 m,
70 Hz) stays far above the record's 2 Hz. Softness costs accuracy: at 0.25 g the FDEM slip is
+48 % above Newmark's at E = 50 MPa, +4.6 % at 200 MPa and +1.1 % at 1 GPa (the block rocks and
rings on its penalty contacts, as ``docs/shaking.md`` found without element damping), so the
tolerance below is set for 200 MPa.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from fdem.blocks.newmark import one_way_slip
from fdem.cases.block_on_incline import unbreakable
from fdem.geometry.polygons import rectangle
from fdem.geometry.section import Geometry
from fdem.mesh.topology import build_topology
from fdem.mesh.triangulate import mesh_geometry
from fdem.physics.contact import ContactSet
from fdem.physics.cracks import CrackSet
from fdem.physics.elastic import ElasticMaterial
from fdem.solve.model import DEFAULT_ELEMENT_DAMPING, Model
from fdem.solve.simulation import Simulation
from fdem.workflow.fos import factor_of_safety
from fdem.workflow.seismic import BaseShaking

THETA, PHI, G = 20.0, 30.0, 9.81
YOUNG, DENSITY = 2e8, 2700.0
FREQUENCY, CYCLES, SETTLE = 2.0, 1.0, 0.2      # Hz, -, s
THRESHOLD = 0.005                              # m of permanent slip counts as failure
TOL = 0.008                                    # g: bisection tolerance


def k_y(theta=THETA, phi=PHI) -> float:
    t, p = math.tan(math.radians(theta)), math.tan(math.radians(phi))
    return (p - t) / (1 + p * t)


def scene():
    base = rectangle(0.0, 0.0, 4.0, 0.5, name="incline")
    block = rectangle(1.5, 0.5, 1.0, 1.0, name="block")
    topo = build_topology(mesh_geometry(Geometry([base, block]), 0.5))
    model = Model(topo, ElasticMaterial(young=YOUNG, poisson=0.25, density=DENSITY))
    model.set_element_damping(DEFAULT_ELEMENT_DAMPING)
    th = math.radians(THETA)
    model.set_gravity(G * math.sin(th), -G * math.cos(th))
    base_nodes = np.flatnonzero(np.repeat(topo.triangle_body == 0, 3))
    block_nodes = np.flatnonzero(np.repeat(topo.triangle_body == 1, 3))
    # base acceleration up-slope horizontally first: the inertial drive on the block points down-slope
    shaking = BaseShaking.sine(FREQUENCY, CYCLES, direction=(-math.cos(th), -math.sin(th)), settle=SETTLE,
                               threshold=THRESHOLD, monitor=block_nodes, g=G)
    shaking.attach(model, base_nodes, "xy")
    cracks = CrackSet(topo, {0: unbreakable(YOUNG)})
    contact = ContactSet(topo, 20 * YOUNG, friction_angle=PHI, mass=model.node_mass(), cracks=cracks)
    sim = Simulation(model, providers=[cracks, contact], progress=False)
    return sim, shaking


def newmark_slip(shaking: BaseShaking, amplitude: float) -> float:
    """Exact rigid-block slip along the plane [m] under the horizontal drive of the record."""
    th, ph = math.radians(THETA), math.radians(PHI)
    horizontal = (math.cos(th), math.sin(th))              # down-slope horizontal, model frame
    s, _ = one_way_slip(shaking.t, shaking.drive(amplitude, horizontal), k_y() * G)
    return (math.cos(th) + math.tan(ph) * math.sin(th)) * float(s[-1])


def newmark_critical(shaking: BaseShaking, tol: float = 1e-6) -> float:
    lo, hi = k_y(), 5 * k_y()
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if newmark_slip(shaking, mid) < THRESHOLD else (lo, mid)
    return 0.5 * (lo + hi)


@pytest.fixture
def one_thread():
    """One Numba thread, as the cases use for a mesh this small: on shared cores two threads'
    spin-waiting made this test 4x slower (492 s against 134 s)."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


def test_critical_amplitude_of_a_block_matches_newmark_above_the_yield_acceleration(one_thread):
    wall = time.perf_counter()
    sim, shaking = scene()
    sim.run(t_end=0.1, history_every=10**9, final_output=False)     # settle under gravity alone
    a_nm = newmark_critical(shaking)
    ky = k_y()
    # the bracket is itself a check: at k_y the block must stand, at 1.1 times Newmark's amplitude slip
    result = factor_of_safety(sim, lower=ky, upper=1.1 * a_nm, tol=TOL, trigger=shaking,
                              trial=shaking.trial_stage(sim), judge=shaking.judge)
    lo, hi = result.bracket
    print(f"k_y {ky:.4f} g, Newmark critical {a_nm:.4f} g, FDEM bracket [{lo:.4f}, {hi:.4f}] g, "
          f"{len(result.trials)} trials, {time.perf_counter() - wall:.1f} s")
    assert result.ended_by == "tolerance"
    assert a_nm > ky                                   # a finite pulse needs more than k_y
    assert lo > ky                                     # the FDEM block does not slip the threshold below k_y
    # the deformable block slips a few per cent more than Newmark's rigid block (module docstring);
    # the slip grows faster than the amplitude above k_y, so its critical amplitude is lower by less:
    # within 3 % (plus half the bracket)
    assert abs(result.fos / a_nm - 1) < 0.03 + 0.5 * TOL / a_nm
    # the search leaves the simulation at rest, the base unshaken
    assert shaking.current(sim) == 0.0


def test_base_shaking_trigger_is_checked():
    with pytest.raises(ValueError, match="strictly increasing"):
        BaseShaking([0.0, 0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="zero everywhere"):
        BaseShaking([0.0, 1.0], [0.0, 0.0])
    with pytest.raises(ValueError, match="frequency"):
        BaseShaking.sine(0.0)
    s = BaseShaking.sine(2.0, 1.0, direction=(3.0, 4.0))
    assert s.duration == pytest.approx(0.5)
    h = s.record(0.5, start=1.0)
    assert np.linalg.norm(h.a, axis=1).max() == pytest.approx(0.5 * 9.81, rel=1e-6)
    assert h.t_start == 1.0 and np.allclose(3 * h.a[:, 1], 4 * h.a[:, 0])
    assert s.current(None) == 0.0 and s.log == []
