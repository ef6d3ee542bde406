"""Minden station graph: shortest paths reproduce the paper's distances (sections 3 and 5.2.2)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from battery_predictor.errors import ParamsError, ProfileError
from battery_predictor.profiles.station import Edge, Segment, Station, load_station

REPO = Path(__file__).resolve().parents[2]
STATION_PATH = REPO / "params" / "minden_station.yaml"


@pytest.fixture(scope="module")
def station():
    return load_station(STATION_PATH)


@pytest.mark.parametrize(
    ("start", "goal", "length_m"),
    [
        ("charger", "platform11_south", 190.0),
        ("platform11_south", "platform13_south", 420.0),
        ("platform13_south", "charger", 280.0),
        ("charger", "platform11_middle", 70.0),
        ("platform11_south", "platform11_north", 295.0),
        ("platform13_south", "platform13_north", 295.0),
        ("platform1_south", "platform1_north", 157.0),
        ("platform12_south", "platform12_north", 157.0),
    ],
)
def test_shortest_paths_reproduce_the_paper_distances(station, start, goal, length_m):
    assert station.distance_m(start, goal) == pytest.approx(length_m)
    assert station.distance_m(goal, start) == pytest.approx(length_m)


def test_loaded_leg_has_345_m_flat_then_75_m_uphill(station):
    path = station.shortest_path("platform11_south", "platform13_south")
    assert [(s.slope, s.length_m) for s in path.segments] == [("flat", 345.0), ("uphill", 75.0)]
    assert path.nodes == ("platform11_south", "platform13_south")


def test_return_leg_has_75_m_downhill_then_205_m_flat(station):
    path = station.shortest_path("platform13_south", "charger")
    assert [(s.slope, s.length_m) for s in path.segments] == [("downhill", 75.0), ("flat", 205.0)]


def test_travelling_an_edge_backwards_swaps_uphill_and_downhill(station):
    path = station.shortest_path("charger", "platform13_south")
    assert [(s.slope, s.length_m) for s in path.segments] == [("flat", 205.0), ("uphill", 75.0)]
    assert path.length_by_slope_m() == {"flat": 205.0, "uphill": 75.0, "downhill": 0.0}


def test_consecutive_flat_edges_merge_into_one_segment(station):
    path = station.shortest_path("charger", "platform11_north")
    assert path.nodes == ("charger", "platform11_middle", "platform11_north")
    assert [(s.slope, s.length_m) for s in path.segments] == [("flat", 217.5)]


def test_a_path_to_the_start_itself_is_empty(station):
    path = station.shortest_path("charger", "charger")
    assert path.length_m == 0.0 and path.segments == () and path.nodes == ("charger",)


def test_unknown_location_raises_profile_error(station):
    with pytest.raises(ProfileError, match="unknown location 'platform99'"):
        station.shortest_path("charger", "platform99")


def test_unreachable_location_raises_profile_error():
    station = Station({"a": "", "b": "", "c": ""}, [Edge("a", "b", (Segment(10.0, "flat"),))])
    with pytest.raises(ProfileError, match="no path"):
        station.shortest_path("a", "c")


@pytest.mark.parametrize(("length_m", "slope"), [(0.0, "flat"), (float("nan"), "flat"), (5.0, "steep")])
def test_invalid_segment_raises_profile_error(length_m, slope):
    with pytest.raises(ProfileError):
        Segment(length_m, slope)


@pytest.mark.parametrize(
    ("mutate", "key"),
    [
        (lambda d: d["edges"][0].update(to="platform99"), "edges[0].to"),
        (lambda d: d["edges"][1]["segments"][1].update(slope="steep"), "edges[1].segments[1].slope"),
        (lambda d: d["edges"][2]["segments"][0].update(length_m=-5), "edges[2].segments[0].length_m"),
        (lambda d: d["edges"][0].pop("segments"), "edges[0].segments"),
        (lambda d: d["edges"][0]["segments"][0].update(lenght_m=3), "edges[0].segments[0].lenght_m"),
    ],
)
def test_bad_station_yaml_raises_params_error_naming_file_and_key(tmp_path, mutate, key):
    data = yaml.safe_load(STATION_PATH.read_text())
    mutate(data)
    path = tmp_path / "station_bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ParamsError) as info:
        load_station(path)
    assert str(path) in str(info.value) and key in str(info.value)
