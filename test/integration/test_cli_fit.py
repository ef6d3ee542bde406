"""The fit / simulate / screen commands as a user runs them: JSON output and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from battery_predictor.io.csv_io import save_csv
from battery_predictor.params import load_params
from battery_predictor.recording import DeepestState, Recording
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator
from battery_predictor.simulation.extensions import weak_group_fraction, with_weak_group

REPO = Path(__file__).resolve().parents[2]
CLI = str(Path(sys.executable).parent / "battery-predictor")


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([CLI, *args], capture_output=True, text=True, timeout=600, cwd=REPO)


@pytest.fixture(scope="module")
def train_csv(tmp_path_factory, synthetic_temi):
    path = tmp_path_factory.mktemp("data") / "train.csv"
    save_csv(synthetic_temi[2], path)
    return path


@pytest.mark.slow
def test_fit_json_and_fitted_params_file_loadable(train_csv, tmp_path):
    out = tmp_path / "fit.yaml"
    proc = _run("fit", "--params", "params/temi.yaml", "--data", str(train_csv), "--trials", "12", "--seed", "3",
                "--parameters", "Electrode height [m]", "r_c_ohm", "--out", str(out), "--json", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)
    assert set(obj) >= {"r2_mod", "trials", "failed_trials", "seconds", "params"}
    assert obj["trials"] == 12
    assert set(obj["params"]) == {"Electrode height [m]", "r_c_ohm"}
    fitted = load_params(out)
    assert fitted.value("r_c_ohm") == pytest.approx(obj["params"]["r_c_ohm"])
    assert fitted.provenance["r2_mod"] == pytest.approx(obj["r2_mod"])
    # the data's deepest state is kept for the route check unless it lies outside the pack's window (as here)
    deepest = DeepestState.from_thresholds(fitted.thresholds)
    assert obj["fit_data_deepest_state"] == (None if deepest is None else deepest.as_thresholds())
    assert obj["weak_group"] == {"fraction": None, "note": "no weak series group inferred (no route threshold)"}
    assert out.with_suffix(".png").stat().st_size > 10_000
    assert out.with_suffix(".optuna.db").exists()
    # resume: asking for 15 trials runs only 3 more on the same study
    proc2 = _run("fit", "--params", "params/temi.yaml", "--data", str(train_csv), "--trials", "15", "--seed", "3",
                 "--parameters", "Electrode height [m]", "r_c_ohm", "--out", str(out), "--json", "--no-progress")
    assert json.loads(proc2.stdout)["trials"] == 15


@pytest.mark.slow
def test_fit_of_ranger_data_that_stop_under_load_above_the_threshold_writes_the_weak_group_they_imply(tmp_path):
    params = load_params(REPO / "params" / "ranger_mini.yaml")
    request = SimulationRequest(load=StepLoad.constant(3.0, 48 * 3600.0), output_time_s=np.arange(0.0, 48 * 3600.0, 60.0))
    run = get_simulator("engine").simulate(with_weak_group(params, 0.8), request)  # to the weak group's stop
    csv = tmp_path / "weak_day.csv"
    save_csv(Recording(run.time_s, run.pack_voltage_v, np.full(run.time_s.size, 3.0)), csv)
    out = tmp_path / "fit.yaml"
    proc = _run("fit", "--params", "params/ranger_mini.yaml", "--data", str(csv), "--method", "tpe", "--trials", "4",
                "--parameters", "r_c_ohm", "--out", str(out), "--json", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)
    fitted = load_params(out)
    assert "cell_imbalance" in fitted.extensions
    assert obj["weak_group"]["fraction"] == pytest.approx(weak_group_fraction(fitted))
    assert weak_group_fraction(fitted) == pytest.approx(0.8, abs=0.03)
    assert obj["weak_group"]["note"].startswith("weak series group inferred")
    again = _run("fit", "--params", "params/ranger_mini.yaml", "--data", str(csv), "--method", "tpe", "--trials", "4",
                 "--parameters", "r_c_ohm", "--out", str(tmp_path / "off.yaml"), "--no-progress",
                 "--no-weak-group-inference")
    assert again.returncode == 0, again.stderr
    assert "no weak series group inferred (--no-weak-group-inference)" in again.stdout
    assert "cell_imbalance" not in load_params(tmp_path / "off.yaml").extensions


def test_simulate_json_reports_score_and_runtimes(train_csv):
    proc = _run("simulate", "--params", "params/temi.yaml", "--data", str(train_csv), "--json")
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)
    assert set(obj) >= {"r2_mod", "rmse_mV", "runtime_s_measured", "runtime_s_simulated", "seconds"}
    assert obj["runtime_s_measured"] > 3600
    assert -5 < obj["r2_mod"] <= 1
    # measured and simulated are the same event: the first time at the recording's lowest voltage
    data = np.loadtxt(train_csv, delimiter=",", skiprows=1)
    lowest = int(np.argmin(data[:, 1]))
    assert obj["end_voltage_v"] == pytest.approx(data[lowest, 1], abs=1e-6)
    assert obj["runtime_s_measured"] == pytest.approx(data[lowest, 0] - data[0, 0], abs=1e-6)


def test_screen_json_lists_relevant_parameters():
    proc = _run("screen", "--params", "params/temi.yaml", "--json")
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)
    assert "Electrode height [m]" in obj["relevant"]


def _assert_one_line_error(proc, *fragments):
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for frag in fragments:
        assert frag in lines[0]


def test_bad_params_file_is_one_line_error_exit_2(tmp_path, train_csv):
    data = yaml.safe_load((REPO / "params" / "temi.yaml").read_text())
    data["cell"]["manual"]["Electrode width"] = 0.058
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(data))
    proc = _run("simulate", "--params", str(bad), "--data", str(train_csv))
    _assert_one_line_error(proc, "bad.yaml", "Electrode width", "missing unit")


@pytest.mark.parametrize(
    ("content", "fragment"),
    [
        ("", "empty"),
        ("time_s,voltage_V\n0,16.0\n1,15.9\n", "current_A"),
        ("time_s,voltage_V,current_A\n0,16.0,2.0\n1,nan,2.0\n2,15.9,2.0\n", "line 3"),
        ("time_s,voltage_V,current_A\n0,16.0,2.0\n10,15.9,2.0\n5,15.8,2.0\n", "line 4"),
        ("time_s,voltage_V,current_A\n" + "".join(f"{i},{16000 - i},2.0\n" for i in range(20)), "millivolts"),
    ],
)
def test_bad_data_file_is_one_line_error_exit_2(tmp_path, content, fragment):
    path = tmp_path / "data.csv"
    path.write_text(content)
    proc = _run("fit", "--params", "params/temi.yaml", "--data", str(path), "--trials", "2", "--out",
                str(tmp_path / "o.yaml"))
    _assert_one_line_error(proc, "data.csv", fragment)


def test_wrong_sign_convention_is_rejected(tmp_path):
    t = np.arange(0.0, 3600.0, 10.0)
    rows = "".join(f"{ti},{16.0 - ti / 3600},-3.0\n" for ti in t)
    path = tmp_path / "neg.csv"
    path.write_text("time_s,voltage_V,current_A\n" + rows)
    proc = _run("simulate", "--params", "params/temi.yaml", "--data", str(path))
    _assert_one_line_error(proc, "neg.csv")


@pytest.fixture(scope="module")
def short_temi_csv(tmp_path_factory) -> Path:
    """The first 30 min of the bundled temi recording as CSV (a fit on the engine takes ~2 s)."""
    from battery_predictor.io.bags import read_recording_bag
    from battery_predictor.recording import Recording

    rec = read_recording_bag(REPO / "bags" / "temi_dynamic_pack1")
    keep = rec.time_s <= 1800.0
    short = Recording(time_s=rec.time_s[keep], voltage_v=rec.voltage_v[keep], current_a=rec.current_a[keep],
                      temperature_k=None, source="short")
    return save_csv(short, tmp_path_factory.mktemp("short") / "short.csv")


def test_tpe_fit_says_when_no_trial_beat_the_start_and_names_a_resumed_study(short_temi_csv, tmp_path):
    """Issue 13 item 4: a resumed study is named on stderr before the work; "X -> X" comes with a reason."""
    out = tmp_path / "fit.yaml"
    db = out.with_suffix(".optuna.db").resolve()

    def fit(trials: int, *extra: str) -> subprocess.CompletedProcess:
        return _run("fit", "--method", "tpe", "--params", "params/temi.yaml", "--data", str(short_temi_csv),
                    "--simulator", "engine", "--parameters", "r_c_ohm", "--trials", str(trials), "--out", str(out),
                    "--no-progress", *extra)

    first = fit(1)  # the only trial is the enqueued start: nothing can beat it
    assert first.returncode == 0, first.stderr
    assert "no trial beat the start" in first.stdout
    assert "resuming" not in first.stderr

    second = fit(3)
    assert second.returncode == 0, second.stderr
    resumed = [ln for ln in second.stderr.splitlines() if "resuming study" in ln]
    assert len(resumed) == 1, second.stderr
    assert "already holds 1 trial;" in resumed[0] and "running 2 more" in resumed[0]
    assert "--study-name" in resumed[0] and str(db) in resumed[0]

    third = fit(3, "--json")  # nothing left to do: said so, and counted in the JSON
    assert third.returncode == 0, third.stderr
    assert "already holds 3 trials; no new trial runs (pass --trials N with N > 3" in third.stderr
    obj = json.loads(third.stdout)
    assert obj["resumed_trials"] == 3 and obj["trials"] == 3

    afresh = fit(1, "--study-name", "another", "--json")
    assert afresh.returncode == 0, afresh.stderr
    assert "resuming" not in afresh.stderr
    assert json.loads(afresh.stdout)["improved"] is False
