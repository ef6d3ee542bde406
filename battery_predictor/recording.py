"""A measured (or emulated) pack recording: the one data type every command consumes."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from battery_predictor.errors import InputDataError


@dataclass(frozen=True)
class Recording:
    """Time series of one discharge (or any load) of a pack or cell.

    Attributes
    ----------
    time_s : numpy.ndarray
        Sample times in s, strictly increasing, starting anywhere.
    voltage_v : numpy.ndarray
        Terminal voltage in V.
    current_a : numpy.ndarray
        Current in A, **positive while discharging** (PyBaMM convention).
    temperature_k : numpy.ndarray or None
        Temperature in K (ambient or cell surface), or None when not measured.
    source : str
        Where it came from (file path), used in error messages.
    metadata : dict
        Free-form metadata (pack id, seed, ground truth...).
    group_voltage_v : numpy.ndarray or None
        Voltage in V of each series group (or cell) of the pack, shape (n_samples, n_groups), NaN where
        a group was not measured at a sample (CSV columns ``group<k>_voltage_V``,
        ``sensor_msgs/BatteryState.cell_voltage`` in a bag); None when not measured.
    """

    time_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    temperature_k: np.ndarray | None = None
    source: str = "<memory>"
    metadata: dict[str, Any] = field(default_factory=dict)
    group_voltage_v: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.time_s)
        for name in ("voltage_v", "current_a"):
            if len(getattr(self, name)) != n:
                raise InputDataError(f"{self.source}: column {name} has {len(getattr(self, name))} rows, time_s has {n}")
        if self.temperature_k is not None and len(self.temperature_k) != n:
            raise InputDataError(f"{self.source}: column temperature has {len(self.temperature_k)} rows, time_s has {n}")
        if self.group_voltage_v is not None:
            shape = np.shape(self.group_voltage_v)
            if len(shape) != 2 or shape[0] != n or shape[1] < 1:
                raise InputDataError(f"{self.source}: group voltages have shape {shape}, expected ({n}, n_groups)")

    @property
    def min_group_voltage_v(self) -> np.ndarray | None:
        """The lowest measured group voltage (V) at each sample (NaN where no group was measured); None
        when the recording has no group voltages."""
        if self.group_voltage_v is None:
            return None
        g = np.asarray(self.group_voltage_v, dtype=float)
        finite = np.isfinite(g)
        out = np.min(np.where(finite, g, np.inf), axis=1)
        out[~finite.any(axis=1)] = np.nan
        return out

    @property
    def duration_s(self) -> float:
        """Duration of the recording in s."""
        return float(self.time_s[-1] - self.time_s[0]) if len(self.time_s) else 0.0

    @property
    def relative_time_s(self) -> np.ndarray:
        """Time in s from the first sample."""
        return self.time_s - self.time_s[0]

    def charge_drawn_ah(self) -> float:
        """Charge drawn over the recording in Ah (trapezoidal, discharge positive)."""
        if len(self.time_s) < 2:
            return 0.0
        dt = np.diff(self.time_s)
        return float(np.sum(0.5 * (self.current_a[1:] + self.current_a[:-1]) * dt) / 3600.0)

    def mean_temperature_k(self, default_k: float = 298.15) -> float:
        """Mean temperature in K, or ``default_k`` when not measured."""
        if self.temperature_k is None or not np.isfinite(self.temperature_k).any():
            return float(default_k)
        return float(np.nanmean(self.temperature_k))

    def slice_time(self, start_s: float, end_s: float) -> Recording:
        """Samples with ``start_s <= time_s <= end_s`` (absolute times)."""
        mask = (self.time_s >= start_s) & (self.time_s <= end_s)
        return Recording(
            time_s=self.time_s[mask],
            voltage_v=self.voltage_v[mask],
            current_a=self.current_a[mask],
            temperature_k=None if self.temperature_k is None else self.temperature_k[mask],
            source=self.source,
            metadata=dict(self.metadata),
            group_voltage_v=None if self.group_voltage_v is None else self.group_voltage_v[mask],
        )


#: A recording is taken to end at its cut-off when its last voltage is within this fraction of
#: its voltage range above its minimum and the last current is a discharge (under a varying
#: load the lowest voltage may fall on an earlier high-current step) ...
END_AT_MIN_FRACTION = 0.02
#: ... and it ends on the knee of its discharge curve: over the last :data:`KNEE_CHARGE_FRACTION` of
#: the charge it drew, its voltage corrected for the ohmic drop (:func:`end_steepness`) falls at least
#: this many times faster than on average over the recording. A cut-off is where the open-circuit
#: voltage turns steep near empty: the measured discharges that stop at their cut-off (LG M50,
#: Panasonic drive cycles, K2 LFP, the Leaf pack, 1-2.75C) fall 2.9-13x faster there; a working day
#: that stops on the plateau while a high load happens to give its lowest voltage falls about as fast
#: as on average (0.1-1.5x, second generator; docs/findings.md).
KNEE_STEEPNESS = 2.0
#: Share of the recording's drawn charge over which the end's steepness is measured.
KNEE_CHARGE_FRACTION = 0.03


#: A current step is a change between consecutive samples of at least this share of the recording's current range.
STEP_FRACTION_OF_RANGE = 0.1
#: Metadata key under which a recording trimmed to its discharge keeps how long (s) the recording went on after
#: it (rests, a recharge; :func:`~battery_predictor.fitting.problem.trim_to_discharge`).
DROPPED_TAIL_S_KEY = "dropped_tail_s"
#: Metadata key under which a recording averaged over windows keeps the step resistance of its samples as
#: measured: ``[Ohm, number of steps]`` (:func:`~battery_predictor.fitting.resample.resample_windows`,
#: :func:`as_measured_steps`).
AS_MEASURED_STEP_RESISTANCE_KEY = "ohmic_resistance_as_measured_ohm"


def _step_ratios(rec: Recording) -> np.ndarray:
    """``-dV / dI`` (Ohm) over the recording's current steps (:data:`STEP_FRACTION_OF_RANGE`)."""
    v = np.asarray(rec.voltage_v, dtype=float)
    i = np.asarray(rec.current_a, dtype=float)
    if i.size < 2:
        return np.empty(0)
    dv, di = np.diff(v), np.diff(i)
    steps = np.abs(di) >= STEP_FRACTION_OF_RANGE * max(float(np.ptp(i)), 1e-12)
    return -dv[steps] / di[steps]


def ohmic_resistance_estimate(rec: Recording) -> float:
    """The recording's ohmic resistance from its current steps (Ohm, >= 0; 0 when it has none).

    The median of ``-dV / dI`` over consecutive samples whose current changes by at least 10 % of
    the recording's current range (fewer than three such steps: 0, e.g. a constant-current discharge).
    """
    ratios = _step_ratios(rec)
    if ratios.size < 3:
        return 0.0
    return max(float(np.median(ratios)), 0.0)


def _load_step_ratios(rec: Recording) -> np.ndarray:
    """:func:`_step_ratios` of a recording whose current varies by at least :data:`STEP_FRACTION_OF_RANGE` of its
    largest magnitude; none otherwise (a constant-current discharge's "steps" are the current reading's noise)."""
    i = np.asarray(rec.current_a, dtype=float)
    if i.size < 2 or float(np.ptp(i)) < STEP_FRACTION_OF_RANGE * float(np.max(np.abs(i))):
        return np.empty(0)
    return _step_ratios(rec)


def as_measured_steps(rec: Recording) -> list[float]:
    """``[median -dV/dI (Ohm), number of steps]`` of the recording's load steps (:func:`step_resistance_ohm`), for
    its metadata when it is averaged."""
    ratios = _load_step_ratios(rec)
    return [float(np.median(ratios)) if ratios.size else 0.0, float(ratios.size)]


def step_resistance_ohm(recordings: Sequence[Recording]) -> float:
    """The instantaneous resistance (Ohm, pack terminals) the recordings' current steps show; 0 when they have none.

    The median of ``-dV / dI`` over the current steps of all recordings pooled (a step as in
    :func:`ohmic_resistance_estimate`; a recording whose current range is below a tenth of its largest
    current, such as a constant-current discharge, has none), at each recording's own resolution: a recording averaged over
    windows contributes the estimate of its samples as measured, kept in its metadata
    (:data:`AS_MEASURED_STEP_RESISTANCE_KEY`), once per step it had. A window average mixes the
    step with the first seconds of polarisation; the samples as measured hold the step itself.

    Parameters
    ----------
    recordings : sequence of Recording
        Voltage in V, current in A (discharge positive).

    Returns
    -------
    float
        The step resistance in Ohm (>= 0); 0 when fewer than three steps are found.
    """
    ratios: list[np.ndarray] = []
    for rec in recordings:
        kept = rec.metadata.get(AS_MEASURED_STEP_RESISTANCE_KEY)
        if kept is not None:
            value_ohm, count = kept
            ratios.append(np.full(int(count), float(value_ohm)))
        else:
            ratios.append(_load_step_ratios(rec))
    pooled = np.concatenate(ratios) if ratios else np.empty(0)
    if pooled.size < 3:
        return 0.0
    return max(float(np.median(pooled)), 0.0)


def end_steepness(rec: Recording, charge_fraction: float = KNEE_CHARGE_FRACTION) -> float:
    """How much faster the recording's voltage falls at its end than on average, per charge drawn.

    The voltage is corrected for the ohmic drop (``V + I R``, :func:`ohmic_resistance_estimate`) so
    that a load step does not count as a fall. Returns the drop over the last ``charge_fraction`` of
    the drawn charge divided by ``charge_fraction`` times the drop from the recording's highest
    corrected voltage to its last one (1 = as steep as on average; 0 when nothing was drawn or the
    voltage did not fall).
    """
    t = np.asarray(rec.time_s, dtype=float)
    i = np.asarray(rec.current_a, dtype=float)
    if t.size < 2:
        return 0.0
    u = np.asarray(rec.voltage_v, dtype=float) + i * ohmic_resistance_estimate(rec)
    dis = np.maximum(i, 0.0)
    q = np.concatenate([[0.0], np.cumsum(0.5 * (dis[1:] + dis[:-1]) * np.diff(t))])
    span = float(np.max(u) - u[-1])
    if q[-1] <= 0.0 or span <= 0.0:
        return 0.0
    k = int(np.searchsorted(q, q[-1] * (1.0 - charge_fraction)))
    before = float(np.median(u[max(k - 2, 0):k + 3]))  # a few samples: the noise
    return (before - float(u[-1])) / (charge_fraction * span)


#: ``thresholds`` keys under which a fitted params file keeps the deepest state of its fit data
#: (:class:`DeepestState`; written by ``fit``, read by the route check).
DEEPEST_STATE_KEYS = ("fit_data_deepest_voltage_v", "fit_data_deepest_current_a", "fit_data_deepest_temperature_k")


@dataclass(frozen=True)
class DeepestState:
    """The most discharged state a set of recordings shows: one sample of them.

    Attributes
    ----------
    voltage_v : float
        Terminal voltage at the sample, V.
    current_a : float
        Current at the sample, A (>= 0: discharge or rest).
    temperature_k : float
        Temperature at the sample, K.
    """

    voltage_v: float
    current_a: float
    temperature_k: float

    def as_thresholds(self) -> dict[str, float]:
        """The state as ``thresholds`` entries (:data:`DEEPEST_STATE_KEYS`)."""
        return dict(zip(DEEPEST_STATE_KEYS, (self.voltage_v, self.current_a, self.temperature_k), strict=True))

    @classmethod
    def from_thresholds(cls, thresholds: dict[str, float]) -> DeepestState | None:
        """The state kept in ``thresholds``; None unless all of :data:`DEEPEST_STATE_KEYS` are there."""
        if not all(key in thresholds for key in DEEPEST_STATE_KEYS):
            return None
        return cls(*(float(thresholds[key]) for key in DEEPEST_STATE_KEYS))


def deepest_state(recordings: Sequence[Recording], default_temperature_k: float) -> DeepestState | None:
    """The sample of ``recordings`` whose voltage, corrected for the ohmic drop, is lowest; None without samples.

    The correction is ``V + I R`` with the recordings' step resistance (:func:`step_resistance_ohm`, 0 for
    constant currents), over the samples that discharge or rest (``I >= 0``), so that a high load on a full pack
    does not count as deeper than a light one near empty.

    Parameters
    ----------
    recordings : sequence of Recording
        Voltage in V, current in A (discharge positive), temperature in K or None.
    default_temperature_k : float
        Temperature (K) of a sample whose recording has none.
    """
    r_ohm = step_resistance_ohm(recordings)
    best: tuple[float, DeepestState] | None = None
    for rec in recordings:
        corrected = _depth_voltage_v(rec, r_ohm)
        if corrected.size == 0 or not np.isfinite(corrected.min()):
            continue
        k = int(np.argmin(corrected))
        if best is None or corrected[k] < best[0]:
            temp = float(rec.temperature_k[k]) if rec.temperature_k is not None else math.nan
            temp = temp if math.isfinite(temp) else float(default_temperature_k)
            best = (float(corrected[k]), DeepestState(float(rec.voltage_v[k]), float(rec.current_a[k]), temp))
    return None if best is None else best[1]


def _depth_voltage_v(rec: Recording, r_ohm: float) -> np.ndarray:
    """``V + I R`` (V) of the samples that discharge or rest, +inf elsewhere (the depth :func:`deepest_state` ranks)."""
    v = np.asarray(rec.voltage_v, dtype=float)
    i = np.asarray(rec.current_a, dtype=float)
    return np.where((i >= 0.0) & np.isfinite(v) & np.isfinite(i), v + i * r_ohm, np.inf)


def recording_ending_at_deepest(recordings: Sequence[Recording]) -> Recording | None:
    """The recording that ends, discharging, at the recordings' deepest state (:func:`deepest_state`); None if none.

    Such data stopped under load: the pack (and a robot's logger with it) was switched off there, as
    the battery management does when a cell reaches its cut-off. Data that end at rest, charging or
    recovered from their deepest state (the robot went to its charger) did not, nor does a recording
    trimmed to its discharge whose rests or recharge after it were dropped (:data:`DROPPED_TAIL_S_KEY`).
    A recording that ends within :data:`END_AT_MIN_FRACTION` of its depth range above the deepest state
    counts as ending there (the noise).

    Parameters
    ----------
    recordings : sequence of Recording
        Voltage in V, current in A (discharge positive).
    """
    r_ohm = step_resistance_ohm(recordings)
    depths = [_depth_voltage_v(rec, r_ohm) for rec in recordings]
    finite = [d[np.isfinite(d)] for d in depths]
    if not any(f.size for f in finite):
        return None
    lowest = min(float(f.min()) for f in finite if f.size)
    for rec, depth, f in zip(recordings, depths, finite, strict=True):
        if f.size < 2 or not rec.current_a[-1] > 0.0 or not np.isfinite(depth[-1]):
            continue
        if rec.metadata.get(DROPPED_TAIL_S_KEY, 0.0) > 0.0:
            continue  # it went on after its discharge
        if depth[-1] - lowest <= END_AT_MIN_FRACTION * float(f.max() - f.min()):
            return rec
    return None


#: A sample discharges when its current exceeds this fraction of the recording's largest discharge current, and
#: charges below minus that (rests, soaks and sensor offsets in between are neither).
DISCHARGE_CURRENT_FRACTION = 0.01


def discharge_threshold_a(current_a: Any) -> float:
    """The current (A) beyond which a recording's samples discharge (or, below its negative, charge):
    :data:`DISCHARGE_CURRENT_FRACTION` of its largest discharge current; 0 when it never discharges."""
    i = np.asarray(current_a, dtype=float)
    return DISCHARGE_CURRENT_FRACTION * max(float(np.max(i)), 0.0) if i.size else 0.0


def ends_at_cutoff(rec: Recording) -> bool:
    """True when the recording ends at its minimum voltage while discharging, on the knee (its runtime is defined).

    Only such a recording says what the cell would have done after its end (it stopped at its
    cut-off): the seed paper's R2_mod padding (Eq. 2, the measured voltage continued at its minimum)
    and a simulation run past the end apply to it. A working day that stops at 40 % SOC, or ends
    in a rest or a recharge, says nothing about later voltages; nor does one that stops on the
    plateau during a high load, whose last voltage is then its lowest (:data:`KNEE_STEEPNESS`).

    Parameters
    ----------
    rec : Recording
        Voltage in V, current in A (discharge positive).
    """
    v = np.asarray(rec.voltage_v, dtype=float)
    span = float(v.max() - v.min())
    at_min = bool(span > 0 and v[-1] - v.min() <= END_AT_MIN_FRACTION * span and rec.current_a[-1] > 0)
    return at_min and end_steepness(rec) >= KNEE_STEEPNESS
