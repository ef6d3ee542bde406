"""``battery-predictor diagnose``: what the SPM gets wrong on observed data, the cause, the extension that fixes it."""

from __future__ import annotations

import argparse
import datetime as _dt
import shlex
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from battery_predictor.cli.common import add_input_check_arguments, check_output_dir, check_output_file, print_json
from battery_predictor.params import EXTENSION_NAMES

if TYPE_CHECKING:
    from pathlib import Path

    from battery_predictor.diagnosis.results import Diagnosis
    from battery_predictor.params import PackParams
    from battery_predictor.recording import Recording


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "diagnose",
        help="name the cause of the model's error on observed data (temperature, capacity fade, ...)",
        description="Fit the baseline on the reference data, then fit each candidate extension and the baseline "
                    "(same evaluation budget) on the first part of every observed recording and judge them on the "
                    "held-out rest. Prints the named cause or 'none'.")
    p.add_argument("--params", required=True, help="params YAML of the pack or cell")
    p.add_argument("--reference", nargs="+", default=[], metavar="FILE",
                   help="recordings without the effect; the baseline is fitted on them (omit to use --params as is)")
    p.add_argument("--data", nargs="+", required=True, metavar="FILE", help="observed recordings (CSV or bag)")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    p.add_argument("--report", default=None, metavar="DIR", help="write report.md and figures into DIR")
    p.add_argument("--write-params", default=None, metavar="OUT",
                   help="write the params with the named extension active and its fitted values")
    p.add_argument("--budget", type=int, default=None,
                   help="model evaluations of each observed-data fit, baseline and candidates alike (default 80)")
    p.add_argument("--reference-budget", type=int, default=None,
                   help="model evaluations of each reference identification ('fit --method identify' on the SPM "
                        "engine; default 1000; up to three run: without the end padding and with the particle "
                        "diffusivities as well)")
    p.add_argument("--fit-fraction", type=float, default=0.6,
                   help="fraction of each observed recording's discharge throughput (Ah, rests, soaks and recharges not "
                        "counted) in its fit part; the rest is held out (default 0.6)")
    p.add_argument("--split", choices=("auto", "time", "recordings"), default="auto",
                   help="hold-out: 'time' fits on the first --fit-fraction of every observed recording; "
                        "'recordings' fits once per recording on all other recordings whole plus the first "
                        "--fit-fraction of it, and judges the rest of it; 'auto' (default): 'recordings' when "
                        "two or more recordings are observed, else 'time'")
    p.add_argument("--causes", nargs="+", choices=EXTENSION_NAMES, default=None,
                   help="candidate causes to try (default all)")
    p.add_argument("--trim", action="store_true",
                   help="trim every recording to the discharge that holds its minimum voltage; default keeps rests "
                        "and charge phases, which separate some causes")
    p.add_argument("--resample", type=float, default=None, metavar="SECONDS",
                   help="average every recording over time windows of SECONDS (dense data such as 1 s drive cycles)")
    add_input_check_arguments(p)
    # diagnose keeps the last row of a repeated timestamp by default (cycler exports repeat the time at
    # step changes; the later row is the start of the new step): a documented default, not an error
    for action in p._actions:
        if action.dest == "duplicate_times":
            action.default = "keep_last"
            action.help = ("CSV rows that repeat a timestamp: keep the last row of each repeated time (default "
                           "for diagnose: the later row starts the new step), keep the first, or reject ('error')")
    p.add_argument("--seed", type=int, default=0, help="seed of the multistart points (default 0)")
    p.add_argument("--workers", type=int, default=None,
                   help="processes for the candidate fits and the reference fit's Jacobian (default: CPUs, at most 4)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument("--simulator", choices=("engine", "pybamm"), default="engine",
                   help="candidate runs on the SPM engine where it covers them, PyBaMM's solver otherwise "
                        "(default; each candidate's JSON row says which ran), or PyBaMM's solver for all")
    p.set_defaults(func=run)


def _load(paths: Sequence[str], args: argparse.Namespace, params: PackParams) -> list[Recording]:
    from battery_predictor.fitting.problem import trim_to_discharge
    from battery_predictor.io.loader import load_recording
    from battery_predictor.params_checks import check_recordings_against_pack

    recs = [load_recording(p, duplicate_times=args.duplicate_times, drop_nan=args.drop_nan,
                           expect_discharge=None if args.expect_discharge else False) for p in paths]
    check_recordings_against_pack(params, recs)
    if args.trim:
        recs = [trim_to_discharge(r) for r in recs]
    if args.resample:
        # the windows of 'fit --resample' (the first sample, the state before the load, kept), so that the
        # reference fit sees what 'fit' sees
        from battery_predictor.fitting.resample import resample_windows

        recs = [resample_windows(r, args.resample) for r in recs]
    return recs


def run(args: argparse.Namespace) -> int:
    from battery_predictor.diagnosis.diagnose import (
        DEFAULT_BUDGET,
        DEFAULT_REFERENCE_BUDGET,
        default_progress,
        diagnose,
    )
    from battery_predictor.params import load_params

    if args.write_params:
        check_output_file(args.write_params, "--write-params", suffixes=(".yaml", ".yml"))
    if args.report:
        check_output_dir(args.report, "--report")
    params = load_params(args.params)
    observed = _load(args.data, args, params)
    references = _load(args.reference, args, params) if args.reference else []
    from battery_predictor.diagnosis.engine import Engine

    diag = diagnose(params, observed, references, engine=Engine(spm_engine=args.simulator == "engine"),
                    budget=args.budget or DEFAULT_BUDGET,
                    reference_budget=args.reference_budget or DEFAULT_REFERENCE_BUDGET,
                    fit_fraction=args.fit_fraction, causes=args.causes, seed=args.seed,
                    progress=None if args.quiet else default_progress, workers=args.workers, split=args.split)
    out = diag.to_json()
    if args.write_params and diag.judged:
        out["params_written"] = str(_write_extended(diag, args))
    if args.report:
        from battery_predictor.diagnosis.report import write_report
        from battery_predictor.io.paths import portable_path

        command = ("battery-predictor " + " ".join(shlex.quote(portable_path(a)) for a in sys.argv[1:])
                   if sys.argv else "")
        out["report"] = str(write_report(diag, args.report, command=command))
    if args.json:
        print_json(out)
        return 0
    _print_diagnosis(diag, out, args)
    return 0


def _write_extended(diag: Diagnosis, args: argparse.Namespace) -> Path:
    """Write the params with the winning extension and its fitted values to ``--write-params``; the path."""
    from dataclasses import replace

    extended = diag.extended_params()
    extended = replace(extended, provenance={
        **dict(extended.provenance),
        "diagnosed_by": "battery-predictor diagnose",
        "diagnosed_at": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "cause": diag.cause,
        "gain_pct": diag.gain_pct,
        "reference": [str(p) for p in args.reference],
        "data": [str(p) for p in args.data],
        "started_from": str(args.params),
    })
    return extended.to_yaml(args.write_params)


def _print_diagnosis(diag: Diagnosis, out: dict[str, Any], args: argparse.Namespace) -> None:
    """The human-readable answer: the cause, the evidence, each candidate's held-out RMSE (mV) and gain (%)."""
    print(f"cause: {diag.cause}")
    print(diag.evidence)
    if not diag.judged:
        if args.write_params:
            print("no params written: nothing was judged")
        return
    print(f"baseline held-out RMSE {diag.baseline.heldout_rmse_mV:.1f} mV; extended ({diag.extended.cause}) "
          f"{diag.extended.heldout_rmse_mV:.1f} mV; gain {diag.gain_pct:.1f} %")
    for c in diag.candidates:
        if c.applicable:
            print(f"  {c.cause:<22} {c.heldout_rmse_mV:9.1f} mV  {c.gain_pct:+7.1f} %")
        else:
            print(f"  {c.cause:<22} not applicable: {c.reason}")
    if args.write_params:
        print(f"wrote {out['params_written']}")
    if args.report:
        print(f"wrote {out['report']}")
