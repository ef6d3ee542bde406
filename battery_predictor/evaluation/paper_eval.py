"""The seed paper's experiments (section 5), reproduced on recordings.

- :func:`table2`: fit each base parameter set on one discharge, validate on the other (Table 2).
- :func:`runtime_evaluation`: remaining runtime after 30, 60, ... min with the predictor's
  strategy against the actual remaining runtime (5.1.6, Fig. 5).
- :func:`route_evaluation`: voltage at the standstill current after each longest-route cycle,
  and the accept/reject decisions, against the truth recorded in the bags (5.2.4, Fig. 8).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.errors import BatteryPredictorError, InputDataError
from battery_predictor.fitting.cost import r2_mod
from battery_predictor.fitting.optimiser import TPEOptimiser
from battery_predictor.fitting.problem import FitProblem, request_for_recording
from battery_predictor.fitting.screening import relevant_names, screen
from battery_predictor.fitting.space import fit_space
from battery_predictor.params import PackParams
from battery_predictor.recording import Recording
from battery_predictor.simulation import get_simulator

if TYPE_CHECKING:
    from battery_predictor.prediction.core import PredictorCore
    from battery_predictor.simulation.base import PackSimResult

#: The paper's figures, printed beside ours.
PAPER: dict[str, Any] = {
    "table2": {("dynamic", "Chen2020"): (0.97, 0.95), ("dynamic", "NCA_Kim2011"): (0.55, -0.61),
               ("dynamic", "OKane2022"): (0.98, 0.93), ("static", "Chen2020"): (0.97, 0.94),
               ("static", "NCA_Kim2011"): (-0.51, 0.55), ("static", "OKane2022"): (0.97, 0.92)},
    "runtime_mae_min": 14.92, "runtime_mape_pct": 18.88,
    "route_mae_v": 0.17, "route_mape_pct": 0.37,
    "ranger_stepwise_r2_mod": 0.98,
}
#: Runtime checkpoints of 5.1.6, s.
CHECKPOINTS_S = tuple(60.0 * m for m in range(30, 301, 30))


@dataclass(frozen=True)
class FitValidation:
    """One row of Table 2."""

    opt_profile: str
    base_parameter_set: str
    opt_r2_mod: float
    val_r2_mod: float
    parameters: tuple[str, ...]
    params: PackParams = field(repr=False)
    opt_result: PackSimResult | None = field(repr=False, default=None)
    val_result: PackSimResult | None = field(repr=False, default=None)


def score_fit(params: PackParams, rec: Recording) -> tuple[float, PackSimResult]:
    """R2_mod of ``params`` on ``rec`` (fast simulator, the params' initial state) and the simulation."""
    sim = get_simulator("fast")
    res = sim.simulate(params, request_for_recording(params, rec, initial_state="params",
                                                     extend_s=0.2 * rec.duration_s))
    return r2_mod(rec.relative_time_s, rec.voltage_v, res.time_s, res.pack_voltage_v), res


def fit_pack(params: PackParams, recs: Sequence[Recording], *, trials: int, seed: int,
             storage: str | None = None, screen_first: bool = True,
             workers: int = 1) -> tuple[PackParams, tuple[str, ...], object]:
    """Screen (optional) and TPE-fit ``params`` to ``recs``; returns fitted params, names, optimiser result."""
    names = tuple(params.fit.parameters)
    if screen_first:
        rows = screen(params, get_simulator("fast"))
        names = tuple(n for n in relevant_names(rows) if n not in ("r_b_ohm", "r_c_ohm", "r_i_ohm"))
        names = names + ("r_b_ohm", "r_c_ohm", "r_i_ohm")
    problem = FitProblem(params, list(recs), get_simulator("fast"), initial_state="params")
    result = TPEOptimiser(n_trials=trials, seed=seed, storage=storage, workers=workers, progress=False).run(
        problem, fit_space(params, names))
    return params.with_values(result.best_values), names, result


def table2(start: PackParams, dynamic: Recording, static: Recording, *, base_sets: Sequence[str], trials: int,
           seed: int = 0, progress: Callable[[str], None] | None = None, storage: str | None = None,
           workers: int = 1) -> list[FitValidation]:
    """Fit on the dynamic discharge and validate on the static one, and vice versa, per base set.

    With an Optuna ``storage`` every fit is a stored study: a stopped evaluation resumes them.

    Every base set starts from the params' manual values (paper Table 1) without the shipped fit,
    its fit parameters are the relevant ones of its own screening plus R_b, R_c, R_i.
    """
    rows = []
    for base in base_sets:
        params = dataclasses.replace(start, base_parameter_set=base, fitted={}, provenance={})
        for opt_name, opt_rec, val_rec in (("dynamic", dynamic, static), ("static", static, dynamic)):
            try:
                fitted, names, _ = fit_pack(params, [opt_rec], trials=trials, seed=seed, storage=storage,
                                            workers=workers)
                opt_r2, opt_res = score_fit(fitted, opt_rec)
                val_r2, val_res = score_fit(fitted, val_rec)
            except BatteryPredictorError as exc:
                if progress:
                    progress(f"{base} {opt_name}: failed: {exc}")
                rows.append(FitValidation(opt_name, base, math.nan, math.nan, (), params))
                continue
            rows.append(FitValidation(opt_name, base, opt_r2, val_r2, names, fitted, opt_res, val_res))
            if progress:
                progress(f"{base} fitted on {opt_name}: R2_mod {opt_r2:.3f}, validation {val_r2:.3f}")
    return rows


@dataclass(frozen=True)
class RuntimePoint:
    """One checkpoint of the runtime evaluation."""

    recording: str
    elapsed_s: float
    predicted_remaining_s: float
    actual_remaining_s: float
    valid: bool
    reason: str

    @property
    def abs_error_min(self) -> float:
        return abs(self.predicted_remaining_s - self.actual_remaining_s) / 60.0

    @property
    def abs_pct_error(self) -> float:
        return 100.0 * abs(self.predicted_remaining_s - self.actual_remaining_s) / self.actual_remaining_s


def actual_runtime_s(rec: Recording, cutoff_v: float) -> float:
    """True runtime: from the bag's ground truth, else the first time the recorded voltage reaches ``cutoff_v``."""
    truth = rec.metadata.get("truth") if isinstance(rec.metadata, dict) else None
    if isinstance(truth, dict) and isinstance(truth.get("runtime_s"), (int, float)):
        return float(truth["runtime_s"])
    below = np.nonzero(rec.voltage_v <= cutoff_v)[0]
    if below.size == 0:
        raise InputDataError(f"{rec.source}: never reaches {cutoff_v:.2f} V and holds no ground-truth runtime")
    return float(rec.relative_time_s[below[0]])


def runtime_evaluation(params: PackParams, recs: Sequence[Recording], *, checkpoints_s: Sequence[float] = CHECKPOINTS_S,
                       cutoff_v: float | None = None, peak_current_quantile: float = 0.0,
                       load_model: str = "current") -> list[RuntimePoint]:
    """The predictor's strategy after 30, 60, ... min of each recording vs the actual remaining runtime.

    ``peak_current_quantile`` = 0 is the paper's strategy (average load); > 0 the predictor's
    load-peak strategy (see :class:`~battery_predictor.prediction.core.PredictorConfig`).
    ``load_model`` is the paper's constant current by default (the emulated recordings draw their
    profile's currents as they are); the predictor's default ``"auto"`` is measured in
    ``docs/runtime_real_data``.
    """
    from battery_predictor.prediction.core import PredictorConfig, PredictorCore

    cutoff = float(cutoff_v if cutoff_v is not None else params.thresholds["runtime_cutoff_voltage_v"])
    points = []
    for rec in recs:
        t_true = actual_runtime_s(rec, cutoff)
        core = PredictorCore(PredictorConfig(params_file=params.source, cutoff_voltage_v=cutoff,
                                             stale_after_s=1e9, peak_current_quantile=peak_current_quantile,
                                             load_model=load_model),
                             params=params)
        t = rec.relative_time_s
        temp = rec.temperature_k if rec.temperature_k is not None else np.full(t.size, math.nan)
        k = 0
        for cp in checkpoints_s:
            if cp >= t_true:
                break
            while k < t.size and t[k] <= cp:
                core.update_state(float(t[k]), float(rec.voltage_v[k]), float(rec.current_a[k]), float(temp[k]))
                k += 1
            st = core.remaining_runtime(float(t[k - 1]))
            points.append(RuntimePoint(str(rec.source), cp, st.remaining_s if st.valid else math.nan,
                                       t_true - float(t[k - 1]), st.valid, st.reason))
    return points


def runtime_summary(points: Sequence[RuntimePoint]) -> dict:
    """MAE (min) and MAPE (%) per recording and overall (invalid predictions counted separately)."""
    out: dict = {"per_recording": {}, "invalid": sum(not p.valid for p in points)}
    valid = [p for p in points if p.valid and math.isfinite(p.predicted_remaining_s)]
    for name in dict.fromkeys(p.recording for p in points):
        sub = [p for p in valid if p.recording == name]
        out["per_recording"][name] = {
            "mae_min": float(np.mean([p.abs_error_min for p in sub])) if sub else math.nan,
            "mape_pct": float(np.mean([p.abs_pct_error for p in sub])) if sub else math.nan,
            "points": len(sub),
        }
    out["mae_min"] = float(np.mean([p.abs_error_min for p in valid])) if valid else math.nan
    out["mape_pct"] = float(np.mean([p.abs_pct_error for p in valid])) if valid else math.nan
    out["bias_min"] = (float(np.mean([(p.predicted_remaining_s - p.actual_remaining_s) / 60.0 for p in valid]))
                       if valid else math.nan)
    # MAE scales with the runtimes: the mean actual remaining runtime makes it comparable across data sets
    out["mean_actual_remaining_min"] = float(np.mean([p.actual_remaining_s / 60.0 for p in valid])) if valid else math.nan
    return out


@dataclass(frozen=True)
class RouteCase:
    """Route evaluation of one luggage-robot recording."""

    recording: str
    payload_kg: float
    predicted_v: tuple[float, ...]  # after the first and the second cycle
    actual_v: tuple[float, ...]
    decisions: tuple[bool, ...]  # at the three states
    truth: tuple[bool | None, ...]  # None: not known from the recording
    reasons: tuple[str, ...]


def route_truth_from_recording(rec: Recording, payload_kg: float, params: PackParams) -> dict:
    """The route ground truth measured in a recording of repeated longest routes (no metadata needed).

    The recording must start at the beginning of a longest-route cycle of ``payload_kg``
    (:func:`~battery_predictor.profiles.ranger.longest_route`: standstill, loaded leg, empty
    return, standstill), repeated back to back, as in the paper's 5.2.4. The voltage "at 1.70 A
    after cycle k" is the mean over the final standstill of cycle k; whether a further cycle
    stays above the threshold is known only when a third cycle was recorded (else None).

    Raises
    ------
    InputDataError
        When the recording does not cover two cycles.
    """
    from battery_predictor.lab.experiments import standstill_voltage_v
    from battery_predictor.profiles.ranger import longest_route

    route = longest_route(float(payload_kg))
    period = float(route.duration_s)
    standstill = float(route.sections[-1].standstill_s) or float(route.sections[0].standstill_s)
    threshold = float(params.thresholds["route_min_voltage_v"])
    t = rec.relative_time_s
    if t[-1] < 2 * period - standstill:
        raise InputDataError(f"{rec.source}: {t[-1]:.0f} s recorded, two longest-route cycles of "
                             f"{payload_kg:g} kg take {2 * period:.0f} s")
    try:
        after = [standstill_voltage_v(t, rec.voltage_v, period * k, standstill) for k in (1, 2)]
    except BatteryPredictorError as exc:
        raise InputDataError(f"{rec.source}: {exc}") from None
    third = (t >= 2 * period - 1e-6) & (t <= 3 * period + 1e-6)
    further = None
    if t[-1] >= 3 * period - 5.0 and third.any():
        further = bool(float(np.min(rec.voltage_v[third])) >= threshold)
    return {"cycle_duration_s": period, "standstill_s": standstill, "voltage_at_1_70_a_after_cycle_v": after,
            "further_cycle_stays_above_threshold": further, "threshold_v": threshold, "derived_from": "recording"}


def route_evaluation(params: PackParams, recs: Sequence[Recording],
                     payloads_kg: Sequence[float | None] | None = None) -> list[RouteCase]:
    """Predicted vs recorded voltage at the standstill current after each of the two cycles.

    The prediction starts from the state calibrated (as the predictor node does) at the end of
    the first standstill and simulates two cycles in succession with the average currents of each
    (payload, slope), as the paper does; decisions are asked of :class:`PredictorCore` at the
    start, after cycle 1 and after cycle 2 (each for one more longest route) and compared with
    the recorded truth.

    The truth comes from the recording's metadata (bundled bags), else it is measured in the
    recording itself (:func:`route_truth_from_recording`) for the payload given in
    ``payloads_kg`` (one per recording, None = from the metadata).
    """
    from battery_predictor.prediction.core import PredictorConfig, PredictorCore
    from battery_predictor.prediction.route import route_segments
    from battery_predictor.profiles.ranger import longest_route

    template = PredictorCore(PredictorConfig(params_file=params.source, stale_after_s=1e9), params=params)
    runner = template.runner
    if runner is None:
        raise InputDataError(f"{params.source}: no pack model to evaluate the routes with")
    threshold = float(params.thresholds["route_min_voltage_v"])
    i_stand = float(params.thresholds["standstill_current_a"])
    payloads = list(payloads_kg) if payloads_kg is not None else [None] * len(recs)
    if len(payloads) != len(recs):
        raise InputDataError(f"{len(payloads)} payload(s) given for {len(recs)} route recording(s)")
    cases = []
    for rec, payload_given in zip(recs, payloads, strict=True):
        meta = rec.metadata if isinstance(rec.metadata, dict) else {}
        truth, route_meta = meta.get("truth"), meta.get("route")
        if payload_given is not None:
            payload = float(payload_given)
        elif isinstance(route_meta, dict) and "payload_kg" in route_meta:
            payload = float(route_meta["payload_kg"])
        else:
            raise InputDataError(f"{rec.source}: no payload in the metadata; give it (--route-payload-kg)")
        if not isinstance(truth, dict) or "voltage_at_1_70_a_after_cycle_v" not in truth:
            truth = route_truth_from_recording(rec, payload, params)
        period = float(truth["cycle_duration_s"])
        standstill = float(truth["standstill_s"])
        sections = longest_route(payload).sections
        segs = route_segments(sections, i_stand)
        core = PredictorCore(template.config, params=params)
        core.runner = runner  # share the built model
        feeder = _Feeder(core, rec)
        t_rec = rec.relative_time_s
        # state at the end of the first standstill: the route proper starts there
        feeder.until(standstill)
        latest = core.latest_state()
        assert latest is not None  # the feeder has fed the standstill
        temp0 = core._temperature(latest[3])
        run = runner.run(core.calibration(temp0).start, segs[1:] + segs, temp0)
        n1 = len(segs) - 1
        ends = run.segment_end_index
        t = run.time_s

        pred = (_mean_before(t, run.pack_voltage_v, ends[n1 - 1], standstill) if len(ends) >= n1 else math.nan,
                _mean_before(t, run.pack_voltage_v, ends[-1], standstill)
                if len(ends) == len(segs) * 2 - 1 else math.nan)
        actual = tuple(float(x) for x in truth["voltage_at_1_70_a_after_cycle_v"])
        decisions, reasons = [], []
        for t_state in (standstill, period, 2 * period):
            now = feeder.until(min(t_state, float(t_rec[-1])))
            d = core.can_accept_route(sections, now)
            decisions.append(bool(d.accepted))
            reasons.append(d.reason)
        further = truth.get("further_cycle_stays_above_threshold")
        truth_dec = (actual[0] >= threshold, actual[1] >= threshold, None if further is None else bool(further))
        cases.append(RouteCase(str(rec.source), payload, pred, actual, tuple(decisions), truth_dec, tuple(reasons)))
    return cases


class _Feeder:
    """Feeds a recording's samples into a PredictorCore up to a time, like the monitor would."""

    def __init__(self, core: PredictorCore, rec: Recording) -> None:
        self.core, self.rec, self.k = core, rec, 0
        self.t = rec.relative_time_s
        self.temp = rec.temperature_k if rec.temperature_k is not None else np.full(self.t.size, math.nan)

    def until(self, t_s: float) -> float:
        """Feed every sample at or before ``t_s``; returns the last fed time (s)."""
        while self.k < self.t.size and self.t[self.k] <= t_s + 1e-9:
            k = self.k
            self.core.update_state(float(self.t[k]), float(self.rec.voltage_v[k]), float(self.rec.current_a[k]),
                                   float(self.temp[k]))
            self.k += 1
        return float(self.t[max(self.k - 1, 0)])


def _mean_before(t: np.ndarray, v: np.ndarray, end_idx: int, window_s: float) -> float:
    """Mean of ``v`` over the ``window_s`` seconds ending at sample ``end_idx``."""
    t_end = t[end_idx]
    m = (t >= t_end - window_s + 1e-6) & (t <= t_end + 1e-9)
    return float(np.mean(v[m]))


def route_summary(cases: Sequence[RouteCase]) -> dict:
    """MAE (V), MAPE (%) per cycle and overall, and decision accuracy."""
    errs: dict[int, list[tuple[float, float]]] = {1: [], 2: []}
    for c in cases:
        for k in (1, 2):
            p, a = c.predicted_v[k - 1], c.actual_v[k - 1]
            if math.isfinite(p) and math.isfinite(a):
                errs[k].append((abs(p - a), 100.0 * abs(p - a) / a))
    allv = errs[1] + errs[2]
    known = [(d, t) for c in cases for d, t in zip(c.decisions, c.truth, strict=True) if t is not None]
    n_dec = len(known)
    correct = sum(d == t for d, t in known)
    unsafe = sum(d and not t for d, t in known)
    return {
        "mae_v": float(np.mean([e[0] for e in allv])) if allv else math.nan,
        "mape_pct": float(np.mean([e[1] for e in allv])) if allv else math.nan,
        "mae_v_cycle1": float(np.mean([e[0] for e in errs[1]])) if errs[1] else math.nan,
        "mae_v_cycle2": float(np.mean([e[0] for e in errs[2]])) if errs[2] else math.nan,
        "bias_v_cycle1": float(np.mean([c.predicted_v[0] - c.actual_v[0] for c in cases])) if cases else math.nan,
        "bias_v_cycle2": float(np.mean([c.predicted_v[1] - c.actual_v[1] for c in cases])) if cases else math.nan,
        "decisions": n_dec, "decisions_correct": correct, "unsafe_accepts": unsafe,
    }
