"""``battery-predictor fit --method identify``: identifiable coordinates, TPE + least squares, identifiability."""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from battery_predictor.cli.common import (
    check_output_file,
    check_plot_file,
    engine_fallback,
    fit_data_limits_of,
    prepared_data,
    print_deepest_state,
    print_json,
    weak_group_json,
)
from battery_predictor.errors import InputDataError
from battery_predictor.ocp import ocp_origin

if TYPE_CHECKING:
    from battery_predictor.fitting.identifiability import IdentifiabilityReport
    from battery_predictor.fitting.identifiable import Coordinate
    from battery_predictor.fitting.identification import CandidateScore, IdentificationResult
    from battery_predictor.params import PackParams
    from battery_predictor.recording import Recording
    from battery_predictor.simulation.base import PackSimulator


def simulator_named(name: str) -> PackSimulator:
    """The simulator of ``--simulator`` (:func:`~battery_predictor.simulation.get_simulator`)."""
    from battery_predictor.simulation import get_simulator

    return get_simulator(name)


def _progress_printer(enabled: bool) -> Callable[[str, int, float], None] | None:
    if not enabled:
        return None

    def show(phase: str, evaluations: int, cost: float) -> None:
        sys.stderr.write(f"fit: {phase}: {evaluations} evaluations, 1 - cost = {1.0 - cost:.4f}\n")
        sys.stderr.flush()

    return show


def run_identify(args: argparse.Namespace) -> int:
    """Run the identification, write the fitted params, plot, and report identifiability."""
    from battery_predictor.fitting.identification import (
        DEFAULT_STARTS,
        DEFAULT_TPE_FRACTION,
        identifiability_of,
        identify_structures,
    )
    from battery_predictor.params import load_params
    from battery_predictor.plots import plot_voltage_fit
    from battery_predictor.simulation.cell_setup import is_lumped_thermal, with_thermal
    from battery_predictor.simulation.extensions import with_cold_window_anchors, with_fitted_extension_keys

    check_output_file(args.out, "--out", suffixes=(".yaml", ".yml"))
    check_plot_file(args.plot or Path(args.out).with_suffix(".png"))
    params = with_fitted_extension_keys(with_cold_window_anchors(
        with_thermal(load_params(args.params), getattr(args, "thermal", "params"))))
    thermal = "lumped" if is_lumped_thermal(params) else "isothermal"
    recs = prepared_data(args, params, command="fit")
    extra = _optional_coordinates(params, args.coordinates)
    warned: set[str] = set()
    fits = identify_structures(params, recs, simulator_named(args.simulator),
                               lambda p: _space(p, recs, extra, warned),
                               group_voltages=not getattr(args, "ignore_group_voltages", False),
                               ohmic=getattr(args, "ohmic_structure", False),
                               progress=_progress_printer(not args.no_progress and not args.json),
                               evaluations=args.evaluations, seed=args.seed,
                               tpe_fraction=DEFAULT_TPE_FRACTION if args.tpe_fraction is None else args.tpe_fraction,
                               starts=DEFAULT_STARTS if args.starts is None else args.starts)
    chosen = fits[0]
    params, problem, result, space = chosen.params, chosen.problem, chosen.result, chosen.problem.space
    best = chosen.score if chosen.score is not None else problem.score(result.coordinates)
    structures = [{"structure": f.label, "r2_mod": f.r2_mod, "evaluations": f.result.evaluations,
                   "seconds": f.result.seconds} for f in fits]
    evaluations, seconds = sum(f.result.evaluations for f in fits), sum(f.result.seconds for f in fits)
    report = identifiability_of(problem, result.unit)
    out = Path(args.out)
    states = {str(r.source): result.coordinates[c.name] for r, c in zip(recs, space[-len(recs):], strict=True)}
    provenance = _provenance(args, params, recs, best, result, report, states, thermal, problem.fits_weakest_group)
    provenance.update({"structure": chosen.label, "structures": structures})
    limits = fit_data_limits_of(args, params.with_values(best.values[0], provenance=provenance, fit=params.fit),
                                recs)
    fitted, deepest, weak_line = limits.params, limits.deepest, limits.weak_group_line
    fitted.to_yaml(out)
    plot_path = Path(args.plot) if args.plot else out.with_suffix(".png")
    plot_voltage_fit(recs, best.results, plot_path, title=f"{params.name} fit: R2_mod = {best.r2_mod:.4f}",
                     identifiability=report.plot_rows())
    if args.json:
        print_json({"method": "identify", "resample_s": args.resample, "structure": chosen.label,
                    "structures": structures, "r2_mod": best.r2_mod, "r2_mod_per_file": best.per_recording,
                    "rmse_mv_per_file": best.rmse_mv, "evaluations": evaluations,
                    "tpe_evaluations": sum(f.result.tpe_evaluations for f in fits), "seconds": seconds,
                    "model_seconds": sum(f.result.model_seconds for f in fits),
                    "optimiser_seconds": sum(f.result.optimiser_seconds for f in fits),
                    "coordinates": result.coordinates, "params": best.values[0],
                    "fitted_weakest_group_voltage": problem.fits_weakest_group,
                    "identifiability": report.to_dict(), "ocp": ocp_origin(params), "thermal": thermal,
                    "engine_fallback": engine_fallback(best.results),
                    "fit_data_deepest_state": None if deepest is None else deepest.as_thresholds(),
                    "weak_group": weak_group_json(fitted, weak_line),
                    "out": str(out), "plot": str(plot_path)})
        return 0
    if problem.fits_weakest_group:
        print("fitting the weakest measured group voltage too (cell_imbalance; --ignore-group-voltages: pack only)")
    print(f"fit of {params.name} on {len(recs)} file(s): R2_mod = {best.r2_mod:.4f} "
          f"({result.evaluations} evaluations, {result.seconds:.0f} s: model {result.model_seconds:.1f} s, "
          f"optimiser {result.optimiser_seconds:.1f} s; {ocp_origin(params)}; {thermal} cell)")
    if len(fits) > 1:
        print(f"structure: {chosen.label} (" + ", ".join(f"{f.label} R2_mod {f.r2_mod:.4f}" for f in fits)
              + f"; {evaluations} evaluations, {seconds:.0f} s in all)")
    for c in space:
        print(f"  {c.name:<34} {c.initial:>12.5g} -> {result.coordinates[c.name]:>12.5g}   "
              f"[{c.low:.4g}, {c.high:.4g}]{' log' if c.log else ''}")
    for line in report.summary_lines():
        print(line)
    if engine_fallback(best.results):
        print(f"engine fallback: {engine_fallback(best.results)}")
    print_deepest_state(deepest)
    print(weak_line)
    print(f"wrote {out} and {plot_path}")
    return 0


def _optional_coordinates(params: PackParams, requested: Sequence[str] | None) -> tuple[str, ...]:
    """``--coordinates``: the names given (``none``: no optional coordinate), else the params' default (said on
    stderr when there is one)."""
    from battery_predictor.fitting.identifiable import default_optional_coordinates

    if requested is not None:
        names = tuple(requested)
        if "none" in names and len(names) > 1:
            raise InputDataError("--coordinates none cannot be combined with coordinate names")
        return () if names == ("none",) else names
    extra = default_optional_coordinates(params)
    if extra:
        sys.stderr.write(f"fit: the params carry a measured OCV: searching {' and '.join(extra)} as well "
                         "(--coordinates none: not)\n")
    return extra


def _space(params: PackParams, recs: Sequence[Recording], extra: tuple[str, ...],
           warned: set[str] | None = None) -> list[Coordinate]:
    """The identifiable coordinates of ``params`` on ``recs`` (plus ``extra``); its warnings go to stderr, each
    once (``warned`` holds those already written)."""
    from battery_predictor.fitting.identifiable import default_space

    warned = set() if warned is None else warned
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        space = default_space(params, recs, extra=extra)
    for w in caught:
        if str(w.message) not in warned:
            warned.add(str(w.message))
            sys.stderr.write(f"warning: {w.message}\n")
    return space


def _provenance(args: argparse.Namespace, params: PackParams, recs: Sequence[Recording], best: CandidateScore,
                result: IdentificationResult, report: IdentifiabilityReport, states: dict[str, float],
                thermal: str, fits_weakest_group: bool = False) -> dict[str, Any]:
    """The fitted params file's ``provenance``: how, when and on what it was identified, the scores and the
    initial OCV (V) each data file started from."""
    return {
        "fitted_by": "battery-predictor fit --method identify (TPE + trust-region least squares in identifiable "
                     "coordinates, R2_mod of the seed paper Eq. 1-3)",
        "fitted_at": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "data": [str(r.source) for r in recs],
        "resample_s": args.resample,
        "r2_mod": best.r2_mod,
        "r2_mod_per_file": best.per_recording,
        "rmse_mv_per_file": best.rmse_mv,
        "coordinates": {k: v for k, v in result.coordinates.items() if not k.startswith("initial_ocv_v:")},
        "initial_ocv_v_per_file": states,
        "initial_state_of_this_file": "the first data file's",
        "evaluations": result.evaluations,
        "seed": args.seed,
        "simulator": args.simulator,
        "fitted_weakest_group_voltage": fits_weakest_group,
        "thermal": thermal,
        "ocp": ocp_origin(params),
        "identifiability": report.to_dict(),
        "started_from": str(args.params),
    }
