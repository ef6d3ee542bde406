"""After the fact: the median time of the first load state that crosses, from the upcrossing rates so far.

An experiment, not the predictor (docs/runtime_real_data/README.md, "The end event of a random usage"). For
each far-truth Temi day of ``benchmarks/runtime_far_truth.py`` it scores the predictor's answers as they are,
then replaces each peak-limited answer by the median first-passage time: the threshold current falls linearly
from the 0.99-quantile peak at the peak-load crossing to the average current at the average-load crossing, and
each level recurs at the upcrossing rate of the day's 5 s windows so far. The oracle counter (told the charge the
day delivers) is scored beside both.

Run from the repository: ``nice .venv/bin/python docs/runtime_real_data/end_event_posthoc.py 160 162 163``
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO))

import identification_far_truth as far  # noqa: E402

import battery_predictor.prediction.core as core_mod  # noqa: E402
from battery_predictor.evaluation.runtime_eval import Windows, charge_to_end_ah, evaluate_recording  # noqa: E402
from battery_predictor.fitting.identifiable import pybamm_values  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402

THRESHOLD_V = 13.30
CAPTURED: list[tuple] = []
_PREDICT = core_mod.predict_remaining_runtime


def _capturing(*args, **kwargs):
    """The core's runtime prediction, kept with its average (A) and peak (A) current."""
    prediction = _PREDICT(*args, **kwargs)
    CAPTURED.append((prediction, args[4], kwargs.get("peak_current_a")))
    return prediction


def upcrossing_rate_per_s(current_a: np.ndarray, level_a: float, window_s: float) -> float:
    """How often the window currents rise through ``level_a``, per s of history."""
    ups = np.sum((current_a[:-1] < level_a) & (current_a[1:] >= level_a))
    return float(ups) / (window_s * current_a.size)


def first_passage_p50_s(current_a: np.ndarray, window_s: float, t_peak_s: float, t_avg_s: float,
                        peak_a: float, average_a: float) -> float:
    """Median time (s) of the first state heavy enough to cross, between the peak- and average-load crossings."""
    if not (math.isfinite(t_avg_s) and t_avg_s > t_peak_s and peak_a > average_a):
        return t_peak_s
    taus = np.linspace(t_peak_s, t_avg_s, 200)
    step_s = taus[1] - taus[0]
    hazard = 0.0
    for tau in taus:
        level = peak_a + (average_a - peak_a) * (tau - t_peak_s) / (t_avg_s - t_peak_s)
        hazard += upcrossing_rate_per_s(current_a, level, window_s) * step_s
        if hazard >= math.log(2.0):
            return float(tau)
    return t_avg_s


def score_seed(seed: int, work: Path, errors: dict[str, list[float]]) -> None:
    params = load_params(REPO / "params" / "temi.yaml")
    truth = far.draw_truth(params, np.random.default_rng(1000 + seed))
    truth_params = params.with_values(pybamm_values(params, truth)[0])
    fit_day, _, _ = far.day(truth_params, 2 * seed + 1, None, "temi")
    test_day, _, _ = far.day(truth_params, 2 * seed + 2, 4.0, "temi")
    below = np.flatnonzero(test_day.voltage_v <= THRESHOLD_V)
    if not below.size:
        return
    fit_csv, test_csv, fit_yaml = work / f"{seed}a.csv", work / f"{seed}b.csv", work / f"{seed}.yaml"
    far.write_day_csv(fit_day, fit_csv)
    far.write_day_csv(test_day, test_csv, int(below[0]) + 1)
    far.fit_with_cli(REPO / "params" / "temi.yaml", fit_csv, fit_yaml)
    fitted, rec = load_params(fit_yaml), load_recording(test_csv)
    CAPTURED.clear()
    result = evaluate_recording(fitted, rec, cutoff_v=THRESHOLD_V,
                                capacities_ah={"oracle": charge_to_end_ah(fitted, rec, THRESHOLD_V)})
    win = Windows.of(rec)
    line = []
    for c in result.checkpoints:
        hits = [x for x in CAPTURED if abs(x[0].remaining_s - c.predicted_s) < 1e-6]
        if not hits:
            continue
        prediction, average_a, peak_a = hits[-1]
        now_s = result.discharge.start_s + c.time_s
        history = (win.time_s >= result.discharge.start_s) & (win.time_s <= now_s)
        passage_s = prediction.remaining_s
        if prediction.limited_by == "peak_cutoff":
            passage_s = first_passage_p50_s(win.current_a[history], 5.0, prediction.remaining_s,
                                            prediction.average_end_s, peak_a or average_a, average_a)
        errors["predictor"].append((c.predicted_s - c.true_remaining_s) / 60.0)
        errors["first passage"].append((passage_s - c.true_remaining_s) / 60.0)
        errors["oracle counter"].append((c.counters_s["oracle"] - c.true_remaining_s) / 60.0)
        line.append(f"{errors['predictor'][-1]:+.0f}/{errors['first passage'][-1]:+.0f}")
    print(seed, " ".join(line), flush=True)


def main() -> None:
    core_mod.predict_remaining_runtime = _capturing
    errors: dict[str, list[float]] = {"predictor": [], "first passage": [], "oracle counter": []}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in map(int, sys.argv[1:]):
            score_seed(seed, Path(tmp), errors)
    for name, values in errors.items():
        v = np.asarray(values)
        print(f"{name}: MAE {np.mean(np.abs(v)):.1f} min, bias {np.mean(v):+.1f} min, {v.size} answers")


if __name__ == "__main__":
    main()
