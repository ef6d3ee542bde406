"""`fit` at its default settings on the measured Panasonic drive cycles (issue 17), with the cold window.

Prints, in one run:
- the cold window's anchors (each electrode's charged-end stoichiometry) solved on the OCP tables
  (``simulation.extensions.cold_window_anchors``) beside PyBaMM's ``get_min_max_stoichiometries``,
  milliseconds per call and the largest difference;
- the default identification (engine, 1000 evaluations, the 1 s data) from
  ``params/panasonic_18650pf.yaml`` (with its cold-window prior): R2_mod, evaluations, wall time.

Needs ``../shared/data/panasonic_18650pf``. Usage: .venv/bin/python benchmarks/panasonic_default_fit.py [--calls 20]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from battery_predictor.fitting.identifiable import default_space  # noqa: E402
from battery_predictor.fitting.identification import IdentificationProblem, identify  # noqa: E402
from battery_predictor.fitting.problem import trim_to_discharge  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.simulation import get_simulator  # noqa: E402
from battery_predictor.simulation.extensions import (  # noqa: E402
    cold_window_anchors,
    with_cold_window_anchors,
    with_fitted_extension_keys,
)

DATA = REPO.parent / "shared" / "data" / "panasonic_18650pf"


def _anchors(params, calls: int) -> None:
    import pybamm

    pv = params.parameter_values()
    cold_window_anchors(params, pv)  # the OCP tables are built once per cell
    tic = time.perf_counter()
    for _ in range(calls):
        ours = cold_window_anchors(params, pv)
    ours_ms = 1e3 * (time.perf_counter() - tic) / calls
    tic = time.perf_counter()
    for _ in range(calls):
        _, x100, y100, _ = pybamm.lithium_ion.get_min_max_stoichiometries(pv)
    theirs_ms = 1e3 * (time.perf_counter() - tic) / calls
    assert ours is not None
    diff = max(abs(ours[0] - x100), abs(ours[1] - y100))
    print(f"anchors on the OCP tables: {ours_ms:.2f} ms per call; PyBaMM's electrode balance: {theirs_ms:.0f} ms "
          f"({theirs_ms / ours_ms:.0f}x); largest stoichiometry difference {diff:.1e}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=20)
    ap.add_argument("--evaluations", type=int, default=1000)
    args = ap.parse_args()
    if not DATA.is_dir():
        print(f"no data at {DATA}")
        return 1
    params = with_fitted_extension_keys(with_cold_window_anchors(load_params(REPO / "params" / "panasonic_18650pf.yaml")))
    _anchors(load_params(REPO / "params" / "panasonic_18650pf.yaml"), args.calls)
    recs = [trim_to_discharge(load_recording(DATA / f"drive_T25C_{n}.csv")) for n in ("HWFET", "LA92")]
    problem = IdentificationProblem(params=params, recordings=recs, simulator=get_simulator("engine"),
                                    space=default_space(params, recs))
    tic = time.perf_counter()
    result = identify(problem, evaluations=args.evaluations)
    wall = time.perf_counter() - tic
    score = problem.score(result.coordinates)
    print(f"default identification, 1 s data, cold-window prior: R2_mod {score.r2_mod:.4f} "
          f"(HWFET {score.per_recording[0]:.4f}, LA92 {score.per_recording[1]:.4f}), {result.evaluations} evaluations, "
          f"{wall:.0f} s wall")
    print("  " + ", ".join(f"{k} {v:.4g}" for k, v in result.coordinates.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
