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
    ``temperature`` is in °C, NaN when not measured. ``cell_voltage`` carries the
    recording's series-group voltages (``Recording.group_voltage_v``, V, NaN where a group
    was not measured; empty when there are none). The sample time is
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
    :func:`battery_predictor.io.validation.check_current_sign`).

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

from battery_predictor.io.bags.info import bag_info
from battery_predictor.io.bags.reader import read_recording_bag
from battery_predictor.io.bags.schema import (
    BATTERY_STATE_TYPE,
    DEFAULT_BATTERY_STATE_TOPIC,
    DEFAULT_RELAY_PREFIX,
    DEFAULT_START_NS,
    FLOAT32_TYPE,
    FLOAT64_TYPE,
    RELAY_SCALAR_TYPES,
    RELAY_SUFFIXES,
    RESERVED_PREFIX,
    STYLES,
    TEMPERATURE_TYPE,
)
from battery_predictor.io.bags.writer import write_recording_bag

__all__ = [
    "BATTERY_STATE_TYPE",
    "DEFAULT_BATTERY_STATE_TOPIC",
    "DEFAULT_RELAY_PREFIX",
    "DEFAULT_START_NS",
    "FLOAT32_TYPE",
    "FLOAT64_TYPE",
    "RELAY_SCALAR_TYPES",
    "RELAY_SUFFIXES",
    "RESERVED_PREFIX",
    "STYLES",
    "TEMPERATURE_TYPE",
    "bag_info",
    "read_recording_bag",
    "write_recording_bag",
]
