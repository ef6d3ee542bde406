"""Conversions between ROS messages and the ROS-free cores (times, route sections, answers).

Sign conventions: ``PackState`` and ``RemainingRuntime`` carry currents positive
while discharging, as the cores do; ``sensor_msgs/BatteryState`` is converted
only through :mod:`battery_predictor.conventions` (in the monitor node).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from battery_predictor_msgs.msg import PackState, PlannedRoute, RemainingRuntime, TaskResult
from battery_predictor_msgs.msg import RouteSection as RouteSectionMsg
from battery_predictor_msgs.msg import Task as TaskMsg
from battery_predictor_msgs.srv import CanAcceptRoute, FeasibleTasks, PlanRoute
from builtin_interfaces.msg import Time

from battery_predictor.errors import BatteryPredictorError, RequestError
from battery_predictor.monitor.core import PackSnapshot
from battery_predictor.prediction.core import RuntimeStatus
from battery_predictor.prediction.planning import CHARGE_FIRST, LEAST_CHARGE_PATH, SHORTEST, PlanRequest, RoutePlan
from battery_predictor.prediction.route import MAX_SECTIONS, RouteDecision
from battery_predictor.prediction.tasks import (
    MAX_TASKS,
    POLICY_GREEDY,
    POLICY_INDEPENDENT,
    POLICY_ORDERED,
    Task,
    TaskPlan,
)
from battery_predictor.profiles.ranger import DEFAULT_SPEED_M_S, RouteSection
from battery_predictor.profiles.temi import INFORMATION, NAVIGATION

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


#: Whether the built ``PackState`` has ``min_cell_voltage_v`` (an interface package built before the field
#: was added has not: ``make setup`` rebuilds it; until then no cell voltage is passed on).
PACK_STATE_HAS_MIN_CELL = hasattr(PackState(), "min_cell_voltage_v")


def pack_state_msg(snap: PackSnapshot, frame_id: str) -> PackState:
    """A monitor snapshot as ``PackState``."""
    msg = PackState(voltage_v=float(snap.voltage_v), current_a=float(snap.current_a),
                    peak_current_a=float(snap.peak_current_a),
                    temperature_k=float(snap.temperature_k), window_s=float(snap.window_s),
                    samples_used=int(min(snap.samples_used, 2**32 - 1)),
                    samples_rejected=int(min(snap.samples_rejected, 2**32 - 1)), stale=bool(snap.stale))
    if PACK_STATE_HAS_MIN_CELL:
        msg.min_cell_voltage_v = float(snap.min_cell_voltage_v)
    msg.header.stamp = s_to_stamp(snap.stamp_s)
    msg.header.frame_id = frame_id
    return msg


def pack_state_min_cell_voltage_v(msg: PackState) -> float:
    """``PackState.min_cell_voltage_v`` in V; NaN when not measured (NaN, <= 0: the default of a message that
    does not set it, or a ``PackState`` built without the field)."""
    value = float(getattr(msg, "min_cell_voltage_v", math.nan))
    return value if math.isfinite(value) and value > 0.0 else math.nan


def remaining_runtime_msg(status: RuntimeStatus, frame_id: str) -> RemainingRuntime:
    """A core runtime answer as ``RemainingRuntime``."""
    msg = RemainingRuntime(remaining_s=float(status.remaining_s), assumed_current_a=float(status.assumed_current_a),
                           assumed_temperature_k=float(status.assumed_temperature_k),
                           state_of_charge=float(status.state_of_charge),
                           remaining_p10_s=float(status.remaining_p10_s), remaining_p90_s=float(status.remaining_p90_s),
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
    response.probability_above_threshold = float(decision.probability_above_threshold)
    response.voltage_at_risk_v = float(decision.voltage_at_risk_v)
    response.risk = float(decision.risk)
    response.reason = str(decision.reason) or ("accepted" if decision.accepted else "rejected")
    return response


#: FeasibleTasks.srv policy constants -> policies of the ROS-free core, and back.
POLICY_NAMES = {FeasibleTasks.Request.POLICY_INDEPENDENT: POLICY_INDEPENDENT,
                FeasibleTasks.Request.POLICY_ORDERED: POLICY_ORDERED,
                FeasibleTasks.Request.POLICY_GREEDY: POLICY_GREEDY}
POLICY_CODES = {name: code for code, name in POLICY_NAMES.items()}
#: Task.msg kind constants -> task kinds of the ROS-free core, and back.
KIND_NAMES = {TaskMsg.KIND_INFORMATION: INFORMATION, TaskMsg.KIND_NAVIGATION: NAVIGATION}
KIND_CODES = {name: code for code, name in KIND_NAMES.items()}
#: PlannedRoute.msg kind constants of the planner's route kinds.
ROUTE_KIND_CODES = {SHORTEST: PlannedRoute.KIND_SHORTEST, LEAST_CHARGE_PATH: PlannedRoute.KIND_LEAST_CHARGE_PATH,
                    CHARGE_FIRST: PlannedRoute.KIND_CHARGE_FIRST}


def _short(text: str) -> str:
    return text if len(text) <= MAX_NAME_CHARS else text[:MAX_NAME_CHARS] + "..."


def task_policy(code: int) -> str:
    """The core's policy name of a ``FeasibleTasks`` policy constant (RequestError when unknown)."""
    policy = POLICY_NAMES.get(int(code))
    if policy is None:
        raise RequestError(f"policy {int(code)} is not one of POLICY_INDEPENDENT=0, POLICY_ORDERED=1, "
                           "POLICY_GREEDY=2")
    return policy


def tasks_from_msgs(msgs: Sequence[TaskMsg]) -> list[Task]:
    """Validated core tasks from a request.

    ``duration_s == 0`` and ``current_a == 0`` mean "not given" (the walk to the destination, the
    kind's mean current). A task without a name is named by its position.

    Raises
    ------
    RequestError
        With a one-line reason: too many tasks, an unknown kind, profile arrays of different
        lengths, or a task the core rejects (NaN or negative duration, absurd current...).
    """
    if len(msgs) > MAX_TASKS:
        raise RequestError(f"{len(msgs)} tasks (at most {MAX_TASKS})")
    out = []
    for k, m in enumerate(msgs, start=1):
        name = _short(m.name if m.name.strip() else f"task {k}")
        kind = KIND_NAMES.get(int(m.kind))
        if kind is None:
            raise RequestError(f"task {k} ({name!r}): kind {int(m.kind)} is not one of KIND_INFORMATION=0, "
                               "KIND_NAVIGATION=1")
        durations, currents = list(m.profile_duration_s), list(m.profile_current_a)
        if len(durations) != len(currents):
            raise RequestError(f"task {k} ({name!r}): profile_duration_s has {len(durations)} values but "
                               f"profile_current_a {len(currents)}")
        duration, current = float(m.duration_s), float(m.current_a)
        try:
            out.append(Task(name, kind, math.nan if duration == 0.0 else duration, _short(str(m.destination)),
                            math.nan if current == 0.0 else current, tuple(zip(durations, currents))))
        except BatteryPredictorError as exc:
            raise RequestError(f"task {k}: {exc}") from None
    return out


def fill_feasible_tasks_response(response: FeasibleTasks.Response, plan: TaskPlan) -> FeasibleTasks.Response:
    """Copy a core task plan into the service response."""
    response.valid = bool(plan.valid)
    response.policy = int(POLICY_CODES.get(plan.policy, 0))
    response.results = [TaskResult(name=o.name, kind=int(KIND_CODES.get(o.kind, 0)), feasible=bool(o.feasible),
                                   duration_s=float(o.duration_s), current_a=float(o.current_a),
                                   end_voltage_v=float(o.end_voltage_v), return_voltage_v=float(o.return_voltage_v),
                                   margin_v=float(o.margin_v), remaining_after_s=float(o.remaining_after_s),
                                   end_location=str(o.end_location),
                                   probability_feasible=float(o.probability_feasible), reason=str(o.reason) or
                                   ("feasible" if o.feasible else "not feasible"))
                        for o in plan.outcomes]
    response.feasible_count = int(plan.feasible_count)
    response.more_guided_walks = int(min(max(plan.more_guided_walks, 0), 2**32 - 1))
    response.walk_length_m = float(plan.walk_length_m)
    response.more_information_s = float(plan.more_information_s)
    response.summary = str(plan.summary)
    response.state_of_charge = float(plan.state_of_charge)
    response.cutoff_voltage_v = float(plan.cutoff_voltage_v)
    response.reason = str(plan.reason) or ("valid" if plan.valid else "not valid")
    return response


def plan_request(request: PlanRoute.Request) -> PlanRequest:
    """A validated core plan request (RequestError with the reason otherwise)."""
    speed = float(request.speed_m_s)
    try:
        return PlanRequest(str(request.start_node), str(request.pickup), str(request.dropoff),
                           float(request.payload_kg), bool(request.use_position), float(request.x_m),
                           float(request.y_m), bool(request.ends_away_from_charger), float(request.loading_s),
                           float(request.unloading_s), DEFAULT_SPEED_M_S if speed == 0.0 else speed)
    except RequestError:
        raise
    except BatteryPredictorError as exc:
        raise RequestError(str(exc)) from None


def fill_plan_route_response(response: PlanRoute.Response, plan: RoutePlan, threshold_v: float
                             ) -> PlanRoute.Response:
    """Copy a core route plan into the service response."""
    route = plan.route
    response.start_node = str(plan.start_node)
    response.approach_m = float(plan.approach_m)
    response.threshold_voltage_v = float(threshold_v)
    if route is None:
        response.accepted = False
        for attr in ("length_m", "predicted_voltage_v", "margin_v", "route_duration_s", "route_charge_ah",
                     "state_of_charge", "probability_above_threshold", "voltage_at_risk_v", "risk"):
            setattr(response, attr, math.nan)
    else:
        d = route.decision
        response.accepted = bool(d.accepted)
        response.nodes = list(route.nodes)
        response.sections = route_section_msgs(route.sections)
        response.length_m = float(route.length_m)
        response.predicted_voltage_v = float(d.predicted_voltage_v)
        response.threshold_voltage_v = float(d.threshold_voltage_v)
        response.margin_v = float(d.margin_v)
        response.route_duration_s = float(d.route_duration_s)
        response.route_charge_ah = float(d.route_charge_ah)
        response.state_of_charge = float(d.state_of_charge)
        response.probability_above_threshold = float(d.probability_above_threshold)
        response.voltage_at_risk_v = float(d.voltage_at_risk_v)
        response.risk = float(d.risk)
    response.alternatives = [
        PlannedRoute(kind=ROUTE_KIND_CODES[a.kind], feasible=bool(a.feasible), nodes=list(a.nodes),
                     sections=route_section_msgs(a.sections), length_m=float(a.length_m),
                     predicted_voltage_v=float(a.decision.predicted_voltage_v), margin_v=float(a.decision.margin_v),
                     route_duration_s=float(a.decision.route_duration_s),
                     route_charge_ah=float(a.decision.route_charge_ah), required_soc=float(a.required_soc),
                     probability_above_threshold=float(a.decision.probability_above_threshold),
                     voltage_at_risk_v=float(a.decision.voltage_at_risk_v), risk=float(a.decision.risk),
                     reason=str(a.reason)) for a in plan.alternatives]
    response.reason = str(plan.reason) or ("accepted" if response.accepted else "rejected")
    return response
