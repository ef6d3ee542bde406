"""Which topic of a bag holds the battery recording: the ``BatteryState`` topic or the relay group."""

from __future__ import annotations

from pathlib import Path

from battery_predictor.errors import BagError, option_hint
from battery_predictor.io.bags.schema import (
    BATTERY_STATE_TYPE,
    DEFAULT_BATTERY_STATE_TOPIC,
    DEFAULT_RELAY_PREFIX,
    RELAY_SCALAR_TYPES,
    RELAY_SUFFIXES,
    TEMPERATURE_TYPE,
)


def describe_topics(topics: dict[str, tuple[str, int]]) -> str:
    if not topics:
        return "the bag has no topics"
    return "topics in the bag: " + ", ".join(f"{name} [{msgtype}] x{count}" for name, (msgtype, count) in topics.items())


def relay_prefixes(topics: dict[str, tuple[str, int]]) -> list[str]:
    out = []
    for name, (msgtype, _) in topics.items():
        if name.endswith(RELAY_SUFFIXES["voltage"]) and msgtype in RELAY_SCALAR_TYPES:
            prefix = name[: -len(RELAY_SUFFIXES["voltage"])]
            cur = topics.get(prefix + RELAY_SUFFIXES["current"])
            if cur and cur[0] in RELAY_SCALAR_TYPES:
                out.append(prefix)
    return out


def select_topic(p: Path, topics: dict[str, tuple[str, int]], topic: str | None) -> tuple[str, str]:
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
                    if prefix in relay_prefixes(topics):
                        return "relay", prefix
            raise BagError(
                f"{p}: topic {topic!r} has type {msgtype}, which cannot be read as a battery recording "
                f"({supported}); {describe_topics(topics)}"
            )
        if topic.rstrip("/") in relay_prefixes(topics):
            return "relay", topic.rstrip("/")
        raise BagError(f"{p}: topic {topic!r} is not in the bag; {describe_topics(topics)}")
    states = [name for name, (msgtype, _) in topics.items() if msgtype == BATTERY_STATE_TYPE]
    if len(states) == 1:
        return "battery_state", states[0]
    if len(states) > 1:
        if DEFAULT_BATTERY_STATE_TOPIC in states:
            return "battery_state", DEFAULT_BATTERY_STATE_TOPIC
        raise BagError(f"{p}: several {BATTERY_STATE_TYPE} topics ({', '.join(states)})"
                       + option_hint("topic", None, "to choose one"))
    prefixes = relay_prefixes(topics)
    if len(prefixes) == 1:
        return "relay", prefixes[0]
    if len(prefixes) > 1:
        if DEFAULT_RELAY_PREFIX in prefixes:
            return "relay", DEFAULT_RELAY_PREFIX
        raise BagError(
            f"{p}: several relay topic groups ({', '.join(x + '/*' for x in prefixes)})"
            + option_hint("topic", None, "to choose one")
        )
    raise BagError(f"{p}: no supported battery topics ({supported}); {describe_topics(topics)}")
