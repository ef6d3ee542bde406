"""``battery-predictor fit``: fit a pack model to measured discharges (R2_mod).

Two methods: ``identify`` (default) searches the identifiable coordinates of
:mod:`battery_predictor.fitting.identifiable` with seeded TPE then trust-region least squares and
reports identifiability; ``tpe`` is the seed paper's TPE over the params' raw ``fit.parameters``
(chosen automatically when ``--trials`` is given).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from battery_predictor.cli.common import (
    add_data_arguments,
    add_resample_arguments,
    check_output_file,
    check_plot_file,
    engine_fallback,
    fit_data_limits_of,
    print_deepest_state,
    print_json,
    progress_wanted,
    weak_group_json,
)
from battery_predictor.fitting.identification import DEFAULT_EVALUATIONS
from battery_predictor.simulation import SIMULATORS

if TYPE_CHECKING:
    from battery_predictor.fitting.identifiability import IdentifiabilityReport
    from battery_predictor.fitting.optimiser import FitResult
    from battery_predictor.fitting.problem import Evaluation
    from battery_predictor.fitting.space import FitParameter
    from battery_predictor.recording import Recording


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="fit a pack model to measured data (identifiable coordinates, or the paper's TPE)")
    p.add_argument("--params", required=True, help="params YAML to start from")
    add_data_arguments(p)
    p.add_argument("--method", choices=("identify", "tpe"), default=None,
                   help="identify: TPE + least squares in identifiable coordinates (default); tpe: the paper's TPE "
                        "over fit.parameters (default when --trials is given)")
    p.add_argument("--evaluations", type=int, default=DEFAULT_EVALUATIONS,
                   help=f"identify: budget in model evaluations (default {DEFAULT_EVALUATIONS})")
    p.add_argument("--tpe-fraction", type=float, default=None,
                   help="identify: share of the budget spent in TPE before the refinement (default 0.25)")
    p.add_argument("--starts", type=int, default=None,
                   help="identify: refinements from the best distinct TPE candidates (default 3)")
    p.add_argument("--coordinates", nargs="+", default=None, metavar="NAME",
                   help="identify: optional coordinates to search as well (negative_diffusivity_m2_s, "
                        "positive_diffusivity_m2_s, negative_kinetic_scale, positive_kinetic_scale; with the "
                        "hysteresis extension hysteresis_relaxation_rate_s, hysteresis_activation_energy_j_mol), or "
                        "'none'. Default: both particle diffusivities where the params carry a measured OCV "
                        "(battery-predictor ocv), none otherwise")
    p.add_argument("--ignore-group-voltages", action="store_true",
                   help="identify: fit the pack voltage only, also when the data carry series-group voltages "
                        "(group<k>_voltage_V) and the params use cell_imbalance (default: the weakest group's "
                        "voltage is fitted too)")
    p.add_argument("--ohmic-structure", action="store_true",
                   help="identify: where the data have current steps, also identify the ohmic structure (the fastest "
                        "kinetics searched, the series resistance started at the data's instantaneous step) with the "
                        "same budget, and keep the one with the higher R2_mod on the fit data (default: the params' "
                        "structure only)")
    add_resample_arguments(p, "fit")
    p.add_argument("--trials", type=int, default=None, help="tpe: total TPE trials (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    p.add_argument("--storage", default=None,
                   help="Optuna storage URL (default: sqlite file next to --out); a stopped fit resumes")
    p.add_argument("--study-name", default=None, help="Optuna study name (default: derived from params + data)")
    p.add_argument("--workers", type=int, default=1, help="processes working on the study (default 1)")
    p.add_argument("--parameters", nargs="+", default=None,
                   help="fit these parameters instead of the params' fit.parameters")
    p.add_argument("--simulator", choices=SIMULATORS, default=SIMULATORS[0],
                   help="engine (default: PyBaMM's SPM stepped exactly, milliseconds per day; hands what it does not "
                        "cover to fast and says so), fast (PyBaMM's solver) or liionpack (reference)")
    p.add_argument("--thermal", choices=("params", "isothermal", "lumped"), default="params",
                   help="cell thermal model of the fit (and of the fitted params): as the params say (default; "
                        "cell.options thermal), isothermal at the data's temperature, or lumped (PyBaMM's lumped "
                        "thermal cell self-heating from the data's first temperature)")
    p.add_argument("--initial-state", choices=("auto", "params", "voltage"), default="auto")
    p.add_argument("--no-weak-group-inference", action="store_true",
                   help="keep the params' cells identical even when the fit data stop under load above the "
                        "route threshold (default: infer the weak series group that makes the pack stop there)")
    p.add_argument("--out", required=True, help="fitted params YAML to write")
    p.add_argument("--plot", default=None, help="PNG of measured vs simulated (default: <out>.png)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    args.no_progress = not progress_wanted(args)  # bars only on an interactive stderr, never with --json
    method = args.method or ("tpe" if args.trials is not None else "identify")
    if method == "identify":
        from battery_predictor.cli.fit_identify import run_identify

        return run_identify(args)
    if args.trials is None:
        args.trials = 1000
    return _run_tpe(args)


def _run_tpe(args: argparse.Namespace) -> int:
    """``fit --method tpe``: the paper's TPE fit of the raw parameters; writes the params file and the plot."""
    from battery_predictor.cli.common import prepared_data
    from battery_predictor.cli.fit_identify import simulator_named
    from battery_predictor.fitting.identification import raw_identifiability
    from battery_predictor.fitting.optimiser import TPEOptimiser
    from battery_predictor.fitting.problem import FitProblem
    from battery_predictor.fitting.space import fit_space
    from battery_predictor.params import load_params
    from battery_predictor.plots import plot_voltage_fit
    from battery_predictor.simulation.cell_setup import is_lumped_thermal, with_thermal
    from battery_predictor.simulation.extensions import with_cold_window_anchors

    check_output_file(args.out, "--out", suffixes=(".yaml", ".yml"))
    check_plot_file(args.plot or Path(args.out).with_suffix(".png"))
    params = with_cold_window_anchors(with_thermal(load_params(args.params), args.thermal))
    recs = prepared_data(args, params, command="fit")
    out = Path(args.out)
    storage = args.storage or f"sqlite:///{out.with_suffix('.optuna.db').resolve()}"
    out.parent.mkdir(parents=True, exist_ok=True)
    space = fit_space(params, tuple(args.parameters) if args.parameters else None)
    problem = FitProblem(params=params, recordings=recs, simulator=simulator_named(args.simulator),
                         initial_state=args.initial_state)
    optimiser = TPEOptimiser(n_trials=args.trials, seed=args.seed, storage=storage, study_name=args.study_name,
                             workers=args.workers, progress=not args.no_progress,
                             notice=lambda line: print(line, file=sys.stderr, flush=True))
    result = optimiser.run(problem, space)
    best = problem.evaluate(result.best_values)
    report = raw_identifiability(problem, space, result.best_values)
    thermal = "lumped" if is_lumped_thermal(params) else "isothermal"
    limits = fit_data_limits_of(
        args, params.with_values(result.best_values, provenance=_provenance(args, recs, best, result, report, thermal),
                                 fit=params.fit), recs)
    fitted, deepest, weak_line = limits.params, limits.deepest, limits.weak_group_line
    fitted.to_yaml(out)
    plot_path = Path(args.plot) if args.plot else out.with_suffix(".png")
    plot_voltage_fit(recs, best.results, plot_path, title=f"{params.name} fit: R2_mod = {best.r2_mod:.4f}")
    if args.json:
        print_json({"method": "tpe", "r2_mod": best.r2_mod, "trials": result.trials,
                    "failed_trials": result.failed_trials, "resumed_trials": result.resumed_trials,
                    "improved": result.improved, "seconds": result.seconds, "params": result.best_values,
                    "thermal": thermal, "identifiability": report.to_dict(), "out": str(out), "plot": str(plot_path),
                    "engine_fallback": engine_fallback(best.results),
                    "fit_data_deepest_state": None if deepest is None else deepest.as_thresholds(),
                    "weak_group": weak_group_json(fitted, weak_line)})
        return 0
    print(f"fit of {params.name} on {len(recs)} file(s): R2_mod = {best.r2_mod:.4f} "
          f"({result.trials} trials, {result.failed_trials} failed, {result.seconds:.0f} s; "
          f"{'lumped thermal' if thermal == 'lumped' else 'isothermal'} cell)")
    _print_values(result, space)
    for line in report.summary_lines():
        print(line)
    print_deepest_state(deepest)
    print(weak_line)
    print(f"wrote {out} and {plot_path}")
    return 0


def _provenance(args: argparse.Namespace, recs: Sequence[Recording], best: Evaluation, result: FitResult,
                report: IdentifiabilityReport, thermal: str) -> dict[str, Any]:
    """The fitted params file's ``provenance``: how, when and on what it was fitted, and the scores."""
    return {
        "fitted_by": "battery-predictor fit (Optuna TPE, R2_mod of the seed paper Eq. 1-3)",
        "fitted_at": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "data": [str(r.source) for r in recs],
        "resample_s": args.resample,
        "r2_mod": best.r2_mod,
        "r2_mod_per_file": best.per_recording,
        "rmse_mv_per_file": best.rmse_mv,
        "trials": result.trials,
        "failed_trials": result.failed_trials,
        "seed": args.seed,
        "simulator": args.simulator,
        "thermal": thermal,
        "study": result.study_name,
        "storage": result.storage,
        "started_from": str(args.params),
        "identifiability": report.to_dict(),
    }


def _print_values(result: FitResult, space: Sequence[FitParameter]) -> None:
    """Each fitted parameter's start and fitted value (a note first when no trial beat the start)."""
    if not result.improved:
        print("  no trial beat the start (trial 0, the params' own values): the fitted params equal the start; "
              "more --trials or other --parameters may help")
    for space_p in space:
        v = result.best_values[space_p.name]
        print(f"  {space_p.name:<58} {space_p.initial:>12.5g} -> {v:>12.5g}")
