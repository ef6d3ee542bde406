"""Route planning for the luggage robot without ROS (battery_predictor.prediction.planning)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from battery_predictor.errors import ParamsError, ProfileError, RequestError
from battery_predictor.prediction.core import PredictorConfig, PredictorCore
from battery_predictor.prediction.planning import (
    CHARGE_FIRST,
    LEAST_CHARGE_PATH,
    MAX_SNAP_M,
    SOC_TOLERANCE,
    PlanRequest,
    RoutePlanner,
    plan_from_core,
)
from battery_predictor.prediction.route import RouteDecision
from battery_predictor.prediction.station_services import StationServices, StationServicesConfig
from battery_predictor.prediction.uncertainty import evaluate_route_at_risk
from battery_predictor.profiles.ranger import route_from_station
from battery_predictor.profiles.station import UPHILL, load_station

PARAMS = Path(__file__).resolve().parents[2] / "params"
T_K = 298.15
#: A station with a short ramp and a longer flat detour between the platforms (no positions on "yard").
DETOUR = {
    "nodes": {"charger": {"description": "charger", "x_m": 0, "y_m": 0},
              "low": {"description": "lower platform", "x_m": 100, "y_m": 0},
              "high": {"description": "upper platform", "x_m": 200, "y_m": 0},
              "yard": "no position"},
    "edges": [
        {"from": "charger", "to": "low", "segments": [{"length_m": 100.0, "slope": "flat"}]},
        {"from": "low", "to": "high", "segments": [{"length_m": 100.0, "slope": "uphill"}]},
        {"from": "low", "to": "yard", "segments": [{"length_m": 90.0, "slope": "flat"}]},
        {"from": "yard", "to": "high", "segments": [{"length_m": 90.0, "slope": "flat"}]},
    ],
}


@pytest.fixture(scope="module")
def core():
    return PredictorCore(PredictorConfig(params_file=str(PARAMS / "ranger_mini.yaml")))


@pytest.fixture
def detour(tmp_path):
    path = tmp_path / "detour.yaml"
    path.write_text(yaml.safe_dump(DETOUR))
    return load_station(path)


def fed_core(core, voltage_v: float, current_a: float = 1.7, seconds: int = 60, t0: float = 1000.0) -> PredictorCore:
    c = PredictorCore(core.config, params=core.params)
    for k in range(seconds):
        c.update_state(t0 + k, voltage_v, current_a, T_K)
    return c


def decision(accepted: bool, margin_v: float = 0.0) -> RouteDecision:
    return RouteDecision(accepted, 46.31 + margin_v, 46.31, margin_v, 100.0, 0.1, 0.5,
                         "accepted" if accepted else "rejected")


@pytest.mark.parametrize(("fields", "match"), [
    (dict(payload_kg=math.nan), "payload"),
    (dict(payload_kg=201.0), "payload"),
    (dict(dropoff="low"), "pickup and drop-off are both 'low'"),
    (dict(speed_m_s=0.0), "speed_m_s is 0.0"),
    (dict(loading_s=-1.0), "loading_s is -1.0"),
    (dict(unloading_s=math.inf), "unloading_s is inf"),
    (dict(use_position=True, x_m=math.nan, y_m=0.0), "not finite"),
    (dict(start_node="x" * 65), "at most 64"),
])
def test_malformed_plan_requests_raise_request_error(fields, match):
    base = dict(start_node="charger", pickup="low", dropoff="high", payload_kg=80.0)
    with pytest.raises(RequestError, match=match):
        PlanRequest(**{**base, **fields})


def test_positions_map_to_the_nearest_node(detour):
    assert detour.nearest_node(190.0, 5.0) == ("high", pytest.approx(math.hypot(10, 5)))
    planner = RoutePlanner(detour)
    req = PlanRequest("", "low", "high", 0.0, use_position=True, x_m=3.0, y_m=4.0)
    assert planner.resolve_start(req) == ("charger", pytest.approx(5.0))
    with pytest.raises(RequestError, match=f"at most {MAX_SNAP_M:.0f} m"):
        planner.resolve_start(PlanRequest("", "low", "high", 0.0, use_position=True, x_m=0.0, y_m=500.0))
    minden = load_station(PARAMS / "minden_station.yaml")
    assert minden.nearest_node(69.0, -140.0)[0] == "platform11_south"


def test_station_without_positions_says_so(tmp_path):
    data = {"nodes": {"a": "A", "b": "B"}, "edges": [{"from": "a", "to": "b", "segments": [
        {"length_m": 5.0, "slope": "flat"}]}]}
    path = tmp_path / "plain.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ProfileError, match="gives no node positions"):
        load_station(path).nearest_node(0.0, 0.0)
    data["nodes"]["a"] = {"description": "A", "x_m": 1.0}
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ParamsError, match="nodes.a needs both x_m and y_m"):
        load_station(path)


def test_least_charge_path_avoids_the_loaded_climb(detour):
    planner = RoutePlanner(detour)
    # unloaded the 100 m ramp draws less than the 180 m detour; with 80 kg it draws more
    assert planner.least_charge("low", "high", 0.0).nodes == ("low", "high")
    assert planner.least_charge("low", "high", 80.0).nodes == ("low", "yard", "high")
    assert planner.shortest("low", "high", 80.0).nodes == ("low", "high")
    with pytest.raises(ProfileError, match="segment cost"):
        detour.least_cost_path("low", "high", lambda s: -1.0)


def test_a_rejected_climb_offers_the_flat_detour(detour):
    """With a decision that rejects any loaded climb, the shortest route is rejected and the detour accepted."""
    planner = RoutePlanner(detour)
    calls = []

    def decide(sections, starts_away, ends_away):
        calls.append((tuple(s.name for s in sections), starts_away, ends_away))
        climbs = any(s.slope == UPHILL and s.payload_kg > 0 for s in sections)
        return decision(not climbs, -0.2 if climbs else 0.4)

    plan = planner.plan(PlanRequest("charger", "low", "high", 80.0), decide)
    assert not plan.accepted and plan.route.nodes == ("charger", "low", "high", "low", "charger")
    assert [a.kind for a in plan.alternatives] == [LEAST_CHARGE_PATH]
    alt = plan.alternatives[0]
    assert alt.feasible and alt.nodes == ("charger", "low", "yard", "high", "low", "charger")
    assert "0 m uphill instead of 100 m" in alt.reason and "Instead: least-charge path" in plan.reason
    assert calls[0][1:] == (False, False)  # from the charger, back to the charger
    # ends away from the charger: no return leg, and charge-first is not offered
    away = planner.plan(PlanRequest("low", "charger", "high", 80.0, ends_away_from_charger=True), decide,
                        from_soc=lambda sections, soc: decision(True))
    assert away.route.nodes[-1] == "high" and calls[-1][1:] == (True, True)
    assert all(a.kind != CHARGE_FIRST for a in away.alternatives)


def test_job_sections_match_the_profile_builder():
    """From the charger, a planned job drives what route_from_station describes (the paper's route)."""
    station = load_station(PARAMS / "minden_station.yaml")
    planner = RoutePlanner(station)
    req = PlanRequest("charger", "platform11_south", "platform13_south", 80.0)
    _, sections = planner.job(req, "charger", 0.0, planner.shortest)
    reference = route_from_station(station, "charger", "platform11_south", "platform13_south", 80.0)
    assert [(s.length_m, s.slope, s.payload_kg, s.standstill_s) for s in sections] == \
        [(s.length_m, s.slope, s.payload_kg, s.standstill_s) for s in reference.sections]


def test_plans_from_the_core_state(core):
    planner = RoutePlanner(load_station(PARAMS / "minden_station.yaml"))
    job = PlanRequest("platform13_north", "platform11_south", "platform13_south", 80.0)
    charged = plan_from_core(fed_core(core, 49.8, 3.0), planner, job, 1060.0)
    assert charged.accepted and charged.route.decision.margin_v > 0 and not charged.alternatives
    knee_core = fed_core(core, 47.6)
    knee = plan_from_core(knee_core, planner, job, 1060.0)
    assert not knee.accepted and knee.route.decision.margin_v < 0
    first = [a for a in knee.alternatives if a.kind == CHARGE_FIRST][0]
    assert first.feasible and first.nodes[:4] == ("platform13_north", "platform13_middle", "platform13_south",
                                                  "charger")
    # the required SOC is the bisection's: the job from it is accepted at the node's risk, a little below it is not
    required = first.required_soc

    def from_soc(soc):
        return evaluate_route_at_risk(core.runner, soc, first.sections, T_K, threshold_v=46.31, standstill_current_a=1.70,
                                      risk=core.config.decision_risk, model=core.uncertainty,
                                      state_voltage_sigma_v=core.state_voltage_sigma_v())

    assert from_soc(required).accepted
    assert required == 0.0 or not from_soc(required - 2 * SOC_TOLERANCE).accepted
    # the same sections through /can_accept_route's decision: the planner adds nothing of its own
    direct = knee_core.can_accept_route(knee.route.sections, 1060.0, starts_away_from_charger=True)
    assert direct.margin_v == pytest.approx(knee.route.decision.margin_v)
    below = plan_from_core(fed_core(core, 44.0, 3.0), planner, job, 1060.0)
    assert not below.accepted and "already below the route threshold" in below.reason
    assert not any(a.feasible for a in below.alternatives)
    unknown = plan_from_core(PredictorCore(core.config, params=core.params), planner, job, 1060.0)
    assert not unknown.accepted and "no pack state received yet" in unknown.reason
    bad = plan_from_core(fed_core(core, 49.8, 3.0), planner,
                         PlanRequest("platform99", "platform11_south", "platform13_south", 80.0), 1060.0)
    assert bad.route is None and "invalid request: start_node 'platform99' is not a node" in bad.reason


def test_services_read_their_files_and_refuse_bad_ones(tmp_path):
    services = StationServices(StationServicesConfig())
    assert "charger" in services.station.nodes and "restroom" in services.task_map.nodes
    assert services.loads.speed_m_s == 0.90
    with pytest.raises(ParamsError, match="station services"):
        StationServices(StationServicesConfig(charger_node="dock"))
    with pytest.raises(ParamsError, match="station services"):
        StationServices(StationServicesConfig(station_file=str(tmp_path / "missing.yaml")))
