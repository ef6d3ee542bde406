"""A bag's battery topics as a time-ordered message stream on the recording's time axis."""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from battery_predictor.errors import BagError
from battery_predictor.io.bags import schema, storage
from battery_predictor.io.bags.reader import recording_from_messages, time_origin
from battery_predictor.io.bags.topics import select_topic
from battery_predictor.recording import Recording

#: Types of the battery input topics a replay plays.
INPUT_TYPES = (schema.BATTERY_STATE_TYPE, schema.FLOAT64_TYPE, schema.FLOAT32_TYPE, schema.TEMPERATURE_TYPE)


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

    def recording(self, *, drop_nan: bool = False) -> Recording:
        """The stream's battery messages as the recording :func:`~battery_predictor.io.bags.read_recording_bag`
        reads from the bag (the same decoding, relay pairing and checks), without reading the bag again."""
        ts = schema.typestore()
        got: dict[str, list[tuple[int, Any]]] = {}
        for msg in self.messages:
            try:
                decoded = ts.deserialize_cdr(msg.data, msg.msgtype)
            except Exception as exc:  # noqa: BLE001 - rosbags raises many types on corrupt input
                raise storage.corrupt(Path(self.source), exc) from None
            got.setdefault(msg.topic, []).append((msg.log_time_ns, decoded))
        origin = None if self._origin_ns is None else (self._origin_ns, self._base_s)
        return recording_from_messages(self.source, self.style, self.battery_topic, got, metadata=self.metadata,
                                       time_origin=origin, drop_nan=drop_nan)

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
    origin = time_origin(custom)
    return ReplayStream(source=str(src), style=style, battery_topic=name,
                        topics={m.topic: m.msgtype for m in messages}, messages=messages,
                        metadata=storage.decode_custom(custom), _origin_ns=origin[0] if origin else None,
                        _base_s=origin[1] if origin else 0.0)
