"""One entry point for every recording format, and CSV <-> bag conversion.

``load_recording`` picks the reader from the path:

* ``*.csv`` -> :func:`battery_predictor.io.csv_io.load_csv`;
* a directory with ``metadata.yaml`` or a ``.mcap`` file in it, or a
  ``*.mcap`` / ``*.db3`` file -> :func:`battery_predictor.io.bags.read_recording_bag`;
* anything else -> :class:`~battery_predictor.errors.InputDataError`.

``csv_to_bag`` / ``bag_to_csv`` let the public measured data sets be replayed
like robot recordings (and robot bags be inspected as CSV).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from battery_predictor.errors import InputDataError
from battery_predictor.io.bags import read_recording_bag, write_recording_bag
from battery_predictor.io.csv_io import load_csv, save_csv
from battery_predictor.recording import Recording

BAG_SUFFIXES = (".mcap", ".db3")


def _is_bag(p: Path) -> bool:
    if p.is_dir():
        return (p / "metadata.yaml").is_file() or any(p.glob("*.mcap")) or any(p.glob("*.db3"))
    return p.suffix.lower() in BAG_SUFFIXES


def load_recording(
    path: str | os.PathLike[str],
    *,
    expect_discharge: bool | None = None,
    drop_nan: bool = False,
    duplicate_times: str = "error",
    topic: str | None = None,
) -> Recording:
    """Load a recording from a CSV file or a rosbag2 bag (directory or ``.mcap``).

    Parameters
    ----------
    path : str or os.PathLike
        ``.csv`` file, rosbag2 directory, or ``.mcap``/``.db3`` file.
    expect_discharge : bool, optional
        Run the current-sign check. Default (None): the reader's default,
        True for CSV, False for bags (robot recordings may include charging).
    drop_nan : bool
        Drop invalid samples instead of raising (see the readers).
    duplicate_times : {"error", "keep_first", "keep_last"}
        CSV only: repeated timestamps (bags always keep the last message).
    topic : str, optional
        Bags only: the BatteryState topic or relay prefix to read.
    """
    p = Path(path)
    if p.suffix.lower() == ".csv" and not p.is_dir():
        if topic is not None:
            raise InputDataError(f"{p}: topic= applies to bags, not to CSV files")
        return load_csv(
            p,
            expect_discharge=True if expect_discharge is None else expect_discharge,
            drop_nan=drop_nan,
            duplicate_times=duplicate_times,
        )
    if (p.exists() and _is_bag(p)) or (not p.exists() and p.suffix.lower() in BAG_SUFFIXES):
        return read_recording_bag(
            p, topic=topic, drop_nan=drop_nan, expect_discharge=bool(expect_discharge)
        )
    if not p.exists():
        raise InputDataError(f"{p}: file not found")
    what = "directory without metadata.yaml or .mcap files" if p.is_dir() else f"file type {p.suffix or '(no suffix)'!r}"
    raise InputDataError(
        f"{p}: unknown recording format ({what}); expected a .csv file, a rosbag2 directory or a .mcap file"
    )


def csv_to_bag(
    csv_path: str | os.PathLike[str],
    bag_path: str | os.PathLike[str],
    style: str = "battery_state",
    *,
    topic_prefix: str | None = None,
    metadata: dict[str, Any] | None = None,
    overwrite: bool = False,
    expect_discharge: bool = True,
    drop_nan: bool = False,
    duplicate_times: str = "error",
) -> Path:
    """Convert a measurement CSV to a rosbag2 MCAP bag of the given style.

    The CSV is validated like :func:`load_csv` (same options). The bag's
    metadata holds the CSV's load metadata, ``source_csv`` (the file name) and
    ``metadata``.
    """
    rec = load_csv(csv_path, expect_discharge=expect_discharge, drop_nan=drop_nan, duplicate_times=duplicate_times)
    meta = {"source_csv": Path(csv_path).name, **(metadata or {})}
    return write_recording_bag(rec, bag_path, style=style, topic_prefix=topic_prefix, metadata=meta, overwrite=overwrite)


def bag_to_csv(
    bag_path: str | os.PathLike[str],
    csv_path: str | os.PathLike[str],
    *,
    topic: str | None = None,
    drop_nan: bool = False,
    overwrite: bool = False,
) -> Path:
    """Convert a bag (either topic style) to ``time_s,voltage_V,current_A[,temperature_C][,group<k>_voltage_V]``.

    The bag's metadata is not kept (CSV has no place for it). ``time_s`` is
    the bag's time axis (see :mod:`battery_predictor.io.bags`).
    """
    rec = read_recording_bag(bag_path, topic=topic, drop_nan=drop_nan)
    return save_csv(rec, csv_path, overwrite=overwrite)
