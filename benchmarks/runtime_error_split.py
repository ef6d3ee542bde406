"""Where the remaining-runtime error comes from: the load forecast, or the state and the model.

For each recording (CSV or bag, discharging to the cut-off) and a fitted params file it prints, at the
checkpoints of ``evaluate-runtime`` (10 % .. 90 % of the discharge, node defaults, the monitor's 5 s
windows carried window by window):

- **predictor**: the answers as ``evaluate-runtime`` gives them (MAE, bias, answers after 30 % off by more
  than half the true remaining time);
- **load known**: the same core, the same state, but at each checkpoint its load estimator is fed the
  windows still to come instead of those so far (mean, power, load kind and peaks of the *future* load): an
  oracle no predictor has, which removes the load forecast's error and leaves the state's and the model's;
- **start SOC**: the model's state of charge at the discharge's start that makes the model, driven open
  loop by the recording's own windows at their mean temperature, reach the cut-off exactly at the measured
  end, against the state the predictor calibrated from the voltage at the first checkpoint carried back by
  the same windows. A recording whose consistent start lies far below the others' (same cell, same full
  charge) holds less charge than the model for that load, and no voltage reading at the start shows it.

The load-known answers reach into the core (its load estimator is swapped for each answer): an instrument
for this diagnosis, not an interface.

Usage::

    .venv/bin/python benchmarks/runtime_error_split.py --params FIT.yaml --data A.csv B.csv ... [--cutoff-v V] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
#: How close (s) the open-loop run must end to the measured end for its start SOC to count.
END_TOLERANCE_S = 60.0


def _future_estimator(core, win, now_s: float, end_s: float):
    """A load estimator of the core's settings fed the windows after ``now_s`` up to ``end_s``."""
    est = core._fresh_load_estimator()
    ahead = (win.time_s > now_s) & (win.time_s <= end_s)
    for t, i, peak, v in zip(win.time_s[ahead], win.current_a[ahead], win.peak_current_a[ahead],
                             win.voltage_v[ahead], strict=True):
        est.add(float(t), float(i), float(peak), float(v))
    return est


def _time_to_cutoff_s(runner, start, segments, temperature_k: float, cutoff_v: float) -> float:
    from battery_predictor.prediction.runtime import run_end_s

    run = runner.run(start, segments, temperature_k)
    end = run_end_s(run, cutoff_v)
    return math.inf if end is None else float(end)


def consistent_start_soc(runner, win, start_s: float, end_s: float, cutoff_v: float) -> float:
    """Start SOC whose open-loop run under the recording's windows reaches ``cutoff_v`` at ``end_s`` (NaN if none)."""
    from scipy.optimize import brentq

    keep = (win.time_s > start_s) & (win.time_s <= end_s + 3600.0)
    temperature_k = float(np.nanmean(win.temperature_k[keep]))
    segments = [(5.0, float(i)) for i in win.current_a[keep]]
    target_s = end_s - start_s
    lo, hi = runner.soc_bounds

    def gap(soc: float) -> float:
        return min(_time_to_cutoff_s(runner, soc, segments, temperature_k, cutoff_v), 2 * target_s) - target_s

    try:
        soc = float(brentq(gap, lo + 0.02, hi, xtol=1e-4))
    except ValueError:
        return math.nan
    # a root only where the run ends near the measured end (not a jump to "never" past the windows)
    return soc if abs(gap(soc)) <= END_TOLERANCE_S else math.nan


def split_recording(params, rec, cutoff_v: float) -> dict:
    """Predictor answers, load-known answers and start SOCs of one recording."""
    from battery_predictor.evaluation import runtime_eval as ev
    from battery_predictor.prediction.core import PredictorConfig, PredictorCore

    win = ev.Windows.of(rec)
    discharge = ev._discharge_of(params, win, cutoff_v, None)
    if not discharge.known:
        return {"source": str(rec.source), "skipped": "the discharge does not end at the cut-off"}
    core = PredictorCore(PredictorConfig(params_file=str(params.source), cutoff_voltage_v=cutoff_v), params=params)
    rows, k, first_cal = [], 0, None
    for fraction in ev.DEFAULT_CHECKPOINTS:
        t_cp = discharge.start_s + fraction * (discharge.end_s - discharge.start_s)
        while k < win.time_s.size and win.time_s[k] <= t_cp:
            core.update_state(win.time_s[k], win.voltage_v[k], win.current_a[k], win.temperature_k[k],
                              win.peak_current_a[k])
            core.precalibrate()
            k += 1
        now = float(win.time_s[k - 1])
        answer = core.remaining_runtime(now)
        own = core._load
        core._load = _future_estimator(core, win, now, discharge.end_s)
        try:
            known = core.remaining_runtime(now)
        finally:
            core._load = own
        if first_cal is None:
            state = core.latest_state()
            first_cal = (now, core.calibration(core._temperature(state[3])).soc)
        rows.append({"fraction": fraction, "true_min": (discharge.end_s - now) / 60,
                     "predictor_min": answer.remaining_s / 60 if answer.valid else math.nan,
                     "load_known_min": known.remaining_s / 60 if known.valid else math.nan})
    runner = core.runner
    start_soc = consistent_start_soc(runner, win, discharge.start_s, discharge.end_s, cutoff_v)
    # the first calibration carried back to the start by the model's charge (SOC is charge over capacity)
    drawn_ah = win.charge_ah(discharge.start_s, first_cal[0])
    calibrated_start = first_cal[1] + drawn_ah / runner.capacity_ah
    return {"source": str(rec.source), "rows": rows, "consistent_start_soc": start_soc,
            "calibrated_start_soc": calibrated_start, "capacity_ah": runner.capacity_ah}


def figures(rows: list[dict], key: str) -> dict:
    """MAE and bias (min, :func:`~battery_predictor.evaluation.runtime_eval.error_summary`) of the answers ``key``,
    and how many after the first 30 % of the discharge are off by more than half the true remaining time."""
    from battery_predictor.evaluation.runtime_eval import error_summary

    summary = error_summary([(60.0 * r[key], 60.0 * r["true_min"]) for r in rows])
    late = [abs(r[key] - r["true_min"]) / r["true_min"] > 0.5 for r in rows if r["fraction"] > 0.3]
    return {"mae_min": summary["mae_min"], "bias_min": summary["bias_min"], "over_half_after_30pct": int(sum(late))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--params", required=True)
    ap.add_argument("--data", nargs="+", required=True)
    ap.add_argument("--cutoff-v", type=float, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from battery_predictor.io.loader import load_recording
    from battery_predictor.params import load_params
    from battery_predictor.prediction.core import PredictorConfig, PredictorCore

    params = load_params(args.params)
    cutoff_v = args.cutoff_v if args.cutoff_v is not None else \
        PredictorCore(PredictorConfig(params_file=str(params.source)), params=params).cutoff_voltage_v
    out = []
    for path in args.data:
        res = split_recording(params, load_recording(path), cutoff_v)
        out.append(res)
        if args.json or "rows" not in res:
            continue
        p, o = figures(res["rows"], "predictor_min"), figures(res["rows"], "load_known_min")
        print(f"{Path(path).name}: predictor MAE {p['mae_min']:.1f} min (bias {p['bias_min']:+.1f}, "
              f"{p['over_half_after_30pct']} over 50 %); load known {o['mae_min']:.1f} min (bias {o['bias_min']:+.1f}, "
              f"{o['over_half_after_30pct']} over 50 %); start SOC consistent with the end "
              f"{res['consistent_start_soc']:.3f}, calibrated {res['calibrated_start_soc']:.3f}")
    scored = [r for r in out if "rows" in r]
    pooled = {key: figures([row for r in scored for row in r["rows"]], key)
              for key in ("predictor_min", "load_known_min")}
    if args.json:
        print(json.dumps({"params": args.params, "cutoff_v": cutoff_v, "recordings": out, "pooled": pooled},
                         indent=1, default=float))
    else:
        for key, f in pooled.items():
            print(f"pooled {key[:-4]}: MAE {f['mae_min']:.2f} min, bias {f['bias_min']:+.2f}, "
                  f"{f['over_half_after_30pct']} answers over 50 % after 30 %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
