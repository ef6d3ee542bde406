"""``battery-predictor lab``: the emulation lab that generates the shipped bags.

Sub-commands::

    battery-predictor lab list                         # the experiment catalogue
    battery-predictor lab make-bags --out bags [--only NAME ...] [--jobs 2]
    battery-predictor lab run NAME --out DIR           # one experiment

Every bag is EMULATED (see ``bags/README.md``): a seeded liionpack "real
pack" richer than the fitted SPM, driven by a seeded load profile and
measured by emulated instruments (10 Hz, 0.01 V / 0.1 A, 5 s averages).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from battery_predictor.cli.common import check_output_dir, print_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("lab", help="emulated lab: regenerate the shipped bags (EMULATED data, not measured)")
    lab = p.add_subparsers(dest="lab_command", required=True)

    ls = lab.add_parser("list", help="list the experiment catalogue")
    ls.add_argument("--json", action="store_true", help="print one JSON object")
    ls.set_defaults(func=run_list)

    mk = lab.add_parser("make-bags", help="regenerate every shipped bag (deterministic)")
    mk.add_argument("--out", required=True, help="output directory (e.g. bags)")
    mk.add_argument("--only", nargs="+", default=None, metavar="NAME", help="only these experiments")
    mk.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    mk.add_argument("--params-dir", default=None, help="directory with temi.yaml / ranger_mini.yaml "
                                                       "(default: the shipped params)")
    mk.add_argument("--json", action="store_true", help="print one JSON object at the end")
    mk.set_defaults(func=run_make_bags)

    one = lab.add_parser("run", help="run one experiment and write its bag")
    one.add_argument("name", help="experiment name (see `lab list`)")
    one.add_argument("--out", required=True, help="output directory")
    one.add_argument("--params-dir", default=None, help="directory with the robot params files")
    one.add_argument("--json", action="store_true", help="print one JSON object")
    one.set_defaults(func=run_one)


def run_list(args: argparse.Namespace) -> int:
    from battery_predictor.lab.experiments import catalogue

    rows = [{"name": e.name, "robot": e.robot, "kind": e.kind, "pack_id": e.pack_id, "profile_seed": e.profile_seed,
             "payload_kg": e.payload_kg, "ambient_temperature_k": e.ambient_temperature_k} for e in catalogue()]
    if args.json:
        print_json({"experiments": rows})
        return 0
    for r in rows:
        extra = f", payload {r['payload_kg']:g} kg" if r["payload_kg"] is not None else ""
        seed = f", profile seed {r['profile_seed']}" if r["profile_seed"] is not None else ""
        print(f"{r['name']}: {r['robot']} {r['kind']} on {r['pack_id']}{seed}{extra}")
    return 0


def _line(res: dict[str, Any]) -> str:
    truth = res["truth"]
    if "runtime_s" in truth:
        what = f"runtime to {truth['stop_voltage_v']:.2f} V {truth['runtime_s'] / 60:.1f} min"
    else:
        v = truth["voltage_at_1_70_a_after_cycle_v"]
        what = (f"start SOC {truth['start_soc']:.4f}, V at 1.70 A after cycles {v[0]:.3f} / {v[1]:.3f} V, "
                f"further cycle {'ok' if truth['further_cycle_stays_above_threshold'] else 'rejected'}")
    return f"{res['name']}: {res['bytes'] / 1e6:.2f} MB, {what} ({res['seconds']:.0f} s)"


def run_make_bags(args: argparse.Namespace) -> int:
    from battery_predictor.lab.experiments import make_bags

    check_output_dir(args.out, "--out")
    tic = time.perf_counter()

    def progress(res: dict[str, Any]) -> None:
        if not args.json:
            print(_line(res), flush=True)
        else:
            print(_line(res), file=sys.stderr, flush=True)

    results = make_bags(args.out, args.only, jobs=max(1, args.jobs), params_dir=args.params_dir, progress=progress)
    total = sum(r["bytes"] for r in results)
    seconds = time.perf_counter() - tic
    if args.json:
        print_json({"bags": results, "total_bytes": total, "seconds": seconds})
        return 0
    print(f"{len(results)} bags, {total / 1e6:.2f} MB in {args.out} ({seconds:.0f} s)")
    return 0


def run_one(args: argparse.Namespace) -> int:
    from battery_predictor.lab.experiments import find_experiments, run_experiment

    check_output_dir(args.out, "--out")
    res = run_experiment(find_experiments([args.name])[0], args.out, params_dir=args.params_dir)
    if args.json:
        print_json(res)
    else:
        print(_line(res))
    return 0
