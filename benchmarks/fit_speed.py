"""Fit-speed benchmark on the information robot's 5 h dynamic profile (issue: foundation).

Prints, measured side by side in one run:
- seconds per simulation: liionpack (reference) and the fast path (first build, re-solve with
  changed [input] parameters, rebuild after a geometric change), and their ratio;
- the fast path's agreement with liionpack on that profile (pack voltage RMS in mV, time to
  cut-off difference in %);
- the wall time of a full TPE fit (default 1000 trials, 11 parameters, 2 worker processes);
- peak resident memory of this process and of the fit workers.

Usage: .venv/bin/python benchmarks/fit_speed.py [--trials 1000] [--workers 2] [--liionpack-runs 1]
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from battery_predictor.fitting.optimiser import TPEOptimiser  # noqa: E402
from battery_predictor.fitting.problem import FitProblem  # noqa: E402
from battery_predictor.fitting.space import fit_space  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.profiles.temi import generate_usage_profile  # noqa: E402
from battery_predictor.recording import Recording  # noqa: E402
from battery_predictor.simulation import SimulationRequest, StepLoad  # noqa: E402
from battery_predictor.simulation.fast import FastPackSimulator  # noqa: E402
from battery_predictor.simulation.liionpack_sim import LiionpackSimulator  # noqa: E402


def _peak_mb(who=resource.RUSAGE_SELF) -> float:
    return resource.getrusage(who).ru_maxrss / 1024.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--liionpack-runs", type=int, default=1)
    ap.add_argument("--fast-runs", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    params = load_params(REPO / "params" / "temi.yaml")
    profile = generate_usage_profile(seed=args.seed, max_duration_s=5 * 3600)
    load = StepLoad.from_profile(profile).resample(10.0)
    # start so that the pack reaches its cut-off within the 5 h profile
    req = SimulationRequest(load=load, initial_soc=0.42)
    print(f"profile: Temi usage seed {args.seed}, {load.duration_s / 3600:.2f} h, {len(load.start_s)} steps of 10 s, "
          f"mean {load.mean_current_a():.2f} A; pack {params.name} {params.series}S{params.parallel}P, SOC0 0.42")

    lp_times = []
    for _ in range(args.liionpack_runs):
        t0 = time.perf_counter()
        ref = LiionpackSimulator(period_s=10.0).simulate(params, req)
        lp_times.append(time.perf_counter() - t0)
    fast_sim = FastPackSimulator()
    t0 = time.perf_counter()
    fast = fast_sim.simulate(params, req)
    t_first = time.perf_counter() - t0
    resolve = []
    for k in range(args.fast_runs):
        p = params.with_values({"Electrode height [m]": 0.89719 * (1 + 0.001 * (k + 1))})
        t0 = time.perf_counter()
        fast_sim.simulate(p, req)
        resolve.append(time.perf_counter() - t0)
    thick = []
    for k in range(args.fast_runs):
        p = params.with_values({"Negative electrode thickness [m]": 1.2137e-4 * (1 + 0.001 * (k + 1))})
        t0 = time.perf_counter()
        fast_sim.simulate(p, req)
        thick.append(time.perf_counter() - t0)
    rebuild = []
    for k in range(max(3, args.fast_runs // 3)):
        p = params.with_values({"Negative particle radius [m]": 5.86e-6 * (1 + 0.01 * (k + 1))})
        t0 = time.perf_counter()
        fast_sim.simulate(p, req)
        rebuild.append(time.perf_counter() - t0)

    n = min(len(fast.time_s), len(ref.time_s))
    diff = fast.pack_voltage_v[: n - 1] - ref.pack_voltage_v[: n - 1]
    rms_mv = 1e3 * float(np.sqrt(np.mean(diff**2)))
    runtime_diff_pct = 100.0 * (fast.end_time_s - ref.end_time_s) / ref.end_time_s
    t_lp = float(np.median(lp_times))
    t_fast = float(np.median(resolve))
    print("\n== seconds per simulation (5 h dynamic profile) ==")
    print(f"liionpack (reference, {params.n_cells} cells, 10 s steps): {t_lp:.2f} s  (runs: {len(lp_times)})")
    print(f"fast path, first build + solve:         {t_first:.3f} s")
    print(f"fast path, re-solve ([input] change):   {t_fast:.3f} s  (median of {len(resolve)})")
    print(f"fast path, thickness change (folded):   {float(np.median(thick)):.3f} s  (median of {len(thick)})")
    print(f"fast path, rebuild (particle radius):   {float(np.median(rebuild)):.3f} s  (median of {len(rebuild)})")
    print(f"ratio liionpack / fast re-solve:        {t_lp / t_fast:.0f}x")
    print(f"ratio liionpack / fast thickness:       {t_lp / float(np.median(thick)):.0f}x")
    print(f"ratio liionpack / fast rebuild:         {t_lp / float(np.median(rebuild)):.0f}x")
    print(f"fast path builds in this run:           {fast_sim.builds}")
    print("\n== agreement fast vs liionpack ==")
    print(f"pack voltage RMS difference:            {rms_mv:.2f} mV over {n - 1} samples")
    print(f"terminations: liionpack {ref.termination}, fast {fast.termination}")
    print(f"time to cut-off: liionpack {ref.end_time_s / 3600:.3f} h, fast {fast.end_time_s / 3600:.3f} h, "
          f"difference {runtime_diff_pct:+.3f} %")

    # full TPE fit on the liionpack run as "measured" data, from the shipped params
    rec = Recording(ref.time_s, ref.pack_voltage_v, ref.pack_current_a, source="liionpack-5h")
    problem = FitProblem(params, [rec], FastPackSimulator(), initial_state="params")
    space = fit_space(params)
    with tempfile.TemporaryDirectory() as tmp:
        storage = f"sqlite:///{Path(tmp) / 'bench.db'}"
        opt = TPEOptimiser(n_trials=args.trials, seed=args.seed, storage=storage, workers=args.workers,
                           progress=False)
        t0 = time.perf_counter()
        result = opt.run(problem, space)
        wall = time.perf_counter() - t0
    print(f"\n== full fit: {args.trials} TPE trials, {len(space)} parameters, {args.workers} worker(s) ==")
    print(f"wall time:                              {wall:.0f} s ({wall / 60:.1f} min)")
    print(f"per trial (wall):                       {wall / args.trials:.3f} s")
    print(f"best R2_mod:                            {result.best_r2_mod:.4f}  (failed trials: "
          f"{result.failed_trials})")
    print("\n== peak resident memory ==")
    print(f"this process:                           {_peak_mb():.0f} MB")
    print(f"largest fit worker (children):          {_peak_mb(resource.RUSAGE_CHILDREN):.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
