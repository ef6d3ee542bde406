"""Remaining runtime on measured recordings: the predictor's core against naive Coulomb counters.

Each recording is turned into the 5 s window averages the battery monitor publishes
(:func:`~battery_predictor.monitor.core.monitor_windows`) and fed, window by window, to a
:class:`~battery_predictor.prediction.core.PredictorCore` at its default settings, exactly as the
predictor node feeds it. At each checkpoint (a fraction of the discharge's duration) the core's
remaining runtime is compared with the truth, and so is each counter's.

The truth
---------
The discharge starts at the first window drawing more than ``start_current_a``. It ends at the
first window at or below the cut-off; a recording whose windows never reach it but whose
discharge stops (the current falls to rest for good) within ``end_margin_v`` of it ended on a
peak shorter than a window (test equipment that stops at the cut-off), and its discharge end is
the truth (``ended_by = "discharge_end"``). Any other recording has no known end and is reported
but not scored.

The counters
------------
``remaining Ah / average current``: the charge drawn since the discharge started is subtracted
from a capacity (the params' nominal capacity, one given by the user, or the mean charge drawn to
the end in other recordings, e.g. the fit data), divided by the mean net current so far. The
counter assumes the discharge started full.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.errors import InputDataError
from battery_predictor.monitor.core import MonitorConfig, monitor_windows
from battery_predictor.params import PackParams
from battery_predictor.prediction.core import PredictorConfig, PredictorCore
from battery_predictor.recording import Recording
from battery_predictor.replay.truth import RuntimeTruth

if TYPE_CHECKING:
    from battery_predictor.prediction.uncertainty import Spread

#: Default checkpoints: 10 %, 20 %, ..., 90 % of the discharge.
DEFAULT_CHECKPOINTS = tuple(round(0.1 * k, 1) for k in range(1, 10))


@dataclass(frozen=True)
class Windows:
    """Monitor windows of one recording (arrays of equal length; s, V, mean and largest sample A positive =
    discharge, K)."""

    time_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    temperature_k: np.ndarray
    peak_current_a: np.ndarray

    @classmethod
    def of(cls, rec: Recording, window_s: float = 5.0) -> Windows:
        """The windows the monitor publishes for ``rec``."""
        cfg = MonitorConfig(min_voltage_v=0.0, max_voltage_v=1e4, max_discharge_current_a=1e4,
                            max_charge_current_a=1e4, window_s=window_s)
        snaps = monitor_windows(rec.time_s, rec.voltage_v, rec.current_a, rec.temperature_k, cfg)
        if len(snaps) < 3:
            raise InputDataError(f"{rec.source}: fewer than 3 monitor windows of {window_s:g} s")
        cols = np.array([(s.stamp_s, s.voltage_v, s.current_a, s.temperature_k, s.peak_current_a) for s in snaps],
                        dtype=float)
        return cls(cols[:, 0], cols[:, 1], cols[:, 2], cols[:, 3], cols[:, 4])

    def charge_ah(self, start_s: float, end_s: float) -> float:
        """Net charge drawn between two window stamps, Ah (each window's mean holds over its window)."""
        keep = (self.time_s > start_s) & (self.time_s <= end_s)
        dt = np.diff(np.concatenate([[start_s], self.time_s[keep]]))
        return float(np.sum(dt * self.current_a[keep]) / 3600.0)


@dataclass(frozen=True)
class Discharge:
    """Where a recording's discharge starts and ends (s on the recording's clock)."""

    start_s: float
    end_s: float
    ended_by: str  # "cutoff_window", "discharge_end" or "unknown"

    @property
    def known(self) -> bool:
        return self.ended_by != "unknown"


def nominal_capacity_ah(params: PackParams) -> float:
    """The pack's nominal capacity from its params file, Ah (NaN when not given)."""
    return float(params.pack_info.get("nominal_capacity_ah", math.nan))


def _start_current_a(params: PackParams) -> float:
    """A window drawing more than this (A) starts a discharge: C/100, at least 0.05 A."""
    nominal = nominal_capacity_ah(params)
    return max(0.01 * nominal, 0.05) if math.isfinite(nominal) else 0.05


def find_discharge(win: Windows, cutoff_v: float, *, start_current_a: float, end_margin_v: float) -> Discharge:
    """The discharge of a recording and how its end is known (module docstring)."""
    drawing = np.nonzero(win.current_a > start_current_a)[0]
    if drawing.size == 0:
        raise InputDataError(f"no window draws more than {start_current_a:.3g} A: not a discharge")
    first = int(drawing[0])
    start_s = float(win.time_s[first - 1] if first > 0 else win.time_s[0] - (win.time_s[1] - win.time_s[0]))
    below = np.nonzero((win.voltage_v <= cutoff_v) & (np.arange(win.time_s.size) >= first))[0]
    if below.size:
        return Discharge(start_s, float(win.time_s[below[0]]), "cutoff_window")
    last = int(drawing[-1])
    if float(np.min(win.voltage_v[first:last + 1])) <= cutoff_v + end_margin_v:
        return Discharge(start_s, float(win.time_s[last]), "discharge_end")
    return Discharge(start_s, float(win.time_s[last]), "unknown")


@dataclass
class CheckpointResult:
    """One checkpoint: truth, the predictor's answer and each counter's (s)."""

    fraction: float
    time_s: float
    true_remaining_s: float
    predicted_s: float
    valid: bool
    status: int
    reason: str
    counters_s: dict[str, float] = field(default_factory=dict)
    p10_s: float = math.nan
    p90_s: float = math.nan
    #: ``{source: [lower, upper]}`` log deviations at the band (see :class:`~battery_predictor.prediction.uncertainty.Spread`).
    spread_log: dict[str, list[float]] = field(default_factory=dict)


@dataclass
class RecordingResult:
    """The checkpoints of one recording."""

    source: str
    discharge: Discharge
    mean_temperature_c: float
    checkpoints: list[CheckpointResult]


def counter_remaining_s(win: Windows, start_s: float, now_s: float, capacity_ah: float) -> float:
    """Naive counter: (capacity - charge drawn) / mean net current since ``start_s``, s."""
    drawn = win.charge_ah(start_s, now_s)
    if now_s <= start_s or drawn <= 0:
        return math.nan
    mean_a = drawn * 3600.0 / (now_s - start_s)
    return max(capacity_ah - drawn, 0.0) * 3600.0 / mean_a


def evaluate_recording(params: PackParams, rec: Recording, *, cutoff_v: float, capacities_ah: dict[str, float],
                       checkpoints: Sequence[float] = DEFAULT_CHECKPOINTS, end_margin_v: float | None = None,
                       config: PredictorConfig | None = None) -> RecordingResult:
    """Feed one recording's windows to a fresh predictor core and score it at the checkpoints.

    Parameters
    ----------
    params : PackParams
        The fitted pack.
    rec : Recording
        Measured recording (not trimmed).
    cutoff_v : float
        Pack voltage at which the robot stops, V.
    capacities_ah : dict
        Counter name -> capacity in Ah.
    checkpoints : sequence of float
        Fractions of the discharge's duration.
    end_margin_v : float, optional
        How close to the cut-off a discharge must stop to count as ended on it, V
        (default 0.5 V per series cell: a sanity bound, the recordings are meant to end at the cut-off).
    config : PredictorConfig, optional
        Predictor settings (default: the node's defaults with this cut-off).
    """
    win = Windows.of(rec)
    discharge = _discharge_of(params, win, cutoff_v, end_margin_v)
    core = PredictorCore(config or PredictorConfig(params_file=str(params.source), cutoff_voltage_v=cutoff_v),
                         params=params)
    times = [discharge.start_s + f * (discharge.end_s - discharge.start_s) for f in checkpoints]
    results, k = [], 0
    for fraction, t_cp in zip(checkpoints, times):
        while k < win.time_s.size and win.time_s[k] <= t_cp:
            core.update_state(win.time_s[k], win.voltage_v[k], win.current_a[k], win.temperature_k[k],
                              win.peak_current_a[k])
            core.precalibrate()  # as the node's pack-state callback: the state is carried window by window
            k += 1
        stamp = float(win.time_s[k - 1])
        answer = core.remaining_runtime(stamp)
        counters = {name: counter_remaining_s(win, discharge.start_s, stamp, cap) for name, cap in capacities_ah.items()}
        truth = discharge.end_s - stamp if discharge.known else math.nan
        results.append(CheckpointResult(fraction, stamp - discharge.start_s, truth, answer.remaining_s, answer.valid,
                                        answer.status, answer.reason, counters, answer.remaining_p10_s,
                                        answer.remaining_p90_s, _spread_parts(answer.spread)))
    temps = win.temperature_k[np.isfinite(win.temperature_k)]
    mean_c = float(np.mean(temps) - 273.15) if temps.size else math.nan
    return RecordingResult(str(rec.source), discharge, mean_c, results)


def _spread_parts(spread: Spread | None) -> dict[str, list[float]]:
    if spread is None:
        return {}
    return {k: [spread.lower.get(k, 0.0), spread.upper.get(k, 0.0)] for k in {**spread.lower, **spread.upper}}


def charge_to_end_ah(params: PackParams, rec: Recording, cutoff_v: float, end_margin_v: float | None = None) -> float:
    """Charge drawn from the discharge start to its end, Ah (for a counter's capacity); NaN when unknown."""
    win = Windows.of(rec)
    d = _discharge_of(params, win, cutoff_v, end_margin_v)
    return win.charge_ah(d.start_s, d.end_s) if d.known else math.nan


def recording_runtime_truth(params: PackParams, rec: Recording, cutoff_v: float, *, time_offset_s: float = 0.0,
                            checkpoints: Sequence[float] = DEFAULT_CHECKPOINTS) -> RuntimeTruth | None:
    """The truth of a measured recording for a replay: its discharge's end (module docstring), or None.

    Parameters
    ----------
    params : PackParams
        The pack (series count and nominal capacity set the discharge's start and end margins).
    rec : Recording
        The measured recording.
    cutoff_v : float
        Pack voltage that ends the discharge, V.
    time_offset_s : float
        Added to the recording's times to put them on the replay's time axis, s.
    checkpoints : sequence of float
        Fractions of the discharge at which the replay compares (converted to minutes).

    Returns
    -------
    RuntimeTruth or None
        None when the recording's end is not known to be the cut-off (or it is no discharge).
    """
    try:
        discharge = _discharge_of(params, Windows.of(rec), cutoff_v, None)
    except InputDataError:
        return None
    if not discharge.known:
        return None
    start_s, end_s = discharge.start_s + time_offset_s, discharge.end_s + time_offset_s
    marks = tuple((start_s + f * (end_s - start_s)) / 60.0 for f in checkpoints)
    return RuntimeTruth(cutoff_v, end_s, source=f"recording: {discharge.ended_by}", checkpoints_min=marks)


def _discharge_of(params: PackParams, win: Windows, cutoff_v: float, end_margin_v: float | None) -> Discharge:
    """:func:`find_discharge` with the pack's defaults (start at C/100, end within 0.5 V per series cell)."""
    margin = 0.5 * params.series if end_margin_v is None else end_margin_v
    return find_discharge(win, cutoff_v, start_current_a=_start_current_a(params), end_margin_v=margin)


#: An answer is "off by half" when its error exceeds this fraction of the true remaining time (issue 9's rule,
#: counted after ``late_after`` of a discharge).
OFF_BY_FRACTION = 0.5


def error_summary(pairs: Sequence[tuple[float, float]], *, late_fraction_pairs: Sequence[tuple[float, float]] = ()
                  ) -> dict[str, float]:
    """MAE / MAPE / bias / worst error (min, %) of (predicted_s, true_s) pairs; invalid answers are NaN.

    Of ``late_fraction_pairs`` (the checkpoints after ``late_after`` of a discharge): the largest error relative
    to the true remaining time (``worst_late_pct``), how many were answered (``answers_after``) and how many of those
    are off by more than :data:`OFF_BY_FRACTION` of it (``off_by_half_after``).
    """
    scored = [(p, t) for p, t in pairs if math.isfinite(t) and t > 0]
    answered = [(p, t) for p, t in scored if math.isfinite(p)]
    late = [abs(p - t) / t for p, t in late_fraction_pairs if math.isfinite(p) and math.isfinite(t) and t > 0]
    out = {"checkpoints": len(scored), "answered": len(answered), "answers_after": len(late),
           "off_by_half_after": sum(r > OFF_BY_FRACTION for r in late)}
    if not answered:
        return {**out, "mae_min": math.nan, "mape_pct": math.nan, "bias_min": math.nan, "worst_min": math.nan,
                "worst_late_pct": math.nan}
    err = np.array([p - t for p, t in answered]) / 60.0
    rel = np.array([abs(p - t) / t for p, t in answered]) * 100.0
    return {**out, "mae_min": float(np.mean(np.abs(err))), "mape_pct": float(np.mean(rel)),
            "bias_min": float(np.mean(err)), "worst_min": float(err[np.argmax(np.abs(err))]),
            "worst_late_pct": 100.0 * float(max(late)) if late else math.nan}


def ratio_to_best_counter(block: dict) -> dict[str, Any]:
    """The predictor's MAE over the best counter's in a ``summarise`` block (issue 9 asks for at most 0.7x).

    Returns ``{"ratio": float, "counter": name}``; NaN and None when no counter has a finite MAE.
    """
    counters = {name: f["mae_min"] for name, f in block.items()
                if name.startswith("counter[") and math.isfinite(f["mae_min"]) and f["mae_min"] > 0}
    if not counters or not math.isfinite(block["predictor"]["mae_min"]):
        return {"ratio": math.nan, "counter": None}
    best = min(counters, key=counters.__getitem__)
    return {"ratio": block["predictor"]["mae_min"] / counters[best], "counter": best}


def interval_coverage(checkpoints: Sequence[CheckpointResult]) -> dict[str, float]:
    """How often the true remaining time fell inside P10..P90 (target 80 %), below P10 and above P90 (10 % each)."""
    scored = [c for c in checkpoints if c.valid and math.isfinite(c.true_remaining_s) and c.true_remaining_s > 0
              and math.isfinite(c.p10_s) and math.isfinite(c.p90_s)]
    n = len(scored)
    if not n:
        return {"intervals": 0, "inside_pct": math.nan, "below_p10_pct": math.nan, "above_p90_pct": math.nan}
    below = sum(c.true_remaining_s < c.p10_s for c in scored)
    above = sum(c.true_remaining_s > c.p90_s for c in scored)
    return {"intervals": n, "inside_pct": 100.0 * (n - below - above) / n, "below_p10_pct": 100.0 * below / n,
            "above_p90_pct": 100.0 * above / n}


def calibrate_runtime_sigma(results: Sequence[RecordingResult], coverage: float = 0.8) -> tuple[float, int]:
    """Structural runtime sigma (log) with which P10..P90 holds ``coverage`` of these checkpoints, and their count."""
    from battery_predictor.prediction.uncertainty import Spread, calibrated_model_sigma

    rows = [c for r in results for c in r.checkpoints if c.valid and math.isfinite(c.true_remaining_s) and c.spread_log]
    spreads = [Spread({k: v[0] for k, v in c.spread_log.items()}, {k: v[1] for k, v in c.spread_log.items()})
               for c in rows]
    sigma = calibrated_model_sigma([c.predicted_s for c in rows], [c.true_remaining_s for c in rows], spreads,
                                   coverage)
    return sigma, len(rows)


def with_runtime_sigma(params: PackParams, results: Sequence[RecordingResult], coverage: float = 0.8) -> PackParams:
    """``params`` with ``provenance.uncertainty`` calibrated on these recordings' checkpoints (see :func:`calibrate_runtime_sigma`).

    Raises
    ------
    InputDataError
        When no checkpoint has a known truth and an interval.
    """
    sigma, n = calibrate_runtime_sigma(results, coverage)
    if not (n and math.isfinite(sigma)):
        raise InputDataError("no checkpoint with a known end of discharge and an interval to calibrate on")
    provenance = dict(params.provenance)
    provenance["uncertainty"] = {"runtime_log_sigma": float(sigma), "checkpoints": n, "coverage": coverage,
                                 "calibrated_on": [r.source for r in results]}
    return replace(params, provenance=provenance)


def summarise(results: Sequence[RecordingResult], counters: Sequence[str], *, late_after: float = 0.3) -> dict:
    """Per recording and pooled figures of the predictor and each counter (see :func:`error_summary`)."""

    def figures(checkpoints: list[CheckpointResult], pick: Callable[[CheckpointResult], float]) -> dict[str, float]:
        pairs = [(pick(c), c.true_remaining_s) for c in checkpoints]
        late = [(pick(c), c.true_remaining_s) for c in checkpoints if c.fraction >= late_after]
        return error_summary(pairs, late_fraction_pairs=late)

    def counter(name: str) -> Callable[[CheckpointResult], float]:
        return lambda c: c.counters_s.get(name, math.nan)

    def block(checkpoints: list[CheckpointResult]) -> dict:
        return {"predictor": figures(checkpoints, lambda c: c.predicted_s if c.valid else math.nan),
                **{f"counter[{n}]": figures(checkpoints, counter(n)) for n in counters}}

    every = [c for r in results for c in r.checkpoints]
    return {
        "per_recording": [{"source": r.source, "ended_by": r.discharge.ended_by,
                           "discharge_min": (r.discharge.end_s - r.discharge.start_s) / 60.0,
                           "mean_temperature_c": r.mean_temperature_c, **block(r.checkpoints),
                           "interval": interval_coverage(r.checkpoints)} for r in results],
        "pooled": block(every),
        "pooled_ratio_to_best_counter": ratio_to_best_counter(block(every)),
        "pooled_interval": interval_coverage(every),
        "late_after_fraction": late_after,
        "off_by_fraction": OFF_BY_FRACTION,
    }


def result_rows(results: Sequence[RecordingResult]) -> list[dict]:
    """Every checkpoint as a flat JSON-able row."""
    return [{"source": r.source, **asdict(c)} for r in results for c in r.checkpoints]
