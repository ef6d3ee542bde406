"""Series-group voltages of a measured pack: CSV ``group<k>_voltage_V`` -> Recording -> bag ``cell_voltage`` -> Recording.

The Nissan Leaf 6S2P data (``../shared/data/nissan_leaf_6s2p_pack_ornl``) carries each group's voltage; a
pack ends when its weakest group reaches the cell cut-off, so the fit and the route safety check read them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.errors import InputDataError
from battery_predictor.fitting.resample import resample_windows
from battery_predictor.io.csv_io import load_csv, load_csv_groups, save_csv
from battery_predictor.io.loader import bag_to_csv, csv_to_bag, load_recording
from battery_predictor.recording import Recording


def _write(path: Path, rows: list[str], header: str = "time_s,current_A,voltage_V,group2_voltage_V,group1_voltage_V") -> Path:
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def _discharge(n: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n, dtype=float)
    i = np.where(t < 2, 0.0, 10.0)
    g = np.column_stack([4.1 - 0.01 * t, 4.05 - 0.012 * t])
    v = g.sum(axis=1) - 0.01 * i
    return t, i, v, g


def test_group_columns_are_read_in_group_order_with_their_names(tmp_path: Path) -> None:
    p = _write(tmp_path / "g.csv", ["0,0,8.2,4.0,4.2", "1,5,8.0,3.9,4.1", "2,5,7.9,3.85,4.05"])
    rec = load_csv(p)
    assert rec.group_voltage_v is not None and rec.group_voltage_v.shape == (3, 2)
    assert np.array_equal(rec.group_voltage_v[:, 0], [4.2, 4.1, 4.05])  # group1 first though it comes second
    assert rec.metadata["group_voltage_columns"] == ["group1_voltage_V", "group2_voltage_V"]
    assert np.array_equal(rec.min_group_voltage_v, [4.0, 3.9, 3.85])


def test_without_group_columns_there_are_none(tmp_path: Path) -> None:
    p = _write(tmp_path / "n.csv", ["0,0,8.2", "1,5,8.0", "2,5,7.9"], header="time_s,current_A,voltage_V")
    rec = load_csv(p)
    assert rec.group_voltage_v is None and rec.min_group_voltage_v is None
    assert "group_voltage_columns" not in rec.metadata


def test_a_missing_group_reading_is_nan_and_never_drops_the_sample(tmp_path: Path) -> None:
    p = _write(tmp_path / "g.csv", ["0,0,8.2,4.0,4.2", "1,5,8.0,,4.1", "2,5,7.9,nan,", "3,5,7.8,3.8,4.0"])
    rec = load_csv(p)
    assert rec.time_s.size == 4
    assert np.isnan(rec.group_voltage_v[1, 1]) and np.isnan(rec.group_voltage_v[2]).all()
    assert rec.min_group_voltage_v[1] == 4.1 and np.isnan(rec.min_group_voltage_v[2])


def test_group_columns_that_are_empty_everywhere_give_none(tmp_path: Path) -> None:
    rec = load_csv(_write(tmp_path / "e.csv", ["0,0,8.2,,", "1,5,8.0,,", "2,5,7.9,,"]))
    assert rec.group_voltage_v is None


def test_a_non_positive_group_voltage_names_its_line_and_column(tmp_path: Path) -> None:
    p = _write(tmp_path / "z.csv", ["0,0,8.2,4.0,4.2", "1,5,8.0,0,4.1", "2,5,7.9,3.8,4.0"])
    with pytest.raises(InputDataError, match=r"line 3 \(data row 2\): group2_voltage_V 0\.0 is not positive.*drop_nan"):
        load_csv(p)
    assert np.isnan(load_csv(p, drop_nan=True).group_voltage_v[1, 1])


def test_millivolt_group_voltages_are_refused(tmp_path: Path) -> None:
    p = _write(tmp_path / "mv.csv", ["0,0,8.2,4000,4200", "1,5,8.0,3900,4100", "2,5,7.9,3850,4050"])
    with pytest.raises(InputDataError, match="millivolts"):
        load_csv(p)


def test_rows_dropped_for_the_pack_columns_drop_their_group_voltages(tmp_path: Path) -> None:
    p = _write(tmp_path / "d.csv", ["0,0,8.2,4.0,4.2", "1,5,,3.9,4.1", "2,5,7.9,3.85,4.05", "2,5,7.8,3.8,4.0"])
    rec = load_csv(p, drop_nan=True, duplicate_times="keep_last")
    assert np.array_equal(rec.group_voltage_v[:, 1], [4.0, 3.8])
    assert np.array_equal(rec.slice_time(1.0, 3.0).group_voltage_v, [[4.0, 3.8]])


def test_long_format_groups_keep_their_own_group_voltages(tmp_path: Path) -> None:
    p = _write(tmp_path / "l.csv", ["0,0,8.2,4.0,4.2,a", "1,5,8.0,3.9,4.1,a", "0,0,8.1,3.95,4.15,b", "1,5,7.9,3.8,4.0,b"],
               header="time_s,current_A,voltage_V,group2_voltage_V,group1_voltage_V,run")
    out = load_csv_groups(p, ["run"], expect_discharge=False)
    assert np.array_equal(out[("b",)].group_voltage_v[:, 0], [4.15, 4.0])


def test_save_then_load_keeps_the_group_voltages(tmp_path: Path) -> None:
    t, i, v, g = _discharge()
    g[5, 1] = np.nan
    rec = Recording(t, v, i, group_voltage_v=g)
    back = load_csv(save_csv(rec, tmp_path / "s.csv"))
    assert np.array_equal(back.group_voltage_v, g, equal_nan=True)


def test_a_recording_refuses_group_voltages_of_another_length() -> None:
    t, i, v, g = _discharge()
    with pytest.raises(InputDataError, match="group voltages have shape"):
        Recording(t, v, i, group_voltage_v=g[:-1])


def test_resampling_averages_each_group_like_the_voltage_over_its_measured_samples() -> None:
    t, i, v, g = _discharge(41)
    g[11:21, 0] = np.nan  # group 1 not measured in the second window
    g[13, 1] = np.nan
    out = resample_windows(Recording(t, v, i, group_voltage_v=g), 10.0)
    assert out.group_voltage_v.shape == (out.time_s.size, 2)
    assert np.isnan(out.group_voltage_v[2, 0])
    window = slice(11, 21)
    assert out.voltage_v[2] == pytest.approx(np.mean(v[window]))
    assert out.group_voltage_v[2, 1] == pytest.approx(np.nanmean(g[window, 1]))
    assert out.group_voltage_v[1, 0] == pytest.approx(np.mean(g[1:11, 0]))


def test_csv_to_bag_to_recording_round_trips_the_group_voltages_as_cell_voltage(tmp_path: Path) -> None:
    t, i, v, g = _discharge()
    g[7, 0] = np.nan
    src = save_csv(Recording(t, v, i, group_voltage_v=g), tmp_path / "src.csv")
    bag = csv_to_bag(src, tmp_path / "bag")
    rec = load_recording(bag)
    assert rec.group_voltage_v is not None and rec.group_voltage_v.shape == g.shape
    # BatteryState.cell_voltage is float32
    assert np.allclose(rec.group_voltage_v, g, rtol=0, atol=1e-6, equal_nan=True)
    assert np.isnan(rec.group_voltage_v[7, 0])
    back = load_csv(bag_to_csv(bag, tmp_path / "back.csv"))
    assert np.allclose(back.group_voltage_v, g, rtol=0, atol=1e-6, equal_nan=True)


def test_a_bag_without_cell_voltages_reads_none(tmp_path: Path) -> None:
    t, i, v, _ = _discharge()
    bag = csv_to_bag(save_csv(Recording(t, v, i), tmp_path / "n.csv"), tmp_path / "bag")
    assert load_recording(bag).group_voltage_v is None
