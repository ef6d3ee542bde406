"""Diagnosis speed on 6-hour recordings (issue: diagnosis, "within 10 minutes on this 2-core machine").

For each pack, a synthetic 6 h reference day (healthy) and a 6 h observed day (the same pack with a
grown contact resistance) are simulated with the fast pack simulator at the paper's 5 s resolution
(Temi: the stochastic usage at 2x current with a 1 h charging stop; Ranger: random luggage jobs on
the station graph) with 4 mV voltage noise and 20 mA current-sensor noise (so that nearly every
sample is a new current step, the solver's worst case), written as CSV, and ``battery-predictor diagnose --json`` is run on them as a
subprocess. Prints wall seconds, peak resident memory (largest process: the CLI or one of its
fit workers), the named cause and the gain.

Usage: .venv/bin/python benchmarks/diagnose_speed.py [--packs temi ranger_mini] [--hours 6] [--workers N]
       [--current-noise 0.02]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from battery_predictor.io.csv_io import save_csv  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.recording import Recording  # noqa: E402
from battery_predictor.simulation import SimulationRequest, StepLoad  # noqa: E402
from battery_predictor.simulation.fast import FastPackSimulator  # noqa: E402

SAMPLE_S = 5.0


def _load(pack: str, hours: float, seed: int) -> tuple[StepLoad, float]:
    rng = np.random.default_rng(seed)
    if pack == "temi":
        from battery_predictor.profiles.temi import generate_usage_profile

        half = 0.5 * (hours - 1.0) * 3600.0
        use = [StepLoad.from_profile(generate_usage_profile(seed=int(rng.integers(1 << 30)), max_duration_s=half))
               .scale_current(2.0) for _ in range(2)]
        return use[0].append(StepLoad.constant(-0.4 * 14.7, 3600.0)).append(use[1]), 0.95
    from battery_predictor.profiles.ranger import route_from_station, route_profile
    from battery_predictor.profiles.station import load_station

    station = load_station()
    places = [n for n in station.nodes if n != "charger"]
    load = None
    while load is None or load.end_s < hours * 3600.0:
        a, b = rng.choice(places, size=2, replace=False)
        route = route_from_station(station, "charger", str(a), str(b), float(rng.choice([20.0, 40.0, 60.0, 80.0])))
        part = StepLoad.from_profile(route_profile(route, seed=int(rng.integers(1 << 30))))
        part = part.append(StepLoad.constant(1.70, float(rng.uniform(60.0, 240.0))))
        load = part if load is None else load.append(part)
    return load.truncate(hours * 3600.0), 0.9


def _recording(params, load: StepLoad, soc0: float, seed: int, current_noise_a: float) -> Recording:
    stepped = load.resample(SAMPLE_S)
    t = np.arange(0.0, stepped.end_s, SAMPLE_S)
    res = FastPackSimulator().simulate(params, SimulationRequest(load=stepped, initial_soc=soc0, output_time_s=t))
    rng = np.random.default_rng(seed)
    v = np.round(res.pack_voltage_v + rng.normal(0.0, 0.004, res.time_s.size), 2)
    # a current sensor's noise makes (nearly) every sample a new current step: the solver's worst case
    i = np.round(res.pack_current_a + rng.normal(0.0, current_noise_a, res.time_s.size), 2)
    return Recording(res.time_s, v, i, np.full(res.time_s.size, 298.15))


def bench(pack: str, hours: float, workers: int | None, tmp: Path, current_noise_a: float = 0.02,
          simulator: str = "engine") -> dict:
    params = load_params(REPO / "params" / f"{pack}.yaml")
    ref_load, soc0 = _load(pack, hours, 1)
    obs_load, _ = _load(pack, hours, 2)
    r_contact = 0.03 if pack == "temi" else 0.012
    aged = replace(params, extensions=("resistance_growth",), extra={"Contact resistance [Ohm]": r_contact})
    ref = save_csv(_recording(params, ref_load, soc0, 3, current_noise_a), tmp / f"{pack}_reference.csv",
                   overwrite=True)
    obs_rec = _recording(aged, obs_load, soc0, 4, current_noise_a)
    obs = save_csv(obs_rec, tmp / f"{pack}_observed.csv", overwrite=True)
    cmd = [str(Path(sys.executable).parent / "battery-predictor"), "diagnose", "--params",
           str(REPO / "params" / f"{pack}.yaml"), "--reference", str(ref), "--data", str(obs), "--json", "--quiet",
           "--simulator", simulator]
    if workers:
        cmd += ["--workers", str(workers)]
    tic = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - tic
    if proc.returncode != 0:
        raise SystemExit(proc.stderr[-2000:])
    out = json.loads(proc.stdout)
    return {"pack": pack, "hours": obs_rec.duration_s / 3600.0, "samples": len(obs_rec.time_s),
            "current_changes": int(np.count_nonzero(np.diff(obs_rec.current_a))), "seconds": seconds,
            "cause": out["cause"], "gain_pct": out["gain_pct"], "truth_contact_resistance_ohm": r_contact,
            "fitted": next(c["fitted"] for c in out["candidates"] if c["cause"] == "resistance_growth"),
            "reference_fit_s": out["reference_fit"]["seconds"], "simulator": simulator,
            "candidate_fit_s": sum(c["seconds"] for c in out["candidates"]),
            "engine_runs": sum(c.get("simulator", {}).get("engine_runs", 0) for c in out["candidates"]),
            "pybamm_runs": sum(c.get("simulator", {}).get("pybamm_runs", 0) for c in out["candidates"])}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--packs", nargs="+", default=["temi", "ranger_mini"])
    ap.add_argument("--hours", type=float, default=6.0)
    ap.add_argument("--workers", type=int, default=None, help="diagnose --workers (default: the CLI's default)")
    ap.add_argument("--current-noise", type=float, default=0.02,
                    help="current sensor noise in A (std); 0 keeps the profile's steps only")
    ap.add_argument("--simulators", nargs="+", default=["engine", "pybamm"], choices=("engine", "pybamm"),
                    help="diagnose --simulator values, each run side by side on the same files")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        for pack in args.packs:
            for simulator in args.simulators:
                r = bench(pack, args.hours, args.workers, Path(d), args.current_noise, simulator)
                peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
                print(f"{r['pack']} [{simulator}: {r['engine_runs']} engine / {r['pybamm_runs']} PyBaMM candidate runs]: "
                      f"{r['hours']:.2f} h observed + reference, {r['samples']} samples "
                      f"({r['current_changes']} current changes) -> {r['seconds']:.0f} s wall "
                      f"(reference fit {r['reference_fit_s']:.0f} s, candidate fits {r['candidate_fit_s']:.0f} s), "
                      f"peak RSS {peak:.0f} MB (largest process so far); named {r['cause']} "
                      f"(gain {r['gain_pct']:.1f} %), contact resistance {r['fitted']} vs truth "
                      f"{r['truth_contact_resistance_ohm']} Ohm", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
