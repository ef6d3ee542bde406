"""Identification in identifiable coordinates: seeded TPE, then trust-region least squares.

The search runs on the unit cube of the coordinates of
:mod:`~battery_predictor.fitting.identifiable` (log scale where the coordinate is). A seeded
Optuna TPE explores the box; the best distinct TPE candidates then start a trust-region
reflective least-squares refinement (``scipy.optimize.least_squares``, finite-difference
Jacobian) on the residual vector whose sum of squares is ``1 - mean R2_mod``. Budgets count
model evaluations (one evaluation simulates every recording once); every evaluation, also
those of the Jacobians, counts.

Data sampled faster than :data:`COARSE_WINDOW_S` are searched in two stages: the search above on
the data averaged over those windows, then one refinement of its result on the data as given.
The coarse stage sees the charge-driven shape that sets the identifiable coordinates without the
sample-to-sample detail of the end of a discharge, where the cost of the data as given is a narrow
curved valley (the model's end of discharge against the recording's, a few samples wide) that a
refinement follows only slowly; each coarse evaluation is also cheaper.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.errors import BatteryPredictorError, SimulationError
from battery_predictor.fitting.cost import r2_mod, rmse_v
from battery_predictor.fitting.identifiable import Coordinate, electrode_basis, pybamm_values
from battery_predictor.fitting.resample import resample_windows
from battery_predictor.params import PackParams
from battery_predictor.recording import Recording, ends_at_cutoff
from battery_predictor.simulation.base import PackSimResult, PackSimulator
from battery_predictor.simulation.extensions import with_cold_window_anchors

if TYPE_CHECKING:
    import optuna

    from battery_predictor.fitting.identifiability import IdentifiabilityReport
    from battery_predictor.fitting.problem import FitProblem
    from battery_predictor.fitting.space import FitParameter

#: Default budget of an identification in model evaluations.
DEFAULT_EVALUATIONS = 1250
#: Share of the evaluation budget spent in TPE (the rest refines).
DEFAULT_TPE_FRACTION = 0.25
#: Start-up (random) trials: the paper's rule per coordinate, capped at this share of the TPE trials.
STARTUP_TRIALS_PER_COORDINATE = 20
MAX_STARTUP_FRACTION = 0.3
#: Refinements started from the best distinct TPE candidates.
DEFAULT_STARTS = 3
#: A refinement may always spend this many Jacobians' worth of evaluations (convergence from a
#: TPE candidate took 100-185 evaluations on 5 coordinates), even when later starts then get less.
MIN_REFINE_JACOBIANS = 25
#: Budget left after the planned starts goes to further distinct candidates while it buys at least
#: this many Jacobians.
MIN_LEFTOVER_JACOBIANS = 3
#: Two TPE candidates are distinct when they differ by this much (max-norm on the unit cube).
DISTINCT_UNIT_DISTANCE = 0.25
#: Finite-difference step on the unit cube.
FD_STEP = 2e-3
#: The first stage searches the data averaged over windows of this length (s) when every recording is
#: sampled at least three times per window (:func:`identify`).
COARSE_WINDOW_S = 30.0
#: Share of the budget for the second stage: the refinement on the data as given.
FINE_FRACTION = 0.25
#: The coordinate whose optimum has several basins: aligning the negative electrode's OCP plateaus
#: with the data's can match them one stage off (:func:`alignment_sweep`).
SWEEP_COORDINATE = "negative_stoichiometry"
#: Where the sweep starts, on that coordinate's unit range.
SWEEP_STARTS = (0.1, 0.3, 0.5, 0.7, 0.9)
#: Share of the budget for the sweep, split evenly over its starts (at the default budget each start
#: refines for 37 evaluations: enough to fall well into its basin, not to converge).
SWEEP_FRACTION = 0.15
#: A sweep start within this distance (unit range) of the point swept from is in its basin already.
SWEEP_SKIP_DISTANCE = 0.1


class BudgetExhausted(BatteryPredictorError):
    """The evaluation budget is spent (caught inside the optimiser)."""


@dataclass
class EvaluationLog:
    """Counts evaluations and remembers the best point (unit cube) seen."""

    budget: int
    count: int = 0
    best_cost: float = math.inf
    best_unit: np.ndarray | None = None
    failed: int = 0
    #: Wall time inside the model evaluations (simulation and residual), s.
    model_seconds: float = 0.0

    def charge(self) -> None:
        """Account one evaluation or raise :class:`BudgetExhausted`."""
        if self.count >= self.budget:
            raise BudgetExhausted(f"evaluation budget {self.budget} spent")
        self.count += 1

    def record(self, unit: np.ndarray, cost: float) -> None:
        """Keep ``unit`` when its cost is the lowest so far."""
        if cost < self.best_cost:
            self.best_cost = cost
            self.best_unit = np.array(unit, dtype=float)


def padding_s(rec: Recording, extend_fraction: float) -> float:
    """How far past its end (s) a recording is simulated and compared: R2_mod's padding, or none.

    A recording that ends at its cut-off (:func:`~battery_predictor.recording.ends_at_cutoff`) is
    padded by ``extend_fraction`` of its duration with its minimum voltage (Eq. 2 of the seed
    paper), so a model that would run longer shows it. Any other recording (a working day that
    stops at 40 % SOC, a discharge that ends in a rest) is compared on its samples only: padding it
    would ask the model to be empty where the recording stopped, which biases the identified
    capacity low (a far-truth Temi day that ended at 3.5 V per cell: reference RMSE 36 mV with the
    padding, 6 mV without, docs/findings.md).

    Parameters
    ----------
    rec : Recording
        The recording.
    extend_fraction : float
        Padding as a fraction of the recording's duration when it ends at its cut-off.

    Returns
    -------
    float
        Padding in s (0 when the recording does not end at its cut-off).
    """
    return extend_fraction * rec.duration_s if ends_at_cutoff(rec) else 0.0


@dataclass(frozen=True)
class ResidualGrid:
    """Fixed comparison grid of one recording (measurement grid extended past its end when it ends at its cut-off).

    Attributes
    ----------
    time_s : numpy.ndarray
        Relative measurement times, extended with the median interval by the padding
        (:func:`padding_s`).
    measured_v : numpy.ndarray
        Measured voltage, padded with its minimum after the end (Eq. 2 of the seed paper).
    u_min_v : float
        Minimum measured voltage.
    weight : float
        ``1 / sqrt(n_recordings * sum (U - mean U)^2)`` over the measured samples.
    ends_at_cutoff : bool
        Whether the recording ends at its cut-off (:func:`~battery_predictor.recording.ends_at_cutoff`):
        only then is a prediction below ``U_min`` clipped to it (Eq. 1's stand-in).
    signal : {"pack", "min_cell"}
        What is compared: the pack voltage (``PackSimResult.pack_voltage_v``), or the lowest series
        group's voltage (the recording's :attr:`~battery_predictor.recording.Recording.min_group_voltage_v`
        against the model's ``min_cell_voltage_v``, see :func:`ResidualGrid.for_weakest_group`).
    """

    time_s: np.ndarray
    measured_v: np.ndarray
    u_min_v: float
    weight: float
    ends_at_cutoff: bool = True
    signal: str = "pack"

    @classmethod
    def for_recording(cls, rec: Recording, extend_s: float, n_recordings: int,
                      at_cutoff: bool | None = None) -> ResidualGrid:
        """The grid of ``rec`` with ``extend_s`` seconds of padding (``at_cutoff``: default :func:`ends_at_cutoff`)."""
        return cls._padded(rec.relative_time_s, np.asarray(rec.voltage_v, dtype=float), extend_s, n_recordings,
                           ends_at_cutoff(rec) if at_cutoff is None else at_cutoff, "pack")

    @classmethod
    def for_weakest_group(cls, rec: Recording, extend_s: float, n_recordings: int,
                          at_cutoff: bool | None = None) -> ResidualGrid | None:
        """The grid of ``rec``'s lowest measured group voltage (V, the samples where any group was measured),
        padded like :meth:`for_recording`; None when the recording has no group voltages.

        The model's counterpart is the lowest cell voltage of its groups (the weak group's with the
        extension ``cell_imbalance``), the cell's terminal voltage without the pack's series
        resistance: a measured group voltage is taken at the group's terminals. On the Nissan Leaf
        6S2P data the groups add up to the pack voltage plus 0.08-0.11 V, so the pack's connection
        drop is outside them.
        """
        u_all = rec.min_group_voltage_v
        if u_all is None:
            return None
        measured = np.isfinite(u_all)
        if measured.sum() < 2:
            return None
        return cls._padded(rec.relative_time_s[measured], u_all[measured], extend_s, n_recordings,
                           ends_at_cutoff(rec) if at_cutoff is None else at_cutoff, "min_cell")

    @classmethod
    def _padded(cls, t: np.ndarray, u: np.ndarray, extend_s: float, n_recordings: int, at_cutoff: bool,
                signal: str) -> ResidualGrid:
        u_min = float(u.min())
        dt = float(np.median(np.diff(t)))
        extra = np.arange(t[-1] + dt, t[-1] + extend_s + 0.5 * dt, dt) if extend_s > 0 else np.empty(0)
        ss_tot = float(np.sum((u - u.mean()) ** 2)) or 1.0
        return cls(np.concatenate([t, extra]), np.concatenate([u, np.full(extra.size, u_min)]), u_min,
                   1.0 / math.sqrt(n_recordings * ss_tot), at_cutoff, signal)

    def residuals(self, result: PackSimResult | None) -> np.ndarray:
        """Weighted ``measured - predicted``: a continuous stand-in for R2_mod's comparison.

        The prediction is clipped at ``U_min`` from below (rather than truncated at its first
        sample below it, Eq. 1, which jumps whenever a load peak dips below ``U_min``) and padded
        with ``U_min`` after its end; a simulation that stops at its cut-off between two report
        times is continued linearly to ``U_min`` at its end time. A recording that does not end
        at its cut-off is compared as it is: a prediction below its ``U_min`` is an error there.
        """
        pred = np.full(self.time_s.size, self.u_min_v)
        if result is not None and result.time_s.size >= 2:
            tp = result.time_s
            up = result.pack_voltage_v if self.signal == "pack" else result.min_cell_voltage_v
            if result.reached_cutoff and result.end_time_s > tp[-1]:
                tp, up = np.append(tp, result.end_time_s), np.append(up, min(up[-1], self.u_min_v))
            pred = np.interp(self.time_s, tp, up, right=self.u_min_v)
            pred[self.time_s > tp[-1]] = self.u_min_v
            if self.ends_at_cutoff:
                pred = np.maximum(pred, self.u_min_v)
        return self.weight * (self.measured_v - pred)


@dataclass(frozen=True)
class CandidateScore:
    """Score of one coordinate vector.

    Attributes
    ----------
    r2_mod : float
        Mean R2_mod over the recordings (seed paper Eq. 1-3).
    per_recording : list of float
        R2_mod of each recording.
    rmse_mv : list of float
        RMS voltage error (mV) of each recording over the simulated span.
    results : list of PackSimResult
        The simulations.
    values : list of dict
        The PyBaMM/interconnect values of each recording.
    """

    r2_mod: float
    per_recording: list[float]
    rmse_mv: list[float]
    results: list[PackSimResult] = field(repr=False)
    values: list[dict[str, float]] = field(repr=False)


@dataclass
class IdentificationProblem:
    """Recordings + params + simulator, evaluated at points of a coordinate space.

    Parameters
    ----------
    params : PackParams
        The starting model (its geometry is kept; see :func:`pybamm_values`).
    recordings : sequence of Recording
        Fit data, each with its own initial-OCV coordinate in ``space``.
    simulator : PackSimulator
        Usually the fast simulator (coordinates move only ``[input]`` parameters).
    space : list of Coordinate
        From :func:`~battery_predictor.fitting.identifiable.default_space`.
    extend_fraction : float
        Simulations of a recording that ends at its cut-off run this fraction of its duration past
        its end, compared with its minimum voltage (late ends show); others are not padded
        (:func:`padding_s`).
    group_voltages : bool
        Fit the weakest measured group voltage too when the params use ``cell_imbalance`` (below);
        False: the pack voltage only.
    cutoff_ends : bool
        False: no recording is taken to end at its cut-off (none is padded, clipped or truncated),
        whatever :func:`~battery_predictor.recording.ends_at_cutoff` says.

    With the extension ``cell_imbalance``, a recording that carries its series groups' voltages
    adds a second residual block: its lowest group voltage against the model's lowest cell
    voltage (:meth:`ResidualGrid.for_weakest_group`), weighted like the pack's (each block's sum of
    squares is about ``1 - R2`` of its signal). From the pack voltage alone the weak group's
    capacity fraction trades against the electrode capacities; the weakest group's own voltage
    separates them. The cost is then no longer ``1 - mean R2_mod``; :meth:`score` still reports the
    pack's R2_mod. Without group voltages or without the extension nothing changes.
    """

    params: PackParams
    recordings: Sequence[Recording]
    simulator: PackSimulator
    space: list[Coordinate]
    extend_fraction: float = 0.2
    group_voltages: bool = True
    cutoff_ends: bool = True

    def __post_init__(self) -> None:
        # every candidate narrows a cold window towards the start's anchors: the same coordinates give the
        # same model whatever ran before, and one engine extraction serves every candidate
        self.params = with_cold_window_anchors(self.params)
        n = len(self.recordings)
        self._basis = electrode_basis(self.params)
        self._grids = [ResidualGrid.for_recording(r, self._padding_s(r), n, self._at_cutoff(r)) for r in self.recordings]
        self._group_grids: list[tuple[int, ResidualGrid]] = []
        if self.group_voltages and "cell_imbalance" in self.params.extensions:
            for k, r in enumerate(self.recordings):
                grid = ResidualGrid.for_weakest_group(r, self._padding_s(r), n, self._at_cutoff(r))
                if grid is not None:
                    self._group_grids.append((k, grid))

    def _at_cutoff(self, rec: Recording) -> bool:
        return self.cutoff_ends and ends_at_cutoff(rec)

    def _padding_s(self, rec: Recording) -> float:
        return padding_s(rec, self.extend_fraction) if self.cutoff_ends else 0.0

    @property
    def fits_weakest_group(self) -> bool:
        """Whether the residuals include the lowest measured group voltage (``cell_imbalance`` and group voltages)."""
        return bool(self._group_grids)

    @property
    def names(self) -> list[str]:
        """Coordinate names in search order."""
        return [c.name for c in self.space]

    def coordinates(self, unit: Sequence[float] | np.ndarray) -> dict[str, float]:
        """Coordinate values of a point of the unit cube."""
        return {c.name: c.from_unit(u) for c, u in zip(self.space, unit, strict=True)}

    def unit(self, coordinates: dict[str, float]) -> np.ndarray:
        """Unit-cube position of coordinate values (missing ones at their initial value)."""
        return np.array([c.to_unit(min(max(coordinates.get(c.name, c.initial), c.low), c.high)) for c in self.space])

    def values(self, coordinates: dict[str, float]) -> list[dict[str, float]]:
        """PyBaMM/interconnect values per recording (:func:`pybamm_values`)."""
        return pybamm_values(self.params, coordinates, len(self.recordings), self._basis)

    def simulate(self, coordinates: dict[str, float]) -> tuple[list[PackSimResult], list[dict[str, float]]]:
        """Simulate every recording; raise :class:`SimulationError` when any fails."""
        from battery_predictor.fitting.problem import request_for_recording

        values = self.values(coordinates)
        results = []
        for rec, vals in zip(self.recordings, values, strict=True):
            params = self.params.with_values(vals)
            req = request_for_recording(params, rec, initial_state="params",
                                        extend_s=self._padding_s(rec))
            res = self.simulator.simulate(params, req)
            if res.time_s.size < 2:
                raise SimulationError(f"{rec.source}: simulation ended immediately (cut-off at start)")
            results.append(res)
        return results, values

    def residuals(self, coordinates: dict[str, float]) -> np.ndarray:
        """Concatenated weighted residuals; a failed simulation counts as a prediction at U_min."""
        results: list[PackSimResult] | list[None]
        try:
            results, _ = self.simulate(coordinates)
        except SimulationError:
            results = [None] * len(self.recordings)
        return np.concatenate([g.residuals(r) for g, r in zip(self._grids, results, strict=True)]
                              + [g.residuals(results[k]) for k, g in self._group_grids])

    def failed(self, residuals: np.ndarray) -> bool:
        """Whether ``residuals`` (of :meth:`residuals`) are those of a simulation that failed."""
        failure = np.concatenate([g.residuals(None) for g in self._grids]
                                 + [g.residuals(None) for _, g in self._group_grids])
        return bool(np.array_equal(residuals, failure))

    def score(self, coordinates: dict[str, float]) -> CandidateScore:
        """R2_mod and RMSE of ``coordinates`` (raises :class:`SimulationError` on failure)."""
        results, values = self.simulate(coordinates)
        r2s, rmses = [], []
        for rec, res in zip(self.recordings, results, strict=True):
            t = rec.relative_time_s
            r2s.append(r2_mod(t, rec.voltage_v, res.time_s, res.pack_voltage_v, self._at_cutoff(rec)))
            rmses.append(1e3 * rmse_v(t, rec.voltage_v, res.time_s, res.pack_voltage_v))
        return CandidateScore(float(np.mean(r2s)), r2s, rmses, results, values)


@dataclass(frozen=True)
class IdentificationResult:
    """Outcome of :func:`identify`.

    Attributes
    ----------
    coordinates : dict
        Best coordinate values.
    unit : numpy.ndarray
        The same point on the unit cube.
    cost : float
        Sum of squared residuals at the best point (about ``1 - mean R2_mod``).
    evaluations : int
        Model evaluations spent (TPE + refinement).
    tpe_evaluations : int
        Of which in TPE.
    starts : int
        Refinements run.
    seconds : float
        Wall time in s.
    history : list of tuple
        ``(evaluations, best cost)`` after each phase.
    model_seconds : float
        Of ``seconds``, the time inside model evaluations (simulation and residual) in s; the rest,
        :attr:`optimiser_seconds`, is the optimiser's own (TPE's sampler, the trust-region steps).
    ends : list of tuple
        ``(cost, unit)`` of every end point the search chose from (TPE's best and each refinement's end).
    """

    coordinates: dict[str, float]
    unit: np.ndarray
    cost: float
    evaluations: int
    tpe_evaluations: int
    starts: int
    seconds: float
    history: list[tuple[str, int, float]]
    model_seconds: float = 0.0
    ends: list[tuple[float, np.ndarray]] = field(default_factory=list, repr=False)

    @property
    def optimiser_seconds(self) -> float:
        """Wall time outside the model evaluations (s)."""
        return max(self.seconds - self.model_seconds, 0.0)


def startup_trials(n_tpe: int, n_coordinates: int, per_coordinate: int = STARTUP_TRIALS_PER_COORDINATE,
                   max_fraction: float = MAX_STARTUP_FRACTION) -> int:
    """Random start-up trials of TPE: ``per_coordinate`` each, at most ``max_fraction`` of the TPE trials."""
    return max(1, min(per_coordinate * n_coordinates, int(max_fraction * n_tpe)))


def _cost_function(problem: IdentificationProblem, log: EvaluationLog) -> Callable[[np.ndarray], np.ndarray]:
    cache: dict[bytes, np.ndarray] = {}

    def residual(unit: np.ndarray) -> np.ndarray:
        unit = np.clip(np.asarray(unit, dtype=float), 0.0, 1.0)
        key = unit.tobytes()
        if key not in cache:
            log.charge()
            tic = time.perf_counter()
            r = problem.residuals(problem.coordinates(unit))
            log.model_seconds += time.perf_counter() - tic
            cache[key] = r
            log.record(unit, float(r @ r))
        return cache[key]

    return residual


def _run_tpe(problem: IdentificationProblem, residual: Callable[[np.ndarray], np.ndarray], n_trials: int, seed: int, start_unit: np.ndarray,
             startup_per_coordinate: int) -> list[tuple[float, np.ndarray]]:
    """TPE on the unit cube; returns ``(cost, unit)`` of every completed trial."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.ERROR)
    n_startup = startup_trials(n_trials, len(problem.space), startup_per_coordinate)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        sampler = optuna.samplers.TPESampler(seed=seed, n_startup_trials=n_startup, multivariate=True)
    study = optuna.create_study(direction="minimize", sampler=sampler)
    study.enqueue_trial({f"u{i}": float(u) for i, u in enumerate(start_unit)})
    done: list[tuple[float, np.ndarray]] = []

    def objective(trial: optuna.Trial) -> float:
        unit = np.array([trial.suggest_float(f"u{i}", 0.0, 1.0) for i in range(len(problem.space))])
        r = residual(unit)
        done.append((float(r @ r), unit))
        return float(r @ r)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        try:
            study.optimize(objective, n_trials=n_trials)
        except BudgetExhausted:
            pass
    return done


def distinct_best(candidates: list[tuple[float, np.ndarray]], count: int,
                  distance: float = DISTINCT_UNIT_DISTANCE) -> list[np.ndarray]:
    """The ``count`` lowest-cost points that are pairwise at least ``distance`` apart (max-norm)."""
    picked: list[np.ndarray] = []
    for _cost, unit in sorted(candidates, key=lambda c: c[0]):
        if all(np.max(np.abs(unit - p)) >= distance for p in picked):
            picked.append(unit)
        if len(picked) >= count:
            break
    return picked


def with_start(picked: list[np.ndarray], start: np.ndarray) -> list[np.ndarray]:
    """``picked`` with the start point refined second (first when it is the best candidate).

    The start (the params the user gave) is the prior: a refinement from it always runs, so the
    identification never ends worse than the local optimum next to the user's params, while the best
    TPE candidate still goes first. Candidates are otherwise kept in their order.
    """
    rest = [p for p in picked if not np.array_equal(p, start)]
    if picked and np.array_equal(picked[0], start):
        return [start] + rest
    return rest[:1] + [start] + rest[1:]


def _fd_jacobian(residual: Callable[[np.ndarray], np.ndarray], unit: np.ndarray, step: float = FD_STEP) -> np.ndarray:
    """Forward differences on the unit cube (backward at the upper bound)."""
    f0 = residual(unit)
    jac = np.empty((f0.size, unit.size))
    for i in range(unit.size):
        h = step if unit[i] + step <= 1.0 else -step
        shifted = unit.copy()
        shifted[i] += h
        jac[:, i] = (residual(shifted) - f0) / h
    return jac


def _refine(residual: Callable[[np.ndarray], np.ndarray], start: np.ndarray,
            max_evaluations: int) -> tuple[float, np.ndarray]:
    """Trust-region reflective least squares from ``start``; returns the lowest cost it reached and where."""
    from scipy.optimize import least_squares

    seen: list[tuple[float, np.ndarray]] = []

    def tracked(unit: np.ndarray) -> np.ndarray:
        r = residual(unit)
        seen.append((float(r @ r), np.array(unit, dtype=float)))
        return r

    try:
        least_squares(tracked, start, jac=lambda u: _fd_jacobian(residual, u), bounds=(0.0, 1.0), method="trf",
                      x_scale=1.0, max_nfev=max(2, max_evaluations), xtol=1e-6, ftol=1e-8, gtol=1e-8)
    except BudgetExhausted:
        pass
    return min(seen, key=lambda c: c[0], default=(math.inf, start))


def select_by_r2_mod(problem: IdentificationProblem, ends: Sequence[tuple[float, np.ndarray]]) -> tuple[float, np.ndarray]:
    """The end point with the highest R2_mod (seed paper Eq. 1-3); ties and failures go by the cost.

    The residual vector is a continuous stand-in for R2_mod (it clips a dip below ``U_min`` where Eq. 1
    truncates), so two refinements' end points can rank differently by cost and by R2_mod; the fit
    reports R2_mod, so it chooses by it.
    """
    best: tuple[float, float, np.ndarray] | None = None
    for cost, unit in ends:
        try:
            r2 = problem.score(problem.coordinates(unit)).r2_mod
        except SimulationError:
            r2 = -math.inf
        r2 = r2 if math.isfinite(r2) else -math.inf
        if best is None or (r2, -cost) > (best[0], -best[1]):
            best = (r2, cost, unit)
    if best is None:
        raise BatteryPredictorError("no end point to select from")
    return best[1], best[2]


def alignment_sweep(problem: IdentificationProblem, log: EvaluationLog, unit: np.ndarray,
                    evaluations: int) -> tuple[float, np.ndarray] | None:
    """Short refinements from ``unit`` moved across the negative stoichiometry; the lowest end reached.

    A refinement converges into the basin it starts in, and the negative electrode's OCP plateaus
    give the stoichiometry several: a fit can align the data's features with the wrong plateau and
    stay there with a cost a hundred times the truth's. Each start (:data:`SWEEP_STARTS`, except
    those within :data:`SWEEP_SKIP_DISTANCE` of ``unit``'s own value) keeps ``unit``'s other coordinates
    and refines for an equal share of ``evaluations``.

    Parameters
    ----------
    problem : IdentificationProblem
        Its space names the coordinates; without :data:`SWEEP_COORDINATE` there is nothing to sweep.
    log : EvaluationLog
        Counts the sweep's evaluations.
    unit : numpy.ndarray
        The point swept from.
    evaluations : int
        The sweep's budget in model evaluations.

    Returns
    -------
    tuple of (float, numpy.ndarray) or None
        ``(cost, unit)`` of the lowest end, or None when no start ran.
    """
    names = [c.name for c in problem.space]
    if SWEEP_COORDINATE not in names:
        return None
    j = names.index(SWEEP_COORDINATE)
    residual = _cost_function(problem, log)
    total = log.count + evaluations
    each = evaluations // len(SWEEP_STARTS)
    ends: list[tuple[float, np.ndarray]] = []
    for q in SWEEP_STARTS:
        if abs(q - float(unit[j])) < SWEEP_SKIP_DISTANCE:
            continue
        log.budget = min(log.count + each, total)
        if log.budget - log.count < 2:
            break
        start = np.array(unit, dtype=float)
        start[j] = q
        ends.append(_refine(residual, start, max_evaluations=each))
    log.budget = total
    ends = [e for e in ends if math.isfinite(e[0])]
    return min(ends, key=lambda e: e[0]) if ends else None


def coarsened(problem: IdentificationProblem, window_s: float = COARSE_WINDOW_S) -> IdentificationProblem | None:
    """``problem`` on its recordings averaged over ``window_s`` windows, or None when one is sampled too sparsely.

    Every recording needs a median sampling interval of at most a third of the window (s), so that
    each window averages several samples.
    """
    if not (math.isfinite(window_s) and window_s > 0):
        return None
    for rec in problem.recordings:
        t = np.asarray(rec.time_s, dtype=float)
        if t.size < 2 or 3.0 * float(np.median(np.diff(t))) > window_s:
            return None
    return replace(problem, recordings=[resample_windows(r, window_s) for r in problem.recordings])


def identify(problem: IdentificationProblem, *, evaluations: int = DEFAULT_EVALUATIONS, seed: int = 0,
             tpe_fraction: float = DEFAULT_TPE_FRACTION, starts: int = DEFAULT_STARTS,
             startup_per_coordinate: int = STARTUP_TRIALS_PER_COORDINATE,
             progress: Callable[[str, int, float], None] | None = None,
             coarse_window_s: float | None = COARSE_WINDOW_S, fine_fraction: float = FINE_FRACTION) -> IdentificationResult:
    """Seeded TPE then multi-start trust-region least squares, within ``evaluations`` model runs.

    With ``coarse_window_s`` and data sampled at least three times per window, the search runs on
    the data averaged over those windows (:func:`coarsened`), and its result is refined on the data
    as given with ``fine_fraction`` of the budget; otherwise on the data as given only. Between the stages an :func:`alignment_sweep` on the averaged data
    (:data:`SWEEP_FRACTION` of the budget, when the space has the negative stoichiometry) looks for
    a better basin of that coordinate; an end below the first stage's cost is refined on the data
    as given too, and the better of the two by R2_mod is kept. The first stage gets the rest:
    ``1 - fine_fraction - SWEEP_FRACTION`` (750 evaluations of the default 1250). The refinement starts from the coarse result or the start point, whichever fits the
    data as given better. When neither simulates on the data as given (a load peak the windows
    averaged away drives the model out of its range), it starts from the best of the coarse stage's
    other end points that does; when none does, the rest of the budget searches the data as given in
    one stage. The returned cost is the data-as-given cost.

    Parameters
    ----------
    problem : IdentificationProblem
        What to fit.
    evaluations : int
        Budget in model evaluations (each simulates every recording once; a coarse one counts as one).
    seed : int
        TPE sampler seed (the refinement is deterministic).
    tpe_fraction : float
        Share of the (first stage's) budget for TPE (0 = refinement from the start point only).
    starts : int
        Refinements planned from the best distinct TPE candidates (the start point counts as a
        candidate); budget they leave unspent refines further distinct candidates.
    startup_per_coordinate : int
        Random TPE start-up trials per coordinate (capped at 30 % of the TPE trials).
    progress : callable, optional
        Called as ``progress(phase, evaluations, best_cost)`` after each phase.
    coarse_window_s : float or None
        Window (s) of the first stage; None: one stage on the data as given.
    fine_fraction : float
        Share of the budget for the refinement on the data as given, in (0, 1).
    """
    if evaluations < 2:
        raise BatteryPredictorError(f"--evaluations must be >= 2, got {evaluations}")
    coarse = coarsened(problem, coarse_window_s) if coarse_window_s else None
    n_first, n_sweep, n_fine = _stage_budgets(problem, evaluations, fine_fraction)
    if coarse is None or not 0.0 < fine_fraction < 1.0 or n_first < 2 or n_fine < 2:
        return _identify_one_stage(problem, evaluations=evaluations, seed=seed, tpe_fraction=tpe_fraction,
                                   starts=starts, startup_per_coordinate=startup_per_coordinate, progress=progress)
    label = f"{coarse_window_s:g} s windows: "

    def coarse_progress(phase: str, count: int, cost: float) -> None:
        if progress is not None:
            progress(label + phase, count, cost)

    first = _identify_one_stage(coarse, evaluations=n_first, seed=seed, tpe_fraction=tpe_fraction,
                                starts=starts, startup_per_coordinate=startup_per_coordinate,
                                progress=coarse_progress)
    tic = time.perf_counter()
    log = EvaluationLog(budget=n_fine + n_sweep)
    residual = _cost_function(problem, log)
    # the refinement starts from the better, on the data as given, of the coarse result and the start point
    # (a start already at the optimum of the data as given stays there when the coarse optimum differs)
    start = problem.unit({c.name: c.initial for c in problem.space})
    begin = min((first.unit, start), key=lambda u: _sum_of_squares(residual(u)))
    history = [(label + phase, count, c) for phase, count, c in first.history]
    if problem.failed(residual(begin)):
        running = _running_end(problem, residual, first.ends)
        begin = begin if running is None else running
    if problem.failed(residual(begin)) and n_fine + n_sweep - log.count >= 2:
        return _searched_as_given(problem, first, history, n_fine + n_sweep - log.count, log, seed=seed,
                                  tpe_fraction=tpe_fraction, starts=starts,
                                  startup_per_coordinate=startup_per_coordinate, progress=progress, tic=tic)
    sweep_log = EvaluationLog(budget=0)
    swept = alignment_sweep(coarse, sweep_log, first.unit, min(n_sweep, n_fine + n_sweep - log.count))
    return _refined_as_given(problem, first, residual, begin, swept, log, sweep_log, n_fine + n_sweep, history,
                             label=label, progress=progress, tic=tic)


def _stage_budgets(problem: IdentificationProblem, evaluations: int, fine_fraction: float) -> tuple[int, int, int]:
    """Evaluations of :func:`identify`'s first (coarse) stage, its alignment sweep and its refinement on the data as
    given: the sweep gets :data:`SWEEP_FRACTION` when the space has :data:`SWEEP_COORDINATE`, the refinement
    ``fine_fraction``, the first stage the rest."""
    n_fine = int(round(fine_fraction * evaluations))
    sweeps = any(c.name == SWEEP_COORDINATE for c in problem.space)
    n_sweep = int(round(SWEEP_FRACTION * evaluations)) if sweeps else 0
    return evaluations - n_fine - n_sweep, n_sweep, n_fine


def _refined_as_given(problem: IdentificationProblem, first: IdentificationResult,
                      residual: Callable[[np.ndarray], np.ndarray], begin: np.ndarray,
                      swept: tuple[float, np.ndarray] | None, log: EvaluationLog, sweep_log: EvaluationLog,
                      budget: int, history: list[tuple[str, int, float]], *, label: str,
                      progress: Callable[[str, int, float], None] | None, tic: float) -> IdentificationResult:
    """:func:`identify`'s second stage: the refinement from ``begin`` on the data as given, and of the alignment
    sweep's end when it lies below the first stage's cost, within ``budget`` evaluations (the sweep's included);
    the better of the two by R2_mod."""

    def note(phase: str, count: int, cost: float) -> None:
        history.append((phase, count, cost))
        if progress is not None:
            progress(phase, count, cost)

    if swept is not None:
        note(label + f"alignment sweep (reached {swept[0]:.4g})", first.evaluations + sweep_log.count, first.cost)
    # the refinement of the stage's result first: at most its share and what the sweep left
    log.budget = budget - sweep_log.count
    cost, best = _refine(residual, begin, max_evaluations=log.budget)
    note("refine on the data as given", first.evaluations + sweep_log.count + log.count, cost)
    n_starts, scored = first.starts + 1, 0
    # a sweep end below the first stage's optimum lies in a better basin: refined on the data as given as
    # well, and the two ends scored (two evaluations kept back)
    log.budget -= 2
    if (swept is not None and swept[0] < first.cost
            and log.budget - log.count >= MIN_LEFTOVER_JACOBIANS * (len(begin) + 1)):
        other = _refine(residual, swept[1], max_evaluations=log.budget - log.count)
        cost, best = select_by_r2_mod(problem, [(cost, best), other])
        n_starts, scored = n_starts + 1, 2
        note(f"refine the alignment sweep's end (first-stage cost {swept[0]:.4g} < {first.cost:.4g})",
             first.evaluations + sweep_log.count + log.count + scored, cost)
    return IdentificationResult(coordinates=problem.coordinates(best), unit=best, cost=cost,
                                evaluations=first.evaluations + sweep_log.count + log.count + scored,
                                tpe_evaluations=first.tpe_evaluations, starts=n_starts,
                                seconds=first.seconds + time.perf_counter() - tic, history=history,
                                model_seconds=first.model_seconds + sweep_log.model_seconds + log.model_seconds)


def _running_end(problem: IdentificationProblem, residual: Callable[[np.ndarray], np.ndarray],
                 ends: Sequence[tuple[float, np.ndarray]]) -> np.ndarray | None:
    """Of a coarse stage's ``ends``, the one that fits the data as given best among those that simulate there."""
    try:
        running = [u for _, u in ends if not problem.failed(residual(u))]
    except BudgetExhausted:
        return None
    return min(running, key=lambda u: _sum_of_squares(residual(u))) if running else None


def _searched_as_given(problem: IdentificationProblem, first: IdentificationResult,
                       history: list[tuple[str, int, float]], evaluations: int, log: EvaluationLog, *,
                       seed: int, tpe_fraction: float, starts: int, startup_per_coordinate: int,
                       progress: Callable[[str, int, float], None] | None, tic: float) -> IdentificationResult:
    """The second stage of :func:`identify` when neither the coarse result nor the start simulates on the
    data as given: a one-stage search there with the ``evaluations`` left (the coarse stage's result and
    the evaluations spent on it are kept in the counts)."""
    second = _identify_one_stage(problem, evaluations=max(evaluations, 2), seed=seed, tpe_fraction=tpe_fraction,
                                 starts=starts, startup_per_coordinate=startup_per_coordinate, progress=None)
    history.extend(("the coarse result fails on the data as given; searched there: " + phase,
                    first.evaluations + log.count + count, c) for phase, count, c in second.history)
    if progress is not None:
        progress(*history[-1])
    return replace(second, evaluations=first.evaluations + log.count + second.evaluations,
                   tpe_evaluations=first.tpe_evaluations + second.tpe_evaluations,
                   starts=first.starts + second.starts, history=history,
                   seconds=first.seconds + time.perf_counter() - tic,
                   model_seconds=first.model_seconds + log.model_seconds + second.model_seconds)


def _sum_of_squares(r: np.ndarray) -> float:
    return float(r @ r)


def _identify_one_stage(problem: IdentificationProblem, *, evaluations: int, seed: int, tpe_fraction: float,
                        starts: int, startup_per_coordinate: int,
                        progress: Callable[[str, int, float], None] | None) -> IdentificationResult:
    """Seeded TPE then multi-start trust-region least squares on ``problem``'s data as given (see :func:`identify`)."""
    if evaluations < 2:
        raise BatteryPredictorError(f"--evaluations must be >= 2, got {evaluations}")
    if not 0.0 <= tpe_fraction < 1.0:
        raise BatteryPredictorError(f"TPE fraction must be within [0, 1), got {tpe_fraction}")
    tic = time.perf_counter()
    log = EvaluationLog(budget=evaluations)
    residual = _cost_function(problem, log)
    start = problem.unit({c.name: c.initial for c in problem.space})
    history: list[tuple[str, int, float]] = []

    def note(phase: str) -> None:
        history.append((phase, log.count, log.best_cost))
        if progress is not None:
            progress(phase, log.count, log.best_cost)

    n_tpe = int(round(tpe_fraction * evaluations))
    candidates: list[tuple[float, np.ndarray]] = []
    if n_tpe > 0:
        candidates = _run_tpe(problem, residual, n_tpe, seed, start, startup_per_coordinate)
    else:
        r = residual(start)
        candidates = [(float(r @ r), start)]
    tpe_count = log.count
    note("tpe")
    picked = with_start(distinct_best(candidates, len(candidates)), start)
    jacobian_cost = len(problem.space) + 1
    ends = [(log.best_cost, log.best_unit if log.best_unit is not None else start)]
    for k, unit in enumerate(picked):
        # one scoring evaluation per end point is kept back: TPE's best and every refinement planned or run
        budget = max(log.count, evaluations - (max(1, starts, k + 1) + 1))
        remaining = budget - log.count
        if remaining < MIN_LEFTOVER_JACOBIANS * jacobian_cost:
            break
        planned_left = max(max(1, starts) - k, 1)
        log.budget = log.count + min(remaining, max(remaining // planned_left, MIN_REFINE_JACOBIANS * jacobian_cost))
        ends.append(_refine(residual, unit, max_evaluations=log.budget - log.count))
        log.budget = budget
        note(f"refine {k + 1} (reached {ends[-1][0]:.4g})")
    scoring_tic = time.perf_counter()
    cost, best = select_by_r2_mod(problem, ends)
    model_s = log.model_seconds + time.perf_counter() - scoring_tic
    return IdentificationResult(coordinates=problem.coordinates(best), unit=best, cost=cost,
                                evaluations=log.count + len(ends), tpe_evaluations=tpe_count, starts=len(ends) - 1,
                                seconds=time.perf_counter() - tic, history=history, model_seconds=model_s,
                                ends=ends)


#: Labels of the structures :func:`identify_structures` fits.
STRUCTURE_AS_GIVEN = "params"
STRUCTURE_OHMIC = "ohmic step"


@dataclass(frozen=True)
class StructureFit:
    """One model structure identified on the data (:func:`identify_structures`).

    Attributes
    ----------
    label : str
        :data:`STRUCTURE_AS_GIVEN` or :data:`STRUCTURE_OHMIC`.
    params : PackParams
        The params the structure starts from (the fitted params are these with the identified values).
    problem : IdentificationProblem
        Its identification problem.
    result : IdentificationResult
        The identification.
    score : CandidateScore or None
        R2_mod and RMSE at the result (None when it fails to simulate).
    """

    label: str
    params: PackParams
    problem: IdentificationProblem
    result: IdentificationResult
    score: CandidateScore | None

    @property
    def r2_mod(self) -> float:
        """Mean R2_mod on the fit data (``-inf`` when the result fails to simulate)."""
        return self.score.r2_mod if self.score is not None and math.isfinite(self.score.r2_mod) else -math.inf


def identify_structures(params: PackParams, recordings: Sequence[Recording], simulator: PackSimulator,
                        space_for: Callable[[PackParams], list[Coordinate]], *, group_voltages: bool = True,
                        ohmic: bool = False, progress: Callable[[str, int, float], None] | None = None,
                        **identify_options: Any) -> list[StructureFit]:
    """Identify the params as given and, with ``ohmic`` where the data show current steps, the ohmic structure; best first.

    The ohmic structure (:func:`~battery_predictor.fitting.identifiable.ohmic_structure`: the fastest
    kinetics searched, the series resistance started at the data's instantaneous step) is a second
    model of the same coordinates, identified with the same options (so the budget is per structure);
    the structures are ranked by R2_mod on the fit data (seed paper Eq. 1-3), as the end points within
    one identification are (:func:`select_by_r2_mod`).

    Parameters
    ----------
    params : PackParams
        The starting model.
    recordings : sequence of Recording
        The fit data.
    simulator : PackSimulator
        The simulator of every evaluation.
    space_for : callable
        ``space_for(params)``: the search box of a structure's params (e.g. :func:`default_space`).
    group_voltages : bool
        As :class:`IdentificationProblem`.
    ohmic : bool
        True: also the ohmic structure where the data have current steps (``fit --ohmic-structure``);
        False (default): the params' structure only.
    progress : callable, optional
        ``progress(phase, evaluations, best_cost)``; the phase names the structure.
    **identify_options
        Passed to :func:`identify` (``evaluations``, ``seed``, ...).

    Returns
    -------
    list of StructureFit
        Highest R2_mod first.
    """
    from battery_predictor.fitting.identifiable import ohmic_structure, with_start_value

    structures: list[tuple[str, PackParams, list[Coordinate]]] = [(STRUCTURE_AS_GIVEN, params, space_for(params))]
    alternative = ohmic_structure(params, recordings) if ohmic else None
    if alternative is not None:
        ohmic_params, step_ohm = alternative
        structures.append((STRUCTURE_OHMIC, ohmic_params,
                           with_start_value(space_for(ohmic_params), "series_resistance_ohm", step_ohm)))
    fits = []
    for label, structure_params, space in structures:
        problem = IdentificationProblem(params=structure_params, recordings=recordings, simulator=simulator,
                                        space=space, group_voltages=group_voltages)

        def labelled(phase: str, evaluations: int, cost: float, label: str = label) -> None:
            if progress is not None:
                progress(f"{label}: {phase}", evaluations, cost)

        result = identify(problem, progress=labelled, **identify_options)
        try:
            score: CandidateScore | None = problem.score(result.coordinates)
        except SimulationError:
            score = None
        fits.append(StructureFit(label, structure_params, problem, result, score))
    return sorted(fits, key=lambda f: -f.r2_mod)


def jacobian_at(problem: IdentificationProblem, unit: np.ndarray, step: float = FD_STEP) -> tuple[np.ndarray,
                                                                                                np.ndarray]:
    """Residuals and their Jacobian on the unit cube at ``unit`` (``n + 1`` evaluations)."""
    log = EvaluationLog(budget=unit.size + 2)
    residual = _cost_function(problem, log)
    return residual(unit), _fd_jacobian(residual, np.asarray(unit, dtype=float), step)


__all__ = ["IdentificationProblem", "IdentificationResult", "StructureFit", "identify", "identify_structures",
           "identifiability_of", "jacobian_at",
           "raw_identifiability", "startup_trials",
           "distinct_best", "ResidualGrid", "CandidateScore"]


def identifiability_of(problem: IdentificationProblem, unit: np.ndarray) -> IdentifiabilityReport:
    """:class:`~battery_predictor.fitting.identifiability.IdentifiabilityReport` at ``unit`` (n + 1 evaluations)."""
    from battery_predictor.fitting.identifiability import analyse, theta_jacobian

    residuals, jac_unit = jacobian_at(problem, unit)
    spans = [math.log(c.high / c.low) if c.log else c.high - c.low for c in problem.space]
    coords = problem.coordinates(unit)
    return analyse(problem.names, [coords[n] for n in problem.names], [c.log for c in problem.space], residuals,
                   theta_jacobian(jac_unit, spans), [(c.low, c.high) for c in problem.space])


def raw_identifiability(problem: FitProblem, space: Sequence[FitParameter], values: dict[str, float],
                        relative_step: float = 1e-3) -> IdentifiabilityReport:
    """Identifiability of the raw parameters of the paper's fit (``fit --method tpe``) at ``values``.

    ``theta = ln(value)`` for every parameter (intervals are relative), with forward differences of
    ``relative_step`` in ``theta``; residuals as in :class:`ResidualGrid`. Costs ``n + 1``
    evaluations of the :class:`~battery_predictor.fitting.problem.FitProblem`.
    """
    from battery_predictor.fitting.identifiability import analyse

    n_rec = len(problem.recordings)
    grids = [ResidualGrid.for_recording(r, padding_s(r, problem.extend_fraction), n_rec) for r in problem.recordings]

    def residuals(vals: dict[str, float]) -> np.ndarray:
        results: Sequence[PackSimResult | None]
        try:
            results = problem.evaluate(vals).results
        except SimulationError:
            results = [None] * n_rec
        return np.concatenate([g.residuals(r) for g, r in zip(grids, results, strict=True)])

    names = [p.name for p in space]
    base = {n: float(values[n]) for n in names}
    r0 = residuals(base)
    jac = np.empty((r0.size, len(names)))
    for i, name in enumerate(names):
        shifted = dict(base)
        shifted[name] = base[name] * math.exp(relative_step)
        jac[:, i] = (residuals(shifted) - r0) / relative_step
    return analyse(names, [base[n] for n in names], [True] * len(names), r0, jac,
                   [(p.low, p.high) for p in space])
