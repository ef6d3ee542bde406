"""One set of YAML checks for every YAML file of the package: reading, and numbers.

Numbers (docs/decisions.md, "Numbers in YAML files"):
A YAML number, or a string YAML 1.2 reads as a decimal number (``1e-3``: PyYAML's YAML 1.1 loads it as
a string), is accepted; any other string fails with one line naming the file and the key. The same
rule holds for pack params (:mod:`battery_predictor.params`, its ``cell.ocp`` section) and the other
YAML readers (:mod:`battery_predictor.config`: station maps, load profiles).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from battery_predictor.config import read_yaml_mapping, yaml_number
from battery_predictor.errors import ParamsError
from battery_predictor.params import load_params
from battery_predictor.profiles.station import load_station

REPO = Path(__file__).resolve().parents[2]

ACCEPTED = [("1e-3", 1e-3), ("1E5", 1e5), ("-2.5e+4", -2.5e4), ("+.5", 0.5), ("3", 3.0), ("4.", 4.0),
            ("1.5e3", 1500.0)]
REFUSED = ["1,5", "3.7 V", " 3.7", "0x10", "1_000", "tall", "", "1e", "e3", ".", "inf", ".nan"]


def test_pyyaml_loads_exponent_without_dot_as_a_string():
    """Why the rule exists: the trap it closes."""
    assert yaml.safe_load("x: 1e-3") == {"x": "1e-3"}
    assert yaml.safe_load("x: 1.0e-3") == {"x": 1e-3}


@pytest.mark.parametrize(("text", "number"), ACCEPTED)
def test_strings_yaml_1_2_reads_as_decimal_numbers_are_accepted(text, number):
    assert yaml_number(text, "f.yaml", "a.b") == pytest.approx(number)


@pytest.mark.parametrize("text", REFUSED)
def test_other_strings_are_refused_in_one_line_naming_the_key(text):
    with pytest.raises(ParamsError) as err:
        yaml_number(text, "f.yaml", "a.b")
    msg = str(err.value)
    assert msg.startswith("f.yaml: key 'a.b': expected a number") and "\n" not in msg
    assert "1e-3" in msg  # the fix


@pytest.mark.parametrize("value", [True, None, [1.0], {"a": 1}, float("inf"), float("nan")])
def test_non_numbers_and_non_finite_values_are_refused(value):
    with pytest.raises(ParamsError, match="f.yaml: key 'a.b'"):
        yaml_number(value, "f.yaml", "a.b")


def test_numbers_of_any_real_type_are_accepted():
    import numpy as np

    assert yaml_number(2, "f", "k") == 2.0
    assert yaml_number(np.float64(0.25), "f", "k") == 0.25
    assert yaml_number(np.int64(7), "f", "k") == 7.0


# ------------------------------------------------------------------------------ pack params (params.py)
def _pack_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "pack.yaml"
    path.write_text(text)
    return path


def test_pack_params_accept_1e_minus_3_unquoted(tmp_path):
    text = (REPO / "params" / "temi.yaml").read_text()
    data = yaml.safe_load(text)
    key = "r_b_ohm"
    assert key in data["interconnect"]
    text = text.replace(f"{key}: {data['interconnect'][key]!r}", f"{key}: 1e-3")
    path = _pack_file(tmp_path, text)
    assert yaml.safe_load(path.read_text())["interconnect"][key] == "1e-3"
    assert load_params(path).interconnect[key] == pytest.approx(1e-3)


def test_pack_params_refuse_a_number_with_a_unit_naming_the_key(tmp_path):
    data = yaml.safe_load((REPO / "params" / "temi.yaml").read_text())
    data["interconnect"]["r_b_ohm"] = "0.001 Ohm"
    path = _pack_file(tmp_path, yaml.safe_dump(data))
    with pytest.raises(ParamsError) as err:
        load_params(path)
    msg = str(err.value)
    assert str(path) in msg and "'interconnect.r_b_ohm'" in msg and "\n" not in msg


def test_pack_params_ocp_section_uses_the_same_rule(tmp_path):
    path = REPO / "docs" / "runtime_real_data" / "panasonic_ocv.yaml"
    data = yaml.safe_load(path.read_text())
    reference = load_params(path)
    positive = data["cell"]["ocp"]["positive"]
    width = positive["widths"][0]
    positive["slope_v"] = f"{float(positive['slope_v']):.17g}e0"  # a string to PyYAML, a number to YAML 1.2
    positive["widths"][0] = "wide"
    bad = _pack_file(tmp_path, yaml.safe_dump(data))
    with pytest.raises(ParamsError, match=r"'cell\.ocp\.positive\.widths\[0\]'"):
        load_params(bad)
    positive["widths"][0] = width
    good = _pack_file(tmp_path, yaml.safe_dump(data))
    assert isinstance(yaml.safe_load(good.read_text())["cell"]["ocp"]["positive"]["slope_v"], str)
    assert load_params(good).cell_values == reference.cell_values


# ------------------------------------------------------------------------- other YAML files (config.py)
def test_station_map_accepts_1e_minus_3_style_lengths(tmp_path):
    data = yaml.safe_load((REPO / "params" / "minden_station.yaml").read_text())
    data["edges"][0]["segments"][0]["length_m"] = "3e1"
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump(data))
    station = load_station(path)
    assert station.edges[0].segments[0].length_m == 30.0


def test_station_map_refuses_other_strings_naming_the_key(tmp_path):
    data = yaml.safe_load((REPO / "params" / "minden_station.yaml").read_text())
    data["edges"][0]["segments"][0]["length_m"] = "30 m"
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ParamsError) as err:
        load_station(path)
    msg = str(err.value)
    assert str(path) in msg and "edges[0].segments[0].length_m" in msg and "\n" not in msg


# ------------------------------------------------------------------------------------------- reading
def test_a_syntax_error_names_the_file_and_line_for_every_reader(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("pack:\n  series: 4\n  parallel: [6\n")
    for read in (load_params, load_station, read_yaml_mapping):
        with pytest.raises(ParamsError) as err:
            read(path)
        msg = str(err.value)
        assert msg.startswith(f"{path}: line ") and "YAML syntax error" in msg and "\n" not in msg


def test_a_directory_is_refused_in_one_line(tmp_path):
    for read in (load_params, load_station):
        with pytest.raises(ParamsError, match="is a directory"):
            read(tmp_path)


# --------------------------------------------------------------------------- node params (cli/_ros_params)
def _node_file(tmp_path: Path, **predictor: object) -> Path:
    data = yaml.safe_load((REPO / "params" / "ros" / "temi_nodes.yaml").read_text())
    data["predictor"]["ros__parameters"].update(predictor)
    path = tmp_path / "nodes.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_node_params_use_the_same_rule(tmp_path):
    from battery_predictor.cli._ros_params import check_node_params_file

    assert check_node_params_file(str(_node_file(tmp_path, cutoff_voltage_v="1.33e1"))) is not None
    assert check_node_params_file(str(_node_file(tmp_path, cutoff_voltage_v=float("nan")))) is not None  # "from the pack"
    with pytest.raises(ParamsError) as err:
        check_node_params_file(str(_node_file(tmp_path, cutoff_voltage_v="13.3 V")))
    assert "'predictor.cutoff_voltage_v'" in str(err.value) and "\n" not in str(err.value)
