"""Opening a bag and reading its messages, turning every kind of corruption into :class:`BagError`.

The four layers of corruption checks of :mod:`battery_predictor.io.bags` live here: ``rosbags``
while opening, CDR decoding, message counts against the index, and the SHA-256 per topic that
:func:`~battery_predictor.io.bags.writer.write_recording_bag` stores.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from battery_predictor.errors import BagError, BatteryPredictorError
from battery_predictor.io.bags.schema import KEY_SHA256, RESERVED_PREFIX, typestore

if TYPE_CHECKING:
    from _hashlib import HASH

    from rosbags.rosbag2 import Reader


def one_line(text: object) -> str:
    """``str(text)`` on one line (an exception's message, say), runs of white space made one space."""
    return " ".join(str(text).split())


def resolve(path: str | os.PathLike[str]) -> Path:
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


def corrupt(p: Path, exc: BaseException) -> BagError:
    return BagError(
        f"{p}: corrupt or truncated bag ({type(exc).__name__}: {one_line(exc)}); "
        "if the recorder was killed, `mcap recover` may salvage the messages"
    )


@contextmanager
def open_reader(p: Path) -> Iterator[Any]:
    from rosbags.rosbag2 import Reader

    try:
        reader = Reader(p)
        reader.open()
    except BatteryPredictorError:
        raise
    except MemoryError as exc:
        raise corrupt(p, exc) from None
    except Exception as exc:  # noqa: BLE001 - rosbags raises many types on corrupt input
        raise corrupt(p, exc) from None
    try:
        yield reader
    finally:
        try:
            reader.close()
        except Exception:  # noqa: BLE001 - closing a broken reader must not hide the real error
            pass


def read_custom_data(p: Path) -> dict[str, str]:
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
        raise corrupt(p, exc) from None
    custom = info.get("custom_data") if isinstance(info, dict) else None
    return {str(k): str(v) for k, v in (custom or {}).items()}


def decode_custom(custom: dict[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, raw in custom.items():
        if key.startswith(RESERVED_PREFIX):
            continue
        try:
            out[key] = json.loads(raw)
        except ValueError:
            out[key] = raw  # written by another tool: keep the string
    return out


def list_topics(reader: Reader) -> dict[str, tuple[str, int]]:
    out: dict[str, tuple[str, int]] = {}
    for conn in reader.connections:
        msgtype, count = out.get(conn.topic, (conn.msgtype, 0))
        if msgtype != conn.msgtype:
            msgtype = f"{msgtype}|{conn.msgtype}"
        out[conn.topic] = (msgtype, count + int(conn.msgcount))
    return dict(sorted(out.items()))


def digest_update(h: HASH, log_ns: int, raw: bytes | memoryview) -> None:
    h.update(int(log_ns).to_bytes(8, "little", signed=False))
    h.update(len(raw).to_bytes(8, "little"))
    h.update(raw)


def read_messages(p: Path, reader: Reader, topic_names: set[str], custom: dict[str, str]) -> dict[str, list[tuple[int, Any]]]:
    """Deserialised messages per topic as (log_time_ns, msg), verified against the bag's counts and digests."""
    ts = typestore()
    conns = [c for c in reader.connections if c.topic in topic_names]
    out: dict[str, list[tuple[int, Any]]] = {name: [] for name in topic_names}
    hashes = {name: hashlib.sha256() for name in topic_names}
    try:
        for conn, log_ns, raw in reader.messages(connections=conns):
            digest_update(hashes[conn.topic], log_ns, raw)
            try:
                msg = ts.deserialize_cdr(raw, conn.msgtype)
            except Exception as exc:  # noqa: BLE001
                raise BagError(
                    f"{p}: corrupt bag: message {len(out[conn.topic])} on {conn.topic} [{conn.msgtype}] "
                    f"cannot be decoded ({type(exc).__name__}: {one_line(exc)})"
                ) from None
            out[conn.topic].append((int(log_ns), msg))
    except BatteryPredictorError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many types on corrupt input
        raise corrupt(p, exc) from None
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
        stored = json.loads(custom.get(KEY_SHA256, "{}"))
    except ValueError:
        stored = {}
    for name in sorted(topic_names):
        want = stored.get(name) if isinstance(stored, dict) else None
        if want is not None and want != hashes[name].hexdigest():
            raise BagError(f"{p}: corrupt bag: the messages on {name} do not match the SHA-256 stored when it was written")
    return out
