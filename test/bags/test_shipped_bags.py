"""The shipped, EMULATED bags in ``bags/``: complete, readable, small, and consistent with their ground truth."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.io.bags import bag_info, read_recording_bag
from battery_predictor.lab import LAB_VERSION
from battery_predictor.lab.experiments import ROUTE_THRESHOLD_V, catalogue, standstill_voltage_v

BAGS = Path(__file__).resolve().parents[2] / "bags"
EXPERIMENTS = {e.name: e for e in catalogue()}
MAX_BAG_BYTES = 2_000_000
MAX_TOTAL_BYTES = 25_000_000
COMMON_KEYS = ("emulated", "generator", "generator_version", "lab_version", "experiment", "robot", "kind", "pack_id",
               "profile_seed", "instrument_seed", "ambient_temperature_k", "real_pack", "instruments", "profile", "truth")


def _size(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


@pytest.fixture(scope="module")
def recordings():
    return {}


def _read(recordings, name):
    if name not in recordings:
        recordings[name] = read_recording_bag(BAGS / name)
    return recordings[name]


def test_bags_directory_holds_exactly_the_catalogue_and_a_readme():
    assert (BAGS / "README.md").is_file()
    text = (BAGS / "README.md").read_text()
    assert "EMULATED" in text and "lab make-bags" in text
    shipped = {p.name for p in BAGS.iterdir() if p.is_dir()}
    assert shipped == set(EXPERIMENTS)
    assert sum(_size(BAGS / n) for n in shipped) <= MAX_TOTAL_BYTES


@pytest.mark.parametrize("name", list(EXPERIMENTS))
def test_bag_opens_with_its_ground_truth(recordings, name):
    exp = EXPERIMENTS[name]
    path = BAGS / name
    assert _size(path) <= MAX_BAG_BYTES
    rec = _read(recordings, name)
    meta = rec.metadata
    for key in COMMON_KEYS:
        assert key in meta, key
    assert meta["emulated"] is True and meta["experiment"] == name
    assert meta["generator_version"]["lab"] == meta["lab_version"] == LAB_VERSION
    assert meta["pack_id"] == exp.pack_id and meta["profile_seed"] == exp.profile_seed
    assert meta["real_pack"]["spec"]["pack_id"] == exp.pack_id and meta["real_pack"]["model"] == "SPMe"
    assert bag_info(path)["style"] == exp.style
    assert len(rec.time_s) > 100
    np.testing.assert_allclose(np.diff(rec.time_s), 5.0)
    assert np.all(np.isfinite(rec.voltage_v)) and np.all(rec.current_a > 0)
    assert rec.temperature_k is not None and np.all((rec.temperature_k > 280) & (rec.temperature_k < 330))


@pytest.mark.parametrize("name", [n for n, e in EXPERIMENTS.items() if e.kind != "route"])
def test_discharge_bags_end_where_the_truth_says(recordings, name):
    rec = _read(recordings, name)
    truth = rec.metadata["truth"]
    stop_v = truth["stop_voltage_v"]
    assert stop_v == {"static": 12.00, "dynamic": 13.30, "stepwise": 45.00}[EXPERIMENTS[name].kind]
    # the recorded voltage crosses the end voltage exactly at the true runtime, and not before
    assert rec.time_s[-1] == pytest.approx(truth["runtime_s"], abs=1e-6)
    assert rec.voltage_v[-1] <= stop_v + 1e-4
    assert np.all(rec.voltage_v[:-1] > stop_v)
    noise_free = truth["runtime_noise_free_s"]
    assert noise_free is not None and abs(noise_free - truth["runtime_s"]) <= 30.0
    charge = float(np.sum(rec.current_a[:-1] * np.diff(rec.time_s)) / 3600.0)
    assert charge == pytest.approx(truth["charge_drawn_ah"], rel=0.01)


@pytest.mark.parametrize("name", [n for n, e in EXPERIMENTS.items() if e.kind == "route"])
def test_route_bags_end_just_above_the_threshold(recordings, name):
    rec = _read(recordings, name)
    meta = rec.metadata
    truth = meta["truth"]
    assert truth["threshold_v"] == ROUTE_THRESHOLD_V and truth["standstill_current_a"] == 1.70
    assert 0.0 < truth["start_soc"] < 1.0
    assert meta["route"]["payload_kg"] == EXPERIMENTS[name].payload_kg
    period, standstill = truth["cycle_duration_s"], truth["standstill_s"]
    assert rec.time_s[-1] + 5.0 == pytest.approx(2 * period, abs=1.0)
    v = [standstill_voltage_v(rec.time_s, rec.voltage_v, k * period, standstill) for k in (1, 2)]
    np.testing.assert_allclose(v, truth["voltage_at_1_70_a_after_cycle_v"], atol=2e-4)  # float32 messages
    # the standstill at 1.70 A closes each cycle
    for k in (1, 2):
        sel = (rec.time_s >= k * period - standstill - 1e-6) & (rec.time_s + 5.0 <= k * period + 1e-6)
        assert np.all(np.abs(rec.current_a[sel] - 1.70) < 0.06)
    assert ROUTE_THRESHOLD_V < v[1] <= ROUTE_THRESHOLD_V + 0.3
    assert v[0] > v[1]
    assert truth["second_cycle_ends_above_threshold"] is True
    assert isinstance(truth["further_cycle_stays_above_threshold"], bool)
    v3 = truth["voltage_at_1_70_a_after_cycle_noise_free_v"][2]
    assert truth["further_cycle_stays_above_threshold"] == (v3 is not None and truth["further_cycle_completed"]
                                                            and v3 >= ROUTE_THRESHOLD_V)
    assert not math.isnan(truth["voltage_at_1_70_a_after_cycle_noise_free_v"][1])
