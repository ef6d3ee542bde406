"""Why ``identify`` lands in different basins per seed: every stage of it logged, per seed (issue 17).

Runs ``fit``'s identification (``identify`` on ``fit``'s own problem: ``default_space``, the params'
cut-off, 1000 evaluations) for each ``--seeds`` value and prints, per stage (the 30 s coarse stage and
the refinement on the data as given, or the one stage with ``--coarse-window 0``): the best TPE
candidates, each refinement's start and end (cost, R2_mod, coordinates on the unit cube), and which end
``select_by_r2_mod`` returns; for each refinement end and the result, each recording's model end minus its
recording's end (s: a model running thousands of s into a recording's padding is past the cost's cliff,
docs/identification_k2/README.md). R2_mod of a coarse-stage point is given on the coarse data (what the
selection sees) and on the data as given. The library is instrumented by wrapping ``_run_tpe``,
``_refine`` and ``select_by_r2_mod``; nothing else changes.

``--variant`` tests a change without touching the package:

``default``
    ``identify`` as it is.
``by-cost``
    the end point chosen by the lowest cost instead of the highest R2_mod.
``whole-mean``
    the padding past a recording's end (``request_for_recording``'s ``extend_s``) runs at the whole
    recording's mean current (the package before 2026-11-27's sixteenth session) instead of
    :func:`~battery_predictor.fitting.problem.end_current_a` during the search; the result is scored with
    the padding as it is (the R2_mod ``fit`` reports).

Usage (from the repository root)::

    D=../shared/data/k2_lfp26650_arts
    PYTHONPATH=$PWD .venv/bin/python benchmarks/identification_seed_spread.py \\
        docs/identification_k2/k2_lfp26650_hysteresis.yaml --data $D/cc_discharge_T20C.csv $D/hppc_T20C.csv \\
        --seeds 0 1 2 --coarse-window 30
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from rc_branch_posthoc import _fit_data  # noqa: E402

from battery_predictor.cli.fit_identify import _space, simulator_named  # noqa: E402
from battery_predictor.errors import SimulationError  # noqa: E402
from battery_predictor.fitting import identification as ident  # noqa: E402
from battery_predictor.fitting import problem as fproblem  # noqa: E402
from battery_predictor.fitting.identification import IdentificationProblem  # noqa: E402
from battery_predictor.simulation.load import StepLoad  # noqa: E402

LOG: list[tuple] = []
ORIG_TPE, ORIG_REFINE, ORIG_SELECT = ident._run_tpe, ident._refine, ident.select_by_r2_mod
ORIG_REQUEST = fproblem.request_for_recording
def _r2(problem: IdentificationProblem, unit: np.ndarray) -> float:
    try:
        return problem.score(problem.coordinates(unit)).r2_mod
    except SimulationError:
        return -np.inf


def _gaps(problem: IdentificationProblem, unit: np.ndarray) -> str:
    """Model end minus recording end (s) per recording: where the end sits against the padding's cliff."""
    try:
        results, _ = problem.simulate(problem.coordinates(unit))
    except SimulationError:
        return "failed"
    return "/".join(f"{r.end_time_s - rec.duration_s:+.0f}" for r, rec in zip(results, problem.recordings, strict=True))


def request_whole_mean(params, rec, *, initial_state="auto", extend_s=0.0):  # noqa: ANN001, ANN201
    """``request_for_recording`` with the padding run at the whole recording's mean current."""
    req = ORIG_REQUEST(params, rec, initial_state=initial_state, extend_s=0.0)
    if extend_s <= 0:
        return req
    load = req.load.append(StepLoad.constant(max(req.load.mean_current_a(), 0.0), extend_s))
    t = rec.relative_time_s
    dt = float(np.median(np.diff(t)))
    out_t = np.concatenate([t, np.arange(t[-1] + dt, load.end_s, dt)])
    return replace(req, load=load, output_time_s=out_t)


def _units(u: np.ndarray) -> str:
    return "[" + " ".join(f"{x:.3f}" for x in u) + "]"


def tpe(problem, residual, n_trials, seed, start_unit, startup_per_coordinate):  # noqa: ANN001, ANN201
    done = ORIG_TPE(problem, residual, n_trials, seed, start_unit, startup_per_coordinate)
    LOG.append(("tpe", problem, done))
    return done


def refine(residual, start, max_evaluations):  # noqa: ANN001, ANN201
    r0 = residual(start)
    cost, unit = ORIG_REFINE(residual, start, max_evaluations)
    LOG.append(("refine", np.array(start), float(r0 @ r0), cost, unit, max_evaluations))
    return cost, unit


def select(problem, ends):  # noqa: ANN001, ANN201
    chosen = ORIG_SELECT(problem, ends)
    LOG.append(("select", problem, list(ends), chosen))
    return chosen


def select_by_cost(problem, ends):  # noqa: ANN001, ANN201
    chosen = min(ends, key=lambda e: e[0])
    LOG.append(("select", problem, list(ends), chosen))
    return chosen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("start")
    ap.add_argument("--data", nargs="+", required=True)
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--coarse-window", type=float, default=ident.COARSE_WINDOW_S, help="0: one stage")
    ap.add_argument("--evaluations", type=int, default=1000)
    ap.add_argument("--variant", choices=["default", "by-cost", "whole-mean"], default="default")
    ap.add_argument("--top", type=int, default=5, help="TPE candidates shown")
    ap.add_argument("--coordinates", nargs="*", default=[], help="optional coordinates, as fit's --coordinates")
    a = ap.parse_args()
    params, recs = _fit_data(a.start, a.data)
    problem = IdentificationProblem(params=params, recordings=recs, simulator=simulator_named("engine"),
                                    space=_space(params, recs, tuple(a.coordinates)))
    print("coordinates:", " ".join(problem.names))
    ident._run_tpe, ident._refine = tpe, refine
    ident.select_by_r2_mod = select_by_cost if a.variant == "by-cost" else select
    coarse = {"coarse_window_s": a.coarse_window or None}
    summary = []
    for seed in a.seeds:
        LOG.clear()
        tic = time.perf_counter()
        if a.variant == "whole-mean":
            fproblem.request_for_recording = request_whole_mean
        res = ident.identify(problem, evaluations=a.evaluations, seed=seed, **coarse)
        cost, unit = res.cost, res.unit
        wall = time.perf_counter() - tic
        fproblem.request_for_recording = ORIG_REQUEST
        r2 = _r2(problem, unit)
        print(f"\n=== seed {seed}: R2_mod {r2:.4f} (ends {_gaps(problem, unit)} s), cost {cost:.5f}, {wall:.0f} s ({a.variant}, coarse "
              f"{a.coarse_window or 'off'})")
        stage = "coarse" if a.coarse_window else "one stage"
        for entry in LOG:
            if entry[0] == "tpe":
                prob, done = entry[1], entry[2]
                best = sorted(done, key=lambda c: c[0])[: a.top]
                print(f"  [{stage}] TPE {len(done)} trials; best {a.top}: cost (R2_mod on its data"
                      + (", on the data as given" if prob is not problem else "") + ") unit")
                for c, u in best:
                    extra = f", {_r2(problem, u):.4f}" if prob is not problem else ""
                    print(f"    {c:.5f} ({_r2(prob, u):.4f}{extra}) {_units(u)}")
            elif entry[0] == "refine":
                _, s, c0, c1, u, budget = entry
                print(f"  [{stage}] refine (budget {budget}): start {c0:.5f} {_units(s)} -> end {c1:.5f} {_units(u)}"
                      f"  R2_mod as given {_r2(problem, u):.4f}"
                      f", model end - recording end {_gaps(problem, u)} s")
            elif entry[0] == "select":
                prob, ends, chosen = entry[1], entry[2], entry[3]
                print(f"  [{stage}] ends (cost, R2_mod on its data): "
                      + "; ".join(f"{c:.5f}, {_r2(prob, u):.4f}" for c, u in ends)
                      + f" -> chosen cost {chosen[0]:.5f}")
                stage = "as given"
        summary.append((seed, r2, wall))
    print("\nseed  R2_mod  wall s")
    for seed, r2, wall in summary:
        print(f"{seed:4d}  {r2:.4f}  {wall:.0f}")
    print(f"mean {np.mean([s[1] for s in summary]):.4f}, min {min(s[1] for s in summary):.4f}")


if __name__ == "__main__":
    main()
