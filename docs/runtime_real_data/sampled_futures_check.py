"""Where the far-truth Temi days' runtime error comes from with ``end_event: sampled``: the state, or the load ahead.

An analysis, not part of the package (docs/runtime_real_data/README.md, "The far-truth days' remaining error is
the load ahead"). For days kept by ``benchmarks/runtime_far_truth.py --work W`` (``W/fit<seed>.yaml`` and
``W/s<seed>_day2.csv``), the predictor's core (node defaults, ``end_event sampled``) is fed the day's 5 s windows
as ``evaluate-runtime`` feeds them; at 30 % .. 90 % of the discharge it prints

- ``truth``: the time left until the day's first window at or below 13.30 V (min);
- ``answer``: the core's answer (min);
- ``known load``: the model run from the core's calibrated state with the day's *actual* windows ahead (min):
  what the answer would be if the load ahead were known;
- ``PIT``: the share of 40 sampled futures (the core's own ``sampled_ends_s``) that end before the truth. For
  futures drawn like the day's own future it would be uniform on 0..1. (Until 2026-11-28 it was the share of 20
  quantiles of the 40 ends, each quantile running the futures again; the figures in the README were made so.)

Run from the repository::

    nice .venv/bin/python docs/runtime_real_data/sampled_futures_check.py W 220 221 222 [--cutoff-v 45.0]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import battery_predictor.prediction.runtime as runtime  # noqa: E402
from battery_predictor.evaluation.runtime_eval import Windows, find_discharge, nominal_capacity_ah  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.prediction.core import PredictorConfig, PredictorCore  # noqa: E402

THRESHOLD_V = 13.30
SHIPPED = runtime.sampled_end_s


def check_day(work: Path, seed: int, cutoff_v: float = THRESHOLD_V) -> list[float]:
    """Print one day's checkpoints to ``cutoff_v`` (V); return their PIT values."""
    fit = work / f"fit{seed}.yaml"
    params = load_params(fit)
    win = Windows.of(load_recording(work / f"s{seed}_day2.csv"))
    discharge = find_discharge(win, cutoff_v, start_current_a=nominal_capacity_ah(params) / 100.0, end_margin_v=0.5 * params.series)
    core = PredictorCore(PredictorConfig(params_file=str(fit), cutoff_voltage_v=cutoff_v, end_event="sampled"),
                         params=params)
    seen: dict = {}

    def capture(runner, start, history_a, window_s, average, temperature_k, cutoff_v, average_end_s, **kw):
        seen.update(runner=runner, start=start, temperature_k=temperature_k,
                    ends=runtime.sampled_ends_s(runner, start, history_a, window_s, average, temperature_k, cutoff_v,
                                                average_end_s, futures=40))
        return SHIPPED(runner, start, history_a, window_s, average, temperature_k, cutoff_v, average_end_s, **kw)

    runtime.sampled_end_s = capture
    pits, k, t = [], 0, win.time_s
    try:
        for fraction in np.arange(0.3, 0.95, 0.1):
            t_cp = discharge.start_s + fraction * (discharge.end_s - discharge.start_s)
            while k < t.size and t[k] <= t_cp:
                core.update_state(t[k], win.voltage_v[k], win.current_a[k], win.temperature_k[k],
                                  win.peak_current_a[k])
                core.precalibrate()
                k += 1
            core._sampled = None  # run the futures at every checkpoint
            seen.clear()
            answer = core.remaining_runtime(float(t[k - 1]))
            truth_s = discharge.end_s - float(t[k - 1])
            if "ends" not in seen:
                print(f"  {fraction:.1f}: no sampled answer ({answer.reason})")
                continue
            ahead = [(5.0, float(c)) for c in win.current_a[k:]] + [(5.0, float(win.current_a[-1]))] * 200
            run = seen["runner"].run(seen["start"], ahead, seen["temperature_k"])
            known_s = runtime.time_to_voltage_s(run.time_s, run.pack_voltage_v, cutoff_v)
            pit = float(np.mean(seen["ends"] < truth_s))
            pits.append(pit)
            print(f"  {fraction:.1f}: truth {truth_s / 60:6.1f}  answer {answer.remaining_s / 60:6.1f}  known load "
                  f"{(known_s or math.nan) / 60:6.1f}  PIT {pit:.2f}")
    finally:
        runtime.sampled_end_s = SHIPPED
    return pits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("work", type=Path)
    ap.add_argument("seeds", nargs="+", type=int)
    ap.add_argument("--cutoff-v", type=float, default=THRESHOLD_V,
                    help="the days' cut-off, V (13.30, the Temi's; 45.0 for `runtime_far_truth.py --pack ranger` days)")
    args = ap.parse_args()
    day_means = []
    for seed in args.seeds:
        print(f"seed {seed}")
        pits = check_day(args.work, seed, args.cutoff_v)
        if pits:
            day_means.append(float(np.mean(pits)))
    if day_means:
        print(f"{len(day_means)} days: mean PIT {np.mean(day_means):.2f}, days above 0.5: "
              f"{sum(m > 0.5 for m in day_means)}")


if __name__ == "__main__":
    main()
