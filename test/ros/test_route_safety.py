"""Through the real monitor + predictor nodes: a route is never accepted against the measurement.

The scenario a new user met: ``BatteryState`` at 49.8 V / 3 A for 30 s, then 44.0 V / 3 A, then
46.5 V / 7 A (Ranger node params, lock step on ``/clock``). The longest route at 80 kg is accepted
on the charged pack and rejected, with the reason, once the measurement says the pack is low;
``/remaining_runtime`` never says ``valid`` with a status other than OK.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from battery_predictor_msgs.msg import RemainingRuntime
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
S = 10**9


def samples(start_s: float, end_s: float, voltage_v: float, current_a: float) -> list[BagMessage]:
    out = []
    for k in range(round(end_s - start_s)):
        t_ns = T0_NS + round((start_s + k) * S)
        msg = BatteryState(voltage=voltage_v, current=float(internal_current_to_battery_state(current_a)),
                           temperature=25.0, present=True)
        msg.header.stamp = ns_to_stamp(t_ns)
        out.append(BagMessage(t_ns, "/battery_state", "sensor_msgs/msg/BatteryState", serialize_message(msg)))
    return out


def test_route_rejected_once_the_measured_pack_is_low(ros_context: Context) -> None:
    request = CanAcceptRoute.Request(sections=route_section_msgs(longest_route(80.0).sections))
    stream = stream_from_messages(samples(0.0, 30.0, 49.8, 3.0) + samples(30.0, 60.0, 44.0, 3.0)
                                  + samples(60.0, 90.0, 46.5, 7.0), style="battery_state",
                                  battery_topic="/battery_state")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 5.0}, rate=0) as session:
        session.play_until(T0_NS + 29 * S)
        charged = session.call_route(request)
        session.play_until(T0_NS + 59 * S)
        low = session.call_route(request)
        session.play_until()
        loaded = session.call_route(request)
        runtimes = session.recorder.snapshot(session.outputs["remaining_runtime"])
    assert charged.accepted, charged.reason
    assert not low.accepted and "already below the route threshold 46.31 V" in low.reason, low.reason
    assert not loaded.accepted, loaded.reason
    assert runtimes and all(r.valid == (r.status == RemainingRuntime.STATUS_OK) for r in runtimes)
    assert any(r.status == RemainingRuntime.STATUS_BELOW_CUTOFF and not r.valid for r in runtimes)
