"""A weak series group inferred from fit data that stop on the plateau above the route threshold."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.cli.common import with_inferred_weak_group
from battery_predictor.params import load_params
from battery_predictor.prediction.pack_model import pack_model
from battery_predictor.prediction.weak_group import inferred_weak_fraction, stop_voltage_v, weak_group_evidence
from battery_predictor.recording import DeepestState, Recording, deepest_state, ends_at_deepest
from battery_predictor.simulation.extensions import weak_group_fraction, with_weak_group

PARAMS = Path(__file__).resolve().parents[2] / "params"
T_K = 298.15


def ranger():
    return load_params(PARAMS / "ranger_mini.yaml")


def discharge_until_stop(params, current_a: float, step_s: float = 60.0) -> Recording:
    """A constant-current discharge of ``params`` from full to its stop, sampled every ``step_s``."""
    run = pack_model(params)[0].run(1.0, [(48 * 3600.0, current_a)], T_K)
    t = np.arange(0.0, float(run.time_s[-1]), step_s)
    t = np.append(t, float(run.time_s[-1]))
    v = np.interp(t, run.time_s, run.pack_voltage_v)
    return Recording(t, v, np.full(t.size, current_a))


def plateau_recording(end_drop_v: float, end_current_a: float = 2.0) -> Recording:
    """An hour on a falling plateau (49 -> 47.5 V), its last sample ``end_drop_v`` lower still."""
    t = np.arange(0.0, 3600.0, 60.0)
    v = np.linspace(49.0, 47.5, t.size)
    v[-1] -= end_drop_v
    i = np.full(t.size, 2.0)
    i[-1] = end_current_a
    return Recording(t, v, i)


def test_a_recording_that_stops_while_discharging_ends_at_its_deepest_state():
    assert ends_at_deepest([plateau_recording(0.0)])
    assert ends_at_deepest([plateau_recording(0.8)])  # on its knee too


def test_a_recording_that_ends_at_rest_charging_or_recovered_does_not():
    assert not ends_at_deepest([plateau_recording(0.0, end_current_a=0.0)])
    assert not ends_at_deepest([plateau_recording(0.0, end_current_a=-3.0)])
    recovered = plateau_recording(0.0)
    recovered.voltage_v[-5:] += 0.6  # its deepest state lies before the end
    assert not ends_at_deepest([recovered])
    assert ends_at_deepest([recovered, plateau_recording(0.1)])  # another recording ends at the deepest state


def test_the_stop_of_a_pack_with_a_weak_group_is_found_again_from_its_voltage():
    params = ranger()
    stop_v = stop_voltage_v(params, 0.85, DeepestState(47.0, 2.5, T_K))
    assert stop_v > params.thresholds["route_min_voltage_v"]  # the weak group stops the pack on the plateau
    inference = inferred_weak_fraction(params, DeepestState(stop_v, 2.5, T_K))
    assert inference.fraction == pytest.approx(0.85, abs=2e-3)
    assert inference.stop_voltage_v == pytest.approx(stop_v, abs=0.01)
    assert not inference.at_bound


def test_fit_data_of_a_weak_pack_that_stop_on_the_plateau_give_it_its_weak_group():
    params = ranger()
    rec = discharge_until_stop(with_weak_group(params, 0.8), 3.0)
    deepest = deepest_state([rec], T_K)
    assert weak_group_evidence(params, [rec], deepest) == ""
    fitted, line = with_inferred_weak_group(params, [rec], deepest)
    assert weak_group_fraction(fitted) == pytest.approx(0.8, abs=0.01)
    assert line.startswith("weak series group inferred: its cells hold 0.80")


def test_fit_data_of_identical_cells_cut_on_the_knee_above_the_threshold_get_a_group_near_one_that_stops_there():
    params = ranger()
    rec = discharge_until_stop(params, 3.0)
    keep = int(np.searchsorted(-rec.voltage_v, -46.6))  # stopped on the knee above 46.31 V
    cut = Recording(rec.time_s[:keep], rec.voltage_v[:keep], rec.current_a[:keep])
    fitted, _ = with_inferred_weak_group(params, [cut], deepest_state([cut], T_K))
    assert 0.9 < weak_group_fraction(fitted) < 1.0
    assert stop_voltage_v(params, weak_group_fraction(fitted), DeepestState(0.0, 3.0, T_K)) == pytest.approx(
        float(cut.voltage_v[-1]), abs=0.02)


def test_fit_data_that_end_at_the_charger_leave_the_cells_identical():
    params = ranger()
    rec = plateau_recording(0.0, end_current_a=-5.0)
    fitted, line = with_inferred_weak_group(params, [rec], deepest_state([rec], T_K))
    assert fitted is params
    assert line == "no weak series group inferred (the fit data do not end at their deepest state under load)"


@pytest.mark.parametrize(("change", "reason"), [
    (lambda p: replace(p, thresholds={}), "no route threshold"),
    (lambda p: with_weak_group(p, 0.9), "the params model a weak group already"),
    (lambda p: replace(p, thresholds={**p.thresholds, "route_min_voltage_v": 48.5}),
     "the fit data reach the route threshold"),
])
def test_no_group_is_inferred_without_a_threshold_with_one_modelled_or_when_the_data_reach_the_threshold(change,
                                                                                                        reason):
    rec = plateau_recording(0.0)
    assert weak_group_evidence(change(ranger()), [rec], deepest_state([rec], T_K)) == reason
