"""A tabulated OCV (state of charge -> V) as the cell's positive OCP: the reader, the branch, the CLI."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from battery_predictor import ocp
from battery_predictor.errors import InputDataError
from battery_predictor.fitting.ocv import cell_ocv_v, ocv_from_table, params_capacity_ah, positive_ocp_values
from battery_predictor.io.ocv_table import is_ocv_table, load_ocv_table
from battery_predictor.params import load_params

REPO = Path(__file__).resolve().parents[2]
LGM50 = REPO / "params" / "lgm50.yaml"
CLI = Path(sys.executable).with_name("battery-predictor")
SHARED_TABLE = REPO.parent / "shared" / "data" / "lgm50_wmg" / "ocv_T25C.csv"


def true_ocv_v(soc: np.ndarray) -> np.ndarray:
    """An NMC-like open-circuit voltage (V), unlike Chen2020's LG M50 curve."""
    soc = np.asarray(soc, dtype=float)
    return 3.3 + 0.85 * soc + 0.06 * np.tanh((soc - 0.5) / 0.1) - 0.35 * np.exp(-soc / 0.03)


def write_table(path: Path, hysteresis_v: float | None = 0.01, percent: bool = True) -> Path:
    soc = np.linspace(0.0, 1.0, 51)
    head = ["soc_percent" if percent else "soc", "ocv_mean_V"] + (["hysteresis_V"] if hysteresis_v is not None else [])
    rows = [",".join(head)]
    for z in soc:
        cells = [f"{100 * z if percent else z:.4f}", f"{float(true_ocv_v(z)):.5f}"]
        if hysteresis_v is not None:
            cells.append(f"{hysteresis_v:.4f}")
        rows.append(",".join(cells))
    path.write_text("\n".join(rows) + "\n")
    return path


def test_a_table_is_told_from_a_recording_by_its_header(tmp_path):
    assert is_ocv_table(write_table(tmp_path / "t.csv"))
    rec = tmp_path / "rec.csv"
    rec.write_text("time_s,voltage_V,current_A,soc\n0,4.1,0.1,1.0\n")
    assert not is_ocv_table(rec)


def test_the_discharge_branch_is_the_mean_minus_the_hysteresis_and_soc_may_be_a_fraction(tmp_path):
    table = load_ocv_table(write_table(tmp_path / "t.csv", hysteresis_v=0.012, percent=False))
    dis = ocv_from_table(table, 5.0)
    mean = ocv_from_table(table, 5.0, branch="mean")
    np.testing.assert_allclose(mean.ocv_v - dis.ocv_v, 0.012, atol=1e-9)
    np.testing.assert_allclose(np.interp(table.soc, mean.soc, mean.ocv_v), table.ocv_v, atol=1e-6)
    assert dis.capacity_ah == 5.0 and dis.discharge_current_a == 0.0


def test_a_table_without_hysteresis_gives_its_mean_and_says_so(tmp_path):
    curve = ocv_from_table(load_ocv_table(write_table(tmp_path / "t.csv", hysteresis_v=None)), 5.0)
    assert "no hysteresis" in curve.method


@pytest.mark.parametrize("text, match", [
    ("soc_percent,ocv_mean_V\n" + "\n".join(f"{k},x" for k in range(12)), "not a number"),
    ("soc_percent,volts\n" + "\n".join(f"{k},3.7" for k in range(12)), "voltage column"),
    ("soc_percent,ocv_V\n" + "\n".join(f"{k},3.7" for k in range(5)), "at least 10 rows"),
    ("soc_percent,ocv_V\n" + "\n".join(f"{10 * k},3.7" for k in range(12)), "outside 0..1"),
    ("soc_percent,ocv_V\n" + "\n".join(f"{k},37" for k in range(12)), "not a cell's OCV"),
])
def test_a_bad_table_is_a_one_line_error(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text + "\n")
    with pytest.raises(InputDataError, match=match):
        load_ocv_table(path)


def test_a_partial_table_is_refused(tmp_path):
    table = load_ocv_table(write_table(tmp_path / "t.csv"))
    part = type(table)(table.soc[10:], table.ocv_v[10:], None, table.source)
    with pytest.raises(InputDataError, match="covers 20..100 %"):
        ocv_from_table(part, 5.0)


def test_the_derived_ocp_reproduces_the_table_and_keeps_the_params_capacity(tmp_path):
    params = load_params(LGM50)
    capacity = params_capacity_ah(params)
    curve = ocv_from_table(load_ocv_table(write_table(tmp_path / "t.csv")), capacity)
    fit = positive_ocp_values(params, curve)
    assert fit.rms_error_v < 0.002
    new = params.with_values({}, ocp=fit.ocp_values, manual={**params.manual, **fit.manual_values})
    inner = (curve.soc > 0.05) & (curve.soc < 0.95)
    assert np.max(np.abs(cell_ocv_v(new, curve.soc[inner]) - curve.ocv_v[inner])) < 0.01
    assert params_capacity_ah(new) == pytest.approx(capacity, rel=1e-3)


@pytest.mark.skipif(not SHARED_TABLE.is_file(), reason="measured data not available (../shared/data)")
def test_cli_takes_the_lgm50_table_into_the_params(tmp_path):
    out = tmp_path / "lgm50_ocv.yaml"
    proc = subprocess.run([str(CLI), "ocv", "--params", str(LGM50), "--data", str(SHARED_TABLE), "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "table, discharge branch" in proc.stdout and f"wrote {out}" in proc.stdout
    params = load_params(out)
    assert ocp.has_series(params.ocp) and "ocv_T25C.csv" in params.ocp_source
