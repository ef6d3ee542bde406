"""The diagnosis on measured data: the LG M50 cell at 10 degC, the Panasonic 18650PF at -10 degC.

Reference: the four 25 degC constant-current discharges (identified on the SPM engine); observed: the
0.5C, 1C and 2C discharges at 10 degC (each trimmed to its discharge), judged with the
cross-recording split (each fold fits on the two other discharges whole and the first 60 % of the
discharge throughput of the third, and predicts the rest of it). The Panasonic: 25 degC HWFET + LA92
(../shared/data) against the -10 degC HWFET + US06 in test/data (each after a 2 h soak). Findings in
docs/findings.md.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "lgm50_wmg"
PARAMS = Path(__file__).resolve().parents[2] / "params" / "lgm50.yaml"
CLI = str(Path(sys.executable).parent / "battery-predictor")


@pytest.mark.slow
@pytest.mark.extended  # 2-3 min alone, the slowest of make test; the hidden-effect diagnoses stay there
@pytest.mark.skipif(not DATA.is_dir(), reason="measured data not available (../shared/data)")
def test_lgm50_10degC_discharges_name_temperature(process_workers_args):
    refs = [str(DATA / f"cc_T25C_{r}.csv") for r in ("0p1C", "0p5C", "1C", "2C")]
    obs = [str(DATA / f"cc_T10C_{r}.csv") for r in ("0p5C", "1C", "2C")]
    cmd = [CLI, "diagnose", "--params", str(PARAMS), "--reference", *refs, "--data", *obs, "--trim",
           "--duplicate-times", "keep_last", "--json", "--quiet", *process_workers_args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout)
    assert result["split"] == "recordings"
    # the reference fit is the project's identification on the engine: good enough to judge with
    assert result["judged"] and result["reference_fit"]["method"] == "identify"
    assert result["reference_fit"]["r2_mod"] > 0.99, result["reference_fit"]
    assert result["temperature_shift_k"] < -5.0
    # the plain SPM is far off at 10 degC; a sensor offset (the earlier, capacity-like answer) is not claimed
    assert result["baseline"]["heldout_rmse_mV"] > 100.0
    assert result["cause"] != "current_offset", result["evidence"]
    # the temperature extension anchored at the references' end-of-discharge temperature (36.4 degC) predicts
    # the held-out parts 56 % better (docs/findings.md); the issue asks >= 30 %
    assert result["cause"] == "temperature", result["evidence"]
    assert result["gain_pct"] >= 30.0, result["evidence"]
    # cell_imbalance does not apply to a single cell
    imbalance = next(c for c in result["candidates"] if c["cause"] == "cell_imbalance")
    assert "not_applicable" in imbalance


PANASONIC = Path(__file__).resolve().parents[3] / "shared" / "data" / "panasonic_18650pf"
COLD = Path(__file__).resolve().parents[1] / "data" / "panasonic_18650pf_cold"
PANASONIC_OCV = Path(__file__).resolve().parents[2] / "docs" / "runtime_real_data" / "panasonic_ocv.yaml"


@pytest.mark.slow
@pytest.mark.extended  # 6 min alone
@pytest.mark.skipif(not PANASONIC.is_dir(), reason="measured data not available (../shared/data)")
def test_panasonic_minus10degC_drive_cycles_fitted_at_25degC_name_temperature(process_workers_args):
    # the issue's own real case (named current_offset once): -10 degC HWFET + US06 against 25 degC HWFET + LA92,
    # each observed recording starting with a 2 h soak; params with the measured OCV (no cold prior in them)
    refs = [str(PANASONIC / f"drive_T25C_{c}.csv") for c in ("HWFET", "LA92")]
    obs = [str(COLD / f"drive_Tm10C_{c}.csv") for c in ("HWFET", "US06")]
    cmd = [CLI, "diagnose", "--params", str(PANASONIC_OCV), "--reference", *refs, "--data", *obs,
           "--resample", "10", "--json", "--quiet", *process_workers_args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout)
    assert result["judged"] and result["reference_fit"]["r2_mod"] > 0.99, result["reference_fit"]
    assert result["temperature_shift_k"] < -20.0
    # measured once (docs/findings.md, "Colder cells nobody tuned on"): baseline 161.7 mV, temperature +57 %
    assert result["baseline"]["heldout_rmse_mV"] > 100.0
    assert result["cause"] == "temperature", result["evidence"]
    assert result["gain_pct"] >= 30.0, result["evidence"]
