"""``battery_monitor``: raw pack samples in, one clean ``PackState`` and ``/diagnostics`` out.

Inputs (parameter ``input_style``), subscribed with the sensor-data QoS passed in
(default ``qos_profile_sensor_data``: best effort, keep last 5):

* ``battery_state``: ``sensor_msgs/BatteryState`` on ``battery_state_topic``
  (Ranger SDK bridge). ``current`` is negative while discharging in that
  message; it is converted by :func:`battery_predictor.conventions.battery_state_current_to_internal`.
  ``temperature`` is in °C, NaN = not measured. ``cell_voltage`` (V, NaN = not
  measured): the window's lowest goes on in ``PackState.min_cell_voltage_v`` (the
  predictor refuses routes when it is at or below the cell's lower cut-off).
  Timed by ``header.stamp`` (the node clock when the stamp is zero).
* ``relay``: ``std_msgs/Float64`` ``<relay_prefix>/voltage`` (V) and
  ``<relay_prefix>/current`` (A, positive = discharge) and
  ``sensor_msgs/Temperature`` ``<relay_prefix>/temperature`` (°C) from the ESP32 +
  INA260 relay. Float64 has no stamp, so every relay sample is timed by the node
  clock at reception.

Outputs: ``battery_predictor_msgs/PackState`` on ``pack_state_topic`` (reliable,
one per closed averaging window, plus stale states while the input is stale) and
``diagnostic_msgs/DiagnosticArray`` on ``/diagnostics`` every
``diagnostics_period_s`` (OK / WARN stale / ERROR invalid, with rejection
counts). Validation, windows and staleness are :mod:`battery_predictor.monitor.core`.

Time is the node's ROS clock (``use_sim_time`` follows ``/clock``, as a replay publishes it).
"""

from __future__ import annotations

import math
import threading

from battery_predictor_msgs.msg import PackState
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import BatteryState, Temperature
from std_msgs.msg import Float64

from battery_predictor.config import resolve_params_file
from battery_predictor.conventions import battery_state_current_to_internal, celsius_to_kelvin
from battery_predictor.monitor.core import STYLES, BatteryMonitor, MonitorConfig, PackSnapshot
from battery_predictor.nodes._params import declare_float, declare_str, reject_undeclared
from battery_predictor.nodes._sync import TimerProbe
from battery_predictor.nodes.messages import pack_state_msg, stamp_to_s

#: QoS of the PackState output (reliable; deep enough for a fast replay).
PACK_STATE_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
#: QoS of /diagnostics (the ROS default).
DIAGNOSTICS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class BatteryMonitorNode(Node):
    """The battery monitor node.

    Parameters
    ----------
    node_name : str
        Node name (the params file's top-level key).
    sensor_qos : QoSProfile
        QoS of the input subscriptions (default: ``qos_profile_sensor_data``).
    **kwargs
        Passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``, ``cli_args``...).
    """

    def __init__(self, node_name: str = "battery_monitor", *, sensor_qos: QoSProfile = qos_profile_sensor_data,
                 **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self.config, topics = self._declare_parameters()
        reject_undeclared(self)
        self._check_against_pack()
        self.monitor = BatteryMonitor(self.config)
        self._lock = threading.Lock()
        #: Messages received per input (for lock-step replays and tests).
        self.received: dict[str, int] = {}
        self.states_published = 0
        self.diagnostics_published = 0

        group = MutuallyExclusiveCallbackGroup()  # the monitor core is not thread-safe: one callback at a time
        self.pack_state_pub = self.create_publisher(PackState, topics["pack_state"], PACK_STATE_QOS)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, topics["diagnostics"], DIAGNOSTICS_QOS)
        if self.config.input_style == "battery_state":
            self.create_subscription(BatteryState, topics["battery_state"], self._on_battery_state, sensor_qos,
                                     callback_group=group)
            self.input_topics = {"battery_state": topics["battery_state"]}
        else:
            prefix = topics["relay_prefix"].rstrip("/")
            self.input_topics = {"voltage": f"{prefix}/voltage", "current": f"{prefix}/current",
                                 "temperature": f"{prefix}/temperature"}
            self.create_subscription(Float64, self.input_topics["voltage"], self._on_voltage, sensor_qos,
                                     callback_group=group)
            self.create_subscription(Float64, self.input_topics["current"], self._on_current, sensor_qos,
                                     callback_group=group)
            self.create_subscription(Temperature, self.input_topics["temperature"], self._on_temperature, sensor_qos,
                                     callback_group=group)
        self.tick_probe = TimerProbe(self.get_clock())
        self.tick_timer = self.create_timer(self._diagnostics_period_s, self.tick_probe.wrap(self._on_tick),
                                            callback_group=group)
        self.tick_probe.timer = self.tick_timer
        self.get_logger().info(
            f"monitoring {self.config.input_style} input ({', '.join(self.input_topics.values())}), "
            f"{self.config.window_s:g} s windows, stale after {self.config.stale_after_s:g} s, "
            f"voltage {self.config.min_voltage_v:g}..{self.config.max_voltage_v:g} V")

    # ------------------------------------------------------------ parameters
    def _declare_parameters(self) -> tuple[MonitorConfig, dict[str, str]]:
        style = declare_str(self, "input_style", "battery_state",
                            "Input topics: sensor_msgs/BatteryState (Ranger SDK bridge) or the ESP32 + INA260 "
                            "relay's separate voltage / current / temperature topics.", STYLES)
        topics = {
            "battery_state": declare_str(self, "battery_state_topic", "/battery_state",
                                         "sensor_msgs/BatteryState topic (input_style battery_state)."),
            "relay_prefix": declare_str(self, "relay_prefix", "/battery",
                                        "Prefix of the relay topics <prefix>/voltage, <prefix>/current "
                                        "(std_msgs/Float64) and <prefix>/temperature (sensor_msgs/Temperature)."),
            "pack_state": declare_str(self, "pack_state_topic", "pack_state",
                                      "Output topic of the clean pack state (battery_predictor_msgs/PackState)."),
            "diagnostics": declare_str(self, "diagnostics_topic", "/diagnostics",
                                       "Output topic of diagnostic_msgs/DiagnosticArray."),
        }
        self.params_file = declare_str(
            self, "params_file", "",
            "Pack params file (bundled name or path) the voltage range must cover; checked at start-up. "
            "Empty: no check. A '/**' section can give the predictor's params_file to both nodes.")
        self.frame_id = declare_str(self, "frame_id", "battery", "frame_id of the published PackState headers.")
        self.hardware_id = declare_str(self, "hardware_id", "battery_pack", "hardware_id in the diagnostics.")
        self._diagnostics_period_s = declare_float(
            self, "diagnostics_period_s", 1.0,
            "Period of /diagnostics and of the staleness check, s (node clock).", 0.01, 3600.0)
        config = MonitorConfig(
            input_style=style,
            min_voltage_v=declare_float(self, "min_voltage_v", 0.0,
                                        "Lowest physically possible pack voltage, V; lower samples are rejected.",
                                        0.0, 1000.0),
            max_voltage_v=declare_float(self, "max_voltage_v", 100.0,
                                        "Highest physically possible pack voltage, V; higher samples are rejected.",
                                        0.0, 1000.0),
            max_discharge_current_a=declare_float(self, "max_discharge_current_a", 50.0,
                                                  "Largest plausible discharge current, A (positive = discharge).",
                                                  0.0, 10000.0),
            max_charge_current_a=declare_float(self, "max_charge_current_a", 50.0,
                                               "Largest plausible charge current, A (a magnitude).", 0.0, 10000.0),
            min_temperature_k=float(celsius_to_kelvin(declare_float(
                self, "min_temperature_c", -40.0, "Lowest plausible pack temperature, degC.", -273.0, 500.0))),
            max_temperature_k=float(celsius_to_kelvin(declare_float(
                self, "max_temperature_c", 85.0, "Highest plausible pack temperature, degC.", -273.0, 500.0))),
            window_s=declare_float(self, "window_s", 5.0, "Averaging window, s.", 0.01, 3600.0),
            stale_after_s=declare_float(self, "stale_after_s", 15.0,
                                        "Input is stale when no valid voltage/current sample arrived for this long, s.",
                                        0.01, 86400.0),
            late_allowance_s=declare_float(self, "late_allowance_s", 1.0,
                                           "A window with no later sample is closed this long after its end, s.",
                                           0.0, 3600.0),
            max_future_s=declare_float(self, "max_future_s", 2.0,
                                       "Samples stamped further ahead of the node clock are rejected, s.",
                                       0.0, 3600.0),
            error_hold_s=declare_float(self, "error_hold_s", 10.0,
                                       "Diagnostics stay at ERROR this long after an invalid sample, s.",
                                       0.0, 86400.0),
        )
        return config, topics

    def _check_against_pack(self) -> None:
        """Refuse to start when ``params_file`` is given and its pack's voltage window is outside the range."""
        if not self.params_file:
            return
        from battery_predictor.params import load_params
        from battery_predictor.params_checks import check_monitor_range

        params = load_params(resolve_params_file(self.params_file))
        check_monitor_range(self.config.min_voltage_v, self.config.max_voltage_v, params,
                            f"parameters of node '{self.get_name()}'")

    # --------------------------------------------------------------- helpers
    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds / 1e9

    def _count(self, name: str) -> None:
        with self._lock:
            self.received[name] = self.received.get(name, 0) + 1

    def _publish(self, snapshots) -> None:
        for snap in snapshots:
            self._publish_one(snap)

    def _publish_one(self, snap: PackSnapshot) -> None:
        self.pack_state_pub.publish(pack_state_msg(snap, self.frame_id))
        with self._lock:
            self.states_published += 1

    # ------------------------------------------------------------- callbacks
    def _on_battery_state(self, msg: BatteryState) -> None:
        now = self._now_s()
        stamp = stamp_to_s(msg.header.stamp)
        if stamp == 0.0:
            stamp = now
        temp_c = float(msg.temperature)
        temp_k = float(celsius_to_kelvin(temp_c)) if not math.isnan(temp_c) else math.nan
        verdict = self.monitor.add_sample(stamp, float(msg.voltage),
                                          float(battery_state_current_to_internal(float(msg.current))), temp_k, now,
                                          [float(v) for v in msg.cell_voltage])
        self._publish(verdict.snapshots)
        self._count("battery_state")

    def _on_voltage(self, msg: Float64) -> None:
        now = self._now_s()
        self._publish(self.monitor.add_voltage(now, float(msg.data), now).snapshots)
        self._count("voltage")

    def _on_current(self, msg: Float64) -> None:
        now = self._now_s()
        self._publish(self.monitor.add_current(now, float(msg.data), now).snapshots)
        self._count("current")

    def _on_temperature(self, msg: Temperature) -> None:
        now = self._now_s()
        self._publish(self.monitor.add_temperature(now, float(celsius_to_kelvin(float(msg.temperature))),
                                                   now).snapshots)
        self._count("temperature")

    def _on_tick(self) -> None:
        now = self._now_s()
        self._publish(self.monitor.tick(now))
        self.diagnostics_pub.publish(self.diagnostics(now))
        with self._lock:
            self.diagnostics_published += 1

    def diagnostics(self, now_s: float) -> DiagnosticArray:
        """The present health as a DiagnosticArray (one status)."""
        status = self.monitor.status(now_s)
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [DiagnosticStatus(
            level=bytes([status.level]), name=f"{self.get_name()}: battery input", message=status.message,
            hardware_id=self.hardware_id, values=[KeyValue(key=k, value=v) for k, v in status.key_values()])]
        return array

    # ------------------------------------------------------------- lock step
    def idle(self, now_ns: int) -> bool:
        """True when the tick timer has nothing due or in flight at ``now_ns`` (see :mod:`._sync`)."""
        return self.tick_probe.idle(now_ns)
