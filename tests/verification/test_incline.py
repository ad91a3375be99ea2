"""Block on an inclined plane through the full solver (crack elements + contact + triangles):
sliding distance against s = g t^2 (sin theta - mu cos theta) / 2, sticking, and the
Goodman-Bray toppling criterion b/h < tan(theta) (verification.md)."""
import numpy as np
import pytest

from conftest import load_case
from fdem.solve.simulation import Simulation

incline = load_case("block_on_incline")


@pytest.mark.parametrize("theta, phi", [(30.0, 20.0), (40.0, 25.0)])
def test_sliding_distance_at_one_second(theta, phi):
    r = incline.run(theta, phi, t_end=1.0)
    assert r["slide_m"] == pytest.approx(r["exact_m"], rel=0.02)
    # The energy ledger closes: friction work is what the block did not gain.
    assert abs(r["balance_error_relative"]) < 0.01


def test_frictionless_slide_conserves_energy():
    r = incline.run(30.0, 0.0, t_end=1.0)
    assert r["slide_m"] == pytest.approx(r["frictionless_m"], rel=0.005)
    assert r["friction_work_J_per_m"] == 0.0
    assert abs(r["balance_error_relative"]) < 1e-6


def test_block_below_its_friction_angle_sticks():
    r = incline.run(20.0, 30.0, t_end=1.0)
    assert abs(r["slide_m"]) < 0.01 * r["frictionless_m"]


@pytest.mark.parametrize("width, topples", [(0.4, True), (0.8, False)])
def test_toppling_follows_goodman_and_bray(width, topples):
    # theta = 30 deg, phi = 45 deg (no sliding); height 1 m: topples when b/h < tan(30) = 0.577.
    r = incline.run(30.0, 45.0, t_end=1.5, block_width=width, block_height=1.0)
    if topples:
        assert abs(r["rotation_deg"]) > 30.0
    else:
        assert abs(r["rotation_deg"]) < 1.0


def _faces_on_the_plane(topology, triangles, y: float = 0.5):
    """(triangles, faces) of the faces of ``triangles`` that lie on the plane y = ``y`` (the
    block's underside, the base's top): face k runs from corner k to corner k + 1."""
    x = topology.x0.reshape(-1, 3, 2)[triangles]
    on = np.abs(x[:, :, 1] - y) < 1e-9
    tri, k = np.nonzero(on & np.roll(on, -1, axis=1))
    return np.asarray(triangles)[tri], k


def _slide_with_face_friction(theta: float, block_phi: float, underside_phi: float, base_top_phi: float,
                              t_end: float = 0.5) -> tuple[float, float]:
    """The block's mean slide at ``t_end`` [m] and the exact rigid-block one for the friction of
    the faces in touch, min(underside, base top): every other face of the block has
    ``block_phi``, every other face of the base the base top's."""
    model, cracks, contact, block = incline.build(theta, block_phi)
    topo = model.topology
    block_tris = np.flatnonzero(topo.triangle_body == 1)
    base_tris = np.flatnonzero(topo.triangle_body == 0)
    contact.set_friction(friction_angle=base_top_phi, triangles=base_tris)
    tri, k = _faces_on_the_plane(topo, block_tris)
    assert len(tri) >= 2  # the underside is meshed in pieces
    contact.set_friction(friction_angle=np.full(len(tri), underside_phi), triangles=tri, faces=k)
    sim = Simulation(model, providers=[cracks, contact], progress=False)
    x0 = sim.state.x[block].copy()
    sim.run(t_end=t_end, output_every=10**9, energy_tolerance=0.05)
    slide = float((sim.state.x[block][:, 0] - x0[:, 0]).mean())
    return slide, incline.sliding_distance(theta, min(underside_phi, base_top_phi), sim.state.time)


def test_a_block_slides_with_the_friction_of_the_faces_in_touch():
    """Friction belongs to the surfaces that slide on each other, not to the lowest face of a
    triangle (Coulomb, rigid block: s = g t^2 (sin theta - mu cos theta) / 2). A block whose
    underside has 30 deg on a base of 30 deg sticks at theta = 20 deg though its other faces
    have 5 deg (a pair friction taken as the lowest face of its triangles would let it slide at
    5 deg); with a 10 deg underside it slides at 10 deg though its other faces have 40; on a
    base whose top has 10 deg it slides at 10 deg whatever its own faces have."""
    stick, exact_stick = _slide_with_face_friction(20.0, block_phi=5.0, underside_phi=30.0, base_top_phi=30.0)
    free = incline.sliding_distance(20.0, 0.0, 0.5)
    assert exact_stick == 0.0 and abs(stick) < 0.01 * free
    slide, exact = _slide_with_face_friction(20.0, block_phi=40.0, underside_phi=10.0, base_top_phi=30.0)
    assert slide == pytest.approx(exact, rel=0.03)
    on_base, exact = _slide_with_face_friction(20.0, block_phi=40.0, underside_phi=30.0, base_top_phi=10.0)
    assert on_base == pytest.approx(exact, rel=0.03)
