"""The predictor's held-out runtime with an ohmic floor under its load peaks (an analysis, not part of the package).

The tester stops a drive cycle on a single sample, and the cell's sub-second step is ohmic (current-independent)
where the fitted SPM's is Butler-Volmer (smaller at large currents). This runs ``evaluate_recording`` (the node's
core fed 5 s windows) with ``PredictorConfig(peak_source=SOURCE, peak_current_quantile=Q)`` and, with ``--ohmic``,
raises the cut-off of the peak-load crossing by ``R_step (T) * (I_peak - I_avg) - model drop`` where the model's own
drop under the peak is smaller: ``R_step`` is the fit data's step resistance (``recording.step_resistance_ohm``)
scaled by the model's 5 s pulse resistance at the run's temperature over that at the fit data's mean temperature.
It prints per recording and pooled MAE / bias and the answers off by more than half after 30 % of a discharge
(docs/runtime_real_data/README.md, "Five more of the source's recordings"). Without ``--ohmic`` it is the peak
source and quantile alone (``--peak-source sample --quantile 1.0``: "The largest sample as the peak" there; this
script replaces ``peak_quantile_check.py``, which measured that).

Run from the repository::

    .venv/bin/python docs/runtime_real_data/ohmic_peak_check.py --params FIT.yaml --fit-data HWFET.csv LA92.csv \
        [--ohmic] [--peak-source sample] [--quantile 0.99] --data A.csv B.csv ...
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from battery_predictor.evaluation.runtime_eval import evaluate_recording  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.prediction import runtime  # noqa: E402
from battery_predictor.prediction.core import PredictorConfig  # noqa: E402
from battery_predictor.prediction.safety import pulse_resistance_ohm  # noqa: E402
from battery_predictor.recording import step_resistance_ohm  # noqa: E402

CUTOFF_V = 2.5
LATE_AFTER = 0.3


def with_ohmic_floor(step_ohm: float, reference_k: float):  # noqa: ANN201 - a patch of runtime.peak_crossing_s
    """``runtime.peak_crossing_s`` whose cut-off is raised by the ohmic step the model's peak drop falls short of."""
    original = runtime.peak_crossing_s
    ratios: dict[tuple[int, int], float] = {}

    def patched(runner, start, average, peak_factor, temperature_k, cutoff_voltage_v, average_run, **kwargs):  # noqa: ANN001, ANN202
        key = (id(runner), round(temperature_k))
        if key not in ratios:
            ratios[key] = pulse_resistance_ohm(runner, float(key[1])) / pulse_resistance_ohm(runner, reference_k)
        first_a = average.current_at(0.0)
        model_drop_v = runtime.peak_voltage_drop_v(runner, start, first_a, peak_factor * first_a, temperature_k,
                                                   kwargs.get("settle_s", 5.0))
        ohmic_v = step_ohm * ratios[key] * (peak_factor - 1.0) * first_a
        return original(runner, start, average, peak_factor, temperature_k,
                        cutoff_voltage_v + max(0.0, ohmic_v - model_drop_v), average_run, **kwargs)

    return patched


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--params", required=True)
    parser.add_argument("--fit-data", nargs="+", required=True)
    parser.add_argument("--data", nargs="+", required=True)
    parser.add_argument("--ohmic", action="store_true")
    parser.add_argument("--peak-source", default="window", choices=("window", "sample"))
    parser.add_argument("--quantile", type=float, default=0.99)
    args = parser.parse_args(argv)
    params = load_params(args.params)
    if args.ohmic:
        fit_recs = [load_recording(Path(f), duplicate_times="keep_last") for f in args.fit_data]
        step_ohm = step_resistance_ohm(fit_recs)
        reference_k = float(np.mean(np.concatenate([r.temperature_k for r in fit_recs])))
        print(f"fit data step resistance {step_ohm * 1000:.1f} mOhm at {reference_k - 273.15:.1f} degC")
        runtime.peak_crossing_s = with_ohmic_floor(step_ohm, reference_k)
    config = PredictorConfig(params_file=args.params, cutoff_voltage_v=CUTOFF_V, peak_source=args.peak_source,
                             peak_current_quantile=args.quantile)
    pooled: list[float] = []
    over: list[str] = []
    for name in args.data:
        result = evaluate_recording(params, load_recording(Path(name), duplicate_times="keep_last"),
                                    cutoff_v=CUTOFF_V, capacities_ah={}, config=config)
        valid = [cp for cp in result.checkpoints if cp.valid]
        errors = [(cp.predicted_s - cp.true_remaining_s) / 60.0 for cp in valid]
        pooled += errors
        over += [f"{Path(name).stem} at {cp.fraction:.0%}: {cp.predicted_s / 60:.1f} vs {cp.true_remaining_s / 60:.1f} min"
                 for cp in valid if cp.fraction >= LATE_AFTER - 1e-9
                 and abs(cp.predicted_s - cp.true_remaining_s) > 0.5 * cp.true_remaining_s]
        if errors:
            print(f"{Path(name).stem}: MAE {np.mean(np.abs(errors)):.1f} min, bias {np.mean(errors):+.1f} min")
    if pooled:
        print(f"pooled: MAE {np.mean(np.abs(pooled)):.2f} min, bias {np.mean(pooled):+.2f} min, {len(pooled)} answers; "
              f"off by > 50 % after {LATE_AFTER:.0%}: {len(over)}")
    for line in over:
        print(f"  {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
