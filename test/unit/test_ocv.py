"""A measured open-circuit voltage as the positive OCP: the series, its YAML form, the derivation, the CLI."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from battery_predictor import ocp
from battery_predictor.errors import InputDataError, ParamsError
from battery_predictor.fitting.ocv import cell_ocv_v, positive_ocp_values, pseudo_ocv
from battery_predictor.params import load_params, params_from_dict
from battery_predictor.recording import Recording
from battery_predictor.simulation import SimulationRequest, StepLoad
from battery_predictor.simulation.engine.simulator import EngineSimulator

REPO = Path(__file__).resolve().parents[2]
PANASONIC = REPO / "params" / "panasonic_18650pf.yaml"
CLI = Path(sys.executable).with_name("battery-predictor")
SHARED_OCV = REPO.parent / "shared" / "data" / "panasonic_18650pf" / "ocv_C20_T25C.csv"
CAPACITY_AH = 2.7
CURRENT_A = CAPACITY_AH / 20


def true_ocv_v(soc: np.ndarray) -> np.ndarray:
    """An NCA-like open-circuit voltage (V) with a steep knee below 5 % SOC, unlike Chen2020's."""
    soc = np.asarray(soc, dtype=float)
    return 3.05 + 1.05 * soc + 0.08 * np.tanh((soc - 0.55) / 0.08) - 0.45 * np.exp(-soc / 0.025)


def low_rate_recording(step_v: float = 0.012, charge: bool = False) -> Recording:
    """600 s rest at full, then a C/20 discharge whose voltage is the OCV minus ``step_v``, 60 s samples."""
    t_rest = np.arange(0.0, 600.0, 60.0)
    t_dis = 600.0 + np.arange(0.0, 20 * 3600.0 + 1.0, 60.0)
    soc = 1.0 - (t_dis - 600.0) * CURRENT_A / 3600.0 / CAPACITY_AH
    time = [t_rest, t_dis]
    volt = [np.full(t_rest.size, true_ocv_v(1.0)), true_ocv_v(soc) - step_v]
    cur = [np.zeros(t_rest.size), np.full(t_dis.size, CURRENT_A)]
    if charge:
        t_ch = t_dis[-1] + 600.0 + np.arange(0.0, 18 * 3600.0, 60.0)
        soc_ch = soc[-1] + (t_ch - t_ch[0]) * CURRENT_A / 3600.0 / CAPACITY_AH
        time.append(t_ch)
        volt.append(true_ocv_v(soc_ch) + 3 * step_v)
        cur.append(np.full(t_ch.size, -CURRENT_A))
    return Recording(np.concatenate(time), np.concatenate(volt), np.concatenate(cur), source="synthetic-c20")


def test_series_section_round_trips_through_yaml_and_params():
    values = {ocp.CONSTANT_KEY: 4.0, ocp.SLOPE_KEY: -0.5}
    for k, (m, w, c) in enumerate([(0.3, 0.05, -0.1), (0.8, 0.02, -0.3)]):
        values.update({f"{ocp.PREFIX} centre {k:02d}": m, f"{ocp.PREFIX} width {k:02d}": w,
                       f"{ocp.PREFIX} coefficient {k:02d} [V]": c})
    section = ocp.values_to_section(values, "bench")
    assert ocp.section_to_values(section, "x") == values
    data = load_params(PANASONIC).to_dict()
    data["cell"]["ocp"] = section
    params = params_from_dict(yaml.safe_load(yaml.safe_dump(data)), "mem")
    assert params.ocp == values and params.ocp_source == "bench"
    assert params_from_dict(params.to_dict(), "again").ocp == values
    sto = np.linspace(0.1, 0.9, 9)
    import pybamm

    pv = params.parameter_values()
    fn = pv[ocp.POSITIVE_OCP_KEY]
    got = [float(pv.process_symbol(fn(pybamm.Scalar(s))).evaluate()) for s in sto]
    assert np.allclose(got, ocp.evaluate(values, sto))


@pytest.mark.parametrize("change, match", [
    ({"widths": [0.1]}, "same length"),
    ({"widths": [0.1, -0.1]}, "widths > 0"),
    ({"colour": 1}, "unknown key"),
])
def test_bad_series_section_is_one_params_error(change, match):
    section = {"positive": {"constant_v": 4.0, "slope_v": -0.5, "centres": [0.3, 0.8], "widths": [0.1, 0.1],
                            "coefficients_v": [-0.1, -0.2], **change}}
    with pytest.raises(ParamsError, match=match):
        ocp.section_to_values(section, "f.yaml")


def test_discharge_branch_is_raised_by_its_starting_step():
    curve = pseudo_ocv(low_rate_recording(step_v=0.012), 2.9)
    assert curve.method == "discharge branch"
    assert curve.capacity_ah == pytest.approx(CAPACITY_AH, rel=0.01)
    inner = (curve.soc > 0.02) & (curve.soc < 0.98)
    assert np.abs(curve.ocv_v[inner] - true_ocv_v(curve.soc[inner])).max() < 0.004


def test_mean_branch_needs_a_charge_and_takes_half_the_gap():
    with pytest.raises(InputDataError, match="no charge branch"):
        pseudo_ocv(low_rate_recording(), 2.9, branch="mean")
    curve = pseudo_ocv(low_rate_recording(step_v=0.01, charge=True), 2.9, branch="mean")
    inner = (curve.soc > 0.1) & (curve.soc < 0.9)
    assert np.abs(curve.ocv_v[inner] - (true_ocv_v(curve.soc[inner]) + 0.01)).max() < 0.004


def test_a_fast_discharge_is_not_an_ocv():
    rec = low_rate_recording()
    fast = Recording(rec.time_s / 10.0, rec.voltage_v, rec.current_a * 10.0, source="1C")
    with pytest.raises(InputDataError, match="C/10 or slower"):
        pseudo_ocv(fast, 2.9)


def test_derived_positive_ocp_makes_the_engine_follow_the_measured_low_rate_discharge():
    params = load_params(PANASONIC)
    rec = low_rate_recording()
    curve = pseudo_ocv(rec, 2.9)
    fit = positive_ocp_values(params, curve)
    assert fit.rms_error_v < 0.005
    new = params.__class__(**{**vars(params), "manual": {**params.manual, **fit.manual_values}, "ocp": fit.ocp_values})
    soc = np.linspace(0.05, 1.0, 50)
    assert np.abs(cell_ocv_v(new, soc) - true_ocv_v(soc)).max() < 0.01
    before = np.abs(cell_ocv_v(params, soc) - true_ocv_v(soc)).max()
    assert before > 0.05  # Chen2020's OCPs are far from this cell
    load = StepLoad(np.array([0.0]), np.array([CURRENT_A]), 21 * 3600.0)
    res = EngineSimulator().simulate(new, SimulationRequest(load=load, initial_soc=1.0,
                                                            output_time_s=np.arange(0.0, 21 * 3600.0, 60.0)))
    assert res.end_time_s * CURRENT_A / 3600.0 == pytest.approx(CAPACITY_AH, rel=0.02)
    q = res.time_s * CURRENT_A / 3600.0
    measured = np.interp(q, (rec.time_s - 600.0) * CURRENT_A / 3600.0, rec.voltage_v)
    body = q < 0.95 * CAPACITY_AH
    assert np.sqrt(np.mean((res.pack_voltage_v[body] - measured[body]) ** 2)) < 0.01


def test_cli_writes_params_with_the_measured_ocp(tmp_path):
    rec = low_rate_recording()
    csv = tmp_path / "c20.csv"
    rows = ["time_s,voltage_V,current_A"] + [f"{t:.1f},{v:.5f},{i:.5f}"
                                              for t, v, i in zip(rec.time_s, rec.voltage_v, rec.current_a)]
    csv.write_text("\n".join(rows) + "\n")
    out = tmp_path / "cell.yaml"
    proc = subprocess.run([str(CLI), "ocv", "--params", str(PANASONIC), "--data", str(csv), "--out", str(out),
                           "--plot", str(tmp_path / "ocv.png")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert f"wrote {out}" in proc.stdout
    params = load_params(out)
    assert ocp.has_series(params.ocp) and "c20.csv" in params.ocp_source
    assert (tmp_path / "ocv.png").stat().st_size > 1000
    bad = subprocess.run([str(CLI), "ocv", "--params", str(PANASONIC), "--data", str(csv), "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "is a directory" in bad.stderr and "Traceback" not in bad.stderr


@pytest.mark.skipif(not SHARED_OCV.is_file(), reason="measured data not available (../shared/data)")
def test_measured_panasonic_c20_curve_is_reproduced_within_two_millivolts():
    from battery_predictor.io.loader import load_recording

    rec = load_recording(SHARED_OCV, expect_discharge=False, duplicate_times="keep_last")
    params = load_params(PANASONIC)
    curve = pseudo_ocv(rec, 2.9)
    fit = positive_ocp_values(params, curve)
    assert curve.capacity_ah == pytest.approx(2.995, abs=0.01)
    assert fit.rms_error_v < 0.002
