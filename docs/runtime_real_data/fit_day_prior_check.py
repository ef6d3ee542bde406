"""Futures that draw blocks from the fit day as well as the day so far: a load prior, measured after the fact.

An analysis, not part of the package (docs/runtime_real_data/README.md, "A load prior from the fit day in the
Temi's futures"). For days kept by ``benchmarks/runtime_far_truth.py --work W`` (``W/s<seed>_day1.csv``, the fit
day, ``W/fit<seed>.yaml`` and ``W/s<seed>_day2.csv``), it scores day 2 as that benchmark does, with the
package's ``sampled_ends_s`` handed a history that is the day so far followed by the fit day's 5 s windows,
scaled to the day so far's mean current: each future's 600 s blocks then come from either day in proportion to
its length, and the futures' mean still follows the average load ahead.

Run from the repository::

    nice .venv/bin/python docs/runtime_real_data/fit_day_prior_check.py W 260 261 262 [--end-event auto]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

import runtime_far_truth as benchmark  # noqa: E402

import battery_predictor.prediction.runtime as runtime  # noqa: E402
from battery_predictor.evaluation.runtime_eval import Windows  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402

SHIPPED = runtime.sampled_ends_s
FIT_DAY_A: list[np.ndarray] = []


def with_fit_day(runner, start, history_a, window_s, *args, **kwargs):
    """The shipped futures, drawn from the day so far followed by the fit day (scaled to the day's mean)."""
    history_a = np.asarray(history_a, dtype=float)
    if FIT_DAY_A and history_a.size and np.mean(history_a) > 0:
        prior = FIT_DAY_A[0] * (np.mean(history_a) / np.mean(FIT_DAY_A[0]))
        history_a = np.concatenate([history_a, prior])
    return SHIPPED(runner, start, history_a, window_s, *args, **kwargs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("work", type=Path)
    ap.add_argument("seeds", nargs="+", type=int)
    ap.add_argument("--end-event", default="auto")
    args = ap.parse_args()
    runtime.sampled_ends_s = with_fit_day
    errors, over_half = [], 0
    for seed in args.seeds:
        day1 = args.work / f"s{seed}_day1.csv"  # not kept where day 2 never reaches the threshold
        FIT_DAY_A[:] = [Windows.of(load_recording(day1)).current_a] if day1.exists() else []
        row = benchmark.run_seed(seed, "params", args.work, end_event=args.end_event)
        errors += row.get("errors_min", [])
        over_half += row.get("off_by_half_after_30pct", 0)
        print(seed, row.get("errors_min", row.get("skipped")), flush=True)
    print(json.dumps({"answers": len(errors), "mae_min": round(float(np.mean(np.abs(errors))), 2),
                      "bias_min": round(float(np.mean(errors)), 2), "off_by_half_after_30pct": over_half}))


if __name__ == "__main__":
    main()
