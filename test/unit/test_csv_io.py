"""Measurement CSV reading/writing: every bad input gives a one-line InputDataError naming file and line/column."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import InputDataError
from battery_predictor.io.csv_io import TEMPERATURE_COLUMNS, load_csv, load_csv_groups, save_csv
from battery_predictor.io.validation import check_current_sign, voltage_response_score
from battery_predictor.recording import Recording

SHARED_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def synthetic_discharge(seed: int = 0, n: int = 600, *, recharge: bool = False) -> dict[str, np.ndarray]:
    """Rest, then a pulsed discharge (and optionally a longer, slower recharge) of a 2.5 Ah cell."""
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(n) * 1.0 + rng.uniform(0.0, 0.2, n), 3)
    t.sort()
    i = np.where(np.arange(n) < 10, 0.0, 2.0 + 0.5 * (np.arange(n) // 40 % 2))
    if recharge:
        i = np.concatenate([i, np.zeros(20), np.full(3 * n, -0.9)])
        t = np.concatenate([t, t[-1] + 1.0 + np.arange(20 + 3 * n) * 1.0])
    q = np.concatenate([[0.0], np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t))]) / 3600.0
    soc = 1.0 - q / 2.5
    v = 3.3 + 0.8 * soc - 0.05 * i + rng.normal(0.0, 2e-4, len(t))
    temp_c = 25.0 + 0.002 * np.arange(len(t)) + rng.normal(0.0, 0.01, len(t))
    return {
        "time_s": np.round(t, 3),
        "voltage_V": np.round(v, 5),
        "current_A": np.round(i, 5),
        "temperature_C": np.round(temp_c, 2),
    }


def write_csv(path: Path, columns: dict[str, np.ndarray | list], order: list[str] | None = None) -> Path:
    names = order or list(columns)
    lines = [",".join(names)]
    n = len(next(iter(columns.values())))
    for k in range(n):
        lines.append(",".join(str(columns[c][k]) for c in names))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def error_of(path: Path, **kwargs) -> str:
    with pytest.raises(InputDataError) as info:
        load_csv(path, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg, "error messages must be one line"
    assert str(path) in msg, "error messages must name the file"
    return msg


@pytest.fixture
def good_csv(tmp_path: Path) -> Path:
    return write_csv(tmp_path / "good.csv", synthetic_discharge(1))


# ---------------------------------------------------------------------------
# valid files
# ---------------------------------------------------------------------------


def test_loads_columns_in_any_order_and_ignores_extra_columns(tmp_path: Path) -> None:
    data = synthetic_discharge(2)
    data["mode"] = ["DCHG"] * len(data["time_s"])
    data["group1_voltage_V"] = data["voltage_V"] / 2
    path = write_csv(tmp_path / "any_order.csv", data, ["mode", "current_A", "temperature_C", "group1_voltage_V", "voltage_V", "time_s"])
    rec = load_csv(path)
    np.testing.assert_array_equal(rec.time_s, data["time_s"])
    np.testing.assert_array_equal(rec.voltage_v, data["voltage_V"])
    np.testing.assert_array_equal(rec.current_a, data["current_A"])
    np.testing.assert_allclose(rec.temperature_k, data["temperature_C"] + 273.15, rtol=0, atol=1e-12)
    assert rec.source == str(path)
    assert rec.metadata["temperature_column"] == "temperature_C"
    assert rec.charge_drawn_ah() > 0


def test_save_then_load_gives_identical_arrays(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    n = 500
    t = np.cumsum(rng.uniform(0.01, 2.0, n))
    i = 1.5 + rng.normal(0, 0.3, n)
    v = 3.9 - 0.3 * np.linspace(0, 1, n) - 0.04 * i
    rec = Recording(time_s=t, voltage_v=v, current_a=i, temperature_k=298.15 + rng.normal(0, 1, n))
    path = save_csv(rec, tmp_path / "roundtrip.csv")
    back = load_csv(path)
    assert np.array_equal(back.time_s, rec.time_s)
    assert np.array_equal(back.voltage_v, rec.voltage_v)
    assert np.array_equal(back.current_a, rec.current_a)
    np.testing.assert_allclose(back.temperature_k, rec.temperature_k, rtol=0, atol=1e-9)
    assert path.read_text().splitlines()[0] == "time_s,voltage_V,current_A,temperature_C"


def test_save_without_temperature_writes_three_columns_and_loads_none(tmp_path: Path) -> None:
    rec = Recording(time_s=np.arange(5.0), voltage_v=np.full(5, 3.7), current_a=np.full(5, 1.0))
    path = save_csv(rec, tmp_path / "no_temp.csv")
    assert path.read_text().splitlines()[0] == "time_s,voltage_V,current_A"
    assert load_csv(path, expect_discharge=False).temperature_k is None


def test_save_refuses_to_overwrite_unless_asked(tmp_path: Path, good_csv: Path) -> None:
    rec = load_csv(good_csv)
    with pytest.raises(InputDataError, match="already exists"):
        save_csv(rec, good_csv)
    save_csv(rec, good_csv, overwrite=True)
    assert not list(tmp_path.glob(".*.tmp")), "no temporary file may be left behind"


def test_comment_lines_before_header_are_skipped_and_counted_in_line_numbers(tmp_path: Path) -> None:
    path = tmp_path / "commented.csv"
    path.write_text("# exported by cycler\n# cell 7\ntime_s,voltage_V,current_A\n0,3.7,1\n1,abc,1\n")
    msg = error_of(path)
    assert "line 5 (data row 2)" in msg and "'abc'" in msg and "voltage_V" in msg


def test_byte_order_mark_and_whitespace_in_header_are_accepted(tmp_path: Path) -> None:
    path = tmp_path / "bom.csv"
    path.write_bytes("\ufefftime_s, voltage_V ,current_A\n0,3.7,1\n1,3.69,1\n2,3.68,1\n".encode())
    rec = load_csv(path)
    assert len(rec.time_s) == 3


# ---------------------------------------------------------------------------
# file-level errors
# ---------------------------------------------------------------------------


def test_missing_file_is_reported(tmp_path: Path) -> None:
    assert "not found" in error_of(tmp_path / "nope.csv")


def test_directory_instead_of_file_is_reported(tmp_path: Path) -> None:
    assert "directory" in error_of(tmp_path)


@pytest.mark.parametrize("content", ["", "\n\n  \n"])
def test_empty_file_is_reported(tmp_path: Path, content: str) -> None:
    path = tmp_path / "empty.csv"
    path.write_text(content)
    assert "empty" in error_of(path)


def test_header_only_file_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "header.csv"
    path.write_text("time_s,voltage_V,current_A\n\n")
    assert "no data rows" in error_of(path)


def test_non_utf8_file_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "latin1.csv"
    path.write_bytes("time_s,voltage_V,current_A,temp_°C\n0,3.7,1,20\n".encode("latin-1"))
    assert "UTF-8" in error_of(path)


def test_missing_column_is_named_and_found_columns_listed(tmp_path: Path) -> None:
    data = synthetic_discharge(3)
    del data["current_A"]
    msg = error_of(write_csv(tmp_path / "no_current.csv", data))
    assert "'current_A'" in msg and "found: time_s, voltage_V, temperature_C" in msg


def test_wrong_case_column_name_gets_a_hint(tmp_path: Path) -> None:
    path = tmp_path / "case.csv"
    path.write_text("time_s,Voltage_V,current_A\n0,3.7,1\n")
    msg = error_of(path)
    assert "'voltage_V'" in msg and "case-sensitive" in msg


def test_semicolon_delimited_file_gets_a_delimiter_hint(tmp_path: Path) -> None:
    path = tmp_path / "semicolon.csv"
    path.write_text("time_s;voltage_V;current_A\n0;3.7;1\n")
    assert "delimiter" in error_of(path)


def test_duplicate_header_column_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "dup_col.csv"
    path.write_text("time_s,voltage_V,current_A,voltage_V\n0,3.7,1,3.7\n")
    msg = error_of(path)
    assert "line 1" in msg and "'voltage_V'" in msg and "more than once" in msg


def test_row_with_extra_fields_is_reported_with_its_line(tmp_path: Path) -> None:
    path = tmp_path / "extra.csv"
    path.write_text("time_s,voltage_V,current_A\n0,3.7,1\n1,3.7,1,5\n")
    msg = error_of(path)
    assert "line 3 (data row 2)" in msg and "4 fields" in msg


# ---------------------------------------------------------------------------
# cell-level errors
# ---------------------------------------------------------------------------


def test_non_numeric_cell_names_line_column_and_value(tmp_path: Path) -> None:
    data = synthetic_discharge(4)
    data["current_A"] = data["current_A"].astype(object)
    data["current_A"][41] = "2.0A"
    msg = error_of(write_csv(tmp_path / "text.csv", data))
    assert "line 43 (data row 42)" in msg and "'current_A'" in msg and "'2.0A'" in msg and "not a number" in msg


@pytest.mark.parametrize("cell", ["", "nan", "NaN", "inf"])
def test_missing_or_non_finite_value_is_rejected_with_its_line(tmp_path: Path, cell: str) -> None:
    data = synthetic_discharge(5)
    data["voltage_V"] = data["voltage_V"].astype(object)
    data["voltage_V"][99] = cell
    data["voltage_V"][200] = cell
    msg = error_of(write_csv(tmp_path / "nan.csv", data))
    assert "line 101 (data row 100)" in msg and "voltage_V" in msg and "2 such row(s)" in msg and "drop_nan=True" in msg


def test_drop_nan_drops_rows_and_counts_them(tmp_path: Path) -> None:
    data = synthetic_discharge(6)
    n = len(data["time_s"])
    data["time_s"] = data["time_s"].astype(object)
    data["time_s"][10] = ""
    data["current_A"] = data["current_A"].astype(object)
    data["current_A"][20] = "nan"
    rec = load_csv(write_csv(tmp_path / "nan.csv", data), drop_nan=True)
    assert len(rec.time_s) == n - 2
    assert rec.metadata["dropped_nan_rows"] == 2


def test_blank_line_inside_the_data_is_an_empty_row(tmp_path: Path) -> None:
    path = tmp_path / "blank.csv"
    path.write_text("time_s,voltage_V,current_A\n0,3.7,1\n\n2,3.69,1\n3,3.68,1\n")
    assert "line 3 (data row 2)" in error_of(path)
    assert len(load_csv(path, drop_nan=True).time_s) == 3


def test_non_positive_voltage_is_rejected_with_its_line(tmp_path: Path) -> None:
    data = synthetic_discharge(7)
    data["voltage_V"][30] = 0.0
    path = write_csv(tmp_path / "zero_v.csv", data)
    msg = error_of(path)
    assert "line 32 (data row 31)" in msg and "not positive" in msg
    assert load_csv(path, drop_nan=True).metadata["dropped_nan_rows"] == 1


# ---------------------------------------------------------------------------
# time axis
# ---------------------------------------------------------------------------


def test_time_going_backwards_names_first_offending_line_and_both_times(tmp_path: Path) -> None:
    data = synthetic_discharge(8)
    data["time_s"][50] = data["time_s"][48]
    msg = error_of(write_csv(tmp_path / "backwards.csv", data))
    assert "line 52 (data row 51)" in msg
    assert repr(float(data["time_s"][48])) in msg and repr(float(data["time_s"][49])) in msg
    assert "strictly increasing" in msg and "backwards" in msg


def test_time_going_backwards_is_an_error_even_with_a_duplicate_policy(tmp_path: Path) -> None:
    data = synthetic_discharge(9)
    data["time_s"][50] = 0.5
    error_of(write_csv(tmp_path / "backwards.csv", data), duplicate_times="keep_last")


def test_repeated_timestamp_is_rejected_by_default_with_a_hint(tmp_path: Path) -> None:
    data = synthetic_discharge(10)
    data["time_s"][11] = data["time_s"][10]
    msg = error_of(write_csv(tmp_path / "dup.csv", data))
    assert "line 13 (data row 12)" in msg and "keep_last" in msg


def test_duplicate_times_keep_last_and_keep_first_choose_the_right_row(tmp_path: Path) -> None:
    path = tmp_path / "step.csv"
    path.write_text("time_s,voltage_V,current_A\n0,4.10,0\n0,4.05,2\n1,4.04,2\n2,4.03,2\n3,4.02,2\n")
    last = load_csv(path, duplicate_times="keep_last")
    first = load_csv(path, duplicate_times="keep_first")
    assert last.voltage_v[0] == 4.05 and last.current_a[0] == 2.0
    assert first.voltage_v[0] == 4.10 and first.current_a[0] == 0.0
    assert last.metadata["dropped_duplicate_time_rows"] == 1
    with pytest.raises(InputDataError, match="duplicate_times"):
        load_csv(path, duplicate_times="average")


def test_long_format_file_suggests_load_csv_groups(tmp_path: Path) -> None:
    path = tmp_path / "long.csv"
    path.write_text("soc_label,cell,time_s,voltage_V,current_A\nS1,C1,0,4.0,0\nS1,C1,1,3.9,2\nS2,C1,0,3.8,0\n")
    assert "load_csv_groups" in error_of(path)


def test_load_csv_groups_splits_records_and_reports_file_lines(tmp_path: Path) -> None:
    path = tmp_path / "long.csv"
    path.write_text(
        "soc_label,cell,time_s,voltage_V,current_A,temperature_C\n"
        "S1,C1,0,4.00,0,25\nS1,C1,1,3.90,2,25\nS1,C1,2,3.89,2,25\n"
        "S2,C1,0,3.80,0,\nS2,C1,1,3.70,2,\nS2,C1,2,3.69,2,\n"
        "S3,C1,0,3.60,0,25\nS3,C1,1,x,2,25\n"
    )
    with pytest.raises(InputDataError, match=r"line 9 \(data row 8\).*'x'"):
        load_csv_groups(path, ("soc_label", "cell"))
    path.write_text(path.read_text().replace(",x,", ",3.5,"))
    groups = load_csv_groups(path, ("soc_label", "cell"))
    assert list(groups) == [("S1", "C1"), ("S2", "C1"), ("S3", "C1")]
    assert groups[("S1", "C1")].temperature_k is not None
    assert groups[("S2", "C1")].temperature_k is None  # column empty for the whole record
    assert groups[("S3", "C1")].metadata["group"] == {"soc_label": "S3", "cell": "C1"}
    assert "[soc_label=S2, cell=C1]" in groups[("S2", "C1")].source
    with pytest.raises(InputDataError, match="'record'"):
        load_csv_groups(path, ("record",))


# ---------------------------------------------------------------------------
# units and sign
# ---------------------------------------------------------------------------


def test_millivolts_are_detected(tmp_path: Path) -> None:
    data = synthetic_discharge(11)
    data["voltage_V"] = np.round(data["voltage_V"] * 1000, 2)
    msg = error_of(write_csv(tmp_path / "mv.csv", data))
    assert "millivolts" in msg and "convert to volts" in msg


def test_milliamperes_are_detected(tmp_path: Path) -> None:
    data = synthetic_discharge(12)
    data["current_A"] = data["current_A"] * 1000
    assert "milliamperes" in error_of(write_csv(tmp_path / "ma.csv", data))


def test_flipped_current_sign_is_rejected_with_an_explanation(tmp_path: Path) -> None:
    data = synthetic_discharge(13)
    data["current_A"] = -data["current_A"]
    path = write_csv(tmp_path / "flipped.csv", data)
    msg = error_of(path)
    assert "current_A > 0 must mean DISCHARGE" in msg
    assert load_csv(path, expect_discharge=False).current_a.min() < 0


def test_discharge_followed_by_longer_recharge_is_accepted(tmp_path: Path) -> None:
    data = synthetic_discharge(14, recharge=True)
    rec = load_csv(write_csv(tmp_path / "cycle.csv", data))
    nonzero = rec.current_a[rec.current_a != 0]
    assert rec.charge_drawn_ah() < 0 and np.mean(nonzero < 0) > 0.6  # the throughput alone would look like a flip
    assert voltage_response_score(rec.voltage_v, rec.current_a) > 0.3


def test_flipped_discharge_with_recharge_is_rejected(tmp_path: Path) -> None:
    data = synthetic_discharge(15, recharge=True)
    data["current_A"] = -data["current_A"]
    assert "DISCHARGE" in error_of(write_csv(tmp_path / "cycle_flipped.csv", data))


def test_voltage_response_score_is_antisymmetric_in_the_current_sign() -> None:
    data = synthetic_discharge(16)
    s = voltage_response_score(data["voltage_V"], data["current_A"])
    assert s > 0.3
    assert voltage_response_score(data["voltage_V"], -data["current_A"]) == pytest.approx(-s)
    assert voltage_response_score(np.full(5, 3.7), np.zeros(5)) == 0.0
    check_current_sign(data["time_s"], data["voltage_V"], data["current_A"], source="x")


# ---------------------------------------------------------------------------
# temperature
# ---------------------------------------------------------------------------


def test_temperature_c_is_preferred_over_chamber_temperature(tmp_path: Path) -> None:
    data = synthetic_discharge(17)
    data["chamber_temperature_C"] = np.full(len(data["time_s"]), 40.0)
    rec = load_csv(write_csv(tmp_path / "both.csv", data, ["time_s", "voltage_V", "current_A", "chamber_temperature_C", "temperature_C"]))
    assert rec.metadata["temperature_column"] == "temperature_C"
    assert rec.temperature_k[0] == pytest.approx(data["temperature_C"][0] + 273.15)


@pytest.mark.parametrize("column", ["chamber_temperature_C", "temperature1_C", "ambient_temperature_C"])
def test_listed_fallback_temperature_columns_are_used(tmp_path: Path, column: str) -> None:
    assert column in TEMPERATURE_COLUMNS
    data = synthetic_discharge(18)
    data[column] = data.pop("temperature_C")
    rec = load_csv(write_csv(tmp_path / "fallback.csv", data))
    assert rec.metadata["temperature_column"] == column and rec.temperature_k is not None


def test_unlisted_celsius_columns_are_not_taken_as_temperature(tmp_path: Path) -> None:
    data = synthetic_discharge(19)
    data["temperature_pos_C"] = data.pop("temperature_C")
    rec = load_csv(write_csv(tmp_path / "tab.csv", data))
    assert rec.temperature_k is None and rec.metadata["temperature_column"] is None
    rec = load_csv(write_csv(tmp_path / "tab.csv", data), temperature_column="temperature_pos_C")
    assert rec.temperature_k is not None


def test_explicit_temperature_column_must_exist_and_carry_a_unit(tmp_path: Path, good_csv: Path) -> None:
    assert "'cell_T'" in error_of(good_csv, temperature_column="cell_T")
    assert "must end in _C" in error_of(good_csv, temperature_column="voltage_V")


def test_temperature_in_kelvin_column_is_used_directly(tmp_path: Path) -> None:
    data = synthetic_discharge(20)
    data["temperature_K"] = np.round(data.pop("temperature_C") + 273.15, 2)
    rec = load_csv(write_csv(tmp_path / "kelvin.csv", data))
    np.testing.assert_array_equal(rec.temperature_k, data["temperature_K"])


def test_kelvin_values_in_a_celsius_column_are_rejected(tmp_path: Path) -> None:
    data = synthetic_discharge(21)
    data["temperature_C"] = data["temperature_C"] + 273.15
    msg = error_of(write_csv(tmp_path / "k_in_c.csv", data))
    assert "'temperature_C'" in msg and "kelvin" in msg


def test_temperature_gap_is_rejected_or_filled_with_drop_nan(tmp_path: Path) -> None:
    data = synthetic_discharge(22)
    data["temperature_C"] = data["temperature_C"].astype(object)
    data["temperature_C"][60] = ""
    path = write_csv(tmp_path / "temp_gap.csv", data)
    msg = error_of(path)
    assert "line 62 (data row 61)" in msg and "'temperature_C'" in msg
    rec = load_csv(path, drop_nan=True)
    assert len(rec.time_s) == len(data["time_s"])  # no V/I sample lost
    assert rec.metadata["filled_temperature_rows"] == 1
    assert rec.temperature_k[60] in (data["temperature_C"][59] + 273.15, data["temperature_C"][61] + 273.15)


def test_entirely_empty_temperature_column_gives_none(tmp_path: Path) -> None:
    data = synthetic_discharge(23)
    data["temperature_C"] = [""] * len(data["time_s"])
    rec = load_csv(write_csv(tmp_path / "no_temp.csv", data))
    assert rec.temperature_k is None


# ---------------------------------------------------------------------------
# the public measured data sets
# ---------------------------------------------------------------------------


def _public_csvs() -> list[Path]:
    return sorted(SHARED_DATA.glob("*/*.csv")) if SHARED_DATA.is_dir() else []


@pytest.mark.skipif(not _public_csvs(), reason=f"{SHARED_DATA} not present")
def test_every_public_csv_loads_with_documented_options() -> None:
    """Time series load with defaults, except files with repeated timestamps (keep_last) and long-format files."""
    import csv

    loaded = 0
    for path in _public_csvs():
        with path.open() as fh:
            header = next(csv.reader(fh))
        if "time_s" not in header:  # a table such as an OCV curve, not a recording
            with pytest.raises(InputDataError, match="'time_s'"):
                load_csv(path)
            continue
        if "soc_label" in header:
            groups = load_csv_groups(path, ("soc_label", "cell"), duplicate_times="keep_last", drop_nan=True)
            assert groups and all(len(r.time_s) >= 2 for r in groups.values()), path
            loaded += len(groups)
            continue
        t = np.genfromtxt(path, delimiter=",", names=True, usecols=("time_s",))["time_s"]
        if (np.diff(t) == 0).any():
            with pytest.raises(InputDataError, match="keep_last"):
                load_csv(path)
            rec = load_csv(path, duplicate_times="keep_last")
        else:
            rec = load_csv(path)
        assert len(rec.time_s) > 10 and np.all(np.diff(rec.time_s) > 0), path
        assert np.median(rec.voltage_v) < 100, path
        assert voltage_response_score(rec.voltage_v, rec.current_a) > 0.1, path  # current_A > 0 = discharge
        loaded += 1
    assert loaded > 40


@pytest.mark.skipif(not _public_csvs(), reason=f"{SHARED_DATA} not present")
def test_public_csv_with_flipped_sign_is_rejected(tmp_path: Path) -> None:
    """Both a plain discharge and a discharge+recharge file are caught when the sign is flipped."""
    for name in ("panasonic_18650pf/drive_T25C_US06.csv", "lgm50_wmg/cc_T25C_1C.csv", "k2_lfp26650_arts/cc_discharge_T20C.csv"):
        src = SHARED_DATA / name
        if not src.exists():
            continue
        rec = load_csv(src)
        flipped = Recording(rec.time_s, rec.voltage_v, -rec.current_a, rec.temperature_k)
        path = save_csv(flipped, tmp_path / re.sub(r"\W", "_", name))
        assert "DISCHARGE" in error_of(path)
