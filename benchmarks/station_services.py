"""Figures of the station services (no ROS): answer times and what the answers say.

* ``/feasible_tasks`` core (information robot, temi params, SPM engine): answer time for four
  tasks (greedy, with the summary) from model states at several SOCs; the summary's guided walks
  and minutes of information; how much information time the walk back to the charger costs
  (entrance, 45 m, vs restroom, 105 m).
* ``/plan_route`` core (luggage robot, Ranger params): answer time of an accepted plan and of a
  rejected one (with its alternatives); the lowest rested SOC at the charger that lets the
  paper's longest job (charger -> platform 11 south -> platform 13 south -> charger) end at or
  above 46.31 V at 1.70 A, per payload; whether a least-charge path ever differs from the
  shortest one on the shipped Minden graph.

Run: ``.venv/bin/python benchmarks/station_services.py [--repeat 5]``
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time
from pathlib import Path

from battery_predictor.prediction.core import PredictorConfig, PredictorCore
from battery_predictor.prediction.planning import PlanRequest, RoutePlanner, plan_from_core
from battery_predictor.prediction.route import evaluate_route
from battery_predictor.prediction.tasks import POLICY_GREEDY, Task, TaskLoads, TaskPlanner
from battery_predictor.profiles.station import load_station
from battery_predictor.profiles.temi import load_usage_config

PARAMS = Path(__file__).resolve().parents[1] / "params"
T_K = 298.15
TASKS = [Task("tickets", "information", 300.0), Task("to the restroom", "navigation", destination="restroom"),
         Task("long talk", "information", 2700.0), Task("to the ticket machine", "navigation",
                                                        destination="ticket_machine")]


def fed_core(core: PredictorCore, voltage_v: float, current_a: float) -> PredictorCore:
    c = PredictorCore(core.config, params=core.params)
    for k in range(60):
        c.update_state(1000.0 + k, voltage_v, current_a, T_K)
    return c


def ms(times: list[float]) -> str:
    return f"median {1e3 * statistics.median(times):.1f} ms, max {1e3 * max(times):.1f} ms"


def tasks_figures(repeat: int) -> None:
    core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml")))
    task_map = load_station(PARAMS / "minden_information_map.yaml")
    loads = TaskLoads.from_usage(load_usage_config(), 0.90)
    planner = TaskPlanner(core.runner, task_map, "charger", loads, 13.30, T_K, 1.70)
    print(f"feasible tasks (temi, {core.model_backend}): information {loads.information_current_a:.2f} A, "
          f"navigation {loads.navigation_current_a:.2f} A, walk back at {loads.return_current_a:.2f} A")
    print("| SOC | answer time (4 tasks, greedy, summary) | feasible | guided walks (60 m and back) | "
          "information, min | information from the restroom, min |")
    print("|---|---|---|---|---|---|")
    for soc in (0.9, 0.6, 0.3, 0.2):
        state = core.runner.run(soc, [(60.0, 1.7)], T_K).final_state  # a state with gradients, as calibrated
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            plan = planner.evaluate(state, "entrance", TASKS, POLICY_GREEDY)
            times.append(time.perf_counter() - t0)
        far = planner.max_time_s(state, "restroom", loads.information_current_a)
        print(f"| {soc:.1f} | {ms(times)} | {plan.feasible_count}/4 | {plan.more_guided_walks} | "
              f"{plan.more_information_s / 60:.0f} | {far / 60:.1f} (entrance: "
              f"{planner.max_time_s(state, 'entrance', loads.information_current_a) / 60:.1f}) |")


def route_figures(repeat: int) -> None:
    core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "ranger_mini.yaml")))
    station = load_station(PARAMS / "minden_station.yaml")
    planner = RoutePlanner(station)
    job = PlanRequest("platform13_north", "platform11_south", "platform13_south", 80.0)
    print(f"\nplan route (Ranger, {core.model_backend}): job {job.start_node} -> {job.pickup} -> {job.dropoff} "
          "-> charger, 80 kg")
    for label, v, i in (("charged, 49.8 V at 3.0 A", 49.8, 3.0), ("knee, 47.6 V at 1.7 A", 47.6, 1.7)):
        c = fed_core(core, v, i)
        plan_from_core(c, planner, job, 1060.0)  # calibration
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            plan = plan_from_core(c, planner, job, 1060.0)
            times.append(time.perf_counter() - t0)
        alts = ", ".join(f"{a.kind} {'feasible' if a.feasible else 'infeasible'}" for a in plan.alternatives)
        print(f"  {label}: {'accepted' if plan.accepted else 'rejected'}, margin "
              f"{plan.route.decision.margin_v:+.2f} V, {ms(times)}; alternatives: {alts or 'none'}")
    print("  lowest rested SOC at the charger for the paper's longest job (890 m):")
    lo_bound = core.runner.soc_bounds[0]
    for kg in (0.0, 20.0, 40.0, 60.0, 80.0):
        secs = planner.job(PlanRequest("charger", "platform11_south", "platform13_south", kg), "charger", 0.0,
                           planner.shortest)[1]
        lo, hi = lo_bound, 1.0
        while hi - lo > 0.001:
            mid = 0.5 * (lo + hi)
            ok = evaluate_route(core.runner, mid, secs, T_K, threshold_v=46.31, standstill_current_a=1.70).accepted
            lo, hi = (lo, mid) if ok else (mid, hi)
        print(f"    {kg:>4.0f} kg: SOC >= {hi:+.3f} (model SOC scale; 0 = the OCV at the 0 % point)")
    differ = 0
    pairs = list(itertools.permutations(sorted(station.nodes), 2))
    for (a, b), kg in itertools.product(pairs, (0.0, 80.0)):
        differ += planner.least_charge(a, b, kg).nodes != planner.shortest(a, b, kg).nodes
    print(f"  least-charge path differs from the shortest for {differ} of {2 * len(pairs)} (pair, payload 0/80 kg) "
          "on the shipped Minden graph")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    tasks_figures(args.repeat)
    route_figures(args.repeat)


if __name__ == "__main__":
    main()
