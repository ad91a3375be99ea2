"""Why an undamped elastic block drifts from the rigid-block answer as the mesh is refined
(docs/damping.md, "Convergence with refinement").

An undamped block keeps the elastic ringing that its release, the base pulse and every
stick-slip transition put into it. Ringing velocities at the base nodes that exceed the slip
velocity reverse or stop the slip there, so the friction the block feels on average falls below
mu N and the block ratchets down the slope. The Newmark block shows it in its purest form: once
the base is at rest, gravity alone cannot move a block with phi > theta (the rigid block stays
put), yet the undamped elastic block keeps creeping. With the default element damping the ringing
dies out, the block stops, and the slip is Newmark's within the 5 % tolerance."""
import numpy as np

from fdem.solve.model import DEFAULT_ELEMENT_DAMPING

from conftest import load_case

newmark = load_case("newmark_block")


def _creep_after_the_record(r: dict) -> float:
    """Slip gained after the base has come to rest (t past the pulse plus 0.05 s) [m]."""
    t = np.asarray(r["t_s"])
    slip = np.asarray(r["slip_curve_m"])
    still = t >= r["t_settle_s"] + r["period_s"] + 0.05
    assert still.sum() >= 10, "the run must continue well past the end of the pulse"
    return float(slip[still][-1] - slip[still][0])


def test_undamped_block_ratchets_on_after_the_shaking_and_the_default_stops_it():
    damped = newmark.run(0.5, element_damping=DEFAULT_ELEMENT_DAMPING)
    undamped = newmark.run(0.5, element_damping=0.0)
    # The rigid block is at rest after the pulse; so is the damped elastic one (to 0.1 mm) ...
    assert abs(_creep_after_the_record(damped)) < 1e-4
    assert abs(damped["error"]) < 0.01
    # ... while the undamped one keeps creeping down the slope under gravity alone, and its
    # slip is far outside the 5 % tolerance.
    assert _creep_after_the_record(undamped) > 2e-3
    assert undamped["error"] > 0.05
