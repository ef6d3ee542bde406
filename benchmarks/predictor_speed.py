"""The predictor core's answer times on both pack models side by side (no ROS).

A route answer (the paper's longest route, 20-80 kg, from a calibrated Ranger state) and a
remaining-runtime update with a full history calibration (temi, fresh core each time), on PyBaMM
stepping (``simulator: pybamm``) and on the SPM engine (``simulator: engine``). Both must give the
same answers; the script prints them.

``--route-temperature-k`` sets the measured temperature of the route answers (default 298.15 K, the
fit temperature: one route run; away from it, e.g. 297.15 K as ``ros_latency.py`` feeds, a route
answer adds the two activation-energy scenario runs). ``--only engine`` skips PyBaMM stepping.

Run: ``.venv/bin/python benchmarks/predictor_speed.py [--repeat 5] [--route-temperature-k 297.15] [--only engine]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from battery_predictor.prediction.core import PredictorConfig, PredictorCore
from battery_predictor.profiles.ranger import longest_route

PARAMS = Path(__file__).resolve().parents[1] / "params"
T_K = 298.15


def route_times_s(simulator: str, repeat: int, temperature_k: float = T_K) -> tuple[list[float], float]:
    core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "ranger_mini.yaml"), simulator=simulator))
    for k in range(130):
        core.update_state(5.0 * k, 49.6, 1.7 if k % 3 else 6.0, temperature_k)
    now = 5.0 * 129 + 1.0
    core.can_accept_route(longest_route(60.0).sections, now)  # calibration and first use
    times, volts = [], []
    for _ in range(repeat):
        for kg in (20.0, 40.0, 60.0, 80.0):
            t0 = time.perf_counter()
            decision = core.can_accept_route(longest_route(kg).sections, now)
            times.append(time.perf_counter() - t0)
            volts.append(decision.predicted_voltage_v)
    return times, float(volts[-1])


def runtime_times_s(simulator: str, repeat: int) -> tuple[list[float], float]:
    times, remaining = [], float("nan")
    for rep in range(repeat + 1):
        core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml"), simulator=simulator))
        for k in range(130):
            core.update_state(5.0 * k, 15.2, 1.0 if k % 5 else 6.0, T_K)
        t0 = time.perf_counter()
        remaining = core.remaining_runtime(5.0 * 129 + 1.0).remaining_s
        if rep > 0:  # the first builds and compiles
            times.append(time.perf_counter() - t0)
    return times, remaining


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--route-temperature-k", type=float, default=T_K,
                    help="measured temperature of the route answers, K (default 298.15, the fit temperature)")
    ap.add_argument("--only", choices=("pybamm", "engine"), default=None, help="one pack model only")
    args = ap.parse_args()
    print(f"{'model':<8} {'route median':>13} {'route p95':>10} {'V after 80 kg':>14} "
          f"{'runtime update':>15} {'remaining':>10}")
    for sim in (args.only,) if args.only else ("pybamm", "engine"):
        route, volt = route_times_s(sim, args.repeat, args.route_temperature_k)
        runtime, remaining = runtime_times_s(sim, args.repeat)
        print(f"{sim:<8} {1e3 * np.median(route):>10.1f} ms {1e3 * np.quantile(route, 0.95):>7.1f} ms "
              f"{volt:>12.3f} V {1e3 * np.median(runtime):>12.0f} ms {remaining / 60:>7.1f} min")


if __name__ == "__main__":
    main()
