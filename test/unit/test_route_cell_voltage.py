"""Issue #9's rule for the cells: a route is never accepted when the latest measured state already
contradicts the threshold, here a series group (cell) measured at or below its lower cut-off voltage.

The battery monitor keeps the lowest ``BatteryState.cell_voltage`` of each window
(``PackSnapshot.min_cell_voltage_v``); the predictor core refuses a route when it is at or below the
cell's ``Lower voltage cut-off [V]`` of the params, whatever the pack voltage says. It only ever
makes answers more conservative.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from battery_predictor.monitor.core import BatteryMonitor, MonitorConfig, monitor_windows
from battery_predictor.prediction.core import PredictorConfig, PredictorCore
from battery_predictor.profiles.ranger import longest_route

PARAMS = Path(__file__).resolve().parents[2] / "params"
T_K = 298.15
T0 = 1_704_067_200.0  # a multiple of the 5 s window


def _monitor() -> BatteryMonitor:
    return BatteryMonitor(MonitorConfig(min_voltage_v=37.5, max_voltage_v=58.0, max_discharge_current_a=30.0,
                                        max_charge_current_a=15.0, window_s=5.0))


# --- monitor -----------------------------------------------------------------


def test_a_window_keeps_its_lowest_measured_cell_voltage():
    mon = _monitor()
    cells = [[3.90, 3.85, math.nan], [3.88, 3.80, 3.95], [math.nan] * 3, []]
    for k, c in enumerate(cells):
        mon.add_sample(T0 + k, 50.0, 3.0, math.nan, T0 + k, c)
    (snap,) = mon.add_sample(T0 + 5.0, 50.0, 3.0, math.nan, T0 + 5.0, [3.7]).snapshots
    assert snap.min_cell_voltage_v == pytest.approx(3.80)
    assert snap.samples_used == 4 and snap.samples_rejected == 0


def test_without_cell_voltages_the_window_has_none_and_stale_states_have_none():
    mon = _monitor()
    for k in range(5):
        mon.add_sample(T0 + k, 50.0, 3.0, math.nan, T0 + k)
    (snap,) = mon.tick(T0 + 6.5)
    assert math.isnan(snap.min_cell_voltage_v)
    mon2 = _monitor()
    mon2.add_sample(T0, 50.0, 3.0, math.nan, T0, [3.6])
    stale = [s for s in mon2.tick(T0 + 6.5) + mon2.tick(T0 + 30.0) if s.stale]
    assert stale and math.isnan(stale[0].min_cell_voltage_v)


@pytest.mark.parametrize("bad, reason", [([3.8, 0.0], "out_of_range"), ([3.8, -1.0], "out_of_range"),
                                         ([3800.0], "out_of_range"), ([3.8, math.inf], "nan")])
def test_invalid_cell_voltages_drop_only_the_cells_and_are_counted(bad, reason):
    mon = _monitor()
    verdict = mon.add_sample(T0, 50.0, 3.0, math.nan, T0, bad)
    assert verdict.accepted  # the pack's voltage and current are kept
    assert mon.rejected["cell_voltage"] == {reason: 1}
    mon.add_sample(T0 + 1.0, 50.0, 3.0, math.nan, T0 + 1.0, [3.9])
    (snap,) = mon.tick(T0 + 6.5)
    assert snap.min_cell_voltage_v == 3.9 and snap.voltage_v == 50.0


def test_offline_windows_carry_the_recordings_group_voltages():
    t = np.arange(0.0, 20.0, 1.0)
    groups = np.column_stack([np.linspace(3.9, 3.5, t.size), np.full(t.size, 3.95)])
    groups[3, 0] = np.nan
    snaps = monitor_windows(t, np.full(t.size, 50.0), np.full(t.size, 3.0), cell_voltage_v=groups)
    assert [s.min_cell_voltage_v for s in snaps] == pytest.approx([np.nanmin(groups[k:k + 5]) for k in range(0, 20, 5)])


# --- predictor ---------------------------------------------------------------


@pytest.fixture(scope="module")
def core() -> PredictorCore:
    return PredictorCore(PredictorConfig(params_file=str(PARAMS / "ranger_mini.yaml")))  # cell cut-off 3.0 V


def _decide(core: PredictorCore, stamp_s: float, min_cell_v: float):
    for k in range(6):
        core.update_state(stamp_s + 5.0 * k, 49.8, 3.0, T_K, min_cell_voltage_v=min_cell_v)
    return core.can_accept_route(longest_route(80).sections, stamp_s + 26.0)


def test_a_cell_at_or_below_its_cut_off_refuses_a_route_the_pack_voltage_would_accept(core):
    assert _decide(core, 0.0, math.nan).accepted  # a charged pack, no cell voltages: accepted as before
    assert _decide(core, 100.0, 3.85).accepted  # cells well above the cut-off: same answer
    for stamp, v_cell in ((200.0, 3.0), (300.0, 2.71)):
        decision = _decide(core, stamp, v_cell)
        assert not decision.accepted
        assert f"measured minimum cell voltage {v_cell:.3f} V" in decision.reason
        assert "lower cut-off 3.00 V" in decision.reason
    assert _decide(core, 400.0, 3.01).accepted  # the latest state decides: the cell has recovered


def test_the_cell_check_only_makes_answers_more_conservative(core):
    """Over random pack states, an answer with a measured cell voltage is never an acceptance where the same
    state without one is refused."""
    rng = np.random.default_rng(3)
    stamp = 1000.0
    outcomes = set()
    for _ in range(8):
        v_pack, v_cell = float(rng.uniform(45.0, 50.5)), float(rng.uniform(2.8, 3.6))
        base = without = None
        for cells in (math.nan, v_cell):
            for k in range(6):
                core.update_state(stamp + 5.0 * k, v_pack, 3.0, T_K, min_cell_voltage_v=cells)
            decision = core.can_accept_route(longest_route(80).sections, stamp + 26.0)
            stamp += 100.0
            if math.isnan(cells):
                without = decision.accepted
            else:
                base = decision.accepted
        assert not (base and not without), (v_pack, v_cell)
        if v_cell <= 3.0:
            assert not base
        outcomes.add((without, base))
    assert {(True, True), (True, False)} <= outcomes  # the draws reach both: accepted, and refused by the cell
