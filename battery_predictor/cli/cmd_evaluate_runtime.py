"""``battery-predictor evaluate-runtime``: the predictor's remaining runtime on measured recordings.

Prints per recording and pooled MAE / MAPE / bias / worst error of the predictor's core (fed the
monitor's 5 s windows, default settings) and, side by side, of naive Coulomb counters; writes a
plot of predicted vs true remaining runtime per recording and the figures as JSON with ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from battery_predictor.cli.common import add_input_check_arguments, check_output_dir, print_json
from battery_predictor.errors import InputDataError

if TYPE_CHECKING:
    from battery_predictor.evaluation.runtime_eval import RecordingResult
    from battery_predictor.recording import Recording


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate-runtime",
                       help="remaining runtime on measured recordings: predictor vs Coulomb counters")
    p.add_argument("--params", required=True, help="fitted pack params YAML")
    p.add_argument("--data", nargs="+", required=True, metavar="FILE",
                   help="recordings (CSV or rosbag2), each one discharge to the cut-off")
    p.add_argument("--cutoff-v", type=float, default=None, metavar="V",
                   help="pack voltage at which the robot stops (default: the params file's)")
    p.add_argument("--checkpoints", default="0.1:0.9:0.1", metavar="START:STOP:STEP",
                   help="fractions of each discharge at which to predict (default 0.1:0.9:0.1)")
    p.add_argument("--capacity-ah", type=float, default=None, metavar="AH",
                   help="a capacity for the counter (in addition to the params' nominal one)")
    p.add_argument("--capacity-from", nargs="+", default=(), metavar="FILE",
                   help="recordings (e.g. the fit data) whose mean charge to the cut-off is a counter's capacity")
    p.add_argument("--end-margin-v", type=float, default=None, metavar="V",
                   help="a discharge that stops this close to the cut-off ended on it (default 0.5 V per cell)")
    p.add_argument("--peak-source", choices=("window", "sample"), default=None,
                   help="which load peaks stop the pack: 5 s window means or single samples "
                        "(default: the predictor's default, see the node parameter peak_source)")
    p.add_argument("--load-model", choices=("auto", "power", "current"), default=None,
                   help="what of the average load stays constant ahead (default: the predictor's, auto; see the "
                        "node parameter load_model)")
    p.add_argument("--load-estimator", choices=("cycle", "ewma"), default=None,
                   help="the average load ahead: the present cycle's mean (cycle) or an exponentially weighted mean "
                        "(ewma) (default: the predictor's, cycle; see the node parameter load_estimator)")
    p.add_argument("--load-time-constant-s", type=float, default=None, metavar="S",
                   help="time constant of --load-estimator ewma, s (default: the predictor's, 1800; node parameter "
                        "load_time_constant_s)")
    p.add_argument("--drift-correction", choices=("auto", "full", "smallest"), default=None,
                   help="where a carried state that left the state tolerance goes (default: the predictor's, auto; "
                        "see the node parameter drift_correction)")
    p.add_argument("--end-event", choices=("auto", "peak", "sampled"), default=None,
                   help="where a load with peaks ends: where a quantile peak drawn at any moment crosses (peak), "
                        "the median end of futures resampled from the cycle's windows (sampled), or sampled where "
                        "the cycle's heavy windows last 15 s or more on average, else peak (auto) (default: the "
                        "predictor's, auto; see the node parameter end_event)")
    p.add_argument("--thermal-forecast", choices=("auto", "held"), default=None,
                   help="the cell temperature ahead: integrated by the params' lumped thermal cell when they carry one "
                        "(auto), or held at the latest measurement (default: the predictor's, auto; see the node "
                        "parameter thermal_forecast)")
    p.add_argument("--ambient-k", type=float, default=None, metavar="K",
                   help="ambient temperature of a self-heating forecast, K (default: the lowest cell temperature "
                        "measured in the discharge cycle; node parameter ambient_temperature_k)")
    p.add_argument("--calibrate-uncertainty", default=None, metavar="PARAMS_OUT",
                   help="calibrate the structural runtime spread so that P10..P90 holds 80 %% of these recordings' "
                        "checkpoints (use the fit recordings, judge on others) and write the params with it here")
    p.add_argument("--out", default=None, metavar="DIR", help="write summary.json, checkpoints.json and plots here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_input_check_arguments(p)
    p.set_defaults(func=run)


def parse_checkpoints(text: str) -> tuple[float, ...]:
    """``"0.1:0.9:0.1"`` -> (0.1, ..., 0.9); a comma list is taken as is."""
    try:
        if ":" in text:
            start, stop, step = (float(x) for x in text.split(":"))
            if step <= 0:
                raise ValueError
            values = []
            k = 0
            while start + k * step <= stop + 1e-9:
                values.append(round(start + k * step, 6))
                k += 1
        else:
            values = [float(x) for x in text.split(",")]
    except ValueError:
        raise InputDataError(f"--checkpoints {text!r}: expected START:STOP:STEP or a comma list of fractions") from None
    if not values or any(not 0.0 < v < 1.0 for v in values):
        raise InputDataError(f"--checkpoints {text!r}: fractions must lie strictly between 0 and 1")
    return tuple(values)


def run(args: argparse.Namespace) -> int:
    from battery_predictor.evaluation import runtime_eval as ev
    from battery_predictor.io.loader import load_recording
    from battery_predictor.params import load_params
    from battery_predictor.prediction.core import PredictorConfig, PredictorCore

    checkpoints = parse_checkpoints(args.checkpoints)
    if args.load_time_constant_s is not None and not (math.isfinite(args.load_time_constant_s)
                                                      and args.load_time_constant_s > 0):
        raise InputDataError(f"--load-time-constant-s {args.load_time_constant_s}: must be a positive number of seconds")
    out_dir = check_output_dir(args.out, "--out") if args.out else None
    tic = time.perf_counter()
    params = load_params(args.params)
    cutoff_v = args.cutoff_v if args.cutoff_v is not None else \
        PredictorCore(PredictorConfig(params_file=str(params.source)), params=params).cutoff_voltage_v
    if not (math.isfinite(cutoff_v) and cutoff_v > 0):
        raise InputDataError(f"{params.source}: no cut-off voltage in the params; pass --cutoff-v V")

    def load(path: str) -> Recording:
        return load_recording(path, duplicate_times=args.duplicate_times, drop_nan=args.drop_nan,
                              expect_discharge=None if args.expect_discharge else False)

    capacities = {}
    if math.isfinite(ev.nominal_capacity_ah(params)):
        capacities["nominal"] = ev.nominal_capacity_ah(params)
    if args.capacity_ah is not None:
        capacities["given"] = float(args.capacity_ah)
    if args.capacity_from:
        charges = [ev.charge_to_end_ah(params, load(p), cutoff_v, args.end_margin_v) for p in args.capacity_from]
        known = [q for q in charges if math.isfinite(q)]
        if not known:
            raise InputDataError("--capacity-from: none of these recordings ends at the cut-off")
        capacities["measured"] = sum(known) / len(known)
    options = {"peak_source": args.peak_source, "load_model": args.load_model,
               "load_estimator": args.load_estimator, "load_time_constant_s": args.load_time_constant_s,
               "drift_correction": args.drift_correction, "thermal_forecast": args.thermal_forecast,
               "ambient_temperature_k": args.ambient_k, "end_event": args.end_event}
    config = PredictorConfig(params_file=str(params.source), cutoff_voltage_v=cutoff_v,
                             **{k: v for k, v in options.items() if v})
    recordings = [load(path) for path in args.data]  # every input is checked before minutes of evaluation
    results = []
    for rec in recordings:
        res = ev.evaluate_recording(params, rec, cutoff_v=cutoff_v, capacities_ah=capacities,
                                    checkpoints=checkpoints, end_margin_v=args.end_margin_v, config=config)
        results.append(res)
        if not args.json:
            _print_recording(res, list(capacities))
    summary = ev.summarise(results, list(capacities))
    if args.calibrate_uncertainty:
        calibrated = ev.with_runtime_sigma(params, results)
        written = calibrated.to_yaml(args.calibrate_uncertainty)
        summary["calibrated_uncertainty"] = {**calibrated.provenance["uncertainty"], "params_out": str(written)}
    summary.update({"params": str(params.source), "cutoff_v": cutoff_v, "peak_source": config.peak_source,
                    "load_model": config.load_model, "load_estimator": config.load_estimator,
                    "load_time_constant_s": config.load_time_constant_s, "drift_correction": config.drift_correction,
                    "end_event": config.end_event, "thermal_forecast": config.thermal_forecast, "ambient_temperature_k": config.ambient_temperature_k,
                    "capacities_ah": capacities,
                    "checkpoints": list(checkpoints), "seconds": time.perf_counter() - tic})
    if out_dir is not None:
        _write_outputs(out_dir, summary, results)
        summary["out"] = str(out_dir)
    if args.json:
        print_json(summary)
    else:
        _print_pooled(summary)
    return 0


def _fmt(x: float, spec: str = ".1f") -> str:
    return format(x, spec) if isinstance(x, (int, float)) and math.isfinite(x) else "-"


def _line(name: str, f: dict, summary: dict) -> str:
    return (f"  {name:<20} MAE {_fmt(f['mae_min']):>6} min  MAPE {_fmt(f['mape_pct']):>6} %  "
            f"bias {_fmt(f['bias_min'], '+.1f'):>7} min  worst {_fmt(f['worst_min'], '+.1f'):>7} min  "
            f"answered {f['answered']}/{f['checkpoints']}  off by > {summary['off_by_fraction']:.0%} after "
            f"{summary['late_after_fraction']:.0%}: {f['off_by_half_after']}/{f['answers_after']}")


def _ratio_text(summary: dict) -> str:
    """The pooled predictor MAE over the best counter's, as a sentence ("" without a counter)."""
    best = summary["pooled_ratio_to_best_counter"]
    if best["counter"] is None:
        return ""
    return f"predictor MAE / best counter's ({best['counter']}): {best['ratio']:.2f}x"


def _interval_line(f: dict) -> str:
    return (f"  {'P10..P90':<20} true inside {_fmt(f['inside_pct'], '.0f'):>4} % (target 80), below P10 "
            f"{_fmt(f['below_p10_pct'], '.0f')} %, above P90 {_fmt(f['above_p90_pct'], '.0f')} % of {f['intervals']}")


def _print_recording(res: RecordingResult, counters: list[str]) -> None:
    from battery_predictor.evaluation.runtime_eval import summarise

    summary = summarise([res], counters)
    block = summary["per_recording"][0]
    d = res.discharge
    print(f"{Path(res.source).name}: {(d.end_s - d.start_s) / 60:.1f} min discharge (end: {d.ended_by}), "
          f"{_fmt(res.mean_temperature_c)} degC")
    for name in ["predictor", *(f"counter[{c}]" for c in counters)]:
        print(_line(name, block[name], summary))
    print(_interval_line(block["interval"]))
    invalid = [c for c in res.checkpoints if not c.valid]
    for c in invalid:
        print(f"    invalid at {c.fraction:.0%}: {c.reason}")


def _print_pooled(summary: dict) -> None:
    print(f"pooled over {len(summary['per_recording'])} recordings (capacities: "
          + ", ".join(f"{k} {v:.3f} Ah" for k, v in summary["capacities_ah"].items()) + "):")
    for name, f in summary["pooled"].items():
        print(_line(name, f, summary))
    print(_interval_line(summary["pooled_interval"]))
    if _ratio_text(summary):
        print(f"  {_ratio_text(summary)}")
    if "calibrated_uncertainty" in summary:
        cal = summary["calibrated_uncertainty"]
        print(f"calibrated runtime spread: sigma {cal['runtime_log_sigma']:.3f} (log) on {cal['checkpoints']} "
              f"checkpoints; params written to {cal['params_out']}")
    if "out" in summary:
        print(f"written: {summary['out']}/report.md, summary.json, checkpoints.json, runtime.png")


def _write_outputs(out_dir: Path, summary: dict, results: Sequence[RecordingResult]) -> None:
    from battery_predictor.evaluation.runtime_eval import result_rows
    from battery_predictor.evaluation.runtime_plot import plot_runtime

    out_dir.mkdir(parents=True, exist_ok=True)
    clean = json.loads(json.dumps(summary, default=str).replace("NaN", "null"))
    (out_dir / "summary.json").write_text(json.dumps(clean, indent=1) + "\n")
    rows = json.loads(json.dumps(result_rows(results), default=str).replace("NaN", "null"))
    (out_dir / "checkpoints.json").write_text(json.dumps(rows, indent=1) + "\n")
    plot_runtime(results, out_dir / "runtime.png")
    (out_dir / "report.md").write_text(report_markdown(summary))


def report_markdown(summary: dict) -> str:
    """The figures as a Markdown report (per recording and pooled, predictor beside the counters)."""
    import shlex
    import sys

    names = list(summary["pooled"])
    head = ("| recording | degC | min | " + " | ".join(f"{n} MAE / bias / worst % / off by half" for n in names)
            + " |")
    lines = ["# Remaining runtime on measured recordings", "",
             f"Made by `battery-predictor {' '.join(shlex.quote(a) for a in sys.argv[1:])}`", "",
             f"Params `{Path(summary['params']).name}`, cut-off {summary['cutoff_v']:.2f} V, peaks from "
             f"{summary['peak_source']}s, constant {summary['load_model']} ahead (load estimator {summary['load_estimator']}), drift correction {summary['drift_correction']}, temperature ahead {summary['thermal_forecast']}, checkpoints {', '.join(f'{c:g}' for c in summary['checkpoints'])} of each "
             "discharge. Counter capacities: " + ", ".join(f"{k} {v:.3f} Ah" for k, v in summary["capacities_ah"].items())
             + ". MAE / bias in min; worst % = the largest error, early or late, relative to the true remaining time after "
             f"{summary['late_after_fraction']:.0%} of the discharge; off by half = the answers after "
             f"{summary['late_after_fraction']:.0%} off by more than {summary['off_by_fraction']:.0%} of the true remaining time, "
             "of those answered.", "", head,
             "|" + "---|" * (3 + len(names))]

    def cells(block: dict) -> str:
        return " | ".join(f"{_fmt(block[n]['mae_min'])} / {_fmt(block[n]['bias_min'], '+.1f')} / "
                          f"{_fmt(block[n]['worst_late_pct'], '.0f')} / "
                          f"{block[n]['off_by_half_after']} of {block[n]['answers_after']}" for n in names)

    for r in summary["per_recording"]:
        lines.append(f"| {Path(r['source']).name} ({r['ended_by']}) | {_fmt(r['mean_temperature_c'])} | "
                     f"{_fmt(r['discharge_min'])} | {cells(r)} |")
    lines.append(f"| **pooled** | | | {cells(summary['pooled'])} |")
    if _ratio_text(summary):
        lines += ["", f"Pooled, {_ratio_text(summary)}."]
    lines += ["", "P10..P90 of the predictor: how often the true remaining time fell inside (target 80 %), "
              "below P10 and above P90 (10 % each).", "",
              "| recording | inside % | below P10 % | above P90 % | intervals |", "|---|---|---|---|---|"]
    rows = [(Path(r["source"]).name, r["interval"]) for r in summary["per_recording"]]
    for name, f in [*rows, ("**pooled**", summary["pooled_interval"])]:
        lines.append(f"| {name} | {_fmt(f['inside_pct'], '.0f')} | {_fmt(f['below_p10_pct'], '.0f')} | "
                     f"{_fmt(f['above_p90_pct'], '.0f')} | {f['intervals']} |")
    lines += ["", "![predicted vs true remaining runtime](runtime.png)", ""]
    return "\n".join(lines)
