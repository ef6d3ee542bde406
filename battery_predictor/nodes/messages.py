"""Conversions between ROS messages and the ROS-free cores (times, route sections, answers).

Sign conventions: ``PackState`` and ``RemainingRuntime`` carry currents positive
while discharging, as the cores do; ``sensor_msgs/BatteryState`` is converted
only through :mod:`battery_predictor.conventions` (in the monitor node).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from battery_predictor_msgs.msg import PackState, RemainingRuntime
from battery_predictor_msgs.msg import RouteSection as RouteSectionMsg
from battery_predictor_msgs.srv import CanAcceptRoute
from builtin_interfaces.msg import Time

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.monitoring import PackSnapshot
from battery_predictor.prediction.core import RuntimeStatus
from battery_predictor.prediction.route import MAX_SECTIONS, RouteDecision
from battery_predictor.profiles.ranger import DEFAULT_SPEED_M_S, RouteSection

#: Longer section names are shortened (they are echoed in reasons).
MAX_NAME_CHARS = 80
#: RouteSection.msg slope constants -> slope names of the ROS-free core.
SLOPE_NAMES = {RouteSectionMsg.SLOPE_FLAT: "flat", RouteSectionMsg.SLOPE_UPHILL: "uphill",
               RouteSectionMsg.SLOPE_DOWNHILL: "downhill"}


def stamp_to_s(stamp: Time) -> float:
    """``builtin_interfaces/Time`` -> seconds."""
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def s_to_stamp(time_s: float) -> Time:
    """Seconds -> ``builtin_interfaces/Time`` (rounded to the nanosecond; NaN/negative -> zero)."""
    if not math.isfinite(time_s) or time_s < 0:
        return Time()
    ns = round(time_s * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def ns_to_stamp(time_ns: int) -> Time:
    """Nanoseconds -> ``builtin_interfaces/Time``."""
    return Time(sec=int(time_ns) // 1_000_000_000, nanosec=int(time_ns) % 1_000_000_000)


def pack_state_msg(snap: PackSnapshot, frame_id: str) -> PackState:
    """A monitor snapshot as ``PackState``."""
    msg = PackState(voltage_v=float(snap.voltage_v), current_a=float(snap.current_a),
                    peak_current_a=float(snap.peak_current_a),
                    temperature_k=float(snap.temperature_k), window_s=float(snap.window_s),
                    samples_used=int(min(snap.samples_used, 2**32 - 1)),
                    samples_rejected=int(min(snap.samples_rejected, 2**32 - 1)), stale=bool(snap.stale))
    msg.header.stamp = s_to_stamp(snap.stamp_s)
    msg.header.frame_id = frame_id
    return msg


def remaining_runtime_msg(status: RuntimeStatus, frame_id: str) -> RemainingRuntime:
    """A core runtime answer as ``RemainingRuntime``."""
    msg = RemainingRuntime(remaining_s=float(status.remaining_s), assumed_current_a=float(status.assumed_current_a),
                           assumed_temperature_k=float(status.assumed_temperature_k),
                           state_of_charge=float(status.state_of_charge),
                           cutoff_voltage_v=float(status.cutoff_voltage_v), valid=bool(status.valid),
                           status=int(status.status), reason=str(status.reason))
    msg.header.stamp = s_to_stamp(status.stamp_s)
    msg.header.frame_id = frame_id
    return msg


def route_sections(msgs: Sequence[RouteSectionMsg]) -> list[RouteSection]:
    """Validated core route sections from a request.

    ``speed_m_s == 0`` means the robot's default speed (0.50 m/s). A section
    without a name is named by its position; names are cut to ``MAX_NAME_CHARS``.

    Raises
    ------
    BatteryPredictorError
        With a one-line reason: no sections, too many, an unknown slope, or a
        section the core rejects (NaN or negative length, absurd payload...).
    """
    if len(msgs) == 0:
        raise BatteryPredictorError("route has no sections")
    if len(msgs) > MAX_SECTIONS:
        raise BatteryPredictorError(f"route has {len(msgs)} sections (at most {MAX_SECTIONS})")
    out = []
    for k, m in enumerate(msgs, start=1):
        name = m.name if m.name.strip() else f"section {k}"
        if len(name) > MAX_NAME_CHARS:
            name = name[:MAX_NAME_CHARS] + "..."
        slope = SLOPE_NAMES.get(int(m.slope))
        if slope is None:
            raise BatteryPredictorError(f"section {k} ({name!r}): slope {int(m.slope)} is not one of "
                                        "SLOPE_FLAT=0, SLOPE_UPHILL=1, SLOPE_DOWNHILL=2")
        speed = float(m.speed_m_s)
        if speed == 0.0:
            speed = DEFAULT_SPEED_M_S
        try:
            out.append(RouteSection(name, float(m.length_m), slope, float(m.payload_kg), speed,
                                    float(m.standstill_s)))
        except BatteryPredictorError as exc:
            raise BatteryPredictorError(f"section {k}: {exc}") from None
    return out


def route_section_msgs(sections: Sequence[RouteSection]) -> list[RouteSectionMsg]:
    """Core route sections as ``RouteSection`` messages (for clients, benchmarks and tests)."""
    codes = {name: code for code, name in SLOPE_NAMES.items()}
    return [RouteSectionMsg(name=s.name, length_m=float(s.length_m), slope=codes[s.slope],
                            payload_kg=float(s.payload_kg), speed_m_s=float(s.speed_m_s),
                            standstill_s=float(s.standstill_s)) for s in sections]


def fill_route_response(response: CanAcceptRoute.Response, decision: RouteDecision) -> CanAcceptRoute.Response:
    """Copy a core decision into the service response."""
    response.accepted = bool(decision.accepted)
    response.predicted_voltage_v = float(decision.predicted_voltage_v)
    response.threshold_voltage_v = float(decision.threshold_voltage_v)
    response.margin_v = float(decision.margin_v)
    response.route_duration_s = float(decision.route_duration_s)
    response.route_charge_ah = float(decision.route_charge_ah)
    response.state_of_charge = float(decision.state_of_charge)
    response.reason = str(decision.reason) or ("accepted" if decision.accepted else "rejected")
    return response
