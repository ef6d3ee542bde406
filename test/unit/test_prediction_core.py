"""Prediction core (no ROS): SOC calibration, remaining runtime, route decisions, bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.params import load_params
from battery_predictor.prediction.calibration import calibrate_on_history, calibrate_soc
from battery_predictor.prediction.cell_runner import PackRunner
from battery_predictor.prediction.core import (
    STATUS_CHARGING,
    STATUS_MODEL_NOT_FITTED,
    STATUS_NO_INPUT,
    STATUS_OK,
    STATUS_STALE_INPUT,
    PredictorConfig,
    PredictorCore,
)
from battery_predictor.prediction.route import evaluate_route
from battery_predictor.prediction.runtime import predict_remaining_runtime, time_to_voltage_s
from battery_predictor.profiles.ranger import RouteSection, longest_route
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator

PARAMS = Path(__file__).resolve().parents[2] / "params"


@pytest.fixture(scope="module")
def temi_runner():
    return PackRunner(load_params(PARAMS / "temi.yaml"))


@pytest.fixture(scope="module")
def ranger_core():
    return PredictorCore(PredictorConfig(params_file=str(PARAMS / "ranger_mini.yaml")))


@pytest.mark.parametrize("soc", [0.15, 0.5, 0.9])
def test_calibration_recovers_the_soc_that_produced_a_voltage(temi_runner, soc):
    v = temi_runner.settled_voltage_v(soc, 2.0, 298.15)
    cal = calibrate_soc(temi_runner, v, 2.0, 298.15)
    assert cal.soc == pytest.approx(soc, abs=2e-3)
    assert abs(cal.residual_v) < 1e-3 and cal.clipped == ""


def test_calibration_clips_outside_the_model_range(temi_runner):
    assert calibrate_soc(temi_runner, 25.0, 1.0, 298.15).clipped == "above_full"
    assert calibrate_soc(temi_runner, 9.0, 1.0, 298.15).clipped == "below_empty"


def test_runner_agrees_with_fast_simulator(temi_runner):
    params = temi_runner.params
    segs = [(600.0, 3.0), (300.0, 6.0), (900.0, 1.5)]
    run = temi_runner.run(0.7, segs, 298.15)
    ref = get_simulator("fast").simulate(params, SimulationRequest(
        load=StepLoad.from_durations([d for d, _ in segs], [i for _, i in segs]), initial_soc=0.7,
        output_time_s=np.array([599.0, 899.0, 1799.0])))
    np.testing.assert_allclose(run.pack_voltage_v[run.segment_end_index], ref.pack_voltage_v, atol=0.01)


def test_runtime_prediction_matches_a_simulated_discharge(temi_runner):
    # truth: constant 2.5 A from SOC 0.6 until 13.30 V, simulated by the fast simulator
    params = temi_runner.params
    res = get_simulator("fast").simulate(params, SimulationRequest(load=StepLoad.constant(2.5, 10 * 3600.0),
                                                                   initial_soc=0.6))
    t_true = res.time_to_pack_voltage_s(13.30)
    t_now = 3600.0
    t_hist = np.arange(0.0, t_now + 1.0, 5.0)
    v_hist = np.interp(t_hist + 0.002, res.time_s, res.pack_voltage_v)
    cal = calibrate_on_history(temi_runner, t_hist, v_hist, np.full(t_hist.size, 2.5), 298.15)
    pred = predict_remaining_runtime(temi_runner, float(v_hist[-1]), 2.5, 298.15, 2.5, 13.30, calibration=cal)
    assert pred.remaining_s == pytest.approx(t_true - t_now, rel=0.02)
    assert pred.limited_by == "pack_cutoff"


def test_heavier_payload_lowers_the_predicted_voltage(ranger_core):
    runner = ranger_core.runner
    volts = [evaluate_route(runner, 0.4, longest_route(kg).sections, 298.15, threshold_v=46.31,
                            standstill_current_a=1.7).predicted_voltage_v for kg in (20, 40, 60, 80)]
    assert all(np.diff(volts) < 0)


def test_route_rejected_near_empty_and_accepted_when_full(ranger_core):
    runner = ranger_core.runner
    full = evaluate_route(runner, 0.95, longest_route(80).sections, 298.15, threshold_v=46.31,
                          standstill_current_a=1.7)
    four_times = longest_route(80).sections * 4
    empty = evaluate_route(runner, 0.01, four_times, 298.15, threshold_v=46.31, standstill_current_a=1.7)
    assert full.accepted and full.margin_v > 0 and "accepted" in full.reason
    assert not empty.accepted and empty.reason
    assert full.route_duration_s == pytest.approx(1900.0)


def test_route_longer_than_any_battery_is_rejected_with_reason(ranger_core):
    huge = [RouteSection("far", 1.0e5, "uphill", 80.0)]
    d = evaluate_route(ranger_core.runner, 1.0, huge, 298.15, threshold_v=46.31, standstill_current_a=1.7)
    assert not d.accepted and "longer than any battery" in d.reason


def test_core_without_state_or_with_stale_state_rejects_and_invalidates(ranger_core):
    fresh = PredictorCore(PredictorConfig(params_file=str(PARAMS / "ranger_mini.yaml")))
    rt = fresh.remaining_runtime(100.0)
    assert not rt.valid and rt.status == STATUS_NO_INPUT
    d = fresh.can_accept_route(longest_route(20).sections, 100.0)
    assert not d.accepted and "no pack state" in d.reason
    fresh.update_state(100.0, 50.0, 1.7, 298.15)
    assert fresh.can_accept_route(longest_route(20).sections, 101.0).accepted
    stale = fresh.can_accept_route(longest_route(20).sections, 100.0 + 31.0)
    assert not stale.accepted and "stale" in stale.reason
    assert fresh.remaining_runtime(131.0).status == STATUS_STALE_INPUT


def test_core_with_broken_params_reports_model_not_fitted(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\n")
    core = PredictorCore(PredictorConfig(params_file=str(bad)))
    core.update_state(1.0, 15.0, 2.0, 298.15)
    rt = core.remaining_runtime(1.0)
    assert rt.status == STATUS_MODEL_NOT_FITTED and not rt.valid and "bad.yaml" in rt.reason
    assert not core.can_accept_route(longest_route(20).sections, 1.0).accepted


def test_core_runtime_uses_the_cycle_average_through_blips_and_restarts_after_a_charging_session():
    core = PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml")))
    for k in range(10):
        core.update_state(10.0 * k, 15.5, 2.0 if k % 2 else 4.0, 298.15)
    rt = core.remaining_runtime(95.0)
    assert rt.status == STATUS_OK and rt.valid
    assert rt.assumed_current_a == pytest.approx(3.0, abs=0.25)
    core.update_state(100.0, 15.6, -2.0, 298.15)  # a 10 s charging blip stays in the cycle
    core.update_state(110.0, 15.5, 3.0, 298.15)
    blip = core.remaining_runtime(111.0)
    assert blip.valid and blip.assumed_current_a == pytest.approx((9 * 10 * 3.0 + 10 * 3.0 - 10 * 2.0) / 110, rel=0.05)
    for k in range(32):  # 320 s at -5 A: a charging session ends the cycle
        core.update_state(120.0 + 10.0 * k, 16.0, -5.0, 298.15)
    charging = core.remaining_runtime(441.0)
    assert (charging.valid, charging.status) == (False, STATUS_CHARGING) and "charging at 5.00 A" in charging.reason
    core.update_state(450.0, 15.9, 1.0, 298.15)
    core.update_state(460.0, 15.9, 1.0, 298.15)
    after = core.remaining_runtime(461.0)
    assert after.valid and after.assumed_current_a == pytest.approx(1.0)
    assert math.isfinite(after.remaining_s)


def test_history_calibration_carries_polarisation_and_beats_single_sample(temi_runner):
    segs = [(120.0, 9.0), (60.0, 1.0), (180.0, 12.0), (60.0, 2.0), (180.0, 10.0)]
    run = temi_runner.run(0.55, segs, 298.15)
    true_soc = temi_runner.soc_of(run.final_state)
    t = np.arange(0.0, run.time_s[-1], 5.0)
    v = np.interp(t, run.time_s, run.pack_voltage_v)
    i = np.interp(t, run.time_s, run.pack_current_a)
    hist = calibrate_on_history(temi_runner, t, v, i, 298.15)
    single = calibrate_soc(temi_runner, float(v[-1]), float(i[-1]), 298.15)
    assert hist.state is not None
    assert abs(hist.soc - true_soc) < 0.005
    assert abs(hist.soc - true_soc) < abs(single.soc - true_soc)


def test_soc_bounds_extend_beyond_0_and_1_within_stoichiometry(temi_runner):
    lo, hi = temi_runner.soc_bounds
    assert lo < 0.0 < 1.0 <= hi
    x0, x100, y100, y0 = temi_runner.stoichiometry_window
    for soc in (lo, hi):
        c_n, c_p = temi_runner.concentrations(soc)
        assert 0 < c_n and 0 < c_p


def test_tiny_and_huge_sections_get_a_reason_not_an_exception(ranger_core):
    runner = ranger_core.runner
    tiny = [RouteSection("tiny", 1e-9, "flat", 20.0)]
    d = evaluate_route(runner, 0.5, tiny, 298.15, threshold_v=46.31, standstill_current_a=1.7)
    assert not d.accepted and "shorter than" in d.reason
    mixed = [RouteSection("tiny", 5e-324, "flat", 20.0), *longest_route(20).sections]
    assert evaluate_route(runner, 0.5, mixed, 298.15, threshold_v=46.31, standstill_current_a=1.7).accepted
    huge = [RouteSection("huge", 1e308, "flat", 20.0)]
    d = evaluate_route(runner, 0.5, huge, 298.15, threshold_v=46.31, standstill_current_a=1.7)
    assert not d.accepted and len(d.reason) < 200


def test_peak_load_option_shortens_the_predicted_runtime():
    base = dict(params_file=str(PARAMS / "temi.yaml"))
    runs = {}
    for q in (0.0, 0.95):
        core = PredictorCore(PredictorConfig(**base, peak_current_quantile=q))
        for k in range(60):
            core.update_state(10.0 * k, 15.2, 4.0 if k % 10 == 0 else 1.5, 298.15)
        runs[q] = core.remaining_runtime(595.0)
    assert runs[0.95].remaining_s < runs[0.0].remaining_s


def test_peak_runtime_ends_where_a_peak_from_the_average_trajectory_meets_the_cutoff(temi_runner):
    cal = calibrate_soc(temi_runner, temi_runner.settled_voltage_v(0.5, 2.0, 298.15), 2.0, 298.15)
    avg = predict_remaining_runtime(temi_runner, 15.0, 2.0, 298.15, 2.0, 13.30, calibration=cal)
    peak = predict_remaining_runtime(temi_runner, 15.0, 2.0, 298.15, 2.0, 13.30, calibration=cal,
                                     peak_current_a=5.0)
    assert peak.limited_by == "peak_cutoff" and avg.limited_by == "pack_cutoff"
    assert peak.remaining_s < avg.remaining_s - 600.0  # a 3 A heavier peak costs well over 10 min here

    def peak_voltage_v(t_s):  # independent check: 5 s at 5 A after t_s at 2 A, straight from the runner
        run = temi_runner.run(cal.start, [(t_s, 2.0), (5.0, 5.0)], 298.15)
        return float(np.mean(run.pack_voltage_v[run.time_s >= run.time_s[-1] - 5.0 + 1e-9]))

    assert peak_voltage_v(peak.remaining_s - 120.0) > 13.30 > peak_voltage_v(peak.remaining_s + 120.0)


def test_peak_no_higher_than_the_average_keeps_the_papers_runtime(temi_runner):
    cal = calibrate_soc(temi_runner, temi_runner.settled_voltage_v(0.5, 2.0, 298.15), 2.0, 298.15)
    avg = predict_remaining_runtime(temi_runner, 15.0, 2.0, 298.15, 2.0, 13.30, calibration=cal)
    low = predict_remaining_runtime(temi_runner, 15.0, 2.0, 298.15, 2.0, 13.30, calibration=cal, peak_current_a=1.5)
    assert low.remaining_s == avg.remaining_s and low.limited_by == "pack_cutoff"


class _KneePack:
    """A pack whose voltage steepens towards empty (4 V - (Ah drawn)^4 - 0.05 Ohm I), sampled every second."""

    def run(self, start, segments, temperature_k):
        from battery_predictor.simulation.base import SegmentRun

        t, q, times, volts, cur = 0.0, 0.0, [0.0], [4.0], [segments[0][1]]
        for duration, current in segments:
            for dt in np.diff(np.append(np.arange(0.0, duration, 1.0), duration)):
                t, q = t + dt, q + current * dt / 3600.0
                times.append(t)
                volts.append(4.0 - q ** 4 - 0.05 * current)
                cur.append(current)
        v = np.asarray(volts)
        return SegmentRun(np.asarray(times), v, np.asarray(cur), [], bool(np.any(v <= 3.0)), t, None)


def test_a_peak_equal_to_the_average_that_holds_at_the_sampled_average_crossing_ends_there():
    from battery_predictor.prediction.runtime import LoadPath, peak_crossing_s
    from battery_predictor.simulation.base import SegmentRun

    pack = _KneePack()
    fine = pack.run(0.0, [(4000.0, 1.0)], 298.15)
    coarse = np.arange(0, fine.time_s.size, 300)  # the average run's report samples: the knee falls between two
    average_run = SegmentRun(fine.time_s[coarse], fine.pack_voltage_v[coarse], fine.pack_current_a[coarse], [],
                             True, float(fine.time_s[-1]), None)
    t_avg = time_to_voltage_s(average_run.time_s, average_run.pack_voltage_v, 3.0)
    crossing = peak_crossing_s(pack, 0.0, LoadPath.constant(1.0, 4000.0), 1.0, 298.15, 3.0, average_run)
    assert crossing == pytest.approx(t_avg)


def test_constant_power_ahead_raises_the_current_and_shortens_the_runtime(temi_runner):
    from battery_predictor.prediction.runtime import demand_run

    cal = calibrate_soc(temi_runner, 15.0, 2.0, 298.15)
    current = predict_remaining_runtime(temi_runner, 15.0, 2.0, 298.15, 2.0, 13.30, calibration=cal)
    power = predict_remaining_runtime(temi_runner, 15.0, 2.0, 298.15, 2.0, 13.30, calibration=cal,
                                      average_power_w=30.0)
    assert power.remaining_s < current.remaining_s
    run, path = demand_run(temi_runner, cal.start, 2.0, 30.0, 1.0, current.remaining_s, 298.15, 15.0, 13.30)
    ahead = path.current_a[: int(power.remaining_s // path.step_s)]
    assert ahead[0] == pytest.approx(30.0 / 15.0, rel=0.05) and np.all(np.diff(ahead) > -1e-3)
    v = np.interp((np.arange(ahead.size) + 0.5) * path.step_s, run.time_s, run.pack_voltage_v)
    assert np.allclose(ahead * v, 30.0, rtol=0.01)  # the pack delivers the power at every step


def test_core_default_load_model_is_auto_and_current_is_the_papers(temi_runner):
    assert PredictorConfig(params_file="x").load_model == "auto"
    with pytest.raises(ValueError, match="load_model"):
        PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml"), load_model="torque"))


def _undecided_reason(params_path: Path) -> str:
    """The runtime reason after ten minutes of a varying load: too short for the windows to tell current from power."""
    core = PredictorCore(PredictorConfig(params_file=str(params_path), peak_current_quantile=0.0))
    rng = np.random.default_rng(3)
    for k in range(120):
        current_a = float(rng.choice([1.5, 2.0, 4.0]))
        core.update_state(5.0 * k, 15.6 - 0.1 * current_a, current_a, 298.15)
    answer = core.remaining_runtime(5.0 * 119)
    assert answer.valid, answer.reason
    return answer.reason


def test_an_undecided_load_follows_the_params_prior_constant_current_for_the_temi(tmp_path):
    # temi.yaml: operating.load_prior_power_fraction 0, its usage model's constant-current states
    assert PredictorCore(PredictorConfig(params_file=str(PARAMS / "temi.yaml"))).load_kind_prior == 0.0
    assert " W (now " not in _undecided_reason(PARAMS / "temi.yaml")
    text = (PARAMS / "temi.yaml").read_text().replace("load_prior_power_fraction: 0.0", "load_prior_power_fraction: 1.0")
    power = tmp_path / "temi_power.yaml"
    power.write_text(text)
    assert " W (now " in _undecided_reason(power)


def test_without_a_params_prior_an_undecided_load_is_a_constant_power():
    assert PredictorCore(PredictorConfig(params_file=str(PARAMS / "panasonic_18650pf.yaml"))).load_kind_prior == 1.0


def test_a_load_prior_outside_zero_to_one_is_refused(tmp_path):
    from battery_predictor.errors import ParamsError

    bad = tmp_path / "bad.yaml"
    bad.write_text((PARAMS / "temi.yaml").read_text().replace("load_prior_power_fraction: 0.0",
                                                              "load_prior_power_fraction: 1.5"))
    with pytest.raises(ParamsError, match="load_prior_power_fraction"):
        load_params(bad)
