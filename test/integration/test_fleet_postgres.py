"""Fleets on a real PostgreSQL server: two worker processes on one study, and a fleet of packs.

The test starts its own server (Debian's ``postgresql`` package: ``initdb`` + ``pg_ctl``) in a
temporary directory on a free local port, as the ``postgres`` system user when it runs as root
(PostgreSQL refuses to run as root), as itself otherwise; ``make test`` installs the package when
it can (root with apt-get). Skipped, with the reason, only where the server binaries are missing.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from battery_predictor.fitting.local_postgres import LocalPostgres, free_port, server_binaries
from battery_predictor.fitting.storage import close_storage, open_storage
from battery_predictor.io.bags import read_recording_bag
from battery_predictor.io.csv_io import save_csv
from battery_predictor.params import load_params
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[2]
CLI = str(Path(sys.executable).parent / "battery-predictor")
#: Trials per study: enough (~0.15 s each on the engine) that a worker starting a few seconds later still joins.
TRIALS = 30


@pytest.fixture(scope="module")
def postgres_url():
    """URL of a PostgreSQL server started for this module (trust authentication on 127.0.0.1 only)."""
    if server_binaries() is None:
        pytest.skip("PostgreSQL server binaries (initdb, pg_ctl) not found: apt-get install postgresql "
                    "(make test does so when it runs as root)")
    with LocalPostgres() as url:
        yield url


@pytest.fixture(scope="module")
def pack_csvs(tmp_path_factory) -> list[Path]:
    """The first 30 min of three bundled temi packs as CSV (a 30-trial fit on the engine: ~5 s)."""
    out = []
    folder = tmp_path_factory.mktemp("packs")
    for k in (1, 2, 3):
        rec = read_recording_bag(REPO / "bags" / f"temi_dynamic_pack{k}")
        keep = rec.time_s <= 1800.0
        short = Recording(time_s=rec.time_s[keep], voltage_v=rec.voltage_v[keep], current_a=rec.current_a[keep],
                          temperature_k=None, source=f"pack{k}")
        out.append(save_csv(short, folder / f"pack{k}.csv"))
    return out


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([CLI, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)


def _finish(proc: subprocess.Popen) -> str:
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err[-3000:]
    return out


def _workers_per_study(url: str, names: list[str]) -> dict[str, Counter]:
    import optuna
    from optuna.trial import TrialState

    done = (TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL)
    result = {}
    storage = open_storage(url)
    try:
        for name in names:
            study = optuna.load_study(study_name=name, storage=storage)
            result[name] = Counter(t.user_attrs.get("worker") for t in study.get_trials(states=done))
    finally:
        close_storage(storage)
    return result


def test_two_fit_processes_work_on_one_study(postgres_url, pack_csvs, tmp_path):
    common = ("fit", "--method", "tpe", "--params", "params/temi.yaml", "--data", str(pack_csvs[0]),
              "--simulator", "engine", "--parameters", "r_c_ohm", "Electrode height [m]", "--trials", str(TRIALS),
              "--storage", postgres_url, "--study-name", "shared", "--json", "--no-progress")
    first = _start(*common, "--seed", "1", "--out", str(tmp_path / "a.yaml"))
    second = _start(*common, "--seed", "2", "--out", str(tmp_path / "b.yaml"))
    a, b = json.loads(_finish(first)), json.loads(_finish(second))
    workers = _workers_per_study(postgres_url, ["shared"])["shared"]
    assert len(workers) == 2, workers  # both processes ran trials of the one study
    assert TRIALS <= sum(workers.values()) <= TRIALS + 2  # each stops once the study holds enough
    assert min(a["trials"], b["trials"]) >= TRIALS
    for name in ("a.yaml", "b.yaml"):
        assert load_params(tmp_path / name).provenance["storage"] == postgres_url


def test_fleet_of_packs_shared_by_two_workers(postgres_url, pack_csvs, tmp_path):
    common = ("fleet", "fit", "--params", "params/temi.yaml", "--data", *map(str, pack_csvs), "--parameters",
              "r_c_ohm", "--trials", str(TRIALS), "--storage", postgres_url, "--study-prefix", "fleet-test-", "--json")
    first = _start(*common, "--seed", "1", "--out", str(tmp_path / "w1"))
    second = _start(*common, "--seed", "2", "--out", str(tmp_path / "w2"))
    summaries = [json.loads(_finish(first)), json.loads(_finish(second))]
    names = [f"fleet-test-pack{k}" for k in (1, 2, 3)]
    per_study = _workers_per_study(postgres_url, names)
    for name in names:
        assert TRIALS <= sum(per_study[name].values()) <= TRIALS + 2, per_study
    # the two workers shared the fleet: both ran trials, and at least one study holds trials of both
    assert sum(len(c) == 2 for c in per_study.values()) >= 1, per_study
    assert {s["storage"] for s in summaries} == {postgres_url}
    for summary, folder in zip(summaries, ("w1", "w2"), strict=True):
        assert [p["pack"] for p in summary["packs"]] == ["pack1", "pack2", "pack3"]
        for pack in summary["packs"]:
            assert (tmp_path / folder / f"{pack['pack']}.yaml").exists()
            assert pack["trials"] >= TRIALS


def test_unreachable_storage_is_one_line_exit_2(pack_csvs, tmp_path):
    proc = subprocess.run([CLI, "fleet", "fit", "--params", "params/temi.yaml", "--data", str(pack_csvs[0]),
                           "--trials", "2", "--storage", f"postgresql://fleet:secret@127.0.0.1:{free_port()}/x",
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=300, cwd=REPO)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and "cannot open Optuna storage" in lines[0], proc.stderr
    assert "secret" not in proc.stderr and "Traceback" not in proc.stderr
