"""Through the real monitor + predictor nodes: a cell measured at its cut-off refuses a route.

``BatteryState`` at 49.8 V / 3 A (Ranger node params, 15 cells in series, cell cut-off 3.0 V) with
``cell_voltage`` set: the longest route at 80 kg is accepted while the cells read 3.32 V, and
refused, naming the measured minimum cell voltage, once one cell reads 2.95 V at the same pack
voltage. ``PackState.min_cell_voltage_v`` carries the window's lowest cell voltage.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from battery_predictor_msgs.srv import CanAcceptRoute
from rclpy.context import Context
from rclpy.serialization import serialize_message
from sensor_msgs.msg import BatteryState

from battery_predictor.conventions import internal_current_to_battery_state
from battery_predictor.nodes.messages import PACK_STATE_HAS_MIN_CELL, ns_to_stamp, route_section_msgs
from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.profiles.ranger import longest_route
from battery_predictor.replay import BagMessage, stream_from_messages

from ._helpers import T0_NS, S

pytestmark = [pytest.mark.ros,
              pytest.mark.skipif(not PACK_STATE_HAS_MIN_CELL,
                                 reason="the built battery_predictor_msgs predate PackState.min_cell_voltage_v "
                                        "(make setup rebuilds them)")]

REPO = Path(__file__).resolve().parents[2]


def _samples(start_s: float, end_s: float, cells_v: list[float]) -> list[BagMessage]:
    out = []
    for k in range(round(end_s - start_s)):
        t_ns = T0_NS + round((start_s + k) * S)
        msg = BatteryState(voltage=49.8, current=float(internal_current_to_battery_state(3.0)), temperature=25.0,
                           present=True, cell_voltage=cells_v)
        msg.header.stamp = ns_to_stamp(t_ns)
        out.append(BagMessage(t_ns, "/battery_state", "sensor_msgs/msg/BatteryState", serialize_message(msg)))
    return out


def test_a_cell_at_its_cut_off_refuses_the_route_the_pack_voltage_accepts(ros_context: Context) -> None:
    request = CanAcceptRoute.Request(sections=route_section_msgs(longest_route(80.0).sections))
    healthy = [3.32] * 15
    weak = [3.32] * 14 + [2.95]
    stream = stream_from_messages(_samples(0.0, 30.0, healthy) + _samples(30.0, 60.0, weak),
                                  style="battery_state", battery_topic="/battery_state")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 5.0}, rate=0) as session:
        session.play_until(T0_NS + 29 * S)
        before = session.call_route(request)
        session.play_until()
        after = session.call_route(request)
        states = session.pack_states()
    assert before.accepted, before.reason
    assert not after.accepted
    assert "measured minimum cell voltage 2.950 V" in after.reason and "lower cut-off 3.00 V" in after.reason
    fresh = [s for s in states if not s.stale]
    assert fresh and all(math.isclose(s.min_cell_voltage_v, 3.32, abs_tol=1e-5) or
                         math.isclose(s.min_cell_voltage_v, 2.95, abs_tol=1e-5) for s in fresh)
    assert math.isclose(fresh[-1].min_cell_voltage_v, 2.95, abs_tol=1e-5)
