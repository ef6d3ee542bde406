"""Helpers shared by the sub-commands (loading data, JSON output)."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Sequence
from typing import Any

from battery_predictor.recording import Recording


def load_data(paths: Sequence[str], *, trim: bool = True, duplicate_times: str = "error") -> list[Recording]:
    """Load recordings (CSV or bag); trimmed to their discharge unless ``trim`` is False."""
    from battery_predictor.fitting.problem import trim_to_discharge
    from battery_predictor.io.loader import load_recording

    recs = [load_recording(p, duplicate_times=duplicate_times) for p in paths]
    return [trim_to_discharge(r) for r in recs] if trim else recs


def _clean(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def print_json(obj: dict[str, Any]) -> None:
    """Print exactly one JSON object on stdout (non-finite numbers become null)."""
    sys.stdout.write(json.dumps(_clean(obj), sort_keys=False) + "\n")
    sys.stdout.flush()


def add_data_arguments(parser) -> None:
    """``--data FILE [FILE...]`` and ``--no-trim``."""
    parser.add_argument("--data", nargs="+", required=True, metavar="FILE",
                        help="CSV (time_s, voltage_V, current_A > 0 = discharge[, temperature_C]) or rosbag2 MCAP")
    parser.add_argument("--no-trim", action="store_true",
                        help="keep samples after the minimum voltage (rests, recharge)")
    parser.add_argument("--duplicate-times", choices=("error", "keep_first", "keep_last"), default="error",
                        help="CSV rows that repeat a timestamp: reject (default) or keep one")
