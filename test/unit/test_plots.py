"""The figures a user looks at: the fit plot's identifiability panel."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure

from battery_predictor import plots
from battery_predictor.fitting.identifiability import IdentifiabilityReport
from battery_predictor.recording import Recording
from battery_predictor.simulation.base import PackSimResult

REPORT = IdentifiabilityReport(
    names=["negative_capacity_ah", "series_resistance_ohm", "initial_ocv_v:0"],
    values=[3.7, 0.008, 4.2], ci95_low=[3.6, -math.inf, 4.19], ci95_high=[3.8, math.inf, 4.21],
    determined=[True, False, True], correlated_pairs=[("negative_capacity_ah", "initial_ocv_v:0", -0.97)],
    eigen_directions=[], sigma=0.01)


def test_relative_half_widths_are_relative_to_the_value_and_infinite_when_unbounded():
    widths = REPORT.relative_half_widths()
    assert abs(widths[0] - 0.1 / 3.7) < 1e-12
    assert math.isinf(widths[1])
    assert abs(widths[2] - 0.01 / 4.2) < 1e-12


def test_the_fit_plot_has_an_identifiability_panel_naming_the_compensating_pair(tmp_path, monkeypatch):
    t = np.arange(0.0, 600.0, 5.0)
    rec = Recording(t, 4.0 - 1e-4 * t, np.ones_like(t), source="day.csv")
    res = PackSimResult(t, 4.0 - 1e-4 * t, np.ones_like(t), 4.0 - 1e-4 * t, "end_of_load", float(t[-1]))
    figures: list[Figure] = []
    monkeypatch.setattr(plots.Figure, "savefig", lambda self, *a, **k: figures.append(self))
    plots.plot_voltage_fit([rec], [res], tmp_path / "fit.png", title="fit", identifiability=REPORT.plot_rows())
    panel = figures[0].axes[-1]
    assert [tick.get_text() for tick in panel.get_yticklabels()] == REPORT.names
    assert "negative_capacity_ah ~ initial_ocv_v:0 (-0.97)" in panel.get_title()
    bars = panel.patches
    assert [b.get_width() for b in bars][1] == plots.HALF_WIDTH_AXIS_MAX  # unbounded drawn to the axis end
    assert bars[0].get_facecolor() != bars[1].get_facecolor()  # determined vs not


def test_the_fit_plot_without_a_report_has_one_panel_per_recording(tmp_path):
    t = np.arange(0.0, 600.0, 5.0)
    rec = Recording(t, 4.0 - 1e-4 * t, np.ones_like(t), source="day.csv")
    res = PackSimResult(t, 4.0 - 1e-4 * t, np.ones_like(t), 4.0 - 1e-4 * t, "end_of_load", float(t[-1]))
    path = plots.plot_voltage_fit([rec, rec], [res, res], tmp_path / "fit.png", title="fit")
    assert path.stat().st_size > 0
