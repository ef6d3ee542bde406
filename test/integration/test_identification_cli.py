"""``fit --method identify`` and ``--resample`` as a user runs them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.io.csv_io import save_csv
from battery_predictor.params import load_params
from battery_predictor.recording import DeepestState, Recording
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator

REPO = Path(__file__).resolve().parents[2]
CLI = str(Path(sys.executable).parent / "battery-predictor")
PARAMS = REPO / "params" / "panasonic_18650pf.yaml"


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([CLI, *args], capture_output=True, text=True, timeout=600, cwd=REPO)


@pytest.fixture(scope="module")
def one_second_csv(tmp_path_factory) -> Path:
    """A 40 min pulsed discharge of the shipped Panasonic cell, sampled every second, 1 mV noise."""
    rng = np.random.default_rng(5)
    load = StepLoad.from_durations(rng.uniform(5.0, 40.0, 120), rng.uniform(0.0, 4.0, 120))
    t = np.arange(0.0, load.end_s - 1.0, 1.0)
    res = get_simulator("fast").simulate(load_params(PARAMS), SimulationRequest(load=load, output_time_s=t))
    rec = Recording(res.time_s, res.pack_voltage_v + rng.normal(0.0, 0.001, res.time_s.size),
                    load.current_at(res.time_s), source="one_second")
    path = tmp_path_factory.mktemp("data") / "one_second.csv"
    save_csv(rec, path)
    return path


@pytest.mark.slow
def test_fit_identify_json_reports_budget_coordinates_and_identifiability(one_second_csv, tmp_path):
    out = tmp_path / "fit.yaml"
    proc = _run("fit", "--params", str(PARAMS), "--data", str(one_second_csv), "--resample", "10",
                "--evaluations", "16", "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)
    assert obj["method"] == "identify"
    assert obj["engine_fallback"] is None  # the shipped cell runs on the engine
    assert obj["evaluations"] <= 16
    names = [p["name"] for p in obj["identifiability"]["parameters"]]
    assert names[:4] == ["negative_capacity_ah", "positive_capacity_ah", "negative_stoichiometry",
                         "series_resistance_ohm"]
    assert names[4] == "initial_ocv_v:0"
    fitted = load_params(out)
    assert fitted.provenance["resample_s"] == 10.0
    assert "identifiability" in fitted.provenance
    deepest = DeepestState.from_thresholds(fitted.thresholds)  # the 10 s windows' deepest, kept for the route check
    assert deepest is not None and deepest.as_thresholds() == pytest.approx(obj["fit_data_deepest_state"])
    sim = _run("simulate", "--params", str(out), "--data", str(one_second_csv), "--resample", "10", "--json")
    assert sim.returncode == 0, sim.stderr
    assert json.loads(sim.stdout)["r2_mod"] == pytest.approx(obj["r2_mod"], abs=0.02)


@pytest.mark.slow
def test_trials_without_method_keeps_the_papers_tpe(one_second_csv, tmp_path):
    proc = _run("fit", "--params", str(PARAMS), "--data", str(one_second_csv), "--resample", "60",
                "--trials", "2", "--out", str(tmp_path / "tpe.yaml"), "--json", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)
    assert obj["method"] == "tpe" and obj["trials"] == 2
    # the paper's raw parameters: thickness and active fraction of an electrode compensate each other
    pairs = {frozenset((p["a"], p["b"])) for p in obj["identifiability"]["correlated_pairs"]}
    assert frozenset(("Negative electrode thickness [m]",
                      "Negative electrode active material volume fraction")) in pairs


@pytest.mark.parametrize("window", ["0", "-5", "nan"])
def test_a_resample_window_that_is_not_positive_is_a_one_line_error(one_second_csv, tmp_path, window):
    proc = _run("simulate", "--params", str(PARAMS), "--data", str(one_second_csv), "--resample", window)
    assert proc.returncode == 2
    assert "--resample" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_simulate_on_the_engine_scores_like_the_fast_simulator(one_second_csv):
    scores = {}
    for sim in ("fast", "engine"):
        proc = _run("simulate", "--params", str(PARAMS), "--data", str(one_second_csv), "--resample", "10",
                    "--simulator", sim, "--json")
        assert proc.returncode == 0, proc.stderr
        scores[sim] = json.loads(proc.stdout)["rmse_mV"]
    assert scores["engine"] == pytest.approx(scores["fast"], abs=0.1)


@pytest.mark.slow
def test_fit_thermal_lumped_fits_and_writes_a_lumped_thermal_cell(one_second_csv, tmp_path):
    """``fit --thermal lumped`` mirrors ``simulate --thermal``: the fit runs and the fitted params keep the cell."""
    out = tmp_path / "thermal.yaml"
    proc = _run("fit", "--params", str(PARAMS), "--data", str(one_second_csv), "--resample", "30",
                "--evaluations", "8", "--thermal", "lumped", "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    obj = json.loads(proc.stdout)
    assert obj["thermal"] == "lumped"
    fitted = load_params(out)
    assert fitted.options.get("thermal") == "lumped"
    assert fitted.provenance["thermal"] == "lumped"
    sim = _run("simulate", "--params", str(out), "--data", str(one_second_csv), "--resample", "30", "--json")
    assert sim.returncode == 0, sim.stderr
    assert json.loads(sim.stdout)["thermal"] == "lumped"
    assert json.loads(sim.stdout)["r2_mod"] == pytest.approx(obj["r2_mod"], abs=0.02)
