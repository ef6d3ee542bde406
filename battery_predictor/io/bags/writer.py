"""Writing a :class:`~battery_predictor.recording.Recording` as a rosbag2 directory (MCAP storage)."""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
from contextlib import suppress
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.conventions import internal_current_to_battery_state, kelvin_to_celsius
from battery_predictor.errors import BagError, option_hint
from battery_predictor.io.bags.schema import (
    BATTERY_STATE_TYPE,
    DEFAULT_BATTERY_STATE_TOPIC,
    DEFAULT_RELAY_PREFIX,
    DEFAULT_START_NS,
    EPOCH_THRESHOLD_S,
    FLOAT64_TYPE,
    KEY_BASE_S,
    KEY_ORIGIN_NS,
    KEY_SHA256,
    KEY_SOURCE,
    KEY_STYLE,
    RELAY_SUFFIXES,
    RESERVED_PREFIX,
    STYLES,
    TEMPERATURE_TYPE,
    typestore,
)
from battery_predictor.io.bags.storage import digest_update, one_line
from battery_predictor.io.paths import portable_path, portable_paths
from battery_predictor.jsonutil import json_default as _json_default
from battery_predictor.recording import Recording

if TYPE_CHECKING:
    from _hashlib import HASH

    from rosbags.interfaces import Connection
    from rosbags.rosbag2 import Writer
    from rosbags.typesys.store import Typestore


def _looks_like_bag_dir(path: Path) -> bool:
    allowed = {".mcap", ".db3", ".yaml", ".zstd", ".tmp"}
    entries = list(path.iterdir())
    return all(e.is_file() and (e.suffix in allowed or e.name == "metadata.yaml") for e in entries)


def write_recording_bag(
    recording: Recording,
    path: str | os.PathLike[str],
    *,
    style: str = "battery_state",
    topic_prefix: str | None = None,
    metadata: dict[str, Any] | None = None,
    overwrite: bool = False,
) -> Path:
    """Write ``recording`` as a rosbag2 directory (version 9, MCAP storage).

    Parameters
    ----------
    recording : Recording
        Current positive = discharge (converted to the BatteryState sign here).
    path : str or os.PathLike
        Bag directory to create (``<path>/metadata.yaml``, ``<path>/<name>.mcap``).
    style : {"battery_state", "relay"}
        Topic layout, see the module docstring.
    topic_prefix : str, optional
        ``"battery_state"``: the topic name (default ``/battery_state``).
        ``"relay"``: the namespace of ``voltage``/``current``/``temperature``
        (default ``/battery``).
    metadata : dict, optional
        Extra metadata (pack id, profile seed, generator version, ground truth
        such as the true time to cut-off...). Merged over
        ``recording.metadata``; JSON-serialisable values, string keys.
    overwrite : bool
        Replace an existing bag directory (a directory holding anything other
        than bag files is never deleted).

    Returns
    -------
    pathlib.Path
        The bag directory.
    """
    p = Path(path)
    if style not in STYLES:
        raise BagError(f"{p}: unknown bag style {style!r}; expected one of {', '.join(STYLES)}")
    if p.suffix in (".mcap", ".db3"):
        raise BagError(f"{p}: give the bag directory to create, not a {p.suffix} file name")
    prefix = topic_prefix if topic_prefix is not None else (
        DEFAULT_BATTERY_STATE_TOPIC if style == "battery_state" else DEFAULT_RELAY_PREFIX
    )
    if not prefix.startswith("/") or prefix.endswith("/") or "//" in prefix or " " in prefix:
        raise BagError(f"{p}: invalid topic name {prefix!r} (must start with '/', no trailing '/')")
    v, i, temp_k = _finite_samples(p, recording)
    stamps, origin_ns, t_base = _stamps_ns(p, recording)
    meta = portable_paths({**recording.metadata, **(metadata or {})})
    custom = _custom_data(p, meta)
    custom[KEY_STYLE] = style
    custom[KEY_SOURCE] = portable_path(str(recording.source))
    custom[KEY_ORIGIN_NS] = str(origin_ns)
    custom[KEY_BASE_S] = repr(t_base)
    _make_room(p, overwrite)
    group_v = None if recording.group_voltage_v is None else np.asarray(recording.group_voltage_v, dtype=float)
    _write(p, custom, style, prefix, stamps, v, i, temp_k, meta, group_v)
    return p


def _finite_samples(p: Path, recording: Recording) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Voltage (V), current (A) and temperature (K, or None) of ``recording``, refused when not finite."""
    t = np.asarray(recording.time_s, dtype=float)
    v = np.asarray(recording.voltage_v, dtype=float)
    i = np.asarray(recording.current_a, dtype=float)
    temp_k = None if recording.temperature_k is None else np.asarray(recording.temperature_k, dtype=float)
    if len(t) == 0:
        raise BagError(f"{p}: recording {recording.source} has no samples")
    for name, arr in (("time_s", t), ("voltage_v", v), ("current_a", i)):
        bad = ~np.isfinite(arr)
        if bad.any():
            k = int(np.argmax(bad))
            raise BagError(f"{p}: recording {recording.source}: sample {k} has non-finite {name} ({arr[k]!r})")
    return v, i, temp_k


def _stamps_ns(p: Path, recording: Recording) -> tuple[np.ndarray, int, float]:
    """The message stamps (ns), the time origin (ns) and the time base (s) of ``recording``.

    Relative time axes (the usual case) are stored as DEFAULT_START_NS + round(time_s * 1e9), so that
    (stamp - origin) / 1e9 gives back exactly the same float for times with <= 9 decimals; epoch times
    keep their whole seconds in the origin.
    """
    t = np.asarray(recording.time_s, dtype=float)
    t_base = float(math.floor(t[0])) if t[0] >= EPOCH_THRESHOLD_S else 0.0
    origin_ns = int(t_base) * 1_000_000_000 if t_base else DEFAULT_START_NS
    rel_ns = np.rint((t - t_base) * 1e9).astype(np.int64)
    if len(t) > 1 and (np.diff(rel_ns) <= 0).any():
        k = int(np.argmax(np.diff(rel_ns) <= 0)) + 1
        raise BagError(
            f"{p}: recording {recording.source}: time_s must be strictly increasing (by >= 1 ns), "
            f"sample {k} has {t[k]!r} after {t[k - 1]!r}"
        )
    stamps = origin_ns + rel_ns
    if stamps[0] < 0:
        raise BagError(f"{p}: recording {recording.source}: time_s starts at {t[0]!r} s, too far before 2024-01-01")
    return stamps, origin_ns, t_base


def _custom_data(p: Path, meta: dict[str, Any]) -> dict[str, str]:
    """``meta`` JSON-encoded per key for the bag's custom_data (reserved keys refused)."""
    custom: dict[str, str] = {}
    for key, value in meta.items():
        if not isinstance(key, str) or not key:
            raise BagError(f"{p}: metadata key {key!r} must be a non-empty string")
        if key.startswith(RESERVED_PREFIX):
            raise BagError(f"{p}: metadata key {key!r} uses the reserved prefix {RESERVED_PREFIX!r}")
        try:
            custom[key] = json.dumps(value, default=_json_default, sort_keys=True)
        except (TypeError, ValueError) as exc:
            raise BagError(f"{p}: metadata key {key!r}: value is not JSON-serialisable ({exc})") from None
    return custom


def _make_room(p: Path, overwrite: bool) -> None:
    """Remove an existing bag at ``p`` when ``overwrite``; refuse anything else in the way."""
    if p.exists() or p.is_symlink():
        if not overwrite:
            raise BagError(f"{p}: already exists" + option_hint("overwrite", True, "to replace it"))
        if not p.is_dir() or not _looks_like_bag_dir(p):
            raise BagError(f"{p}: exists and is not a bag directory; not overwriting it")
        shutil.rmtree(p)
    if not p.parent.is_dir():
        raise BagError(f"{p}: parent directory {p.parent} does not exist")


def _write(p: Path, custom: dict[str, str], style: str, prefix: str, stamps: np.ndarray, v: np.ndarray,
           i: np.ndarray, temp_k: np.ndarray | None, meta: dict[str, Any], group_v: np.ndarray | None = None) -> None:
    """Write the messages and their SHA-256 digests; never leave a half-written bag behind."""
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

    ts = typestore()
    writer = Writer(p, version=9, storage_plugin=StoragePlugin.MCAP)
    for key, value in custom.items():
        writer.set_custom_data(key, value)
    try:
        writer.open()
    except (OSError, WriterError) as exc:
        raise BagError(f"{p}: cannot create bag ({one_line(exc)})") from None
    digests = _DigestingWriter(writer)
    try:
        if style == "battery_state":
            _write_battery_state(digests, ts, prefix, stamps, v, i, temp_k, meta, group_v)
        else:
            _write_relay(digests, ts, prefix, stamps, v, i, temp_k)
        writer.set_custom_data(KEY_SHA256, json.dumps(digests.hexdigests(), sort_keys=True))
        writer.close()
    except BaseException as exc:
        # a half-written bag would read as corrupt later
        with suppress(Exception):
            writer.abort()
        shutil.rmtree(p, ignore_errors=True)
        if isinstance(exc, (OSError, WriterError)):
            raise BagError(f"{p}: cannot write bag ({one_line(exc)})") from None
        raise


class _DigestingWriter:
    """Forwards to a rosbags Writer and keeps a SHA-256 of every topic's (log time, payload) stream.

    rosbags writes MCAP chunks without CRC, so without this a flipped byte in
    a message would go unnoticed; the digests go to custom_data and are
    verified by :func:`read_recording_bag`.
    """

    def __init__(self, writer: Writer) -> None:
        self._writer = writer
        self._hashes: dict[str, HASH] = {}

    def add_connection(self, topic: str, msgtype: str, **kwargs: Any) -> Connection:
        self._hashes[topic] = hashlib.sha256()
        return self._writer.add_connection(topic, msgtype, **kwargs)

    def write(self, conn: Connection, ns: int, raw: bytes | memoryview) -> None:
        digest_update(self._hashes[conn.topic], ns, raw)
        self._writer.write(conn, ns, raw)

    def hexdigests(self) -> dict[str, str]:
        return {topic: h.hexdigest() for topic, h in self._hashes.items()}


def _stamp(ts: Typestore, ns: int) -> Any:
    """A ``builtin_interfaces/Time`` message (its class is made by rosbags at run time) at ``ns``."""
    time_cls = ts.types["builtin_interfaces/msg/Time"]
    return time_cls(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def _write_battery_state(writer: _DigestingWriter, ts: Typestore, topic: str, stamps: np.ndarray, v: np.ndarray,
                         i: np.ndarray, temp_k: np.ndarray | None, meta: dict[str, Any],
                         group_v: np.ndarray | None = None) -> None:
    """BatteryState messages; the series-group voltages (V, NaN where not measured) go to ``cell_voltage``."""
    # rosbags makes the message classes at run time: their constants are not known to the type checker
    msg_cls: Any = ts.types[BATTERY_STATE_TYPE]
    header_cls = ts.types["std_msgs/msg/Header"]
    conn = writer.add_connection(topic, BATTERY_STATE_TYPE, typestore=ts)
    msg_current = np.asarray(internal_current_to_battery_state(i), dtype=float)
    temp_c = np.full(len(v), math.nan) if temp_k is None else np.asarray(kelvin_to_celsius(temp_k), dtype=float)
    status = np.where(
        i > 0,
        msg_cls.POWER_SUPPLY_STATUS_DISCHARGING,
        np.where(i < 0, msg_cls.POWER_SUPPLY_STATUS_CHARGING, msg_cls.POWER_SUPPLY_STATUS_NOT_CHARGING),
    )
    serial = str(meta.get("pack_id", "")) if meta.get("pack_id") is not None else ""
    empty = np.zeros(0, dtype=np.float32)
    nan = math.nan
    for k, ns in enumerate(stamps.tolist()):
        msg = msg_cls(
            header=header_cls(stamp=_stamp(ts, ns), frame_id="battery"),
            voltage=float(v[k]),
            temperature=float(temp_c[k]),
            current=float(msg_current[k]),
            charge=nan,
            capacity=nan,
            design_capacity=nan,
            percentage=nan,
            power_supply_status=int(status[k]),
            power_supply_health=msg_cls.POWER_SUPPLY_HEALTH_UNKNOWN,
            power_supply_technology=msg_cls.POWER_SUPPLY_TECHNOLOGY_UNKNOWN,
            present=True,
            cell_voltage=empty if group_v is None else group_v[k].astype(np.float32),
            cell_temperature=empty,
            location="",
            serial_number=serial,
        )
        writer.write(conn, ns, ts.serialize_cdr(msg, BATTERY_STATE_TYPE))


def _write_relay(writer: _DigestingWriter, ts: Typestore, prefix: str, stamps: np.ndarray, v: np.ndarray,
                 i: np.ndarray, temp_k: np.ndarray | None) -> None:
    f64 = ts.types[FLOAT64_TYPE]
    temp_cls = ts.types[TEMPERATURE_TYPE]
    header_cls = ts.types["std_msgs/msg/Header"]
    c_v = writer.add_connection(prefix + RELAY_SUFFIXES["voltage"], FLOAT64_TYPE, typestore=ts)
    c_i = writer.add_connection(prefix + RELAY_SUFFIXES["current"], FLOAT64_TYPE, typestore=ts)
    c_t = None
    temp_c = None
    if temp_k is not None:
        c_t = writer.add_connection(prefix + RELAY_SUFFIXES["temperature"], TEMPERATURE_TYPE, typestore=ts)
        temp_c = np.asarray(kelvin_to_celsius(temp_k), dtype=float)
    for k, ns in enumerate(stamps.tolist()):
        writer.write(c_v, ns, ts.serialize_cdr(f64(data=float(v[k])), FLOAT64_TYPE))
        writer.write(c_i, ns, ts.serialize_cdr(f64(data=float(i[k])), FLOAT64_TYPE))
        if c_t is not None and temp_c is not None and math.isfinite(temp_c[k]):
            msg = temp_cls(header=header_cls(stamp=_stamp(ts, ns), frame_id="battery"), temperature=float(temp_c[k]), variance=0.0)
            writer.write(c_t, ns, ts.serialize_cdr(msg, TEMPERATURE_TYPE))
