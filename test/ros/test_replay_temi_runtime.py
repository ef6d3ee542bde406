"""Remaining runtime published by the real nodes while the bundled information-robot bags are replayed.

Each ``bags/temi_dynamic_pack<n>`` bag (relay topics, a stochastic usage profile
on one of four emulated physical packs) carries the true time at which its
voltage reached 13.30 V. The bag is replayed into ``battery_monitor`` and
``predictor`` (bundled node params and pack params ``params/temi.yaml``,
``use_sim_time``, lock step, so nothing depends on the machine's speed) up to
300 min, with a runtime update every 5 min of bag time; the published
``/remaining_runtime`` at 30, 60, ..., 300 min is compared with the truth at the
stamp of the pack state it is based on (the end of the 5 s window before each
checkpoint).

Tolerances (stated, from measurement, see MEASURED below): every checkpoint
within ``MAX_ABS_ERROR_MIN`` of the truth, the mean absolute error of each bag
within ``MAX_MAE_MIN`` and over all four bags within ``MAX_OVERALL_MAE_MIN``,
and the predictions falling with time at 1 min per min within ``SLOPE_TOLERANCE``
(a frozen or mis-scaled prediction fails that however close it starts). The
seed paper reports MAE 14.92 min / MAPE 18.9 % on the real robot; this is
worse, see MEASURED.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from rclpy.context import Context

from battery_predictor.nodes.replay_session import ReplaySession
from battery_predictor.replay import (
    DEFAULT_CHECKPOINTS_MIN,
    compare_at_checkpoints,
    error_summary,
    read_replay_stream,
    runtime_truth,
)

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / "bags"
TEMI_BAGS = [f"temi_dynamic_pack{n}" for n in (1, 2, 3, 4)]
RUNTIME_PERIOD_S = 300.0  # an update every 5 min of bag time (production 10 s: within 8 min at 30-60 min, 1 min later)

#: MEASURED (shipped params/temi.yaml, the prediction core of this commit, these bags), error = predicted -
#: true at the checkpoints: pack 1 -32..+45 min (MAE 30.1), pack 2 -23..+5 (MAE 7.1), pack 3 +38..+72
#: (MAE 56.6), pack 4 +42..+72 (MAE 58.1); all four MAE 38.0 min; slope of the predictions -0.84..-1.08.
#: Why worse than the paper: the predictor simulates the cycle's *average* current down to 13.30 V (the
#: paper's 5.1.5 strategy) while the bags' truth is the first 5 s window at 13.30 V, which falls on a
#: navigation current peak (bags/README.md), so late predictions run long by ~40 min; and packs 3 and 4
#: differ from the (unfitted, paper Table 3) params. Tighten these when the model accounts for both.
MAX_ABS_ERROR_MIN = 80.0
MAX_MAE_MIN = 60.0
MAX_OVERALL_MAE_MIN = 45.0
#: The emulated bags draw the usage profile's currents as they are (constant-current steps, see
#: profiles/temi.py), so they are replayed with the paper's constant-current load ahead; the default
#: constant-power load is measured on them in docs/runtime_real_data (early, never late).
LOAD_MODEL = "current"
SLOPE_TOLERANCE = 0.3

_results: dict[str, list] = {}


def _checkpoints(name: str, context: Context) -> list:
    """Replay one bag (once per test session) and return its checkpoints."""
    if name in _results:
        return _results[name]
    path = BAGS / name
    assert path.exists(), f"bundled bag {path} missing (make bags)"
    stream = read_replay_stream(path)
    truth = runtime_truth(stream.metadata)
    assert truth is not None and truth.stop_voltage_v == pytest.approx(13.30)
    last_checkpoint_s = 60.0 * max(DEFAULT_CHECKPOINTS_MIN)
    assert truth.runtime_s > last_checkpoint_s
    with ReplaySession(stream, context=context, params_file=str(REPO / "params/ros/temi_nodes.yaml"),
                       predictor_overrides={"runtime_period_s": RUNTIME_PERIOD_S, "load_model": LOAD_MODEL},
                       monitor_overrides={"diagnostics_period_s": 60.0}, rate=0) as session:
        session.play_until(stream.ros_time_ns(last_checkpoint_s))  # only what the checkpoints need
        points = session.runtime_points()
        rejected = session.monitor.monitor.rejected_total
    assert rejected == 0
    # an update every 5 min: the first before any pack state (invalid, NO_INPUT), then all valid
    assert len(points) == 1 + round(last_checkpoint_s / RUNTIME_PERIOD_S)
    assert not points[0].valid and points[0].status == 2
    assert all(p.valid and p.status == 0 and math.isfinite(p.remaining_s) for p in points[1:])
    checkpoints = compare_at_checkpoints(points, truth, max_age_s=10.0)
    assert [c.checkpoint_min for c in checkpoints] == list(DEFAULT_CHECKPOINTS_MIN)
    _results[name] = checkpoints
    return checkpoints


def _table(checkpoints) -> str:
    return "\n".join(f"  {c.checkpoint_min:>4.0f} min: predicted {c.predicted_min:6.1f}, true {c.true_min:6.1f}, "
                     f"error {c.error_min:+6.1f} min" for c in checkpoints)


@pytest.mark.parametrize("name", TEMI_BAGS)
def test_remaining_runtime_at_checkpoints_is_within_tolerance_of_the_truth(name: str, ros_context: Context) -> None:
    checkpoints = _checkpoints(name, ros_context)
    table = _table(checkpoints)
    summary = error_summary(checkpoints)
    assert all(abs(c.error_min) <= MAX_ABS_ERROR_MIN for c in checkpoints), f"{name}:\n{table}"
    assert summary["mae_min"] <= MAX_MAE_MIN, f"{name}: MAE {summary['mae_min']:.1f} min\n{table}"
    # the prediction follows the clock: -1 min per min (fit over 60..300 min, after the first average settles)
    later = [c for c in checkpoints if c.checkpoint_min >= 60]
    slope = np.polyfit([c.time_s / 60 for c in later], [c.predicted_min for c in later], 1)[0]
    assert abs(slope + 1.0) <= SLOPE_TOLERANCE, f"{name}: slope {slope:.2f} min/min\n{table}"


def test_mean_absolute_error_over_all_bags(ros_context: Context) -> None:
    errors = [c.error_min for name in TEMI_BAGS for c in _checkpoints(name, ros_context)]
    mae = float(np.mean(np.abs(errors)))
    assert mae <= MAX_OVERALL_MAE_MIN, f"MAE over {len(TEMI_BAGS)} bags {mae:.1f} min"


def test_published_intervals_hold_the_truth_and_are_not_decorative(ros_context: Context) -> None:
    """``remaining_p10_s`` <= ``remaining_s`` <= ``remaining_p90_s``; inside P10..P90 at >= 70 %, band < 2.5x.

    The shipped params carry no calibration (the default structural spread, docs/uncertainty). These
    40 checkpoints (30..300 min of 8 h discharges, ten per bag, strongly correlated) cannot judge the
    80 +- 10 % target itself: that is measured over whole discharges with ``evaluate-runtime``
    (test/integration/test_runtime_real_data.py, docs/uncertainty). MEASURED: 100 % inside, median
    P90 / P10 1.91 (the uncalibrated structural spread is wide on purpose).
    """
    checkpoints = [c for name in TEMI_BAGS for c in _checkpoints(name, ros_context)]
    assert all(c.p10_min <= c.predicted_min <= c.p90_min for c in checkpoints)
    inside = np.mean([c.p10_min <= c.true_min <= c.p90_min for c in checkpoints])
    ratio = np.median([c.p90_min / c.p10_min for c in checkpoints])
    table = "\n".join(f"  {c.p10_min:6.1f} {c.predicted_min:6.1f} {c.p90_min:6.1f} true {c.true_min:6.1f}"
                      for c in checkpoints)
    assert inside >= 0.7, f"truth inside P10..P90 at {inside:.0%} of {len(checkpoints)} checkpoints\n{table}"
    assert ratio < 2.5, f"median P90 / P10 {ratio:.2f}\n{table}"
