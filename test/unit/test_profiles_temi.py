"""Temi usage model: survey derivation, config loading and the stochastic generator (paper 5.1.2-5.1.4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from battery_predictor.errors import ParamsError, ProfileError
from battery_predictor.profiles.temi import (
    IDLING,
    INFORMATION,
    NAVIGATION,
    STATES,
    derive_usage_probabilities,
    generate_usage_profile,
    load_usage_config,
    navigation_duration_range_s,
)

REPO = Path(__file__).resolve().parents[2]
CONFIG_PATH = REPO / "params" / "temi_usage.yaml"
PAPER_COUNTS = {"information_services": 78, "navigation_services": 56, "other_services": 17, "other_purposes": 1}
N_POINTS = 6000


@pytest.fixture(scope="module")
def config():
    return load_usage_config(CONFIG_PATH)


@pytest.fixture(scope="module")
def large_profile(config):
    return generate_usage_profile(config, seed=12345, max_points=N_POINTS)


def _durations(profile, state):
    return profile.duration_s[np.array(profile.labels) == state]


def test_paper_survey_gives_10_0_57_6_32_4_percent():
    p = derive_usage_probabilities(PAPER_COUNTS, 0.10)
    assert p[IDLING] == pytest.approx(0.100)
    assert p[INFORMATION] == pytest.approx(0.576)
    assert p[NAVIGATION] == pytest.approx(0.324)
    assert sum(p.values()) == pytest.approx(1.0)


def test_exact_normalisation_without_rounding_gives_56_8_and_33_2_percent():
    p = derive_usage_probabilities(PAPER_COUNTS, 0.10, share_resolution=None)
    assert p[INFORMATION] == pytest.approx(0.9 * 96 / 152)
    assert p[NAVIGATION] == pytest.approx(0.9 * 56 / 152)


def test_a_new_survey_changes_the_probabilities():
    counts = {"information_services": 50, "navigation_services": 50, "other_services": 0, "other_purposes": 0}
    p = derive_usage_probabilities(counts, 0.20)
    assert p == pytest.approx({IDLING: 0.20, INFORMATION: 0.40, NAVIGATION: 0.40})


def test_shipped_config_reproduces_the_paper_probabilities(config):
    assert config.probabilities == pytest.approx({IDLING: 0.100, INFORMATION: 0.576, NAVIGATION: 0.324})
    assert config.stop_voltage_v == pytest.approx(13.30)


@pytest.mark.parametrize(
    ("counts", "idle_share"),
    [
        ({"information_services": -1, "navigation_services": 5}, 0.1),
        ({"information_services": 0, "navigation_services": 0}, 0.1),
        ({"information_services": 3, "unassigned_answer": 2}, 0.1),
        ({"information_services": 3, "navigation_services": 2}, 1.0),
        ({"information_services": 3, "navigation_services": 2.5}, 0.1),
    ],
)
def test_invalid_survey_raises_profile_error(counts, idle_share):
    with pytest.raises(ProfileError):
        derive_usage_probabilities(counts, idle_share)


def test_interaction_samples_match_the_paper_observation(config):
    raw = yaml.safe_load(CONFIG_PATH.read_text())["durations"]["interaction_samples_s"]
    assert len(raw["ticket_machine"]) == 7
    assert len(raw["personal_contact"]) == 17
    samples = config.interaction_samples_s
    assert samples.min() == 19.0
    assert 15 * 60 <= samples.max() <= 17 * 60
    assert samples.mean() == pytest.approx(4.5 * 60, abs=15.0)


def test_navigation_range_is_derived_from_1_to_60_m_at_0_90_m_s(config):
    low, high = navigation_duration_range_s(1.0, 60.0, 0.90)
    assert (low, high) == pytest.approx((1.0 / 0.9, 60.0 / 0.9))
    assert config.navigation_duration_range_s == pytest.approx((low, high))
    assert round(low) == 1 and round(high) == 67


def test_state_frequencies_match_probabilities_within_4_sigma(config, large_profile):
    labels = np.array(large_profile.labels)
    assert len(labels) == N_POINTS
    for state in STATES:
        p = config.probabilities[state]
        sigma = np.sqrt(N_POINTS * p * (1 - p))
        assert abs(np.sum(labels == state) - N_POINTS * p) < 4 * sigma, state


def test_navigation_durations_are_uniform_between_1_and_67_s_with_mean_34_s(config, large_profile):
    durations = _durations(large_profile, NAVIGATION)
    low, high = config.navigation_duration_range_s
    assert durations.min() >= low and durations.max() <= high
    expected_mean = (low + high) / 2
    assert expected_mean == pytest.approx(34.0, abs=0.5)
    standard_error = (high - low) / np.sqrt(12) / np.sqrt(len(durations))
    assert abs(durations.mean() - expected_mean) < 4 * standard_error
    # Uniform: each third of the range holds about a third of the trips.
    counts, _ = np.histogram(durations, bins=3, range=(low, high))
    assert np.all(np.abs(counts - len(durations) / 3) < 4 * np.sqrt(len(durations) * 2 / 9))


@pytest.mark.parametrize("state", [IDLING, INFORMATION])
def test_idle_and_information_durations_follow_the_clipped_interaction_kde(config, large_profile, state):
    durations = _durations(large_profile, state)
    distribution = config.duration_distribution(state)
    assert durations.min() >= 19.0 and durations.max() <= config.interaction_samples_s.max()
    standard_error = distribution.std / np.sqrt(len(durations))
    assert abs(durations.mean() - distribution.mean) < 4 * standard_error
    # The KDE mean stays near the observed 4.5 min average.
    assert distribution.mean == pytest.approx(270.0, rel=0.1)


def test_currents_stay_in_each_states_sample_range_and_navigation_draws_most(config, large_profile):
    labels = np.array(large_profile.labels)
    means = {}
    for state in STATES:
        currents = large_profile.current_a[labels == state]
        samples = config.current_samples_a[state]
        assert currents.min() >= samples.min() and currents.max() <= samples.max()
        means[state] = currents.mean()
    assert means[NAVIGATION] > means[INFORMATION] > means[IDLING]
    assert means[INFORMATION] - means[IDLING] < 0.5  # only slightly above the base load


def test_same_seed_gives_the_same_profile_and_other_seeds_differ(config):
    a = generate_usage_profile(config, 7, max_points=300)
    b = generate_usage_profile(config, 7, max_points=300)
    c = generate_usage_profile(config, 8, max_points=300)
    np.testing.assert_array_equal(a.duration_s, b.duration_s)
    np.testing.assert_array_equal(a.current_a, b.current_a)
    assert a.labels == b.labels
    assert not np.array_equal(a.current_a, c.current_a)


def test_a_shorter_profile_is_a_prefix_of_a_longer_one_with_the_same_seed(config):
    short = generate_usage_profile(config, 3, max_points=100)
    long = generate_usage_profile(config, 3, max_points=1000)
    np.testing.assert_array_equal(short.current_a, long.current_a[:100])
    assert short.labels == long.labels[:100]


def test_max_duration_stops_with_exactly_that_total(config):
    profile = generate_usage_profile(config, 1, max_duration_s=8 * 3600.0)
    assert profile.total_duration_s == pytest.approx(8 * 3600.0, abs=1e-6)
    assert profile.metadata["stop_voltage_v"] == pytest.approx(13.30)
    assert profile.metadata["seed"] == 1
    assert set(profile.labels) <= set(STATES)


def test_max_charge_stops_with_exactly_that_charge(config):
    profile = generate_usage_profile(config, 2, max_charge_ah=12.5)
    assert profile.charge_ah == pytest.approx(12.5, abs=1e-9)


def test_the_first_limit_reached_wins(config):
    profile = generate_usage_profile(config, 2, max_duration_s=1e6, max_points=10)
    assert profile.n_points == 10


@pytest.mark.parametrize(
    "limits",
    [{}, {"max_duration_s": 0.0}, {"max_charge_ah": float("nan")}, {"max_points": 0}, {"max_points": 2.5}],
)
def test_missing_or_invalid_stop_condition_raises_profile_error(config, limits):
    with pytest.raises(ProfileError):
        generate_usage_profile(config, 0, **limits)


def _write_config(tmp_path, mutate):
    data = yaml.safe_load(CONFIG_PATH.read_text())
    mutate(data)
    path = tmp_path / "temi_bad.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("mutate", "key"),
    [
        (lambda d: d["survey"].pop("idle_share"), "survey.idle_share"),
        (lambda d: d["navigation"].update(speed_m_s=0.0), "navigation.speed_m_s"),
        (lambda d: d["currents_a"].update(navigation=[3.0, "x"]), "currents_a.navigation[1]"),
        (lambda d: d["currents_a"].update(idling=[1.0, -1.0]), "currents_a.idling[1]"),
        (lambda d: d["survey"]["assignment"].update(other_services="fun"), "survey.assignment.other_services"),
        (lambda d: d.update(lenght_m=3), "lenght_m"),
        (lambda d: d["durations"]["interaction_samples_s"].update(ticket_machine=[0.0]),
         "durations.interaction_samples_s.ticket_machine[0]"),
    ],
)
def test_bad_config_raises_params_error_naming_file_and_key(tmp_path, mutate, key):
    path = _write_config(tmp_path, mutate)
    with pytest.raises(ParamsError) as info:
        load_usage_config(path)
    assert str(path) in str(info.value)
    assert key in str(info.value)


def test_missing_config_file_raises_params_error(tmp_path):
    with pytest.raises(ParamsError, match="cannot read"):
        load_usage_config(tmp_path / "nope.yaml")
