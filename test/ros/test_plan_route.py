"""``/plan_route`` through the real monitor + predictor nodes (luggage robot, Ranger node params).

``BatteryState`` samples put the pack at 49.8 V / 3 A (charged), then at 47.6 V / 1.7 A (in the
LiFePO4 knee), then at 44.0 V / 3 A (below the route threshold), lock step on ``/clock``. A job
from platform 13 north (pickup platform 11 south, drop-off platform 13 south, 80 kg) is planned
over the middleware at each state: accepted on the charged pack; rejected in the knee with a
feasible charge-first alternative (the drive to the charger accepted, the SOC to charge to);
rejected below the threshold, the charger then unreachable too. A position maps to its nearest
node; malformed requests are answered ``accepted = false`` with the reason; ``/can_accept_route``
still answers beside it.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
from battery_predictor_msgs.msg import PlannedRoute
from battery_predictor_msgs.srv import CanAcceptRoute, PlanRoute
from rclpy.context import Context

from battery_predictor.nodes.messages import route_section_msgs
from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.profiles.ranger import longest_route
from battery_predictor.replay import stream_from_messages

from ._helpers import T0_NS, S, call_service
from ._helpers import battery_state_samples as samples

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
JOB = dict(start_node="platform13_north", pickup="platform11_south", dropoff="platform13_south", payload_kg=80.0)
MALFORMED = {
    "'platform99' is not a node": dict(JOB, start_node="platform99"),
    "pickup and drop-off are both": dict(JOB, dropoff="platform11_south"),
    "payload": dict(JOB, payload_kg=math.nan),
    "500": dict(JOB, payload_kg=500.0),
    "not on the station graph": dict(JOB, use_position=True, x_m=1e4, y_m=0.0),
    "not finite": dict(JOB, use_position=True, x_m=math.inf, y_m=0.0),
    "speed_m_s": dict(JOB, speed_m_s=-1.0),
    "loading_s": dict(JOB, loading_s=math.inf),
}


NODES = ["charger", "platform13_north", "platform11_south", "platform13_south", "bus_stop", "", "x" * 64, "ü"]
NUMBERS = [math.nan, math.inf, -math.inf, -1.0, 0.0, 1e-9, 0.5, 80.0, 199.9, 200.1, 1e9, 1e308, -1e308]
N_FUZZ = 100


def random_request(rng: np.random.Generator) -> PlanRoute.Request:
    """A seeded random, mostly malformed request (within what the interface can carry)."""
    def num(normal: float) -> float:
        return float(rng.choice(NUMBERS)) if rng.random() < 0.3 else normal

    return PlanRoute.Request(start_node=str(rng.choice(NODES)), use_position=bool(rng.random() < 0.3),
                             x_m=num(float(rng.uniform(-50, 150))), y_m=num(float(rng.uniform(-150, 150))),
                             pickup=str(rng.choice(NODES)), dropoff=str(rng.choice(NODES)),
                             payload_kg=num(float(rng.choice([0.0, 20.0, 80.0]))),
                             ends_away_from_charger=bool(rng.random() < 0.3), loading_s=num(60.0),
                             unloading_s=num(60.0), speed_m_s=num(0.0))




def call(session: ReplaySession, request: PlanRoute.Request, timeout_s: float = 60.0) -> PlanRoute.Response:
    """Call the service over the middleware from the session's client node."""
    return call_service(session, PlanRoute, session.predictor.plan_service.srv_name, request, timeout_s)


def test_plan_route_valid_infeasible_and_malformed(ros_context: Context) -> None:
    stream = stream_from_messages(samples(0.0, 30.0, 49.8, 3.0) + samples(30.0, 60.0, 47.6, 1.7)
                                  + samples(60.0, 90.0, 44.0, 3.0), style="battery_state",
                                  battery_topic="/battery_state")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 5.0}, rate=0) as session:
        session.play_until(T0_NS + 29 * S)
        t0 = time.perf_counter()
        charged = call(session, PlanRoute.Request(**JOB))
        latency_s = time.perf_counter() - t0
        by_position = call(session, PlanRoute.Request(**dict(JOB, use_position=True, x_m=118.0, y_m=140.0)))
        malformed = {key: call(session, PlanRoute.Request(**fields)) for key, fields in MALFORMED.items()}
        rng = np.random.default_rng(14)
        fuzz = [(req, call(session, req)) for req in (random_request(rng) for _ in range(N_FUZZ))]
        after_fuzz = call(session, PlanRoute.Request(**JOB))
        route = session.call_route(CanAcceptRoute.Request(sections=route_section_msgs(longest_route(80.0).sections)))
        session.play_until(T0_NS + 59 * S)
        knee = call(session, PlanRoute.Request(**JOB))
        session.play_until()
        low = call(session, PlanRoute.Request(**JOB))
    print(f"plan_route latency {latency_s * 1000:.0f} ms; knee: {knee.reason}")

    assert charged.accepted and charged.margin_v > 0, charged.reason
    assert list(charged.nodes) == ["platform13_north", "platform13_middle", "platform13_south", "platform11_south",
                                   "platform13_south", "charger"]
    assert charged.length_m == pytest.approx(295 + 420 + 420 + 280)
    assert sum(s.length_m for s in charged.sections) == pytest.approx(charged.length_m)
    assert {s.payload_kg for s in charged.sections if "platform11_south->platform13_south" in s.name} == {80.0}
    assert charged.threshold_voltage_v == pytest.approx(46.31)
    assert charged.predicted_voltage_v == pytest.approx(charged.threshold_voltage_v + charged.margin_v)
    assert "accepted" in charged.reason and not charged.alternatives
    assert by_position.start_node == "platform13_north" and 0 < by_position.approach_m < 10
    assert by_position.sections[0].name == "approach to platform13_north"
    assert route.accepted, route.reason

    for key, answer in malformed.items():
        assert not answer.accepted and "invalid request" in answer.reason and key in answer.reason, (key,
                                                                                                    answer.reason)
        assert not answer.alternatives and math.isnan(answer.margin_v)

    for req, answer in fuzz:  # every answer carries a reason; the service survives them all
        assert answer.reason
        if not (math.isfinite(req.payload_kg) and 0 <= req.payload_kg <= 200) or req.pickup == req.dropoff:
            assert not answer.accepted and "invalid request" in answer.reason, answer.reason
        if answer.accepted:
            assert answer.margin_v >= 0 and answer.nodes[-1] in ("charger", req.dropoff), answer.reason
    assert sum(a.accepted for _, a in fuzz) >= 1 and sum(not a.accepted for _, a in fuzz) > 50
    assert after_fuzz.accepted, after_fuzz.reason

    assert not knee.accepted and knee.margin_v < 0, knee.reason
    first = [a for a in knee.alternatives if a.kind == PlannedRoute.KIND_CHARGE_FIRST]
    assert len(first) == 1 and first[0].feasible, knee.reason
    assert 0.0 <= first[0].required_soc < 1.0 and "charge to SOC >=" in first[0].reason
    assert list(first[0].nodes[:3]) == ["platform13_north", "platform13_middle", "platform13_south"]
    assert "Instead: charge first" in knee.reason

    assert not low.accepted and "already below the route threshold 46.31 V" in low.reason, low.reason
    assert not any(a.feasible for a in low.alternatives), low.reason


#: Another station as a YAML file: a 150 m ramp between two platforms, or a 260 m flat detour by the yard.
DETOUR_YAML = """
nodes:
  charger: {description: charger, x_m: 0, y_m: 0}
  low: {description: lower platform, x_m: 300, y_m: 0}
  high: {description: upper platform, x_m: 300, y_m: 60}
  yard: {description: yard, x_m: 360, y_m: 30}
edges:
  - {from: charger, to: low, segments: [{length_m: 300.0, slope: flat}]}
  - {from: low, to: high, segments: [{length_m: 150.0, slope: uphill}]}
  - {from: low, to: yard, segments: [{length_m: 130.0, slope: flat}]}
  - {from: yard, to: high, segments: [{length_m: 130.0, slope: flat}]}
"""


def test_another_station_from_a_yaml_file_offers_the_lower_slope_path(ros_context: Context, tmp_path: Path) -> None:
    """``station_file`` swaps the graph; with 80 kg the flat detour draws less than the ramp and ends higher."""
    station = tmp_path / "detour_station.yaml"
    station.write_text(DETOUR_YAML)
    stream = stream_from_messages(samples(0.0, 60.0, 47.4, 1.7), style="battery_state", battery_topic="/battery_state")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 30.0, "station_file": str(station)},
                       rate=0) as session:
        session.play_until()
        answer = call(session, PlanRoute.Request(start_node="charger", pickup="low", dropoff="high", payload_kg=80.0))
    assert list(answer.nodes) == ["charger", "low", "high", "low", "charger"], answer.reason
    assert not answer.accepted and answer.margin_v < 0, answer.reason
    kinds = {a.kind: a for a in answer.alternatives}
    detour = kinds[PlannedRoute.KIND_LEAST_CHARGE_PATH]
    assert list(detour.nodes) == ["charger", "low", "yard", "high", "low", "charger"]
    assert detour.route_charge_ah < answer.route_charge_ah and detour.margin_v > answer.margin_v, detour.reason
    assert "0 m uphill instead of 150 m" in detour.reason
    assert kinds[PlannedRoute.KIND_CHARGE_FIRST].feasible
