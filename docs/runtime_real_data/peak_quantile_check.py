"""The predictor's held-out runtime with another peak source and quantile (an analysis, not part of the package).

``evaluate-runtime`` has ``--peak-source`` but not the peak quantile; this runs the same evaluation
(``evaluation.runtime_eval.evaluate_recording``, the node's core fed 5 s windows) with
``PredictorConfig(peak_source=SOURCE, peak_current_quantile=Q)`` and prints per recording and pooled MAE / bias and
the answers off by more than half after 30 % of a discharge (docs/runtime_real_data/README.md, "A depth resistance
from the HPPC, and the largest sample as the peak").

Run from the repository::

    .venv/bin/python docs/runtime_real_data/peak_quantile_check.py FIT.yaml sample 1.0 $D/drive_T10C_Cycle1.csv ...
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from battery_predictor.evaluation.runtime_eval import evaluate_recording  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.prediction.core import PredictorConfig  # noqa: E402

CUTOFF_V = 2.5
LATE_AFTER = 0.3


def main(argv: list[str]) -> int:
    if len(argv) < 4:
        sys.stderr.write(__doc__ or "")
        return 2
    params_file, source, quantile, files = argv[0], argv[1], float(argv[2]), argv[3:]
    params = load_params(params_file)
    config = PredictorConfig(params_file=params_file, cutoff_voltage_v=CUTOFF_V, peak_source=source,
                             peak_current_quantile=quantile)
    pooled, over = [], []
    for name in files:
        rec = load_recording(Path(name), duplicate_times="keep_last")
        result = evaluate_recording(params, rec, cutoff_v=CUTOFF_V, capacities_ah={}, config=config)
        errors = [(cp.predicted_s - cp.true_remaining_s) / 60.0 for cp in result.checkpoints if cp.valid]
        pooled += errors
        over += [f"{Path(name).stem} at {cp.fraction:.0%}: {cp.predicted_s / 60:.1f} vs {cp.true_remaining_s / 60:.1f} min"
                 for cp in result.checkpoints if cp.valid and cp.fraction >= LATE_AFTER - 1e-9
                 and abs(cp.predicted_s - cp.true_remaining_s) > 0.5 * cp.true_remaining_s]
        if errors:
            print(f"{Path(name).stem}: MAE {sum(map(abs, errors)) / len(errors):.1f} min, "
                  f"bias {sum(errors) / len(errors):+.1f} min, {len(errors)} answers")
    if pooled:
        print(f"pooled: MAE {sum(map(abs, pooled)) / len(pooled):.2f} min, bias {sum(pooled) / len(pooled):+.2f} min, "
              f"{len(pooled)} answers; off by > 50 % after {LATE_AFTER:.0%}: {len(over)}")
    for line in over:
        print(f"  {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
