"""Screening (paper step 4) reproduces the paper's finding for the information robot."""

from __future__ import annotations

import pytest

from battery_predictor.fitting.screening import EXCLUDED_SUBSTRINGS, screen, screenable_parameters
from battery_predictor.simulation import get_simulator

GEOMETRY_OR_CONCENTRATION = ("thickness", "height", "concentration", "volume fraction")


@pytest.fixture(scope="module")
def temi_rows(temi_params):
    return screen(temi_params, get_simulator("fast"))


def test_geometry_and_concentration_parameters_dominate_for_temi(temi_rows):
    relevant = [r for r in temi_rows if r.relevant]
    assert 6 <= len(relevant) <= 10  # the paper finds 8 with Chen2020
    for row in relevant:
        assert any(word in row.name for word in GEOMETRY_OR_CONCENTRATION), row.name
    # the top of the ranking is geometry/concentration, the most relevant changes runtime by > 5 %
    assert abs(relevant[0].runtime_change_pct) > 5.0


def test_diffusivities_and_particle_radii_have_minor_influence(temi_rows):
    minor = [r for r in temi_rows if "diffusivity" in r.name or "particle radius" in r.name]
    assert minor
    for row in minor:
        assert not row.relevant, row
        assert abs(row.runtime_change_pct) < 1.0


def test_ranking_puts_relevant_first_and_reports_both_figures(temi_rows):
    flags = [r.relevant for r in temi_rows]
    assert flags == sorted(flags, reverse=True)
    for r in temi_rows:
        assert r.r2 <= 1.0 + 1e-9


def test_excluded_parameters_are_not_screened(temi_params):
    names = screenable_parameters(temi_params)
    assert "Electrode width [m]" not in names
    assert "Ambient temperature [K]" not in names
    assert not any("Number of electrodes" in n for n in names)
    assert all(not any(s in n for s in EXCLUDED_SUBSTRINGS) for n in names)
    assert {"r_b_ohm", "r_c_ohm", "r_i_ohm"} <= set(names)
