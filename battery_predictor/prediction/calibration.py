"""SOC calibration from the latest measured voltage, current and temperature (paper 5.1.5, step 1).

The model's SOC is the one whose short simulation reproduces the measured pack
voltage (root of a monotone function, :func:`scipy.optimize.brentq`):

- :func:`calibrate_soc` (the paper's form): from relaxed particles, ``settle_s`` at the
  latest current must end at the latest voltage;
- :func:`calibrate_on_history`: the SOC at the start of a recent window (default 10 min)
  from which the measured current history reproduces the voltages of the window's last
  minutes. It carries the particles' concentration gradients into the present state, which
  matters right after driving (polarisation) and for flat-OCV chemistries such as LiFePO4.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from scipy.optimize import brentq

from battery_predictor.errors import SimulationError
from battery_predictor.prediction.cell_runner import RunState

if TYPE_CHECKING:
    from battery_predictor.prediction.pack_model import PackModel
    from battery_predictor.simulation.engine.segments import EngineState

_PAST_CUTOFF = -1e3


@dataclass(frozen=True)
class Calibration:
    """A calibrated state of charge.

    Attributes
    ----------
    soc : float
        Present state of charge on PyBaMM's linear scale (0..1 between the 0 %/100 % OCV
        points; may lie outside when the pack is used beyond them, see ``PackRunner.soc_bounds``).
    residual_v : float
        Simulated minus measured pack voltage in V at the solution.
    clipped : str
        ``""``, or ``"below_empty"`` / ``"above_full"`` when the measurement lies outside the model's range.
    state : RunState, EngineState or None
        The present model state (with gradients) when calibrated on history, else None (PyBaMM
        stepping's or the engine's).
    latest_residual_v : float
        Simulated minus measured pack voltage in V over the latest measurements (the last sample, or
        the matched end of a history window); NaN when unknown.
    """

    soc: float
    residual_v: float
    clipped: str = ""
    state: RunState | EngineState | None = None
    latest_residual_v: float = math.nan

    @property
    def start(self) -> float | RunState | EngineState:
        """What a prediction continues from: the state when known, else the SOC."""
        return self.state if self.state is not None else self.soc


def _solve_monotone(f: Callable[[float], float], bounds: tuple[float, float],
                    tol: float) -> tuple[float, float, str]:
    """Root of an increasing ``f`` within ``bounds``; returns (x, f(x), clipped)."""
    lo, hi = bounds
    f_lo = f(lo)
    step = 0.01
    while f_lo <= _PAST_CUTOFF and lo < hi - step:
        lo = min(lo + step, hi)
        f_lo = f(lo)
        step *= 1.6
    if f_lo >= 0 or f_lo <= _PAST_CUTOFF:
        return lo, f_lo, "below_empty"
    f_hi = f(hi)
    if f_hi <= 0:
        return hi, f_hi, "above_full"
    x = brentq(f, lo, hi, xtol=tol)
    return float(x), float(f(x)), ""


def _start(runner: PackModel, soc: float, cell_temperature_k: float | None) -> object:
    """A run's start at ``soc``: with its cells at ``cell_temperature_k`` (K) when given (lumped thermal cells)."""
    if cell_temperature_k is None:
        return soc
    return runner.at_cell_temperature(soc, cell_temperature_k)  # type: ignore[attr-defined]


def _check_finite(**values: float) -> None:
    for name, val in values.items():
        if not math.isfinite(val):
            raise SimulationError(f"cannot calibrate: {name} is not finite ({val})")


def calibrate_soc(runner: PackModel, voltage_v: float, current_a: float, temperature_k: float,
                  settle_s: float = 60.0, tol_soc: float = 1e-4, *,
                  cell_temperature_k: float | None = None) -> Calibration:
    """SOC whose ``settle_s`` simulation at ``current_a`` ends at the measured ``voltage_v``.

    Parameters
    ----------
    runner : PackModel
        The pack model.
    voltage_v : float
        Measured pack voltage in V.
    current_a : float
        Measured pack current in A (positive = discharge).
    temperature_k : float
        Measured temperature in K (a lumped thermal cell's ambient when ``cell_temperature_k`` is given).
    settle_s : float
        Length of the short simulation in s.
    cell_temperature_k : float, optional
        Lumped thermal cells: the cells start at this measured temperature (K) instead of ``temperature_k``
        (``runner.at_cell_temperature``).
    """
    _check_finite(voltage=voltage_v, current=current_a, temperature=temperature_k)
    holder: dict = {}

    def f(soc: float) -> float:
        try:
            run = runner.run(_start(runner, soc, cell_temperature_k), [(settle_s, current_a)], temperature_k)
        except SimulationError as exc:
            if "Minimum voltage" not in str(exc):
                raise
            return _PAST_CUTOFF  # at or past the cut-off already at this SOC
        if run.reached_cutoff:
            return _PAST_CUTOFF
        holder[soc] = run
        return float(run.pack_voltage_v[-1]) - voltage_v

    soc, res, clipped = _solve_monotone(f, runner.soc_bounds, tol_soc)
    run = holder.get(soc)
    if run is None or run.final_state is None or clipped:
        return Calibration(soc, res, clipped)
    # the settle's end stands for "now": continue from its state (charge of the settle not counted)
    state = replace(run.final_state, soc_start=soc, charge_ah=0.0)  # keeps every group's solution
    return Calibration(soc, res, clipped, state, res)


def history_segments(time_s: npt.ArrayLike, current_a: npt.ArrayLike,
                     max_segments: int = 24) -> list[tuple[float, float]]:
    """Charge-conserving constant-current segments (s, A) of a sampled current history.

    The current at ``time_s[k]`` holds until ``time_s[k + 1]``; the span is cut into at
    most ``max_segments`` equal segments carrying the mean current of each.
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_a, dtype=float)
    if t.size < 2:
        raise SimulationError("history needs at least two samples")
    span = float(t[-1] - t[0])
    n = max(1, min(max_segments, t.size - 1))
    edges = np.linspace(t[0], t[-1], n + 1)
    cum_t = np.concatenate([[0.0], np.cumsum(np.diff(t) * i[:-1])])
    cum = np.interp(edges, t, cum_t)
    dur = span / n
    return [(dur, float((cum[k + 1] - cum[k]) / dur)) for k in range(n)]


def calibrate_on_history(runner: PackModel, time_s: npt.ArrayLike, voltage_v: npt.ArrayLike, current_a: npt.ArrayLike,
                         temperature_k: float, *,
                         window_s: float = 600.0, match_s: float = 120.0, max_segments: int = 12,
                         tol_soc: float = 5e-4, target_residual_v: float = 0.0,
                         cell_temperature_k: float | None = None) -> Calibration:
    """Calibrate on the last ``window_s`` of history; returns the present SOC and state.

    Parameters
    ----------
    time_s, voltage_v, current_a : array_like
        Pack history (s, V, A positive = discharge), increasing time; the last sample is "now".
    temperature_k : float
        Temperature in K (a lumped thermal cell's ambient when ``cell_temperature_k`` is given).
    window_s : float
        History simulated from the unknown start SOC.
    match_s : float
        The last part of the window whose mean voltage must be reproduced.
    target_residual_v : float
        Simulated minus measured mean voltage the solution should leave, V (0: reproduce the measurement;
        the predictor's smallest correction of a drifted state leaves part of its tolerance). Ignored when
        the history is too short to calibrate on.
    cell_temperature_k : float, optional
        Lumped thermal cells: the temperature (K) measured at the window's start, where the cells start
        (also the start of the settle when the history is too short to calibrate on).
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_v, dtype=float)
    i = np.asarray(current_a, dtype=float)
    _check_finite(temperature=temperature_k)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v)) and np.all(np.isfinite(i))):
        raise SimulationError("cannot calibrate: history holds non-finite samples")
    keep = t >= t[-1] - window_s
    t, v, i = t[keep], v[keep], i[keep]
    if t.size < 3 or t[-1] - t[0] < 2 * match_s / 3:
        return calibrate_soc(runner, float(v[-1]), float(i[-1]), temperature_k, cell_temperature_k=cell_temperature_k)
    segs = history_segments(t, i, max_segments)
    rel = t - t[0]
    match = rel >= rel[-1] - match_s
    holder: dict = {}

    def f(soc: float) -> float:
        try:
            run = runner.run(_start(runner, soc, cell_temperature_k), segs, temperature_k)
        except SimulationError as exc:
            if "Minimum voltage" not in str(exc):
                raise
            return _PAST_CUTOFF
        if run.reached_cutoff:
            return _PAST_CUTOFF
        holder[soc] = run
        sim = np.interp(rel[match], run.time_s, run.pack_voltage_v)
        return float(np.mean(sim - v[match])) - target_residual_v

    soc0, res, clipped = _solve_monotone(f, runner.soc_bounds, tol_soc)
    res = res + target_residual_v if res > _PAST_CUTOFF else res
    run = holder.get(soc0)
    if run is None or run.final_state is None:
        return Calibration(soc0, res, clipped)
    return Calibration(runner.soc_of(run.final_state), res, clipped, run.final_state, res)
