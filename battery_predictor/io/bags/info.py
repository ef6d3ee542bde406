"""``battery-predictor bag info``: a bag's topics, time span, metadata and battery summary."""

from __future__ import annotations

import os
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from battery_predictor.conventions import kelvin_to_celsius
from battery_predictor.errors import BagError, InputDataError
from battery_predictor.io.bags.reader import read_recording_bag
from battery_predictor.io.bags.storage import decode_custom, list_topics, open_reader, read_custom_data, resolve
from battery_predictor.io.bags.topics import select_topic


def _iso(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, tz=UTC).isoformat().replace("+00:00", "Z")


def bag_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Describe a bag: topics, time span, metadata and a battery summary.

    Returns
    -------
    dict
        ``path``, ``storage`` (the opened directory or file), ``topics``
        (list of ``{"name", "type", "count"}``), ``message_count``,
        ``start``/``end`` (ISO 8601 UTC, or None), ``start_ns``/``end_ns``,
        ``duration_s``, ``metadata`` (decoded custom_data, reserved keys
        removed), ``style`` and ``battery_topic`` (None when there is no
        supported topic), ``summary`` (``samples``, ``duration_s``,
        ``charge_drawn_ah``, ``min_voltage_v``, ``max_voltage_v``,
        ``mean_current_a`` (time-weighted, = charge / duration), ``min/max
        temperature_c`` or None) and ``summary_error`` (why there is no
        summary, or None).

    Raises
    ------
    BagError
        Missing path, not a bag, corrupt or truncated storage.
    """
    src = Path(path)
    p = resolve(src)
    custom = read_custom_data(p)
    with open_reader(p) as reader:
        topics = list_topics(reader)
        count = int(reader.message_count)
        start_ns = int(reader.start_time) if count else None
        end_ns = int(reader.end_time) - 1 if count else None  # rosbags' end_time is one past the last stamp
    info: dict[str, Any] = {
        "path": str(src),
        "storage": str(p),
        "topics": [{"name": n, "type": t, "count": c} for n, (t, c) in topics.items()],
        "message_count": count,
        "start_ns": start_ns,
        "end_ns": end_ns,
        "start": _iso(start_ns) if start_ns is not None else None,
        "end": _iso(end_ns) if end_ns is not None else None,
        "duration_s": (end_ns - start_ns) / 1e9 if start_ns is not None and end_ns is not None else 0.0,
        "metadata": decode_custom(custom),
        "style": None,
        "battery_topic": None,
        "summary": None,
        "summary_error": None,
    }
    try:
        style, name = select_topic(src, topics, None)
    except BagError as exc:
        info["summary_error"] = str(exc)
        return info
    info["style"] = style
    info["battery_topic"] = name
    try:
        rec = read_recording_bag(src, topic=name, drop_nan=True)
    except InputDataError as exc:
        info["summary_error"] = str(exc)
        return info
    duration = rec.duration_s
    charge = rec.charge_drawn_ah()
    temp_c = None if rec.temperature_k is None else np.asarray(kelvin_to_celsius(rec.temperature_k))
    info["summary"] = {
        "samples": len(rec.time_s),
        "duration_s": duration,
        "charge_drawn_ah": charge,
        "min_voltage_v": float(np.min(rec.voltage_v)),
        "max_voltage_v": float(np.max(rec.voltage_v)),
        "mean_current_a": charge * 3600.0 / duration if duration > 0 else float(np.mean(rec.current_a)),
        "min_temperature_c": None if temp_c is None else float(np.min(temp_c)),
        "max_temperature_c": None if temp_c is None else float(np.max(temp_c)),
    }
    return info
