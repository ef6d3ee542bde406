"""Fixtures shared by every test directory (the shipped Temi params, a synthetic Temi discharge)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.recording import Recording

REPO = Path(__file__).resolve().parents[1]

#: Parameters the synthetic "truth" pack differs in from the shipped Temi params.
SYNTHETIC_TRUTH = {
    "Electrode height [m]": 0.80,
    "Negative electrode active material volume fraction": 0.66,
    "r_c_ohm": 0.06,
}


def _synthesize(params, seed: int) -> Recording:
    """A liionpack discharge of the Temi pack under a (3x heavier) usage profile, 5 s samples + noise."""
    from battery_predictor.profiles.temi import generate_usage_profile
    from battery_predictor.simulation import SimulationRequest, StepLoad
    from battery_predictor.simulation.liionpack_sim import LiionpackSimulator

    profile = generate_usage_profile(seed=seed, max_duration_s=4 * 3600)
    load = StepLoad.from_profile(profile).scale_current(3.0).resample(10.0)
    res = LiionpackSimulator(period_s=10.0).simulate(params, SimulationRequest(load=load))
    rng = np.random.default_rng(seed)
    v = np.round(res.pack_voltage_v + rng.normal(0.0, 0.003, res.time_s.size), 2)
    return Recording(time_s=res.time_s, voltage_v=v, current_a=np.round(res.pack_current_a, 1),
                     temperature_k=np.full(res.time_s.size, 298.15), source=f"synthetic-{seed}")


@pytest.fixture(scope="session")
def temi_params():
    return load_params(REPO / "params" / "temi.yaml")


@pytest.fixture(scope="session")
def synthetic_temi(temi_params):
    """(truth values, truth params, training recording, held-out recording) made by liionpack."""
    truth = temi_params.with_values(SYNTHETIC_TRUTH)
    return dict(SYNTHETIC_TRUTH), truth, _synthesize(truth, 11), _synthesize(truth, 12)


@pytest.fixture(scope="session")
def ranger_params():
    """The shipped Ranger Mini params."""
    return load_params(REPO / "params" / "ranger_mini.yaml")


@pytest.fixture(scope="session")
def longest_route_segments():
    """[(duration_s, pack current A), ...] of the longest route at 80 kg (mean currents), then 60 s standstill."""
    from battery_predictor.profiles.ranger import longest_route, route_profile

    profile = route_profile(longest_route(80.0), mode="mean")
    return list(zip(profile.duration_s, profile.current_a)) + [(60.0, 1.70)]
