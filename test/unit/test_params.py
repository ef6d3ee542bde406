"""Params files: the shipped ones load, and every malformed file gives a one-line ParamsError."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from battery_predictor.errors import ParamsError
from battery_predictor.params import load_params, params_from_dict

PARAMS_DIR = Path(__file__).resolve().parents[2] / "params"
PACK_FILES = ["temi.yaml", "ranger_mini.yaml", "lgm50.yaml", "panasonic_18650pf.yaml"]


@pytest.mark.parametrize("name", PACK_FILES)
def test_shipped_pack_params_load_and_build_pybamm_values(name):
    p = load_params(PARAMS_DIR / name)
    pv = p.parameter_values()
    assert p.series >= 1 and p.parallel >= 1
    for key, value in p.cell_values.items():
        assert pv[key] == pytest.approx(value)


def test_paper_configurations_and_thresholds():
    temi = load_params(PARAMS_DIR / "temi.yaml")
    ranger = load_params(PARAMS_DIR / "ranger_mini.yaml")
    assert (temi.series, temi.parallel, temi.base_parameter_set) == (4, 6, "Chen2020")
    assert (ranger.series, ranger.parallel, ranger.base_parameter_set) == (15, 4, "Prada2013")
    assert temi.thresholds["runtime_cutoff_voltage_v"] == 13.30
    assert ranger.thresholds["route_min_voltage_v"] == 46.31
    assert ranger.thresholds["standstill_current_a"] == 1.70
    assert ranger.thresholds["terminal_voltage_v"] == 45.00
    assert temi.value("Electrode height [m]") == pytest.approx(0.89719)
    assert ranger.interconnect["r_i_ohm"] == pytest.approx(0.09784)


def _write(tmp_path, data) -> Path:
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _base() -> dict:
    return yaml.safe_load((PARAMS_DIR / "temi.yaml").read_text())


def test_round_trip_through_yaml_keeps_every_value(tmp_path):
    p = load_params(PARAMS_DIR / "temi.yaml")
    q = load_params(p.with_values({"r_c_ohm": 0.05, "Electrode height [m]": 0.8}).to_yaml(tmp_path / "q.yaml"))
    assert q.interconnect["r_c_ohm"] == 0.05
    assert q.value("Electrode height [m]") == 0.8
    assert q.fit.parameters == p.fit.parameters
    assert q.manual == p.manual


@pytest.mark.parametrize(
    ("mutate", "fragment"),
    [
        (lambda d: d.update(colour="red"), "unknown key 'colour'"),
        (lambda d: d["cell"]["manual"].update({"Electrode height": 0.5}), "missing unit, use 'Electrode height [m]'"),
        (lambda d: d["cell"]["manual"].update({"Electrode height [mm]": 615.0}), "wrong unit"),
        (lambda d: d["cell"]["manual"].update({"Flux capacitor [V]": 1.0}), "unknown key 'Flux capacitor [V]'"),
        (lambda d: d["thresholds"].update(runtime_cutoff=13.3), "missing unit"),
        (lambda d: d["interconnect"].update(r_b=0.001), "missing unit"),
        (lambda d: d["interconnect"].update(r_c_ohm=-1.0), "must be > 0"),
        (lambda d: d["pack"].update(series=0), "positive integer"),
        (lambda d: d["cell"]["fitted"].update({"Electrode height [m]": "tall"}), "expected a number"),
        (lambda d: d["cell"].update(base_parameter_set="Nope2099"), "unknown PyBaMM parameter set"),
        (lambda d: d.update(extensions=["flux"]), "unknown extension 'flux'"),
        (lambda d: d["fit"].update(parameters=["Electrode heigth [m]"]), "unknown key"),
        (lambda d: d.pop("pack"), "missing section 'pack'"),
    ],
)
def test_malformed_params_file_names_file_and_key(tmp_path, mutate, fragment):
    data = _base()
    mutate(data)
    path = _write(tmp_path, data)
    with pytest.raises(ParamsError) as err:
        load_params(path)
    msg = str(err.value)
    assert fragment in msg
    assert str(path) in msg
    assert "\n" not in msg


def test_missing_and_empty_and_broken_yaml_files(tmp_path):
    with pytest.raises(ParamsError, match="not found"):
        load_params(tmp_path / "nope.yaml")
    (tmp_path / "empty.yaml").write_text("")
    with pytest.raises(ParamsError, match="empty"):
        load_params(tmp_path / "empty.yaml")
    (tmp_path / "bad.yaml").write_text("pack: [unclosed\n")
    with pytest.raises(ParamsError, match="YAML syntax error"):
        load_params(tmp_path / "bad.yaml")


def test_params_from_dict_rejects_non_mapping():
    with pytest.raises(ParamsError, match="mapping"):
        params_from_dict(["not", "a", "mapping"], source="x.yaml")
