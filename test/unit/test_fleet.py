"""``battery-predictor fleet fit`` without a server (SQLite storage) and its one-line errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from battery_predictor.errors import InputDataError
from battery_predictor.fitting.fleet import parse_packs
from battery_predictor.fitting.storage import redacted

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






def test_fleet_fit_bad_input_is_one_line_before_any_fit(tmp_path):
    proc = subprocess.run([CLI, "fleet", "fit", "--params", "params/temi.yaml", "--data", str(tmp_path / "none.csv"),
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=300, cwd=REPO)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and "none.csv" in lines[0], proc.stderr
