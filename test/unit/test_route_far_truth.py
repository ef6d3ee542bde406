"""The truth side of benchmarks/route_far_truth.py: it says no when the route runs the pack below the threshold."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from battery_predictor.params import load_params
from battery_predictor.profiles import longest_route, route_profile
from battery_predictor.simulation import StepLoad

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench(repo_script):
    return repo_script("benchmarks/route_far_truth.py")


def test_the_truth_accepts_a_route_from_a_charged_pack_and_refuses_it_from_a_drained_one(bench):
    params = load_params(REPO / "params" / "ranger_mini.yaml")
    route = StepLoad.from_profile(route_profile(longest_route(80.0), mode="mean"))
    day = StepLoad.constant(10.0, 4 * 3600.0)
    fresh = bench.truth_after_route(params, day, 60.0, route)
    drained = bench.truth_after_route(params, day, 4 * 3600.0 - 60.0, route)
    assert fresh >= bench.THRESHOLD_V
    assert math.isnan(drained) or drained < bench.THRESHOLD_V


def test_the_tally_counts_a_yes_where_the_truth_says_no_as_unsafe(bench):
    answers = [
        {"accepted": True, "truth_yes": False, "predicted_v": 46.5, "truth_v": 46.1},
        {"accepted": False, "truth_yes": True, "predicted_v": 46.2, "truth_v": 46.4},
        {"accepted": True, "truth_yes": True, "predicted_v": 47.0, "truth_v": 47.0},
        {"accepted": False, "truth_yes": False, "predicted_v": math.nan, "truth_v": math.nan},
    ]
    t = bench.tally(answers)
    assert (t["questions"], t["unsafe_accepts"], t["wasted_rejects"], t["accepted"], t["truth_yes"]) == (4, 1, 1, 2, 2)
    assert t["voltage_mae_v"] == pytest.approx((0.4 + 0.2 + 0.0) / 3)


def test_a_truth_with_a_weak_group_says_no_where_the_pack_voltage_alone_would_say_yes(bench):
    params = load_params(REPO / "params" / "ranger_mini.yaml")
    route = StepLoad.from_profile(route_profile(longest_route(80.0), mode="mean"))
    day = StepLoad.constant(10.0, 4 * 3600.0)
    # after 1.8 h at 10 A the identical cells end the route above the threshold; a group at 80 % stops on the way
    assert bench.truth_after_route(params, day, 1.8 * 3600.0, route) >= bench.THRESHOLD_V
    assert math.isnan(bench.truth_after_route(bench.with_weak_group(params, 0.8), day, 1.8 * 3600.0, route))
