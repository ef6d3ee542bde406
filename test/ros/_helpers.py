"""Helpers of the node tests: synthetic pack samples as bag messages, a service call over the middleware."""

from __future__ import annotations

import time

from rclpy.serialization import serialize_message
from sensor_msgs.msg import BatteryState

from battery_predictor.conventions import internal_current_to_battery_state
from battery_predictor.nodes.messages import ns_to_stamp
from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.replay import BagMessage

#: Start of the synthetic recordings (2024-01-01 00:00 UTC), ns; one second in ns.
T0_NS = 1_704_067_200 * 10**9
S = 10**9


def battery_state_samples(start_s: float, end_s: float, voltage_v: float, current_a: float) -> list[BagMessage]:
    """One ``/battery_state`` message per second from ``start_s`` to ``end_s`` (V, A positive = discharge)."""
    out = []
    for k in range(round(end_s - start_s)):
        t_ns = T0_NS + round((start_s + k) * S)
        msg = BatteryState(voltage=voltage_v, current=float(internal_current_to_battery_state(current_a)),
                           temperature=25.0, present=True)
        msg.header.stamp = ns_to_stamp(t_ns)
        out.append(BagMessage(t_ns, "/battery_state", "sensor_msgs/msg/BatteryState", serialize_message(msg)))
    return out


def call_service(session: ReplaySession, srv_type, srv_name: str, request, timeout_s: float = 60.0):
    """Call ``srv_name`` over the middleware from the session's client node; fails the test on a time-out."""
    client = session.client_node.create_client(srv_type, srv_name)
    try:
        deadline = time.monotonic() + timeout_s
        while not client.service_is_ready():
            assert time.monotonic() < deadline, f"{srv_name} service not discovered"
            time.sleep(0.01)
        future = client.call_async(request)
        while not future.done():
            assert time.monotonic() < deadline, f"no {srv_name} response"
            time.sleep(0.005)
        return future.result()
    finally:
        session.client_node.destroy_client(client)
