"""``battery-predictor evaluate``: report, figures and JSON from the bundled bags (few trials)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / "bags"
CLI = str(Path(sys.executable).parent / "battery-predictor")


def _evaluate(tmp_path: Path, *args: str) -> tuple[dict, Path]:
    out = tmp_path / "report"
    proc = subprocess.run([CLI, "evaluate", "--out", str(out), "--json", *args], capture_output=True, text=True,
                          timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout), out


@pytest.mark.slow
def test_route_evaluation_reports_voltage_errors_and_decisions_against_truth(tmp_path):
    routes = [str(BAGS / "ranger_route_20kg_pack1"), str(BAGS / "ranger_route_80kg_pack3")]
    summary, out = _evaluate(tmp_path, "--skip", "table2", "runtime", "--trials", "4", "--ranger-routes", *routes)
    r = summary["routes"]
    assert r["decisions"] == 6 and 0 <= r["decisions_correct"] <= 6
    assert math.isfinite(r["mae_v"]) and 0.0 <= r["mae_v"] < 1.0  # volts on a 48 V pack
    assert len(summary["route_cases"]) == 2
    assert {c["payload_kg"] for c in summary["route_cases"]} == {20.0, 80.0}
    assert summary["paper"]["route_mae_v"] == 0.17
    report = (out / "report.md").read_text()
    assert "0.17" in report and "Decisions" in report
    # the stepwise fit keeps what `fit` keeps; the bundled experiment reaches below the pack's voltage window
    assert summary["stepwise"]["fit_data_deepest_state"] is None
    assert summary["stepwise"]["weak_group"] == ("no weak series group inferred (no deepest state kept: the fit "
                                                 "data reach below the pack's voltage window)")
    assert f"Fitted params: {summary['stepwise']['weak_group']}." in report
    for png in ("fig7_stepwise.png", "fig8_routes.png"):
        assert (out / png).stat().st_size > 10_000
    assert json.loads((out / "summary.json").read_text())["routes"] == r


@pytest.mark.slow
def test_table2_and_runtime_rows_carry_the_paper_values_beside_ours(tmp_path):
    summary, out = _evaluate(tmp_path, "--skip", "routes", "--trials", "3", "--base-sets", "Chen2020",
                             "--temi-dynamic", str(BAGS / "temi_dynamic_pack1"))
    rows = summary["table2"]
    assert [(r["opt_profile"], r["base_parameter_set"]) for r in rows] == [("dynamic", "Chen2020"),
                                                                           ("static", "Chen2020")]
    assert all(math.isfinite(r["opt_r2_mod"]) and math.isfinite(r["val_r2_mod"]) for r in rows)
    assert summary["runtime"]["per_recording"] and math.isfinite(summary["runtime"]["mae_min"])
    report = (out / "report.md").read_text()
    assert "14.92" in report and "| dynamic | Chen2020 |" in report
    assert (out / "fig4_fit.png").exists() and (out / "fig5_runtime.png").exists()
    assert (out / "temi_fit_dynamic.yaml").exists()


def test_missing_bags_directory_is_a_one_line_error(tmp_path):
    proc = subprocess.run([CLI, "evaluate", "--bags", str(tmp_path / "none"), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "no information-robot recordings" in proc.stderr and "Traceback" not in proc.stderr


def test_route_truth_measured_in_the_recording_matches_the_bundled_metadata():
    from battery_predictor.evaluation.paper_eval import route_truth_from_recording
    from battery_predictor.io.loader import load_recording
    from battery_predictor.params import load_params

    params = load_params(REPO / "params" / "ranger_mini.yaml")
    for name in ("ranger_route_20kg_pack1", "ranger_route_80kg_pack2"):
        rec = load_recording(BAGS / name)
        meta = rec.metadata["truth"]
        derived = route_truth_from_recording(rec, rec.metadata["route"]["payload_kg"], params)
        assert derived["cycle_duration_s"] == pytest.approx(meta["cycle_duration_s"])
        assert derived["standstill_s"] == pytest.approx(meta["standstill_s"])
        assert derived["voltage_at_1_70_a_after_cycle_v"] == pytest.approx(meta["voltage_at_1_70_a_after_cycle_v"],
                                                                           abs=1e-6)  # float32 in the bag
        assert derived["further_cycle_stays_above_threshold"] is None  # only two cycles recorded


def test_route_truth_needs_two_recorded_cycles():
    from battery_predictor.errors import InputDataError
    from battery_predictor.evaluation.paper_eval import route_truth_from_recording
    from battery_predictor.io.loader import load_recording
    from battery_predictor.params import load_params

    params = load_params(REPO / "params" / "ranger_mini.yaml")
    rec = load_recording(BAGS / "ranger_route_40kg_pack1")
    short = rec.slice_time(rec.time_s[0], rec.time_s[0] + 2500.0)
    with pytest.raises(InputDataError, match="two longest-route cycles"):
        route_truth_from_recording(short, 40.0, params)


@pytest.mark.slow
def test_route_csv_without_metadata_is_evaluated_with_the_payload_given(tmp_path):
    from battery_predictor.io.loader import bag_to_csv

    csv = bag_to_csv(BAGS / "ranger_route_60kg_pack3", tmp_path / "route60.csv")
    no_payload = subprocess.run([CLI, "evaluate", "--skip", "table2", "runtime", "--trials", "2", "--ranger-routes",
                                 str(csv), "--out", str(tmp_path / "a")], capture_output=True, text=True, timeout=900)
    assert no_payload.returncode == 2 and "--route-payload-kg" in no_payload.stderr
    summary, _ = _evaluate(tmp_path, "--skip", "table2", "runtime", "--trials", "2", "--ranger-routes", str(csv),
                           "--route-payload-kg", "60")
    case = summary["route_cases"][0]
    assert case["payload_kg"] == 60.0 and case["truth"][2] is None
    assert summary["routes"]["decisions"] == 2  # the third decision has no recorded truth
