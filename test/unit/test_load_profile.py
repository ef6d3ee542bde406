"""LoadProfile: validation, step series, sampling, CSV round trip."""

from __future__ import annotations

import numpy as np
import pytest

from battery_predictor.errors import ProfileError
from battery_predictor.profiles.load_profile import LoadProfile, constant_current_profile


def _profile() -> LoadProfile:
    return LoadProfile(np.array([10.0, 5.0, 20.0]), np.array([1.0, -0.5, 3.0]), ("a", "b", "a"), {"x": 1})


def test_totals_and_start_times_follow_the_curve_points():
    profile = _profile()
    assert profile.total_duration_s == 35.0
    assert profile.charge_ah == pytest.approx((10 * 1.0 - 5 * 0.5 + 20 * 3.0) / 3600.0)
    np.testing.assert_array_equal(profile.times_s(), [0.0, 10.0, 15.0])
    assert len(profile) == profile.n_points == 3


def test_step_series_pairs_every_edge_and_interpolates_to_the_steps():
    time_s, current_a = _profile().as_step_series()
    np.testing.assert_array_equal(time_s, [0, 10, 10, 15, 15, 35])
    np.testing.assert_array_equal(current_a, [1, 1, -0.5, -0.5, 3, 3])
    # Midpoints of each point interpolate to the point's current.
    np.testing.assert_allclose(np.interp([5.0, 12.5, 25.0], time_s, current_a), [1.0, -0.5, 3.0])


def test_sample_returns_the_step_in_force_and_the_new_step_at_edges():
    np.testing.assert_array_equal(_profile().sample(5.0), [1.0, 1.0, -0.5, 3.0, 3.0, 3.0, 3.0])


def test_concatenate_and_repeat_keep_order_labels_and_metadata():
    profile = _profile()
    joined = profile.concatenate(constant_current_profile(2.0, 7.0))
    assert joined.labels == ("a", "b", "a", "constant")
    assert joined.total_duration_s == 42.0
    assert joined.metadata == {"x": 1}
    tripled = profile.repeat(3)
    assert tripled.n_points == 9
    assert tripled.charge_ah == pytest.approx(3 * profile.charge_ah)
    assert tripled.labels[3:6] == profile.labels


def test_csv_round_trip_is_exact(tmp_path):
    profile = LoadProfile(np.array([0.1, 1 / 3]), np.array([np.pi, 2.0]), ("idling", "label, with comma"))
    read = LoadProfile.from_csv(profile.to_csv(tmp_path / "p.csv"))
    np.testing.assert_array_equal(read.duration_s, profile.duration_s)
    np.testing.assert_array_equal(read.current_a, profile.current_a)
    assert read.labels == profile.labels
    assert (tmp_path / "p.csv").read_text().splitlines()[0] == "duration_s,current_a,label"


def test_arrays_are_read_only():
    profile = _profile()
    with pytest.raises(ValueError):
        profile.current_a[0] = 5.0


@pytest.mark.parametrize(
    ("durations", "currents", "labels"),
    [
        ([], [], None),
        ([1.0, 2.0], [1.0], None),
        ([1.0, 0.0], [1.0, 1.0], None),
        ([1.0, -2.0], [1.0, 1.0], None),
        ([1.0, np.nan], [1.0, 1.0], None),
        ([1.0, 1.0], [1.0, np.inf], None),
        ([1.0, 1.0], [1.0, 1.0], ("only one",)),
        ([[1.0, 1.0]], [[1.0, 1.0]], None),
    ],
)
def test_invalid_profiles_raise_profile_error(durations, currents, labels):
    with pytest.raises(ProfileError):
        LoadProfile(np.array(durations, dtype=float), np.array(currents, dtype=float), labels)


@pytest.mark.parametrize("n", [0, -1, 1.5, True])
def test_repeat_needs_a_positive_integer(n):
    with pytest.raises(ProfileError):
        _profile().repeat(n)


def test_sample_needs_a_positive_period():
    with pytest.raises(ProfileError):
        _profile().sample(0.0)


def test_from_csv_names_file_and_row_of_a_bad_value(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("duration_s,current_a,label\n1.0,2.0,a\nx,2.0,b\n")
    with pytest.raises(ProfileError, match=r"bad\.csv: row 3"):
        LoadProfile.from_csv(path)
    path.write_text("time,current\n1,2\n")
    with pytest.raises(ProfileError, match="header"):
        LoadProfile.from_csv(path)
    with pytest.raises(ProfileError, match="cannot read"):
        LoadProfile.from_csv(tmp_path / "missing.csv")
