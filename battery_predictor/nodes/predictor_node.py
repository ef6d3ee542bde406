"""``predictor``: remaining runtime on ``/remaining_runtime``; ``/can_accept_route``, ``/feasible_tasks``, ``/plan_route``.

A thin adapter around :class:`battery_predictor.prediction.core.PredictorCore`
(the fitted pack model from ``params_file``, the output of ``fit``):

* ``PackState`` (from ``battery_monitor``) -> :meth:`PredictorCore.update_state`;
  a state flagged ``stale`` by the monitor is not fed to the model and makes
  every answer invalid/rejected until a fresh state arrives.
* every ``runtime_period_s`` (node clock) -> :meth:`PredictorCore.remaining_runtime`
  -> ``battery_predictor_msgs/RemainingRuntime`` (stamp = the pack state it is based on).
* ``can_accept_route`` (``battery_predictor_msgs/CanAcceptRoute``) ->
  :meth:`PredictorCore.can_accept_route`. Invalid requests, unknown or stale
  state and model failures give ``accepted = false`` with a reason; the
  callback never raises.
* ``feasible_tasks`` (``FeasibleTasks``, the information robot) and ``plan_route``
  (``PlanRoute``, the luggage robot) -> :class:`~battery_predictor.prediction.station_services.StationServices`
  with the route core; the maps come from ``station_file`` / ``task_map_file``. Malformed
  requests are answered with the reason, never an exception.

Threading: four mutually exclusive callback groups -- pack states, the runtime
timer (the ~0.1 s model run), ``can_accept_route``, and the station services
(``feasible_tasks``, ``plan_route``: up to ~2 s for 100 tasks) -- so with a
:class:`~.executor.StartedMultiThreadedExecutor` a route is answered while a
runtime update or a station-service answer runs. The core is thread-safe and caches its SOC calibration,
which the pack-state callback computes as each state arrives (``PredictorCore.precalibrate``), so
by default the service shares the runtime's model and reuses that calibration;
``separate_route_model`` gives the service a model of its own instead (one model
solves one simulation at a time). ``/diagnostics`` carries the model status, the runtime
update time and the service latency (the route callback's own time: last, max, p50, p95 of the last 1000).

Time is the node's ROS clock: staleness is ``now - stamp of the last pack state``
on the same time base as the monitor's stamps (``use_sim_time`` in a replay).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque

from battery_predictor_msgs.msg import PackState, RemainingRuntime
from battery_predictor_msgs.srv import CanAcceptRoute, FeasibleTasks, PlanRoute
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from battery_predictor.config import resolve_params_file
from battery_predictor.errors import BatteryPredictorError, ParamsError
from battery_predictor.nodes._params import (
    declare_bool,
    declare_config_fields,
    declare_float,
    declare_str,
    reject_undeclared,
)
from battery_predictor.nodes._sync import TimerProbe
from battery_predictor.nodes.messages import (
    fill_feasible_tasks_response,
    fill_plan_route_response,
    fill_route_response,
    pack_state_min_cell_voltage_v,
    plan_request,
    remaining_runtime_msg,
    route_sections,
    stamp_to_s,
    task_policy,
    tasks_from_msgs,
)
from battery_predictor.nodes.predictor_parameters import PREDICTOR_PARAMETERS
from battery_predictor.params_checks import check_node_voltages
from battery_predictor.prediction.core import (
    STATUS_MODEL_FAILED,
    STATUS_STALE_INPUT,
    PredictorConfig,
    PredictorCore,
    RuntimeStatus,
)
from battery_predictor.prediction.pack_model import FALLBACK_PREFIX
from battery_predictor.prediction.planning import RoutePlan
from battery_predictor.prediction.route import RouteDecision, rejected
from battery_predictor.prediction.station_services import StationServices, StationServicesConfig
from battery_predictor.prediction.tasks import TaskPlan, invalid_plan

#: A pack state this much older than the latest one restarts the predictor (time base restarted), s.
TIME_BACK_RESET_S = 60.0
#: QoS of the PackState input (reliable, deep enough for a fast replay).
PACK_STATE_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
#: QoS of /remaining_runtime and /diagnostics.
OUTPUT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


class PredictorNode(Node):
    """The predictor node.

    Parameters
    ----------
    node_name : str
        Node name (the params file's top-level key).
    core : PredictorCore, optional
        An already built core (tests, benchmarks); default: built from the parameters.
    **kwargs
        Passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``, ``cli_args``...).
    """

    def __init__(self, node_name: str = "predictor", *, core: PredictorCore | None = None, **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self.config, topics, runtime_period_s = self._declare_parameters()
        self.services_config = self._declare_station_parameters(topics)
        reject_undeclared(self)
        t0 = time.perf_counter()
        self.core = core if core is not None else PredictorCore(self.config)
        if core is None and self.core.runner is None:
            raise ParamsError(f"{self.get_name()}: no usable pack model: {self.core.model_error}")
        if self.core.params is not None:
            check_node_voltages(f"parameters of node '{self.get_name()}'", self.core.params,
                                {"cutoff_voltage_v": self.config.cutoff_voltage_v,
                                 "route_min_voltage_v": self.config.route_min_voltage_v})
        # Optionally the service gets a pack model of its own so a route answer never waits for a runtime
        # update (each model solves one simulation at a time). A given core serves both, and so does the
        # runtime's when routes need no model (no route threshold, or no model at all).
        separate = (self._separate_route_model and core is None and self.core.runner is not None
                    and math.isfinite(self.core.route_min_voltage_v))
        self.route_core = PredictorCore(self.config, params=self.core.params) if separate else self.core
        if self.core.runner is None:
            self.get_logger().error(f"no usable pack model: {self.core.model_error}")
        else:
            route = (f"route threshold {self.core.route_min_voltage_v:.2f} V at {self.core.standstill_current_a:.2f} A"
                     if math.isfinite(self.core.route_min_voltage_v) else "no route threshold (routes are rejected)")
            self.get_logger().info(f"pack model {self.core.params.name} from {self.core.params.source} loaded in "
                                   f"{time.perf_counter() - t0:.1f} s on {self.core.model_backend}; cut-off "
                                   f"{self.core.cutoff_voltage_v:.2f} V, {route}")
            if self.core.model_backend.startswith(FALLBACK_PREFIX):
                self.get_logger().warning(f"the SPM engine does not cover these params, answers come from PyBaMM "
                                          f"stepping (about 100x slower): {self.core.model_backend}")
        for warm in {id(self.core): self.core, id(self.route_core): self.route_core}.values():
            self._compile_route_kernel(warm)
        self.station_services = StationServices(self.services_config)
        self._lock = threading.Lock()
        self._monitor_stale = False
        self._monitor_stale_since_s = math.nan
        self.states_received = 0
        self.runtimes_published = 0
        self.routes_answered = 0
        self.tasks_answered = 0
        self.plans_answered = 0
        #: Wall-clock durations (s) of the last runtime updates and route answers.
        self.runtime_update_s: deque[float] = deque(maxlen=1000)
        self.route_latency_s: deque[float] = deque(maxlen=1000)
        self.last_runtime: RuntimeStatus | None = None

        self.state_group = MutuallyExclusiveCallbackGroup()
        self.runtime_group = MutuallyExclusiveCallbackGroup()
        self.service_group = MutuallyExclusiveCallbackGroup()
        #: feasible_tasks and plan_route (up to ~2 s for 100 tasks): a group of their own, so a
        #: can_accept_route answer never waits for them.
        self.station_group = MutuallyExclusiveCallbackGroup()
        self.create_subscription(PackState, topics["pack_state"], self._on_pack_state, PACK_STATE_QOS,
                                 callback_group=self.state_group)
        self.runtime_pub = self.create_publisher(RemainingRuntime, topics["remaining_runtime"], OUTPUT_QOS)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, topics["diagnostics"], OUTPUT_QOS)
        self.route_service = self.create_service(CanAcceptRoute, topics["can_accept_route"], self._on_can_accept_route,
                                                 callback_group=self.service_group)
        self.tasks_service = self.create_service(FeasibleTasks, topics["feasible_tasks"], self._on_feasible_tasks,
                                                 callback_group=self.station_group)
        self.plan_service = self.create_service(PlanRoute, topics["plan_route"], self._on_plan_route,
                                                callback_group=self.station_group)
        self.runtime_probe = TimerProbe(self.get_clock())
        self.runtime_timer = self.create_timer(runtime_period_s, self.runtime_probe.wrap(self._on_runtime_timer),
                                               callback_group=self.runtime_group)
        self.runtime_probe.timer = self.runtime_timer

    # ------------------------------------------------------------ parameters
    def _declare_parameters(self) -> tuple[PredictorConfig, dict[str, str], float]:
        topics = {
            "pack_state": declare_str(self, "pack_state_topic", "pack_state",
                                      "Input: clean pack state from battery_monitor."),
            "remaining_runtime": declare_str(self, "remaining_runtime_topic", "remaining_runtime",
                                             "Output: battery_predictor_msgs/RemainingRuntime."),
            "can_accept_route": declare_str(self, "can_accept_route_service", "can_accept_route",
                                            "Service: battery_predictor_msgs/CanAcceptRoute."),
            "diagnostics": declare_str(self, "diagnostics_topic", "/diagnostics",
                                       "Output topic of diagnostic_msgs/DiagnosticArray."),
        }
        self.frame_id = declare_str(self, "frame_id", "battery", "frame_id of the published headers.")
        self._separate_route_model = declare_bool(
            self, "separate_route_model", False,
            "Give the can_accept_route service a pack model of its own, so a route answer never waits for a "
            "runtime update; it then calibrates the state itself instead of reusing the runtime update's "
            "calibration (false: shared model, less work per answer; see benchmarks/ros_latency.py).")
        runtime_period_s = declare_float(self, "runtime_period_s", 10.0,
                                         "Period of the remaining-runtime update and of /remaining_runtime, s "
                                         "(node clock).", 0.01, 86400.0)
        config = PredictorConfig(**declare_config_fields(self, PREDICTOR_PARAMETERS, PredictorConfig))
        return config, topics, runtime_period_s

    def _declare_station_parameters(self, topics: dict[str, str]) -> StationServicesConfig:
        topics["feasible_tasks"] = declare_str(self, "feasible_tasks_service", "feasible_tasks",
                                               "Service: battery_predictor_msgs/FeasibleTasks (information robot).")
        topics["plan_route"] = declare_str(self, "plan_route_service", "plan_route",
                                           "Service: battery_predictor_msgs/PlanRoute (luggage robot).")
        return StationServicesConfig(
            station_file=resolve_params_file(declare_str(
                self, "station_file", "", "Station graph of the luggage robot for plan_route (nodes, edges of "
                "segments with length and slope, optional node positions); empty = the bundled "
                "minden_station.yaml.")),
            task_map_file=resolve_params_file(declare_str(
                self, "task_map_file", "", "Map of the information robot for feasible_tasks (same format); empty = "
                "the bundled minden_information_map.yaml.")),
            task_usage_file=resolve_params_file(declare_str(
                self, "task_usage_file", "", "Usage model with the information robot's task currents and walking "
                "speed; empty = the bundled temi_usage.yaml.")),
            charger_node=declare_str(self, "charger_node", "charger", "Node of the charger on both maps."),
            route_currents_file=self.config.route_currents_file,
        )

    # --------------------------------------------------------------- helpers
    def _compile_route_kernel(self, core: PredictorCore) -> None:
        """Compile the engine's kernels at start-up, so the first route answer and runtime update do not.

        The engine answers a route with its fused compiled kernel (``EnginePack.run_end``) and a runtime
        update with the compiled two-pass pieces (``EnginePack.run``), compiled on first use (seconds,
        holding the GIL); PyBaMM stepping has nothing to compile.
        """
        warm_up = getattr(core.runner, "warm_up", None)
        if warm_up is None:
            return
        t0 = time.perf_counter()
        try:
            warm_up(core.default_temperature_k)
        except BatteryPredictorError as exc:
            self.get_logger().warning(f"route kernel warm-up failed (the first route answer compiles it): {exc}")
            return
        self.get_logger().debug(f"route kernel ready in {time.perf_counter() - t0:.1f} s")

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds / 1e9

    def _stale_reason(self) -> str | None:
        with self._lock:
            if not self._monitor_stale:
                return None
            since = self._monitor_stale_since_s
        return f"battery monitor reports stale input (since {since:.1f} s on the node clock)"

    # ------------------------------------------------------------- callbacks
    def _restart_if_time_went_back(self, stamp: float) -> None:
        """A pack state much older than the latest one means the time base restarted (a bag played again):
        start over with fresh cores, else every new state would be ignored as out of order."""
        latest = self.core.latest_state()
        if latest is None or stamp >= latest[0] - TIME_BACK_RESET_S:
            return
        self.get_logger().warning(f"pack state time went back by {latest[0] - stamp:.1f} s (bag restarted?): "
                                  "starting over")
        shared = self.route_core is self.core
        self.core = PredictorCore(self.config, params=self.core.params)
        self.route_core = self.core if shared else PredictorCore(self.config, params=self.core.params)

    def _on_pack_state(self, msg: PackState) -> None:
        stamp = stamp_to_s(msg.header.stamp)
        self._restart_if_time_went_back(stamp)
        if msg.stale:
            with self._lock:
                if not self._monitor_stale:
                    self._monitor_stale_since_s = stamp
                self._monitor_stale = True
        else:
            with self._lock:
                self._monitor_stale = False
            for core in {id(self.core): self.core, id(self.route_core): self.route_core}.values():
                core.update_state(stamp, float(msg.voltage_v), float(msg.current_a), float(msg.temperature_k),
                                  float(msg.peak_current_a), pack_state_min_cell_voltage_v(msg))
                core.precalibrate()  # here, so a route answer finds the state calibrated
        with self._lock:
            self.states_received += 1

    def runtime_status(self, now_s: float) -> RuntimeStatus:
        """The remaining runtime at ``now_s`` (never raises)."""
        stale = self._stale_reason()
        if stale is not None:
            return RuntimeStatus(now_s, math.nan, math.nan, math.nan, math.nan, self.core.cutoff_voltage_v, False,
                                 STATUS_STALE_INPUT, stale)
        try:
            return self.core.remaining_runtime(now_s)
        except Exception as exc:  # noqa: BLE001 - the core should not raise; never let the node die of it
            return RuntimeStatus(now_s, math.nan, math.nan, math.nan, math.nan, self.core.cutoff_voltage_v, False,
                                 STATUS_MODEL_FAILED, f"internal error: {type(exc).__name__}: {exc}")

    def _on_runtime_timer(self) -> None:
        t0 = time.perf_counter()
        status = self.runtime_status(self._now_s())
        elapsed = time.perf_counter() - t0
        self.runtime_pub.publish(remaining_runtime_msg(status, self.frame_id))
        with self._lock:
            self.runtime_update_s.append(elapsed)
            self.last_runtime = status
            self.runtimes_published += 1
        self.diagnostics_pub.publish(self.diagnostics())

    def decide_route(self, request: CanAcceptRoute.Request) -> RouteDecision:
        """The decision for a request at the present node time (never raises)."""
        threshold = self.route_core.route_min_voltage_v
        try:
            sections = route_sections(request.sections)
        except BatteryPredictorError as exc:
            return rejected(f"invalid request: {exc}", threshold)
        except Exception as exc:  # noqa: BLE001 - malformed input must never take the service down
            return rejected(f"invalid request: {type(exc).__name__}: {exc}", threshold)
        stale = self._stale_reason()
        if stale is not None:
            return rejected(f"state unknown: {stale}", threshold)
        try:
            return self.route_core.can_accept_route(sections, self._now_s(),
                                              starts_away_from_charger=bool(request.starts_away_from_charger),
                                              ends_away_from_charger=bool(request.ends_away_from_charger))
        except Exception as exc:  # noqa: BLE001
            return rejected(f"model failed: internal error: {type(exc).__name__}: {exc}", threshold)

    def _on_can_accept_route(self, request: CanAcceptRoute.Request,
                             response: CanAcceptRoute.Response) -> CanAcceptRoute.Response:
        t0 = time.perf_counter()
        fill_route_response(response, self.decide_route(request))
        with self._lock:
            self.route_latency_s.append(time.perf_counter() - t0)
            self.routes_answered += 1
        return response

    def answer_tasks(self, request: FeasibleTasks.Request) -> TaskPlan:
        """The feasible-tasks answer at the present node time (never raises)."""
        core = self.route_core
        try:
            policy = task_policy(request.policy)
            tasks = tasks_from_msgs(request.tasks)
        except Exception as exc:  # noqa: BLE001 - malformed input must never take the service down
            return invalid_plan([], "independent", f"invalid request: {exc}", core.cutoff_voltage_v)
        stale = self._stale_reason()
        if stale is not None:
            return invalid_plan(tasks, policy, f"state unknown: {stale}", core.cutoff_voltage_v)
        return self.station_services.feasible_tasks(core, tasks, str(request.location), policy, self._now_s())

    def _on_feasible_tasks(self, request: FeasibleTasks.Request,
                           response: FeasibleTasks.Response) -> FeasibleTasks.Response:
        fill_feasible_tasks_response(response, self.answer_tasks(request))
        with self._lock:
            self.tasks_answered += 1
        return response

    def answer_plan(self, request: PlanRoute.Request) -> RoutePlan:
        """The planned route at the present node time (never raises)."""
        try:
            job = plan_request(request)
        except Exception as exc:  # noqa: BLE001
            return RoutePlan("", 0.0, None, (), f"invalid request: {exc}")
        stale = self._stale_reason()
        if stale is not None:
            return RoutePlan("", 0.0, None, (), f"state unknown: {stale}")
        return self.station_services.plan_route(self.route_core, job, self._now_s())

    def _on_plan_route(self, request: PlanRoute.Request, response: PlanRoute.Response) -> PlanRoute.Response:
        fill_plan_route_response(response, self.answer_plan(request), self.route_core.route_min_voltage_v)
        with self._lock:
            self.plans_answered += 1
        return response

    def diagnostics(self) -> DiagnosticArray:
        """Model status, last runtime answer, runtime update time and service latency."""
        with self._lock:
            last = self.last_runtime
            updates = list(self.runtime_update_s)
            latencies = list(self.route_latency_s)
            values = [("states_received", str(self.states_received)),
                      ("runtimes_published", str(self.runtimes_published)),
                      ("routes_answered", str(self.routes_answered)),
                      ("tasks_answered", str(self.tasks_answered)), ("plans_answered", str(self.plans_answered))]
        if self.core.runner is None:
            level, message = DiagnosticStatus.ERROR, f"no usable pack model: {self.core.model_error}"
        elif last is not None and not last.valid:
            level, message = DiagnosticStatus.WARN, f"remaining runtime invalid: {last.reason}"
        else:
            level, message = DiagnosticStatus.OK, last.reason if last is not None else "waiting for pack state"
        if updates:
            values += [("runtime_update_last_s", f"{updates[-1]:.4f}"), ("runtime_update_max_s", f"{max(updates):.4f}")]
        if latencies:
            ordered = sorted(latencies)
            values += [("route_latency_last_s", f"{latencies[-1]:.4f}"),
                       ("route_latency_max_s", f"{ordered[-1]:.4f}"),
                       ("route_latency_p50_s", f"{ordered[len(ordered) // 2]:.4f}"),
                       ("route_latency_p95_s", f"{ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))]:.4f}")]
        if self.core.params is not None:
            values += [("params_file", str(self.core.params.source)), ("pack_model", self.core.model_backend)]
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [DiagnosticStatus(level=level, name=f"{self.get_name()}: pack model", message=message,
                                         hardware_id="battery_pack",
                                         values=[KeyValue(key=k, value=v) for k, v in values])]
        return array

    # ------------------------------------------------------------- lock step
    def idle(self, now_ns: int) -> bool:
        """True when the runtime timer has nothing due or in flight at ``now_ns`` (see :mod:`._sync`)."""
        return self.runtime_probe.idle(now_ns)
