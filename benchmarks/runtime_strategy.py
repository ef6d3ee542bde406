"""Remaining-runtime strategies side by side: the paper's average load vs the predictor's load peaks.

For the bundled information-robot bags (``bags/temi_dynamic_pack1..4``) and the shipped
``params/temi.yaml`` it prints, for ``peak_current_quantile`` 0 (paper) and the given quantiles:

- the runtime evaluation of the paper's 5.1.6 (after 30, 60, ..., 300 min): MAE (min), MAPE (%),
  mean signed error (min);
- the wall time of one runtime prediction (SOC calibration excluded: the same calibrated state
  is reused), median and max over the checkpoints, measured in the same run.

Usage: .venv/bin/python benchmarks/runtime_strategy.py [--quantiles 0.98 0.99 0.995] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quantiles", nargs="+", type=float, default=[0.98, 0.99, 0.995])
    ap.add_argument("--params", default=str(REPO / "params" / "temi.yaml"))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from battery_predictor.evaluation.paper_eval import runtime_evaluation, runtime_summary
    from battery_predictor.fitting.problem import trim_to_discharge
    from battery_predictor.io.loader import load_recording
    from battery_predictor.params import load_params
    from battery_predictor.prediction.calibration import calibrate_soc
    from battery_predictor.prediction.cell_runner import PackRunner
    from battery_predictor.prediction.runtime import predict_remaining_runtime

    params = load_params(args.params)
    recs = [trim_to_discharge(load_recording(REPO / "bags" / f"temi_dynamic_pack{k}")) for k in (1, 2, 3, 4)]
    runner = PackRunner(params)
    cutoff_v = float(params.thresholds["runtime_cutoff_voltage_v"])
    rows = []
    for q in [0.0, *args.quantiles]:
        tic = time.perf_counter()
        summary = runtime_summary(runtime_evaluation(params, recs, peak_current_quantile=q))
        eval_s = time.perf_counter() - tic
        # one prediction at a time, from states along pack 1's discharge (calibration done beforehand)
        rec = recs[0]
        peak_a = float(np.quantile(rec.current_a, q)) if q > 0 else None
        avg_a = float(np.mean(rec.current_a))
        times_s = []
        for t_s in np.arange(1800.0, 18001.0, 1800.0):
            k = int(np.searchsorted(rec.relative_time_s, t_s))
            v, i = float(rec.voltage_v[k]), float(rec.current_a[k])
            cal = calibrate_soc(runner, v, i, 298.15)
            tic = time.perf_counter()
            predict_remaining_runtime(runner, v, i, 298.15, avg_a, cutoff_v, calibration=cal, peak_current_a=peak_a)
            times_s.append(time.perf_counter() - tic)
        rows.append({"peak_current_quantile": q, "mae_min": summary["mae_min"], "mape_pct": summary["mape_pct"],
                     "bias_min": summary["bias_min"],
                     "per_pack_mae_min": [round(v["mae_min"], 1) for v in summary["per_recording"].values()],
                     "prediction_median_s": float(np.median(times_s)), "prediction_max_s": float(np.max(times_s)),
                     "evaluation_s": eval_s})
    if args.json:
        print(json.dumps(rows))
        return 0
    print("| quantile | MAE [min] | MAPE [%] | bias [min] | MAE per pack [min] | prediction median / max [s] |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        q = "0 (paper)" if r["peak_current_quantile"] == 0 else f"{r['peak_current_quantile']:g}"
        print(f"| {q} | {r['mae_min']:.2f} | {r['mape_pct']:.2f} | {r['bias_min']:+.2f} | "
              f"{', '.join(str(x) for x in r['per_pack_mae_min'])} | "
              f"{r['prediction_median_s']:.3f} / {r['prediction_max_s']:.3f} |")
    return 0 if all(math.isfinite(r["mae_min"]) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
