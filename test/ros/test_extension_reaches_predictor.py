"""A model extension activated in a pack params file reaches ``/remaining_runtime`` and ``/can_accept_route``.

The same information-robot bag (``bags/temi_dynamic_pack1``) is replayed into the real
``battery_monitor`` and ``predictor`` nodes (bundled node params, ``use_sim_time``, lock
step) twice: with a copy of ``params/temi.yaml`` and with the same copy plus
``extensions: [cell_imbalance]`` (one series group holding ``WEAK_FRACTION`` of the others'
capacity). Both copies are written to ``tmp_path`` the same way, so the extension is their only
difference. After ``PLAY_S`` of bag time the last published remaining runtime is read and
``can_accept_route`` is asked for the same route over the middleware.

Expected physics: both models are calibrated on the same measured voltages, but the weak
group empties ``1 / WEAK_FRACTION`` times faster, so

* the remaining runtime is shorter (MEASURED at 10 min: 378.1 vs 474.2 min, ratio 0.80, the weak
  group's cell cut-off ending it);
* after a route drawing ~1.4 Ah the weak group sits lower on its OCV curve, so the predicted
  pack voltage after the route is lower (MEASURED: 16.075 vs 16.120 V).

A predictor that ignored the extension (as before the runner had a weak group) gives
identical answers and fails both.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml
from battery_predictor_msgs.msg import RouteSection
from battery_predictor_msgs.srv import CanAcceptRoute
from rclpy.context import Context

from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.replay import read_replay_stream
from battery_predictor.simulation.extensions import WEAK_FRACTION as WEAK_FRACTION_KEY

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
BAG = REPO / "bags" / "temi_dynamic_pack1"
NODE_PARAMS = REPO / "params" / "ros" / "temi_nodes.yaml"
WEAK_FRACTION = 0.7
#: Bag time played before the questions, s (recording time axis).
PLAY_S = 600.0
#: temi's params have no route threshold; any finite one makes the service predict a voltage.
ROUTE_THRESHOLD_V = 13.0
#: A route of 30 min driving (~1.4 Ah on the 14.7 Ah pack): 2 x 300 m flat, 300 m uphill, 20 kg, 0.5 m/s.
ROUTE = (("out", 300.0, RouteSection.SLOPE_FLAT), ("ramp", 300.0, RouteSection.SLOPE_UPHILL),
         ("back", 300.0, RouteSection.SLOPE_FLAT))


def _params_copy(path: Path, extension: dict | None) -> Path:
    """``params/temi.yaml`` written to ``path``, with ``extension`` = {"extensions": [...], "extra": {...}}."""
    data = yaml.safe_load((REPO / "params" / "temi.yaml").read_text())
    if extension is not None:
        data["extensions"] = list(extension["extensions"])
        data["cell"]["extra"] = dict(extension["extra"])
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _answers(params_file: Path, context: Context) -> tuple:
    """Replay ``PLAY_S`` of the bag with ``params_file``; (last runtime point, route response)."""
    stream = read_replay_stream(BAG)
    overrides = {"params_file": str(params_file), "runtime_period_s": 60.0,
                 "route_min_voltage_v": ROUTE_THRESHOLD_V}
    with ReplaySession(stream, context=context, params_file=str(NODE_PARAMS), predictor_overrides=overrides,
                       monitor_overrides={"diagnostics_period_s": 60.0}, rate=0) as session:
        session.play_until(stream.ros_time_ns(PLAY_S))
        points = session.runtime_points()
        request = CanAcceptRoute.Request(sections=[
            RouteSection(name=name, length_m=length_m, slope=slope, payload_kg=20.0, speed_m_s=0.5, standstill_s=0.0)
            for name, length_m, slope in ROUTE])
        response = session.call_route(request)
    assert points, "no remaining runtime published"
    return points[-1], response


def test_cell_imbalance_in_the_params_file_shortens_runtime_and_lowers_the_route_voltage(
        tmp_path: Path, ros_context: Context) -> None:
    plain_file = _params_copy(tmp_path / "temi_plain.yaml", None)
    weak_file = _params_copy(tmp_path / "temi_weak_group.yaml", {
        "extensions": ["cell_imbalance"], "extra": {WEAK_FRACTION_KEY: WEAK_FRACTION}})
    plain_rt, plain_route = _answers(plain_file, ros_context)
    weak_rt, weak_route = _answers(weak_file, ros_context)
    for rt in (plain_rt, weak_rt):
        assert rt.valid and rt.status == 0 and math.isfinite(rt.remaining_s), rt.reason
        assert rt.time_s > PLAY_S - 70.0  # a fresh update, not the first one
    for route in (plain_route, weak_route):
        assert math.isfinite(route.predicted_voltage_v), route.reason
        assert route.route_charge_ah == pytest.approx(plain_route.route_charge_ah)
    report = (f"runtime plain {plain_rt.remaining_s / 60:.1f} min, weak group {weak_rt.remaining_s / 60:.1f} min; "
              f"route voltage plain {plain_route.predicted_voltage_v:.3f} V, "
              f"weak group {weak_route.predicted_voltage_v:.3f} V")
    # the weak group empties first: the runtime shrinks by roughly its capacity fraction
    assert WEAK_FRACTION - 0.1 < weak_rt.remaining_s / plain_rt.remaining_s < 0.9, report
    # ... and after the same route it sits lower on its OCV curve
    assert weak_route.predicted_voltage_v < plain_route.predicted_voltage_v - 0.01, report
