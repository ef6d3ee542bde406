"""``battery-predictor fleet fit`` on SQLite storage: a fit per pack, and a resumed run (solver-heavy)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from battery_predictor.io.bags import read_recording_bag
from battery_predictor.io.csv_io import save_csv
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[2]
CLI = str(Path(sys.executable).parent / "battery-predictor")


@pytest.fixture(scope="module")
def two_packs(tmp_path_factory) -> list[Path]:
    folder = tmp_path_factory.mktemp("fleet")
    out = []
    for k in (1, 2):
        rec = read_recording_bag(REPO / "bags" / f"temi_dynamic_pack{k}")
        keep = rec.time_s <= 1800.0
        out.append(save_csv(Recording(time_s=rec.time_s[keep], voltage_v=rec.voltage_v[keep],
                                      current_a=rec.current_a[keep], temperature_k=None, source=f"p{k}"),
                            folder / f"pack{k}.csv"))
    return out


def test_fleet_fit_on_sqlite_writes_a_fit_per_pack_and_resumes(two_packs, tmp_path):
    args = [CLI, "fleet", "fit", "--params", "params/temi.yaml", "--data", *map(str, two_packs),
            "--parameters", "r_c_ohm", "--trials", "6", "--out", str(tmp_path / "fits"), "--json"]
    first = subprocess.run(args, capture_output=True, text=True, timeout=600, cwd=REPO)
    assert first.returncode == 0, first.stderr
    summary = json.loads(first.stdout)
    assert [p["pack"] for p in summary["packs"]] == ["pack1", "pack2"]
    assert all(p["trials"] == 6 and p["own_trials"] == 6 for p in summary["packs"])
    assert json.loads((tmp_path / "fits" / "fleet.json").read_text())["packs"] == summary["packs"]
    for k in (1, 2):
        assert (tmp_path / "fits" / f"pack{k}.yaml").exists()
    again = subprocess.run(args, capture_output=True, text=True, timeout=600, cwd=REPO)  # a second worker, later
    assert again.returncode == 0, again.stderr
    assert all(p["resumed_trials"] == 6 and p["own_trials"] == 0 for p in json.loads(again.stdout)["packs"])
