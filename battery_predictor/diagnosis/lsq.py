"""Budgeted bounded least squares (scipy ``least_squares``, trust-region reflective).

Every model of a diagnosis (the baseline refit and each candidate) gets the same number of
objective evaluations, counted here, including those scipy spends on finite-difference
Jacobians (which its own ``max_nfev`` does not count). When the budget is spent the best
point seen so far is returned. Parameters are searched in the unit cube (each mapped to its
bounds, linearly or logarithmically by the caller).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.processes import ProcessPool, shared

#: Finite-difference step in the unit cube: 1 % of each parameter's range. The solver's relative
#: tolerance (1e-5) makes smaller steps noisy enough to stall the trust region on a false minimum.
DIFF_STEP = 1e-2


class _BudgetSpent(Exception):
    pass


@dataclass
class LsqResult:
    """Best point of a budgeted fit.

    Attributes
    ----------
    u : numpy.ndarray
        Best point in the unit cube.
    cost : float
        Sum of squared residuals at ``u``.
    evaluations : int
        Objective evaluations spent (all starts).
    failures : int
        Evaluations whose simulation failed (penalised).
    """

    u: np.ndarray
    cost: float
    evaluations: int
    failures: int


def _call_parallel(u: np.ndarray) -> np.ndarray | None:
    try:
        r = np.asarray(shared("lsq_residual")(u), dtype=float)
        return r if np.all(np.isfinite(r)) else None
    except BatteryPredictorError:
        return None


@dataclass
class _Spent:
    """What :func:`budgeted_least_squares` has spent and found so far."""

    n: int = 0
    best_u: np.ndarray | None = None
    best_cost: float = np.inf
    fail: int = 0
    limit: int = 0


class _Counted:
    """The residual and its forward-difference Jacobian, counted against the budget of
    :func:`budgeted_least_squares` (raise :class:`_BudgetSpent` at the limit); a failed or
    non-finite evaluation costs ``failure_residual()``, and the best point is kept in ``spent``.
    """

    def __init__(self, fun: Callable[[np.ndarray], np.ndarray], failure_residual: Callable[[], np.ndarray],
                 diff_step: float, parallel: ParallelEvaluator | None) -> None:
        self.fun = fun
        self.failure_residual = failure_residual
        self.diff_step = diff_step
        self.parallel = parallel
        self.spent = _Spent()
        #: the last point evaluated and its residual (the Jacobian's f0 when it is asked there)
        self.last: dict[str, np.ndarray] = {}

    def record(self, u: np.ndarray, r: np.ndarray | None) -> np.ndarray:
        """``r`` (the failure residual when None), with ``u`` kept when it is the best so far."""
        state = self.spent
        if r is None:
            state.fail += 1
            r = self.failure_residual()
        cost = float(r @ r)
        if cost < state.best_cost:
            state.best_cost, state.best_u = cost, np.array(u, dtype=float)
        return r

    def residual(self, u: np.ndarray) -> np.ndarray:
        """One counted evaluation of the residual at ``u``."""
        state = self.spent
        if state.n >= state.limit:
            raise _BudgetSpent
        state.n += 1
        r: np.ndarray | None
        try:
            r = np.asarray(self.fun(u), dtype=float)
            if not np.all(np.isfinite(r)):
                r = None
        except BatteryPredictorError:
            r = None
        r = self.record(u, r)
        self.last["u"], self.last["r"] = np.array(u, dtype=float), r
        return r

    def jacobian(self, u: np.ndarray) -> np.ndarray:
        """Forward differences (backward at the upper bound) at ``u``, the columns in the parallel workers."""
        state, last, diff_step = self.spent, self.last, self.diff_step
        u = np.asarray(u, dtype=float)
        f0 = last["r"] if "u" in last and np.array_equal(last["u"], u) else self.residual(u)
        if state.n + u.size > state.limit:
            raise _BudgetSpent
        steps = np.where(u + diff_step <= 1.0, diff_step, -diff_step)
        points = []
        for i in range(u.size):
            p = u.copy()
            p[i] += steps[i]
            points.append(p)
        assert self.parallel is not None  # the Jacobian is only used with a ParallelEvaluator
        rows = self.parallel.map(points)
        state.n += u.size
        jac = np.empty((f0.size, u.size))
        for i, (p, r) in enumerate(zip(points, rows)):
            jac[:, i] = (self.record(p, r) - f0) / steps[i]
        return jac


class ParallelEvaluator:
    """Evaluate a residual function at several points in forked worker processes.

    Use as a context manager around :func:`budgeted_least_squares` (``parallel=``): the
    finite-difference Jacobian's columns are then computed concurrently. The function and
    everything it closes over (built models) are inherited by the forked workers.
    """

    def __init__(self, fun: Callable[[np.ndarray], np.ndarray], workers: int) -> None:
        self.fun = fun
        self.workers = workers
        self._pool = ProcessPool(workers, shared={"lsq_residual": fun})

    def __enter__(self) -> ParallelEvaluator:
        self._pool.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self._pool.__exit__(*exc)

    def map(self, points: list[np.ndarray]) -> list[np.ndarray | None]:
        """The residual at each point (None where it failed or is not finite)."""
        return self._pool.map(_call_parallel, points)


def budgeted_least_squares(fun: Callable[[np.ndarray], np.ndarray], starts: Sequence[np.ndarray], budget: int,
                           failure_residual: Callable[[], np.ndarray], diff_step: float | None = None,
                           parallel: ParallelEvaluator | None = None) -> LsqResult:
    """Minimise ``sum(fun(u) ** 2)`` over ``u`` in [0, 1]^n with at most ``budget`` evaluations.

    Parameters
    ----------
    fun : callable
        Residual vector of a point; raises :class:`BatteryPredictorError` when the model fails.
    starts : sequence of numpy.ndarray
        Starting points; the budget is split evenly among them.
    budget : int
        Total number of evaluations.
    failure_residual : callable
        Residual vector used for a failed evaluation (a large, constant penalty).
    diff_step : float
        Finite-difference step in the unit cube.
    parallel : ParallelEvaluator, optional
        Computes the forward-difference Jacobian's columns concurrently (same evaluation count).
    """
    from scipy.optimize import least_squares

    if budget < 1:
        raise BatteryPredictorError(f"budget must be >= 1, got {budget}")
    diff_step = DIFF_STEP if diff_step is None else diff_step
    counted = _Counted(fun, failure_residual, diff_step, parallel)
    state, wrapped, jacobian = counted.spent, counted.residual, counted.jacobian

    starts = [np.clip(np.asarray(s, dtype=float), 1e-6, 1 - 1e-6) for s in starts] or [np.zeros(0)]
    n_dim = starts[0].size
    per_start = max(1, budget // len(starts))
    for k, u0 in enumerate(starts):
        state.limit = budget if k == len(starts) - 1 else min(budget, state.n + per_start)
        if state.n >= state.limit:
            break
        if n_dim == 0:
            try:
                wrapped(u0)
            except _BudgetSpent:
                pass
            continue
        try:
            least_squares(wrapped, u0, jac=jacobian if parallel is not None else "2-point",
                          bounds=(np.zeros(n_dim), np.ones(n_dim)), method="trf", diff_step=diff_step,
                          x_scale=1.0, max_nfev=10 * budget, xtol=1e-6, ftol=1e-8, gtol=1e-8)
        except _BudgetSpent:
            pass
    if state.best_u is None:
        return LsqResult(u=starts[0], cost=np.inf, evaluations=state.n, failures=state.fail)
    return LsqResult(u=state.best_u, cost=state.best_cost, evaluations=state.n, failures=state.fail)
