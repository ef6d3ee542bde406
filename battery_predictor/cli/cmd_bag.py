"""``battery-predictor bag``: inspect rosbag2 recordings and convert them to/from CSV.

Sub-commands::

    battery-predictor bag info BAG [--json]
    battery-predictor bag from-csv CSV BAG [--style battery_state|relay] [--topic-prefix T]
                                          [--meta KEY=VALUE ...] [--overwrite]
                                          [--duplicate-times error|keep_first|keep_last] [--drop-nan]
                                          [--no-sign-check]
    battery-predictor bag to-csv BAG CSV [--topic T] [--drop-nan] [--overwrite]

Errors are raised as BatteryPredictorError; ``main()`` prints them as one line
and exits with code 2.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from battery_predictor.cli.common import add_input_check_arguments, check_output_file
from battery_predictor.errors import InputDataError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bag`` command and its sub-commands."""
    parser = subparsers.add_parser(
        "bag",
        help="inspect rosbag2 (MCAP) recordings, convert CSV <-> bag",
        description=__doc__.split("\n\n")[0],
    )
    sub = parser.add_subparsers(dest="bag_command", required=True)

    info = sub.add_parser("info", help="topics, time span, metadata and a battery summary of a bag")
    info.add_argument("bag", help="rosbag2 directory or .mcap file")
    info.add_argument("--json", action="store_true", help="print the info as JSON")
    info.set_defaults(func=_cmd_info)

    from_csv = sub.add_parser("from-csv", help="write a measurement CSV as a rosbag2 MCAP bag")
    from_csv.add_argument("csv", help="CSV with time_s, voltage_V, current_A (>0 = discharge)")
    from_csv.add_argument("bag", help="bag directory to create")
    from_csv.add_argument(
        "--style",
        choices=("battery_state", "relay"),
        default="battery_state",
        help="sensor_msgs/BatteryState on one topic, or the ESP32/INA260 relay topics (default: %(default)s)",
    )
    from_csv.add_argument(
        "--topic-prefix",
        default=None,
        help="BatteryState topic (default /battery_state) or relay namespace (default /battery)",
    )
    from_csv.add_argument(
        "--meta",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="metadata to store in the bag (VALUE parsed as JSON if possible); repeatable",
    )
    from_csv.add_argument("--overwrite", action="store_true", help="replace an existing bag")
    add_input_check_arguments(from_csv)
    from_csv.set_defaults(func=_cmd_from_csv)

    to_csv = sub.add_parser("to-csv", help="write a bag as time_s,voltage_V,current_A[,temperature_C] CSV")
    to_csv.add_argument("bag", help="rosbag2 directory or .mcap file")
    to_csv.add_argument("csv", help="CSV file to write")
    to_csv.add_argument("--topic", default=None, help="BatteryState topic or relay prefix (default: auto-detect)")
    to_csv.add_argument("--drop-nan", action="store_true", help="drop samples with NaN voltage/current")
    to_csv.add_argument("--overwrite", action="store_true", help="replace an existing CSV")
    to_csv.set_defaults(func=_cmd_to_csv)


def _parse_meta(items: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputDataError(f"--meta {item!r}: expected KEY=VALUE")
        try:
            out[key.strip()] = json.loads(value)
        except ValueError:
            out[key.strip()] = value
    return out


def _fmt(value: Any, unit: str = "", digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if isinstance(value, float):
        return f"{value:.{digits}g}{unit}"
    return f"{value}{unit}"


#: Widest metadata value ``bag info`` prints; longer ones are summarised (``--json`` has them in full).
META_VALUE_CHARS = 60


def _short(value: Any) -> str:
    """One metadata value in at most :data:`META_VALUE_CHARS` characters."""
    text = json.dumps(value)
    if len(text) <= META_VALUE_CHARS:
        return text
    if isinstance(value, dict):
        keys = ", ".join(str(k) for k in value)
        keys = keys if len(keys) <= META_VALUE_CHARS - 12 else keys[:META_VALUE_CHARS - 15] + "..."
        return f"{{{len(value)} keys: {keys}}}"
    if isinstance(value, list):
        return f"[{len(value)} values]"
    return text[:META_VALUE_CHARS - 3] + "..."


def _cmd_info(args: argparse.Namespace) -> int:
    from battery_predictor.io.bags import bag_info

    info = bag_info(args.bag)
    if args.json:
        print(json.dumps(info, indent=2, sort_keys=False))
        return 0
    lines = [
        f"bag:          {info['path']}",
        f"messages:     {info['message_count']}",
        f"start:        {info['start'] or 'n/a'}",
        f"end:          {info['end'] or 'n/a'}",
        f"duration:     {info['duration_s']:.3f} s",
        "topics:",
    ]
    width = max((len(t["name"]) for t in info["topics"]), default=0)
    lines += [f"  {t['name']:<{width}}  {t['type']}  x{t['count']}" for t in info["topics"]] or ["  (none)"]
    if info["metadata"]:
        lines.append("metadata:" + ("  (long values shortened; --json prints them in full)"
                                    if any(len(json.dumps(v)) > META_VALUE_CHARS for v in info["metadata"].values())
                                    else ""))
        lines += [f"  {k}: {_short(v)}" for k, v in info["metadata"].items()]
    s = info["summary"]
    if s is None:
        lines.append(f"summary:      n/a ({info['summary_error']})")
    else:
        lines += [
            f"battery:      {info['battery_topic']} ({info['style']} style)",
            f"samples:      {s['samples']}",
            f"charge drawn: {_fmt(s['charge_drawn_ah'], ' Ah')}",
            f"voltage:      {_fmt(s['min_voltage_v'], ' V')} .. {_fmt(s['max_voltage_v'], ' V')}",
            f"mean current: {_fmt(s['mean_current_a'], ' A')} (positive = discharge)",
        ]
        if s["min_temperature_c"] is not None:
            lines.append(f"temperature:  {_fmt(s['min_temperature_c'], ' °C', 3)} .. {_fmt(s['max_temperature_c'], ' °C', 3)}")
    print("\n".join(lines))
    return 0


def _cmd_from_csv(args: argparse.Namespace) -> int:
    from battery_predictor.io.loader import csv_to_bag

    path = csv_to_bag(
        args.csv,
        args.bag,
        args.style,
        topic_prefix=args.topic_prefix,
        metadata=_parse_meta(args.meta),
        overwrite=args.overwrite,
        expect_discharge=args.expect_discharge,
        drop_nan=args.drop_nan,
        duplicate_times=args.duplicate_times,
    )
    print(f"wrote {path} ({args.style} style)")
    return 0


def _cmd_to_csv(args: argparse.Namespace) -> int:
    from battery_predictor.io.loader import bag_to_csv

    check_output_file(args.csv, "CSV", suffixes=(".csv",), overwrite=True)
    path = bag_to_csv(args.bag, args.csv, topic=args.topic, drop_nan=args.drop_nan, overwrite=args.overwrite)
    print(f"wrote {path}")
    return 0
