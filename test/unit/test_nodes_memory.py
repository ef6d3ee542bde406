"""battery_predictor/nodes/memory.py: the node processes give memory back (issue 13); ROS-free parts."""

from __future__ import annotations

import os
from pathlib import Path

from battery_predictor.nodes.memory import FASTDDS_PROFILE_XML, configure_process
from battery_predictor.processes import resident_mb


def test_fast_dds_gets_the_dynamic_profile_unless_the_user_chose_one() -> None:
    env: dict[str, str] = {}
    configure_process(env, allocator=False)
    profile = Path(env["FASTRTPS_DEFAULT_PROFILES_FILE"])
    assert profile.read_text() == FASTDDS_PROFILE_XML and "<historyMemoryPolicy>DYNAMIC<" in FASTDDS_PROFILE_XML
    assert env["RMW_FASTRTPS_USE_QOS_FROM_XML"] == "1"
    configure_process(env, allocator=False)  # idempotent
    assert Path(env["FASTRTPS_DEFAULT_PROFILES_FILE"]) == profile

    own = {"FASTDDS_DEFAULT_PROFILES_FILE": "/etc/my_profiles.xml"}
    configure_process(own, allocator=False)
    assert own == {"FASTDDS_DEFAULT_PROFILES_FILE": "/etc/my_profiles.xml"}
    other_rmw = {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}
    configure_process(other_rmw, allocator=False)
    assert other_rmw == {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}


def test_resident_memory_of_this_process() -> None:
    assert 10.0 < resident_mb() < 100_000.0
    assert resident_mb(os.getpid()) > 10.0
