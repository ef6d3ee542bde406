"""Give memory back after a large request: the node processes' middleware and allocator settings.

Why: a ``CanAcceptRoute`` request is bounded to 500 sections, but a section's ``name`` is a free
string, and Jazzy's generated type support checks bounds only while serialising, never while
deserialising, so any client can send a request of many megabytes. Measured on the node started
by ``battery-predictor run`` (``test/ros/test_route_fuzz.py``): with rmw_fastrtps' defaults one
50 MB request (500 sections with 100 kB names) left the process 113 MB larger for good (415 ->
528 MB). Two things keep it:

* Fast DDS keeps each reader's sample buffers at the size of the largest sample received
  (rmw_fastrtps sets the history memory policy ``PREALLOCATED_WITH_REALLOC``);
* glibc's allocator raises its mmap threshold after freeing a large block (up to 32 MB), so the
  next large buffers come from the heap of the thread that served the request and stay mapped.

:func:`configure_process` (called before ``rclpy.init`` by the node entry points) switches Fast
DDS to ``DYNAMIC`` sample buffers, freed after each sample is taken, through an XML profile
(only when the user has not set a profiles file of their own), and fixes glibc's mmap threshold
at 64 KiB. With both, the same process returns to its size within a few seconds after each such
request (415 -> 511 MB at the peak -> 415 MB).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import hashlib
import os
import sys
import tempfile
from collections.abc import MutableMapping
from pathlib import Path

#: Fast DDS profile: every reader and writer allocates sample buffers per sample and frees them.
FASTDDS_PROFILE_XML = """<?xml version="1.0" encoding="UTF-8"?>
<!-- battery_predictor: sample buffers freed after use (see battery_predictor/nodes/memory.py) -->
<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <profiles>
    <data_reader profile_name="battery_predictor_reader" is_default_profile="true">
      <historyMemoryPolicy>DYNAMIC</historyMemoryPolicy>
    </data_reader>
    <data_writer profile_name="battery_predictor_writer" is_default_profile="true">
      <historyMemoryPolicy>DYNAMIC</historyMemoryPolicy>
    </data_writer>
  </profiles>
</dds>
"""
#: Environment variables through which a user chooses Fast DDS profiles (then they are left alone).
PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
#: Allocations at least this large are mmapped and given back on free, bytes (glibc).
MMAP_THRESHOLD_BYTES = 64 * 1024
_M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter number


def _profile_file() -> Path:
    """The profile XML in the temporary directory (written once per content, atomically)."""
    digest = hashlib.sha1(FASTDDS_PROFILE_XML.encode()).hexdigest()[:12]
    path = Path(tempfile.gettempdir()) / f"battery_predictor_fastdds_{digest}.xml"
    if not path.is_file() or path.read_text(errors="replace") != FASTDDS_PROFILE_XML:
        fd, tmp = tempfile.mkstemp(prefix=path.name, dir=path.parent)
        with os.fdopen(fd, "w") as fh:
            fh.write(FASTDDS_PROFILE_XML)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    return path


def _libc():
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return None
    return libc if hasattr(libc, "mallopt") else None


def configure_process(environ: MutableMapping[str, str] | None = None, *, allocator: bool = True) -> list[str]:
    """Set up this process so that the middleware and the allocator give memory back.

    Call before ``rclpy.init`` (Fast DDS reads its profiles when the first participant is made).

    Parameters
    ----------
    environ : mutable mapping, optional
        The environment to set the Fast DDS variables in (default ``os.environ``).
    allocator : bool
        Also fix glibc's mmap threshold for this process (default True).

    Returns
    -------
    list of str
        What was changed (empty when nothing was).
    """
    env = os.environ if environ is None else environ
    changed = []
    rmw = env.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    if rmw.startswith("rmw_fastrtps") and not any(env.get(name) for name in PROFILE_VARIABLES):
        try:
            env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(_profile_file())
            env["RMW_FASTRTPS_USE_QOS_FROM_XML"] = "1"
            changed.append("Fast DDS sample buffers: DYNAMIC")
        except OSError:  # no writable temporary directory: keep the middleware's defaults
            pass
    libc = _libc() if allocator else None
    if libc is not None and libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1:
        changed.append(f"malloc mmap threshold: {MMAP_THRESHOLD_BYTES} B")
    return changed
