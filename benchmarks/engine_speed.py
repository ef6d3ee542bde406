"""Engine speed and agreement benchmark (issue 18): every simulator side by side in one run.

For a 6 h Temi-like day and a 5 h Ranger-like day (5 s steps, every step a new current), prints
the wall time of one simulation with

- liionpack (the reference, every cell simulated);
- the fast path, first call (PyBaMM build + IDAKLU solve) and re-solve (PyBaMM IDAKLU with the
  current as an interpolant, the project's tolerances rtol 1e-6 / atol 1e-8);
- the engine through the simulator interface (first call with the PyBaMM extraction, then a
  repeat: initial state, run, report voltages), and its own run time; then 1000 calls with the
  params' fit parameters drawn within +-20 % (the simulations of a 1000-trial fit, without the
  optimiser and the cost function);
- the engine's cell run alone: fused Numba kernel and NumPy path, single set and batched over
  1 / 100 / 1000 parameter sets (radii, diffusivities, thicknesses, active fractions +-20 %,
  seeded), best of ``--repeat``;

and the engine's agreement on the full day with PyBaMM's IDAKLU at rtol = atol = 1e-10 (RMS pack
voltage, time to cut-off) and with liionpack.

Thermal rows (the Temi day, same run): the lumped thermal cell (``{"thermal": "lumped"}``) next to
the isothermal one through the simulator interface and as cell runs (compiled and NumPy
recurrence, 1 / 100 / 1000 parameter sets), and its agreement with PyBaMM's own lumped SPM at
1e-10 (pack voltage, cell temperature, time to cut-off).

Usage: nice .venv/bin/python benchmarks/engine_speed.py [--repeat 5] [--skip-liionpack]
       [--skip-reference] [--numpy-sets 100] [--thermal-only]
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

from battery_predictor.errors import SimulationError  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.prediction.cell_runner import PackRunner  # noqa: E402
from battery_predictor.profiles.load_profile import LoadProfile  # noqa: E402
from battery_predictor.profiles.ranger import longest_route, route_profile  # noqa: E402
from battery_predictor.profiles.temi import generate_usage_profile  # noqa: E402
from battery_predictor.simulation import SimulationRequest, StepLoad  # noqa: E402
from battery_predictor.simulation.cell_setup import initial_concentrations, prepared_parameter_values  # noqa: E402
from battery_predictor.simulation.engine.kernel import fused_kernel  # noqa: E402
from battery_predictor.simulation.engine.modal import modal_system  # noqa: E402
from battery_predictor.simulation.engine.model import extract_linear_spm  # noqa: E402
from battery_predictor.simulation.engine.pack import pack_voltage_v  # noqa: E402
from battery_predictor.simulation.engine.run import ParameterSets, run_cells  # noqa: E402
from battery_predictor.simulation.engine.segments import EnginePack  # noqa: E402
from battery_predictor.simulation.engine.simulator import DIFFUSIVITY_KEYS, EngineSimulator  # noqa: E402
from battery_predictor.simulation.engine.thermal import diffusivity_temperature  # noqa: E402
from battery_predictor.simulation.fast import FastPackSimulator  # noqa: E402

STEP_S = 5.0
SET_KEYS = ("radius_n", "radius_p", "diffusivity_n", "diffusivity_p", "thickness_n", "thickness_p", "fraction_n",
            "fraction_p")


def temi_day() -> tuple[str, object, SimulationRequest]:
    params = load_params(REPO / "params" / "temi.yaml")
    load = StepLoad.from_profile(generate_usage_profile(seed=0, max_duration_s=6 * 3600)).resample(STEP_S)
    return "Temi 6 h", params, SimulationRequest(load=load, initial_soc=0.62)


def ranger_day() -> tuple[str, object, SimulationRequest]:
    params = load_params(REPO / "params" / "ranger_mini.yaml")
    routes = [route_profile(longest_route(payload), seed=k) for k, payload in enumerate([20.0, 40.0, 60.0, 80.0] * 4)]
    day = LoadProfile(np.concatenate([r.duration_s for r in routes]), np.concatenate([r.current_a for r in routes]))
    load = StepLoad.from_profile(day).truncate(5 * 3600).resample(STEP_S)
    return "Ranger 5 h", params, SimulationRequest(load=load, initial_soc=0.47)


def best_of(fn, repeat: int) -> tuple[float, object]:
    """(shortest wall time in s, last result) of ``repeat`` calls."""
    best, out = np.inf, None
    for _ in range(repeat):
        tic = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - tic)
    return best, out


def compare(a, b) -> str:
    """RMS pack-voltage difference (mV) on common report times and relative end-time difference (%)."""
    n = min(a.time_s.size, b.time_s.size)
    same = np.abs(a.time_s[:n] - b.time_s[:n]) < 1e-6
    d = (a.pack_voltage_v[:n] - b.pack_voltage_v[:n])[same]
    rms_mv = float(np.sqrt(np.mean(d ** 2)) * 1e3)
    dt_pct = abs(a.end_time_s - b.end_time_s) / b.end_time_s * 100.0
    return f"RMS {rms_mv:.4f} mV, end {a.end_time_s:.1f} s vs {b.end_time_s:.1f} s ({dt_pct:.4f} %)"


def reference_comparison(params, request: SimulationRequest, engine_result) -> str:
    """The engine against IDAKLU at 1e-10 evaluated at the engine's report times."""
    ref = FastPackSimulator(rtol=1e-10, atol=1e-10)
    tic = time.perf_counter()
    res = ref.simulate(params, request)
    seconds = time.perf_counter() - tic
    t = engine_result.time_s[engine_result.time_s <= res.end_time_s]
    v_cell = np.asarray(res.extra["solution"]["Terminal voltage [V]"](t), dtype=float)
    v_ref = pack_voltage_v(v_cell, request.load.current_at(t), series=params.series, r_eq_ohm=res.extra["r_eq_ohm"])
    d = engine_result.pack_voltage_v[: t.size] - v_ref
    dt_pct = abs(engine_result.end_time_s - res.end_time_s) / res.end_time_s * 100.0
    return (f"{seconds:8.2f} s   engine vs IDAKLU 1e-10: RMS {np.sqrt(np.mean(d ** 2)) * 1e3:.4f} mV, "
            f"end {engine_result.end_time_s:.2f} s vs {res.end_time_s:.2f} s ({dt_pct:.5f} %)")


def fit_calls(engine: EngineSimulator, params, request: SimulationRequest, n_calls: int) -> None:
    """``n_calls`` simulations with the params' fit parameters drawn within +-20 % (seeded), as a fit makes them."""
    if n_calls <= 0:
        return
    rng = np.random.default_rng(1)
    base = {**params.cell_values, **params.interconnect}
    names = [name for name in params.fit.parameters if name in base]
    failed = 0
    extractions = engine.extractions
    tic = time.perf_counter()
    for _ in range(n_calls):
        trial = params.with_values({name: float(base[name]) * rng.uniform(0.8, 1.2) for name in names})
        try:
            engine.simulate(trial, request)
        except SimulationError:
            failed += 1
    seconds = time.perf_counter() - tic
    row(f"engine simulator, {n_calls} calls with {len(names)} fit parameters +-20 %", seconds,
        f"{seconds / n_calls * 1e3:.2f} ms per call, {failed} failed, "
        f"{engine.extractions - extractions} new extractions")
    cell_names = [name for name in names if name in params.cell_values]
    values = {name: float(base[name]) * rng.uniform(0.8, 1.2, n_calls) for name in cell_names}
    engine.simulate_batch(params, request, values)
    tic = time.perf_counter()
    batch = engine.simulate_batch(params, request, values)
    seconds = time.perf_counter() - tic
    row(f"engine simulate_batch, {n_calls} variants of the {len(cell_names)} cell fit parameters", seconds,
        f"engine's own {batch.engine_seconds * 1e3:.1f} ms, {int(batch.reached_cutoff.sum())} reach the cut-off")


def route_answer(model, modal, params, c_n0: float, c_p0: float, duration_s, current_a, repeat: int) -> None:
    """The engine's part of a route answer: the longest route at 80 kg plus 60 s at 1.70 A from a carried state.

    The state is the one after the day's first 10 min (non-uniform particles), as the predictor carries it.
    """
    before = run_cells(model, modal, duration_s[:120], current_a[:120], c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                       temperature_k=298.15)
    route = StepLoad.from_profile(route_profile(longest_route(80.0), mode="mean")).append(StepLoad.constant(1.70, 60.0))
    steps, amps = np.diff(route.edges_s()), route.current_a / params.parallel
    seconds, runs = best_of(lambda: run_cells(model, modal, steps, amps, initial_state=before.final_state,
                                              temperature_k=298.15), max(repeat, 20))
    row(f"engine run, longest route ({steps.size} steps) + 60 s at 1.70 A, from a carried state", seconds,
        f"last voltage {params.series * runs.start_voltage_v[0, -1]:.3f} V (pack, before R_eq)")
    segments = list(zip(steps, route.current_a))
    pack, runner = EnginePack(params), PackRunner(params)
    cases = (("EnginePack.run (route from SOC 0.3, samples in segments)", lambda: pack.run(0.3, segments, 298.15)),
             ("PackRunner.run (the predictor's PyBaMM steps), same route", lambda: runner.run(0.3, segments, 298.15)))
    for label, fn in cases:
        fn()
        times = []
        for _ in range(max(repeat, 20)):
            tic = time.perf_counter()
            fn()
            times.append(time.perf_counter() - tic)
        row(label, float(np.median(times)), f"p95 {np.percentile(times, 95) * 1e3:.2f} ms")
    diff = pack.run(0.3, segments, 298.15).pack_voltage_v - runner.run(0.3, segments, 298.15).pack_voltage_v
    print(f"    EnginePack vs PackRunner on that route: max |dV| {np.abs(diff).max() * 1e3:.4f} mV")


def row(label: str, seconds: float, note: str = "") -> None:
    print(f"  {label:<58s} {seconds * 1e3:12.2f} ms   {note}")


def bench_day(name: str, params, request: SimulationRequest, args) -> None:
    load = request.load
    print(f"\n{name}: {params.name} {params.series}S{params.parallel}P, {load.duration_s / 3600:.2f} h, "
          f"{load.start_s.size} steps of {STEP_S:g} s, mean {load.mean_current_a():.2f} A, SOC0 {request.initial_soc}")
    lp_result = None
    if not args.skip_liionpack:
        from battery_predictor.simulation.liionpack_sim import LiionpackSimulator

        seconds, lp_result = best_of(lambda: LiionpackSimulator(period_s=STEP_S).simulate(params, request), 1)
        row("liionpack (reference, every cell)", seconds, lp_result.termination)
    fast = FastPackSimulator()
    seconds, fast_result = best_of(lambda: fast.simulate(params, request), 1)
    row("fast path, first call (PyBaMM build + IDAKLU solve)", seconds)
    seconds, fast_result = best_of(lambda: fast.simulate(params, request), args.repeat)
    row("PyBaMM IDAKLU re-solve (interpolant current, 1e-6/1e-8)", seconds, fast_result.termination)
    engine = EngineSimulator(fallback=None)
    seconds, _ = best_of(lambda: engine.simulate(params, request), 1)
    row("engine simulator, first call (PyBaMM extraction + run)", seconds)
    own_s = []

    def engine_call():
        result = engine.simulate(params, request)
        own_s.append(result.extra["engine_seconds"])
        return result

    seconds, eng_result = best_of(engine_call, args.repeat)
    row("engine simulator, repeat (initial state + run + report)", seconds,
        f"engine's own time {min(own_s) * 1e3:.2f} ms (best of {len(own_s)}, {eng_result.extra['engine_backend']})")
    fit_calls(engine, params, request, args.fit_calls)

    model = extract_linear_spm(params)
    modal = modal_system(model)
    pv = prepared_parameter_values(params)
    c_n0, c_p0 = initial_concentrations(params, pv, initial_soc=request.initial_soc, initial_cell_ocv_v=None)
    duration_s = np.diff(load.edges_s())
    current_a = load.current_a / params.parallel
    temperature_k = params.ambient_temperature_k
    rng = np.random.default_rng(0)

    def runner(n_sets: int, backend: str):
        sets = None if n_sets == 0 else ParameterSets(**{k: rng.uniform(0.8, 1.2, n_sets) for k in SET_KEYS})

        return lambda: run_cells(model, modal, duration_s, current_a, c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                                 temperature_k=temperature_k, sets=sets, backend=backend)

    has_kernel = fused_kernel(model) is not None
    tic = time.perf_counter()
    runner(0, "auto")()
    serial_s = time.perf_counter() - tic
    tic = time.perf_counter()
    runner(100, "auto")()
    print(f"  (first calls with this model's Numba compilation: serial {serial_s:.1f} s, parallel "
          f"{time.perf_counter() - tic:.1f} s; {'fused kernel' if has_kernel else 'no fused kernel: NumPy voltage'})")
    for label, n_sets, backend in [("engine run, single cell, fused Numba kernel", 0, "auto"),
                                   ("engine run, single cell, NumPy path", 0, "numpy"),
                                   ("engine run, 1 parameter set, fused Numba kernel", 1, "auto"),
                                   ("engine run, 100 parameter sets, fused Numba kernel", 100, "auto"),
                                   ("engine run, 1000 parameter sets, fused Numba kernel", 1000, "auto"),
                                   (f"engine run, {args.numpy_sets} parameter sets, NumPy path", args.numpy_sets,
                                    "numpy")]:
        fn = runner(n_sets, backend)
        fn()
        seconds, runs = best_of(fn, args.repeat if n_sets < 1000 else max(1, args.repeat // 2))
        note = f"{runs.reached_cutoff.sum()}/{runs.reached_cutoff.size} reach the cut-off"
        if n_sets > 1:
            note += f", {seconds / n_sets * 1e3:.3f} ms per set"
        row(label, seconds, note)
    if params.name.startswith("ranger"):
        route_answer(model, modal, params, c_n0, c_p0, duration_s, current_a, args.repeat)
    print("  agreement:")
    print(f"    engine vs fast path (1e-6/1e-8, its own report times): {compare(eng_result, fast_result)}")
    if lp_result is not None:
        print(f"    engine vs liionpack:                                   {compare(eng_result, lp_result)}")
    if not args.skip_reference:
        print(f"    IDAKLU 1e-10 solve: {reference_comparison(params, request, eng_result)}")


def thermal_rows(name: str, params, request: SimulationRequest, args) -> None:
    """The lumped thermal cell next to the isothermal one on the same day (see module docstring)."""
    thermal = replace(params, options={**params.options, "thermal": "lumped"})
    load = request.load
    print(f"\n{name}, lumped thermal vs isothermal (same run, {load.start_s.size} steps of {STEP_S:g} s):")
    results = {}
    for label, p in (("isothermal", params), ("lumped thermal", thermal)):
        engine = EngineSimulator(fallback=None)
        engine.simulate(p, request)
        own_s = []

        def call(engine=engine, p=p, own_s=own_s):
            result = engine.simulate(p, request)
            own_s.append(result.extra["engine_seconds"])
            return result

        seconds, results[label] = best_of(call, args.repeat)
        row(f"engine simulator, {label}, repeat", seconds,
            f"engine's own {min(own_s) * 1e3:.2f} ms ({results[label].extra['engine_backend']})")
    duration_s = np.diff(load.edges_s())
    current_a = load.current_a / params.parallel
    rng = np.random.default_rng(0)
    for label, p in (("isothermal", params), ("lumped thermal", thermal)):
        model = extract_linear_spm(p)
        modal = modal_system(model)
        pv = prepared_parameter_values(p)
        c_n0, c_p0 = initial_concentrations(p, pv, initial_soc=request.initial_soc, initial_cell_ocv_v=None)
        table = diffusivity_temperature(pv, DIFFUSIVITY_KEYS, p.ambient_temperature_k)
        for n_sets, backend in ((0, "auto"), (0, "numpy"), (100, "auto"), (1000, "auto")):
            sets = None if n_sets == 0 else ParameterSets(**{k: rng.uniform(0.8, 1.2, n_sets) for k in SET_KEYS})

            def fn(model=model, modal=modal, sets=sets, backend=backend, c_n0=c_n0, c_p0=c_p0, table=table,
                   temperature_k=p.ambient_temperature_k):
                return run_cells(model, modal, duration_s, current_a, c_n0_mol_m3=c_n0, c_p0_mol_m3=c_p0,
                                 temperature_k=temperature_k, sets=sets, backend=backend,
                                 diffusivity_temperature=table)

            fn()
            seconds, runs = best_of(fn, args.repeat if n_sets < 1000 else max(1, args.repeat // 2))
            note = f"{runs.extra['backend']}, {runs.reached_cutoff.sum()}/{runs.reached_cutoff.size} reach the cut-off"
            if n_sets > 1:
                note += f", {seconds / n_sets * 1e3:.3f} ms per set"
            row(f"engine run, {label}, {max(n_sets, 1)} set{'s' if n_sets > 1 else ''}, {backend}", seconds, note)
    eng = results["lumped thermal"]
    temps = eng.extra["cell_temperature_k"]
    print(f"  lumped cell: temperature rise {temps.max() - temps[0]:.2f} K; isothermal vs lumped end "
          f"{results['isothermal'].end_time_s:.1f} s vs {eng.end_time_s:.1f} s")
    if args.skip_reference:
        return
    ref = FastPackSimulator(rtol=1e-10, atol=1e-10)
    tic = time.perf_counter()
    res = ref.simulate(thermal, request)
    seconds = time.perf_counter() - tic
    t = eng.time_s[eng.time_s <= res.end_time_s]
    sol = res.extra["solution"]
    v_ref = pack_voltage_v(np.asarray(sol["Terminal voltage [V]"](t), dtype=float), load.current_at(t),
                           series=params.series, r_eq_ohm=res.extra["r_eq_ohm"])
    t_ref = np.asarray(sol["Volume-averaged cell temperature [K]"](t), dtype=float)
    d_v = eng.pack_voltage_v[: t.size] - v_ref
    d_t = temps[: t.size] - t_ref
    dt_pct = abs(eng.end_time_s - res.end_time_s) / res.end_time_s * 100.0
    print(f"    IDAKLU 1e-10 lumped solve: {seconds:8.2f} s   engine vs PyBaMM lumped: RMS {np.sqrt(np.mean(d_v ** 2)) * 1e3:.4f}"
          f" mV, temperature RMS {np.sqrt(np.mean(d_t ** 2)):.2e} K (max {np.abs(d_t).max():.2e} K), end "
          f"{eng.end_time_s:.2f} s vs {res.end_time_s:.2f} s ({dt_pct:.5f} %)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="repetitions of each timed row (best is printed)")
    ap.add_argument("--skip-liionpack", action="store_true", help="leave out the liionpack rows (~1 min per day)")
    ap.add_argument("--skip-reference", action="store_true", help="leave out the IDAKLU 1e-10 agreement")
    ap.add_argument("--numpy-sets", type=int, default=100, help="sets of the batched NumPy row")
    ap.add_argument("--fit-calls", type=int, default=1000, help="simulations of the fit-like row (0: none)")
    ap.add_argument("--thermal-only", action="store_true", help="only the thermal rows (Temi day)")
    args = ap.parse_args()
    import os

    print(f"engine_speed: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at start")
    if not args.thermal_only:
        for name, params, request in (temi_day(), ranger_day()):
            bench_day(name, params, request, args)
    thermal_rows(*temi_day(), args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
