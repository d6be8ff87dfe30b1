"""The one integer-program runner: every side-count program (layouts, single patches) goes
through :func:`run_milp`, so solver failures are told apart from infeasible requests in one place."""

from __future__ import annotations

__all__ = ["MILP_TIME_LIMIT", "run_milp"]


MILP_TIME_LIMIT = 30.0
"""Seconds HiGHS may spend on one integer program; past it the best solution found is used."""


def run_milp(cost, constraints, integrality, bounds, *, time_limit: float = MILP_TIME_LIMIT):
    """Solve one integer program with :func:`scipy.optimize.milp` (HiGHS): ``x`` (the best
    solution found: optimal, or the incumbent at the time limit), or None when the program is
    infeasible. A solver failure (status 3 or 4, or a time limit without a solution) is retried
    once without presolve, then raised as :class:`jaxmatch.errors.SolverError`, never reported
    as infeasible."""
    from scipy.optimize import milp

    from jaxmatch.errors import SolverError

    res = None
    for presolve in (True, False):
        res = milp(cost, constraints=constraints, integrality=integrality, bounds=bounds,
                   options={"time_limit": float(time_limit), "presolve": presolve})
        if res.status in (0, 1) and res.x is not None:
            return res.x
        if res.status == 2:
            return None
    raise SolverError(f"the integer program failed (HiGHS status {res.status}: {res.message})", res.status)
