"""Feasible tasks of the information robot without ROS (battery_predictor.prediction.tasks)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import RequestError
from battery_predictor.prediction.core import PredictorConfig, PredictorCore
from battery_predictor.prediction.tasks import (
    MAX_PROFILE_POINTS,
    MAX_TASKS,
    POLICY_GREEDY,
    POLICY_INDEPENDENT,
    POLICY_ORDERED,
    SEARCH_TOLERANCE_S,
    Task,
    TaskLoads,
    TaskPlanner,
    TaskRisk,
    feasible_tasks,
)
from battery_predictor.profiles.station import load_station
from battery_predictor.profiles.temi import load_usage_config

PARAMS = Path(__file__).resolve().parents[2] / "params"
T_K = 298.15


@pytest.fixture(scope="module")
def core():
    return PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml")))


@pytest.fixture(scope="module")
def task_map():
    return load_station(PARAMS / "minden_information_map.yaml")


@pytest.fixture(scope="module")
def loads():
    return TaskLoads.from_usage(load_usage_config(), 0.90)


def planner(core, task_map, loads, average_a: float = 1.8) -> TaskPlanner:
    return TaskPlanner(core.runner, task_map, "charger", loads, 13.30, T_K, average_a)


def fed_core(core, voltage_v: float, current_a: float = 1.7, seconds: int = 60, t0: float = 1000.0) -> PredictorCore:
    c = PredictorCore(core.config, params=core.params)
    for k in range(seconds):
        c.update_state(t0 + k, voltage_v, current_a, T_K)
    return c


@pytest.mark.parametrize(("kwargs", "match"), [
    (dict(kind="dancing", duration_s=60.0), "kind 'dancing'"),
    (dict(kind="information"), "needs a duration_s"),
    (dict(kind="navigation"), "needs a duration_s or a destination"),
    (dict(kind="information", duration_s=math.nan), "needs a duration_s"),
    (dict(kind="information", duration_s=-5.0), "duration_s is -5.0"),
    (dict(kind="information", duration_s=math.inf), "duration_s is inf"),
    (dict(kind="information", duration_s=1e9), "must be > 0 and <="),
    (dict(kind="information", duration_s=60.0, current_a=-1.0), "current_a is -1.0"),
    (dict(kind="information", duration_s=60.0, current_a=1e4), "current_a is 10000.0"),
    (dict(kind="information", profile=((60.0, math.nan),)), "profile point 0 draws nan"),
    (dict(kind="information", profile=((0.0, 1.0),)), "profile point 0 lasts 0.0"),
    (dict(kind="information", profile=((60.0,),)), "must be (duration_s, current_a)"),
    (dict(kind="information", profile=((60.0, 1.0),) * (MAX_PROFILE_POINTS + 1)), "at most 256"),
])
def test_malformed_tasks_raise_request_error_with_the_reason(kwargs, match):
    with pytest.raises(RequestError, match=re.escape(match)):
        Task("t", **kwargs)


def test_task_loads_come_from_the_usage_model(loads):
    assert loads.information_current_a == pytest.approx(1.65, abs=0.05)
    assert loads.navigation_current_a == pytest.approx(3.30, abs=0.1)
    assert loads.return_current_a > loads.navigation_current_a  # a high quantile: errs toward "no"
    assert loads.speed_m_s == 0.90


def test_policies(core, task_map, loads):
    p = planner(core, task_map, loads)
    tasks = [Task("a", "information", 600.0), Task("huge", "information", 11 * 3600.0),
             Task("b", "navigation", destination="restroom"), Task("c", "information", 300.0)]
    start = 0.6
    independent = p.evaluate(start, "entrance", tasks, POLICY_INDEPENDENT)
    ordered = p.evaluate(start, "entrance", tasks, POLICY_ORDERED)
    greedy = p.evaluate(start, "entrance", tasks, POLICY_GREEDY)
    assert [o.feasible for o in independent.outcomes] == [True, False, True, True]
    assert [o.feasible for o in ordered.outcomes] == [True, False, False, False]
    assert "follows the infeasible task 'huge'" in ordered.outcomes[3].reason
    assert [o.feasible for o in greedy.outcomes] == [True, False, True, True]
    # greedy carries the state: each later task starts lower and leaves less time
    g = greedy.outcomes
    assert g[3].end_voltage_v < independent.outcomes[3].end_voltage_v
    assert g[0].remaining_after_s > g[2].remaining_after_s > g[3].remaining_after_s
    assert g[2].end_location == "restroom" and g[2].duration_s == pytest.approx(60.0 / 0.9)
    assert "falls to 13.30 V" in independent.outcomes[1].reason
    assert greedy.feasible_count == 3 and greedy.valid


def test_the_walk_back_is_the_reserve(core, task_map, loads):
    """A task that fits at the entrance (45 m from the charger) does not fit at the restroom (105 m)."""
    p = planner(core, task_map, loads)
    start = 0.2  # about 12 min of information left (13.30 V is 3.325 V per cell)
    near = p.max_time_s(start, "entrance", loads.information_current_a)
    far = p.max_time_s(start, "restroom", loads.information_current_a)
    assert 0 < far < near
    task = Task("talk", "information", 0.5 * (near + far))
    assert p.try_task(start, "entrance", task)[0].feasible
    at_restroom = p.try_task(start, "restroom", task)[0]
    assert not at_restroom.feasible and at_restroom.margin_v < 0
    assert "105 m walk back" in at_restroom.reason
    # a walk without destination ends somewhere unknown: the walk back counts from the farthest node
    unknown = p.try_task(start, "entrance", Task("walk", "navigation", 30.0))[0]
    assert unknown.end_location == "" and "assumed restroom" in unknown.reason


def test_feasible_means_the_model_stays_above_the_cutoff(core, task_map, loads):
    """The answer agrees with a direct simulation of task + walk back, and the search is tight."""
    p = planner(core, task_map, loads)
    start = 0.3
    t_max = p.max_time_s(start, "entrance", loads.information_current_a)
    ret = [(45.0 / 0.9, loads.return_current_a)]
    run_ok = core.runner.run(start, [(t_max, loads.information_current_a), *ret], T_K)
    run_over = core.runner.run(start, [(t_max + 2 * SEARCH_TOLERANCE_S, loads.information_current_a), *ret], T_K)
    assert np.min(run_ok.pack_voltage_v) >= 13.30
    assert run_over.reached_cutoff or np.min(run_over.pack_voltage_v) < 13.30
    plan = p.evaluate(start, "entrance", [], POLICY_INDEPENDENT)
    assert plan.more_information_s == 60.0 * math.floor(t_max / 60.0)
    walk_s = 2 * 60.0 / 0.9
    nav_s = p.max_time_s(start, "entrance", loads.navigation_current_a)
    assert plan.more_guided_walks == int(nav_s // walk_s) and plan.walk_length_m == 60.0
    assert f"about {plan.more_guided_walks} more guided walks (60 m to the restroom and back)" in plan.summary
    assert f"or {plan.more_information_s / 60:.0f} minutes of information" in plan.summary


def test_a_current_profile_replaces_duration_and_current(core, task_map, loads):
    p = planner(core, task_map, loads)
    o = p.try_task(0.5, "entrance", Task("video", "information", profile=((60.0, 2.0), (120.0, 4.0))))[0]
    assert o.feasible and o.duration_s == 180.0 and o.current_a == pytest.approx((120 + 480) / 180)


def test_requests_are_bounded_and_checked(core, task_map, loads):
    p = planner(core, task_map, loads)
    with pytest.raises(RequestError, match="at most 100"):
        p.evaluate(0.5, "entrance", [Task("t", "information", 1.0)] * (MAX_TASKS + 1), POLICY_GREEDY)
    with pytest.raises(RequestError, match="not on the map"):
        p.evaluate(0.5, "platform 9", [], POLICY_GREEDY)
    with pytest.raises(RequestError, match="policy 'random'"):
        p.evaluate(0.5, "entrance", [], "random")
    bad = p.try_task(0.5, "entrance", Task("t", "navigation", destination="moon"))[0]
    assert not bad.feasible and "destination 'moon' is not on the map" in bad.reason


def test_answers_from_the_core_state(core, task_map, loads):
    tasks = [Task("t", "information", 300.0)]

    def ask(c, now_s=1060.0):
        return feasible_tasks(c, tasks, "entrance", POLICY_GREEDY, now_s, task_map, "charger", loads, 1.7)

    nothing = ask(PredictorCore(core.config, params=core.params))
    assert not nothing.valid and "no pack state received yet" in nothing.reason
    assert not nothing.outcomes[0].feasible and nothing.outcomes[0].reason == nothing.reason
    charged = fed_core(core, 15.0)
    stale = ask(charged, now_s=5000.0)
    assert not stale.valid and "stale" in stale.reason
    ok = ask(charged)
    assert ok.valid and ok.outcomes[0].feasible and "present average current 1.70 A" in ok.reason
    assert 0.0 < ok.state_of_charge <= 1.0
    empty = ask(fed_core(core, 13.2))
    assert empty.valid and not empty.outcomes[0].feasible and "at or below the cut-off" in empty.reason
    assert empty.summary == "I need to return to my charger now."
    swapped = fed_core(core, 15.0)
    swapped.runner = None
    swapped.model_error = "broken"
    assert "no usable pack model: broken" in ask(swapped).reason


def test_a_task_with_a_thin_margin_is_feasible_on_its_median_but_not_at_the_default_risk(core, task_map, loads):
    """With the predictor's risk (P10 of the lowest voltage) a task whose median margin is inside the spread is refused."""
    p50 = planner(core, task_map, loads)
    start = 0.3
    t_max = p50.max_time_s(start, "entrance", loads.information_current_a)
    task = Task("talk", "information", t_max - 60.0)  # the median leaves about a minute of information
    median = p50.try_task(start, "entrance", task)[0]
    assert median.feasible and math.isnan(median.probability_feasible)
    risk = TaskRisk(0.1, core.uncertainty, core.state_voltage_sigma_v())
    at_risk = TaskPlanner(core.runner, task_map, "charger", loads, 13.30, T_K, 1.8, risk).try_task(start, "entrance",
                                                                                                   task)[0]
    assert not at_risk.feasible and 0.5 <= at_risk.probability_feasible < 0.9
    assert "probability above the cut-off" in at_risk.reason and at_risk.reason.startswith("not feasible")
    short = Task("hello", "information", 60.0)
    sure = TaskPlanner(core.runner, task_map, "charger", loads, 13.30, T_K, 1.8, risk).try_task(start, "entrance",
                                                                                                short)[0]
    assert sure.feasible and sure.probability_feasible >= 0.9


def test_task_current_spread_comes_from_the_usage_model(loads):
    usage = load_usage_config()
    assert loads.information_std_a == pytest.approx(np.std(usage.current_samples_a["information"], ddof=1))
    assert loads.navigation_std_a > 0
