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

from battery_predictor.nodes.messages import route_section_msgs
from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.profiles.ranger import longest_route
from battery_predictor.replay import stream_from_messages

from ._helpers import T0_NS, S
from ._helpers import battery_state_samples as samples

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]




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
