"""battery_monitor over rclpy: NaN / out-of-range samples are counted on /diagnostics and never reach the model.

The real nodes (monitor + predictor with the bundled node params) run on a
StartedMultiThreadedExecutor with ``use_sim_time``; the test publishes ``/clock`` and
the samples itself and waits, after each step, until the nodes have handled it
(lock step, :class:`~battery_predictor.nodes.replay_session.ReplaySession`),
so nothing depends on the machine's speed.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from rclpy.context import Context
from rclpy.serialization import serialize_message
from sensor_msgs.msg import BatteryState, Temperature
from std_msgs.msg import Float64

from battery_predictor.conventions import internal_current_to_battery_state
from battery_predictor.nodes.messages import ns_to_stamp, stamp_to_s
from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.replay import BagMessage, stream_from_messages

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
T0_NS = 1_704_067_200 * 10**9  # 2024-01-01T00:00:00Z
STEP_NS = 500_000_000  # 2 samples per second


def battery_state(t_ns: int, voltage_v: float, current_a: float, temperature_c: float = math.nan) -> BagMessage:
    """A BatteryState sample (current given positive = discharge, converted to the message's sign)."""
    msg = BatteryState(voltage=voltage_v, current=float(internal_current_to_battery_state(current_a)),
                       temperature=temperature_c, present=True)
    msg.header.stamp = ns_to_stamp(t_ns)
    return BagMessage(t_ns, "/battery_state", "sensor_msgs/msg/BatteryState", serialize_message(msg))


def monitor_status(session: ReplaySession):
    """The latest /diagnostics status of the monitor as (level, {key: value})."""
    statuses = [s for d in session.diagnostics() for s in d.status if s.name.endswith("battery input")]
    assert statuses, "no monitor diagnostics recorded"
    last = statuses[-1]
    return last.level[0], {kv.key: kv.value for kv in last.values}


def test_invalid_battery_state_samples_are_counted_and_do_not_reach_the_model(ros_context: Context) -> None:
    rng = np.random.default_rng(7)
    n = 60
    times = [T0_NS + k * STEP_NS for k in range(n)]
    volts = 49.8 + rng.normal(0.0, 0.02, n)
    amps = 1.7 + rng.normal(0.0, 0.05, n)
    garbage = {3: (math.nan, 1.7), 7: (49.8, math.inf), 11: (1000.0, 1.7), 15: (49.8, -99.0), 19: (5.0, 1.7),
               23: (math.nan, math.nan), 27: (-math.inf, 1.7)}
    messages = []
    for k, t in enumerate(times):
        v, i = garbage.get(k, (volts[k], amps[k]))
        messages.append(battery_state(t, v, i, 24.0))
    stream = stream_from_messages(messages, style="battery_state", battery_topic="/battery_state")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       rate=0) as session:
        session.play_until()
        session.advance_clock(times[-1] + 2 * 10**9)  # closes the last window, publishes diagnostics
        level, values = monitor_status(session)
        levels = [s.level[0] for d in session.diagnostics() for s in d.status if s.name.endswith("battery input")]
        states = session.pack_states()
        latest = session.predictor.core.latest_state()

    n_nan = sum(1 for v, i in garbage.values() if not (math.isfinite(v) and math.isfinite(i)))
    n_range = len(garbage) - n_nan
    assert values["rejected_nan"] == str(n_nan) == "4"
    assert values["rejected_out_of_range"] == str(n_range) == "3"
    assert values["rejected_battery_state_nan"] == "4"
    assert values["samples_rejected_total"] == "7"
    assert values["accepted_battery_state"] == str(n - len(garbage))
    # ERROR while invalid samples arrive, OK again error_hold_s (10 s) after the last one (at 13.5 s of 31.5 s)
    assert 2 in levels[:25]
    assert level == 0
    # the windows average exactly the valid samples (float32 message fields)
    valid_v = np.array([np.float32(v) for k, v in enumerate(volts) if k not in garbage], dtype=float)
    valid_t = np.array([t for k, t in enumerate(times) if k not in garbage])
    assert len(states) == 6 and not any(s.stale for s in states)
    for s in states:
        end_ns = round(stamp_to_s(s.header.stamp) * 1e9)
        in_window = (valid_t >= end_ns - 5 * 10**9) & (valid_t < end_ns)
        assert s.voltage_v == pytest.approx(valid_v[in_window].mean(), abs=1e-9)
        assert s.samples_used == in_window.sum()
        assert 45.0 < s.voltage_v < 55.0 and 1.0 < s.current_a < 2.5
        assert s.temperature_k == pytest.approx(297.15)
    assert sum(s.samples_rejected for s in states) == len(garbage)
    # the model saw the last clean window, nothing else
    assert latest is not None
    assert latest[1] == pytest.approx(states[-1].voltage_v) and latest[2] == pytest.approx(states[-1].current_a)


def test_diagnostics_return_to_ok_after_the_error_hold(ros_context: Context) -> None:
    times = [T0_NS + k * STEP_NS for k in range(60)]
    messages = [battery_state(t, math.nan if k == 2 else 49.8, 1.7) for k, t in enumerate(times)]
    stream = stream_from_messages(messages, style="battery_state", battery_topic="/battery_state")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       rate=0) as session:
        session.play_until(times[6])
        assert monitor_status(session)[0] == 2
        session.play_until()  # 28 s of valid samples: beyond error_hold_s = 10 s
        level, values = monitor_status(session)
    assert level == 0
    assert values["rejected_nan"] == "1" and values["stale"] == "false"


def test_relay_topics_invalid_values_are_counted_per_topic(ros_context: Context) -> None:
    messages = []
    for k in range(40):
        t = T0_NS + k * STEP_NS
        v = {5: math.nan, 9: 99.0}.get(k, 14.6)
        i = {13: -math.inf, 17: 40.0}.get(k, 1.6)
        messages.append(BagMessage(t, "/battery/voltage", "std_msgs/msg/Float64", serialize_message(Float64(data=v))))
        messages.append(BagMessage(t, "/battery/current", "std_msgs/msg/Float64", serialize_message(Float64(data=i))))
        if k % 10 == 0:
            temp = Temperature(temperature=math.nan if k == 10 else 23.0)
            messages.append(BagMessage(t, "/battery/temperature", "sensor_msgs/msg/Temperature",
                                       serialize_message(temp)))
    stream = stream_from_messages(messages, style="relay", battery_topic="/battery")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/temi_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 3600.0}, rate=0) as session:
        session.play_until()
        session.advance_clock(stream.end_ns + 2 * 10**9)
        _, values = monitor_status(session)
        levels = [s.level[0] for d in session.diagnostics() for s in d.status if s.name.endswith("battery input")]
        states = session.pack_states()
    assert 2 in levels
    assert values["rejected_voltage_nan"] == "1" and values["rejected_voltage_out_of_range"] == "1"
    assert values["rejected_current_nan"] == "1" and values["rejected_current_out_of_range"] == "1"
    assert values["rejected_temperature_nan"] == "1"
    assert values["accepted_voltage"] == "38" and values["accepted_current"] == "38"
    assert len(states) == 4
    for s in states:
        assert s.voltage_v == pytest.approx(14.6) and s.current_a == pytest.approx(1.6)
        assert s.temperature_k == pytest.approx(296.15)
