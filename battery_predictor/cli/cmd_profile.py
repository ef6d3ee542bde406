"""``battery-predictor profile``: generate load profiles (seed paper 5.1.4 and 5.2.2).

Sub-commands::

    battery-predictor profile temi [--seed S] [--duration-h H] [--charge-ah Q] [--points N] [--config YAML]
    battery-predictor profile route --from NODE --to NODE --payload-kg KG [--start charger]
                                    [--seed S] [--mode sampled|mean] [--station YAML] [--currents YAML]
    battery-predictor profile longest-route [--payload-kg 80] [--seed S] [--mode sampled|mean]
    battery-predictor profile stepwise [--currents-a 0.5,1,2,3,4,5,6,7,8] [--step-s 600] [--repeat N]

Every sub-command also takes ``--out CSV`` (duration_s,current_a,label),
``--plot PNG``, ``--psu-dir DIR`` (EA PSB 10060-120 sequences of <= 99
points, ``--psu-voltage-v`` discharge limit) and ``--json`` (print one JSON
object instead of the text summary).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from battery_predictor.cli.common import check_output_dir, check_output_file, check_plot_file
from battery_predictor.errors import ProfileError
from battery_predictor.jsonutil import json_default as _json_default
from battery_predictor.profiles.load_profile import LoadProfile
from battery_predictor.profiles.psu_export import write_psu_csv
from battery_predictor.profiles.ranger import (
    DEFAULT_POINT_DURATION_S,
    load_ranger_currents,
    longest_route,
    route_from_station,
    route_profile,
    stepwise_profile,
)
from battery_predictor.profiles.station import load_station
from battery_predictor.profiles.temi import generate_usage_profile, load_usage_config


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``profile`` command and its sub-commands."""
    parser = subparsers.add_parser(
        "profile",
        help="generate load profiles (Temi usage, Ranger routes, stepwise experiment)",
        description=__doc__.split("\n\n")[0],
    )
    sub = parser.add_subparsers(dest="profile_command", required=True)

    temi = sub.add_parser("temi", help="stochastic Temi information-robot profile (section 5.1.4)")
    temi.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    temi.add_argument("--duration-h", type=float, default=None, help="stop after this many hours")
    temi.add_argument("--charge-ah", type=float, default=None, help="stop after this much charge in Ah")
    temi.add_argument("--points", type=int, default=None, help="stop after this many curve points")
    temi.add_argument("--config", type=Path, default=None, help="usage YAML (default: params/temi_usage.yaml)")
    _add_output_options(temi)
    temi.set_defaults(func=_cmd_temi)

    route = sub.add_parser("route", help="Ranger Mini job route on the station graph (section 5.2.2)")
    route.add_argument("--from", dest="pickup", required=True, help="pickup location, e.g. platform11_south")
    route.add_argument("--to", dest="dropoff", required=True, help="dropoff location, e.g. platform13_south")
    route.add_argument("--payload-kg", type=float, required=True, help="luggage mass in kg")
    route.add_argument("--start", default="charger", help="where the robot waits and returns to (default: %(default)s)")
    route.add_argument("--loading-s", type=float, default=60.0, help="standstill at the pickup in s (default: %(default)s)")
    route.add_argument("--unloading-s", type=float, default=60.0, help="standstill at the dropoff in s (default: %(default)s)")
    route.add_argument("--station", type=Path, default=None, help="station YAML (default: params/minden_station.yaml)")
    _add_ranger_options(route)
    _add_output_options(route)
    route.set_defaults(func=_cmd_route)

    longest = sub.add_parser("longest-route", help="the paper's longest route, 97 points, 31.67 min (section 5.2.2)")
    longest.add_argument("--payload-kg", type=float, default=80.0, help="luggage mass in kg (default: %(default)s)")
    _add_ranger_options(longest)
    _add_output_options(longest)
    longest.set_defaults(func=_cmd_longest)

    stepwise = sub.add_parser("stepwise", help="stepwise currents for 10 min each until 45.00 V (section 5.2.2)")
    stepwise.add_argument("--currents-a", default="0.5,1,2,3,4,5,6,7,8", help="comma-separated currents in A")
    stepwise.add_argument("--step-s", type=float, default=600.0, help="duration of each step in s (default: %(default)s)")
    stepwise.add_argument("--stop-voltage-v", type=float, default=45.0, help="stop voltage in V (default: %(default)s)")
    stepwise.add_argument("--repeat", type=int, default=1, help="number of passes to unroll (default: %(default)s)")
    _add_output_options(stepwise)
    stepwise.set_defaults(func=_cmd_stepwise)


def _add_ranger_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=int, default=0, help="random seed for --mode sampled (default: %(default)s)")
    parser.add_argument("--mode", choices=("sampled", "mean"), default="sampled",
                        help="currents drawn from the KDEs or their means (default: %(default)s)")
    parser.add_argument("--point-duration-s", type=float, default=DEFAULT_POINT_DURATION_S,
                        help="longest driving curve point in s (default: %(default)s)")
    parser.add_argument("--currents", type=Path, default=None, help="currents YAML (default: params/ranger_currents.yaml)")


def _add_output_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=None, help="write the profile CSV (duration_s,current_a,label)")
    parser.add_argument("--plot", type=Path, default=None, help="write a step plot (PNG, PDF, SVG...)")
    parser.add_argument("--psu-dir", type=Path, default=None, help="write EA PSB 10060-120 sequence CSVs here")
    parser.add_argument("--psu-voltage-v", type=float, default=None,
                        help="discharge voltage limit for the PSU (default: the profile's stop voltage)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _check_outputs(args: argparse.Namespace) -> None:
    """Every output path of ``_add_output_options`` is checked before the profile is made."""
    if args.out is not None:
        check_output_file(args.out, "--out", suffixes=(".csv",))
    if args.plot is not None:
        check_plot_file(args.plot)
    if args.psu_dir is not None:
        check_output_dir(args.psu_dir, "--psu-dir")


def _cmd_temi(args: argparse.Namespace) -> int:
    _check_outputs(args)
    if args.duration_h is None and args.charge_ah is None and args.points is None:
        raise ProfileError("profile temi: give --duration-h, --charge-ah or --points")
    config = load_usage_config(args.config)
    profile = generate_usage_profile(
        config,
        args.seed,
        max_duration_s=None if args.duration_h is None else args.duration_h * 3600.0,
        max_charge_ah=args.charge_ah,
        max_points=args.points,
    )
    return _emit("temi", profile, args)


def _cmd_route(args: argparse.Namespace) -> int:
    _check_outputs(args)
    station = load_station(args.station)
    route = route_from_station(
        station, args.start, args.pickup, args.dropoff, args.payload_kg,
        loading_s=args.loading_s, unloading_s=args.unloading_s,
    )
    currents = load_ranger_currents(args.currents)
    profile = route_profile(route, currents, args.seed, args.point_duration_s, args.mode)
    return _emit("route", profile, args)


def _cmd_longest(args: argparse.Namespace) -> int:
    _check_outputs(args)
    currents = load_ranger_currents(args.currents)
    profile = route_profile(longest_route(args.payload_kg), currents, args.seed, args.point_duration_s, args.mode)
    return _emit("longest-route", profile, args)


def _cmd_stepwise(args: argparse.Namespace) -> int:
    _check_outputs(args)
    try:
        currents = [float(x) for x in args.currents_a.split(",") if x.strip()]
    except ValueError:
        raise ProfileError(f"profile stepwise: --currents-a {args.currents_a!r} is not a comma-separated list of numbers") from None
    profile = stepwise_profile(currents, args.step_s, stop_voltage_v=args.stop_voltage_v)
    if args.repeat != 1:
        profile = profile.repeat(args.repeat)
    return _emit("stepwise", profile, args)


def _emit(kind: str, profile: LoadProfile, args: argparse.Namespace) -> int:
    outputs: dict[str, Any] = {}
    if args.out is not None:
        outputs["csv"] = str(profile.to_csv(args.out))
    if args.plot is not None:
        from battery_predictor.profiles.plot import plot_profile

        outputs["plot"] = str(plot_profile(profile, args.plot))
    if args.psu_dir is not None:
        outputs["psu_files"] = [str(p) for p in write_psu_csv(profile, args.psu_dir, args.psu_voltage_v)]
    summary: dict[str, Any] = {
        "kind": kind,
        "points": profile.n_points,
        "total_duration_s": profile.total_duration_s,
        "total_duration_min": profile.total_duration_s / 60.0,
        "charge_ah": profile.charge_ah,
        "mean_current_a": profile.mean_current_a,
        "labels": profile.label_summary(),
        "metadata": profile.metadata,
        "outputs": outputs,
    }
    if args.json:
        print(json.dumps(summary, default=_json_default))
        return 0
    print(f"{kind}: {profile.n_points} curve points, {profile.total_duration_s:.1f} s "
          f"({profile.total_duration_s / 60.0:.2f} min), {profile.charge_ah:.4f} Ah, "
          f"mean {profile.mean_current_a:.3f} A")
    for label, entry in summary["labels"].items():
        print(f"  {label or '(no label)'}: {entry['points']} points, {entry['duration_s']:.1f} s, {entry['charge_ah']:.4f} Ah")
    for name, value in outputs.items():
        print(f"  {name}: {', '.join(value) if isinstance(value, list) else value}")
    return 0


