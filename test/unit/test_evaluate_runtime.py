"""``evaluate-runtime``: truth from the recording, the predictor's core and the counters side by side."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.cli.cmd_evaluate_runtime import parse_checkpoints
from battery_predictor.errors import InputDataError
from battery_predictor.evaluation.runtime_eval import (
    Windows,
    counter_remaining_s,
    error_summary,
    find_discharge,
    ratio_to_best_counter,
    recording_runtime_truth,
)
from battery_predictor.params import load_params
from battery_predictor.prediction.cell_runner import PackRunner
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[2]
CLI = REPO / ".venv" / "bin" / "battery-predictor"
PARAMS = REPO / "params" / "panasonic_18650pf.yaml"


def windows(time_s, voltage_v, current_a) -> Windows:
    t = np.asarray(time_s, float)
    i = np.asarray(current_a, float)
    return Windows(t, np.asarray(voltage_v, float), i, np.full(t.size, math.nan), i)


def test_discharge_ends_at_the_first_window_at_the_cutoff():
    t = np.arange(5.0, 100.0, 5.0)
    v = np.linspace(4.1, 2.4, t.size)
    d = find_discharge(windows(t, v, np.full(t.size, 2.0)), 2.5, start_current_a=0.05, end_margin_v=0.5)
    assert d.ended_by == "cutoff_window" and d.end_s == t[np.argmax(v <= 2.5)] and d.start_s == 0.0


def test_discharge_that_stops_near_the_cutoff_ends_there_and_one_far_from_it_is_unknown():
    t = np.arange(5.0, 200.0, 5.0)
    i = np.where(t < 100.0, 2.0, 0.0)
    v = np.where(t < 100.0, 4.1 - 1.4 * t / 100.0, 3.3)
    assert find_discharge(windows(t, v, i), 2.5, start_current_a=0.05, end_margin_v=0.5).ended_by == "discharge_end"
    far = find_discharge(windows(t, v + 0.6, i), 2.5, start_current_a=0.05, end_margin_v=0.5)
    assert far.ended_by == "unknown" and not far.known


def test_counter_divides_the_charge_left_by_the_mean_current():
    t = np.arange(5.0, 3605.0, 5.0)
    win = windows(t, np.full(t.size, 3.6), np.full(t.size, 1.0))
    assert counter_remaining_s(win, 0.0, 1800.0, 2.0) == pytest.approx(1.5 * 3600.0)


def test_error_summary_scores_only_answered_checkpoints_with_a_truth():
    s = error_summary([(600.0, 660.0), (math.nan, 300.0), (120.0, math.nan)])
    assert (s["checkpoints"], s["answered"]) == (2, 1)
    assert s["mae_min"] == pytest.approx(1.0) and s["bias_min"] == pytest.approx(-1.0)


def test_error_summary_counts_the_answers_after_the_late_fraction_off_by_more_than_half():
    late = [(1000.0, 600.0), (250.0, 600.0), (900.0, 600.0), (math.nan, 600.0), (400.0, 0.0)]
    s = error_summary(late, late_fraction_pairs=late)
    assert (s["answers_after"], s["off_by_half_after"]) == (3, 2)  # 67 % late, 58 % early; 50 % exactly is not over
    assert s["worst_late_pct"] == pytest.approx(100.0 * 400.0 / 600.0)
    assert error_summary([(60.0, 60.0)])["answers_after"] == 0


def test_the_ratio_to_the_best_counter_divides_by_the_smallest_counter_mae():
    block = {"predictor": {"mae_min": 6.0}, "counter[nominal]": {"mae_min": 30.0},
             "counter[measured]": {"mae_min": 20.0}, "counter[given]": {"mae_min": math.nan}}
    assert ratio_to_best_counter(block) == {"ratio": pytest.approx(0.3), "counter": "counter[measured]"}
    alone = ratio_to_best_counter({"predictor": {"mae_min": 6.0}})
    assert alone["counter"] is None and math.isnan(alone["ratio"])


def test_checkpoints_parse_ranges_and_lists_and_refuse_nonsense():
    assert parse_checkpoints("0.1:0.9:0.2") == (0.1, 0.3, 0.5, 0.7, 0.9)
    assert parse_checkpoints("0.25,0.5") == (0.25, 0.5)
    for bad in ("0:1:0.5", "a:b:c", "0.5:0.9:0", "1.5"):
        with pytest.raises(InputDataError, match="--checkpoints"):
            parse_checkpoints(bad)


@pytest.fixture(scope="module")
def model_discharge_csv(tmp_path_factory) -> Path:
    """A 1C discharge of the params' own model to 2.5 V, then 300 s of rest, sampled every second."""
    runner = PackRunner(load_params(PARAMS))
    run = runner.run(0.98, [(5000.0, 2.9)], 298.15)
    assert run.reached_cutoff
    t = np.arange(0.0, run.end_time_s, 1.0)
    v = np.interp(t, run.time_s, run.pack_voltage_v)
    rest = runner.run(run.final_state, [(300.0, 0.0)], 298.15)
    t_rest = t[-1] + 1.0 + np.arange(0.0, 300.0, 1.0)
    v_rest = np.interp(t_rest - t_rest[0], rest.time_s, rest.pack_voltage_v)
    path = tmp_path_factory.mktemp("evrt") / "model_1c.csv"
    rows = ["time_s,voltage_V,current_A"] + [f"{a:.1f},{b:.5f},2.9" for a, b in zip(t, v)] + \
        [f"{a:.1f},{b:.5f},0.0" for a, b in zip(t_rest, v_rest)]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_cli_scores_the_predictor_and_the_counters_on_a_discharge(model_discharge_csv, tmp_path):
    out = tmp_path / "report"
    proc = subprocess.run([str(CLI), "evaluate-runtime", "--params", str(PARAMS), "--data", str(model_discharge_csv),
                           "--checkpoints", "0.2:0.8:0.3", "--capacity-ah", "2.6", "--load-model", "current",
                           "--json", "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    pooled = summary["pooled"]
    assert set(pooled) == {"predictor", "counter[nominal]", "counter[given]"}
    assert pooled["predictor"]["answered"] == pooled["predictor"]["checkpoints"] == 3
    discharge_min = summary["per_recording"][0]["discharge_min"]
    assert pooled["predictor"]["mae_min"] < 0.05 * discharge_min  # its own model and load kind: close to the truth
    assert summary["load_model"] == "current"
    assert (out / "summary.json").is_file() and (out / "runtime.png").stat().st_size > 1000
    report = (out / "report.md").read_text()
    assert "| **pooled** |" in report and "off by half" in report
    assert pooled["predictor"]["answers_after"] == 2  # the checkpoints at 50 and 80 %, after 30 %
    ratio = summary["pooled_ratio_to_best_counter"]
    assert ratio["counter"] in {"counter[nominal]", "counter[given]"}
    assert ratio["ratio"] == pytest.approx(pooled["predictor"]["mae_min"] / pooled[ratio["counter"]]["mae_min"])
    assert f"{ratio['ratio']:.2f}x" in report
    rows = json.loads((out / "checkpoints.json").read_text())
    assert [r["fraction"] for r in rows] == [0.2, 0.5, 0.8]


def test_cli_runs_the_core_with_the_load_estimator_asked_for(model_discharge_csv):
    proc = subprocess.run([str(CLI), "evaluate-runtime", "--params", str(PARAMS), "--data", str(model_discharge_csv),
                           "--checkpoints", "0.5", "--load-model", "current", "--load-estimator", "ewma",
                           "--load-time-constant-s", "600", "--json"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["load_estimator"] == "ewma" and summary["load_time_constant_s"] == 600.0
    # a constant current: the weighted mean is the cycle mean, so the answer stays close to the truth
    pooled = summary["pooled"]["predictor"]
    assert pooled["answered"] == 1 and pooled["mae_min"] < 0.05 * summary["per_recording"][0]["discharge_min"]


@pytest.mark.parametrize("value", ["0", "-5", "nan"])
def test_cli_refuses_a_load_time_constant_that_is_not_positive_in_one_line(model_discharge_csv, value):
    proc = subprocess.run([str(CLI), "evaluate-runtime", "--params", str(PARAMS), "--data", str(model_discharge_csv),
                           "--load-estimator", "ewma", f"--load-time-constant-s={value}"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "--load-time-constant-s" in proc.stderr


def test_cli_refuses_bad_checkpoints_in_one_line(model_discharge_csv):
    proc = subprocess.run([str(CLI), "evaluate-runtime", "--params", str(PARAMS), "--data", str(model_discharge_csv),
                           "--checkpoints", "0.5:2"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "--checkpoints" in proc.stderr


def test_recording_runtime_truth_is_the_first_window_at_the_cutoff_with_checkpoints_over_the_discharge() -> None:
    params = load_params(REPO / "params" / "temi.yaml")
    t = np.arange(0.0, 2400.0, 5.0)
    rec = Recording(t, 15.6 - 2.5 * t / 2400.0, np.full(t.size, 2.0), np.full(t.size, 297.0))
    truth = recording_runtime_truth(params, rec, 13.30, time_offset_s=100.0)
    assert truth is not None and truth.source == "recording: cutoff_window"
    assert 100.0 + 2205.0 <= truth.runtime_s <= 100.0 + 2215.0
    assert len(truth.checkpoints_min) == 9
    assert truth.checkpoints_min[0] * 60 == pytest.approx(100.0 + 0.1 * (truth.runtime_s - 100.0), abs=5.0)


def test_recording_runtime_truth_is_none_when_the_recording_stops_far_above_the_cutoff() -> None:
    params = load_params(REPO / "params" / "temi.yaml")
    t = np.arange(0.0, 2400.0, 5.0)
    rec = Recording(t, 16.0 - 0.2 * t / 2400.0, np.full(t.size, 2.0), np.full(t.size, 297.0))
    assert recording_runtime_truth(params, rec, 13.30) is None


def test_cli_checks_every_file_before_evaluating_any(model_discharge_csv, tmp_path):
    repeated = tmp_path / "repeated.csv"
    repeated.write_text("time_s,voltage_V,current_A\n0.0,4.1,1.0\n1.0,4.0,1.0\n1.0,4.0,1.0\n2.0,3.9,1.0\n")
    proc = subprocess.run([str(CLI), "evaluate-runtime", "--params", str(PARAMS), "--data", str(model_discharge_csv),
                           str(repeated), "--duplicate-times", "error"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "repeated.csv" in proc.stderr and "--duplicate-times keep_last" in proc.stderr
    assert proc.stdout == ""  # the good file was not evaluated first (minutes lost before the error)
