"""After the fact: where a shaped positive diffusivity ends the held-out 25 degC Cycle1 and US06, on a grid.

An experiment, not part of the package (docs/identification.md, "What remains of issue 17"). The fit's
coordinates are held and the positive particle diffusivity becomes ``D_p s ((1 - x) / 0.5) ** p``
(:mod:`diffusivity_shape_posthoc`, beside this file); for each ``(s, p)`` of the grid it prints the fit data's
R2_mod (HWFET + LA92 at 25 degC, 5 s windows) and, for Cycle1 and US06 from their own first voltage,
(R2_mod, RMSE mV, measured min, simulated end min). A feasibility check of the structure: is there any ``(s, p)``
at which both held-out recordings end where the cell did? It selects nothing.

Run from the repository (FIT.json beside FIT.yaml, as ``fit --json`` writes it)::

    .venv/bin/python docs/identification_panasonic/diffusivity_shape_scan.py FIT.yaml 0.3,1,3,10 1,2,4,8
"""

from __future__ import annotations

import itertools
import json
import sys
import time
from pathlib import Path

import pybamm

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import diffusivity_shape_posthoc as shape  # noqa: E402

import battery_predictor.simulation.fast as fast  # noqa: E402
from battery_predictor.cli.common import prepared_data  # noqa: E402
from battery_predictor.cli.main import build_parser  # noqa: E402
from battery_predictor.fitting.identifiable import default_space  # noqa: E402
from battery_predictor.fitting.identification import IdentificationProblem  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402


def main() -> None:
    fast.prepared_parameter_values = shape._prepared
    pybamm.Simulation.solve = shape._solve
    fit_yaml = Path(sys.argv[1])
    params = load_params(fit_yaml)
    args = build_parser().parse_args(["fit", "--params", str(fit_yaml), "--data",
                                      str(shape.DATA / "drive_T25C_HWFET.csv"), str(shape.DATA / "drive_T25C_LA92.csv"),
                                      "--out", "unused.yaml"])
    recs = prepared_data(args, params, command="fit")
    simulator = fast.FastPackSimulator(rtol=1e-5, atol=1e-7)
    problem = IdentificationProblem(params=params, recordings=recs, simulator=simulator,
                                    space=default_space(params, recs))
    coordinates = problem.coordinates(problem.unit(json.loads(fit_yaml.with_suffix(".json").read_text())["coordinates"]))
    scales = [float(x) for x in sys.argv[2].split(",")]
    exponents = [float(x) for x in sys.argv[3].split(",")]
    for s, p in itertools.product(scales, exponents):
        shape.SHAPE["Dp_scale"], shape.SHAPE["Dp_exp"] = s, p
        tic = time.perf_counter()
        r2 = problem.score(coordinates).r2_mod
        held = shape.held_out(params, problem, simulator, coordinates)
        print(f"s {s:6.2f} p {p:4.1f}: fit R2_mod {r2:.4f}  held out {held}  ({time.perf_counter() - tic:.0f} s)",
              flush=True)


if __name__ == "__main__":
    main()
