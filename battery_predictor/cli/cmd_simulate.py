"""``battery-predictor simulate``: drive a pack model with measured current and score it."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from battery_predictor.cli.common import (
    add_data_arguments,
    add_resample_arguments,
    check_plot_file,
    engine_fallback,
    prepared_data,
    print_json,
)
from battery_predictor.simulation import SIMULATORS

if TYPE_CHECKING:
    from collections.abc import Sequence

    from battery_predictor.params import PackParams
    from battery_predictor.recording import Recording
    from battery_predictor.simulation.base import PackSimResult, PackSimulator


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="score a params file on measured data (R2_mod, RMSE, runtime)")
    p.add_argument("--params", required=True, help="params YAML (e.g. the output of fit)")
    add_data_arguments(p)
    p.add_argument("--simulator", choices=SIMULATORS, default=SIMULATORS[0],
                   help="engine (default: PyBaMM's SPM stepped exactly, milliseconds per day; hands what it does not "
                        "cover to fast and says so), fast (PyBaMM's solver) or liionpack (reference)")
    p.add_argument("--thermal", choices=("params", "isothermal", "lumped"), default="params",
                   help="cell thermal model: as the params say (default; cell.options thermal), isothermal at the "
                        "data's temperature, or lumped (PyBaMM's lumped thermal cell self-heating from it)")
    p.add_argument("--initial-state", choices=("auto", "params", "voltage"), default="auto",
                   help="initial state: params' concentrations or first measured voltage; default auto: with a "
                        "fit's params, each data file of that fit from its fitted state and every other recording "
                        "from its own first voltage, else as the params say; a first voltage under load is "
                        "corrected by the model's own drop at that current")
    add_resample_arguments(p, "simulate")
    p.add_argument("--plot", default=None, help="write measured vs simulated voltage to this PNG")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from battery_predictor.cli.fit_identify import simulator_named
    from battery_predictor.params import load_params

    if args.plot:
        check_plot_file(args.plot)
    tic = time.perf_counter()
    from battery_predictor.simulation.cell_setup import is_lumped_thermal, with_thermal

    params = with_thermal(load_params(args.params), args.thermal)
    recs = prepared_data(args, params, command="simulate")
    rows, results = _score(params, recs, simulator_named(args.simulator), args.initial_state)
    out = _summary(rows, results, time.perf_counter() - tic, args.simulator)
    out["engine_fallback"] = engine_fallback(results)  # why the engine handed a recording on (None: it did not)
    out["thermal"] = "lumped" if is_lumped_thermal(params) else "isothermal"
    out["resample_s"] = args.resample  # the window the data were averaged over (None: as measured)
    if args.plot:
        from battery_predictor.plots import plot_voltage_fit

        out["plot"] = str(plot_voltage_fit(recs, results, args.plot, title=f"{params.name}: R2_mod = {out['r2_mod']:.4f}"))
    if args.json:
        print_json(out)
        return 0
    _print_summary(out, rows, args.simulator)
    return 0


def _score(params: PackParams, recs: Sequence[Recording], sim: PackSimulator,
           initial_state: str) -> tuple[list[dict[str, Any]], list[PackSimResult]]:
    """Simulate every recording from its start and score it: one row per recording and the simulations.

    Each row has ``r2_mod``, ``rmse_mV``, the measured and simulated runtime (s: the times at which the
    recording and the run first reach the recording's lowest voltage; the simulated one None when the run
    never reaches it), where the recording's discharge ends (s; later than its lowest voltage when that fell in a
    burst before) and the initial OCV used (V, None with the params' initial state).
    """
    from dataclasses import replace

    import numpy as np

    from battery_predictor.fitting.cost import r2_mod, rmse_v
    from battery_predictor.fitting.problem import loaded_start_ocv_v, request_for_recording, starts_at_rest
    from battery_predictor.recording import ends_at_cutoff

    fitted_ocv_v = _fitted_initial_ocvs_v(params) if initial_state == "auto" else {}
    rows: list[dict[str, Any]] = []
    results: list[PackSimResult] = []
    for rec in recs:
        fitted = fitted_ocv_v.get(Path(str(rec.source)).name)
        # a fit's params hold the state of its first data file: another recording starts from its own state
        state = "voltage" if fitted_ocv_v and fitted is None else initial_state
        req = request_for_recording(params, rec, initial_state=state, extend_s=0.5 * rec.duration_s)
        if fitted is not None:
            req = replace(req, initial_pack_ocv_v=fitted * params.series)
        elif req.initial_pack_ocv_v is not None and not starts_at_rest(params, rec):
            # the first voltage of a recording that starts under load is not its OCV
            req = replace(req, initial_pack_ocv_v=loaded_start_ocv_v(params, rec, sim))
        res = sim.simulate(params, req)
        t = rec.relative_time_s
        u_end = float(rec.voltage_v.min())
        t_sim = res.time_to_pack_voltage_s(u_end)
        if t_sim is None and res.reached_cutoff:
            t_sim = res.end_time_s
        rows.append({
            "data": str(rec.source),
            # as the fit scores it: Eq. 1-2's end handling only for a recording that ends at its cut-off
            "r2_mod": r2_mod(t, rec.voltage_v, res.time_s, res.pack_voltage_v, ends_at_cutoff(rec)),
            "rmse_mV": 1e3 * rmse_v(t, rec.voltage_v, res.time_s, res.pack_voltage_v),
            # the same event in both: a recording that rests after its end (a drive cycle's last 300 s) is not
            # measured to its last sample
            "runtime_s_measured": float(t[int(np.argmin(rec.voltage_v))]),
            "runtime_s_simulated": t_sim,
            # where the recording's discharge ends (s): later than its lowest voltage when that fell in a burst before
            "discharge_end_s_measured": float(t[-1]),
            "end_voltage_v": u_end,
            "initial_ocv_v": req.initial_pack_ocv_v,
        })
        results.append(res)
    return rows, results


def _fitted_initial_ocvs_v(params: PackParams) -> dict[str, float]:
    """The open-circuit cell voltage (V) each data file of the fit that wrote ``params`` started from, by file name
    (``provenance.initial_ocv_v_per_file``); empty for params no identification wrote."""
    per_file = params.provenance.get("initial_ocv_v_per_file")
    if not isinstance(per_file, dict):
        return {}
    return {str(name): float(v) for name, v in per_file.items() if isinstance(v, (int, float))}


def _summary(rows: list[dict[str, Any]], results: list[PackSimResult], seconds: float,
             simulator: str) -> dict[str, Any]:
    """The JSON summary: the one row (or the mean scores of several, with ``per_file``), the wall time ``seconds``
    (s), the simulator's name and the engine's own stepping time (s)."""
    out: dict[str, Any] = dict(rows[0]) if len(rows) == 1 else {
        "r2_mod": sum(r["r2_mod"] for r in rows) / len(rows),
        "rmse_mV": sum(r["rmse_mV"] for r in rows) / len(rows),
        "runtime_s_measured": rows[0]["runtime_s_measured"],
        "runtime_s_simulated": rows[0]["runtime_s_simulated"],
        "end_voltage_v": rows[0]["end_voltage_v"],
        "per_file": rows,
    }
    out.pop("data", None)
    out["seconds"] = seconds
    out["simulator"] = simulator
    engine_s = [res.extra.get("engine_seconds") for res in results]
    #: the engine's own stepping time (s), without start-up, loading and extraction; None when it did not run
    out["engine_seconds"] = sum(engine_s) if all(e is not None for e in engine_s) and engine_s else None
    return out


def _print_summary(out: dict[str, Any], rows: list[dict[str, Any]], simulator: str) -> None:
    """The human-readable lines: one per recording, the simulator and timing, the engine's fallback, the plot."""
    for r in rows:
        ts = r["runtime_s_simulated"]
        end_s = r["discharge_end_s_measured"]
        ends_later = f" (its discharge ends at {end_s / 60:.1f} min)" if end_s - r["runtime_s_measured"] > 60.0 else ""
        print(f"{r['data']}: R2_mod {r['r2_mod']:.4f}, RMSE {r['rmse_mV']:.1f} mV, runtime to its lowest "
              f"{r['end_voltage_v']:.3f} V measured {r['runtime_s_measured'] / 60:.1f} min{ends_later}, simulated "
              f"{'n/a' if ts is None else f'{ts / 60:.1f} min'}")
    engine = f", engine stepping {1e3 * out['engine_seconds']:.1f} ms" if out["engine_seconds"] is not None else ""
    print(f"({simulator} simulator, {out['thermal']} cell, {out['seconds']:.1f} s{engine})")
    if out["engine_fallback"]:
        print(f"engine fallback: {out['engine_fallback']}")
    if "plot" in out:
        print(f"wrote {out['plot']}")
