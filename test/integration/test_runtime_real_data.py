"""Remaining runtime on measured Panasonic 18650PF drive cycles beats naive Coulomb counting.

The shipped fit (``docs/runtime_real_data/``, 25 degC HWFET + LA92) predicts the nine held-out
drive cycles at 25/10/0 degC through the predictor's core at its node defaults; its pooled MAE must
stay at most 0.7x the best counter's (capacity measured on the fit data), as documented there.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from battery_predictor.evaluation.runtime_eval import charge_to_end_ah, evaluate_recording, summarise
from battery_predictor.io.loader import load_recording
from battery_predictor.params import load_params

REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data" / "panasonic_18650pf"
FIT = REPO / "docs" / "runtime_real_data" / "panasonic_fit_hwfet_la92.yaml"
HELD_OUT = ("T25C_Cycle1", "T25C_US06", "T10C_Cycle1", "T10C_HWFET", "T10C_US06", "T00C_Cycle1", "T00C_HWFET",
            "T00C_UDDS", "T00C_US06")


@pytest.mark.skipif(not DATA.is_dir(), reason="measured data not available (../shared/data)")
def test_predictor_beats_the_best_counter_on_held_out_drive_cycles():
    params = load_params(FIT)
    fit_data = [load_recording(DATA / f"drive_{name}.csv") for name in ("T25C_HWFET", "T25C_LA92")]
    capacity_ah = sum(charge_to_end_ah(params, rec, 2.5) for rec in fit_data) / len(fit_data)
    results = [evaluate_recording(params, load_recording(DATA / f"drive_{name}.csv"), cutoff_v=2.5,
                                  capacities_ah={"measured": capacity_ah}) for name in HELD_OUT]
    pooled = summarise(results, ["measured"])["pooled"]
    predictor, counter = pooled["predictor"], pooled["counter[measured]"]
    assert predictor["answered"] == predictor["checkpoints"] == 81
    assert predictor["mae_min"] <= 0.7 * counter["mae_min"], (predictor, counter)
