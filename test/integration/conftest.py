"""Fixtures of the solver-heavy integration tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from battery_predictor.params import load_params

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def temi_params():
    return load_params(REPO / "params" / "temi.yaml")
