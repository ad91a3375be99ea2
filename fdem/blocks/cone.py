"""The one call into the conic solver: ``min 1/2 x'Px + q'x  s.t.  A x + s = b, s in K`` with K a
product of zero, non-negative and second-order cones (Clarabel).

Clarabel (Goulart & Chen 2024, Apache-2.0, on PyPI as wheels) is chosen because it takes a
quadratic objective with second-order cones directly (the dynamic steps are QPs over cones; ECOS
and SCS would need an epigraph reformulation), it is an interior-point method that returns
certificates of infeasibility (the collapse mechanism of a failing slope is one), and it needs
no other package. A status other than solved or infeasible raises :class:`ConeSolverError`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

__all__ = ["ConeSolverError", "ConeProblem", "ConeResult", "solve_cone"]


class ConeSolverError(RuntimeError):
    """The conic solver neither solved the problem nor proved it infeasible."""


@dataclass
class ConeProblem:
    """Rows of ``A x + s = b`` in cone order: ``n_zero`` equalities, ``n_nonneg`` inequalities
    ``s >= 0``, then ``n_soc`` second-order cones of size 2 (``s_0 >= |s_1|``)."""

    A: sp.csc_matrix
    b: np.ndarray
    q: np.ndarray
    n_zero: int
    n_nonneg: int
    n_soc: int
    P: sp.csc_matrix | None = None


@dataclass(frozen=True)
class ConeResult:
    """``status``: ``"solved"``, ``"infeasible"`` (primal: no admissible forces) or ``"unbounded"``
    (dual infeasible). ``x``, ``z`` (multipliers of the rows, or the infeasibility certificate),
    ``iterations``, ``seconds``."""

    status: str
    x: np.ndarray
    z: np.ndarray
    objective: float
    iterations: int
    seconds: float
    raw_status: str


_SOLVED = {"Solved", "AlmostSolved"}
_INFEASIBLE = {"PrimalInfeasible", "AlmostPrimalInfeasible"}
_UNBOUNDED = {"DualInfeasible", "AlmostDualInfeasible"}


def solve_cone(problem: ConeProblem, tol: float = 1e-8, max_iter: int = 200, what: str = "cone program"
               ) -> ConeResult:
    """Solve ``problem`` with Clarabel; raise :class:`ConeSolverError` naming ``what`` and the
    solver's status when it is neither solved nor infeasible nor unbounded."""
    import clarabel

    n = problem.A.shape[1]
    P = problem.P if problem.P is not None else sp.csc_matrix((n, n))
    P = sp.triu(P, format="csc")
    cones = []
    if problem.n_zero:
        cones.append(clarabel.ZeroConeT(problem.n_zero))
    if problem.n_nonneg:
        cones.append(clarabel.NonnegativeConeT(problem.n_nonneg))
    cones += [clarabel.SecondOrderConeT(2)] * problem.n_soc
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_feas = settings.tol_gap_abs = settings.tol_gap_rel = tol
    settings.max_iter = max_iter
    solver = clarabel.DefaultSolver(P, np.asarray(problem.q, float), sp.csc_matrix(problem.A),
                                    np.asarray(problem.b, float), cones, settings)
    sol = solver.solve()
    raw = str(sol.status).split(".")[-1]
    if raw in _SOLVED:
        status = "solved"
    elif raw in _INFEASIBLE:
        status = "infeasible"
    elif raw in _UNBOUNDED:
        status = "unbounded"
    else:
        raise ConeSolverError(f"{what}: the conic solver (Clarabel) stopped with status {raw} after "
                              f"{sol.iterations} iterations ({n} variables, {problem.A.shape[0]} rows): "
                              f"no answer; try a looser tolerance or check the input for extreme values")
    return ConeResult(status, np.array(sol.x), np.array(sol.z), float(sol.obj_val), int(sol.iterations),
                      float(sol.solve_time), raw)
