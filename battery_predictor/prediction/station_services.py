"""The station's services without ROS: feasible tasks and route planning, configured from params.

The predictor node copies its parameters into :class:`StationServicesConfig`, builds
:class:`StationServices` once at start-up (the maps and the usage model are read there, so a bad
file stops the node with one line) and calls :meth:`StationServices.feasible_tasks` and
:meth:`StationServices.plan_route` from its service callbacks with its
:class:`~battery_predictor.prediction.core.PredictorCore`. Another station is another pair of
YAML files (``station_file`` for the luggage robot's graph, ``task_map_file`` for the information
robot's map).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from battery_predictor.config import default_params_file, read_yaml_mapping
from battery_predictor.errors import BatteryPredictorError, ParamsError
from battery_predictor.prediction.planning import PlanRequest, RoutePlan, RoutePlanner, plan_from_core
from battery_predictor.prediction.tasks import Task, TaskLoads, TaskPlan, feasible_tasks, invalid_plan
from battery_predictor.profiles.station import load_station
from battery_predictor.profiles.temi import default_config_path, load_usage_config

if TYPE_CHECKING:
    from battery_predictor.prediction.core import PredictorCore

#: Shipped information-robot map.
DEFAULT_TASK_MAP_FILE = "minden_information_map.yaml"


@dataclass(frozen=True)
class StationServicesConfig:
    """Settings of the station services (copied from ROS parameters by the node).

    Attributes
    ----------
    station_file : str
        Station graph of the luggage robot (``/plan_route``); "" = the shipped ``minden_station.yaml``.
    task_map_file : str
        Map of the information robot (``/feasible_tasks``); "" = the shipped
        ``minden_information_map.yaml``.
    task_usage_file : str
        Usage model with the task currents and walking speed; "" = the shipped ``temi_usage.yaml``.
    charger_node : str
        Name of the charger's node on both maps.
    route_currents_file : str
        Per-(payload, slope) currents of the luggage robot (least-charge paths); "" = shipped.
    """

    station_file: str = ""
    task_map_file: str = ""
    task_usage_file: str = ""
    charger_node: str = "charger"
    route_currents_file: str = ""


class StationServices:
    """Maps, usage model and planners for both services (see the module docstring).

    Raises
    ------
    ParamsError
        When a file cannot be read or the charger is not a node of a map.
    """

    def __init__(self, config: StationServicesConfig) -> None:
        self.config = config
        try:
            self.station = load_station(config.station_file or None)
            self.task_map = load_station(config.task_map_file or default_params_file(DEFAULT_TASK_MAP_FILE))
            usage_path = config.task_usage_file or default_config_path()
            usage = load_usage_config(usage_path)
            speed_m_s = float(read_yaml_mapping(usage_path)[1]["navigation"]["speed_m_s"])
            currents = None
            if config.route_currents_file:
                from battery_predictor.profiles.ranger import load_ranger_currents

                currents = load_ranger_currents(config.route_currents_file)
            self.planner = RoutePlanner(self.station, config.charger_node, currents)
            self.task_map.check_node(config.charger_node)
        except BatteryPredictorError as exc:
            raise ParamsError(f"station services: {exc}") from None
        self.loads = TaskLoads.from_usage(usage, speed_m_s)
        #: Average load assumed for the remaining time when the present cycle has none yet, A.
        self.fallback_current_a = usage.expected_mean_current_a()

    def feasible_tasks(self, core: PredictorCore, tasks: Sequence[Task], location: str, policy: str, now_s: float) -> TaskPlan:
        """Answer ``/feasible_tasks`` from ``core``'s present state (never raises)."""
        try:
            return feasible_tasks(core, tasks, location, policy, now_s, self.task_map, self.config.charger_node,
                                  self.loads, self.fallback_current_a)
        except Exception as exc:  # noqa: BLE001 - an answer with the reason, never a dead service
            return invalid_plan(tasks, policy, f"model failed: internal error: {type(exc).__name__}: {exc}",
                                getattr(core, "cutoff_voltage_v", math.nan))

    def plan_route(self, core: PredictorCore, request: PlanRequest, now_s: float) -> RoutePlan:
        """Answer ``/plan_route`` from ``core``'s present state (never raises)."""
        try:
            return plan_from_core(core, self.planner, request, now_s)
        except Exception as exc:  # noqa: BLE001
            return RoutePlan("", 0.0, None, (), f"model failed: internal error: {type(exc).__name__}: {exc}")
