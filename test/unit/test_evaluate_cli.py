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
