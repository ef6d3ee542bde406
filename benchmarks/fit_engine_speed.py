"""A 1000-evaluation fit of a 6 h Temi day at `fit`'s defaults: wall time, model time, optimiser time.

Issue 18's target: a 1000-evaluation fit of the Temi day in <= 30 s, with the optimiser's own
overhead reported separately. The day is made on the engine from ``params/temi.yaml`` (the Temi
usage profile, 5 s steps, sensor noise and quantisation as the paper's instruments), written to a
CSV, then fitted by the CLI exactly as a user runs it (``battery-predictor fit --params
params/temi.yaml --data day.csv --json``), so start-up (imports, PyBaMM model extraction, Numba
loading) is measured too and printed beside the fit's own figures.

Usage: .venv/bin/python benchmarks/fit_engine_speed.py [--seed 7] [--hours 6] [--initial-soc 0.95]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from battery_predictor.io.csv_io import save_csv  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.profiles.temi import generate_usage_profile  # noqa: E402
from battery_predictor.recording import Recording  # noqa: E402
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator  # noqa: E402

#: Sensor model: voltage noise (V RMS), voltage and current resolution (V, A).
NOISE_V, VOLTAGE_STEP_V, CURRENT_STEP_A = 0.003, 0.01, 0.1


def make_day(seed: int, hours: float, initial_soc: float, out: Path) -> Recording:
    """Simulate the Temi day on the engine and write it with the sensor model applied."""
    params = load_params(REPO / "params" / "temi.yaml")
    load = StepLoad.from_profile(generate_usage_profile(seed=seed, max_duration_s=hours * 3600.0)).resample(5.0)
    res = get_simulator("engine").simulate(params, SimulationRequest(load=load, initial_soc=initial_soc))
    rng = np.random.default_rng(seed)
    voltage_v = res.pack_voltage_v + rng.normal(0.0, NOISE_V, res.pack_voltage_v.size)
    rec = Recording(time_s=res.time_s, voltage_v=np.round(voltage_v / VOLTAGE_STEP_V) * VOLTAGE_STEP_V,
                    current_a=np.round(res.pack_current_a / CURRENT_STEP_A) * CURRENT_STEP_A, source=str(out))
    save_csv(rec, out, overwrite=True)
    return rec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--hours", type=float, default=6.0)
    ap.add_argument("--initial-soc", type=float, default=0.95)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        day = Path(tmp) / "temi_day.csv"
        rec = make_day(args.seed, args.hours, args.initial_soc, day)
        print(f"day: Temi usage seed {args.seed}, {rec.duration_s / 3600:.2f} h, {rec.time_s.size} samples, "
              f"{rec.charge_drawn_ah():.2f} Ah drawn, SOC0 {args.initial_soc}")
        cli = [str(REPO / ".venv" / "bin" / "battery-predictor"), "fit", "--params", str(REPO / "params" / "temi.yaml"),
               "--data", str(day), "--out", str(Path(tmp) / "fit.yaml"), "--json"]
        tic = time.perf_counter()
        done = subprocess.run(cli, capture_output=True, text=True, check=False)
        wall_s = time.perf_counter() - tic
        if done.returncode != 0:
            print(done.stderr, file=sys.stderr)
            return done.returncode
        out = json.loads(done.stdout[done.stdout.index("{"):])
    print("| figure | value |")
    print("|---|---|")
    print(f"| R2_mod | {out['r2_mod']:.5f} |")
    print(f"| evaluations (of them TPE) | {out['evaluations']} ({out['tpe_evaluations']}) |")
    print(f"| fit, as the identification reports it | {out['seconds']:.1f} s |")
    print(f"| of which model evaluations (simulation + residual) | {out['model_seconds']:.1f} s "
          f"({1e3 * out['model_seconds'] / max(out['evaluations'], 1):.1f} ms each) |")
    print(f"| of which the optimiser's own work (TPE sampler, trust-region steps) | {out['optimiser_seconds']:.1f} s |")
    print(f"| the whole command (imports, PyBaMM model, Numba loading, identifiability, plot, output) | {wall_s:.1f} s |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
