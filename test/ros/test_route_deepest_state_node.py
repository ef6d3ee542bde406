"""Through the real monitor + predictor nodes: a route below the fit data's deepest state is refused.

A Ranger pack whose fit data stopped at 47.60 V / 2.20 A (above the 46.31 V route threshold: a weak group) is fed
``BatteryState`` at 47.6 V / 1.7 A. With the shipped params the longest route at 40 kg is accepted (the model's
identical cells run past that state); with the same params keeping that deepest state (as `fit` writes it) the
route is refused, and the reason names the deepest state.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from battery_predictor_msgs.srv import CanAcceptRoute
from rclpy.context import Context
from rclpy.serialization import serialize_message
from sensor_msgs.msg import BatteryState

from battery_predictor.conventions import internal_current_to_battery_state
from battery_predictor.nodes.messages import ns_to_stamp, route_section_msgs
from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.params import load_params
from battery_predictor.profiles.ranger import longest_route
from battery_predictor.recording import DeepestState
from battery_predictor.replay import BagMessage, stream_from_messages

from ._helpers import T0_NS, S

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]


def _samples(seconds: int) -> list[BagMessage]:
    out = []
    for k in range(seconds):
        t_ns = T0_NS + k * S
        msg = BatteryState(voltage=47.6, current=float(internal_current_to_battery_state(1.7)), temperature=25.0,
                           present=True)
        msg.header.stamp = ns_to_stamp(t_ns)
        out.append(BagMessage(t_ns, "/battery_state", "sensor_msgs/msg/BatteryState", serialize_message(msg)))
    return out


def _answer(ros_context: Context, pack_params_file: Path):
    request = CanAcceptRoute.Request(sections=route_section_msgs(longest_route(40.0).sections))
    stream = stream_from_messages(_samples(60), style="battery_state", battery_topic="/battery_state")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 5.0, "params_file": str(pack_params_file)},
                       rate=0) as session:
        session.play_until()
        return session.call_route(request)


def test_a_route_below_the_fit_datas_deepest_state_is_refused_through_the_nodes(ros_context: Context,
                                                                                 tmp_path: Path) -> None:
    params = load_params(REPO / "params" / "ranger_mini.yaml")
    stopped = replace(params, thresholds={**params.thresholds, **DeepestState(47.6, 2.2, 298.15).as_thresholds()})
    stopped.to_yaml(tmp_path / "stopped.yaml")
    plain = _answer(ros_context, REPO / "params" / "ranger_mini.yaml")
    refused = _answer(ros_context, tmp_path / "stopped.yaml")
    assert plain.accepted, plain.reason
    assert not refused.accepted
    assert "deepest state of the fit data (47.60 V at 2.20 A" in refused.reason
