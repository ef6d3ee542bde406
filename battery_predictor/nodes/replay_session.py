"""A bag replayed into the real nodes, in one process: ``battery-predictor replay`` and the ROS tests.

:class:`ReplaySession` starts ``battery_monitor`` and ``predictor`` with
``use_sim_time`` (parameters from a ``node_name: ros__parameters:`` file plus
overrides), a :class:`~.bag_player_node.BagPlayerNode` and an
:class:`~.output_recorder_node.OutputRecorderNode`, all on one
:class:`~.executor.StartedMultiThreadedExecutor` (the production executor) spinning in a
background thread.

Playing a bag (:meth:`ReplaySession.play_until`) goes through its messages
grouped by log time; for every group it

1. waits for the wall time the rate asks for (``rate`` times faster than the bag;
   ``rate <= 0`` or ``inf`` = as fast as possible),
2. publishes ``/clock`` = the group's log time and waits until every node's clock
   shows it and the nodes' timers due at that time (monitor tick, runtime update)
   have run,
3. publishes the group's messages and waits until the monitor has taken them,
   the predictor has taken the resulting pack states and the recorder has
   recorded every output.

This *lock step* makes the outputs independent of the machine's speed (a slow
machine plays more slowly, it does not skip or reorder anything), so the
rate is an upper bound. Waiting polls counters with a timeout (``timeout_s``
per step); nothing sleeps for a tuned time.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from battery_predictor_msgs.srv import CanAcceptRoute
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from battery_predictor.errors import BagError, BatteryPredictorError
from battery_predictor.io.bags import RELAY_SUFFIXES
from battery_predictor.nodes.bag_player_node import BagPlayerNode
from battery_predictor.nodes.battery_monitor_node import BatteryMonitorNode
from battery_predictor.nodes.executor import StartedMultiThreadedExecutor
from battery_predictor.nodes.messages import stamp_to_s
from battery_predictor.nodes.output_recorder_node import OutputRecorderNode
from battery_predictor.nodes.predictor_node import PredictorNode
from battery_predictor.prediction.core import PredictorCore
from battery_predictor.replay import BagMessage, OutputBag, ReplayStream, RuntimePoint

_POLL_S = 0.0002


@dataclass(frozen=True)
class PlayStats:
    """What one :meth:`ReplaySession.play_until` call did."""

    steps: int
    messages: int
    bag_s: float
    wall_s: float


def _overrides(values: dict[str, Any]) -> list[Parameter]:
    return [Parameter(name, value=value) for name, value in values.items()]


class ReplaySession:
    """Nodes + player + recorder in one process, driven in lock step (see the module docstring).

    Parameters
    ----------
    stream : ReplayStream
        The bag's battery input.
    context : rclpy.context.Context, optional
        An initialised context (default: the global one).
    params_file : str, optional
        Node parameters (``battery_monitor:`` / ``predictor:`` ``ros__parameters`` layout).
    monitor_overrides, predictor_overrides : dict, optional
        Parameter values that win over ``params_file``.
    rate : float
        Bag seconds per wall second at most (``<= 0`` or ``inf``: as fast as possible).
    out_bag : OutputBag, optional
        Where the recorder writes the outputs.
    timeout_s : float
        Longest wait for the nodes in one step (a stuck node raises instead of hanging).
    predictor_core : PredictorCore, optional
        A prebuilt core (saves the model build when several sessions use the same pack).
    threads : int
        Executor threads.
    """

    def __init__(self, stream: ReplayStream, *, context: Context | None = None, params_file: str | None = None,
                 monitor_overrides: dict[str, Any] | None = None, predictor_overrides: dict[str, Any] | None = None,
                 rate: float = 1.0, out_bag: OutputBag | None = None, timeout_s: float = 60.0,
                 predictor_core: PredictorCore | None = None, threads: int = 4) -> None:
        self.stream = stream
        self.context = context
        self.rate = rate
        self.timeout_s = timeout_s
        self.out_bag = out_bag
        cli = ["--ros-args", "--params-file", str(params_file)] if params_file else None
        sim = {"use_sim_time": True}
        kw: dict[str, Any] = {"context": context}
        self._nodes: list[Node] = []
        try:
            self.monitor = BatteryMonitorNode(cli_args=cli, parameter_overrides=_overrides(
                {**(monitor_overrides or {}), **sim}), **kw)
            self._nodes.append(self.monitor)
            if self.monitor.config.input_style != stream.style:
                raise BagError(f"{stream.source}: the bag has {stream.style} topics but the monitor's input_style is "
                               f"{self.monitor.config.input_style} (use the node params of the robot that recorded it, "
                               f"set battery_monitor input_style: {stream.style} in a copy of them, or remake the bag "
                               f"with `battery-predictor bag from-csv --style {self.monitor.config.input_style}`)")
            self.predictor = PredictorNode(core=predictor_core, cli_args=cli, parameter_overrides=_overrides(
                {**(predictor_overrides or {}), **sim}), **kw)
            self._nodes.append(self.predictor)
            self._topic_map = self._map_topics()
            self.player = BagPlayerNode({self._topic_map[t]: m for t, m in stream.topics.items()}, **kw)
            self._nodes.append(self.player)
            self.outputs = {
                "pack_state": self.monitor.pack_state_pub.topic_name,
                "remaining_runtime": self.predictor.runtime_pub.topic_name,
                "diagnostics": self.monitor.diagnostics_pub.topic_name,
                "predictor_diagnostics": self.predictor.diagnostics_pub.topic_name,
            }
            recorded = {
                self.outputs["pack_state"]: "battery_predictor_msgs/msg/PackState",
                self.outputs["remaining_runtime"]: "battery_predictor_msgs/msg/RemainingRuntime",
                self.outputs["diagnostics"]: "diagnostic_msgs/msg/DiagnosticArray",
                self.outputs["predictor_diagnostics"]: "diagnostic_msgs/msg/DiagnosticArray",
            }
            self.recorder = OutputRecorderNode(recorded, bag=out_bag, **kw)
            self._nodes.append(self.recorder)
            self.client_node = Node("replay_route_client", **kw)
            self._nodes.append(self.client_node)
            self.route_client = self.client_node.create_client(CanAcceptRoute,
                                                               self.predictor.route_service.srv_name)
        except BaseException:
            for node in self._nodes:
                node.destroy_node()
            raise
        self.executor = StartedMultiThreadedExecutor(num_threads=threads, context=context)
        for node in self._nodes:
            self.executor.add_node(node)
        self._thread = threading.Thread(target=self._spin, name="replay-executor", daemon=True)
        self._spin_error: BaseException | None = None
        self._thread.start()
        self._position = 0  # index into the stream's steps already played
        self._steps = list(stream.steps())
        self._sim_sync_nodes = (self.monitor, self.predictor)
        self._wait(self._matched, "discovery of the replay's publishers and subscribers")

    # ----------------------------------------------------------------- setup
    def _spin(self) -> None:
        try:
            self.executor.spin()
        except BaseException as exc:  # noqa: BLE001 - reported by the waiting thread
            self._spin_error = exc

    def _map_topics(self) -> dict[str, str]:
        """Bag topic -> the monitor's input topic (the bag may use other names than the params)."""
        inputs = self.monitor.input_topics
        out = {}
        for topic in self.stream.topics:
            if self.stream.style == "battery_state":
                out[topic] = inputs["battery_state"]
            else:
                part = next((p for p, s in RELAY_SUFFIXES.items() if topic == self.stream.battery_topic + s), None)
                if part is None:
                    raise BagError(f"{self.stream.source}: unexpected relay topic {topic}")
                out[topic] = inputs[part]
        return out

    def _matched(self) -> bool:
        clock_subs = self.player.clock_pub.get_subscription_count() if self.player.clock_pub else 0
        return (self.player.matched() and clock_subs >= len(self._sim_sync_nodes)
                and self.monitor.pack_state_pub.get_subscription_count() >= 2
                and self.predictor.runtime_pub.get_subscription_count() >= 1
                and self.monitor.diagnostics_pub.get_subscription_count() >= 1
                and self.predictor.diagnostics_pub.get_subscription_count() >= 1
                and self.route_client.service_is_ready())

    def _wait(self, condition: Callable[[], bool], what: str) -> None:
        deadline = time.monotonic() + self.timeout_s
        while not condition():
            if self._spin_error is not None:
                raise BatteryPredictorError(f"replay: the executor stopped: {self._spin_error!r}")
            if time.monotonic() > deadline:
                raise BatteryPredictorError(f"replay: timed out after {self.timeout_s:g} s waiting for {what}")
            time.sleep(_POLL_S)

    # ------------------------------------------------------------------ play
    def _clocks_at(self, t_ns: int) -> bool:
        return all(n.get_clock().now().nanoseconds >= t_ns for n in self._sim_sync_nodes)

    def _idle_at(self, t_ns: int) -> bool:
        return self.monitor.idle(t_ns) and self.predictor.idle(t_ns) and self._outputs_recorded()

    def _inputs_taken(self) -> bool:
        sent = self.player.sent
        received = self.monitor.received
        names = self.monitor.input_topics
        by_topic = {topic: name for name, topic in names.items()}
        return all(received.get(by_topic[topic], 0) >= n for topic, n in sent.items())

    def _outputs_recorded(self) -> bool:
        rec = self.recorder
        return (self.predictor.states_received >= self.monitor.states_published
                and rec.count(self.outputs["pack_state"]) >= self.monitor.states_published
                and rec.count(self.outputs["remaining_runtime"]) >= self.predictor.runtimes_published
                and self._diagnostics_recorded())

    def _diagnostics_recorded(self) -> bool:
        mon, pred = self.outputs["diagnostics"], self.outputs["predictor_diagnostics"]
        n_mon, n_pred = self.monitor.diagnostics_published, self.predictor.runtimes_published
        if mon == pred:
            return self.recorder.count(mon) >= n_mon + n_pred
        return self.recorder.count(mon) >= n_mon and self.recorder.count(pred) >= n_pred

    def advance_clock(self, t_ns: int) -> None:
        """Publish ``/clock`` = ``t_ns`` and wait until the nodes have done what is due at that time."""
        self.player.publish_clock(t_ns)
        self._wait(lambda: self._clocks_at(t_ns), f"the nodes' clocks to reach {t_ns} ns")
        self._wait(lambda: self._idle_at(t_ns), f"the nodes to finish what is due at {t_ns} ns")

    def publish(self, messages: list[BagMessage]) -> None:
        """Publish bag messages (at the present clock) and wait until they and their consequences are handled."""
        for msg in messages:
            self.player.publish(BagMessage(msg.log_time_ns, self._topic_map[msg.topic], msg.msgtype, msg.data))
        self._wait(self._inputs_taken, "the monitor to take the published samples")
        self._wait(self._outputs_recorded, "the predictor and recorder to take the outputs")

    def play_until(self, end_ns: int | None = None, *, on_step: Callable[[int], None] | None = None) -> PlayStats:
        """Play the steps with log time <= ``end_ns`` (default: all) from where the last call stopped."""
        wall0 = time.monotonic()
        first_ns = None
        steps = messages = 0
        pace = self.rate if (self.rate > 0 and math.isfinite(self.rate)) else None
        while self._position < len(self._steps):
            t_ns, group = self._steps[self._position]
            if end_ns is not None and t_ns > end_ns:
                break
            if first_ns is None:
                first_ns = t_ns
            if pace is not None:
                delay = (t_ns - first_ns) / 1e9 / pace - (time.monotonic() - wall0)
                if delay > 0:
                    time.sleep(delay)
            self.advance_clock(t_ns)
            self.publish(group)
            self._position += 1
            steps += 1
            messages += len(group)
            if on_step is not None:
                on_step(t_ns)
        bag_s = 0.0 if first_ns is None else (self._steps[self._position - 1][0] - first_ns) / 1e9
        return PlayStats(steps, messages, bag_s, time.monotonic() - wall0)

    def flush(self) -> None:
        """Advance the clock past the last message by one window (+ the late allowance) so the last window closes."""
        if not self._steps:
            return
        cfg = self.monitor.config
        last_ns = self._steps[min(self._position, len(self._steps)) - 1][0]
        self.advance_clock(last_ns + round((cfg.window_s + cfg.late_allowance_s) * 1e9))

    def rewind(self) -> None:
        """Play from the first message again (the clock then jumps back, as with ``ros2 bag play --loop``)."""
        self._position = 0

    @property
    def finished(self) -> bool:
        """True when every message was played."""
        return self._position >= len(self._steps)

    def now_ns(self) -> int:
        """The replay's present ROS time (the monitor's clock)."""
        return self.monitor.get_clock().now().nanoseconds

    # --------------------------------------------------------------- queries
    def call_route(self, request: CanAcceptRoute.Request) -> CanAcceptRoute.Response:
        """Call ``can_accept_route`` over the middleware at the present (frozen) replay time."""
        future = self.route_client.call_async(request)
        self._wait(future.done, "the can_accept_route response")
        result = future.result()
        if result is None:
            raise BatteryPredictorError(f"can_accept_route failed: {future.exception()!r}")
        return result

    def runtime_points(self) -> list[RuntimePoint]:
        """Every published remaining runtime so far, on the recording time axis."""
        out = []
        for msg in self.recorder.snapshot(self.outputs["remaining_runtime"]):
            t_ns = round(stamp_to_s(msg.header.stamp) * 1e9)
            out.append(RuntimePoint(self.stream.recording_time_s(t_ns), float(msg.remaining_s), bool(msg.valid),
                                    int(msg.status), str(msg.reason), float(msg.remaining_p10_s),
                                    float(msg.remaining_p90_s), float(msg.cutoff_voltage_v)))
        return out

    def pack_states(self) -> list:
        """Every published PackState so far."""
        return self.recorder.snapshot(self.outputs["pack_state"])

    def diagnostics(self) -> list:
        """Every DiagnosticArray recorded so far (monitor and predictor)."""
        out = self.recorder.snapshot(self.outputs["diagnostics"])
        if self.outputs["predictor_diagnostics"] != self.outputs["diagnostics"]:
            out += self.recorder.snapshot(self.outputs["predictor_diagnostics"])
        return out

    # ----------------------------------------------------------------- close
    def close(self) -> None:
        """Stop the executor and destroy the nodes (the output bag is closed by its owner)."""
        self.executor.shutdown()
        self._thread.join(timeout=10.0)
        for node in self._nodes:
            node.destroy_node()
        self._nodes = []

    def __enter__(self) -> ReplaySession:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def default_output_dir(bag: str | Path) -> Path:
    """``<bag name>_replay`` next to the working directory (never inside the input bag)."""
    return Path.cwd() / f"{Path(bag).name.removesuffix('.mcap')}_replay"
