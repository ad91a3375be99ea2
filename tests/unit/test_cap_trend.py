"""The reading of a trial that reached its cap (:func:`fdem.workflow.fos.settling_at_cap`)
against responses whose futures are known: a geometric decay, a steady creep, an accelerating slide."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fdem.workflow.fos import settling_at_cap

T = 0.4           # response time [s]
CHECKS = 40       # rows per response time, as the stages check


def _rows(disp, ratio, n_windows=5):
    t = np.arange(1, n_windows * CHECKS + 1) * (T / CHECKS)
    return t, disp(t), ratio(t)


def test_a_geometric_decay_is_settling_and_its_remainder_and_time_to_the_limit_are_exact():
    """``d(t) = D (1 - q^(t/T))`` and ``r(t) = r0 q^(t/T)``: the growth shrinks by ``q`` each
    response time, the ratio falls ``1/q``-fold; what is left to move after the cap is
    ``D q^(t_end/T)`` and the ratio meets the limit ``log(r(t_end)/limit)/log(1/q)`` response
    times after the cap, which the geometric readings must give to round-off."""
    q, D, r0, limit = 0.55, 0.02, 3e-2, 1e-4
    t, d, r = _rows(lambda t: D * (1 - q ** (t / T)), lambda t: r0 * q ** (t / T))
    trend = settling_at_cap(t, d, r, window=T, limit=limit)
    assert trend["settling"]
    assert trend["share"] == pytest.approx(q, rel=1e-9)
    assert trend["ratio_fall"] == pytest.approx(1 / q, rel=1e-9)
    assert trend["further_if_geometric"] == pytest.approx(D * q ** (t[-1] / T), rel=1e-9)
    r_end = r0 * q ** (t[-1] / T)
    assert trend["windows_to_limit"] == pytest.approx(math.log(r_end / limit) / math.log(1 / q), rel=1e-9)


@pytest.mark.parametrize("growth", ["steady", "accelerating"])
def test_a_creep_or_a_slide_is_not_settling(growth):
    """A displacement growing linearly (a creep at constant rate, a block at its terminal speed
    under mass-proportional damping) or faster (a slide) grows at least as much in the last
    response time as in the one before: not settling, whatever the ratio does."""
    disp = (lambda t: 1e-3 * t) if growth == "steady" else (lambda t: 1e-3 * t ** 2)
    t, d, r = _rows(disp, lambda t: 2e-3 * np.exp(-0.1 * t))
    trend = settling_at_cap(t, d, r, window=T, limit=1e-4)
    assert not trend["settling"] and trend["share"] >= 1.0 - 1e-9
    assert "further_if_geometric" not in trend


def test_a_trial_shorter_than_two_response_times_is_not_read():
    """Its first response time is the elastic answer to the change of strength, which decays on a
    slope that then slides: two windows are the least that tells a settling slope."""
    t, d, r = _rows(lambda t: 1e-3 * (1 - np.exp(-t)), lambda t: 1e-3 * np.exp(-t), n_windows=1.9)
    assert settling_at_cap(t, d, r, window=T) is None


def _trial(factor, stable, length, reason=None, time_capped=False):
    return {"factor": factor, "stable": stable, "t_start": 10.0, "t_end": 10.0 + length,
            "reason": reason or ("converged" if stable else "capped"), "time_capped": time_capped}


def test_the_bracket_at_shorter_caps_counts_a_trial_stable_only_once_it_converged():
    """Trials of 20 response times read at 10, 5 and 2.5 T: a trial converged after 9.3 T is
    failing at 5 T and stable at 10 T; one that failed by displacement at 19 T or reached the cap
    is failing at every cap; a trial the run's --max-time cut is left out. The readings below
    are worked by hand from those rules (the high-angle coarse trials of docs/cases.md A)."""
    from fdem.workflow.fos import bracket_by_cap

    trials = [_trial(1.6, True, 9.3 * T), _trial(3.4, False, 19.0 * T, reason="failed"),
              _trial(2.5, True, 4.0 * T), _trial(2.9, False, 20.0 * T), _trial(2.7, True, 12.0 * T),
              _trial(2.8, False, 3.0 * T, time_capped=True)]
    by_cap = bracket_by_cap(trials, window=T, cap=20.0 * T)
    assert [r["cap_response_times"] for r in by_cap] == pytest.approx([2.5, 5.0, 10.0, 20.0])
    assert [r["bracket"] for r in by_cap] == [[None, 1.6], [2.5, 1.6], [2.5, 2.7], [2.7, 2.9]]
    assert [r["ordered"] for r in by_cap] == [True, False, True, True]
    assert by_cap[1]["stable"] == [2.5] and by_cap[1]["failing"] == [1.6, 2.7, 2.9, 3.4]
    assert all(2.8 not in r["stable"] + r["failing"] for r in by_cap)


def test_a_search_at_the_default_cap_is_read_at_half_of_it_and_no_shorter():
    """5 T trials are read at 2.5 and 5 T; 3 T trials only at their own cap, the first response
    times being the elastic answer to the change of strength (SHORTEST_READ_CAP)."""
    from fdem.workflow.fos import SHORTEST_READ_CAP, bracket_by_cap

    assert SHORTEST_READ_CAP == 2.0
    trials = [_trial(1.0, True, 1.0 * T), _trial(1.5, False, 5.0 * T)]
    assert [r["cap_response_times"] for r in bracket_by_cap(trials, T, 5.0 * T)] == pytest.approx([2.5, 5.0])
    assert [r["cap_response_times"] for r in bracket_by_cap(trials, T, 3.0 * T)] == pytest.approx([3.0])
    assert [r["cap_response_times"] for r in bracket_by_cap(trials, T, 4.0 * T)] == pytest.approx([2.0, 4.0])
