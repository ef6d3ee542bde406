"""``battery-predictor evaluate``: the seed paper's experiments with its figures side by side."""

from __future__ import annotations

import argparse
from pathlib import Path

from battery_predictor.cli.common import check_output_dir, print_json
from battery_predictor.evaluation.pipeline import BASE_SETS, PARTS

REPO = Path(__file__).resolve().parents[2]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="reproduce the paper's evaluation (Table 2, Fig. 4/5/7/8) on recordings")
    p.add_argument("--bags", default=str(REPO / "bags"), help="directory of the bundled bags")
    p.add_argument("--temi-params", default=str(REPO / "params" / "temi.yaml"))
    p.add_argument("--ranger-params", default=str(REPO / "params" / "ranger_mini.yaml"))
    p.add_argument("--temi-dynamic", nargs="+", default=None,
                   help="information robot dynamic discharges (first = fit data); default: bundled temi_dynamic_*")
    p.add_argument("--temi-static", default=None, help="information robot static discharge")
    p.add_argument("--ranger-stepwise", default=None, help="luggage robot stepwise experiment")
    p.add_argument("--ranger-routes", nargs="+", default=None,
                   help="luggage robot recordings of repeated longest routes (bags or CSVs); default: bundled")
    p.add_argument("--route-payload-kg", nargs="+", type=float, default=None,
                   help="payload of each --ranger-routes recording (kg), for recordings without route metadata; "
                        "the truth is then measured in the recording itself")
    p.add_argument("--base-sets", nargs="+", default=list(BASE_SETS), help="PyBaMM sets compared in Table 2")
    p.add_argument("--trials", type=int, default=300, help="TPE trials per fit (paper: 1000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--storage", default=None,
                   help="Optuna storage URL of the fits (default: sqlite:///<out>/studies.db, so a stopped "
                        "evaluation resumes; 'memory' = none)")
    p.add_argument("--workers", type=int, default=1, help="processes per fit (needs a storage)")
    p.add_argument("--skip", nargs="*", default=[], choices=PARTS,
                   help="parts to skip (stepwise: use --ranger-params as they are, no stepwise fit)")
    p.add_argument("--out", default="evaluation", help="report directory")
    p.add_argument("--json", action="store_true", help="print one JSON object with the figures")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from battery_predictor.evaluation.pipeline import (
        PaperEvaluation,
        bundled_recordings,
        check_recordings,
        evaluate_paper,
    )

    bags = Path(args.bags)
    out = check_output_dir(args.out, "--out")
    out.mkdir(parents=True, exist_ok=True)
    ev = PaperEvaluation(
        temi_params=args.temi_params, ranger_params=args.ranger_params,
        temi_dynamic=args.temi_dynamic or bundled_recordings(bags, "temi_dynamic_*"),
        temi_static=args.temi_static or next(iter(bundled_recordings(bags, "temi_static_*")), None),
        ranger_stepwise=args.ranger_stepwise or next(iter(bundled_recordings(bags, "ranger_stepwise_*")), None),
        ranger_routes=args.ranger_routes or bundled_recordings(bags, "ranger_route_*"),
        route_payload_kg=args.route_payload_kg, base_sets=args.base_sets, trials=args.trials, seed=args.seed,
        storage=None if args.storage == "memory" else (args.storage or f"sqlite:///{(out / 'studies.db').resolve()}"),
        workers=args.workers, skip=args.skip, out=out)
    check_recordings(ev, bags)
    summary = evaluate_paper(ev, log=(lambda msg: None) if args.json else (lambda msg: print(msg, flush=True)))
    if args.json:
        print_json(summary)
    else:
        print(f"report: {summary['report']} ({summary['seconds']:.0f} s)")
    return 0
