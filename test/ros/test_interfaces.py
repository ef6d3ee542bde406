"""The custom interfaces in msg_defs/ (battery_predictor_msgs), built by tools/build_msgs.sh.

Checks their fields and constants, and that they travel over rclpy: a
CanAcceptRoute service call and a PackState publish/subscribe, each in one
process on a context (and ROS domain) of its own.
"""

from __future__ import annotations

import math
import time

import pytest
from battery_predictor_msgs.msg import PackState, RemainingRuntime, RouteSection
from battery_predictor_msgs.srv import CanAcceptRoute
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future

pytestmark = pytest.mark.ros

# Generous: discovery and the first call on a loaded 2-core machine.
TIMEOUT_S = 30.0


# --- fields and constants ---------------------------------------------------


def test_pack_state_fields() -> None:
    assert PackState.get_fields_and_field_types() == {
        "header": "std_msgs/Header",
        "voltage_v": "double",
        "current_a": "double",
        "peak_current_a": "double",
        "temperature_k": "double",
        "window_s": "double",
        "samples_used": "uint32",
        "samples_rejected": "uint32",
        "stale": "boolean",
        "min_cell_voltage_v": "double",
    }
    msg = PackState(temperature_k=math.nan, current_a=2.5, stale=True)
    assert math.isnan(msg.temperature_k)
    assert msg.current_a == 2.5
    assert msg.stale is True
    assert msg.samples_used == 0


def test_remaining_runtime_fields_and_status_constants() -> None:
    assert RemainingRuntime.get_fields_and_field_types() == {
        "header": "std_msgs/Header",
        "remaining_s": "double",
        "assumed_current_a": "double",
        "assumed_temperature_k": "double",
        "remaining_p10_s": "double",
        "remaining_p90_s": "double",
        "state_of_charge": "double",
        "cutoff_voltage_v": "double",
        "valid": "boolean",
        "status": "uint8",
        "reason": "string",
    }
    expected = {
        "STATUS_OK": 0,
        "STATUS_STALE_INPUT": 1,
        "STATUS_NO_INPUT": 2,
        "STATUS_MODEL_NOT_FITTED": 3,
        "STATUS_MODEL_FAILED": 4,
        "STATUS_BELOW_CUTOFF": 5,
        "STATUS_CHARGING": 6,
        "STATUS_NO_LOAD": 7,
        "STATUS_BEYOND_HORIZON": 8,
    }
    for name, value in expected.items():
        assert getattr(RemainingRuntime, name) == value, name
    msg = RemainingRuntime(status=RemainingRuntime.STATUS_MODEL_FAILED, reason="solver diverged")
    assert msg.status == 4
    assert msg.reason == "solver diverged"
    assert msg.valid is False


def test_route_section_fields_and_slope_constants() -> None:
    assert RouteSection.get_fields_and_field_types() == {
        "name": "string",
        "length_m": "double",
        "slope": "uint8",
        "payload_kg": "double",
        "speed_m_s": "double",
        "standstill_s": "double",
    }
    assert (RouteSection.SLOPE_FLAT, RouteSection.SLOPE_UPHILL, RouteSection.SLOPE_DOWNHILL) == (0, 1, 2)
    section = RouteSection()
    assert section.slope == RouteSection.SLOPE_FLAT
    assert section.speed_m_s == 0.0  # 0 = robot default speed


def test_can_accept_route_fields() -> None:
    assert CanAcceptRoute.Request.get_fields_and_field_types() == {
        "sections": "sequence<battery_predictor_msgs/RouteSection, 500>",
        "starts_away_from_charger": "boolean",
        "ends_away_from_charger": "boolean",
    }
    assert CanAcceptRoute.Response.get_fields_and_field_types() == {
        "accepted": "boolean",
        "predicted_voltage_v": "double",
        "threshold_voltage_v": "double",
        "margin_v": "double",
        "route_duration_s": "double",
        "route_charge_ah": "double",
        "state_of_charge": "double",
        "probability_above_threshold": "double",
        "voltage_at_risk_v": "double",
        "risk": "double",
        "reason": "string",
    }
    request = CanAcceptRoute.Request()
    # defaults: the route starts and ends at the charger
    assert request.starts_away_from_charger is False
    assert request.ends_away_from_charger is False
    assert list(request.sections) == []


# --- over rclpy -------------------------------------------------------------


def _spin_until(executor: SingleThreadedExecutor, condition, timeout_s: float = TIMEOUT_S) -> bool:
    """Spin until condition() is true or the timeout passes; returns condition()."""
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    return bool(condition())


def test_ros_context_has_its_own_domain_id(ros_context: Context, ros_domain_id: int) -> None:
    assert ros_context.ok()
    assert ros_context.get_domain_id() == ros_domain_id
    assert ros_domain_id != 0


def test_can_accept_route_service_round_trip(ros_context: Context, unique_name: str) -> None:
    service_name = f"/{unique_name}/can_accept_route"
    received: list[CanAcceptRoute.Request] = []

    def handle(request: CanAcceptRoute.Request, response: CanAcceptRoute.Response) -> CanAcceptRoute.Response:
        received.append(request)
        response.route_duration_s = sum(s.length_m / s.speed_m_s + s.standstill_s for s in request.sections)
        response.predicted_voltage_v = 13.1
        response.threshold_voltage_v = 12.8
        response.margin_v = response.predicted_voltage_v - response.threshold_voltage_v
        response.accepted = response.margin_v >= 0.0
        response.route_charge_ah = 0.25
        response.state_of_charge = 0.8
        response.reason = ",".join(s.name for s in request.sections)
        return response

    server_node = Node(f"{unique_name}_server", context=ros_context)
    client_node = Node(f"{unique_name}_client", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        server_node.create_service(CanAcceptRoute, service_name, handle)
        client = client_node.create_client(CanAcceptRoute, service_name)
        executor.add_node(server_node)
        executor.add_node(client_node)
        assert _spin_until(executor, client.service_is_ready), "service did not appear"

        request = CanAcceptRoute.Request(
            sections=[
                RouteSection(
                    name="to_shelf",
                    length_m=40.0,
                    slope=RouteSection.SLOPE_UPHILL,
                    payload_kg=12.5,
                    speed_m_s=0.5,
                    standstill_s=30.0,
                ),
                RouteSection(
                    name="back",
                    length_m=40.0,
                    slope=RouteSection.SLOPE_DOWNHILL,
                    payload_kg=0.0,
                    speed_m_s=0.8,
                    standstill_s=0.0,
                ),
            ],
            starts_away_from_charger=False,
            ends_away_from_charger=True,
        )
        future: Future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=TIMEOUT_S)
        assert future.done(), "no response within the timeout"
        response = future.result()
    finally:
        executor.shutdown()
        client_node.destroy_node()
        server_node.destroy_node()

    assert len(received) == 1
    got = received[0]
    assert [s.name for s in got.sections] == ["to_shelf", "back"]
    assert got.sections[0].slope == RouteSection.SLOPE_UPHILL
    assert got.sections[0].payload_kg == 12.5
    assert got.sections[1].slope == RouteSection.SLOPE_DOWNHILL
    assert got.starts_away_from_charger is False
    assert got.ends_away_from_charger is True

    assert isinstance(response, CanAcceptRoute.Response)
    assert response.accepted is True
    assert response.route_duration_s == pytest.approx(40.0 / 0.5 + 30.0 + 40.0 / 0.8)
    assert response.margin_v == pytest.approx(0.3)
    assert response.threshold_voltage_v == 12.8
    assert response.route_charge_ah == 0.25
    assert response.state_of_charge == 0.8
    assert response.reason == "to_shelf,back"


def test_pack_state_publish_subscribe_round_trip(ros_context: Context, unique_name: str) -> None:
    topic = f"/{unique_name}/pack_state"
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    received: list[PackState] = []

    node = Node(f"{unique_name}_node", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        subscription = node.create_subscription(PackState, topic, received.append, qos)
        publisher = node.create_publisher(PackState, topic, qos)
        executor.add_node(node)
        # Wait for discovery to match both ends before publishing.
        assert _spin_until(
            executor,
            lambda: publisher.get_subscription_count() >= 1 and subscription.get_publisher_count() >= 1,
        ), "publisher and subscription did not match"

        sent = PackState(
            voltage_v=14.2,
            current_a=3.25,
            temperature_k=math.nan,
            window_s=5.0,
            samples_used=50,
            samples_rejected=2,
            stale=False,
        )
        sent.header.frame_id = "battery"
        sent.header.stamp.sec = 1_700_000_000
        sent.header.stamp.nanosec = 123_456_789
        publisher.publish(sent)
        assert _spin_until(executor, lambda: len(received) >= 1), "no PackState received"
    finally:
        executor.shutdown()
        node.destroy_node()

    got = received[0]
    assert got.header.frame_id == "battery"
    assert (got.header.stamp.sec, got.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert got.voltage_v == 14.2
    assert got.current_a == 3.25
    assert math.isnan(got.temperature_k)
    assert got.window_s == 5.0
    assert (got.samples_used, got.samples_rejected) == (50, 2)
    assert got.stale is False
