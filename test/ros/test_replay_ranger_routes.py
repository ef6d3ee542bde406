"""Route decisions of the real nodes against the truth recorded in the bundled luggage-robot bags.

Each ``bags/ranger_route_<payload>kg_pack<n>`` bag is the paper's longest route
driven twice in a row (5.2.4) from a start SOC chosen so that the voltage at
1.70 A after the second cycle is just above 46.31 V; its metadata says whether
the second cycle ended above the threshold and whether a third one would have
(simulated by the lab, not recorded). The bag is replayed into the monitor and
predictor (BatteryState topic, ``use_sim_time``, lock step) and
``/can_accept_route`` is asked, over the middleware, at the bag's own times:

==================  =================  =========================================
asked at            route asked for    truth (bag metadata)
==================  =================  =========================================
start (after 60 s)  the route once     voltage after cycle 1 >= 46.31 V
start (after 60 s)  the route twice    ``second_cycle_ends_above_threshold``
start (after 60 s)  the route 3 times  ``further_cycle_stays_above_threshold``
end of cycle 1      the route once     ``second_cycle_ends_above_threshold``
end of cycle 2      the route once     ``further_cycle_stays_above_threshold``
==================  =================  =========================================

The route sections are the bag's own (its metadata). Each bag is replayed once
(the first of its tests) and the five answers are kept for the other four.

Tolerance (stated, from measurement): the bags are built so that cycle 2 ends
only ~0.1 V above the threshold, closer than the model can resolve (the seed
paper reports a route voltage MAE of 0.17 V). So

* the predicted voltage after the route must be within ``TOLERANCE_V`` of the
  lab pack's (noise-free) voltage at 1.70 A after the same cycle, whenever the
  node predicts one (a route that reaches a cell cut-off has none);
* the accept/reject decision must equal the truth whenever the true voltage is
  more than ``TOLERANCE_V`` away from the 46.31 V threshold; closer decisions
  are within the model's accuracy and are only reported;
* a route the lab pack could not drive above the threshold is never accepted
  (no unsafe accept), however close.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from battery_predictor_msgs.msg import RouteSection
from battery_predictor_msgs.srv import CanAcceptRoute
from rclpy.context import Context

from battery_predictor.nodes.messages import SLOPE_NAMES
from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.replay import read_replay_stream

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / "bags"
ROUTE_BAGS = [f"ranger_route_{kg}kg_pack{n}" for kg in (20, 40, 60, 80) for n in (1, 2, 3)]
SLOPE_CODES = {name: code for code, name in SLOPE_NAMES.items()}
THRESHOLD_V = 46.31
#: (asked at, cycles asked for, truth decision key, index of the truth voltage after the asked cycles)
QUESTIONS = {
    "start_x1": ("start", 1, None, 0),
    "start_x2": ("start", 2, "second_cycle_ends_above_threshold", 1),
    "start_x3": ("start", 3, "further_cycle_stays_above_threshold", 2),
    "cycle1_x1": ("cycle1", 1, "second_cycle_ends_above_threshold", 1),
    "cycle2_x1": ("cycle2", 1, "further_cycle_stays_above_threshold", 2),
}
#: MEASURED with the shipped params/ranger_mini.yaml and the prediction core of this commit on these
#: bags: |predicted - true| mean 0.10 V, max 0.30 V (40 kg pack 3, the route twice from the start),
#: nearly always below the truth (conservative); seed paper: MAE 0.17 V. Decisions: all 36 clear-cut ones
#: right, 11 of the 24 within 0.1 V of the threshold right (the others rejected), none accepted wrongly.
TOLERANCE_V = 0.35

_answers: dict[str, dict[str, tuple[bool, float, CanAcceptRoute.Response]]] = {}


def _sections(metadata: dict) -> list[RouteSection]:
    return [RouteSection(name=s["name"], length_m=float(s["length_m"]), slope=SLOPE_CODES[s["slope"]],
                         payload_kg=float(s["payload_kg"]), speed_m_s=float(s["speed_m_s"]),
                         standstill_s=float(s["standstill_s"])) for s in metadata["route"]["sections"]]


def _replay(name: str, context: Context) -> dict[str, tuple[bool, float, CanAcceptRoute.Response]]:
    path = BAGS / name
    assert path.exists(), f"bundled bag {path} missing (make bags)"
    stream = read_replay_stream(path)
    truth = stream.metadata["truth"]
    true_v = [math.nan if v is None else float(v) for v in truth["voltage_at_1_70_a_after_cycle_noise_free_v"]]
    route = _sections(stream.metadata)
    cycle_s = float(truth["cycle_duration_s"])
    times_s = {"start": 60.0, "cycle1": cycle_s, "cycle2": 2 * cycle_s}
    out = {}
    with ReplaySession(stream, context=context, params_file=str(REPO / "params/ros/ranger_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 3600.0},
                       monitor_overrides={"diagnostics_period_s": 60.0}, rate=0) as session:
        for key, (when, cycles, truth_key, index) in QUESTIONS.items():
            session.play_until(stream.ros_time_ns(times_s[when]))
            response = session.call_route(CanAcceptRoute.Request(sections=route * cycles))
            expected = true_v[index] >= THRESHOLD_V if truth_key is None else bool(truth[truth_key])
            out[key] = (expected, true_v[index], response)
    return out


@pytest.mark.parametrize("question", list(QUESTIONS))
@pytest.mark.parametrize("name", ROUTE_BAGS)
def test_route_decision_matches_the_recorded_truth(name: str, question: str, ros_context: Context) -> None:
    if name not in _answers:
        _answers[name] = _replay(name, ros_context)
    expected, true_v, response = _answers[name][question]
    report = "\n".join(f"  {q}: truth {'accept' if e else 'reject'} ({v:.3f} V), node "
                       f"{'accept' if r.accepted else 'reject'} ({r.reason})" for q, (e, v, r) in _answers[name].items())
    assert response.reason, report
    if math.isfinite(response.predicted_voltage_v):
        assert abs(response.predicted_voltage_v - true_v) <= TOLERANCE_V, f"{name} {question}:\n{report}"
    if not abs(true_v - THRESHOLD_V) <= TOLERANCE_V:  # clear-cut (NaN: the lab pack reached its cut-off)
        assert response.accepted == expected, f"{name} {question}: decision differs from the truth:\n{report}"
    if response.accepted:
        assert expected, f"{name} {question}: accepted a route the lab pack could not drive:\n{report}"
        assert response.threshold_voltage_v == pytest.approx(THRESHOLD_V)
        assert response.margin_v >= 0 and response.predicted_voltage_v >= THRESHOLD_V
        # accepted at the node's risk: the P10 voltage is above the threshold
        assert response.risk == pytest.approx(0.1) and response.probability_above_threshold >= 0.9
        assert response.voltage_at_risk_v >= THRESHOLD_V
    if math.isfinite(response.predicted_voltage_v):
        assert 0.0 <= response.probability_above_threshold <= 1.0


def test_route_probabilities_rank_the_recorded_outcomes(ros_context: Context) -> None:
    """The further above the threshold the lab pack really ended, the higher the node's probability.

    (Routes the lab pack could not finish reach a cell's cut-off in the model too: rejected without
    a probability.)
    """
    from scipy.stats import spearmanr

    for name in ROUTE_BAGS:
        if name not in _answers:
            _answers[name] = _replay(name, ros_context)
    rows = [(v - THRESHOLD_V, r.probability_above_threshold) for a in _answers.values() for _, v, r in a.values()
            if math.isfinite(r.probability_above_threshold) and math.isfinite(v)]
    margins = [m for m, _ in rows]
    probabilities = [p for _, p in rows]
    rho = spearmanr(margins, probabilities).statistic
    brier = sum((p - (m >= 0)) ** 2 for m, p in rows) / len(rows)
    print(f"route probabilities: {len(rows)} answered, rank correlation with the true margin {rho:.2f}, "
          f"Brier score {brier:.3f}")
    assert len(rows) >= 30 and rho > 0.5
    # at the default risk nothing that ended below the threshold was accepted (checked per question above),
    # and what is accepted has the probability the risk asks for
    assert all(p >= 0.9 for a in _answers.values() for _, _, r in a.values() if r.accepted
               for p in [r.probability_above_threshold])
