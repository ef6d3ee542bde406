"""The optional coordinates `fit` searches by default: the transport on params with a measured OCV only."""

from __future__ import annotations

from pathlib import Path

import pytest

from battery_predictor.cli.fit_identify import _optional_coordinates
from battery_predictor.errors import InputDataError
from battery_predictor.fitting.identifiable import TRANSPORT_COORDINATES, default_optional_coordinates
from battery_predictor.params import load_params

REPO = Path(__file__).resolve().parents[2]
MEASURED_OCV = REPO / "docs" / "runtime_real_data" / "panasonic_ocv.yaml"
BASE_SET_OCPS = REPO / "params" / "panasonic_18650pf.yaml"


def test_params_with_a_measured_ocv_search_both_particle_diffusivities_by_default() -> None:
    params = load_params(MEASURED_OCV)
    assert params.ocp
    assert default_optional_coordinates(params) == TRANSPORT_COORDINATES


@pytest.mark.parametrize("name", ["panasonic_18650pf.yaml", "temi.yaml", "ranger_mini.yaml"])
def test_params_with_base_set_ocps_search_no_optional_coordinate_by_default(name: str) -> None:
    assert default_optional_coordinates(load_params(REPO / "params" / name)) == ()


def test_the_default_is_said_on_stderr_and_none_turns_it_off(capsys: pytest.CaptureFixture[str]) -> None:
    params = load_params(MEASURED_OCV)
    assert _optional_coordinates(params, None) == TRANSPORT_COORDINATES
    assert "measured OCV" in capsys.readouterr().err
    assert _optional_coordinates(params, ["none"]) == ()
    assert _optional_coordinates(load_params(BASE_SET_OCPS), ["negative_kinetic_scale"]) == ("negative_kinetic_scale",)
    assert capsys.readouterr().err == ""


def test_none_beside_a_coordinate_name_is_a_clear_error() -> None:
    with pytest.raises(InputDataError, match="--coordinates none"):
        _optional_coordinates(load_params(BASE_SET_OCPS), ["none", "negative_kinetic_scale"])
