"""``battery-predictor fleet fit``: fit many packs of one design, sharing one Optuna storage.

    battery-predictor fleet fit --params params/temi.yaml --data pack01.csv pack02.csv ... \\
        [--pack NAME=FILE[,FILE...]] --storage postgresql://user@host/db --out fits/ --trials 200 --seed 1

One study per pack (``<prefix><pack>``) in ``--storage``; run the same command in more processes or
on more machines, each with its own ``--seed``, and they share the work on every pack
(``battery_predictor/fitting/fleet.py``, ``docs/fleets.md``).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from battery_predictor.cli.common import add_input_check_arguments, data_options, load_data, print_json

if TYPE_CHECKING:
    from battery_predictor.fitting.fleet import PackFit
    from battery_predictor.recording import Recording


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fleet", help="fit many packs of one design, sharing one Optuna storage (several workers)",
                       description=__doc__.split("\n\n")[0])
    fleet_sub = p.add_subparsers(dest="fleet_command", required=True)
    f = fleet_sub.add_parser("fit", help="one study per pack in --storage; run it in several processes to share work")
    f.add_argument("--params", required=True, help="params YAML of the pack design to start from")
    f.add_argument("--data", nargs="+", default=[], metavar="FILE",
                   help="one pack per file (CSV or rosbag2 MCAP), named by the file's stem")
    f.add_argument("--pack", action="append", default=[], metavar="NAME=FILE[,FILE...]",
                   help="a pack with its own name and one or more files (repeatable)")
    f.add_argument("--no-trim", action="store_true", help="keep the samples after the end of the discharge (rests, recharges)")
    add_input_check_arguments(f)
    f.add_argument("--resample", type=float, default=None, metavar="SECONDS",
                   help="average the data over windows of this many seconds first")
    f.add_argument("--storage", default=None,
                   help="Optuna storage URL shared by the workers, e.g. postgresql://user@host:5432/db "
                        "(default: sqlite file <out>/fleet.optuna.db, one machine)")
    f.add_argument("--study-prefix", default=None, help="study names are PREFIX<pack> (default '<params name>-fleet-')")
    f.add_argument("--trials", type=int, default=200, help="trials per pack, all workers together (default 200)")
    f.add_argument("--seed", type=int, default=0, help="this worker's sampler seed: give every worker its own")
    f.add_argument("--parameters", nargs="+", default=None,
                   help="fit these parameters instead of the params' fit.parameters")
    f.add_argument("--simulator", choices=("fast", "liionpack", "engine"), default="engine",
                   help="engine (default, the SPM engine), fast (PyBaMM) or liionpack (reference)")
    f.add_argument("--out", required=True, help="directory for <pack>.yaml and fleet.json")
    f.add_argument("--json", action="store_true", help="print one JSON object")
    f.set_defaults(func=run_fit)


def run_fit(args: argparse.Namespace) -> int:
    from battery_predictor.cli.common import check_output_file
    from battery_predictor.cli.fit_identify import simulator_named
    from battery_predictor.errors import InputDataError
    from battery_predictor.fitting.fleet import fit_fleet, parse_packs
    from battery_predictor.fitting.resample import resample_all
    from battery_predictor.fitting.storage import close_storage, open_storage, redacted
    from battery_predictor.params import load_params

    packs = parse_packs(args.data, args.pack)
    for files in packs.values():  # every file exists before the first fit starts
        for path in files:
            if not Path(path).exists():
                raise InputDataError(f"{path}: data file not found")
    out_dir = Path(args.out)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputDataError(f"--out {out_dir}: is a file; give a directory")
    check_output_file(out_dir / "fleet.json", "--out")
    if args.trials < 1:
        raise InputDataError(f"--trials must be >= 1, got {args.trials}")
    params = load_params(args.params)
    out_dir.mkdir(parents=True, exist_ok=True)
    storage = args.storage or f"sqlite:///{(out_dir / 'fleet.optuna.db').resolve()}"
    close_storage(open_storage(storage))  # unreachable or misspelt: one line before any work
    options = data_options(args)

    def load(files: Sequence[str]) -> list[Recording]:
        return resample_all(load_data(files, pack=params, **options), args.resample)

    def report(fit: PackFit) -> None:
        if not args.json:
            joined = f", {fit.resumed_trials} already there" if fit.resumed_trials else ""
            print(f"{fit.pack}: R2_mod = {fit.r2_mod:.4f} ({fit.trials} trials, {fit.own_trials} here{joined}; "
                  f"{fit.seconds:.1f} s, {fit.rss_mb:.0f} MB) -> {fit.out}", flush=True)

    if not args.json:
        print(f"fleet: {len(packs)} packs of {params.name}, {args.trials} trials each, storage {redacted(storage)}, "
              f"seed {args.seed}", file=sys.stderr, flush=True)
    fits = fit_fleet(params, packs, load, storage=storage, out_dir=out_dir, trials=args.trials, seed=args.seed,
                     simulator=simulator_named(args.simulator), parameters=args.parameters,
                     study_prefix=args.study_prefix, on_pack=report)
    summary = {"params": str(args.params), "storage": redacted(storage), "seed": args.seed, "trials": args.trials,
               "packs": [f.to_dict() for f in fits]}
    (out_dir / "fleet.json").write_text(json.dumps(summary, indent=1) + "\n")
    if args.json:
        print_json(summary)
    else:
        print(f"wrote {len(fits)} fitted params and {out_dir / 'fleet.json'}")
    return 0

