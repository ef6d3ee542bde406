"""``battery-predictor screen``: +10 % parameter screening (seed paper, step 4)."""

from __future__ import annotations

import argparse
import itertools
import sys

from battery_predictor.cli.common import print_json, progress_bar, progress_wanted

#: What the table's columns mean (printed under it).
COLUMNS_NOTE = ("runtime %: change of the time to the cut-off when the parameter is raised by 10 %; "
                "R2: R2_mod of the voltage curve against the unchanged model's")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("screen", help="rank the cell parameters by their effect on a 0.5C discharge")
    p.add_argument("--params", required=True, help="params YAML")
    p.add_argument("--c-rate", type=float, default=None, help="discharge rate in 1/h (default: params or 0.5)")
    p.add_argument("--simulator", choices=("fast", "liionpack"), default="fast")
    p.add_argument("--all", action="store_true", help="list every screened parameter, not only the relevant")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from battery_predictor.fitting.screening import screen, screenable_parameters
    from battery_predictor.params import load_params
    from battery_predictor.simulation import get_simulator

    params = load_params(args.params)
    total = len(screenable_parameters(params))
    with progress_bar(total, "screen", "parameter", enabled=progress_wanted(args)) as update:
        finished = itertools.count(1)
        rows = screen(params, get_simulator(args.simulator), c_rate=args.c_rate,
                      progress=lambda _row: update(next(finished)))
    relevant = [r for r in rows if r.relevant]
    if args.json:
        print_json({
            "params": str(args.params),
            "relevant": [r.name for r in relevant],
            "rows": [{"name": r.name, "base_value": r.base_value, "runtime_change_pct": r.runtime_change_pct,
                      "r2": r.r2, "relevant": r.relevant, "error": r.error} for r in rows],
        })
        return 0
    shown = rows if args.all else relevant
    print(f"screening of {params.name} ({params.base_parameter_set}): {len(relevant)} of {len(rows)} "
          "parameters relevant (runtime change > 1 % or R2 < 0.99)")
    print(f"{'rank':>4}  {'parameter':<62} {'runtime %':>10} {'R2':>8}  relevant")
    for k, r in enumerate(shown, 1):
        note = f"  ({r.error})" if r.error else ""
        print(f"{k:>4}  {r.name:<62} {r.runtime_change_pct:>+10.2f} {r.r2:>8.4f}  {'yes' if r.relevant else 'no'}{note}")
    print(COLUMNS_NOTE)
    sys.stdout.flush()
    return 0
