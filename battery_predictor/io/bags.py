"""rosbag2 (MCAP storage) recordings <-> :class:`~battery_predictor.recording.Recording`.

ROS-free: bags are read and written with ``rosbags`` (type store
``ROS2_JAZZY``); rclpy is never imported. A "bag" is a rosbag2 directory with
``metadata.yaml`` and one or more ``.mcap`` files, or a single ``.mcap`` file
(``.db3`` single files and sqlite3 bag directories are read too).

Two topic styles
----------------
``"battery_state"`` -- the Ranger SDK bridge style
    One topic (default ``/battery_state``) of ``sensor_msgs/msg/BatteryState``.
    ``current`` is **negative while discharging** in the message, as the
    message definition says; it is converted to the internal convention
    (positive = discharge) only by
    :func:`battery_predictor.conventions.battery_state_current_to_internal` /
    :func:`~battery_predictor.conventions.internal_current_to_battery_state`.
    ``temperature`` is in °C, NaN when not measured. The sample time is
    ``header.stamp`` (the bag receive time when the stamp is zero). Fields the
    recording does not have (charge, capacity, percentage...) are written as
    NaN; ``power_supply_status`` is DISCHARGING/CHARGING/NOT_CHARGING from the
    current sign. The message fields are float32, so values round-trip to
    float32 precision.

``"relay"`` -- the ESP32 + INA260 (+ MCP9808) measuring device of the information robot
    Three topics under a prefix (default ``/battery``):

    ========================  ==============================  ================================
    topic                     type                            content
    ========================  ==============================  ================================
    ``<prefix>/voltage``      ``std_msgs/msg/Float64``        bus voltage in V (INA260)
    ``<prefix>/current``      ``std_msgs/msg/Float64``        current in A, positive = discharge
    ``<prefix>/temperature``  ``sensor_msgs/msg/Temperature`` °C near the pack (MCP9808), optional
    ========================  ==============================  ================================

    ``std_msgs`` has no stamped scalar, and the device sends voltage and
    current as plain numbers, so Float64 is used (``std_msgs/msg/Float32`` is
    also accepted when reading) and **every relay topic is timed by the bag
    receive (log) time**; the ``Temperature`` header stamp is not used because
    the ESP32 clock is not necessarily synchronised. Float64 keeps the values
    bit-identical in a round trip.

    Current sign: the INA260 reports positive current for current flowing from
    its IN+ to its IN- pin. **Our assumption** is that the device sits in the
    high-side path battery+ -> IN+ -> IN- -> robot load, so it publishes
    positive = discharge, the internal convention: no conversion is applied
    (and conventions.py has none for this topic). A reversed installation is
    caught by ``expect_discharge=True`` (see
    :func:`battery_predictor.io.csv_io.check_current_sign`).

    Reading merges the three topics onto the time grid of the voltage topic:
    each voltage sample is paired with the **nearest** current sample in
    receive time (both come from the same INA260 reading, published back to
    back); voltage samples with no current sample within
    ``max(0.5 s, 3 x median voltage period)`` are dropped (counted in
    ``metadata["relay_unpaired_samples"]``). Temperature, a slow signal, is
    taken from the nearest temperature sample without a distance limit.

Metadata
--------
``write_recording_bag`` stores ``recording.metadata`` updated with
``metadata=`` in the bag's ``custom_data`` (``metadata.yaml`` and the MCAP
``rosbag2`` metadata record), one entry per key, the value JSON-encoded.
Keys starting with ``battery_predictor.`` are reserved: the writer stores the
style, the source, the time origin and a SHA-256 of every topic's messages
there. The MCAP stamps are ``time_origin_ns + round((time_s - time_base_s) *
1e9)``: a recording with a relative time axis (``time_s[0] < 1e8``) uses
``time_base_s = 0`` and is anchored at 2024-01-01T00:00:00Z, so
``read_recording_bag`` returns bit-identical times (for times with at most 9
decimals); one whose time already looks like epoch seconds keeps it (to ~1e-7
s, the float64 resolution of epoch seconds). For bags without these keys
(recorded on a robot) ``time_s`` is the stamp in epoch seconds.

Errors
------
Everything raises :class:`~battery_predictor.errors.BagError` (or
:class:`~battery_predictor.errors.InputDataError` for implausible data) with a
one-line message naming the path: missing path, not a bag, no supported
topic, a requested topic that is missing or of an unsupported type (the message
lists the topics and types in the bag), and corrupt or truncated storage.
Corruption is detected in four layers, each turned into ``BagError`` (never a
raw traceback; every check is a bounded read, nothing can hang):

1. ``rosbags`` while opening: MCAP start/end magic and footer (a truncated
   file, e.g. a recorder killed mid-write, fails here at once), record
   lengths, chunk CRCs when the writer stored them, metadata.yaml syntax and
   referenced files; any exception it raises while indexing or iterating;
2. CDR decoding of every message that is read;
3. the number of messages read per topic must equal the count in the bag's
   index/metadata (a damaged chunk index otherwise silently drops messages);
4. for bags written here, a SHA-256 of every topic's (log time, payload)
   stream stored in custom_data (``rosbags`` writes chunks without CRC, so a
   flipped byte inside a value would otherwise go unnoticed).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from battery_predictor.conventions import (
    battery_state_current_to_internal,
    celsius_to_kelvin,
    internal_current_to_battery_state,
    kelvin_to_celsius,
)
from battery_predictor.errors import BagError, BatteryPredictorError, InputDataError, option_hint
from battery_predictor.io.csv_io import check_current_sign, check_temperature_k, check_units
from battery_predictor.io.paths import portable_path, portable_paths
from battery_predictor.jsonutil import json_default as _json_default
from battery_predictor.recording import Recording

STYLES = ("battery_state", "relay")

BATTERY_STATE_TYPE = "sensor_msgs/msg/BatteryState"
TEMPERATURE_TYPE = "sensor_msgs/msg/Temperature"
FLOAT64_TYPE = "std_msgs/msg/Float64"
FLOAT32_TYPE = "std_msgs/msg/Float32"
RELAY_SCALAR_TYPES = (FLOAT64_TYPE, FLOAT32_TYPE)

DEFAULT_BATTERY_STATE_TOPIC = "/battery_state"
DEFAULT_RELAY_PREFIX = "/battery"
RELAY_SUFFIXES = {"voltage": "/voltage", "current": "/current", "temperature": "/temperature"}

#: Reserved custom_data key prefix.
RESERVED_PREFIX = "battery_predictor."
_KEY_STYLE = RESERVED_PREFIX + "style"
_KEY_SOURCE = RESERVED_PREFIX + "source"
_KEY_ORIGIN_NS = RESERVED_PREFIX + "time_origin_ns"
_KEY_BASE_S = RESERVED_PREFIX + "time_base_s"
_KEY_SHA256 = RESERVED_PREFIX + "sha256"

#: Where recordings with a relative time axis are anchored (2024-01-01T00:00:00Z).
DEFAULT_START_NS = 1_704_067_200 * 1_000_000_000
#: time_s[0] at or above this is taken as epoch seconds.
_EPOCH_THRESHOLD_S = 1e8

_RELAY_MIN_PAIR_TOLERANCE_S = 0.5


@lru_cache(maxsize=1)
def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


# ---------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------




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
    from rosbags.rosbag2 import StoragePlugin, Writer

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

    t = np.asarray(recording.time_s, dtype=float)
    v = np.asarray(recording.voltage_v, dtype=float)
    i = np.asarray(recording.current_a, dtype=float)
    temp_k = None if recording.temperature_k is None else np.asarray(recording.temperature_k, dtype=float)
    n = len(t)
    if n == 0:
        raise BagError(f"{p}: recording {recording.source} has no samples")
    for name, arr in (("time_s", t), ("voltage_v", v), ("current_a", i)):
        bad = ~np.isfinite(arr)
        if bad.any():
            k = int(np.argmax(bad))
            raise BagError(f"{p}: recording {recording.source}: sample {k} has non-finite {name} ({arr[k]!r})")
    # Relative time axes (the usual case) are stored as DEFAULT_START_NS + round(time_s * 1e9), so that
    # (stamp - origin) / 1e9 gives back exactly the same float for times with <= 9 decimals; epoch times
    # keep their whole seconds in the origin.
    t_base = float(math.floor(t[0])) if t[0] >= _EPOCH_THRESHOLD_S else 0.0
    origin_ns = int(t_base) * 1_000_000_000 if t_base else DEFAULT_START_NS
    rel_ns = np.rint((t - t_base) * 1e9).astype(np.int64)
    if n > 1 and (np.diff(rel_ns) <= 0).any():
        k = int(np.argmax(np.diff(rel_ns) <= 0)) + 1
        raise BagError(
            f"{p}: recording {recording.source}: time_s must be strictly increasing (by >= 1 ns), "
            f"sample {k} has {t[k]!r} after {t[k - 1]!r}"
        )
    stamps = origin_ns + rel_ns
    if stamps[0] < 0:
        raise BagError(f"{p}: recording {recording.source}: time_s starts at {t[0]!r} s, too far before 2024-01-01")

    meta = portable_paths({**recording.metadata, **(metadata or {})})
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
    custom[_KEY_STYLE] = style
    custom[_KEY_SOURCE] = portable_path(str(recording.source))
    custom[_KEY_ORIGIN_NS] = str(origin_ns)
    custom[_KEY_BASE_S] = repr(t_base)

    if p.exists() or p.is_symlink():
        if not overwrite:
            raise BagError(f"{p}: already exists" + option_hint("overwrite", True, "to replace it"))
        if not p.is_dir() or not _looks_like_bag_dir(p):
            raise BagError(f"{p}: exists and is not a bag directory; not overwriting it")
        shutil.rmtree(p)
    if not p.parent.is_dir():
        raise BagError(f"{p}: parent directory {p.parent} does not exist")

    from rosbags.rosbag2 import WriterError

    ts = _typestore()
    writer = Writer(p, version=9, storage_plugin=StoragePlugin.MCAP)
    for key, value in custom.items():
        writer.set_custom_data(key, value)
    try:
        writer.open()
    except (OSError, WriterError) as exc:
        raise BagError(f"{p}: cannot create bag ({_one_line(exc)})") from None
    digests = _DigestingWriter(writer)
    try:
        if style == "battery_state":
            _write_battery_state(digests, ts, prefix, stamps, v, i, temp_k, meta)
        else:
            _write_relay(digests, ts, prefix, stamps, v, i, temp_k)
        writer.set_custom_data(_KEY_SHA256, json.dumps(digests.hexdigests(), sort_keys=True))
        writer.close()
    except BaseException as exc:
        # never leave a half-written bag behind: it would read as corrupt later
        with suppress(Exception):
            writer.abort()
        shutil.rmtree(p, ignore_errors=True)
        if isinstance(exc, (OSError, WriterError)):
            raise BagError(f"{p}: cannot write bag ({_one_line(exc)})") from None
        raise
    return p


def _digest_update(h, log_ns: int, raw: bytes | memoryview) -> None:
    h.update(int(log_ns).to_bytes(8, "little", signed=False))
    h.update(len(raw).to_bytes(8, "little"))
    h.update(raw)


class _DigestingWriter:
    """Forwards to a rosbags Writer and keeps a SHA-256 of every topic's (log time, payload) stream.

    rosbags writes MCAP chunks without CRC, so without this a flipped byte in
    a message would go unnoticed; the digests go to custom_data and are
    verified by :func:`read_recording_bag`.
    """

    def __init__(self, writer):
        self._writer = writer
        self._hashes: dict[str, Any] = {}

    def add_connection(self, topic: str, msgtype: str, **kwargs):
        self._hashes[topic] = hashlib.sha256()
        return self._writer.add_connection(topic, msgtype, **kwargs)

    def write(self, conn, ns: int, raw: bytes | memoryview) -> None:
        _digest_update(self._hashes[conn.topic], ns, raw)
        self._writer.write(conn, ns, raw)

    def hexdigests(self) -> dict[str, str]:
        return {topic: h.hexdigest() for topic, h in self._hashes.items()}


def _stamp(ts, ns: int):
    time_cls = ts.types["builtin_interfaces/msg/Time"]
    return time_cls(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def _write_battery_state(writer, ts, topic, stamps, v, i, temp_k, meta) -> None:
    msg_cls = ts.types[BATTERY_STATE_TYPE]
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
            cell_voltage=empty,
            cell_temperature=empty,
            location="",
            serial_number=serial,
        )
        writer.write(conn, ns, ts.serialize_cdr(msg, BATTERY_STATE_TYPE))


def _write_relay(writer, ts, prefix, stamps, v, i, temp_k) -> None:
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
        if c_t is not None and math.isfinite(temp_c[k]):
            msg = temp_cls(header=header_cls(stamp=_stamp(ts, ns), frame_id="battery"), temperature=float(temp_c[k]), variance=0.0)
            writer.write(c_t, ns, ts.serialize_cdr(msg, TEMPERATURE_TYPE))


# ---------------------------------------------------------------------------
# Opening
# ---------------------------------------------------------------------------


def _resolve(path: str | os.PathLike[str]) -> Path:
    """The path rosbags should open: a bag directory or a single storage file."""
    p = Path(path)
    if not p.exists():
        raise BagError(f"{p}: bag not found (no such file or directory)")
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return p
        storage = sorted(p.glob("*.mcap")) + sorted(p.glob("*.db3"))
        if len(storage) == 1:
            return storage[0]  # e.g. a recorder killed before it wrote metadata.yaml
        if not storage:
            raise BagError(f"{p}: not a rosbag2 directory (no metadata.yaml and no .mcap file)")
        raise BagError(
            f"{p}: has no metadata.yaml and several storage files ({', '.join(s.name for s in storage)}); "
            "open one .mcap file directly"
        )
    if p.suffix not in (".mcap", ".db3"):
        raise BagError(f"{p}: not a bag (expected a rosbag2 directory or a .mcap file)")
    if p.stat().st_size == 0:
        raise BagError(f"{p}: corrupt or truncated bag: the file is empty")
    return p


def _corrupt(p: Path, exc: BaseException) -> BagError:
    return BagError(
        f"{p}: corrupt or truncated bag ({type(exc).__name__}: {_one_line(exc)}); "
        "if the recorder was killed, `mcap recover` may salvage the messages"
    )


@contextmanager
def _open_reader(p: Path) -> Iterator[Any]:
    from rosbags.rosbag2 import Reader

    try:
        reader = Reader(p)
        reader.open()
    except BatteryPredictorError:
        raise
    except MemoryError as exc:
        raise _corrupt(p, exc) from None
    except Exception as exc:  # noqa: BLE001 - rosbags raises many types on corrupt input
        raise _corrupt(p, exc) from None
    try:
        yield reader
    finally:
        try:
            reader.close()
        except Exception:  # noqa: BLE001 - closing a broken reader must not hide the real error
            pass


def _read_custom_data(p: Path) -> dict[str, str]:
    """custom_data of a bag directory (metadata.yaml) or of a single .mcap (rosbag2 metadata record)."""
    try:
        if p.is_dir():
            info = yaml.safe_load((p / "metadata.yaml").read_text(encoding="utf-8"))
            info = (info or {}).get("rosbag2_bagfile_information", {}) or {}
        elif p.suffix == ".mcap":
            from mcap.reader import make_reader

            info = {}
            with p.open("rb") as fh:
                for record in make_reader(fh).iter_metadata():
                    if record.name == "rosbag2" and "serialized_metadata" in record.metadata:
                        info = yaml.safe_load(record.metadata["serialized_metadata"]) or {}
                        break
        else:
            info = {}
    except Exception as exc:  # noqa: BLE001
        raise _corrupt(p, exc) from None
    custom = info.get("custom_data") if isinstance(info, dict) else None
    return {str(k): str(v) for k, v in (custom or {}).items()}


def _decode_custom(custom: dict[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, raw in custom.items():
        if key.startswith(RESERVED_PREFIX):
            continue
        try:
            out[key] = json.loads(raw)
        except ValueError:
            out[key] = raw  # written by another tool: keep the string
    return out


def _topics(reader) -> dict[str, tuple[str, int]]:
    out: dict[str, tuple[str, int]] = {}
    for conn in reader.connections:
        msgtype, count = out.get(conn.topic, (conn.msgtype, 0))
        if msgtype != conn.msgtype:
            msgtype = f"{msgtype}|{conn.msgtype}"
        out[conn.topic] = (msgtype, count + int(conn.msgcount))
    return dict(sorted(out.items()))


def _describe(topics: dict[str, tuple[str, int]]) -> str:
    if not topics:
        return "the bag has no topics"
    return "topics in the bag: " + ", ".join(f"{name} [{msgtype}] x{count}" for name, (msgtype, count) in topics.items())


# ---------------------------------------------------------------------------
# Topic selection
# ---------------------------------------------------------------------------


def _relay_prefixes(topics: dict[str, tuple[str, int]]) -> list[str]:
    out = []
    for name, (msgtype, _) in topics.items():
        if name.endswith(RELAY_SUFFIXES["voltage"]) and msgtype in RELAY_SCALAR_TYPES:
            prefix = name[: -len(RELAY_SUFFIXES["voltage"])]
            cur = topics.get(prefix + RELAY_SUFFIXES["current"])
            if cur and cur[0] in RELAY_SCALAR_TYPES:
                out.append(prefix)
    return out


def _select(p: Path, topics: dict[str, tuple[str, int]], topic: str | None) -> tuple[str, str]:
    """(style, topic or prefix) to read."""
    supported = (
        f"supported: {BATTERY_STATE_TYPE} on one topic, or <prefix>/voltage + <prefix>/current "
        f"[{' or '.join(RELAY_SCALAR_TYPES)}] with optional <prefix>/temperature [{TEMPERATURE_TYPE}]"
    )
    if topic is not None:
        if topic in topics:
            msgtype = topics[topic][0]
            if msgtype == BATTERY_STATE_TYPE:
                return "battery_state", topic
            for part, suffix in RELAY_SUFFIXES.items():
                if topic.endswith(suffix) and part != "temperature":
                    prefix = topic[: -len(suffix)]
                    if prefix in _relay_prefixes(topics):
                        return "relay", prefix
            raise BagError(
                f"{p}: topic {topic!r} has type {msgtype}, which cannot be read as a battery recording "
                f"({supported}); {_describe(topics)}"
            )
        if topic.rstrip("/") in _relay_prefixes(topics):
            return "relay", topic.rstrip("/")
        raise BagError(f"{p}: topic {topic!r} is not in the bag; {_describe(topics)}")
    states = [name for name, (msgtype, _) in topics.items() if msgtype == BATTERY_STATE_TYPE]
    if len(states) == 1:
        return "battery_state", states[0]
    if len(states) > 1:
        if DEFAULT_BATTERY_STATE_TOPIC in states:
            return "battery_state", DEFAULT_BATTERY_STATE_TOPIC
        raise BagError(f"{p}: several {BATTERY_STATE_TYPE} topics ({', '.join(states)})"
                       + option_hint("topic", None, "to choose one"))
    prefixes = _relay_prefixes(topics)
    if len(prefixes) == 1:
        return "relay", prefixes[0]
    if len(prefixes) > 1:
        if DEFAULT_RELAY_PREFIX in prefixes:
            return "relay", DEFAULT_RELAY_PREFIX
        raise BagError(
            f"{p}: several relay topic groups ({', '.join(x + '/*' for x in prefixes)})"
            + option_hint("topic", None, "to choose one")
        )
    raise BagError(f"{p}: no supported battery topics ({supported}); {_describe(topics)}")


# ---------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------


def _messages(p: Path, reader, topic_names: set[str], custom: dict[str, str]) -> dict[str, list[tuple[int, Any]]]:
    """Deserialised messages per topic as (log_time_ns, msg), verified against the bag's counts and digests."""
    ts = _typestore()
    conns = [c for c in reader.connections if c.topic in topic_names]
    out: dict[str, list[tuple[int, Any]]] = {name: [] for name in topic_names}
    hashes = {name: hashlib.sha256() for name in topic_names}
    try:
        for conn, log_ns, raw in reader.messages(connections=conns):
            _digest_update(hashes[conn.topic], log_ns, raw)
            try:
                msg = ts.deserialize_cdr(raw, conn.msgtype)
            except Exception as exc:  # noqa: BLE001
                raise BagError(
                    f"{p}: corrupt bag: message {len(out[conn.topic])} on {conn.topic} [{conn.msgtype}] "
                    f"cannot be decoded ({type(exc).__name__}: {_one_line(exc)})"
                ) from None
            out[conn.topic].append((int(log_ns), msg))
    except BatteryPredictorError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many types on corrupt input
        raise _corrupt(p, exc) from None
    expected: dict[str, int] = {}
    for conn in conns:
        expected[conn.topic] = expected.get(conn.topic, 0) + int(conn.msgcount)
    for name in sorted(topic_names):
        if expected.get(name, 0) != len(out[name]):
            raise BagError(
                f"{p}: corrupt or truncated bag: the index lists {expected.get(name, 0)} messages on {name}, "
                f"{len(out[name])} could be read"
            )
    try:
        stored = json.loads(custom.get(_KEY_SHA256, "{}"))
    except ValueError:
        stored = {}
    for name in sorted(topic_names):
        want = stored.get(name) if isinstance(stored, dict) else None
        if want is not None and want != hashes[name].hexdigest():
            raise BagError(f"{p}: corrupt bag: the messages on {name} do not match the SHA-256 stored when it was written")
    return out


def _stamp_ns(log_ns: int, header) -> int:
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns > 0 else log_ns


def _nearest(t_src: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Index into sorted t_src of the nearest sample to each t_query (ties -> earlier)."""
    if len(t_src) == 1:
        return np.zeros(len(t_query), dtype=int)
    j = np.clip(np.searchsorted(t_src, t_query), 1, len(t_src) - 1)
    left = j - 1
    return np.where(np.abs(t_query - t_src[left]) <= np.abs(t_src[j] - t_query), left, j)


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
        :func:`battery_predictor.io.csv_io.check_current_sign` (off by default:
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
    p = _resolve(src)
    custom = _read_custom_data(p)
    with _open_reader(p) as reader:
        topics = _topics(reader)
        style, name = _select(src, topics, topic)
        if style == "battery_state":
            msgs = _messages(src, reader, {name}, custom)[name]
            if not msgs:
                raise BagError(f"{src}: topic {name} has no messages")
            ns = np.array([_stamp_ns(log, m.header) for log, m in msgs], dtype=np.int64)
            v = np.array([m.voltage for _, m in msgs], dtype=float)
            i = np.asarray(battery_state_current_to_internal(np.array([m.current for _, m in msgs], dtype=float)))
            temp_c = np.array([m.temperature for _, m in msgs], dtype=float)
            ns, (v, i, temp_c), dup = _sorted_unique(ns, v, i, temp_c)
            extra = {"dropped_duplicate_stamps": dup}
            where = name
        else:
            names = {name + s for s in RELAY_SUFFIXES.values() if name + s in topics}
            got = _messages(src, reader, names, custom)
            ns, v, i, temp_c, extra = _merge_relay(src, name, got)
            where = name + "/*"
    source = str(src)
    meta = _decode_custom(custom)
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
        if not len(ns):
            raise InputDataError(f"{source}: {where}: no samples with a valid voltage and current")

    time_s = _times(ns, custom)
    temperature_k = None
    finite_t = np.isfinite(temp_c)
    if finite_t.any():
        if not finite_t.all():
            if not drop_nan:
                k = int(np.argmax(~finite_t))
                raise InputDataError(
                    f"{source}: {where}: sample {k} has no temperature while others do "
                    f"({int((~finite_t).sum())} such sample(s))"
                    + option_hint("drop_nan", True, "to fill from the nearest sample")
                )
            extra_meta["filled_temperature_samples"] = int((~finite_t).sum())
            good = np.flatnonzero(finite_t)
            temp_c = temp_c[good[_nearest(time_s[good], time_s)]]
        temperature_k = np.asarray(celsius_to_kelvin(temp_c), dtype=float)
        check_temperature_k(temperature_k, source=f"{source}: {where}", column="temperature (°C)")
    check_units(v, i, source=f"{source}: {where}")
    if expect_discharge:
        check_current_sign(time_s, v, i, source=f"{source}: {where}")
    meta.update(extra_meta)
    return Recording(time_s=time_s, voltage_v=v, current_a=i, temperature_k=temperature_k, source=source, metadata=meta)


def _times(ns: np.ndarray, custom: dict[str, str]) -> np.ndarray:
    try:
        origin = int(custom[_KEY_ORIGIN_NS])
        base = float(custom[_KEY_BASE_S])
    except (KeyError, ValueError):
        return ns.astype(float) / 1e9
    return base + (ns - origin).astype(float) / 1e9


def _merge_relay(p: Path, prefix: str, got: dict[str, list[tuple[int, Any]]]):
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
    j = _nearest(i_ns, v_ns)
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
            temp_c = t_c[_nearest(t_ns, ns)]
        else:
            temp_c = np.full(len(ns), math.nan)
    else:
        temp_c = np.full(len(ns), math.nan)
    extra = {"dropped_duplicate_stamps": dup_v + dup_i, "relay_unpaired_samples": int((~paired).sum())}
    return ns, v, i, temp_c, extra


# ---------------------------------------------------------------------------
# Info
# ---------------------------------------------------------------------------


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
    p = _resolve(src)
    custom = _read_custom_data(p)
    with _open_reader(p) as reader:
        topics = _topics(reader)
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
        "duration_s": (end_ns - start_ns) / 1e9 if start_ns is not None else 0.0,
        "metadata": _decode_custom(custom),
        "style": None,
        "battery_topic": None,
        "summary": None,
        "summary_error": None,
    }
    try:
        style, name = _select(src, topics, None)
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
