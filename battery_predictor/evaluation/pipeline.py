"""The paper's evaluation end to end (``battery-predictor evaluate``): recordings in, report and figures out.

:func:`evaluate_paper` runs the parts :class:`PaperEvaluation` asks for (Table 2, remaining runtime,
the stepwise fit, routes), writes the figures and ``report.md`` / ``summary.json`` into ``out`` and
returns the summary. The CLI only parses, calls and prints.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from battery_predictor.errors import InputDataError
from battery_predictor.evaluation import report
from battery_predictor.evaluation.paper_eval import (
    PAPER,
    fit_pack,
    route_evaluation,
    route_summary,
    runtime_evaluation,
    runtime_summary,
    score_fit,
    table2,
)
from battery_predictor.fitting.data_limits import with_fit_data_limits
from battery_predictor.fitting.problem import trim_to_discharge
from battery_predictor.io.loader import load_recording
from battery_predictor.io.paths import portable_paths
from battery_predictor.params import PackParams, load_params
from battery_predictor.prediction.core import PredictorConfig

#: PyBaMM parameter sets Table 2 compares.
BASE_SETS = ("Chen2020", "NCA_Kim2011", "OKane2022")
#: Parts that can be skipped.
PARTS = ("table2", "runtime", "routes", "stepwise")


@dataclass(frozen=True)
class PaperEvaluation:
    """What :func:`evaluate_paper` evaluates, and how.

    Attributes
    ----------
    temi_params, ranger_params : str
        Params files of the information and the luggage robot.
    temi_dynamic : list of str
        Information-robot dynamic discharges (the first is the fit data).
    temi_static : str or None
        Information-robot static discharge (Table 2's validation).
    ranger_stepwise : str or None
        Luggage-robot stepwise experiment.
    ranger_routes : list of str
        Luggage-robot recordings of repeated longest routes.
    route_payload_kg : list of float or None
        Payload per route recording (kg), for recordings without route metadata.
    base_sets : list of str
        PyBaMM sets of Table 2.
    trials, seed : int
        TPE trials per fit and the seed.
    storage : str or None
        Optuna storage URL of the fits (None: in memory).
    workers : int
        Processes per fit.
    skip : list of str
        Parts of :data:`PARTS` to skip.
    out : Path
        Report directory (exists).
    """

    temi_params: str
    ranger_params: str
    temi_dynamic: list[str]
    temi_static: str | None
    ranger_stepwise: str | None
    ranger_routes: list[str]
    out: Path
    route_payload_kg: list[float] | None = None
    base_sets: list[str] = field(default_factory=lambda: list(BASE_SETS))
    trials: int = 300
    seed: int = 0
    storage: str | None = None
    workers: int = 1
    skip: list[str] = field(default_factory=list)


def bundled_recordings(bags: Path, pattern: str) -> list[str]:
    """The bags (directories or ``.mcap`` files) in ``bags`` matching ``pattern``, sorted."""
    return sorted(str(p) for p in bags.glob(pattern) if p.is_dir() or p.suffix == ".mcap")


def predictor_peak_quantile() -> float:
    """The predictor's default load-peak quantile (``PredictorConfig.peak_current_quantile``)."""
    default = next(f.default for f in dataclasses.fields(PredictorConfig) if f.name == "peak_current_quantile")
    assert isinstance(default, float)
    return default


def check_recordings(ev: PaperEvaluation, bags: Path) -> None:
    """Raise :class:`InputDataError` when a part that runs has no recordings (``bags``: where they were sought)."""
    need_temi = "table2" not in ev.skip or "runtime" not in ev.skip
    if need_temi and (not ev.temi_dynamic or ("table2" not in ev.skip and ev.temi_static is None)):
        raise InputDataError(f"{bags}: no information-robot recordings (temi_dynamic_*, temi_static_*)")
    if "routes" not in ev.skip and not ev.ranger_routes:
        raise InputDataError(f"{bags}: no luggage-robot route recordings (ranger_route_*)")


def evaluate_paper(ev: PaperEvaluation, *, log: Callable[[str], None] = lambda _msg: None) -> dict[str, Any]:
    """Run the evaluation, write the report; returns the summary (with ``seconds`` and ``report``)."""
    tic = time.perf_counter()
    summary: dict[str, Any] = {
        "paper": {k: v for k, v in PAPER.items() if k != "table2"},
        "settings": {"trials per fit": ev.trials, "seed": ev.seed, "base sets": " ".join(ev.base_sets),
                     "skipped": " ".join(ev.skip) or "none", "storage": ev.storage or "memory"}}
    figures: dict[str, Path | None] = {}
    temi = load_params(ev.temi_params)
    need_temi = "table2" not in ev.skip or "runtime" not in ev.skip
    dyn = [trim_to_discharge(load_recording(f)) for f in ev.temi_dynamic] if need_temi else []
    runtime_params = temi
    if "table2" not in ev.skip:
        runtime_params = _table2_part(ev, temi, dyn, summary, figures, log)
    if "runtime" not in ev.skip:
        _runtime_part(ev, runtime_params, dyn, summary, figures, log)
    if "routes" not in ev.skip and ev.ranger_routes:
        _routes_part(ev, summary, figures, log)
    md = report.write_markdown(ev.out, portable_paths(summary), figures)
    summary["seconds"] = time.perf_counter() - tic
    summary["report"] = str(md)
    return summary


def _table2_part(ev: PaperEvaluation, temi: PackParams, dyn: Sequence, summary: dict, figures: dict,
                 log: Callable[[str], None]) -> PackParams:
    """Table 2 and Fig. 4; returns the params the runtime part uses (Chen2020 fitted on the dynamic profile)."""
    assert ev.temi_static is not None  # Table 2 is run only with the static recording
    static = trim_to_discharge(load_recording(ev.temi_static))
    log(f"Table 2: {len(ev.base_sets)} parameter sets x 2 profiles, {ev.trials} trials each ...")
    rows = table2(temi, dyn[0], static, base_sets=ev.base_sets, trials=ev.trials, seed=ev.seed,
                  progress=lambda m: log("  " + m), storage=ev.storage, workers=ev.workers)
    summary["table2"] = [{"opt_profile": r.opt_profile, "base_parameter_set": r.base_parameter_set,
                          "opt_r2_mod": r.opt_r2_mod, "val_r2_mod": r.val_r2_mod,
                          "parameters": list(r.parameters)} for r in rows]
    figures["Fig. 4 kind: fit and validation"] = report.fig_fit(rows, dyn[0], static, ev.out / "fig4_fit.png")
    chosen = next((r for r in rows if r.base_parameter_set == "Chen2020" and r.opt_profile == "dynamic"
                   and r.opt_result is not None), None)
    if chosen is None:
        return temi
    runtime_params = dataclasses.replace(chosen.params, source=str(ev.out / "temi_fit_dynamic.yaml"))
    runtime_params.to_yaml(ev.out / "temi_fit_dynamic.yaml")
    return runtime_params


def _runtime_part(ev: PaperEvaluation, params: PackParams, dyn: Sequence, summary: dict, figures: dict,
                  log: Callable[[str], None]) -> None:
    """Remaining runtime (5.1.6, Fig. 5) with the paper's strategy and the predictor's load peaks."""
    log(f"runtime evaluation on {len(dyn)} dynamic discharge(s) ...")
    points = runtime_evaluation(params, dyn)
    summary["runtime"] = runtime_summary(points)
    summary["runtime_points"] = [dataclasses.asdict(p) for p in points]
    figures["Fig. 5 kind: remaining runtime (paper strategy)"] = report.fig_runtime(points,
                                                                                   ev.out / "fig5_runtime.png")
    log(f"  paper strategy (average load): MAE {summary['runtime']['mae_min']:.2f} min, MAPE "
        f"{summary['runtime']['mape_pct']:.1f} % (paper {PAPER['runtime_mae_min']} min, "
        f"{PAPER['runtime_mape_pct']} %)")
    q = predictor_peak_quantile()
    if q <= 0:
        return
    peak_points = runtime_evaluation(params, dyn, peak_current_quantile=q)
    summary["runtime_peaks"] = {**runtime_summary(peak_points), "peak_current_quantile": q}
    summary["runtime_peaks_points"] = [dataclasses.asdict(p) for p in peak_points]
    figures["Fig. 5 kind: remaining runtime (load peaks, the predictor's default)"] = report.fig_runtime(
        peak_points, ev.out / "fig5_runtime_peaks.png")
    log(f"  predictor default (load peaks, quantile {q}): MAE {summary['runtime_peaks']['mae_min']:.2f} min, "
        f"MAPE {summary['runtime_peaks']['mape_pct']:.1f} %")


def _routes_part(ev: PaperEvaluation, summary: dict, figures: dict, log: Callable[[str], None]) -> None:
    """The stepwise fit (5.2.3, Fig. 7) unless skipped, then the route decisions (5.2.4, Fig. 8)."""
    ranger = load_params(ev.ranger_params)
    if ev.ranger_stepwise is not None and "stepwise" not in ev.skip:
        step = trim_to_discharge(load_recording(ev.ranger_stepwise))
        log(f"luggage robot: fitting the stepwise experiment ({ev.trials} trials) ...")
        ranger, _, _ = fit_pack(ranger, [step], trials=ev.trials, seed=ev.seed, screen_first=False,
                                storage=ev.storage, workers=ev.workers)
        score, res = score_fit(ranger, step)
        limits = with_fit_data_limits(ranger, [step])  # as `fit` keeps them: the deepest state, the weak group
        ranger = limits.params
        log(f"  {limits.weak_group_line}")
        summary["stepwise"] = {"r2_mod": score, "weak_group": limits.weak_group_line,
                               "fit_data_deepest_state": None if limits.deepest is None else limits.deepest.as_thresholds()}
        figures["Fig. 7 kind: stepwise experiment"] = report.fig_stepwise(step, res, score,
                                                                          ev.out / "fig7_stepwise.png")
        ranger = dataclasses.replace(ranger, source=str(ev.out / "ranger_fit_stepwise.yaml"))
        ranger.to_yaml(ev.out / "ranger_fit_stepwise.yaml")
    log(f"route evaluation on {len(ev.ranger_routes)} recording(s) ...")
    cases = route_evaluation(ranger, [load_recording(f) for f in ev.ranger_routes], ev.route_payload_kg)
    summary["routes"] = route_summary(cases)
    summary["route_cases"] = [dataclasses.asdict(c) for c in cases]
    figures["Fig. 8 kind: routes"] = report.fig_routes(cases, float(ranger.thresholds["route_min_voltage_v"]),
                                                       ev.out / "fig8_routes.png")
    r = summary["routes"]
    log(f"  MAE {r['mae_v']:.3f} V, MAPE {r['mape_pct']:.2f} % (paper {PAPER['route_mae_v']} V, "
        f"{PAPER['route_mape_pct']} %); decisions {r['decisions_correct']}/{r['decisions']} correct, "
        f"{r['unsafe_accepts']} unsafe")
