"""The K2 LiFePO4 fit with the engine's hysteresis extension (docs/identification_k2/README.md).

The stored 20 degC fit (``k2_fit_T20C_hysteresis.yaml``) is scored again on the engine at its stored
coordinates, the hysteresis is shown to carry part of it, and a short refinement from there does not
get worse. Needs the shared data (``../shared/data/k2_lfp26650_arts``); a few seconds.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from battery_predictor.fitting.identifiable import default_space
from battery_predictor.fitting.identification import IdentificationProblem, identify
from battery_predictor.fitting.problem import trim_to_discharge
from battery_predictor.io.loader import load_recording
from battery_predictor.params import load_params
from battery_predictor.simulation import get_simulator
from battery_predictor.simulation.extensions import HYS_HALF_WIDTH

REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data" / "k2_lfp26650_arts"
FIT = REPO / "docs" / "identification_k2" / "k2_fit_T20C_hysteresis.yaml"

pytestmark = [pytest.mark.skipif(not DATA.is_dir(), reason="measured data not available (../shared/data)"),
              pytest.mark.filterwarnings("ignore:.*above the params' upper cut-off:UserWarning")]


def _problem(params):
    recs = [trim_to_discharge(load_recording(DATA / f)) for f in ("cc_discharge_T20C.csv", "hppc_T20C.csv")]
    return IdentificationProblem(params=params, recordings=recs, simulator=get_simulator("engine"),
                                 space=default_space(params, recs))


def _stored_coordinates(params) -> dict[str, float]:
    coords = dict(params.provenance["coordinates"])
    coords.update({f"initial_ocv_v:{k}": v for k, v in enumerate(params.provenance["initial_ocv_v_per_file"].values())})
    return coords


def test_the_stored_hysteresis_fit_scores_as_stored_on_the_engine():
    params = load_params(FIT)
    assert "hysteresis" in params.extensions
    problem = _problem(params)
    coords = _stored_coordinates(params)
    score = problem.score(coords)
    assert score.r2_mod == pytest.approx(params.provenance["r2_mod"], abs=1e-4)
    assert score.r2_mod > 0.97
    for res in score.results:  # the engine ran the hysteresis itself, no fallback
        assert "engine_fallback" not in res.extra
        assert res.extra["engine_backend"].endswith("+hysteresis")
    # without the hysteresis voltage (half-width 0) the same point is clearly worse
    flat = problem.score({**coords, "hysteresis_half_width_v": 0.0})
    assert flat.r2_mod < score.r2_mod - 0.01
    assert params.extra[HYS_HALF_WIDTH] == pytest.approx(coords["hysteresis_half_width_v"])


def test_a_short_refinement_from_the_stored_fit_does_not_get_worse():
    params = load_params(FIT)
    problem = _problem(params)
    stored = _stored_coordinates(params)
    problem.space = [replace(c, initial=min(max(stored.get(c.name, c.initial), c.low), c.high)) for c in problem.space]
    start = problem.score(stored).r2_mod
    result = identify(problem, evaluations=30, tpe_fraction=0.0, starts=1)
    assert result.evaluations <= 30
    assert 1.0 - result.cost >= start - 2e-3  # the cost is about 1 - mean R2_mod
