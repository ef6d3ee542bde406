"""Ranger Mini currents, routes and route profiles (paper 5.2.1-5.2.2)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from battery_predictor.errors import ParamsError, ProfileError
from battery_predictor.profiles.ranger import (
    STANDSTILL_LABEL,
    Route,
    RouteSection,
    constant_current_profile,
    curve_points_for,
    load_ranger_currents,
    longest_route,
    mean_current_a,
    route_from_station,
    route_profile,
    stepwise_profile,
)
from battery_predictor.profiles.station import SLOPES, load_station

REPO = Path(__file__).resolve().parents[2]
CURRENTS_PATH = REPO / "params" / "ranger_currents.yaml"
STATION_PATH = REPO / "params" / "minden_station.yaml"
PAYLOADS_KG = (0.0, 20.0, 40.0, 60.0, 80.0)


@pytest.fixture(scope="module")
def currents():
    return load_ranger_currents(CURRENTS_PATH)


@pytest.fixture(scope="module")
def station():
    return load_station(STATION_PATH)


# --- currents ---------------------------------------------------------------


def test_shipped_currents_hold_15_sets_spanning_0_50_to_7_30_a(currents):
    assert len(currents.samples_a) == 15
    everything = np.concatenate(list(currents.samples_a.values()))
    assert everything.min() == pytest.approx(0.50)
    assert everything.max() == pytest.approx(7.30)
    assert currents.standstill_current_a == pytest.approx(1.70)
    assert currents.speed_m_s == pytest.approx(0.50)


@pytest.mark.parametrize("payload_kg", PAYLOADS_KG)
def test_uphill_draws_far_more_than_flat_and_flat_more_than_downhill(currents, payload_kg):
    flat = currents.mean_current_a(payload_kg, "flat")
    assert currents.mean_current_a(payload_kg, "uphill") > flat + 0.8
    assert flat > currents.mean_current_a(payload_kg, "downhill")


@pytest.mark.parametrize("slope", ["flat", "uphill"])
def test_flat_and_uphill_current_grows_with_payload(currents, slope):
    means = [currents.mean_current_a(p, slope) for p in PAYLOADS_KG]
    assert np.all(np.diff(means) > 0)


def test_mean_current_is_the_sample_mean_at_measured_payloads(currents):
    for (slope, payload), samples in currents.samples_a.items():
        assert currents.mean_current_a(payload, slope) == pytest.approx(samples.mean())


def test_mean_current_interpolates_linearly_between_payload_levels(currents):
    for slope in SLOPES:
        expected = 0.75 * currents.mean_current_a(20, slope) + 0.25 * currents.mean_current_a(40, slope)
        assert currents.mean_current_a(25, slope) == pytest.approx(expected)


def test_mean_current_clamps_payloads_above_80_kg(currents):
    assert currents.mean_current_a(150, "uphill") == currents.mean_current_a(80, "uphill")


def test_module_level_mean_current_uses_the_shipped_currents(currents):
    assert mean_current_a(40, "flat") == pytest.approx(currents.mean_current_a(40, "flat"))


@pytest.mark.parametrize("payload_kg", [-1.0, float("nan"), float("inf"), 250.0, "heavy"])
def test_negative_nan_or_absurd_payload_raises_profile_error(currents, payload_kg):
    with pytest.raises(ProfileError):
        currents.mean_current_a(payload_kg, "flat")


def test_unknown_slope_raises_profile_error(currents):
    with pytest.raises(ProfileError):
        currents.mean_current_a(20, "stairs")


def test_sampled_currents_stay_within_the_measured_range(currents):
    rng = np.random.default_rng(0)
    draws = currents.sample_current_a(30.0, "uphill", 5000, rng)
    low = min(currents.samples_a[("uphill", 20.0)].min(), currents.samples_a[("uphill", 40.0)].min())
    high = max(currents.samples_a[("uphill", 20.0)].max(), currents.samples_a[("uphill", 40.0)].max())
    assert draws.min() >= low and draws.max() <= high
    expected = currents.kde(20, "uphill").mean * 0.5 + currents.kde(40, "uphill").mean * 0.5
    assert abs(draws.mean() - expected) < 4 * draws.std() / np.sqrt(draws.size)


def test_bad_currents_yaml_raises_params_error_naming_file_and_key(tmp_path):
    data = yaml.safe_load(CURRENTS_PATH.read_text())
    del data["samples_a"]["downhill"][60]
    path = tmp_path / "currents_bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ParamsError) as info:
        load_ranger_currents(path)
    assert str(path) in str(info.value) and "samples_a.downhill.60" in str(info.value)


# --- the paper's longest route ----------------------------------------------


def test_longest_route_has_5_steps_and_lasts_29_67_min_travel_plus_2_min_standstill():
    route = longest_route(80)
    assert [name for name, _ in route.legs()] == [
        "step 1: standstill",
        "step 2: charger->platform11_south",
        "step 3: platform11_south->platform13_south",
        "step 4: platform13_south->charger",
        "step 5: standstill",
    ]
    assert route.length_m == pytest.approx(190 + 420 + 280)
    assert route.travel_s / 60 == pytest.approx(29.67, abs=0.005)
    assert route.standstill_s == pytest.approx(120.0)
    assert route.duration_s == pytest.approx(1900.0)


@pytest.mark.parametrize("mode", ["sampled", "mean"])
def test_longest_route_profile_has_97_points_and_lasts_31_67_min(currents, mode):
    profile = route_profile(longest_route(80), currents, seed=1, mode=mode)
    assert profile.n_points == 97
    assert profile.total_duration_s == pytest.approx(1900.0)
    assert profile.total_duration_s / 60 == pytest.approx(31.67, abs=0.005)
    assert profile.metadata["points_per_section"] == [1, 20, 37, 8, 8, 22, 1]
    assert np.all(profile.duration_s[1:-1] <= 19.0 + 1e-9)


def test_splitting_rounds_up_so_no_point_exceeds_19_s():
    assert [curve_points_for(t) for t in (380.0, 690.0, 150.0, 410.0)] == [20, 37, 8, 22]
    # Rounding to the nearest integer would have given 96 points.
    assert 2 + sum(round(t / 19) for t in (380.0, 690.0, 150.0, 150.0, 410.0)) == 96
    assert curve_points_for(1.0) == 1


def test_standstill_points_last_60_s_at_1_70_a(currents):
    profile = route_profile(longest_route(40), currents, seed=2)
    for index in (0, -1):
        assert profile.labels[index] == STANDSTILL_LABEL
        assert profile.duration_s[index] == pytest.approx(60.0)
        assert profile.current_a[index] == pytest.approx(1.70)


def test_mean_mode_uses_the_mean_current_of_each_section(currents):
    route = longest_route(60)
    profile = route_profile(route, currents, mode="mean")
    labels = np.array(profile.labels)
    for section in route.sections:
        if section.length_m > 0:
            values = profile.current_a[labels == section.name]
            np.testing.assert_allclose(values, currents.mean_current_a(section.payload_kg, section.slope))


def test_sampled_mode_is_reproducible_per_seed_and_stays_in_range(currents):
    a = route_profile(longest_route(80), currents, seed=5)
    b = route_profile(longest_route(80), currents, seed=5)
    c = route_profile(longest_route(80), currents, seed=6)
    np.testing.assert_array_equal(a.current_a, b.current_a)
    assert not np.array_equal(a.current_a, c.current_a)
    assert a.current_a.min() >= 0.50 and a.current_a.max() <= 7.30


def test_unknown_mode_raises_profile_error(currents):
    with pytest.raises(ProfileError):
        route_profile(longest_route(80), currents, mode="median")


# --- routes on the station graph --------------------------------------------


def test_station_route_for_the_longest_job_matches_the_paper_route(currents, station):
    route = route_from_station(station, "charger", "platform11_south", "platform13_south", 80)
    paper = route_profile(longest_route(80), currents, mode="mean")
    built = route_profile(route, currents, mode="mean")
    assert built.n_points == 97
    assert built.total_duration_s == pytest.approx(1900.0)
    assert built.charge_ah == pytest.approx(paper.charge_ah)
    assert [s.payload_kg for s in route.sections] == [0.0, 80.0, 80.0, 0.0, 0.0]
    assert [s.slope for s in route.sections] == ["flat", "flat", "uphill", "downhill", "flat"]


def test_station_route_loads_at_the_pickup_and_unloads_at_the_dropoff(currents, station):
    route = route_from_station(station, "charger", "platform11_middle", "platform12_north", 20)
    legs = route.legs()
    assert [name for name, _ in legs] == [
        "charger->platform11_middle",
        "platform11_middle->platform12_north",
        "platform12_north->charger",
    ]
    # Standstill follows a section (as in RouteSection.msg): loading ends the
    # first leg, unloading ends the loaded leg.
    assert legs[0][1][-1].standstill_s == 60.0 and legs[0][1][-1].payload_kg == 0.0
    assert legs[1][1][-1].standstill_s == 60.0 and legs[1][1][-1].payload_kg == 20.0
    assert legs[2][1][-1].standstill_s == 0.0
    assert route.length_m == pytest.approx(70 + 12 + 78.5 + 78.5 + 12 + 70)
    profile = route_profile(route, currents, mode="mean")
    standstill = [i for i, label in enumerate(profile.labels) if label == STANDSTILL_LABEL]
    n_first_leg = curve_points_for(70 / 0.5)
    assert standstill[0] == n_first_leg  # right after arriving at the pickup


def test_pickup_at_the_start_keeps_only_the_loading_standstill_of_the_empty_first_leg(station):
    route = route_from_station(station, "charger", "charger", "platform11_south", 10)
    assert [name for name, _ in route.legs()] == [
        "standstill at charger",
        "charger->platform11_south",
        "platform11_south->charger",
    ]
    assert route.sections[0].length_m == 0.0 and route.sections[0].standstill_s == 60.0
    no_loading = route_from_station(station, "charger", "charger", "platform11_south", 10, loading_s=0.0)
    assert [name for name, _ in no_loading.legs()] == ["charger->platform11_south", "platform11_south->charger"]


def test_pickup_equal_to_dropoff_or_unknown_location_raises_profile_error(station):
    with pytest.raises(ProfileError):
        route_from_station(station, "charger", "platform11_south", "platform11_south", 10)
    with pytest.raises(ProfileError):
        route_from_station(station, "charger", "platform11_south", "platform99", 10)
    with pytest.raises(ProfileError):
        route_from_station(station, "charger", "platform11_south", "platform13_south", -5)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"name": "", "length_m": 10.0, "slope": "flat", "payload_kg": 0.0},
        {"name": "s", "length_m": -1.0, "slope": "flat", "payload_kg": 0.0},
        {"name": "s", "length_m": math.nan, "slope": "flat", "payload_kg": 0.0},
        {"name": "s", "length_m": 10.0, "slope": "sideways", "payload_kg": 0.0},
        {"name": "s", "length_m": 10.0, "slope": "flat", "payload_kg": 300.0},
        {"name": "s", "length_m": 10.0, "slope": "flat", "payload_kg": 0.0, "speed_m_s": 0.0},
        {"name": "s", "length_m": 10.0, "slope": "flat", "payload_kg": 0.0, "standstill_s": -3.0},
        {"name": "s", "length_m": 0.0, "slope": "flat", "payload_kg": 0.0},
    ],
)
def test_invalid_route_section_raises_profile_error(kwargs):
    with pytest.raises(ProfileError):
        RouteSection(**kwargs)


def test_empty_route_or_wrong_section_type_raises_profile_error():
    with pytest.raises(ProfileError):
        Route(())
    with pytest.raises(ProfileError):
        Route(("not a section",))


# --- stepwise and constant profiles -----------------------------------------


def test_stepwise_profile_applies_each_current_for_10_min_with_45_v_stop():
    profile = stepwise_profile()
    np.testing.assert_array_equal(profile.current_a, [0.5, 1, 2, 3, 4, 5, 6, 7, 8])
    np.testing.assert_array_equal(profile.duration_s, np.full(9, 600.0))
    assert profile.metadata["stop_voltage_v"] == 45.0
    assert profile.metadata["repeat_until_stop"] is True
    assert profile.charge_ah == pytest.approx(36.5 / 6)


@pytest.mark.parametrize(("currents_a", "step_s"), [((), 600.0), ((1.0, -2.0), 600.0), ((1.0,), 0.0)])
def test_invalid_stepwise_profile_raises_profile_error(currents_a, step_s):
    with pytest.raises(ProfileError):
        stepwise_profile(currents_a, step_s)


def test_constant_current_profile_is_one_point():
    profile = constant_current_profile(7.35, 3600.0)
    assert profile.n_points == 1 and profile.charge_ah == pytest.approx(7.35)
    with pytest.raises(ProfileError):
        constant_current_profile(1.0, 0.0)
