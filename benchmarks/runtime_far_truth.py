"""Remaining runtime of a Temi pack whose truth is drawn far from the shipped params, as a user gets it.

For each seed: the truth pack and its two days of ``identification_far_truth.py`` (lumped thermal cells,
recorded as the paper's instruments do (``--instrument``: 10 Hz averaged to 5 s by default, ``5s`` as before
2026-11-28), the Temi usage model's constant-current states);
day 1 is fitted with ``battery-predictor fit --params params/temi.yaml`` at its defaults, day 2 (from rest
at 4.0 V per cell) is cut at its first sample at or below 13.30 V (the robot returns to its charger there)
and scored as ``evaluate-runtime`` scores a recording: the predictor's core at its defaults fed the 5 s
windows, nine checkpoints (10 % .. 90 % of the discharge). A day 2 that never reaches 13.30 V is skipped and
said so.

Beside the predictor: a Coulomb counter told the charge day 2 actually delivers to 13.30 V (an oracle:
remaining Ah / mean current so far), so that what remains of its error is the forecast of the load.

``--pack ranger`` does the same for the luggage robot: ``params/ranger_mini.yaml``, its far-truth days of longest
routes at random payloads with standstills, day 2 from rest at 3.33 V per cell, cut-off the node's (the params'
pack minimum, 45.00 V).

``--load-prior power`` removes the fitted params' ``operating.load_prior_power_fraction`` before scoring: the
predictor's ``load_model auto`` then assumes a constant power until the day's windows decide (the package's
prior). ``--load-prior current`` sets it to 0: a constant current until the day decides.

Run::

    nice .venv/bin/python benchmarks/runtime_far_truth.py --seeds 60 61 62 [--pack temi|ranger] [--load-prior params|power|current]
        [--instrument paper|5s] [--drift-correction auto|full|smallest] [--end-event auto|peak|sampled] [--work DIR] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

import identification_far_truth as far  # noqa: E402

from battery_predictor.evaluation.runtime_eval import (  # noqa: E402
    charge_to_end_ah,
    error_summary,
    evaluate_recording,
    interval_coverage,
)
from battery_predictor.fitting.identifiable import pybamm_values  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.prediction.core import DRIFT_CORRECTIONS, END_EVENTS, LOAD_PRIOR_KEY, PredictorConfig  # noqa: E402

THRESHOLD_V = 13.30


def cutoff_of(pack: str, params) -> float:
    """The runtime's cut-off of ``pack`` (V): the Temi returns to its charger at 13.30 V; the Ranger's node runs to
    its params' pack minimum (``cutoff_voltage_v: 0`` in its node file)."""
    return THRESHOLD_V if pack == "temi" else float(params.pack_info["min_voltage_v"])
#: The counter told the charge day 2 delivers to the threshold: remaining Ah / mean current so far.
ORACLE = "counter, true charge to the end"


def run_seed(seed: int, load_prior: str, work: Path, instrument: str = far.INSTRUMENT,
             drift_correction: str = "full", end_event: str = "peak", pack: str = "temi") -> dict:
    """Draw the truth of ``seed``, fit its day 1 with the CLI, score the predictor on its day 2."""
    params_path = REPO / "params" / far.PACKS[pack][0]
    params = load_params(params_path)
    cutoff_v = cutoff_of(pack, params)
    truth = far.draw_truth(params, np.random.default_rng(1000 + seed))
    truth_params = params.with_values(pybamm_values(params, truth)[0])
    fit_day, _, _ = far.day(truth_params, 2 * seed + 1, None, pack, instrument)
    test_day, _, _ = far.day(truth_params, 2 * seed + 2, far.PACKS[pack][2], pack, instrument)
    below = np.flatnonzero(test_day.voltage_v <= cutoff_v)
    if not below.size:
        return {"seed": seed, "skipped": f"day 2 never reaches {cutoff_v:.2f} V"}
    fit_csv, test_csv, fit_yaml = work / f"s{seed}_day1.csv", work / f"s{seed}_day2.csv", work / f"fit{seed}.yaml"
    far.write_day_csv(test_day, test_csv, int(below[0]) + 1)
    if not fit_yaml.exists():  # a kept fit (--work) is the same day's: score it again, do not fit again
        far.write_day_csv(fit_day, fit_csv)
        far.fit_with_cli(params_path, fit_csv, fit_yaml)
    fitted = load_params(fit_yaml)
    if load_prior in ("power", "current"):
        operating = {k: v for k, v in fitted.operating.items() if k != LOAD_PRIOR_KEY}
        if load_prior == "current":
            operating[LOAD_PRIOR_KEY] = 0.0
        fitted = replace(fitted, operating=operating)
    test_rec = load_recording(test_csv)
    # the counter told the charge the day will actually deliver (an oracle): what remains is its load forecast
    oracle_ah = charge_to_end_ah(fitted, test_rec, cutoff_v)
    config = PredictorConfig(params_file=str(fit_yaml), cutoff_voltage_v=cutoff_v, drift_correction=drift_correction,
                             end_event=end_event)
    result = evaluate_recording(fitted, test_rec, cutoff_v=cutoff_v, capacities_ah={ORACLE: oracle_ah}, config=config)
    errors = [(c.predicted_s, c.true_remaining_s) for c in result.checkpoints]
    late = [(c.predicted_s, c.true_remaining_s) for c in result.checkpoints if c.fraction >= 0.3 - 1e-9]
    over_half = sum(1 for p, t in late if not abs(p - t) <= 0.5 * t)
    counter = [(c.counters_s[ORACLE], c.true_remaining_s) for c in result.checkpoints]
    return {"seed": seed, "errors_min": [round((p - t) / 60.0, 1) for p, t in errors],
            "summary": error_summary(errors, late_fraction_pairs=late), "off_by_half_after_30pct": over_half,
            "answers_after_30pct": len(late), "oracle_counter_errors_min": [round((p - t) / 60.0, 1) for p, t in counter],
            "interval": interval_coverage(result.checkpoints),
            "bands_min": [[round(c.p10_s / 60.0, 1), round(c.p90_s / 60.0, 1), round(c.true_remaining_s / 60.0, 1)]
                          for c in result.checkpoints]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", nargs="+", type=int, default=[60])
    ap.add_argument("--pack", choices=("temi", "ranger"), default="temi",
                    help="temi (to 13.30 V, day 2 from 4.0 V per cell) or ranger (to its params' 45.00 V, day 2 from "
                         "3.33 V per cell, its far-truth days of longest routes)")
    ap.add_argument("--load-prior", choices=("params", "power", "current"), default="params",
                    help="the load kind the predictor assumes until the day decides: the fitted params' "
                         "operating.load_prior_power_fraction (params), a constant power (power) or current (current)")
    ap.add_argument("--instrument", choices=far.INSTRUMENTS, default=far.INSTRUMENT)
    ap.add_argument("--drift-correction", choices=DRIFT_CORRECTIONS, default=PredictorConfig.drift_correction,
                    help="the predictor's drift_correction (node parameter; default: the node's default)")
    ap.add_argument("--end-event", choices=END_EVENTS, default=PredictorConfig.end_event,
                    help="the predictor's end_event (node parameter; default: the node's default)")
    ap.add_argument("--work", type=Path, default=None,
                    help="keep the days and fits here and reuse a kept fit (score one fit several ways)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        rows = [run_seed(s, args.load_prior, work, args.instrument, args.drift_correction, args.end_event, args.pack)
                for s in args.seeds]
    scored = [r for r in rows if "summary" in r]
    pooled = [abs(e) for r in scored for e in r["errors_min"]]
    pooled_counter = [abs(e) for r in scored for e in r["oracle_counter_errors_min"]]
    band = _pooled_band(scored)
    if args.json:
        print(json.dumps({"load_prior": args.load_prior, "seeds": rows,
                          "pooled_mae_min": float(np.mean(pooled)) if pooled else None,
                          "pooled_oracle_counter_mae_min": float(np.mean(pooled_counter)) if pooled else None,
                          "pooled_interval": band},
                         indent=1, default=float))
        return
    for r in rows:
        if "skipped" in r:
            print(f"seed {r['seed']}: skipped ({r['skipped']})")
        else:
            s = r["summary"]
            print(f"seed {r['seed']}: MAE {s['mae_min']:.1f} min, bias {s['bias_min']:+.1f} min; errors "
                  + " ".join(f"{e:+.1f}" for e in r["errors_min"]) + "; oracle counter "
                  + " ".join(f"{e:+.1f}" for e in r["oracle_counter_errors_min"])
                  + f"; truth inside P10..P90 {r['interval']['inside_pct']:.0f} %")
    if pooled:
        off = sum(r["off_by_half_after_30pct"] for r in scored)
        after = sum(r["answers_after_30pct"] for r in scored)
        print(f"pooled over {len(scored)} days ({len(pooled)} answers), load prior {args.load_prior}: "
              f"MAE {np.mean(pooled):.1f} min, off by more than half after 30 %: {off} of {after}; "
              f"{ORACLE}: MAE {np.mean(pooled_counter):.1f} min")
        print(f"truth inside P10..P90 at {band['inside_pct']:.0f} % of {band['intervals']} answers "
              f"(below P10 {band['below_p10_pct']:.0f} %, above P90 {band['above_p90_pct']:.0f} %; target 80 / 10 / 10)")


def _pooled_band(rows: list[dict]) -> dict[str, float]:
    """The per-day :func:`interval_coverage` figures of ``rows`` pooled, weighted by their answers."""
    n = sum(r["interval"]["intervals"] for r in rows)
    pooled = {"intervals": n}
    for key in ("inside_pct", "below_p10_pct", "above_p90_pct"):
        pooled[key] = (sum(r["interval"][key] * r["interval"]["intervals"] for r in rows if r["interval"]["intervals"]) / n
                       if n else float("nan"))
    return pooled


if __name__ == "__main__":
    main()
