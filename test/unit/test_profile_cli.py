"""``battery-predictor profile ...`` run in-process."""

from __future__ import annotations

import json

import pytest

from battery_predictor.cli.main import main
from battery_predictor.profiles.load_profile import LoadProfile

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _json(capsys) -> dict:
    return json.loads(capsys.readouterr().out)


def test_longest_route_with_plot_writes_a_png_and_reports_97_points(tmp_path, capsys):
    png = tmp_path / "longest.png"
    assert main(["profile", "longest-route", "--seed", "1", "--plot", str(png), "--json"]) == 0
    summary = _json(capsys)
    assert png.read_bytes()[:8] == PNG_MAGIC
    assert summary["points"] == 97
    assert summary["total_duration_s"] == pytest.approx(1900.0)
    assert summary["labels"]["standstill"]["points"] == 2
    assert summary["outputs"]["plot"] == str(png)


def test_temi_profile_writes_csv_plot_and_psu_sequences(tmp_path, capsys):
    out, png, psu = tmp_path / "temi.csv", tmp_path / "temi.png", tmp_path / "psu"
    args = ["profile", "temi", "--seed", "4", "--duration-h", "8", "--out", str(out), "--plot", str(png),
            "--psu-dir", str(psu), "--json"]
    assert main(args) == 0
    summary = _json(capsys)
    profile = LoadProfile.from_csv(out)
    assert profile.n_points == summary["points"]
    assert profile.total_duration_s == pytest.approx(8 * 3600.0)
    assert summary["charge_ah"] == pytest.approx(profile.charge_ah)
    assert set(summary["labels"]) <= {"idling", "information", "navigation"}
    assert png.read_bytes()[:8] == PNG_MAGIC
    assert len(summary["outputs"]["psu_files"]) == -(-profile.n_points // 99)
    assert (psu / "sequence_001.csv").read_text().splitlines()[1].split(",")[1] == "13.300"


def test_route_between_platforms_in_mean_mode_gives_the_longest_route(capsys):
    args = ["profile", "route", "--from", "platform11_south", "--to", "platform13_south", "--payload-kg", "40",
            "--mode", "mean", "--json"]
    assert main(args) == 0
    summary = _json(capsys)
    assert summary["points"] == 97
    assert summary["total_duration_min"] == pytest.approx(31.67, abs=0.005)
    assert summary["metadata"]["mode"] == "mean"


def test_stepwise_prints_a_text_summary_by_default(capsys):
    assert main(["profile", "stepwise", "--currents-a", "1,2", "--step-s", "60"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("stepwise: 2 curve points, 120.0 s")


def test_unknown_location_exits_with_code_2_and_a_one_line_error(capsys):
    args = ["profile", "route", "--from", "platform99", "--to", "platform13_south", "--payload-kg", "40"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "unknown location 'platform99'" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "args",
    [
        ["profile", "temi", "--seed", "1"],
        ["profile", "route", "--from", "platform11_south", "--to", "platform13_south", "--payload-kg", "-3"],
        ["profile", "stepwise", "--currents-a", "1,x"],
    ],
)
def test_invalid_requests_exit_with_code_2(args, capsys):
    assert main(args) == 2
    assert "error" in capsys.readouterr().err
