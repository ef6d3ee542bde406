"""Route planning for the luggage robot from where it stands (issue 14, item 3), without ROS.

The paper (5.2) decides predefined routes that start and end at the charger. Here the robot
is anywhere on the station graph (a node, or a position mapped to the nearest node): a job is
``start -> pickup`` (unloaded, loading at the pickup) ``-> dropoff`` (loaded, unloading at the
drop-off) ``-> charger`` (unloaded; left out when the request says the route ends away from
the charger). Each leg follows the shortest path of the station graph
(:meth:`~battery_predictor.profiles.station.Station.shortest_path`), and the route is decided by
the same function as ``/can_accept_route`` (:meth:`PredictorCore.can_accept_route`: the
measured-voltage check, the calibrated state, the simulated route, 46.31 V at 1.70 A for the
Ranger Mini), so a planned route is accepted exactly when that service would accept its
sections.

When the shortest route is rejected, alternatives are worked out, each with its own decision:

``least_charge_path``
    every leg on the path that draws the least charge with its payload (Dijkstra with the
    per-(payload, slope) mean currents as costs: steep climbs under load cost more than a
    longer flat detour); offered only when it differs from the shortest route. Decided like the
    shortest route.
``charge_first``
    drive (unloaded) to the charger, charge, then do the job from the charger. The drive to the
    charger is decided from the present state; the job is simulated from a rested pack at a
    given SOC, and the lowest SOC that lets the job end at or above the threshold is found by
    bisection (to :data:`SOC_TOLERANCE`, rounded up). Feasible when the drive to the charger is
    accepted and the job is feasible on a full pack. This is advice: the job itself is decided
    again when it is requested after charging.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from battery_predictor.errors import BatteryPredictorError, RequestError
from battery_predictor.prediction.route import RouteDecision
from battery_predictor.prediction.uncertainty import evaluate_route_at_risk
from battery_predictor.profiles.ranger import (
    DEFAULT_SPEED_M_S,
    DEFAULT_STANDSTILL_S,
    RangerCurrents,
    RouteSection,
    check_payload_kg,
    mean_current_a,
)
from battery_predictor.profiles.station import FLAT, UPHILL, Segment, Station, StationPath

if TYPE_CHECKING:
    from battery_predictor.prediction.core import PredictorCore

#: Kinds of planned routes.
SHORTEST = "shortest"
LEAST_CHARGE_PATH = "least_charge_path"
CHARGE_FIRST = "charge_first"
#: A position farther than this from every node is not mapped to one, m.
MAX_SNAP_M = 50.0
#: Longest node name accepted, characters.
MAX_NODE_CHARS = 64
#: Longest loading or unloading standstill, s.
MAX_STANDSTILL_S = 3600.0
#: Resolution of the charge-first SOC search.
SOC_TOLERANCE = 0.005


@dataclass(frozen=True)
class PlanRequest:
    """A job for the luggage robot.

    Attributes
    ----------
    start_node : str
        Where the robot stands (a node); ignored when ``use_position``.
    pickup, dropoff : str
        Nodes where the luggage is loaded and unloaded.
    payload_kg : float
        Luggage mass, kg (0-200).
    use_position : bool
        Map ``(x_m, y_m)`` to the nearest node instead of naming it; the distance to that node is
        driven first (unloaded, flat).
    x_m, y_m : float
        Position in the station graph's frame, m.
    ends_away_from_charger : bool
        False (default): the job ends with the drive back to the charger.
    loading_s, unloading_s : float
        Standstill at the pickup and the drop-off, s (0-3600).
    speed_m_s : float
        Driving speed, m/s (> 0).
    """

    start_node: str
    pickup: str
    dropoff: str
    payload_kg: float
    use_position: bool = False
    x_m: float = math.nan
    y_m: float = math.nan
    ends_away_from_charger: bool = False
    loading_s: float = DEFAULT_STANDSTILL_S
    unloading_s: float = DEFAULT_STANDSTILL_S
    speed_m_s: float = DEFAULT_SPEED_M_S

    def __post_init__(self) -> None:
        for attr in ("start_node", "pickup", "dropoff"):
            value = getattr(self, attr)
            if not isinstance(value, str):
                raise RequestError(f"{attr} must be a node name")
            if len(value) > MAX_NODE_CHARS:
                raise RequestError(f"{attr} is {len(value)} characters long (at most {MAX_NODE_CHARS})")
        try:
            check_payload_kg(self.payload_kg)
        except BatteryPredictorError as exc:
            raise RequestError(str(exc)) from None
        for attr in ("loading_s", "unloading_s"):
            value = float(getattr(self, attr))
            if not (math.isfinite(value) and 0.0 <= value <= MAX_STANDSTILL_S):
                raise RequestError(f"{attr} is {value!r} (must be 0..{MAX_STANDSTILL_S:.0f} s)")
        if not (math.isfinite(self.speed_m_s) and 0.0 < self.speed_m_s <= 5.0):
            raise RequestError(f"speed_m_s is {self.speed_m_s!r} (must be > 0 and <= 5 m/s)")
        if self.use_position and not (math.isfinite(self.x_m) and math.isfinite(self.y_m)):
            raise RequestError(f"position ({self.x_m}, {self.y_m}) is not finite")
        if self.pickup == self.dropoff:
            raise RequestError(f"pickup and drop-off are both {self.pickup!r}")


@dataclass(frozen=True)
class PlannedRoute:
    """One route through the station and its decision.

    Attributes
    ----------
    kind : str
        :data:`SHORTEST`, :data:`LEAST_CHARGE_PATH` or :data:`CHARGE_FIRST`.
    nodes : tuple of str
        Nodes visited, in order (for ``charge_first``: to the charger, then the job).
    sections : tuple of RouteSection
        What is driven (for ``charge_first``: the job from the charger).
    decision : RouteDecision
        The decision (for ``charge_first``: the job on a full pack).
    feasible : bool
        Whether this route can be driven (for ``charge_first``: after charging).
    required_soc : float
        ``charge_first``: lowest SOC at the charger that lets the job end at or above the
        threshold (NaN otherwise, or when not found).
    reason : str
        One line.
    """

    kind: str
    nodes: tuple[str, ...]
    sections: tuple[RouteSection, ...]
    decision: RouteDecision
    feasible: bool
    required_soc: float = math.nan
    reason: str = ""

    @property
    def length_m(self) -> float:
        """Distance driven, m."""
        return sum(s.length_m for s in self.sections)


@dataclass(frozen=True)
class RoutePlan:
    """The answer to a plan request.

    Attributes
    ----------
    start_node : str
        The node the route starts at ("" when not resolved).
    approach_m : float
        Distance from the given position to ``start_node``, m (0 when a node was named).
    route : PlannedRoute or None
        The shortest route and its decision (None for a request that names no route).
    alternatives : tuple of PlannedRoute
        Worked out when the shortest route is rejected.
    reason : str
        One line.
    """

    start_node: str
    approach_m: float
    route: PlannedRoute | None
    alternatives: tuple[PlannedRoute, ...]
    reason: str

    @property
    def accepted(self) -> bool:
        """True when the shortest route is accepted."""
        return self.route is not None and self.route.decision.accepted


#: ``decide(sections, starts_away_from_charger, ends_away_from_charger) -> RouteDecision`` from the present state.
Decide = Callable[[Sequence[RouteSection], bool, bool], RouteDecision]
#: ``from_soc(sections, soc) -> RouteDecision``: a route from a rested pack at ``soc``.
FromSoc = Callable[[Sequence[RouteSection], float], RouteDecision]


class RoutePlanner:
    """Plans jobs on a station graph (see the module docstring).

    Parameters
    ----------
    station : Station
        The station graph (params YAML, e.g. ``minden_station.yaml``).
    charger : str
        The charger's node.
    currents : RangerCurrents, optional
        Per-(payload, slope) currents for the least-charge paths (default: the shipped ones).
    """

    def __init__(self, station: Station, charger: str = "charger", currents: RangerCurrents | None = None) -> None:
        self.station = station
        self.charger = station.check_node(charger)
        self.currents = currents

    # ------------------------------------------------------------- routes
    def resolve_start(self, request: PlanRequest) -> tuple[str, float]:
        """(start node, distance driven to reach it in m).

        Raises
        ------
        RequestError
            For an unknown node, a station without positions, or a position too far from every node.
        """
        if request.use_position:
            try:
                node, distance = self.station.nearest_node(request.x_m, request.y_m)
            except BatteryPredictorError as exc:
                raise RequestError(str(exc)) from None
            if distance > MAX_SNAP_M:
                raise RequestError(f"position ({request.x_m:.1f}, {request.y_m:.1f}) m is {distance:.0f} m from the "
                                   f"nearest node {node!r} (at most {MAX_SNAP_M:.0f} m): not on the station graph")
            return node, distance
        return self._node(request.start_node, "start_node"), 0.0

    def _node(self, name: str, what: str) -> str:
        if name not in self.station.nodes:
            raise RequestError(f"{what} {name!r} is not a node of {self.station.source} (known: "
                               f"{', '.join(sorted(self.station.nodes))})")
        return name

    def shortest(self, origin: str, goal: str, payload_kg: float) -> StationPath:
        """Shortest path of a leg (the payload does not matter)."""
        return self.station.shortest_path(origin, goal)

    def least_charge(self, origin: str, goal: str, payload_kg: float) -> StationPath:
        """Path of a leg that draws the least charge with ``payload_kg`` (kg)."""
        def cost(segment: Segment) -> float:
            return segment.length_m * mean_current_a(payload_kg, segment.slope, self.currents)
        return self.station.least_cost_path(origin, goal, cost)

    def job(self, request: PlanRequest, start: str, approach_m: float,
            path: Callable[[str, str, float], StationPath]) -> tuple[tuple[str, ...], tuple[RouteSection, ...]]:
        """Nodes and sections of the job from ``start`` with legs on ``path(origin, goal, payload_kg)``."""
        pickup = self._node(request.pickup, "pickup")
        dropoff = self._node(request.dropoff, "dropoff")
        legs = [(start, pickup, 0.0, request.loading_s), (pickup, dropoff, request.payload_kg, request.unloading_s)]
        if not request.ends_away_from_charger:
            legs.append((dropoff, self.charger, 0.0, 0.0))
        sections: list[RouteSection] = []
        if approach_m > 0.0:
            name = f"approach to {start}"
            sections.append(RouteSection(name, approach_m, FLAT, 0.0, request.speed_m_s, 0.0, name))
        nodes = [start]
        for origin, goal, payload, standstill in legs:
            route = path(origin, goal, payload)
            nodes.extend(route.nodes[1:])
            sections.extend(leg_sections(route, origin, goal, payload, request.speed_m_s, standstill))
        return tuple(nodes), tuple(sections)

    def to_charger(self, start: str, approach_m: float, speed_m_s: float
                   ) -> tuple[tuple[str, ...], tuple[RouteSection, ...]]:
        """Nodes and sections of the unloaded drive from ``start`` to the charger."""
        route = self.station.shortest_path(start, self.charger)
        sections = []
        if approach_m > 0.0:
            name = f"approach to {start}"
            sections.append(RouteSection(name, approach_m, FLAT, 0.0, speed_m_s, 0.0, name))
        sections.extend(leg_sections(route, start, self.charger, 0.0, speed_m_s, 0.0))
        return route.nodes, tuple(sections)

    # ------------------------------------------------------------- answer
    def plan(self, request: PlanRequest, decide: Decide, from_soc: FromSoc | None = None,
             soc_range: tuple[float, float] = (0.0, 1.0), present_soc: float = math.nan,
             capacity_ah: float = math.nan) -> RoutePlan:
        """Plan and decide a job (raises only RequestError, for a job the graph cannot describe).

        Parameters
        ----------
        request : PlanRequest
            The job.
        decide : callable
            Decides sections from the present state (``PredictorCore.can_accept_route``).
        from_soc : callable, optional
            Decides the job from a rested pack at an SOC (for ``charge_first``; None: not offered).
        soc_range : tuple of float
            SOCs ``from_soc`` may start at (the highest is "full").
        present_soc : float
            Present calibrated SOC (for the charge to add; NaN: the SOC the decision started from).
        capacity_ah : float
            Pack capacity between 0 and 1 SOC, Ah.
        """
        start, approach_m = self.resolve_start(request)
        starts_away = start != self.charger or approach_m > 0.0
        nodes, sections = self.job(request, start, approach_m, self.shortest)
        decision = decide(sections, starts_away, request.ends_away_from_charger)
        where = f"from {start}" + (f" ({approach_m:.0f} m from the given position)" if approach_m > 0 else "")
        main = PlannedRoute(SHORTEST, nodes, sections, decision, decision.accepted,
                            reason=f"shortest route {where}: {' -> '.join(nodes)}, {_length(sections):.0f} m: "
                                   f"{decision.reason}")
        if decision.accepted:
            return RoutePlan(start, approach_m, main, (), main.reason)
        alternatives: list[PlannedRoute] = []
        lc_nodes, lc_sections = self.job(request, start, approach_m, self.least_charge)
        if lc_nodes != nodes:
            d = decide(lc_sections, starts_away, request.ends_away_from_charger)
            climb = _uphill_m(lc_sections), _uphill_m(sections)
            alternatives.append(PlannedRoute(
                LEAST_CHARGE_PATH, lc_nodes, lc_sections, d, d.accepted,
                reason=f"least-charge path {' -> '.join(lc_nodes)}, {_length(lc_sections):.0f} m, {climb[0]:.0f} m "
                       f"uphill instead of {climb[1]:.0f} m: {d.reason}"))
        if from_soc is not None and not request.ends_away_from_charger:
            soc_now = present_soc if math.isfinite(present_soc) else decision.state_of_charge
            alternatives.append(self._charge_first(request, start, approach_m, decide, from_soc, soc_range,
                                                   soc_now, capacity_ah))
        feasible = [a for a in alternatives if a.feasible]
        if feasible:
            reason = f"{main.reason}. Instead: " + "; or ".join(a.reason for a in feasible)
        elif alternatives:
            reason = f"{main.reason}. No alternative is feasible: " + "; ".join(a.reason for a in alternatives)
        else:
            reason = f"{main.reason}. No alternative route on this station graph"
        return RoutePlan(start, approach_m, main, tuple(alternatives), reason)

    def _charge_first(self, request: PlanRequest, start: str, approach_m: float, decide: Decide, from_soc: FromSoc,
                      soc_range: tuple[float, float], present_soc: float, capacity_ah: float) -> PlannedRoute:
        to_nodes, to_sections = ((self.charger,), ()) if start == self.charger and approach_m == 0.0 else \
            self.to_charger(start, approach_m, request.speed_m_s)
        if to_sections:
            leg = decide(to_sections, True, False)
            leg_text = f"drive {_length(to_sections):.0f} m to the {self.charger} (" + (
                f"accepted, margin {leg.margin_v:+.2f} V, {leg.route_charge_ah:.2f} Ah)" if leg.accepted else
                f"{leg.reason})")
        else:
            leg, leg_text = None, f"at the {self.charger}"
        job_nodes, job_sections = self.job(request, self.charger, 0.0, self.shortest)
        nodes = tuple(to_nodes) + tuple(job_nodes[1:])
        lo, hi = soc_range
        full = from_soc(job_sections, hi)
        reached = leg is None or leg.accepted
        if not full.accepted:
            return PlannedRoute(CHARGE_FIRST, nodes, job_sections, full, False,
                                reason=f"charge first: not feasible even on a full pack ({full.reason})")
        low_ok = from_soc(job_sections, lo)
        if low_ok.accepted:
            required = lo
        else:
            a, b = lo, hi  # rejected at a, accepted at b
            while b - a > SOC_TOLERANCE:
                mid = 0.5 * (a + b)
                a, b = (a, mid) if from_soc(job_sections, mid).accepted else (mid, b)
            required = b
        add = ""
        if math.isfinite(present_soc) and math.isfinite(capacity_ah) and capacity_ah > 0:
            leg_ah = leg.route_charge_ah if leg is not None and math.isfinite(leg.route_charge_ah) else 0.0
            arrival = present_soc - leg_ah / capacity_ah
            add = f" (about {arrival:.3f} on arrival: +{max(required - arrival, 0.0) * capacity_ah:.1f} Ah)"
        verdict = "feasible" if reached else "not feasible: the charger cannot be reached"
        reason = (f"charge first ({verdict}): {leg_text}, charge to SOC >= {required:.3f}{add}, then the job "
                  f"{' -> '.join(job_nodes)}, {_length(job_sections):.0f} m (on a full pack: "
                  f"{full.predicted_voltage_v:.2f} V after it, margin {full.margin_v:+.2f} V)")
        return PlannedRoute(CHARGE_FIRST, nodes, job_sections, full, reached, required, reason)


def leg_sections(route: StationPath, origin: str, goal: str, payload_kg: float, speed_m_s: float,
                 standstill_s: float) -> list[RouteSection]:
    """One section per run of equal slope of a leg, named ``"<from>-><to> <slope>"``; the standstill after the last."""
    leg = f"{origin}->{goal}"
    if not route.segments:
        if standstill_s > 0.0:
            name = f"standstill at {goal}"
            return [RouteSection(name, 0.0, FLAT, payload_kg, speed_m_s, standstill_s, name)]
        return []
    out: list[RouteSection] = []
    seen: dict[str, int] = {}
    for i, segment in enumerate(route.segments):
        seen[segment.slope] = seen.get(segment.slope, 0) + 1
        suffix = f" {seen[segment.slope]}" if seen[segment.slope] > 1 else ""
        out.append(RouteSection(f"{leg} {segment.slope}{suffix}", segment.length_m, segment.slope, payload_kg,
                                speed_m_s, standstill_s if i == len(route.segments) - 1 else 0.0, leg))
    return out


def plan_from_core(core: PredictorCore, planner: RoutePlanner, request: PlanRequest, now_s: float) -> RoutePlan:
    """Plan a job from a :class:`~battery_predictor.prediction.core.PredictorCore`'s present state (never raises).

    The shortest route and the least-charge path are decided by ``core.can_accept_route``; the
    charge-first job by :func:`~battery_predictor.prediction.route.evaluate_route` from a rested
    pack at the node's route threshold, standstill current and temperature.
    """
    threshold = core.route_min_voltage_v

    def decide(sections: Sequence[RouteSection], starts_away: bool, ends_away: bool) -> RouteDecision:
        return core.can_accept_route(sections, now_s, starts_away_from_charger=starts_away,
                                     ends_away_from_charger=ends_away)

    from_soc, soc_range, soc_now, capacity = None, (0.0, 1.0), math.nan, math.nan
    if core.runner is not None and math.isfinite(threshold):
        state = core.latest_state()
        t_k = state[3] if state is not None else math.nan
        temp = t_k if math.isfinite(t_k) and 200.0 < t_k < 400.0 else core.default_temperature_k
        lo, hi = core.runner.soc_bounds
        soc_range = (max(lo, 0.0), min(hi, 1.0))
        capacity = core.runner.capacity_ah

        runner = core.runner

        def from_soc(sections: Sequence[RouteSection], soc: float) -> RouteDecision:
            return evaluate_route_at_risk(runner, soc, sections, temp, threshold_v=threshold,
                                          standstill_current_a=core.standstill_current_a, currents=planner.currents,
                                          risk=core.config.decision_risk, model=core.uncertainty,
                                          state_voltage_sigma_v=core.state_voltage_sigma_v())
    try:
        return planner.plan(request, decide, from_soc, soc_range, soc_now, capacity)
    except BatteryPredictorError as exc:
        return RoutePlan("", 0.0, None, (), f"invalid request: {exc}")


def _length(sections: Sequence[RouteSection]) -> float:
    return sum(s.length_m for s in sections)


def _uphill_m(sections: Sequence[RouteSection]) -> float:
    return sum(s.length_m for s in sections if s.slope == UPHILL)
