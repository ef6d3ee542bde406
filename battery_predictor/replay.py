"""ROS-free parts of ``battery-predictor replay``: the bag as a time-ordered message stream, the
output bag writer, the ground truth of a bag and the predicted-vs-true runtime comparison and plot.

The ROS side (publishing ``/clock`` and the messages, running the nodes,
recording their outputs) is :mod:`battery_predictor.nodes.replay_session`.

Time
----
A replay publishes ``/clock`` with each message's bag (log) time before the
message itself, and the nodes run with ``use_sim_time``: the monitor's
``BatteryState`` stamps, the relay's reception times and the staleness
checks are then all on the bag's time base, whatever the replay rate.
Results are reported on the recording's own time axis (``time_s`` of
:func:`battery_predictor.io.bags.read_recording_bag`, which starts at 0 for
the bundled bags); :meth:`ReplayStream.recording_time_s` maps a ROS time to it.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from battery_predictor.errors import BagError
from battery_predictor.io.bags import schema, storage
from battery_predictor.io.bags.topics import select_topic

#: Types of the battery input topics a replay plays.
INPUT_TYPES = (schema.BATTERY_STATE_TYPE, schema.FLOAT64_TYPE, schema.FLOAT32_TYPE, schema.TEMPERATURE_TYPE)
#: Custom message types the output bag needs definitions for.
CUSTOM_TYPES = ("battery_predictor_msgs/msg/PackState", "battery_predictor_msgs/msg/RemainingRuntime",
                "battery_predictor_msgs/msg/RouteSection")
#: Remaining-runtime checkpoints of the issue and the paper's evaluation (min).
DEFAULT_CHECKPOINTS_MIN = tuple(range(30, 301, 30))


# ---------------------------------------------------------------------------
# Input stream
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class BagMessage:
    """One serialised message of the bag.

    Attributes
    ----------
    log_time_ns : int
        Bag (receive) time in ns; the replay publishes ``/clock`` = this.
    topic, msgtype : str
        Topic and ROS type (``sensor_msgs/msg/BatteryState``...).
    data : bytes
        CDR serialisation as stored (rclpy publishes it unchanged).
    """

    log_time_ns: int
    topic: str
    msgtype: str
    data: bytes


@dataclass
class ReplayStream:
    """The battery input of a bag, time-ordered, ready to be played.

    Attributes
    ----------
    source : str
        Bag path.
    style : str
        ``"battery_state"`` or ``"relay"`` (see :mod:`battery_predictor.io.bags`).
    battery_topic : str
        The BatteryState topic, or the relay prefix.
    topics : dict
        ``{topic: msgtype}`` of the played topics.
    messages : list of BagMessage
        Sorted by log time (stable: the bag's order within one time).
    metadata : dict
        The bag's decoded custom data (ground truth of the bundled bags).
    """

    source: str
    style: str
    battery_topic: str
    topics: dict[str, str]
    messages: list[BagMessage]
    metadata: dict[str, Any] = field(default_factory=dict)
    _origin_ns: int | None = None
    _base_s: float = 0.0

    @property
    def start_ns(self) -> int:
        """Log time of the first message (ns)."""
        return self.messages[0].log_time_ns

    @property
    def end_ns(self) -> int:
        """Log time of the last message (ns)."""
        return self.messages[-1].log_time_ns

    @property
    def duration_s(self) -> float:
        """Time from the first to the last message (s)."""
        return (self.end_ns - self.start_ns) / 1e9

    def recording_time_s(self, time_ns: int | float) -> float:
        """A ROS time (ns, bag time base) on the recording's time axis (s; 0 = start for the bundled bags)."""
        if self._origin_ns is None:
            return float(time_ns) / 1e9
        return self._base_s + (float(time_ns) - self._origin_ns) / 1e9

    def ros_time_ns(self, recording_time_s: float) -> int:
        """Inverse of :meth:`recording_time_s`."""
        if self._origin_ns is None:
            return round(recording_time_s * 1e9)
        return self._origin_ns + round((recording_time_s - self._base_s) * 1e9)

    def steps(self, start_ns: int | None = None, end_ns: int | None = None) -> Iterator[tuple[int, list[BagMessage]]]:
        """``(log_time_ns, messages)`` groups of equal log time with ``start_ns <= t <= end_ns``."""
        group: list[BagMessage] = []
        current: int | None = None
        for msg in self.messages:
            t = msg.log_time_ns
            if (start_ns is not None and t < start_ns) or (end_ns is not None and t > end_ns):
                continue
            if current is not None and t != current:
                yield current, group
                group = []
            current = t
            group.append(msg)
        if current is not None:
            yield current, group

    def counts(self) -> dict[str, int]:
        """Messages per topic."""
        out: dict[str, int] = {}
        for msg in self.messages:
            out[msg.topic] = out.get(msg.topic, 0) + 1
        return out


def stream_from_messages(messages: Sequence[BagMessage], *, style: str, battery_topic: str,
                         metadata: dict[str, Any] | None = None, source: str = "<memory>") -> ReplayStream:
    """A :class:`ReplayStream` of messages built in memory (tests, benchmarks); times are ROS times."""
    if style not in schema.STYLES:
        raise BagError(f"{source}: style {style!r} (must be one of {', '.join(schema.STYLES)})")
    ordered = sorted(messages, key=lambda m: m.log_time_ns)
    if not ordered:
        raise BagError(f"{source}: no messages")
    return ReplayStream(source=source, style=style, battery_topic=battery_topic,
                        topics={m.topic: m.msgtype for m in ordered}, messages=ordered, metadata=dict(metadata or {}))


def read_replay_stream(path: str | os.PathLike[str], *, topic: str | None = None) -> ReplayStream:
    """Read a bag's battery topics as a :class:`ReplayStream`.

    Parameters
    ----------
    path : str or os.PathLike
        rosbag2 directory or ``.mcap`` file.
    topic : str, optional
        BatteryState topic or relay prefix (default: auto-detected as in
        :func:`~battery_predictor.io.bags.read_recording_bag`).

    Raises
    ------
    BagError
        Missing, corrupt, or without battery topics.
    """
    src = Path(path)
    p = storage.resolve(src)
    custom = storage.read_custom_data(p)
    messages: list[BagMessage] = []
    with storage.open_reader(p) as reader:
        topics = storage.list_topics(reader)
        style, name = select_topic(src, topics, topic)
        if style == "battery_state":
            wanted = {name}
        else:
            wanted = {name + s for s in schema.RELAY_SUFFIXES.values() if name + s in topics}
        conns = [c for c in reader.connections if c.topic in wanted and c.msgtype in INPUT_TYPES]
        try:
            for conn, log_ns, raw in reader.messages(connections=conns):
                messages.append(BagMessage(int(log_ns), conn.topic, conn.msgtype, bytes(raw)))
        except Exception as exc:  # noqa: BLE001 - rosbags raises many types on corrupt input
            raise storage.corrupt(src, exc) from None
    if not messages:
        raise BagError(f"{src}: no messages on {', '.join(sorted(wanted))}")
    messages.sort(key=lambda m: m.log_time_ns)  # stable: keeps voltage, current, temperature order
    origin = base = None
    try:
        origin = int(custom[schema.KEY_ORIGIN_NS])
        base = float(custom[schema.KEY_BASE_S])
    except (KeyError, ValueError):
        pass
    return ReplayStream(source=str(src), style=style, battery_topic=name,
                        topics={m.topic: m.msgtype for m in messages}, messages=messages,
                        metadata=storage.decode_custom(custom), _origin_ns=origin,
                        _base_s=base if base is not None else 0.0)


# ---------------------------------------------------------------------------
# Ground truth and comparison
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class RuntimeTruth:
    """True runtime of a discharge bag: the time (recording axis, s) at which ``stop_voltage_v`` was measured."""

    stop_voltage_v: float
    runtime_s: float

    def remaining_s(self, recording_time_s: float) -> float:
        """True remaining runtime (s) at a recording time."""
        return self.runtime_s - recording_time_s


def runtime_truth(metadata: dict[str, Any]) -> RuntimeTruth | None:
    """The runtime truth stored by the lab in a bag's metadata, or None (e.g. route bags)."""
    truth = metadata.get("truth") if isinstance(metadata, dict) else None
    if not isinstance(truth, dict):
        return None
    try:
        runtime = float(truth["runtime_s"])
        stop = float(truth["stop_voltage_v"])
    except (KeyError, TypeError, ValueError):
        return None
    return RuntimeTruth(stop, runtime) if math.isfinite(runtime) else None


@dataclass(frozen=True)
class RuntimePoint:
    """One published remaining-runtime message, on the recording time axis.

    Attributes
    ----------
    time_s : float
        Recording time of the pack state the prediction is based on (its header stamp), s.
    remaining_s : float
        Predicted remaining runtime, s (NaN when invalid).
    valid : bool
        The message's ``valid``.
    status : int
        The message's ``status``.
    reason : str
        The message's ``reason``.
    p10_s, p90_s : float
        The message's ``remaining_p10_s`` and ``remaining_p90_s``, s (NaN when unknown).
    """

    time_s: float
    remaining_s: float
    valid: bool
    status: int
    reason: str = ""
    p10_s: float = math.nan
    p90_s: float = math.nan


@dataclass(frozen=True)
class Checkpoint:
    """Prediction vs truth at one checkpoint (the latest valid prediction at or before it)."""

    checkpoint_min: float
    time_s: float
    predicted_min: float
    true_min: float
    p10_min: float = math.nan
    p90_min: float = math.nan

    @property
    def error_min(self) -> float:
        """Predicted minus true remaining runtime, min."""
        return self.predicted_min - self.true_min


def compare_at_checkpoints(points: Sequence[RuntimePoint], truth: RuntimeTruth,
                           checkpoints_min: Sequence[float] = DEFAULT_CHECKPOINTS_MIN,
                           max_age_s: float = 600.0) -> list[Checkpoint]:
    """For each checkpoint (min from the recording start), the latest valid prediction at or before it.

    Checkpoints after the true end of the discharge, or with no valid
    prediction within ``max_age_s`` before them, are left out.
    """
    valid = sorted((p for p in points if p.valid and math.isfinite(p.remaining_s)), key=lambda p: p.time_s)
    times = np.array([p.time_s for p in valid])
    out = []
    for cp in checkpoints_min:
        t_cp = 60.0 * float(cp)
        if t_cp >= truth.runtime_s or not len(times):
            continue
        k = int(np.searchsorted(times, t_cp + 1e-6, side="right")) - 1
        if k < 0 or t_cp - times[k] > max_age_s:
            continue
        p = valid[k]
        out.append(Checkpoint(float(cp), p.time_s, p.remaining_s / 60.0, truth.remaining_s(p.time_s) / 60.0,
                              p.p10_s / 60.0, p.p90_s / 60.0))
    return out


def error_summary(checkpoints: Sequence[Checkpoint], truth: RuntimeTruth | None = None) -> dict[str, float]:
    """MAE (min), max |error| (min) and MAPE (%) over checkpoints (the paper's metrics)."""
    if not checkpoints:
        return {"n": 0, "mae_min": math.nan, "max_abs_error_min": math.nan, "mape_pct": math.nan}
    err = np.array([c.error_min for c in checkpoints])
    true = np.array([c.true_min for c in checkpoints])
    return {"n": len(checkpoints), "mae_min": float(np.mean(np.abs(err))),
            "max_abs_error_min": float(np.max(np.abs(err))),
            "mape_pct": float(100.0 * np.mean(np.abs(err) / np.maximum(true, 1e-9)))}


def plot_runtime(points: Sequence[RuntimePoint], truth: RuntimeTruth | None, path: str | os.PathLike[str], *,
                 title: str = "", checkpoints: Sequence[Checkpoint] = ()) -> Path:
    """PNG of predicted (and, when known, true) remaining runtime over the recording time."""
    from matplotlib.figure import Figure

    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(8.0, 4.8))
    ax = fig.subplots()
    valid = [p for p in points if p.valid and math.isfinite(p.remaining_s)]
    invalid = [p for p in points if not p.valid]
    if valid:
        ax.plot([p.time_s / 60 for p in valid], [p.remaining_s / 60 for p in valid], ".", ms=3,
                label="predicted (/remaining_runtime)")
    if invalid:
        ax.plot([p.time_s / 60 for p in invalid], [0.0] * len(invalid), "x", color="tab:red", ms=4,
                label="invalid prediction")
    if truth is not None:
        t_end = truth.runtime_s / 60
        ax.plot([0.0, t_end], [t_end, 0.0], "-", color="k", lw=1.2,
                label=f"true (until {truth.stop_voltage_v:.2f} V at {t_end:.0f} min)")
    if checkpoints:
        ax.plot([c.time_s / 60 for c in checkpoints], [c.predicted_min for c in checkpoints], "o", mfc="none",
                color="tab:orange", label="checkpoints")
    ax.set_xlabel("time since start of the recording (min)")
    ax.set_ylabel("remaining runtime (min)")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return out


# ---------------------------------------------------------------------------
# Output bag
# ---------------------------------------------------------------------------


def _msg_definition_dirs() -> list[Path]:
    dirs = [Path(sys.prefix) / "share" / "battery_predictor_msgs" / "msg"]
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / "battery_predictor_msgs" / "msg")
    dirs.append(Path(__file__).resolve().parents[1] / "msg_defs" / "msg")
    return dirs


def output_typestore():
    """The ROS 2 Jazzy type store of ``rosbags`` plus the battery_predictor_msgs types (from their .msg files)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    for msgtype in CUSTOM_TYPES:
        stem = msgtype.rsplit("/", 1)[-1]
        for directory in _msg_definition_dirs():
            f = directory / f"{stem}.msg"
            if f.is_file():
                ts.register(get_types_from_msg(f.read_text(encoding="utf-8"), msgtype))
                break
        else:
            raise BagError(f"cannot find the definition {stem}.msg of {msgtype} (looked in "
                           f"{', '.join(str(d) for d in _msg_definition_dirs())})")
    return ts


class OutputBag:
    """A new rosbag2 directory (MCAP storage) that takes CDR-serialised messages (thread-safe).

    Foxglove opens its ``.mcap`` file, ``rosbags`` and ``ros2 bag`` the directory;
    the custom types' definitions are embedded.

    Parameters
    ----------
    path : str or os.PathLike
        Directory to create (must not exist).
    metadata : dict, optional
        Stored as the bag's custom data (values JSON-encoded).
    """

    def __init__(self, path: str | os.PathLike[str], metadata: dict[str, Any] | None = None) -> None:
        import json
        import threading

        from rosbags.rosbag2 import StoragePlugin, Writer

        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path}: output bag already exists (choose another --out or remove it)")
        self._ts = output_typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        for key, value in (metadata or {}).items():
            self._writer.set_custom_data(str(key), json.dumps(value, default=str))
        self._conns: dict[str, Any] = {}
        self._lock = threading.Lock()
        self.counts: dict[str, int] = {}

    def write(self, topic: str, msgtype: str, time_ns: int, data: bytes) -> None:
        """Append one message (``time_ns``: log time)."""
        with self._lock:
            conn = self._conns.get(topic)
            if conn is None:
                conn = self._conns[topic] = self._writer.add_connection(topic, msgtype, typestore=self._ts)
            self._writer.write(conn, int(time_ns), bytes(data))
            self.counts[topic] = self.counts.get(topic, 0) + 1

    def close(self) -> None:
        """Finish the bag (writes metadata.yaml)."""
        with self._lock:
            if self._writer is not None:
                self._writer.close()
                self._writer = None
