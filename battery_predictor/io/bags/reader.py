"""Reading a battery recording from a bag: decoding, merging the relay topics, the shared checks."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from battery_predictor.conventions import battery_state_current_to_internal
from battery_predictor.errors import BagError, InputDataError, option_hint
from battery_predictor.io.bags.schema import KEY_BASE_S, KEY_ORIGIN_NS, RELAY_SUFFIXES
from battery_predictor.io.bags.storage import (
    decode_custom,
    list_topics,
    open_reader,
    read_custom_data,
    read_messages,
    resolve,
)
from battery_predictor.io.bags.topics import select_topic
from battery_predictor.io.validation import check_group_voltages, check_samples, nearest_index
from battery_predictor.recording import Recording

_RELAY_MIN_PAIR_TOLERANCE_S = 0.5


def _stamp_ns(log_ns: int, header: Any) -> int:
    """``header.stamp`` in ns (a deserialised ``std_msgs/Header``, whose class rosbags makes at run time), else ``log_ns``."""
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns > 0 else log_ns


def _sorted_unique(ns: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], int]:
    """Sort by time (stable) and keep the last sample of each repeated stamp."""
    order = np.argsort(ns, kind="stable")
    ns = ns[order]
    arrays_sorted = [a[order] for a in arrays]
    keep = np.append(np.diff(ns) != 0, True)
    return ns[keep], [a[keep] for a in arrays_sorted], int((~keep).sum())


def read_recording_bag(
    path: str | os.PathLike[str],
    *,
    topic: str | None = None,
    drop_nan: bool = False,
    expect_discharge: bool = False,
) -> Recording:
    """Read a battery recording from a rosbag2 directory or a single ``.mcap`` file.

    Parameters
    ----------
    path : str or os.PathLike
        Bag directory (with ``metadata.yaml``) or ``.mcap`` file.
    topic : str, optional
        A ``BatteryState`` topic, a relay prefix (``/battery``) or one of the
        relay topics. Default: auto-detect (a single BatteryState topic,
        preferring ``/battery_state``; else a single relay group, preferring
        ``/battery``).
    drop_nan : bool
        Drop samples with a NaN/inf voltage or current or a voltage <= 0 V and
        fill temperature gaps from the nearest sample, instead of raising.
    expect_discharge : bool
        Run the sign-convention check of
        :func:`battery_predictor.io.validation.check_current_sign` (off by default:
        robot recordings may include docking/charging).

    Returns
    -------
    Recording
        ``source`` is the path; ``metadata`` is the decoded ``custom_data``
        (reserved ``battery_predictor.*`` keys removed), plus
        ``dropped_duplicate_stamps`` / ``dropped_nan_samples`` /
        ``filled_temperature_samples`` / ``relay_unpaired_samples`` when non-zero.
        Messages with the same stamp keep the last one.
    """
    src = Path(path)
    p = resolve(src)
    custom = read_custom_data(p)
    with open_reader(p) as reader:
        topics = list_topics(reader)
        style, name = select_topic(src, topics, topic)
        wanted = {name} if style == "battery_state" else {name + s for s in RELAY_SUFFIXES.values() if name + s in topics}
        got = read_messages(src, reader, wanted, custom)
    return recording_from_messages(str(src), style, name, got, metadata=decode_custom(custom),
                                   time_origin=time_origin(custom), drop_nan=drop_nan,
                                   expect_discharge=expect_discharge)


def time_origin(custom: dict[str, str]) -> tuple[int, float] | None:
    """The bag's time origin (ROS time in ns, recording time in s) from its custom data; None without one."""
    try:
        return int(custom[KEY_ORIGIN_NS]), float(custom[KEY_BASE_S])
    except (KeyError, ValueError):
        return None


def recording_from_messages(source: str, style: str, name: str, got: Mapping[str, list[tuple[int, Any]]], *,
                            metadata: dict[str, Any], time_origin: tuple[int, float] | None, drop_nan: bool = False,
                            expect_discharge: bool = False) -> Recording:
    """A recording from a bag's deserialised battery messages (:func:`read_recording_bag` after reading).

    ``got`` maps each topic (the BatteryState topic ``name``, or the relay topics of the prefix ``name``)
    to its ``(log_time_ns, message)`` pairs; ``time_origin`` is :func:`time_origin` of the bag; ``metadata``
    its decoded custom data.
    """
    group_v: np.ndarray | None = None
    if style == "battery_state":
        ns, v, i, temp_c, group_v, extra = _battery_states(source, name, got.get(name, []))
        where = name
    else:
        ns, v, i, temp_c, extra = _merge_relay(source, name, got)
        where = name + "/*"
    meta = dict(metadata)
    extra_meta = {k: val for k, val in extra.items() if val}

    bad = ~(np.isfinite(v) & np.isfinite(i)) | (v <= 0)
    if bad.any():
        if not drop_nan:
            k = int(np.argmax(bad))
            raise InputDataError(
                f"{source}: {where}: sample {k} (stamp {int(ns[k])} ns) has an invalid voltage/current "
                f"({v[k]!r} V, {i[k]!r} A: NaN, inf or voltage <= 0); {int(bad.sum())} such sample(s)"
                + option_hint("drop_nan", True, "to drop them")
            )
        extra_meta["dropped_nan_samples"] = int(bad.sum())
        ns, v, i, temp_c = ns[~bad], v[~bad], i[~bad], temp_c[~bad]
        group_v = None if group_v is None else group_v[~bad]
        if not len(ns):
            raise InputDataError(f"{source}: {where}: no samples with a valid voltage and current")

    time_s = _times(ns, time_origin)

    def gap_message(k: int, n: int) -> str:
        return (f"{source}: {where}: sample {k} has no temperature while others do ({n} such sample(s))"
                + option_hint("drop_nan", True, "to fill from the nearest sample"))

    temperature_k, filled = check_samples(
        time_s, v, i, temp_c, source=f"{source}: {where}", column="temperature (°C)", celsius=True,
        drop_nan=drop_nan, gap_message=gap_message, expect_discharge=expect_discharge)
    if filled:
        extra_meta["filled_temperature_samples"] = filled
    if group_v is not None:
        group_v = check_group_voltages(group_v, source=f"{source}: {where}", drop_nan=drop_nan,
                                       columns=[f"cell_voltage[{j}]" for j in range(group_v.shape[1])],
                                       where=lambda k: f"sample {k} (stamp {int(ns[k])} ns)")
    meta.update(extra_meta)
    return Recording(time_s=time_s, voltage_v=v, current_a=i, temperature_k=temperature_k, source=source, metadata=meta,
                     group_voltage_v=group_v)


def _cell_voltages(msgs: list[tuple[int, Any]]) -> np.ndarray | None:
    """The messages' ``cell_voltage`` (V) as (n_messages, n_cells), NaN-padded where a message has fewer
    cells than the longest; None when every message's is empty."""
    cells = [np.asarray(m.cell_voltage, dtype=float).ravel() for _, m in msgs]
    width = max((c.size for c in cells), default=0)
    if width == 0:
        return None
    out = np.full((len(cells), width), np.nan)
    for k, c in enumerate(cells):
        out[k, :c.size] = c
    return out


def _battery_states(source: str, name: str, msgs: list[tuple[int, Any]]
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, dict[str, int]]:
    """The BatteryState messages' (stamps ns, V, A, degC, cell voltages V or None, notes), sorted, the last of
    each repeated stamp kept."""
    if not msgs:
        raise BagError(f"{source}: topic {name} has no messages")
    ns = np.array([_stamp_ns(log, m.header) for log, m in msgs], dtype=np.int64)
    v = np.array([m.voltage for _, m in msgs], dtype=float)
    i = np.asarray(battery_state_current_to_internal(np.array([m.current for _, m in msgs], dtype=float)))
    temp_c = np.array([m.temperature for _, m in msgs], dtype=float)
    cells = _cell_voltages(msgs)
    if cells is None:
        ns, (v, i, temp_c), dup = _sorted_unique(ns, v, i, temp_c)
    else:
        ns, (v, i, temp_c, cells), dup = _sorted_unique(ns, v, i, temp_c, cells)
    return ns, v, i, temp_c, cells, {"dropped_duplicate_stamps": dup}


def _times(ns: np.ndarray, origin: tuple[int, float] | None) -> np.ndarray:
    if origin is None:
        return ns.astype(float) / 1e9
    origin_ns, base_s = origin
    return base_s + (ns - origin_ns).astype(float) / 1e9


def _merge_relay(p: str, prefix: str, got: Mapping[str, list[tuple[int, Any]]]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, int]]:
    """The relay topics' (stamps ns, V, A, degC, notes): each current paired with the nearest voltage."""
    v_msgs = got.get(prefix + RELAY_SUFFIXES["voltage"], [])
    i_msgs = got.get(prefix + RELAY_SUFFIXES["current"], [])
    t_msgs = got.get(prefix + RELAY_SUFFIXES["temperature"], [])
    if not v_msgs or not i_msgs:
        empty = prefix + (RELAY_SUFFIXES["voltage"] if not v_msgs else RELAY_SUFFIXES["current"])
        raise BagError(f"{p}: relay topic {empty} has no messages")
    v_ns, (v,), dup_v = _sorted_unique(
        np.array([log for log, _ in v_msgs], dtype=np.int64), np.array([m.data for _, m in v_msgs], dtype=float)
    )
    i_ns, (i_src,), dup_i = _sorted_unique(
        np.array([log for log, _ in i_msgs], dtype=np.int64), np.array([m.data for _, m in i_msgs], dtype=float)
    )
    j = nearest_index(i_ns, v_ns)
    dist_s = np.abs(i_ns[j] - v_ns) / 1e9
    period = float(np.median(np.diff(v_ns))) / 1e9 if len(v_ns) > 1 else 0.0
    tol = max(_RELAY_MIN_PAIR_TOLERANCE_S, 3.0 * period)
    paired = dist_s <= tol
    if not paired.any():
        raise BagError(
            f"{p}: relay topics {prefix}/voltage and {prefix}/current have no samples within {tol:.3g} s of each other"
        )
    ns, v, i = v_ns[paired], v[paired], i_src[j[paired]]
    if t_msgs:
        t_ns, (t_c,), _ = _sorted_unique(
            np.array([log for log, _ in t_msgs], dtype=np.int64),
            np.array([m.temperature for _, m in t_msgs], dtype=float),
        )
        good = np.isfinite(t_c)
        if good.any():
            t_ns, t_c = t_ns[good], t_c[good]
            temp_c = t_c[nearest_index(t_ns, ns)]
        else:
            temp_c = np.full(len(ns), math.nan)
    else:
        temp_c = np.full(len(ns), math.nan)
    extra = {"dropped_duplicate_stamps": dup_v + dup_i, "relay_unpaired_samples": int((~paired).sum())}
    return ns, v, i, temp_c, extra
