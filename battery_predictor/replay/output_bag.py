"""The output bag of a replay: the nodes' messages as a rosbag2 MCAP directory with the custom types."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from battery_predictor.errors import BagError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

#: Custom message types the output bag needs definitions for.
CUSTOM_TYPES = ("battery_predictor_msgs/msg/PackState", "battery_predictor_msgs/msg/RemainingRuntime",
                "battery_predictor_msgs/msg/RouteSection")


def _msg_definition_dirs() -> list[Path]:
    dirs = [Path(sys.prefix) / "share" / "battery_predictor_msgs" / "msg"]
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / "battery_predictor_msgs" / "msg")
    dirs.append(Path(__file__).resolve().parents[2] / "msg_defs" / "msg")
    return dirs


def output_typestore() -> Typestore:
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
        self._writer: Writer | None = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        for key, value in (metadata or {}).items():
            self._writer.set_custom_data(str(key), json.dumps(value, default=str))
        self._conns: dict[str, Any] = {}
        self._lock = threading.Lock()
        self.counts: dict[str, int] = {}

    def write(self, topic: str, msgtype: str, time_ns: int, data: bytes) -> None:
        """Append one message (``time_ns``: log time)."""
        with self._lock:
            assert self._writer is not None, "write after close"
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
