"""The load a remaining-runtime prediction assumes: the present discharge cycle's statistics.

A discharge cycle runs from its first discharge after a charging session (or after start-up) to the
start of the next charging session; rest before that first discharge (a soak, a robot parked on
its charger) is not part of its load. Only a
*charging session* ends it: a charging current (below ``-charge_current_a``) held for at least
``charge_session_s`` of charging time, without a discharge in between. Regenerative braking,
short charging blips and pauses belong to the cycle: they enter its average as what they are
(negative or zero current), so a drive cycle with regen keeps its load estimate.

Two estimators of the average load, both time-weighted over the 5 s window averages:

- ``"cycle"`` (default, the paper's): the mean net current since the cycle began;
- ``"ewma"``: an exponentially weighted mean with time constant ``time_constant_s``, normalised
  by its weight so that it equals the cycle mean while the cycle is young; it follows a change of
  usage within a cycle at the price of more noise.

Both estimate the mean power (W, from the window voltages) the same way: a robot's drives and
electronics behind DC-DC converters draw a power, not a current, so the current of a repeated task
rises as the pack voltage falls (measured: the repeated drive cycles of the Panasonic 18650PF draw a
constant mean power while their mean current rises by 15 %; docs/runtime_real_data).

The recurring load peak is a quantile of the cycle's window currents (see ``PredictorConfig``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

#: A gap between two samples counts at most this long in the averages, s.
MAX_GAP_S = 300.0
#: Load estimators of :class:`LoadEstimator`.
ESTIMATORS = ("cycle", "ewma")


@dataclass(frozen=True)
class LoadEstimate:
    """The load statistics of the present discharge cycle.

    Attributes
    ----------
    mean_current_a : float
        Estimated average net pack current in A (positive = discharge); NaN before two samples.
    mean_power_w : float
        Estimated average net pack power in W (positive = discharge); NaN without voltages.
    duration_s : float
        Length of the present cycle covered by samples, s.
    charging : bool
        True while a charging session is in progress (the pack charges and has charged for at
        least ``charge_session_s``).
    charging_current_a : float
        Latest current while charging, A (negative); NaN otherwise.
    """

    mean_current_a: float
    duration_s: float
    charging: bool
    charging_current_a: float
    mean_power_w: float = math.nan


class LoadEstimator:
    """Discharge-cycle load statistics fed with window averages (not thread-safe; the core locks).

    Parameters
    ----------
    charge_current_a : float
        A current below ``-charge_current_a`` (A) charges the pack.
    charge_session_s : float
        Charging time (s) after which a charging session ends the discharge cycle.
    estimator : {"cycle", "ewma"}
        How the average load is estimated (module docstring).
    time_constant_s : float
        Time constant of ``"ewma"``, s.
    """

    def __init__(self, charge_current_a: float, charge_session_s: float = 300.0, estimator: str = "cycle",
                 time_constant_s: float = 1800.0) -> None:
        if estimator not in ESTIMATORS:
            raise ValueError(f"load estimator {estimator!r} is not one of {', '.join(ESTIMATORS)}")
        if not time_constant_s > 0:
            raise ValueError(f"time_constant_s must be > 0, got {time_constant_s}")
        self.charge_current_a = charge_current_a
        self.charge_session_s = charge_session_s
        self.estimator = estimator
        self.time_constant_s = time_constant_s
        self.sessions_ended = 0
        self._charging_s = 0.0
        self._in_session = False
        self._last_stamp_s: float | None = None
        self._last_current_a = 0.0
        self._last_power_w = math.nan
        self._reset_cycle()

    def _reset_cycle(self) -> None:
        self._started = False
        self._charge_as = 0.0
        self._duration_s = 0.0
        self._ewma_sum = 0.0
        self._ewma_weight = 0.0
        self._energy_ws = 0.0
        self._power_duration_s = 0.0
        self._ewma_power_sum = 0.0
        self._ewma_power_weight = 0.0
        self.currents: deque[float] = deque(maxlen=20000)
        self.peaks: deque[float] = deque(maxlen=20000)
        self.stamps: deque[float] = deque(maxlen=20000)
        self.voltages: deque[float] = deque(maxlen=20000)

    def add(self, stamp_s: float, current_a: float, peak_current_a: float = math.nan,
            voltage_v: float = math.nan) -> bool:
        """Take a window (s, mean A positive = discharge, largest sample A or NaN, mean V or NaN).

        Returns True when a charging session just began.
        """
        dt = 0.0
        if self._last_stamp_s is not None and stamp_s > self._last_stamp_s:
            dt = min(stamp_s - self._last_stamp_s, MAX_GAP_S)
        previous = self._last_current_a
        previous_power = self._last_power_w
        self._last_stamp_s = stamp_s
        self._last_current_a = current_a
        self._last_power_w = current_a * voltage_v
        was_in_session = self._in_session
        began = self._track_charging(dt, previous, current_a)
        if self._in_session:
            return began
        if not self._started:
            if current_a <= self.charge_current_a:
                return began  # idle or charging before the cycle's first discharge: not its load
            self._started = True
            dt = 0.0
        if dt > 0 and not was_in_session:  # the interval that ends a session belongs to the charger
            self._charge_as += dt * previous
            self._duration_s += dt
            decay = math.exp(-dt / self.time_constant_s)
            self._ewma_sum = self._ewma_sum * decay + previous * (1.0 - decay)
            self._ewma_weight = self._ewma_weight * decay + (1.0 - decay)
            if math.isfinite(previous_power):
                self._energy_ws += dt * previous_power
                self._power_duration_s += dt
                self._ewma_power_sum = self._ewma_power_sum * decay + previous_power * (1.0 - decay)
                self._ewma_power_weight = self._ewma_power_weight * decay + (1.0 - decay)
        self.currents.append(current_a)
        self.peaks.append(peak_current_a if math.isfinite(peak_current_a) else current_a)
        self.stamps.append(stamp_s)
        self.voltages.append(voltage_v)
        return began

    def _track_charging(self, dt: float, previous_a: float, current_a: float) -> bool:
        """Count charging time; a session begins once it reaches ``charge_session_s``, ends at a discharge."""
        if current_a > self.charge_current_a:
            self._charging_s = 0.0
            self._in_session = False
            return False
        if previous_a < -self.charge_current_a:
            self._charging_s += dt
        if not self._in_session and current_a < -self.charge_current_a and self._charging_s >= self.charge_session_s:
            self._in_session = True
            self.sessions_ended += 1
            self._reset_cycle()
            return True
        return False

    @property
    def in_session(self) -> bool:
        """True from the start of a charging session until the next discharge."""
        return self._in_session

    def estimate(self) -> LoadEstimate:
        """The present estimate."""
        if self.estimator == "ewma":
            mean = self._ewma_sum / self._ewma_weight if self._ewma_weight > 0 else math.nan
            power = self._ewma_power_sum / self._ewma_power_weight if self._ewma_power_weight > 0 else math.nan
        else:
            mean = self._charge_as / self._duration_s if self._duration_s > 0 else math.nan
            power = self._energy_ws / self._power_duration_s if self._power_duration_s > 0 else math.nan
        charging = self._in_session and self._last_current_a < -self.charge_current_a
        return LoadEstimate(mean, self._duration_s, charging, self._last_current_a if charging else math.nan, power)

    def kind(self, resistance_ohm: float, prior: float) -> LoadKind:
        """:func:`load_kind` of the present cycle's windows."""
        return load_kind(self.stamps, self.currents, self.voltages, resistance_ohm, prior)

    def quantile_a(self, q: float, *, of_peaks: bool = False) -> float:
        """Quantile ``q`` of the cycle's window currents (or of each window's largest sample), A.

        NaN when there are none or ``q <= 0``.
        """
        values = self.peaks if of_peaks else self.currents
        if not values or q <= 0:
            return math.nan
        return float(np.quantile(np.fromiter(values, float), min(q, 1.0)))


def heavy_run_s(stamps_s: npt.ArrayLike, currents_a: npt.ArrayLike, quantile: float,
                window_s: float | None = None) -> float:
    """Mean duration (s) of the runs of consecutive heavy windows: at or above ``quantile`` of the discharge
    windows and above their median.

    It says whether the windows resolve the load's states: a robot's usage holds a heavy state for tens of
    seconds to minutes (runs of many windows), a drive cycle's heavy moments are shorter than a window or
    two. A window's length is the median step of ``stamps_s``; a step longer than 1.5 windows ends a run.

    Parameters
    ----------
    stamps_s, currents_a : array_like
        Window stamps (s) and mean currents (A, positive = discharge), in time order.
    quantile : float
        Quantile (0 .. 1) of the discharge windows (> 0 A) that makes a window heavy.
    window_s : float, optional
        The windows' length, s, when the caller has it (default: the median step of ``stamps_s``).

    Returns
    -------
    float
        The mean run length in s; NaN with fewer than two discharge windows or none heavy (a constant load).
    """
    t = np.asarray(stamps_s, dtype=float)
    i = np.asarray(currents_a, dtype=float)
    discharge = i[i > 0.0]
    if t.size != i.size or discharge.size < 2:
        return math.nan
    window_s = float(np.median(np.diff(t))) if window_s is None else float(window_s)
    if not (math.isfinite(window_s) and window_s > 0.0):
        return math.nan
    level = float(np.quantile(discharge, min(max(quantile, 0.0), 1.0)))
    heavy = (i >= level) & (i > float(np.median(discharge)))  # a window at the usual level is not heavy
    joined = np.concatenate([[False], heavy[1:] & heavy[:-1] & (np.diff(t) <= 1.5 * window_s)])
    runs = int(np.count_nonzero(heavy & ~joined))
    return float(np.count_nonzero(heavy)) * window_s / runs if runs else math.nan


@dataclass(frozen=True)
class LoadKind:
    """Whether the cycle's load behaves as a current or as a power.

    Attributes
    ----------
    exponent : float
        ``k`` of a demand ``I V^k`` that stays constant: 0 = a constant current, 1 = a constant
        power (``V`` the open-circuit estimate ``V + I R``).
    z_current, z_power : float
        Trend statistics (Spearman's rank correlation with time times sqrt(n)) of the window
        currents and of the window powers over the cycle's discharge windows; NaN when too few.
    windows : int
        Blocks of discharge windows the statistics used.
    decided : bool
        False when the data did not tell the two apart and ``exponent`` is the prior.
    """

    exponent: float
    z_current: float
    z_power: float
    windows: int
    decided: bool


#: Windows are pooled into blocks of this length (s) before the trends are ranked: usage holds a
#: level for minutes, so neighbouring windows are not independent samples.
KIND_BLOCK_S = 300.0
#: Blocks below which the load kind is not judged (the prior applies).
MIN_KIND_BLOCKS = 8
#: Least difference of the two trend statistics for the data to decide.
MIN_KIND_SEPARATION = 3.0
#: A steady load is seen on blocks of this length (s): at least :data:`MIN_STEADY_BLOCKS` of them
#: (not counting the first and the last) whose current (or power) spreads by less than
#: :data:`STEADY_SPREAD` (relative) while the other spreads by more than twice that is a constant
#: current (or power), decided at once.
STEADY_BLOCK_S = 60.0
MIN_STEADY_BLOCKS = 5
STEADY_SPREAD = 0.01


def _block_means(t: np.ndarray, values: list[np.ndarray], block_s: float = KIND_BLOCK_S) -> list[np.ndarray]:
    """Means of each array over consecutive ``block_s`` blocks of ``t`` (empty blocks dropped)."""
    index = np.floor((t - t[0]) / block_s).astype(int)
    counts = np.bincount(index)
    keep = counts > 0
    return [np.bincount(index, weights=v)[keep] / counts[keep] for v in values]


def _spread(values: np.ndarray) -> float:
    """Range of ``values`` relative to their mean magnitude."""
    return float(np.ptp(values)) / max(float(np.mean(np.abs(values))), 1e-12)


def _steady_kind(t: np.ndarray, i: np.ndarray, power: np.ndarray) -> LoadKind | None:
    """A constant current or power seen directly on :data:`STEADY_BLOCK_S` blocks, else None."""
    _, ib, pb = _block_means(t, [t, i, power], STEADY_BLOCK_S)
    ib, pb = ib[1:-1], pb[1:-1]  # the first and last block hold the load's switching on and off
    if ib.size < MIN_STEADY_BLOCKS:
        return None
    spread_i, spread_p = _spread(ib), _spread(pb)
    if spread_i < STEADY_SPREAD < spread_p / 2:
        return LoadKind(0.0, 0.0, math.nan, int(ib.size), True)
    if spread_p < STEADY_SPREAD < spread_i / 2:
        return LoadKind(1.0, math.nan, 0.0, int(ib.size), True)
    return None


def _trend(t: np.ndarray, values: np.ndarray, spearmanr: Callable[[np.ndarray, np.ndarray], Any]) -> float:
    """Spearman's rank correlation of ``values`` with ``t``; 0 (no trend) for a constant series."""
    if np.ptp(values) <= 1e-9 * max(float(np.max(np.abs(values))), 1e-12):
        return 0.0  # a constant current (a CC discharge) has no trend, and rank statistics are undefined
    return float(spearmanr(t, values).statistic)


def load_kind(stamps_s: npt.ArrayLike, currents_a: npt.ArrayLike, voltages_v: npt.ArrayLike, resistance_ohm: float,
              prior: float) -> LoadKind:
    """The exponent of the load's constant demand ``I V^k`` from the windows of a discharge cycle.

    Under a constant current the currents show no trend over the cycle while the powers fall
    with the voltage; under a constant power it is the other way round. The discharge windows
    are pooled into :data:`KIND_BLOCK_S` blocks and the trends measured as Spearman rank
    correlations of the block means with time (robust to the spread of the usage), scaled by
    sqrt(blocks - 1): ``z_current`` and ``z_power``. The exponent is where the trend of ``I V^k``
    would vanish, interpolated linearly between them and clipped to 0..1; ``prior`` with fewer
    than :data:`MIN_KIND_BLOCKS` blocks or when the statistics differ by less than
    :data:`MIN_KIND_SEPARATION` (the voltage has not moved enough to tell). A steady load (a
    constant-current or constant-power test, :data:`STEADY_SPREAD`) is decided first, on shorter
    blocks, without the trends.

    Parameters
    ----------
    stamps_s, currents_a, voltages_v : sequence of float
        Window stamps (s), mean currents (A, positive = discharge) and mean voltages (V).
    resistance_ohm : float
        Pack resistance (Ohm) that moves a window's voltage to its open-circuit estimate.
    prior : float
        Exponent used when the data do not decide.
    """
    from scipy.stats import spearmanr

    t = np.asarray(stamps_s, dtype=float)
    i = np.asarray(currents_a, dtype=float)
    v = np.asarray(voltages_v, dtype=float)
    ok = np.isfinite(v) & np.isfinite(i) & np.isfinite(t)
    if ok.any():
        ok &= i > 0.05 * float(np.max(i[ok]))
    if ok.sum() < 2:
        return LoadKind(prior, math.nan, math.nan, 0, False)
    r_ohm = resistance_ohm if math.isfinite(resistance_ohm) else 0.0
    power = i * (v + i * r_ohm)
    steady = _steady_kind(t[ok], i[ok], power[ok])
    if steady is not None:
        return steady
    tb, ib, pb = _block_means(t[ok], [t[ok], i[ok], power[ok]])
    n = int(tb.size)
    if n < MIN_KIND_BLOCKS:
        return LoadKind(prior, math.nan, math.nan, n, False)
    root = math.sqrt(n - 1)
    z_current = _trend(tb, ib, spearmanr) * root
    z_power = _trend(tb, pb, spearmanr) * root
    if not (math.isfinite(z_current) and math.isfinite(z_power)) or abs(z_current - z_power) < MIN_KIND_SEPARATION:
        return LoadKind(prior, z_current, z_power, n, False)
    exponent = min(max(z_current / (z_current - z_power), 0.0), 1.0)
    return LoadKind(exponent, z_current, z_power, n, True)
