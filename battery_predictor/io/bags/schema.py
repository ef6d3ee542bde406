"""What a battery bag holds: styles, message types, topic names, reserved metadata keys, time anchor."""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

#: Topic layouts (see :mod:`battery_predictor.io.bags`).
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
KEY_STYLE = RESERVED_PREFIX + "style"
KEY_SOURCE = RESERVED_PREFIX + "source"
KEY_ORIGIN_NS = RESERVED_PREFIX + "time_origin_ns"
KEY_BASE_S = RESERVED_PREFIX + "time_base_s"
KEY_SHA256 = RESERVED_PREFIX + "sha256"

#: Where recordings with a relative time axis are anchored (2024-01-01T00:00:00Z).
DEFAULT_START_NS = 1_704_067_200 * 1_000_000_000
#: time_s[0] at or above this is taken as epoch seconds.
EPOCH_THRESHOLD_S = 1e8


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)
