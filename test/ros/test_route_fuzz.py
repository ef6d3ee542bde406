"""Malformed /can_accept_route requests over the middleware: never an exception, always a reason.

A few hundred seeded random requests (no sections, NaN / infinite / negative
numbers, unknown slopes, absurd payloads and speeds, routes longer than any
battery could run, too many sections, odd names) go to the real predictor node
through a real service client. Every answer must carry a reason; every request
that an independent check finds invalid must be rejected; the service must keep
answering (the executor thread never dies) and still decide a valid route.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from battery_predictor_msgs.msg import RouteSection
from battery_predictor_msgs.srv import CanAcceptRoute
from rclpy.context import Context
from rclpy.serialization import serialize_message
from sensor_msgs.msg import BatteryState

from battery_predictor.conventions import internal_current_to_battery_state
from battery_predictor.nodes.messages import ns_to_stamp, route_section_msgs
from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.profiles.ranger import longest_route
from battery_predictor.replay import BagMessage, stream_from_messages

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
T0_NS = 1_704_067_200 * 10**9
N_REQUESTS = 300

NUMBERS = [math.nan, math.inf, -math.inf, -1.0, -1e-9, 0.0, 1e-9, 0.5, 20.0, 75.0, 190.0, 199.9, 200.0, 200.1,
           1e4, 1e9, 1e308, -1e308, 5e-324]
NAMES = ["", " ", "flat", "ü→∂ 🚂", "x" * 2000, "a\nb", "\x00"]


def random_section(rng: np.random.Generator) -> RouteSection:
    def num(normal: float) -> float:
        return float(rng.choice(NUMBERS)) if rng.random() < 0.35 else normal

    return RouteSection(
        name=str(rng.choice(NAMES)) if rng.random() < 0.3 else f"s{rng.integers(100)}",
        length_m=num(float(rng.uniform(0.0, 400.0))),
        slope=int(rng.choice([0, 1, 2, 3, 7, 255])) if rng.random() < 0.2 else int(rng.integers(3)),
        payload_kg=num(float(rng.choice([0.0, 20.0, 40.0, 60.0, 80.0]))),
        speed_m_s=num(float(rng.choice([0.0, 0.5, 0.8]))),
        standstill_s=num(float(rng.choice([0.0, 0.0, 60.0]))),
    )


def random_request(rng: np.random.Generator) -> CanAcceptRoute.Request:
    kind = rng.random()
    if kind < 0.05:
        n = 0
    elif kind < 0.08:
        n = 500  # the most the interface allows
    else:
        n = int(rng.integers(1, 8))
    return CanAcceptRoute.Request(sections=[random_section(rng) for _ in range(n)],
                                  starts_away_from_charger=bool(rng.random() < 0.3),
                                  ends_away_from_charger=bool(rng.random() < 0.3))


def obviously_invalid(request: CanAcceptRoute.Request) -> str | None:
    """Why a request cannot be a drivable route (independent of the node's code), or None."""
    if len(request.sections) == 0:
        return "no sections"
    if len(request.sections) > 500:
        return "too many sections"
    total_s = 0.0
    for s in request.sections:
        values = (s.length_m, s.payload_kg, s.speed_m_s, s.standstill_s)
        if not all(math.isfinite(v) for v in values):
            return "non-finite number"
        if min(values) < 0:
            return "negative number"
        if s.slope > 2:
            return "unknown slope"
        if s.payload_kg > 200:
            return "absurd payload"
        if s.length_m == 0 and s.standstill_s == 0:
            return "empty section"
        speed = s.speed_m_s or 0.5
        total_s += s.length_m / speed + s.standstill_s
    if total_s > 24 * 3600:
        return "longer than a day"
    return None


def state_stream():
    msgs = []
    for k in range(20):
        t = T0_NS + k * 10**9
        msg = BatteryState(voltage=49.6, current=float(internal_current_to_battery_state(1.7)), temperature=25.0)
        msg.header.stamp = ns_to_stamp(t)
        msgs.append(BagMessage(t, "/battery_state", "sensor_msgs/msg/BatteryState", serialize_message(msg)))
    return stream_from_messages(msgs, style="battery_state", battery_topic="/battery_state")


def test_a_request_longer_than_the_interface_bound_never_leaves_the_client() -> None:
    """The middleware refuses to serialise it, so the node never spends time on it."""
    from rclpy.serialization import serialize_message

    serialize_message(CanAcceptRoute.Request(sections=[RouteSection(name="s", length_m=1.0)] * 500))
    with pytest.raises(Exception, match="serialize"):
        serialize_message(CanAcceptRoute.Request(sections=[RouteSection(name="s", length_m=1.0)] * 501))


def test_random_malformed_requests_never_raise_and_always_give_a_reason(ros_context: Context) -> None:
    rng = np.random.default_rng(20240101)
    with ReplaySession(state_stream(), context=ros_context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 3600.0}, rate=0) as session:
        session.play_until()
        results = []
        for _ in range(N_REQUESTS):
            request = random_request(rng)
            results.append((request, session.call_route(request)))
        # still alive and still deciding after the fuzz
        valid = session.call_route(CanAcceptRoute.Request(sections=route_section_msgs(longest_route(60.0).sections)))
        answered = session.predictor.routes_answered

    assert answered == N_REQUESTS + 1
    invalid_count = 0
    for request, response in results:
        assert isinstance(response.accepted, bool)
        assert response.reason.strip(), "an answer without a reason"
        why = obviously_invalid(request)
        if why is not None:
            invalid_count += 1
            assert not response.accepted, f"accepted a request with {why}: {response.reason}"
        if response.accepted:
            assert response.margin_v >= 0 and math.isfinite(response.predicted_voltage_v)
            assert response.predicted_voltage_v >= response.threshold_voltage_v
    assert invalid_count > N_REQUESTS // 2  # the fuzz mostly hits the invalid paths...
    assert any(r.accepted for _, r in results)  # ...and some requests are fine and accepted
    assert "state unknown" not in valid.reason and valid.accepted, valid.reason
    assert valid.route_duration_s == pytest.approx(longest_route(60.0).duration_s)
