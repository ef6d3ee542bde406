"""Route acceptance for the luggage robot (paper 5.2.4).

A route's sections become constant-current segments with the per-(payload,
slope) average currents; the pack is simulated from the calibrated SOC; the
route is accepted only when the pack voltage at the standstill current after the
route stays at or above the threshold (46.31 V at 1.70 A for the Ranger Mini).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from battery_predictor.errors import BatteryPredictorError, RequestError
from battery_predictor.profiles.ranger import RangerCurrents, RouteSection, mean_current_a

if TYPE_CHECKING:
    from battery_predictor.prediction.pack_model import PackModel, RunStart

#: Standstill after the route at which the voltage is read, s (the paper's final curve point).
SETTLE_S = 60.0
#: No single request may describe more than this.
MAX_SECTIONS = 500
MAX_ROUTE_DURATION_S = 24 * 3600.0
#: Shortest driving or standstill part simulated, s.
MIN_SEGMENT_S = 0.01


@dataclass(frozen=True)
class RouteDecision:
    """Answer to "can the robot accept this route?".

    Attributes
    ----------
    accepted : bool
        True when the predicted voltage after the route is at or above the threshold.
    predicted_voltage_v : float
        Pack voltage in V at the standstill current after the route (NaN when not reached).
    threshold_voltage_v : float
        The acceptance threshold in V.
    margin_v : float
        ``predicted - threshold`` in V (NaN when not computed).
    route_duration_s : float
        Route duration in s (driving + standstills).
    route_charge_ah : float
        Charge the route draws in Ah (average currents).
    state_of_charge : float
        SOC the prediction started from (NaN when unknown).
    reason : str
        Human-readable reason.
    probability_above_threshold : float
        Probability that the voltage after the route is at or above the threshold (NaN when not computed).
    voltage_at_risk_v : float
        The voltage after the route that the pack stays above with probability ``1 - risk``, V.
    risk : float
        The accepted probability of ending below the threshold (NaN when the decision used the P50 only).
    """

    accepted: bool
    predicted_voltage_v: float
    threshold_voltage_v: float
    margin_v: float
    route_duration_s: float
    route_charge_ah: float
    state_of_charge: float
    reason: str
    probability_above_threshold: float = math.nan
    voltage_at_risk_v: float = math.nan
    risk: float = math.nan

    def end_soc(self, capacity_ah: float) -> float:
        """The model's SOC after the route: the start SOC less the route's charge over ``capacity_ah`` (Ah)."""
        return self.state_of_charge - self.route_charge_ah / capacity_ah


def route_segments(sections: Sequence[RouteSection], standstill_current_a: float,
                   currents: RangerCurrents | None = None) -> list[tuple[float, float]]:
    """Constant-current segments ``(duration_s, pack_current_a)`` of a route (average currents)."""
    if not sections:
        raise RequestError("route has no sections")
    if len(sections) > MAX_SECTIONS:
        raise RequestError(f"route has {len(sections)} sections (at most {MAX_SECTIONS})")
    segments = []
    for sec in sections:
        # parts shorter than MIN_SEGMENT_S draw no measurable charge and are skipped (the solver
        # cannot step over a zero-length interval)
        if sec.length_m > 0 and sec.travel_s >= MIN_SEGMENT_S:
            segments.append((sec.travel_s, mean_current_a(sec.payload_kg, sec.slope, currents)))
        if sec.standstill_s >= MIN_SEGMENT_S:
            segments.append((sec.standstill_s, standstill_current_a))
    if not segments:
        raise RequestError(f"route is shorter than {MIN_SEGMENT_S} s in total")
    return segments


def rejected(reason: str, threshold_v: float, *, duration_s: float = math.nan, charge_ah: float = math.nan,
             soc: float = math.nan) -> RouteDecision:
    """A rejection that carries its reason (used for invalid requests and unknown state too)."""
    return RouteDecision(False, math.nan, threshold_v, math.nan, duration_s, charge_ah, soc, reason)


def evaluate_route(runner: PackModel, start: RunStart, sections: Sequence[RouteSection],
                   temperature_k: float, *, threshold_v: float, standstill_current_a: float,
                   currents: RangerCurrents | None = None, settle_s: float = SETTLE_S,
                   segments: list[tuple[float, float]] | None = None) -> RouteDecision:
    """Simulate a route from ``start`` and decide (never raises for a bad route: rejects with a reason).

    Parameters
    ----------
    runner : PackModel
        The fitted pack model.
    start : float or RunState
        Calibrated SOC, or the calibrated model state (see ``Calibration.start``).
    sections : sequence of RouteSection
        The route (validated dataclasses).
    temperature_k : float
        Temperature assumed, K.
    threshold_v, standstill_current_a : float
        Acceptance threshold (V) and the standstill current (A) it applies at.
    segments : list, optional
        ``route_segments(sections, standstill_current_a, currents)`` when the caller has them already.
    """
    soc = float(start) if isinstance(start, (int, float)) else runner.soc_of(start)
    if segments is None:
        try:
            segments = route_segments(sections, standstill_current_a, currents)
        except BatteryPredictorError as exc:
            return rejected(f"invalid route: {exc}", threshold_v, soc=soc)
    duration_s = sum(d for d, _ in segments)
    charge_ah = sum(d * i for d, i in segments) / 3600.0
    if duration_s > MAX_ROUTE_DURATION_S:
        return rejected(f"route lasts {duration_s / 3600:.3g} h, longer than any battery could run "
                        f"(limit {MAX_ROUTE_DURATION_S / 3600:.0f} h)", threshold_v, duration_s=duration_s,
                        charge_ah=charge_ah, soc=soc)
    if charge_ah > runner.capacity_ah:
        return rejected(f"route draws {charge_ah:.3g} Ah, more than the full pack holds ({runner.capacity_ah:.1f} Ah)",
                        threshold_v, duration_s=duration_s, charge_ah=charge_ah, soc=soc)
    try:
        reached, end_time_s, v_end = _run_end(runner, start, [*segments, (settle_s, standstill_current_a)],
                                              temperature_k)
    except BatteryPredictorError as exc:
        return rejected(f"model failed: {exc}", threshold_v, duration_s=duration_s, charge_ah=charge_ah, soc=soc)
    if reached:
        return rejected(f"a cell reaches its cut-off {end_time_s / 60:.1f} min into the route",
                        threshold_v, duration_s=duration_s, charge_ah=charge_ah, soc=soc)
    margin = v_end - threshold_v
    accepted = margin >= 0.0
    verdict = "accepted" if accepted else "rejected"
    reason = (f"{verdict}: predicted {v_end:.2f} V at {standstill_current_a:.2f} A after the route "
              f"({duration_s / 60:.1f} min, {charge_ah:.2f} Ah), threshold {threshold_v:.2f} V, "
              f"margin {margin:+.2f} V, start SOC {soc:.3f}")
    return RouteDecision(accepted, v_end, threshold_v, margin, duration_s, charge_ah, soc, reason)


def _run_end(runner: PackModel, start: RunStart, segments: list[tuple[float, float]],
             temperature_k: float) -> tuple[bool, float, float]:
    """(reached_cutoff, end_time_s, last pack voltage V) of ``runner.run(start, segments, temperature_k)``.

    The engine answers this without the samples inside the segments (``EnginePack.run_end``, the
    same values); PyBaMM stepping runs the whole route.
    """
    run_end = getattr(runner, "run_end", None)
    if run_end is not None:
        end = run_end(start, segments, temperature_k)
        return end.reached_cutoff, end.end_time_s, end.pack_voltage_v
    run = runner.run(start, segments, temperature_k)
    return bool(run.reached_cutoff), float(run.end_time_s), float(run.pack_voltage_v[-1])
