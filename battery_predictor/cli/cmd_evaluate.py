"""``battery-predictor evaluate``: the seed paper's experiments with its figures side by side."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from battery_predictor.cli.common import check_output_dir, print_json

REPO = Path(__file__).resolve().parents[2]
BASE_SETS = ("Chen2020", "NCA_Kim2011", "OKane2022")


def register(sub) -> None:
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
    p.add_argument("--skip", nargs="*", default=[], choices=("table2", "runtime", "routes", "stepwise"),
                   help="parts to skip (stepwise: use --ranger-params as they are, no stepwise fit)")
    p.add_argument("--out", default="evaluation", help="report directory")
    p.add_argument("--json", action="store_true", help="print one JSON object with the figures")
    p.set_defaults(func=run)


def _bundled(bags: Path, pattern: str) -> list[str]:
    return sorted(str(p) for p in bags.glob(pattern) if p.is_dir() or p.suffix == ".mcap")


def run(args) -> int:
    from battery_predictor.errors import InputDataError
    from battery_predictor.evaluation import report
    from battery_predictor.evaluation.paper_eval import (
        PAPER,
        _score,
        fit_pack,
        route_evaluation,
        route_summary,
        runtime_evaluation,
        runtime_summary,
        table2,
    )
    from battery_predictor.fitting.problem import trim_to_discharge
    from battery_predictor.io.loader import load_recording
    from battery_predictor.io.paths import portable_paths
    from battery_predictor.params import load_params
    from battery_predictor.prediction.core import PredictorConfig

    tic = time.perf_counter()
    bags = Path(args.bags)
    out = check_output_dir(args.out, "--out")
    out.mkdir(parents=True, exist_ok=True)
    storage = None if args.storage == "memory" else (args.storage or f"sqlite:///{(out / 'studies.db').resolve()}")
    dyn_files = args.temi_dynamic or _bundled(bags, "temi_dynamic_*")
    static_file = args.temi_static or next(iter(_bundled(bags, "temi_static_*")), None)
    step_file = args.ranger_stepwise or next(iter(_bundled(bags, "ranger_stepwise_*")), None)
    route_files = args.ranger_routes or _bundled(bags, "ranger_route_*")
    need_temi = "table2" not in args.skip or "runtime" not in args.skip
    if need_temi and (not dyn_files or ("table2" not in args.skip and static_file is None)):
        raise InputDataError(f"{bags}: no information-robot recordings (temi_dynamic_*, temi_static_*)")
    if "routes" not in args.skip and not route_files:
        raise InputDataError(f"{bags}: no luggage-robot route recordings (ranger_route_*)")

    def log(msg: str) -> None:
        if not args.json:
            print(msg, flush=True)

    summary: dict = {"paper": {k: v for k, v in PAPER.items() if k != "table2"},
                     "settings": {"trials per fit": args.trials, "seed": args.seed,
                                  "base sets": " ".join(args.base_sets), "skipped": " ".join(args.skip) or "none",
                                  "storage": storage or "memory"}}
    figures: dict = {}
    temi = load_params(args.temi_params)
    dyn = [trim_to_discharge(load_recording(f)) for f in dyn_files] if need_temi else []
    static = trim_to_discharge(load_recording(static_file)) if "table2" not in args.skip else None
    runtime_params = temi
    if "table2" not in args.skip:
        log(f"Table 2: {len(args.base_sets)} parameter sets x 2 profiles, {args.trials} trials each ...")
        rows = table2(temi, dyn[0], static, base_sets=args.base_sets, trials=args.trials, seed=args.seed,
                      progress=lambda m: log("  " + m), storage=storage, workers=args.workers)
        summary["table2"] = [{"opt_profile": r.opt_profile, "base_parameter_set": r.base_parameter_set,
                              "opt_r2_mod": r.opt_r2_mod, "val_r2_mod": r.val_r2_mod,
                              "parameters": list(r.parameters)} for r in rows]
        figures["Fig. 4 kind: fit and validation"] = report.fig_fit(rows, dyn[0], static, out / "fig4_fit.png")
        chosen = next((r for r in rows if r.base_parameter_set == "Chen2020" and r.opt_profile == "dynamic"
                       and r.opt_result is not None), None)
        if chosen is not None:
            runtime_params = dataclasses.replace(chosen.params, source=str(out / "temi_fit_dynamic.yaml"))
            runtime_params.to_yaml(out / "temi_fit_dynamic.yaml")
    if "runtime" not in args.skip:
        log(f"runtime evaluation on {len(dyn)} dynamic discharge(s) ...")
        points = runtime_evaluation(runtime_params, dyn)
        summary["runtime"] = runtime_summary(points)
        summary["runtime_points"] = [dataclasses.asdict(p) for p in points]
        figures["Fig. 5 kind: remaining runtime (paper strategy)"] = report.fig_runtime(points,
                                                                                       out / "fig5_runtime.png")
        log(f"  paper strategy (average load): MAE {summary['runtime']['mae_min']:.2f} min, MAPE "
            f"{summary['runtime']['mape_pct']:.1f} % (paper {PAPER['runtime_mae_min']} min, "
            f"{PAPER['runtime_mape_pct']} %)")
        q = PredictorConfig.__dataclass_fields__["peak_current_quantile"].default
        if q > 0:
            peak_points = runtime_evaluation(runtime_params, dyn, peak_current_quantile=q)
            summary["runtime_peaks"] = {**runtime_summary(peak_points), "peak_current_quantile": q}
            summary["runtime_peaks_points"] = [dataclasses.asdict(p) for p in peak_points]
            figures["Fig. 5 kind: remaining runtime (load peaks, the predictor's default)"] = report.fig_runtime(
                peak_points, out / "fig5_runtime_peaks.png")
            log(f"  predictor default (load peaks, quantile {q}): MAE {summary['runtime_peaks']['mae_min']:.2f} min, "
                f"MAPE {summary['runtime_peaks']['mape_pct']:.1f} %")
    if "routes" not in args.skip and route_files:
        ranger = load_params(args.ranger_params)
        if step_file is not None and "stepwise" not in args.skip:
            step = trim_to_discharge(load_recording(step_file))
            log(f"luggage robot: fitting the stepwise experiment ({args.trials} trials) ...")
            ranger, _, _ = fit_pack(ranger, [step], trials=args.trials, seed=args.seed, screen_first=False,
                                    storage=storage, workers=args.workers)
            score, res = _score(ranger, step)
            summary["stepwise"] = {"r2_mod": score}
            figures["Fig. 7 kind: stepwise experiment"] = report.fig_stepwise(step, res, score,
                                                                              out / "fig7_stepwise.png")
            ranger = dataclasses.replace(ranger, source=str(out / "ranger_fit_stepwise.yaml"))
            ranger.to_yaml(out / "ranger_fit_stepwise.yaml")
        log(f"route evaluation on {len(route_files)} recording(s) ...")
        cases = route_evaluation(ranger, [load_recording(f) for f in route_files], args.route_payload_kg)
        summary["routes"] = route_summary(cases)
        summary["route_cases"] = [dataclasses.asdict(c) for c in cases]
        figures["Fig. 8 kind: routes"] = report.fig_routes(cases, float(ranger.thresholds["route_min_voltage_v"]),
                                                           out / "fig8_routes.png")
        r = summary["routes"]
        log(f"  MAE {r['mae_v']:.3f} V, MAPE {r['mape_pct']:.2f} % (paper {PAPER['route_mae_v']} V, "
            f"{PAPER['route_mape_pct']} %); decisions {r['decisions_correct']}/{r['decisions']} correct, "
            f"{r['unsafe_accepts']} unsafe")
    md = report.write_markdown(out, portable_paths(summary), figures)
    summary["seconds"] = time.perf_counter() - tic
    summary["report"] = str(md)
    if args.json:
        print_json(summary)
    else:
        print(f"report: {md} ({summary['seconds']:.0f} s)")
    return 0
