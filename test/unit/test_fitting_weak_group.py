"""A weak series group inferred from fit data that stop on the plateau above the route threshold."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.fitting.data_limits import with_inferred_weak_group
from battery_predictor.fitting.weak_group import inferred_weak_fraction, stop_time_s, weak_group_evidence
from battery_predictor.params import load_params
from battery_predictor.recording import Recording, deepest_state, recording_ending_at_deepest
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator
from battery_predictor.simulation.extensions import weak_group_fraction, with_weak_group

PARAMS = Path(__file__).resolve().parents[2] / "params"
T_K = 298.15


def ranger():
    return load_params(PARAMS / "ranger_mini.yaml")


def discharge_until_stop(params, current_a: float, step_s: float = 60.0) -> Recording:
    """A constant-current discharge of ``params`` from their initial state to the stop, sampled every ``step_s``."""
    request = SimulationRequest(load=StepLoad.constant(current_a, 48 * 3600.0),
                                output_time_s=np.arange(0.0, 48 * 3600.0, step_s))
    run = get_simulator("engine").simulate(params, request)
    assert run.reached_cutoff
    return Recording(run.time_s, run.pack_voltage_v, np.full(run.time_s.size, current_a))


def plateau_recording(end_drop_v: float, end_current_a: float = 2.0) -> Recording:
    """An hour on a falling plateau (49 -> 47.5 V), its last sample ``end_drop_v`` lower still."""
    t = np.arange(0.0, 3600.0, 60.0)
    v = np.linspace(49.0, 47.5, t.size)
    v[-1] -= end_drop_v
    i = np.full(t.size, 2.0)
    i[-1] = end_current_a
    return Recording(t, v, i)


def ends_at_deepest(recordings) -> bool:
    return recording_ending_at_deepest(recordings) is not None


def test_a_recording_that_stops_while_discharging_ends_at_its_deepest_state():
    assert ends_at_deepest([plateau_recording(0.0)])
    assert ends_at_deepest([plateau_recording(0.8)])  # on its knee too


def test_a_recording_that_ends_at_rest_charging_or_recovered_does_not():
    assert not ends_at_deepest([plateau_recording(0.0, end_current_a=0.0)])
    assert not ends_at_deepest([plateau_recording(0.0, end_current_a=-3.0)])
    recovered = plateau_recording(0.0)
    recovered.voltage_v[-5:] += 0.6  # its deepest state lies before the end
    assert not ends_at_deepest([recovered])
    other = plateau_recording(0.1)
    assert recording_ending_at_deepest([recovered, other]) is other  # another recording ends at the deepest state


def test_the_weak_group_that_stopped_a_recording_is_found_again_by_replaying_it():
    params = ranger()
    rec = discharge_until_stop(with_weak_group(params, 0.85), 2.5)
    deepest = deepest_state([rec], T_K)
    assert deepest.voltage_v > params.thresholds["route_min_voltage_v"]  # the weak group stops the pack on the plateau
    inference = inferred_weak_fraction(params, rec, deepest)
    assert inference.fraction == pytest.approx(0.85, abs=3e-3)
    assert inference.stop_s <= inference.end_s  # the safe side: the model stops no later than the data
    assert inference.stop_s == pytest.approx(inference.end_s, abs=120.0)
    assert not inference.at_bound
    engine = get_simulator("engine")
    assert stop_time_s(params, 0.999, rec, engine) == float("inf")  # identical cells run past the stop


def test_fit_data_of_a_weak_pack_that_stop_on_the_plateau_give_it_its_weak_group():
    params = ranger()
    rec = discharge_until_stop(with_weak_group(params, 0.8), 3.0)
    deepest = deepest_state([rec], T_K)
    assert weak_group_evidence(params, [rec], deepest) == (rec, "")
    fitted, line = with_inferred_weak_group(params, [rec], deepest)
    assert weak_group_fraction(fitted) == pytest.approx(0.8, abs=0.01)
    assert line.startswith(f"weak series group inferred: its cells hold {weak_group_fraction(fitted):.3f} of the ")


def test_fit_data_of_identical_cells_cut_on_the_knee_above_the_threshold_get_a_group_near_one_that_stops_there():
    params = ranger()
    rec = discharge_until_stop(params, 3.0)
    keep = int(np.searchsorted(-rec.voltage_v, -46.6))  # stopped on the knee above 46.31 V
    cut = Recording(rec.time_s[:keep], rec.voltage_v[:keep], rec.current_a[:keep])
    fitted, _ = with_inferred_weak_group(params, [cut], deepest_state([cut], T_K))
    assert 0.9 < weak_group_fraction(fitted) < 1.0
    stop_s = stop_time_s(params, weak_group_fraction(fitted), cut, get_simulator("engine"))
    assert stop_s == pytest.approx(float(cut.relative_time_s[-1]), abs=120.0)


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
    assert weak_group_evidence(change(ranger()), [rec], deepest_state([rec], T_K)) == (None, reason)


def test_fit_data_trimmed_before_their_recharge_did_not_stop_where_they_end():
    from battery_predictor.fitting.problem import trim_to_discharge

    day = plateau_recording(0.0)
    t = np.concatenate([day.time_s, day.time_s[-1] + np.arange(60.0, 1260.0, 60.0)])
    v = np.concatenate([day.voltage_v, np.full(20, 50.0)])
    i = np.concatenate([day.current_a, np.full(20, -5.0)])
    trimmed = trim_to_discharge(Recording(t, v, i))
    assert trimmed.time_s[-1] == day.time_s[-1]  # the fit sees the discharge only
    assert recording_ending_at_deepest([trimmed]) is None  # ... which did not end there
    assert recording_ending_at_deepest([trim_to_discharge(day)]) is not None
    params = ranger()
    assert weak_group_evidence(params, [trimmed], deepest_state([trimmed], T_K)) == (
        None, "the fit data do not end at their deepest state under load")


def test_fit_data_below_the_packs_voltage_window_keep_no_state_and_infer_no_group():
    params = ranger()
    fitted, line = with_inferred_weak_group(params, [plateau_recording(0.0)], None)
    assert fitted is params
    assert line == "no weak series group inferred (no deepest state kept: the fit data reach below the pack's voltage window)"
