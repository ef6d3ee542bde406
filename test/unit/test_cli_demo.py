"""The demo's printed answers."""

from __future__ import annotations

from types import SimpleNamespace

from battery_predictor.cli.cmd_demo import _route_outcome


def test_a_planned_route_the_pack_does_not_finish_is_said_so_never_printed_as_nan():
    r = SimpleNamespace(predicted_voltage_v=float("nan"), threshold_voltage_v=46.31, margin_v=float("nan"),
                        probability_above_threshold=float("nan"), risk=float("nan"))
    text = _route_outcome(r)
    assert "nan" not in text.lower()
    assert "does not finish" in text and "46.31 V" in text


def test_a_planned_route_that_ends_above_the_cutoff_prints_its_voltage_and_margin():
    r = SimpleNamespace(predicted_voltage_v=47.2, threshold_voltage_v=46.31, margin_v=0.89,
                        probability_above_threshold=0.93, risk=0.1)
    assert _route_outcome(r) == ("47.20 V at the standstill current after it, threshold 46.31 V, margin +0.89 V, "
                                 "probability above the threshold 0.930 (accepted at risk 0.10)")
