"""Block on an inclined plane through the full solver (crack elements + contact + triangles):
sliding distance against s = g t^2 (sin theta - mu cos theta) / 2, sticking, and the
Goodman-Bray toppling criterion b/h < tan(theta) (verification.md)."""
import pytest

from conftest import load_case

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
