"""Export to EA PSB 10060-120 sequences of at most 99 curve points."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from battery_predictor.errors import ProfileError
from battery_predictor.profiles.load_profile import LoadProfile
from battery_predictor.profiles.psu_export import psu_sequences, write_psu_csv
from battery_predictor.profiles.ranger import longest_route, route_profile


def _profile(n: int, **metadata) -> LoadProfile:
    rng = np.random.default_rng(0)
    return LoadProfile(rng.uniform(1, 60, n), rng.uniform(0.5, 8, n), None, metadata)


def test_250_points_split_into_99_99_and_52():
    profile = _profile(250)
    sequences = psu_sequences(profile, 45.0)
    assert [len(s) for s in sequences] == [99, 99, 52]
    assert [s.index for s in sequences] == [0, 1, 2]
    np.testing.assert_array_equal(np.concatenate([s.current_a for s in sequences]), profile.current_a)
    np.testing.assert_array_equal(np.concatenate([s.duration_s for s in sequences]), profile.duration_s)
    assert all(np.all(s.voltage_limit_v == 45.0) for s in sequences)
    assert sum(s.total_duration_s for s in sequences) == pytest.approx(profile.total_duration_s)


def test_the_longest_route_fits_one_sequence():
    profile = route_profile(longest_route(80), mode="mean")
    sequences = psu_sequences(profile)
    assert [len(s) for s in sequences] == [97]
    assert sequences[0].voltage_limit_v[0] == pytest.approx(45.0)  # from the profile metadata


def test_exactly_99_points_stay_one_sequence():
    assert [len(s) for s in psu_sequences(_profile(99), 13.3)] == [99]


def test_points_longer_than_10_h_are_split_before_chunking():
    profile = LoadProfile(np.array([90_000.0, 10.0]), np.array([1.0, 2.0]))
    (sequence,) = psu_sequences(profile, 13.3)
    np.testing.assert_allclose(sequence.duration_s, [30_000.0, 30_000.0, 30_000.0, 10.0])
    np.testing.assert_array_equal(sequence.current_a, [1.0, 1.0, 1.0, 2.0])


@pytest.mark.parametrize(
    ("profile", "voltage_limit_v", "message"),
    [
        (_profile(3), None, "stop_voltage_v"),
        (_profile(3), 61.0, "voltage_limit_v"),
        (_profile(3), 0.0, "voltage_limit_v"),
        (LoadProfile(np.array([1.0, 1.0]), np.array([1.0, -1.0])), 45.0, "only discharge"),
        (LoadProfile(np.array([1.0]), np.array([150.0])), 45.0, "120 A"),
        (LoadProfile(np.array([1e-5]), np.array([1.0])), 45.0, "0.1 ms"),
    ],
)
def test_profiles_the_supply_cannot_run_raise_profile_error(profile, voltage_limit_v, message):
    with pytest.raises(ProfileError, match=message):
        psu_sequences(profile, voltage_limit_v)


def test_write_psu_csv_writes_one_numbered_file_per_sequence(tmp_path):
    profile = _profile(250, stop_voltage_v=13.3)
    paths = write_psu_csv(profile, tmp_path / "psu")
    assert [p.name for p in paths] == ["sequence_001.csv", "sequence_002.csv", "sequence_003.csv"]
    with paths[2].open(newline="") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["point", "voltage_limit_v", "current_a", "duration_s"]
    assert len(rows) == 1 + 52
    assert rows[1][0] == "1" and float(rows[1][1]) == pytest.approx(13.3)
    assert float(rows[-1][2]) == pytest.approx(profile.current_a[-1], abs=1e-3)
    assert float(rows[-1][3]) == pytest.approx(profile.duration_s[-1], abs=1e-4)
