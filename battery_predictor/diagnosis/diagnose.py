"""The diagnosis procedure: what the baseline gets wrong, which cause explains it, how much it gains.

1. **Baseline.** The params' SPM pack model, fitted on the reference recordings by the project's
   identification (:func:`~battery_predictor.diagnosis.reference.identify_reference`), or taken as
   it is when there is no reference. Every run is simulated on the SPM engine where it covers the
   run, else by PyBaMM's solver (:class:`~battery_predictor.diagnosis.engine.Engine`).
2. **Split.** Each observed recording is split in time: the first ``fit_fraction`` (60 %) is
   the fit part, the rest (40 %) is held out. With one observed recording every fit sees the
   fit part and is judged on the held-out part (``split="time"``). With two or more observed
   recordings the split is *cross-recording* (``split="recordings"``, the default then unless the folds would cost more
   than :data:`MAX_FOLD_STEPS` solver steps): the
   candidate is fitted once per recording k (a fold) on every other recording **whole** plus the
   fit part of k, and the fold predicts the held-out part of k; the held-out parts of all folds
   are pooled. Nothing a fold scores was seen by that fold's fit, the held-out samples are the
   same as in the time split (so both are comparable), and the fit now sees complete
   discharges: an effect that only shows late in a discharge (a low-SOC knee, the end of a
   self-heated run) is identifiable from the other recordings, which a 60 % time split hides
   from every fit. This is the predictor's own situation: past complete days and the start of
   today predict the rest of today. The baseline, whose only unknowns are the per-recording
   initial SOCs, predicts the held-out part of k from the fit part of k alone in every fold, so
   it is fitted once on the time split. Fitted values reported for a candidate are the mean of
   its folds (``fitted_folds`` lists each).
3. **Fits with equal budgets.** The baseline is refitted on the fit part over its *state* only
   (the initial SOC of each recording, unknown on observed data); each candidate fits its few
   extra parameters plus the same initial SOCs. Every fit gets the same number of model
   evaluations (:mod:`battery_predictor.diagnosis.lsq`; with the cross-recording split, every
   fold of a candidate gets that budget and the baseline's single fit too). The baseline gets no other knob on
   purpose: a baseline allowed to refit, say, the electrode height or the interconnect
   resistance could mimic capacity fade or resistance growth, and those causes would become
   undetectable; the question asked is whether the *reference* model, in the state the data
   imply, predicts the observed data.
4. **Judged on held-out data.** Each fitted model simulates the whole recording; only the
   held-out part is scored (RMSE with the padding of R2_mod Eq. 1-2, R2_mod, runtime error),
   so a candidate wins only by predicting better, not by having more knobs.
5. **Decision.** :mod:`battery_predictor.diagnosis.decision` (the thresholds and the rule); a
   claim must also hold on the held-out samples no deeper than the references went
   (:mod:`battery_predictor.diagnosis.coverage`); the result types are
   :mod:`battery_predictor.diagnosis.results`.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from battery_predictor.diagnosis.candidates import CANDIDATES, Baseline, Candidate, candidate
from battery_predictor.diagnosis.coverage import covered_claim, measured_text, reference_coverage, refusal_text
from battery_predictor.diagnosis.decision import (
    GAIN_THRESHOLD_PCT,
    measured_causes,
    name_cause,
    near_lowest,
)
from battery_predictor.diagnosis.engine import (
    Engine,
    Observed,
    SimOut,
    observe,
    soc_from_voltage,
)
from battery_predictor.diagnosis.lsq import LsqResult, budgeted_least_squares
from battery_predictor.diagnosis.reference import (
    DEFAULT_IDENTIFY_BUDGET,
    ReferenceFit,
    identify_reference,
    reference_anchor_k,
    reference_verdict,
)
from battery_predictor.diagnosis.residuals import ResidualAnalysis, analyse_residuals, evidence_text
from battery_predictor.diagnosis.results import NOT_JUDGED, CandidateResult, Diagnosis
from battery_predictor.diagnosis.scoring import (
    fit_residual,
    held_out_score,
    noise_level_v,
    pooled,
)
from battery_predictor.errors import BatteryPredictorError, InputDataError
from battery_predictor.fitting.space import unit_to_value
from battery_predictor.params import PackParams, cached_parameter_values
from battery_predictor.processes import ProcessPool, shared
from battery_predictor.recording import Recording
from battery_predictor.simulation.extensions import ANCHOR_TEMPERATURE, with_cold_window_anchors

#: Default evaluation budget of every observed-data fit (baseline and each candidate; Jacobian columns
#: count). Why 80, and the other constants here: docs/findings.md, "Code notes (issue 15)".
DEFAULT_BUDGET = 80
#: Default evaluation budget of the reference fit (the identification on the SPM engine,
#: :mod:`battery_predictor.diagnosis.reference`).
DEFAULT_REFERENCE_BUDGET = DEFAULT_IDENTIFY_BUDGET


def _log(progress: Callable[[str], None] | None, msg: str) -> None:
    if progress is not None:
        progress(msg)


def default_progress(msg: str) -> None:
    """Print a progress line on stderr."""
    print(f"[diagnose] {msg}", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- candidate fits
def scan_initial_soc(engine: Engine, params: PackParams, obs: Observed, points: int = 25) -> float:
    """Starting SOC of a recording: the best of a grid of SOCs for the baseline on the fit part.

    The first voltage alone is a poor guess when a recording starts under load; a start that
    makes the model reach its cut-off early leaves the fit on a flat (padded) objective. Every
    model (baseline and candidates) starts its fit from this same point.
    """
    best, best_cost = soc_from_voltage(engine, params, float(obs.v[0]) / params.series), math.inf
    for soc in np.linspace(0.02, 0.98, points):
        try:
            sim = Baseline().simulate(engine, params, obs, {}, float(soc), t_end=obs.t_split)
        except BatteryPredictorError:
            continue
        r = fit_residual(obs, sim)
        cost = float(r @ r)
        if cost < best_cost:
            best, best_cost = float(soc), cost
    return best



def _fit_on(engine: Engine, cand: Candidate, params: PackParams, observed: Sequence[Observed],
            soc_guess: Sequence[float], budget: int, seed: int,
            soc_box: Sequence[tuple[float, float]] | None = None
            ) -> tuple[dict[str, float], list[float], LsqResult, float]:
    """Budgeted least squares of ``cand``'s extra parameters and the initial SOCs on the fit parts.

    ``soc_box``: per recording, the (low, high) SOC its start may take (default 0..1; see
    :func:`rest_soc_box`).
    """
    cparams = list(cand.parameters(params, observed))
    n_extra = len(cparams)
    box = list(soc_box) if soc_box is not None else [(0.0, 1.0)] * len(observed)
    rng = np.random.default_rng(seed)
    failure_value = 0.5 * params.series

    def split(u: np.ndarray) -> tuple[dict[str, float], list[float]]:
        theta = {p.name: p.to_unit(x) for p, x in zip(cparams, u[:n_extra])}
        socs = [unit_to_value(x, lo, hi) for x, (lo, hi) in zip(u[n_extra:], box)]
        return theta, socs

    def residual(u: np.ndarray) -> np.ndarray:
        theta, socs = split(u)
        out = []
        for obs, soc in zip(observed, socs):
            sim = cand.simulate(engine, params, obs, theta, soc, t_end=obs.t_split)
            out.append(fit_residual(obs, sim))
        return np.concatenate(out)

    n_res = sum(int(o.fit_mask.sum()) for o in observed)
    starts = []
    for theta0 in cand.start_points(params, rng, observed):
        u0 = [p.from_value(theta0[p.name]) for p in cparams]
        starts.append(np.array(u0 + [min(max((s - lo) / max(hi - lo, 1e-12), 0.0), 1.0)
                                     for s, (lo, hi) in zip(soc_guess, box)], dtype=float))
    res = budgeted_least_squares(residual, starts, budget,
                                 failure_residual=lambda: np.full(n_res, failure_value / math.sqrt(max(n_res, 1))))
    theta, socs = split(res.u)
    fit_rmse = 1e3 * math.sqrt(res.cost / len(observed)) if math.isfinite(res.cost) else float("inf")
    return theta, socs, res, fit_rmse


#: A recording starts at rest when its first current is below this C-rate (of the pack's nominal capacity).
REST_C_RATE = 0.02


def rest_soc_box(engine: Engine, params: PackParams, obs: Observed, tol_v: float) -> tuple[float, float]:
    """The SOCs a recording that starts at rest may start at: open-circuit voltage within ``tol_v`` of its first voltage.

    A cell at rest shows its open-circuit voltage, which the reference fit's OCPs map to an SOC within
    the reference fit's own voltage error (``tol_v``, V per cell: its RMSE plus three noise levels).
    Leaving the start free lets the baseline absorb a capacity the cell cannot deliver (a cold cell
    stopping early looks like one that started less charged). A recording that starts under load
    may start anywhere (0..1).
    """
    cap = float(params.pack_info.get("nominal_capacity_ah") or 0.0) or 1.0
    if abs(float(obs.i[0])) > REST_C_RATE * cap:
        return (0.0, 1.0)
    v_cell = float(obs.v[0]) / params.series
    pv = cached_parameter_values(params)
    ocv0, ocv100 = float(pv["Open-circuit voltage at 0% SOC [V]"]), float(pv["Open-circuit voltage at 100% SOC [V]"])
    lo = 0.0 if v_cell - tol_v <= ocv0 else soc_from_voltage(engine, params, v_cell - tol_v)
    hi = 1.0 if v_cell + tol_v >= ocv100 else soc_from_voltage(engine, params, v_cell + tol_v)
    if not lo < hi:
        return (0.0, 1.0)
    return (lo, hi)


def _predict(engine: Engine, cand: Candidate, params: PackParams, obs: Observed, theta: dict[str, float],
             soc: float) -> SimOut:
    """The whole recording simulated with the fitted values (an empty run when the model fails)."""
    try:
        return cand.simulate(engine, params, obs, theta, soc, want_temperature=True)
    except BatteryPredictorError:
        return SimOut(t=np.zeros(0), v_pack=np.zeros(0), v_cell_min=np.zeros(0), reached_cutoff=True,
                      end_time_s=0.0)


def fit_candidate(engine: Engine, cand: Candidate, params: PackParams, observed: Sequence[Observed],
                  soc_guess: Sequence[float], budget: int, seed: int = 0,
                  soc_box: Sequence[tuple[float, float]] | None = None) -> CandidateResult:
    """Fit ``cand``'s extra parameters and the initial SOCs on the fit parts; score the held-out parts."""
    tic = time.perf_counter()
    before = engine.usage()
    theta, socs, res, fit_rmse = _fit_on(engine, cand, params, observed, soc_guess, budget, seed, soc_box)
    sims = [_predict(engine, cand, params, obs, theta, soc) for obs, soc in zip(observed, socs)]
    agg = pooled([held_out_score(obs, sim) for obs, sim in zip(observed, sims)])
    return CandidateResult(cause=cand.name, fitted={k: float(v) for k, v in theta.items()}, socs=socs,
                           heldout_rmse_mV=agg["heldout_rmse_mV"], heldout_r2_mod=agg["heldout_r2_mod"],
                           runtime_error_s=agg["runtime_error_s"], fit_rmse_mV=fit_rmse,
                           evaluations=res.evaluations, failures=res.failures, seconds=time.perf_counter() - tic,
                           sims=sims, simulator=engine.usage_since(before))


def fold_observed(observed: Sequence[Observed], held: int) -> list[Observed]:
    """Fold ``held`` of the cross-recording split: every other recording whole, ``held`` split in time."""
    return [o if k == held else replace(o, t_split=float(o.t[-1])) for k, o in enumerate(observed)]


def fit_candidate_fold(engine: Engine, cand: Candidate, params: PackParams, observed: Sequence[Observed],
                       soc_guess: Sequence[float], budget: int, held: int, seed: int = 0,
                       soc_box: Sequence[tuple[float, float]] | None = None) -> dict[str, Any]:
    """One fold: fit on the other recordings whole and the first part of ``held``; predict ``held``."""
    tic = time.perf_counter()
    before = engine.usage()
    fold = fold_observed(observed, held)
    theta, socs, res, fit_rmse = _fit_on(engine, cand, params, fold, soc_guess, budget, seed, soc_box)
    sim = _predict(engine, cand, params, observed[held], theta, socs[held])
    return {"theta": {k: float(v) for k, v in theta.items()}, "soc": socs[held], "sim": sim,
            "score": held_out_score(observed[held], sim), "fit_rmse_mV": fit_rmse, "evaluations": res.evaluations,
            "failures": res.failures, "seconds": time.perf_counter() - tic, "simulator": engine.usage_since(before)}


def combine_folds(cause: str, observed: Sequence[Observed], folds: Sequence[dict[str, Any]]) -> CandidateResult:
    """Pool the folds of one candidate: recording k's held-out part is scored by the fold that held it out.

    ``fitted`` is the mean of the folds' values (per fold in ``fitted_folds``); ``socs`` are each
    recording's initial SOC from its own fold.
    """
    agg = pooled([f["score"] for f in folds])
    names = list(folds[0]["theta"]) if folds else []
    fitted = {k: float(np.mean([f["theta"][k] for f in folds])) for k in names}
    res = CandidateResult(cause=cause, fitted=fitted, socs=[f["soc"] for f in folds],
                          heldout_rmse_mV=agg["heldout_rmse_mV"], heldout_r2_mod=agg["heldout_r2_mod"],
                          runtime_error_s=agg["runtime_error_s"],
                          fit_rmse_mV=float(np.mean([f["fit_rmse_mV"] for f in folds])),
                          evaluations=sum(f["evaluations"] for f in folds),
                          failures=sum(f["failures"] for f in folds), seconds=sum(f["seconds"] for f in folds),
                          sims=[f["sim"] for f in folds], simulator=pooled_usage([f.get("simulator", {}) for f in folds]))
    res.fitted_folds = [dict(f["theta"]) for f in folds]
    return res


def pooled_usage(usages: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The solver usage of several fits (:meth:`Engine.usage_since`) summed."""
    reasons: dict[str, int] = {}
    for u in usages:
        for r, n in u.get("pybamm_reasons", {}).items():
            reasons[r] = reasons.get(r, 0) + int(n)
    return {"engine_runs": sum(int(u.get("engine_runs", 0)) for u in usages),
            "pybamm_runs": sum(int(u.get("pybamm_runs", 0)) for u in usages), "pybamm_reasons": reasons}


def usage_note(usage: dict[str, Any]) -> str:
    """``"; PyBaMM's solver for N runs: reason"`` when a fit left the SPM engine, else empty."""
    if not usage.get("pybamm_runs"):
        return ""
    reasons = "; ".join(usage.get("pybamm_reasons", {}))
    return f"; PyBaMM's solver for {usage['pybamm_runs']} of {usage['pybamm_runs'] + usage['engine_runs']} runs: {reasons}"


# --------------------------------------------------------------------------- procedure
def _fit_task(task: tuple[int, Candidate, int | None]) -> tuple[str, int | None, CandidateResult | dict | str]:
    """Worker: fit one candidate, or one fold of it (the engine, params and data come from the forked parent)."""
    k, cand, held = task
    st = shared("diagnosis_fits")
    res: CandidateResult | dict[str, Any]
    try:
        if held is None:
            res = fit_candidate(st["engine"], cand, st["params"], st["obs"], st["soc_guess"], st["budget"],
                                st["seed"] + k, st.get("soc_box"))
        else:
            res = fit_candidate_fold(st["engine"], cand, st["params"], st["obs"], st["soc_guess"], st["budget"],
                                     held, st["seed"] + k, st.get("soc_box"))
    except BatteryPredictorError as exc:
        return cand.name, held, f"failed: {exc}"
    return cand.name, held, res


def _run_fits(engine: Engine, tasks: Sequence[tuple[int, Candidate]], params: PackParams, obs: list[Observed],
              soc_guess: Sequence[float], budget: int, seed: int, workers: int,
              progress: Callable[[str], None] | None, split: str = "time",
              soc_box: Sequence[tuple[float, float]] | None = None) -> dict[str, CandidateResult | str]:
    """Fit every candidate, in ``workers`` forked processes when > 1 (each fit and each fold is independent).

    ``split="recordings"``: every candidate with extra parameters is fitted once per observed recording
    (:func:`fit_candidate_fold`) and the folds are pooled (:func:`combine_folds`); the baseline, whose
    only unknowns are the per-recording initial SOCs, gives the same held-out predictions in every fold
    and is fitted once on the time split.
    """
    state = dict(engine=engine, params=params, obs=obs, soc_guess=soc_guess, budget=budget, seed=seed,
                 soc_box=soc_box)
    # slowest structures first, so that two workers finish together
    order = {"electrolyte_transport": 0, "temperature": 1, "hysteresis": 2, "cell_imbalance": 3, "capacity_fade": 4}
    jobs: list[tuple[int, Candidate, int | None]] = []
    for k, cand in tasks:
        if split == "recordings" and cand.parameters(params, obs):
            jobs += [(k, cand, j) for j in range(len(obs))]
        else:
            jobs.append((k, cand, None))
    jobs.sort(key=lambda kc: order.get(kc[1].name, 9))
    parts: dict[str, dict] = {}
    out: dict[str, CandidateResult | str] = {}

    def collect(name: str, held: int | None, res: CandidateResult | dict | str) -> None:
        if isinstance(res, str):
            out[name] = res
        elif held is None:
            assert not isinstance(res, dict)  # a fit on every recording (no fold) is a CandidateResult
            out[name] = res
        else:
            parts.setdefault(name, {})[held] = res
            if len(parts[name]) < len(obs) or name in out:
                return
            out[name] = combine_folds(name, obs, [parts[name][j] for j in range(len(obs))])
        done = out[name]
        _log(progress, f"{name}: " + (done if isinstance(done, str) else
                                      f"held-out RMSE {done.heldout_rmse_mV:.1f} mV ({done.seconds:.0f} s"
                                      f"{usage_note(done.simulator)})"))

    n_proc = min(workers, len(jobs)) if workers > 1 and len(jobs) > 1 else 1
    with ProcessPool(n_proc, shared={"diagnosis_fits": state}) as pool:
        for name, held, res in pool.imap_unordered(_fit_task, jobs):
            if not isinstance(out.get(name), str):
                collect(name, held, res)
    return out


def default_workers() -> int:
    """Worker processes for the candidate fits: the CPUs available to this process, at most 4."""
    import os

    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:
        n = os.cpu_count() or 1
    return max(1, min(n, 4))


#: ``split="auto"`` uses the cross-recording folds only while they cost at most this many solver
#: steps (folds x current steps of all observed recordings); each fold simulates nearly all the
#: data, so N recordings cost about N times the time split. Constant-current lab discharges have
#: a handful of steps; hours of 1-10 s drive cycles have thousands and fall back to the time split.
MAX_FOLD_STEPS = 5000


def auto_split(obs: Sequence[Observed]) -> str:
    """``"recordings"`` for two or more recordings whose folds stay within :data:`MAX_FOLD_STEPS`, else ``"time"``."""
    if len(obs) < 2:
        return "time"
    steps = sum(max(len(o.load.edges_s()) - 1, 1) for o in obs)
    return "recordings" if len(obs) * steps <= MAX_FOLD_STEPS else "time"


def with_reference_anchor(params: PackParams, refs: Sequence[Observed]) -> PackParams:
    """``params`` (identified on ``refs``) with the temperature at which they hold, for the ``temperature`` candidate.

    The identified model carries the accessible capacity the reference cells had where their discharges
    ended (:func:`~battery_predictor.diagnosis.reference.reference_anchor_k`: LG M50 25 degC
    references 0.1C..2C end at 26-57 degC, anchor 36.4 degC); the extension ``temperature`` changes
    nothing at that temperature. Unchanged (anchor 298.15 K) when a reference has no measured temperature.

    Parameters
    ----------
    params : PackParams
        The reference-identified params.
    refs : sequence of Observed
        The reference recordings (measured temperature in K, current in A, discharge positive).

    Returns
    -------
    PackParams
        ``params`` with ``Temperature extension anchor temperature [K]`` in ``cell.extra``.
    """
    if not refs or any(r.temperature_k is None for r in refs):
        return params
    anchor_k = reference_anchor_k([r.temperature_k for r in refs], [r.i for r in refs])
    return replace(params, extra={**params.extra, ANCHOR_TEMPERATURE: anchor_k})


def diagnose(params: PackParams, observed: Sequence[Recording], references: Sequence[Recording] = (), *,
             budget: int = DEFAULT_BUDGET, reference_budget: int = DEFAULT_REFERENCE_BUDGET,
             fit_fraction: float = 0.6, causes: Sequence[str] | None = None, seed: int = 0,
             progress: Callable[[str], None] | None = None, engine: Engine | None = None,
             workers: int | None = None, split: str = "auto", start_at_rest: bool = False) -> Diagnosis:
    """Diagnose what the baseline pack model gets wrong on ``observed`` (see the module docstring).

    Parameters
    ----------
    params : PackParams
        The pack model (fitted already when ``references`` is empty).
    observed : sequence of Recording
        The recordings to explain (whole recordings: charge phases and rests are kept).
    references : sequence of Recording
        Recordings without the effect; the baseline is fitted on them first.
    budget : int
        Model evaluations of each observed-data fit (baseline and every candidate alike).
    reference_budget : int
        Model evaluations of each identification of the reference fit (up to three,
        :func:`~battery_predictor.diagnosis.reference.identify_reference`).
    fit_fraction : float
        Fraction of each observed recording (in time) used for fitting; the rest is held out.
    split : {"auto", "time", "recordings"}
        ``"time"``: every fit sees the first ``fit_fraction`` of every recording. ``"recordings"``
        (cross-recording folds, needs >= 2 observed recordings): the fold of recording k fits on
        every other recording whole and on the first ``fit_fraction`` of k, and predicts the rest
        of k. ``"auto"`` (default): ``"recordings"`` for two or more observed recordings while
        the folds stay affordable (:func:`auto_split`), else ``"time"``. The held-out samples are the same in both; see the module docstring.
    causes : sequence of str, optional
        Candidate causes to try (default all).
    workers : int, optional
        Processes for the (independent) candidate fits; default :func:`default_workers`.
    start_at_rest : bool
        With references: a recording that starts at rest starts within the reference fit's voltage
        error of its first voltage (:func:`rest_soc_box`) instead of at any SOC. Off by default: on
        the LG M50 0 degC discharges it changed the baseline's held-out RMSE by 1 % (146.6 -> 145.2 mV).
    """
    tic = time.perf_counter()
    _check_arguments(observed, budget, split)
    engine = engine or Engine()
    workers = default_workers() if workers is None else max(1, int(workers))
    reference = None
    refs: list[Observed] = []
    if references:
        refs = [observe(r, params, fit_fraction=0.95, name=str(r.source)) for r in references]
        params, reference = identify_reference(params, references, reference_budget, seed, progress,
                                               noise_mv=1e3 * noise_level_v(refs))
        params = with_reference_anchor(params, refs)
    # a cold window narrows towards the diagnosed cell's charged end for every candidate (one engine extraction)
    params = with_cold_window_anchors(params)
    obs = [observe(r, params, fit_fraction=fit_fraction, name=str(r.source)) for r in observed]
    if reference is not None:
        refusal = reference_verdict(reference, 1e3 * noise_level_v(refs))
        if refusal is not None:
            _log(progress, refusal)
            return not_judged(params, obs, reference, refusal, budget, fit_fraction, causes,
                              time.perf_counter() - tic)
    if split == "auto":
        split = auto_split(obs)
    soc_box = _rest_soc_boxes(engine, params, obs, reference, progress) if start_at_rest else None
    soc_guess = [scan_initial_soc(engine, params, o) for o in obs]
    if soc_box is not None:
        soc_guess = [min(max(g, lo), hi) for g, (lo, hi) in zip(soc_guess, soc_box)]
    tasks, not_applicable = _candidate_tasks(params, obs, causes)
    runnable = [(k, c) for k, c in tasks if c.name not in not_applicable]
    how = (f"one fold per recording (the others whole + the first {100 * fit_fraction:.0f} % of it)"
           if split == "recordings" else f"the first {100 * fit_fraction:.0f} % of every recording")
    _log(progress, f"fitting the baseline (initial SOC only) and {len(runnable) - 1} candidates on {how}, budget "
                   f"{budget} evaluations each fit, {workers} worker(s)")
    fitted = _run_fits(engine, runnable, params, obs, soc_guess, budget, seed, workers, progress, split, soc_box)
    base = fitted["none"]
    if isinstance(base, str):
        raise BatteryPredictorError(f"the baseline cannot be simulated on the observed data: {base}")
    results = _candidate_results(tasks[1:], fitted, not_applicable, base)
    _log(progress, f"held-out RMSE: baseline {base.heldout_rmse_mV:.1f} mV; " + ", ".join(
        f"{r.cause} {r.heldout_rmse_mV:.1f} mV ({r.gain_pct:+.0f} %)" for r in results if r.applicable))
    return _decide(engine, params, obs, refs, reference, base, results,
                   dict(seconds=time.perf_counter() - tic, budget=budget, fit_fraction=fit_fraction, split=split))


def _check_arguments(observed: Sequence[Recording], budget: int, split: str) -> None:
    """The arguments :func:`diagnose` refuses before any work (no data, a budget below 2, an unknown split)."""
    if not observed:
        raise InputDataError("no observed data to diagnose")
    if budget < 2:
        raise BatteryPredictorError(f"--budget must be >= 2, got {budget}")
    if split not in ("auto", "time", "recordings"):
        raise BatteryPredictorError(f"split must be auto, time or recordings, got {split!r}")
    if split == "recordings" and len(observed) < 2:
        raise BatteryPredictorError("the cross-recording split needs at least two observed recordings")


def _rest_soc_boxes(engine: Engine, params: PackParams, obs: list[Observed], reference: ReferenceFit | None,
                    progress: Callable[[str], None] | None) -> list[tuple[float, float]] | None:
    """Per recording, the SOC range its start may take (:func:`rest_soc_box`); None without a reference fit.

    The tolerance is the reference fit's RMSE plus three times the data's voltage noise, per cell (V).
    """
    if reference is None:
        return None
    tol_v = (reference.rmse_mV + 3.0 * 1e3 * noise_level_v(obs)) * 1e-3 / params.series
    soc_box = [rest_soc_box(engine, params, o, tol_v) for o in obs]
    pinned = [k for k, b in enumerate(soc_box) if b != (0.0, 1.0)]
    if pinned:
        _log(progress, f"{len(pinned)} recording(s) start at rest: their initial SOC is searched where the "
                       f"open-circuit voltage is within {1e3 * tol_v:.0f} mV per cell of the first voltage")
    return soc_box


def _candidate_tasks(params: PackParams, obs: list[Observed], causes: Sequence[str] | None
                     ) -> tuple[list[tuple[int, Candidate]], dict[str, str]]:
    """The fits to run, ``(seed offset, candidate)`` with the baseline first, and why a candidate does not apply."""
    cands = [c for c in CANDIDATES if causes is None or c.name in causes]
    unknown = set(causes or ()) - {c.name for c in CANDIDATES} - {"none"}
    if unknown:
        raise BatteryPredictorError(f"unknown cause(s): {', '.join(sorted(unknown))}")
    tasks: list[tuple[int, Candidate]] = [(0, Baseline())] + [(k + 1, c) for k, c in enumerate(cands)]
    not_applicable: dict[str, str] = {}
    for _k, cand in tasks:
        reason = cand.applicable(params, obs)
        if reason:
            not_applicable[cand.name] = reason
    return tasks, not_applicable


def _candidate_results(tasks: Sequence[tuple[int, Candidate]], fitted: dict[str, CandidateResult | str],
                       not_applicable: dict[str, str], base: CandidateResult) -> list[CandidateResult]:
    """Every candidate's result with its held-out gain over ``base`` (%); one that did not apply or failed says why."""
    results = []
    for _, cand in tasks:
        res = fitted[cand.name] if cand.name in fitted else not_applicable[cand.name]
        if isinstance(res, str):
            res = CandidateResult(cause=cand.name, fitted={}, socs=[], heldout_rmse_mV=float("nan"),
                                  heldout_r2_mod=float("nan"), runtime_error_s=None, fit_rmse_mV=float("nan"),
                                  evaluations=0, failures=0, seconds=0.0, applicable=False, reason=res)
        else:
            res.gain_pct = 100.0 * (base.heldout_rmse_mV - res.heldout_rmse_mV) / base.heldout_rmse_mV
        results.append(res)
    return results


def _mark_unresolved(result: CandidateResult, obs: Sequence[Observed]) -> bool:
    """Whether ``result``'s fitted effect is below what the instruments resolve (:meth:`Candidate.unresolved`);
    the reason goes to ``result.unresolved``."""
    why = candidate(result.cause).unresolved(result.fitted, obs)
    result.unresolved = why or ""
    return why is not None


def _decide(engine: Engine, params: PackParams, obs: list[Observed], refs: list[Observed],
            reference: ReferenceFit | None, base: CandidateResult, results: list[CandidateResult],
            run: dict[str, Any]) -> Diagnosis:
    """Name the cause (:func:`name_cause`) and write the evidence.

    ``run`` holds the :class:`Diagnosis` fields of the run itself (``seconds``, ``budget``,
    ``fit_fraction``, ``split``).
    """
    analysis = analyse_residuals(engine, params, obs, base)
    valid = [r for r in results if r.applicable and math.isfinite(r.heldout_rmse_mV)
             and not _mark_unresolved(r, obs)]
    noise_mv = 1e3 * noise_level_v(obs)
    shift_k = None
    if refs and all(o.temperature_k is not None for o in obs) and all(r.temperature_k is not None for r in refs):
        shift_k = float(np.mean([o.mean_temperature_k for o in obs]) - np.mean([r.mean_temperature_k for r in refs]))
    measured_first = measured_causes(shift_k)
    floor_mv = max(noise_mv, reference.rmse_mV if reference is not None else 0.0)
    best, cause = name_cause(valid, base.heldout_rmse_mV, noise_mv, floor_mv, shift_k)
    extended, gain = (best, best.gain_pct) if cause != "none" and best is not None else (base, 0.0)
    # the claim must hold where the references were (mod:`coverage`): not only beyond their depth
    coverage = None
    if reference is not None and refs:
        offset_a = candidate(cause).sensor_offset_a(best.fitted) if best is not None and cause != "none" else 0.0
        coverage = reference_coverage(refs, reference, obs, offset_a)
    refusal = caveat = None
    if cause != "none" and best is not None and coverage is not None and not covered_claim(
            coverage, cause, obs, base.sims, best.sims, noise_mv, floor_mv):
        if cause in measured_first:  # the change is measured, not inferred from the error beyond the references
            coverage.refused, coverage.measured = False, True
            caveat = measured_text(coverage, cause, shift_k)
        else:
            refusal = refusal_text(coverage, cause, gain)
            cause, extended, gain = "none", base, 0.0
    close = []
    if cause != "none":
        close = [r.cause for r in near_lowest(valid, noise_mv) if r is not best and r.gain_pct >= GAIN_THRESHOLD_PCT]
    evidence = evidence_text(cause, base, best, results, analysis, noise_mv, close, floor_mv, shift_k, refusal)
    if caveat:
        evidence += " " + caveat
    for r in results:
        if r.unresolved and r.gain_pct >= GAIN_THRESHOLD_PCT:
            evidence += f" {r.cause} cut the held-out error by {r.gain_pct:.0f} % but is not named: {r.unresolved}."
    return Diagnosis(cause=cause, evidence=evidence, baseline=base, extended=extended, gain_pct=gain,
                     candidates=results, residuals=analysis, noise_mV=noise_mv, params=params, observed=obs,
                     reference=reference, separable_with=close, temperature_shift_k=shift_k, coverage=coverage,
                     **run)


def not_judged(params: PackParams, obs: Sequence[Observed], reference: ReferenceFit, reason: str, budget: int,
               fit_fraction: float, causes: Sequence[str] | None, seconds: float) -> Diagnosis:
    """The diagnosis that refuses to judge: cause :data:`NOT_JUDGED`, no candidate fitted, ``reason`` as evidence."""
    def empty(cause: str) -> CandidateResult:
        return CandidateResult(cause=cause, fitted={}, socs=[], heldout_rmse_mV=float("nan"),
                               heldout_r2_mod=float("nan"), runtime_error_s=None, fit_rmse_mV=float("nan"),
                               evaluations=0, failures=0, seconds=0.0, applicable=False,
                               reason="not judged: the reference fit is too poor")

    base = empty("none")
    cands = [empty(c.name) for c in CANDIDATES if causes is None or c.name in causes]
    residuals = ResidualAnalysis(eta2={}, pearson_r={}, rmse_mV=float("nan"), mean_mV=float("nan"), collinear=[])
    return Diagnosis(cause=NOT_JUDGED, evidence=reason, baseline=base, extended=base, gain_pct=0.0,
                     candidates=cands, residuals=residuals, noise_mV=1e3 * noise_level_v(list(obs)), params=params,
                     observed=list(obs), reference=reference, seconds=seconds, budget=budget,
                     fit_fraction=fit_fraction, judged=False)
