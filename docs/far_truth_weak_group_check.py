"""Post-hoc check (not the package): a weak series group inferred from where the fit data stopped.

For each seed's fit kept by ``benchmarks/route_far_truth.py --work SRC``: the fraction ``f`` of a weak series group
(``cell_imbalance``) at which the fitted model, discharged from full at the deepest state's current, stops (its weak
group at the cell cut-off) at the deepest state's voltage (bisection over 0.3..0.999). Writes the fit with that group
to DST with the day-1 CSV, so that ``route_far_truth.py --work DST`` asks the same questions of it.

Run::

    .venv/bin/python docs/far_truth_weak_group_check.py SRC DST 308 312
    .venv/bin/python benchmarks/route_far_truth.py --seeds 308 312 --every 20 --weak-group 0.75 0.97 --work DST
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

import identification_far_truth as far  # noqa: E402

from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.prediction.pack_model import pack_model  # noqa: E402
from battery_predictor.recording import DeepestState  # noqa: E402


def end_voltage_v(params, fraction: float, deepest: DeepestState) -> float:
    """Pack voltage (V) where the model with a weak group of ``fraction`` stops, discharged from full at the
    deepest state's current."""
    runner = pack_model(far.with_weak_group(params, fraction) if fraction < 1.0 else params)[0]
    run = runner.run(1.0, [(20 * 3600.0, deepest.current_a)], deepest.temperature_k)
    return float(run.pack_voltage_v[-1])


def inferred_fraction(params, deepest: DeepestState, steps: int = 14) -> float:
    lo, hi = 0.3, 0.999
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if end_voltage_v(params, mid, deepest) > deepest.voltage_v:
            lo = mid  # stops above the deepest state: the weak group holds more
        else:
            hi = mid
    return 0.5 * (lo + hi)


def main() -> None:
    src, dst = Path(sys.argv[1]), Path(sys.argv[2])
    dst.mkdir(parents=True, exist_ok=True)
    for seed in sys.argv[3:]:
        params = load_params(src / f"r{seed}_fit.yaml")
        deepest = DeepestState.from_thresholds(params.thresholds)
        if deepest is None:
            print(f"seed {seed}: no deepest state kept")
            continue
        fraction = inferred_fraction(params, deepest)
        print(f"seed {seed}: deepest {deepest.voltage_v:.3f} V at {deepest.current_a:.2f} A -> weak group {fraction:.3f}")
        far.with_weak_group(params, fraction).to_yaml(dst / f"r{seed}_fit.yaml")
        shutil.copy(src / f"r{seed}_day1.csv", dst)


if __name__ == "__main__":
    main()
