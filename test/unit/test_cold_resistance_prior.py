"""The Panasonic's a-priori cold charge-transfer resistance (docs/runtime_real_data/cold_resistance_prior.py).

``params/panasonic_18650pf.yaml`` carries the ``temperature`` extension's Arrhenius charge-transfer resistance as a
prior from another graphite cell (the LG M50's 1 s pulse resistance at 0-45 degC, as a fraction of its 25 degC
value, times the Panasonic's own 1 s step resistance): the shipped value is the script's, the predictor's pack
model applies it in the cold and not at 25 degC.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.prediction.pack_model import pack_model
from battery_predictor.simulation.extensions import COLD_CHARGE_TRANSFER, arrhenius_ratio, extension_value

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "docs" / "runtime_real_data" / "cold_resistance_prior.py"
DATA = REPO.parent / "shared" / "data"
#: The Panasonic's 1 s step resistance on its 25 degC fit recordings (Ohm; the README's 30-35 mOhm).
PANASONIC_STEP_OHM = 0.032


@pytest.fixture(scope="module")
def panasonic():
    return load_params(REPO / "params" / "panasonic_18650pf.yaml")


def test_the_shipped_prior_is_a_physical_share_of_the_cells_step(panasonic):
    # a charge-transfer part of the 1 s resistance: more than a twentieth, less than half of the cell's step
    r = extension_value(panasonic, COLD_CHARGE_TRANSFER)
    assert 0.05 * PANASONIC_STEP_OHM < r < 0.5 * PANASONIC_STEP_OHM
    assert "temperature" in panasonic.extensions


@pytest.mark.skipif(not (DATA / "lgm50_wmg" / "pulses_T25C.csv").is_file()
                    or not (DATA / "panasonic_18650pf").is_dir(), reason="measured data not available (../shared/data)")
def test_the_shipped_prior_is_the_scripts_derivation(panasonic, repo_script):
    module = repo_script(str(SCRIPT.relative_to(REPO)))
    res = module.derive(DATA)
    assert res["at"][1.0]["fraction"] == pytest.approx(0.216, abs=5e-4)
    assert res["panasonic_step_ohm"] == pytest.approx(0.03205, abs=5e-5)
    assert round(res["prior_ohm"], 4) == extension_value(panasonic, COLD_CHARGE_TRANSFER)


def test_the_predictors_pack_model_applies_the_excess_in_the_cold_only(panasonic):
    r = extension_value(panasonic, COLD_CHARGE_TRANSFER)
    without = replace(panasonic, extra={k: v for k, v in panasonic.extra.items() if k != COLD_CHARGE_TRANSFER})
    segments = [(60.0, 0.7), (1.0, 10.7)]  # a burst after a light load, at half charge
    with_model, line = pack_model(panasonic)
    without_model, _ = pack_model(without)
    assert line.startswith("engine")
    for temperature_k, excess_ohm in ((298.15, 0.0), (283.15, r * (arrhenius_ratio(30000.0, 283.15) - 1.0))):
        v_with = with_model.run(0.5, segments, temperature_k).pack_voltage_v[-1]
        v_without = without_model.run(0.5, segments, temperature_k).pack_voltage_v[-1]
        drop_ohm = float(v_without - v_with) / 10.7
        if excess_ohm == 0.0:
            assert abs(drop_ohm) < 1e-5
        else:  # the excess times the charge-transfer shape, near 1 at half lithiation
            assert drop_ohm == pytest.approx(excess_ohm, rel=0.1)
            assert np.isfinite(drop_ohm) and drop_ohm > 0.004
