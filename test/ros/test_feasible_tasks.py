"""``/feasible_tasks`` through the real monitor + predictor nodes (information robot, temi node params).

Relay samples (``/battery/voltage``, ``/battery/current``, 1 s apart) put the pack first at
15.0 V / 1.7 A (well charged), then at 13.45 V / 1.7 A (just above the 13.30 V return voltage,
lock step on ``/clock``). Over the middleware: a valid request is answered task by task with the
predicted end-of-task voltage and remaining time and a summary; a task the pack cannot do is
answered infeasible with the reason; malformed requests are answered ``valid = false`` with the
reason, and the service keeps answering.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
from battery_predictor_msgs.msg import Task
from battery_predictor_msgs.srv import FeasibleTasks
from rclpy.context import Context
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64

from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.replay import BagMessage, stream_from_messages

from ._helpers import T0_NS, S, call_service

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]


def relay(start_s: float, end_s: float, voltage_v: float, current_a: float) -> list[BagMessage]:
    out = []
    for k in range(round(end_s - start_s)):
        t_ns = T0_NS + round((start_s + k) * S)
        out.append(BagMessage(t_ns, "/battery/voltage", "std_msgs/msg/Float64",
                              serialize_message(Float64(data=voltage_v))))
        out.append(BagMessage(t_ns, "/battery/current", "std_msgs/msg/Float64",
                              serialize_message(Float64(data=current_a))))
    return out


def call(session: ReplaySession, request: FeasibleTasks.Request, timeout_s: float = 60.0) -> FeasibleTasks.Response:
    """Call the service over the middleware from the session's client node."""
    return call_service(session, FeasibleTasks, session.predictor.tasks_service.srv_name, request, timeout_s)


def task(name: str, kind: int, duration_s: float = 0.0, destination: str = "", **kw) -> Task:
    return Task(name=name, kind=kind, duration_s=duration_s, destination=destination, **kw)


INFO, NAV = Task.KIND_INFORMATION, Task.KIND_NAVIGATION
TASKS = [task("tickets", INFO, 300.0), task("to the restroom", NAV, destination="restroom"),
         task("ten hours of talk", INFO, 10 * 3600.0), task("one more ticket", INFO, 120.0)]
MALFORMED = {
    "kind": [task("x", 7, 60.0)],
    "duration_s": [task("x", INFO, math.nan)],
    "needs a duration_s": [task("x", INFO)],
    "profile_current_a": [task("x", INFO, 60.0, profile_duration_s=[10.0, 10.0], profile_current_a=[1.0])],
    "current_a": [task("x", INFO, 60.0, current_a=-3.0)],
    "not on the map": [task("x", NAV, destination="platform 9 3/4")],
}


NUMBERS = [math.nan, math.inf, -math.inf, -1.0, 0.0, 1e-9, 0.5, 60.0, 3600.0, 1e9, 1e308, -1e308, 5e-324]
N_FUZZ = 100


def random_request(rng: np.random.Generator) -> FeasibleTasks.Request:
    """A seeded random, mostly malformed request (within what the interface can carry)."""
    def num(normal: float) -> float:
        return float(rng.choice(NUMBERS)) if rng.random() < 0.3 else normal

    tasks = []
    for _ in range(int(rng.integers(0, 5)) if rng.random() > 0.05 else 100):
        n = int(rng.integers(0, 4)) if rng.random() < 0.2 else 0
        tasks.append(Task(name=str(rng.choice(["", "a", "ü→∂ 🚂", "x" * 80])),
                          kind=int(rng.choice([0, 1, 2, 255])) if rng.random() < 0.2 else int(rng.integers(2)),
                          duration_s=num(float(rng.uniform(0.0, 1800.0))),
                          destination=str(rng.choice(["", "restroom", "entrance", "moon", "x" * 64])),
                          current_a=num(0.0), profile_duration_s=[num(30.0) for _ in range(n)],
                          profile_current_a=[num(2.0) for _ in range(n + int(rng.random() < 0.3))]))
    return FeasibleTasks.Request(tasks=tasks, location=str(rng.choice(["", "entrance", "restroom", "nowhere"])),
                                 policy=int(rng.choice([0, 1, 2, 3, 255])))


def test_feasible_tasks_valid_infeasible_and_malformed(ros_context: Context) -> None:
    stream = stream_from_messages(relay(0.0, 60.0, 15.0, 1.7) + relay(60.0, 120.0, 13.45, 1.7), style="relay",
                                  battery_topic="/battery")
    with ReplaySession(stream, context=ros_context, params_file=str(REPO / "params/ros/temi_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": 30.0}, rate=0) as session:
        session.play_until(T0_NS + 59 * S)
        t0 = time.perf_counter()
        charged = call(session, FeasibleTasks.Request(tasks=TASKS, location="entrance",
                                                      policy=FeasibleTasks.Request.POLICY_GREEDY))
        latency_s = time.perf_counter() - t0
        ordered = call(session, FeasibleTasks.Request(tasks=TASKS, location="entrance",
                                                      policy=FeasibleTasks.Request.POLICY_ORDERED))
        malformed = {key: call(session, FeasibleTasks.Request(tasks=tasks, location="entrance"))
                     for key, tasks in MALFORMED.items()}
        bad_location = call(session, FeasibleTasks.Request(tasks=TASKS[:1], location="platform 9 3/4"))
        bad_policy = call(session, FeasibleTasks.Request(tasks=TASKS[:1], policy=9))
        rng = np.random.default_rng(14)
        fuzz = [(req, call(session, req)) for req in (random_request(rng) for _ in range(N_FUZZ))]
        after_fuzz = call(session, FeasibleTasks.Request(tasks=TASKS[:1], location="entrance"))
        session.play_until()
        low = call(session, FeasibleTasks.Request(tasks=TASKS, location="restroom"))
    print(f"feasible_tasks latency {latency_s * 1000:.0f} ms; {charged.summary}; low: {low.summary}")
    assert charged.valid, charged.reason
    ok = [r.feasible for r in charged.results]
    assert ok == [True, True, False, True], [r.reason for r in charged.results]
    for r in charged.results[:2]:
        assert 13.30 < r.end_voltage_v < 16.4 and r.margin_v > 0 and r.remaining_after_s > 3600, r.reason
    assert "skipped (greedy)" in charged.results[2].reason
    # the walk from the entrance to the restroom: 60 m at 0.90 m/s
    assert charged.results[1].end_location == "restroom"
    assert charged.results[1].duration_s == pytest.approx(60.0 / 0.9)
    assert charged.more_guided_walks > 10 and charged.more_information_s > 3600
    assert f"about {charged.more_guided_walks} more guided walks" in charged.summary
    assert charged.feasible_count == 3
    assert [r.feasible for r in ordered.results] == [True, True, False, False]
    assert "follows the infeasible task" in ordered.results[3].reason

    for key, answer in malformed.items():
        assert not answer.valid or not any(r.feasible for r in answer.results), key
        text = answer.reason + " ".join(r.reason for r in answer.results)
        assert key in text, (key, text)
    assert not bad_location.valid and "location 'platform 9 3/4' is not on the map" in bad_location.reason
    assert not bad_policy.valid and "policy 9" in bad_policy.reason
    for req, answer in fuzz:  # every answer carries a reason; the service survives them all
        assert answer.reason and all(r.reason for r in answer.results)
        if req.policy > 2 or any(t.kind > 1 for t in req.tasks):
            assert not answer.valid and not any(r.feasible for r in answer.results), answer.reason
        for r in answer.results:
            assert not r.feasible or (r.margin_v >= 0 and r.end_voltage_v > 13.30), r.reason
    assert sum(a.valid for _, a in fuzz) > 5 and sum(not a.valid for _, a in fuzz) > 5
    assert after_fuzz.valid and after_fuzz.results[0].feasible, after_fuzz.reason

    assert low.valid, low.reason
    assert not any(r.feasible for r in low.results), [r.reason for r in low.results]
    assert low.results[0].margin_v < 0 and "walk back to the charger from restroom" in low.results[0].reason
    assert "falls to 13.30 V" in low.results[2].reason
    assert low.more_guided_walks == 0 and low.more_information_s == 0
    assert low.summary == "I need to return to my charger now."
