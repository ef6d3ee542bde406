"""The identifiability report on the measured Panasonic fit names the determined combinations.

Drive cycles determine each electrode's capacity, the negative electrode's initial stoichiometry,
the series resistance and each recording's initial state (issue 17: a Fisher analysis with PyBaMM's
sensitivities found the same five cell combinations). A short identification from the shipped
fit (``docs/runtime_real_data/panasonic_ocv_fit.yaml``) back to its optimum, then the report there.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from battery_predictor.fitting.identifiable import default_space
from battery_predictor.fitting.identification import IdentificationProblem, identifiability_of, identify
from battery_predictor.fitting.problem import trim_to_discharge
from battery_predictor.fitting.resample import resample_all
from battery_predictor.io.loader import load_recording
from battery_predictor.params import load_params
from battery_predictor.simulation import get_simulator

REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data" / "panasonic_18650pf"
FIT = REPO / "docs" / "runtime_real_data" / "panasonic_ocv_fit.yaml"


@pytest.mark.skipif(not DATA.is_dir(), reason="measured data not available (../shared/data)")
def test_drive_cycles_determine_capacities_stoichiometry_resistance_and_states():
    params = load_params(FIT)
    files = [DATA / "drive_T25C_HWFET.csv", DATA / "drive_T25C_LA92.csv"]
    recs = resample_all([trim_to_discharge(load_recording(f)) for f in files], float(params.provenance["resample_s"]))
    space = default_space(params, recs)
    problem = IdentificationProblem(params=params, recordings=recs, simulator=get_simulator("engine"), space=space)
    result = identify(problem, evaluations=200, seed=0)
    assert problem.score(result.coordinates).r2_mod > 0.99  # back at the shipped optimum (R2_mod 0.9947)
    report = identifiability_of(problem, result.unit)
    determined = {name for name, ok in zip(report.names, report.determined) if ok}
    assert {"negative_capacity_ah", "positive_capacity_ah", "negative_stoichiometry", "series_resistance_ohm",
            "initial_ocv_v:0", "initial_ocv_v:1"} <= determined, report.summary_lines()
