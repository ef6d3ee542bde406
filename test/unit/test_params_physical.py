"""Physical-range checks of params files (``params_checks``): every shipped file passes, impossible values fail."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from battery_predictor.cli._ros_params import check_node_params_file
from battery_predictor.errors import InputDataError, ParamsError
from battery_predictor.io.bags import read_recording_bag
from battery_predictor.params import load_params
from battery_predictor.params_checks import check_recordings_against_pack

REPO = Path(__file__).resolve().parents[2]
PACK_FILES = sorted(p for p in [*REPO.glob("params/*.yaml"), *REPO.glob("docs/*/*.yaml")]
                    if {"pack", "cell"} <= set(yaml.safe_load(p.read_text()) or {}))


def test_every_shipped_pack_file_and_shipped_fit_passes():
    assert len(PACK_FILES) >= 6
    for path in PACK_FILES:
        load_params(path)


@pytest.mark.parametrize("path", sorted((REPO / "params" / "ros").glob("*_nodes.yaml")), ids=lambda p: p.name)
def test_shipped_node_params_fit_their_packs(path):
    check_node_params_file(str(path))


def _load_changed(tmp_path: Path, mutate, base: str = "temi.yaml"):
    data = yaml.safe_load((REPO / "params" / base).read_text())
    mutate(data)
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_params(path)


@pytest.mark.parametrize(("mutate", "fragment"), [
    (lambda d: d["pack"].update(nominal_capacity_ah=-14.7), "pack.nominal_capacity_ah"),
    (lambda d: d["cell"]["manual"].update({"Nominal cell capacity [A.h]": -2.45}), "Nominal cell capacity"),
    (lambda d: d["pack"].update(series=10000), "pack.series"),
    (lambda d: d["pack"].update(series=5), "per cell for 5 cells in series"),
    (lambda d: d["pack"].update(parallel=100000), "pack.parallel"),
    (lambda d: d["pack"].update(parallel=20), "does not match 20 strings in parallel"),
    (lambda d: d["thresholds"].update(runtime_cutoff_voltage_v=1330), "thresholds.runtime_cutoff_voltage_v"),
    (lambda d: d["pack"].update(min_voltage_v=17.0), "pack.nominal_voltage_v"),
    (lambda d: d["operating"].update(ambient_temperature_k=25.0), "operating.ambient_temperature_k"),
    (lambda d: d["interconnect"].update(r_c_ohm=98.29), "interconnect.r_c_ohm"),
    (lambda d: d["cell"]["fitted"].update({"Negative electrode active material volume fraction": 1.2}),
     "volume fraction"),
    (lambda d: d["cell"]["fitted"].update({"Negative electrode thickness [m]": 0.0}), "Negative electrode thickness"),
    (lambda d: d["cell"]["manual"].update({"Upper voltage cut-off [V]": 2.9}), "Upper voltage cut-off [V]"),
    (lambda d: d["cell"]["fitted"].update({"Initial concentration in negative electrode [mol.m-3]": 40000.0}),
     "above the electrode's maximum concentration"),
])
def test_impossible_value_is_one_line_naming_file_and_key(tmp_path, mutate, fragment):
    with pytest.raises(ParamsError) as err:
        _load_changed(tmp_path, mutate)
    message = str(err.value)
    assert fragment in message and "p.yaml" in message and "\n" not in message


def test_recordings_pass_against_their_own_pack_and_fail_against_the_other():
    temi, ranger = load_params(REPO / "params" / "temi.yaml"), load_params(REPO / "params" / "ranger_mini.yaml")
    temi_rec = read_recording_bag(REPO / "bags" / "temi_dynamic_pack1")
    ranger_rec = read_recording_bag(REPO / "bags" / "ranger_stepwise_pack1")
    check_recordings_against_pack(temi, [temi_rec])
    check_recordings_against_pack(ranger, [ranger_rec])
    with pytest.raises(InputDataError, match="not of this pack"):
        check_recordings_against_pack(ranger, [temi_rec])
    with pytest.raises(InputDataError, match="not of this pack"):
        check_recordings_against_pack(temi, [ranger_rec])


def test_predictor_threshold_outside_the_pack_window_is_rejected(tmp_path):
    nodes = yaml.safe_load((REPO / "params" / "ros" / "temi_nodes.yaml").read_text())
    nodes["predictor"]["ros__parameters"]["cutoff_voltage_v"] = 46.31
    path = tmp_path / "nodes.yaml"
    path.write_text(yaml.safe_dump(nodes))
    with pytest.raises(ParamsError, match="predictor.cutoff_voltage_v"):
        check_node_params_file(str(path))


def test_written_params_keep_provenance_paths_relative(tmp_path):
    temi = load_params(REPO / "params" / "temi.yaml")
    data = [str(REPO / "bags" / "temi_dynamic_pack1")]
    fitted = temi.with_values({}, provenance={"data": data, "storage": f"sqlite:///{REPO / 'fit.optuna.db'}"})
    back = load_params(fitted.to_yaml(tmp_path / "fit.yaml"))
    assert back.provenance == {"data": ["bags/temi_dynamic_pack1"], "storage": "sqlite:///fit.optuna.db"}
