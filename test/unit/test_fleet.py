"""``battery-predictor fleet fit`` without a server (SQLite storage) and its one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from battery_predictor.errors import InputDataError
from battery_predictor.fitting.fleet import parse_packs
from battery_predictor.fitting.storage import redacted
from battery_predictor.io.bags import read_recording_bag
from battery_predictor.io.csv_io import save_csv
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[2]
CLI = str(Path(sys.executable).parent / "battery-predictor")


def test_pack_names_come_from_stems_or_are_given():
    assert parse_packs(["d/p1.csv", "d/p2.csv"], ["big=d/a.csv,d/b.csv"]) == {
        "p1": ["d/p1.csv"], "p2": ["d/p2.csv"], "big": ["d/a.csv", "d/b.csv"]}
    for data, packs, fragment in [((), (), "no packs"), (("a/p.csv", "b/p.csv"), (), "given twice"),
                                  ((), ("x",), "NAME=FILE"), ((), ("bad name=f.csv",), "pack name"),
                                  ((), ("p=",), "no data file")]:
        with pytest.raises(InputDataError, match=fragment):
            parse_packs(data, packs)


def test_storage_urls_lose_their_password_in_messages():
    assert redacted("postgresql://fleet:secret@db:5432/x") == "postgresql://fleet:***@db:5432/x"
    assert redacted("postgresql://fleet@db/x") == "postgresql://fleet@db/x"
    assert redacted("sqlite:////tmp/a.db") == "sqlite:////tmp/a.db"


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


def test_fleet_fit_bad_input_is_one_line_before_any_fit(tmp_path):
    proc = subprocess.run([CLI, "fleet", "fit", "--params", "params/temi.yaml", "--data", str(tmp_path / "none.csv"),
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=300, cwd=REPO)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and "none.csv" in lines[0], proc.stderr
