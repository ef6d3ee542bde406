"""Remaining runtime (paper 5.1.5, steps 2-3).

From the calibrated SOC, the pack is simulated under the average load of the present discharge
cycle at ``temperature_k``: the last measured temperature for isothermal cells, the ambient for a
lumped thermal cell, whose start state then carries the measured cell temperature
(:mod:`.temperature`); the remaining runtime is the time until the pack voltage
reaches the robot's cut-off (13.30 V for the information robot) or a cell reaches its lower
cut-off, whichever comes first. The average load is a constant current (the paper's), a
constant power (the current rises as the voltage falls, as it does behind the robots' DC-DC
converters and drives), or in between (:func:`demand_run`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import brentq

from battery_predictor.errors import SimulationError
from battery_predictor.prediction.calibration import Calibration, calibrate_soc

if TYPE_CHECKING:
    from battery_predictor.prediction.pack_model import PackModel, RunStart
    from battery_predictor.simulation.base import SegmentRun

#: Longest horizon simulated, s (beyond it the runtime is reported as at least this).
MAX_HORIZON_S = 72 * 3600.0


@dataclass(frozen=True)
class RuntimePrediction:
    """A remaining-runtime prediction.

    Attributes
    ----------
    remaining_s : float
        Time in s until the cut-off (``MAX_HORIZON_S`` when not reached within it).
    calibration : Calibration
        The calibrated SOC it started from.
    assumed_current_a, assumed_temperature_k : float
        The load (A) and the runs' temperature (K; the ambient of a lumped thermal cell) it assumed.
    cutoff_voltage_v : float
        Pack voltage threshold in V.
    limited_by : str
        ``"pack_cutoff"`` (average load), ``"peak_cutoff"`` (a load peak), ``"sampled_cutoff"`` (futures
        resampled from the cycle's load), ``"cell_cutoff"`` or ``"horizon"``.
    average_end_s : float
        Time in s at which the average load alone reaches the cut-off (NaN beyond the horizon).
    charge_to_end_ah : float
        Charge the average load draws until then, Ah.
    cell_limited : bool
        True when a cell's lower cut-off (e.g. a weak series group's), not the pack threshold, ends
        the average-load run.
    end_temperature_k : float
        Lumped thermal cells: the (normal) cells' temperature where the average-load run ends (its cut-off or
        the horizon), K; NaN for isothermal cells.
    peak_end_s : float
        Time in s at which a load peak drawn at any moment first reaches the cut-off (NaN without peaks).
    """

    remaining_s: float
    calibration: Calibration
    assumed_current_a: float
    assumed_temperature_k: float
    cutoff_voltage_v: float
    limited_by: str
    average_end_s: float = math.nan
    charge_to_end_ah: float = math.nan
    cell_limited: bool = False
    end_temperature_k: float = math.nan
    peak_end_s: float = math.nan


def run_end_temperature_k(run: SegmentRun) -> float:
    """The cells' temperature (K) where ``run`` ended: a lumped thermal state's (normal cells), else NaN."""
    temperatures = getattr(run.final_state, "cell_temperature_k", None)
    return float(np.asarray(temperatures).ravel()[0]) if temperatures is not None else math.nan


def time_to_voltage_s(time_s: np.ndarray, voltage_v: np.ndarray, threshold_v: float) -> float | None:
    """First time (s) at which ``voltage_v`` falls to ``threshold_v`` (linear interpolation), or None."""
    below = np.nonzero(voltage_v <= threshold_v)[0]
    if below.size == 0:
        return None
    i = int(below[0])
    if i == 0:
        return float(time_s[0])
    v0, v1, t0, t1 = voltage_v[i - 1], voltage_v[i], time_s[i - 1], time_s[i]
    return float(t0 + (v0 - threshold_v) / (v0 - v1) * (t1 - t0)) if v0 != v1 else float(t1)


def peak_voltage_drop_v(runner: PackModel, start: RunStart, average_current_a: float, peak_current_a: float,
                        temperature_k: float, settle_s: float = 5.0) -> float:
    """Extra pack voltage drop (V) under ``peak_current_a`` compared to ``average_current_a``.

    Both are simulated for ``settle_s`` (the monitor's 5 s window) from the same state.
    """
    if not peak_current_a > average_current_a:
        return 0.0
    a = runner.run(start, [(settle_s, average_current_a)], temperature_k)
    b = runner.run(start, [(settle_s, peak_current_a)], temperature_k)
    if a.reached_cutoff or b.reached_cutoff:
        return 0.0
    return max(0.0, float(np.mean(a.pack_voltage_v) - np.mean(b.pack_voltage_v)))


#: Step (s) of the piecewise-constant current that follows a constant power.
POWER_STEP_S = 60.0
#: ... at most this many steps over the horizon (longer steps on long horizons).
POWER_MAX_STEPS = 120
#: Fixed-point passes of :func:`demand_run` at most, and the current change (relative) that ends them.
POWER_PASSES = 10
POWER_TOLERANCE = 0.002
#: ... and the change of the time to the cut-off (s) that ends them.
POWER_END_TOLERANCE_S = 30.0


@dataclass(frozen=True)
class LoadPath:
    """The average load ahead as piecewise-constant pack currents.

    Attributes
    ----------
    step_s : float
        Length of every step, s.
    current_a : numpy.ndarray
        Pack current of each step in A (positive = discharge).
    """

    step_s: float
    current_a: np.ndarray

    @classmethod
    def constant(cls, current_a: float, horizon_s: float) -> LoadPath:
        """One constant current for ``horizon_s``."""
        return cls(float(horizon_s), np.array([float(current_a)]))

    def segments(self, until_s: float) -> list[tuple[float, float]]:
        """``[(duration_s, current_a), ...]`` covering the first ``until_s`` s."""
        out, t = [], 0.0
        for cur in self.current_a:
            if t >= until_s - 1e-9:
                break
            out.append((min(self.step_s, until_s - t), float(cur)))
            t += self.step_s
        if t < until_s - 1e-9:
            out.append((until_s - t, float(self.current_a[-1])))
        return out

    def current_at(self, time_s: float) -> float:
        """Pack current (A) at ``time_s`` s."""
        return float(self.currents_at(np.array([time_s]))[0])

    def currents_at(self, time_s: np.ndarray) -> np.ndarray:
        """Pack currents (A) at the times ``time_s`` (s)."""
        k = np.clip((np.asarray(time_s, dtype=float) // self.step_s).astype(int), 0, len(self.current_a) - 1)
        return self.current_a[k]


def demand_run(runner: PackModel, start: RunStart, current_a: float, power_w: float, exponent: float,
               horizon_s: float, temperature_k: float, first_voltage_v: float,
               cutoff_voltage_v: float) -> tuple[SegmentRun, LoadPath]:
    """The pack under a constant demand ``I V^k``: ``(run, LoadPath)``.

    The current of each step (:data:`POWER_STEP_S`, longer when the horizon needs more than
    :data:`POWER_MAX_STEPS` of them) is ``current_a^(1-k) (power_w / V)^k`` with
    the pack voltage ``V`` the previous pass simulated in that step (the first pass takes
    ``first_voltage_v``): a constant current for ``k = 0``, a constant power for ``k = 1``. Passes
    repeat until the currents before the pack reaches ``cutoff_voltage_v`` (but for the last two
    steps, which follow the crossing time) change by less than :data:`POWER_TOLERANCE` (relative)
    and the crossing time by less than :data:`POWER_END_TOLERANCE_S`. After the crossing the
    currents do not matter to the runtime (beyond a cell's cut-off the voltage and so the current
    run away).

    Raises
    ------
    SimulationError
        The passes do not settle (the pack cannot deliver the power).
    """
    if exponent <= 0.0:
        path = LoadPath.constant(current_a, horizon_s)
        return runner.run(start, path.segments(horizon_s), temperature_k), path
    scale = current_a ** (1.0 - exponent) * power_w ** exponent
    step_s = max(POWER_STEP_S, horizon_s / POWER_MAX_STEPS)
    n = max(1, int(math.ceil(horizon_s / step_s)))
    mid = (np.arange(n) + 0.5) * step_s
    path = LoadPath(step_s, np.full(n, scale / first_voltage_v ** exponent))
    last_end_s = math.inf
    for _ in range(POWER_PASSES):
        run = runner.run(start, path.segments(horizon_s), temperature_k)
        t_end = time_to_voltage_s(run.time_s, run.pack_voltage_v, cutoff_voltage_v)
        t_end = float(run.end_time_s) if t_end is None else t_end
        v = np.interp(mid, run.time_s, run.pack_voltage_v)  # held at the last value after the run ends
        v = np.maximum(v, 0.5 * cutoff_voltage_v)
        new = LoadPath(step_s, scale / v ** exponent)
        before = mid < t_end - 2 * step_s  # the steps at the knee follow the crossing time
        change = np.abs(new.current_a[before] - path.current_a[before]) / new.current_a[before]
        settled = change.size == 0 or float(change.max()) < POWER_TOLERANCE
        if settled and abs(t_end - last_end_s) <= POWER_END_TOLERANCE_S:
            return run, path
        path, last_end_s = new, t_end
    raise SimulationError(f"the load ({current_a:.2f} A, {power_w:.1f} W, exponent {exponent:.2f}) did not settle "
                          f"in {POWER_PASSES} passes")


def run_end_s(run: SegmentRun, cutoff_voltage_v: float) -> float | None:
    """Time (s) at which an average-load run reaches the pack cut-off or a cell's, or None within its horizon."""
    t_end = time_to_voltage_s(run.time_s, run.pack_voltage_v, cutoff_voltage_v)
    if t_end is None and run.reached_cutoff:
        t_end = float(run.end_time_s)
    return t_end


def path_charge_ah(path: LoadPath, until_s: float) -> float:
    """Charge (Ah) the load path draws in its first ``until_s`` s."""
    return sum(d * i for d, i in path.segments(until_s)) / 3600.0 if until_s > 0 else 0.0


def load_horizon_s(runner: PackModel, soc: float, average_current_a: float) -> float:
    """Horizon (s) simulated for a load: 1.5 times the charge left at the average current, plus an hour."""
    charge_left_ah = max(soc - runner.soc_bounds[0], 0.02) * runner.capacity_ah
    return min(MAX_HORIZON_S, 1.5 * charge_left_ah * 3600.0 / average_current_a + 3600.0)


def peak_crossing_s(runner: PackModel, start: RunStart, average: LoadPath, peak_factor: float,
                    temperature_k: float, cutoff_voltage_v: float, average_run: SegmentRun, *, settle_s: float = 5.0,
                    tolerance_s: float = 30.0, max_runs: int = 16) -> float | None:
    """First time (s) at which a load peak, drawn from the average-load trajectory, pulls the pack to the cut-off.

    ``g(t)`` = mean pack voltage over ``settle_s`` at ``peak_factor`` times the average current
    of time ``t``, after ``t`` s of the average load, minus the cut-off; its root is bracketed
    between 0 and the average-load crossing (where ``g < 0`` since the peak draws more) and found
    with Brent's method on at most ``max_runs`` model runs (to ``tolerance_s``). The first guess is
    the average-load trajectory lowered by the peak's extra drop at the present state.

    Returns None when no crossing exists before the end of ``average_run``.

    Raises
    ------
    SimulationError
        When the search finds no crossing in the bracket or does not converge in ``max_runs``
        runs: never a made-up time.
    """
    def g(t_s: float) -> float:
        prefix = average.segments(t_s) if t_s > 1.0 else []
        run = runner.run(start, prefix + [(settle_s, peak_factor * average.current_at(t_s))], temperature_k)
        if run.reached_cutoff:
            return -1.0  # a cell reaches its cut-off during the peak: the robot stops here
        peak_part = run.time_s >= run.time_s[-1] - settle_s + 1e-9
        return float(np.mean(run.pack_voltage_v[peak_part])) - cutoff_voltage_v

    t_avg = time_to_voltage_s(average_run.time_s, average_run.pack_voltage_v, cutoff_voltage_v)
    if t_avg is None:
        t_avg = float(average_run.end_time_s) if average_run.reached_cutoff else None
    if t_avg is None:
        return None
    if g(0.0) <= 0.0:
        return 0.0
    first_a = average.current_at(0.0)
    drop_v = peak_voltage_drop_v(runner, start, first_a, peak_factor * first_a, temperature_k, settle_s)
    guess = time_to_voltage_s(average_run.time_s, average_run.pack_voltage_v, cutoff_voltage_v + drop_v)
    lo, hi = 0.0, float(t_avg)
    if guess is not None and 0.0 < guess < hi:  # tighten the bracket with the first guess
        if g(guess) > 0.0:
            lo = guess
        else:
            hi = guess
    if hi - lo <= tolerance_s:
        return 0.5 * (lo + hi)
    g_hi = g(hi)
    if g_hi > 0.0 and hi == t_avg:
        # a peak barely above the average (a constant-current discharge) still holds at the average-load
        # crossing, which is interpolated between samples: the peak-load crossing is that crossing
        return float(hi)
    try:
        root, result = brentq(g, lo, hi, xtol=tolerance_s, maxiter=max_runs, full_output=True, disp=False)
    except ValueError as exc:  # no sign change over the bracket: the model is not monotone here
        raise SimulationError(f"peak-load runtime search found no crossing between {lo / 60:.1f} and "
                              f"{hi / 60:.1f} min ({exc})") from None
    if not result.converged:
        raise SimulationError(f"peak-load runtime search did not converge in {max_runs} model runs "
                              f"(bracket {lo / 60:.1f}..{hi / 60:.1f} min)")
    return float(root)


#: Futures drawn by :func:`sampled_end_s`, the length (s) of the history blocks they are made of, and the shortest
#: history (s) they are drawn from (shorter: the peak-load crossing stands).
SAMPLED_FUTURES = 24
SAMPLED_BLOCK_S = 600.0
SAMPLED_MIN_HISTORY_S = 1200.0


def sampled_ends_s(runner: PackModel, start: RunStart, history_a: np.ndarray, window_s: float, average: LoadPath,
                   temperature_k: float, cutoff_voltage_v: float, average_end_s: float, *,
                   futures: int = SAMPLED_FUTURES, block_s: float = SAMPLED_BLOCK_S, seed: int = 0) -> np.ndarray | None:
    """The times (s) at which futures resampled from the cycle's windows reach the cut-off, one per future.

    Each future is the cycle's window currents (``history_a``, A, one per ``window_s``) cut into blocks of
    ``block_s`` taken from random places, end to end, scaled so that its mean follows the average load ahead
    (``average``: a constant current, or the rising current of a constant power); the model runs it from
    ``start`` and it ends where the pack voltage first reaches ``cutoff_voltage_v`` (or a cell its cut-off). A
    future still running at ``1.25 average_end_s`` + one block ends at ``inf`` (later than any answer). Seeded:
    the same state gives the same futures.

    Returns None when the history is shorter than :data:`SAMPLED_MIN_HISTORY_S`, its mean is not a discharge,
    or ``average_end_s`` is not a positive time.
    """
    history_a = np.asarray(history_a, dtype=float)
    mean_a = float(np.mean(history_a)) if history_a.size else math.nan
    if history_a.size * window_s < SAMPLED_MIN_HISTORY_S or not (math.isfinite(mean_a) and mean_a > 0.0):
        return None
    if not (math.isfinite(average_end_s) and average_end_s > 0.0):
        return None
    horizon_s = 1.25 * average_end_s + block_s
    n_windows = int(math.ceil(horizon_s / window_s))
    block = max(1, min(int(round(block_s / window_s)), history_a.size))
    scale = average.currents_at((np.arange(n_windows) + 0.5) * window_s) / mean_a
    rng = np.random.default_rng(seed)
    ends = []
    for _ in range(futures):
        starts = rng.integers(0, history_a.size - block + 1, size=n_windows // block + 1)
        currents = np.concatenate([history_a[k:k + block] for k in starts])[:n_windows] * scale
        run = runner.run(start, [(window_s, float(c)) for c in currents], temperature_k)
        end = time_to_voltage_s(run.time_s, run.pack_voltage_v, cutoff_voltage_v)
        if end is None and run.reached_cutoff:
            end = float(run.end_time_s)
        ends.append(math.inf if end is None else end)
    return np.array(ends)


def sampled_end_s(runner: PackModel, start: RunStart, history_a: np.ndarray, window_s: float, average: LoadPath,
                  temperature_k: float, cutoff_voltage_v: float, average_end_s: float, *, quantile: float = 0.5,
                  futures: int = SAMPLED_FUTURES, block_s: float = SAMPLED_BLOCK_S, seed: int = 0) -> float | None:
    """Quantile ``quantile`` of :func:`sampled_ends_s` (s): where a random usage's futures reach the cut-off.

    A random usage ends at the first load state heavy enough *at that charge*, not where its heaviest windows
    would cross if they could come at any moment. Returns None where :func:`sampled_ends_s` does, or when the
    quantile falls beyond the futures' horizon (then the caller's answer stands).
    """
    ends = sampled_ends_s(runner, start, history_a, window_s, average, temperature_k, cutoff_voltage_v,
                          average_end_s, futures=futures, block_s=block_s, seed=seed)
    if ends is None:
        return None
    answer = float(np.quantile(ends, quantile, method="inverted_cdf"))
    return answer if math.isfinite(answer) else None


def sampled_fraction_of(prediction: RuntimePrediction) -> float | None:
    """Where a sampled answer lies between its peak-load and average-load crossings (0 .. 1 and beyond), or None."""
    if prediction.limited_by != "sampled_cutoff":
        return None
    span = prediction.average_end_s - prediction.peak_end_s
    if not (math.isfinite(span) and span > 0.0):
        return None
    return (prediction.remaining_s - prediction.peak_end_s) / span


def predict_remaining_runtime(runner: PackModel, voltage_v: float, current_a: float, temperature_k: float,
                              average_current_a: float, cutoff_voltage_v: float,
                              calibration: Calibration | None = None,
                              peak_current_a: float | None = None, peak_duration_s: float = 5.0,
                              average_power_w: float | None = None, load_exponent: float = 1.0,
                              end_event: str = "peak", load_history_a: np.ndarray | None = None,
                              history_window_s: float = 5.0, sampled_fraction: float | None = None) -> RuntimePrediction:
    """Calibrate the SOC (unless given), then simulate the average load to the cut-off.

    Parameters
    ----------
    runner : PackModel
        The fitted pack model.
    voltage_v, current_a, temperature_k : float
        Latest measured pack voltage (V), current (A, positive = discharge) and the runs' temperature (K):
        the latest measured one for isothermal cells; the ambient for lumped thermal cells, whose start
        (``calibration``) carries the cell temperature (:class:`.temperature.TemperatureAhead`).
    average_current_a : float
        Average discharge current of the present cycle in A (> 0).
    cutoff_voltage_v : float
        Pack voltage at which the robot stops (V).
    calibration : Calibration, optional
        An existing calibration of the present state (e.g. on history); else calibrated on the sample.
    peak_current_a : float, optional
        Recurring load peak of the present cycle (A). The robot stops when a *measured* 5 s window
        reaches the cut-off, which happens at a load peak, not at the average load: the runtime is
        the first time a peak drawn from the average-load trajectory reaches the cut-off
        (:func:`peak_crossing_s`), not when the average load does (the paper's strategy). Under a
        constant power the peak keeps its ratio to the average current.
    peak_duration_s : float
        How long a peak lasts in the model, s: the monitor's window for a peak of window means, a
        sample's length for the largest sample of a window.
    average_power_w : float, optional
        Average discharge power of the present cycle in W (> 0): the load ahead is the demand
        ``I V^k`` of :func:`demand_run` with ``k = load_exponent``; without it, a constant
        ``average_current_a``.
    load_exponent : float
        ``k`` (0 = constant current .. 1 = constant power) when ``average_power_w`` is given.
    end_event : {"peak", "sampled"}
        Where a load with peaks ends: ``"peak"`` at the peak-load crossing; ``"sampled"`` at the median end
        of futures resampled from ``load_history_a`` (:func:`sampled_end_s`; ``limited_by`` is
        ``"sampled_cutoff"``), or at the peak-load crossing when the history is too short.
    load_history_a : numpy.ndarray, optional
        The present cycle's window currents (A, positive = discharge, one per ``history_window_s`` s).
    sampled_fraction : float, optional
        With ``end_event="sampled"``: where an earlier sampled answer lay between its peak-load and average-load
        crossings (0 at the first, 1 at the second; :func:`sampled_fraction_of`); the futures are not run again
        and the answer keeps that place between the present crossings.
    """
    if not (math.isfinite(average_current_a) and average_current_a > 0):
        raise SimulationError(f"average discharge current must be > 0 A, got {average_current_a}")
    if average_power_w is not None and not (math.isfinite(average_power_w) and average_power_w > 0):
        raise SimulationError(f"average discharge power must be > 0 W, got {average_power_w}")
    cal = calibration if calibration is not None else calibrate_soc(runner, voltage_v, current_a, temperature_k)
    if voltage_v <= cutoff_voltage_v:
        return RuntimePrediction(0.0, cal, average_current_a, temperature_k, cutoff_voltage_v, "pack_cutoff")
    horizon_s = load_horizon_s(runner, cal.soc, average_current_a)
    exponent = min(max(float(load_exponent), 0.0), 1.0) if average_power_w is not None else 0.0
    run, path = demand_run(runner, cal.start, average_current_a, average_power_w or 0.0, exponent, horizon_s,
                           temperature_k, voltage_v, cutoff_voltage_v)
    assumed_a = path.current_at(0.0)
    t_avg = run_end_s(run, cutoff_voltage_v)
    ends = (t_avg, path_charge_ah(path, t_avg)) if t_avg is not None else (math.nan, math.nan)
    cell_limited = bool(run.reached_cutoff) and time_to_voltage_s(run.time_s, run.pack_voltage_v, cutoff_voltage_v) is None
    end_k = run_end_temperature_k(run)
    if peak_current_a is not None and peak_current_a > average_current_a:
        t_peak = peak_crossing_s(runner, cal.start, path, float(peak_current_a) / average_current_a, temperature_k,
                                 cutoff_voltage_v, run, settle_s=peak_duration_s)
        t_sampled = None
        if t_peak is not None and end_event == "sampled" and t_avg is not None:
            if sampled_fraction is not None and math.isfinite(sampled_fraction) and t_avg > t_peak:
                t_sampled = max(0.0, t_peak + sampled_fraction * (t_avg - t_peak))
            elif load_history_a is not None:
                t_sampled = sampled_end_s(runner, cal.start, load_history_a, history_window_s, path, temperature_k,
                                          cutoff_voltage_v, t_avg)
        if t_sampled is not None:
            return RuntimePrediction(t_sampled, cal, assumed_a, temperature_k, cutoff_voltage_v, "sampled_cutoff",
                                     *ends, cell_limited=cell_limited, end_temperature_k=end_k,
                                     peak_end_s=t_peak if t_peak is not None else math.nan)
        if t_peak is not None:
            return RuntimePrediction(t_peak, cal, assumed_a, temperature_k, cutoff_voltage_v, "peak_cutoff", *ends,
                                     cell_limited=cell_limited, end_temperature_k=end_k, peak_end_s=t_peak)
    t_pack = time_to_voltage_s(run.time_s, run.pack_voltage_v, cutoff_voltage_v)
    if t_pack is not None:
        return RuntimePrediction(t_pack, cal, assumed_a, temperature_k, cutoff_voltage_v, "pack_cutoff", *ends,
                                 end_temperature_k=end_k)
    if run.reached_cutoff:
        return RuntimePrediction(run.end_time_s, cal, assumed_a, temperature_k, cutoff_voltage_v, "cell_cutoff",
                                 *ends, cell_limited=True, end_temperature_k=end_k)
    return RuntimePrediction(horizon_s, cal, assumed_a, temperature_k, cutoff_voltage_v, "horizon",
                             end_temperature_k=end_k)
