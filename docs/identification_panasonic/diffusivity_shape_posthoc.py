"""After the fact: a positive diffusivity that falls towards full lithiation, refitted from a stored fit.

An experiment, not part of the package (docs/identification.md, "What remains of issue 17"). The positive
particle diffusivity becomes ``D_p(x) = D_p s ((1 - x) / 0.5) ** p`` (``x`` the local stoichiometry; vacancy-limited
hopping for ``p = 1``; ``p = 0`` is the constant diffusivity of the fit). The engine steps linear diffusion only,
so this runs on PyBaMM's solver (the fast simulator, patched for the run). From the fit's coordinates,
``scipy.optimize.least_squares`` refines every coordinate of ``fit``'s default space plus ``log10 s`` and ``p`` on
``fit``'s residual (HWFET + LA92 at 25 degC, 5 s windows), then scores the held-out Cycle1 and US06 from their own
first voltage as ``simulate --initial-state voltage`` does.

Run from the repository (FIT.json beside FIT.yaml, as ``fit --json`` writes it; P0 the exponent to start from)::

    .venv/bin/python docs/identification_panasonic/diffusivity_shape_posthoc.py FIT.yaml 1.0
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pybamm
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import battery_predictor.simulation.fast as fast  # noqa: E402
from battery_predictor.cli.common import prepared_data  # noqa: E402
from battery_predictor.cli.main import build_parser  # noqa: E402
from battery_predictor.fitting.cost import r2_mod, rmse_v  # noqa: E402
from battery_predictor.fitting.identifiable import default_space  # noqa: E402
from battery_predictor.fitting.identification import IdentificationProblem  # noqa: E402
from battery_predictor.fitting.problem import loaded_start_ocv_v, request_for_recording, starts_at_rest  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.recording import ends_at_cutoff  # noqa: E402

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "panasonic_18650pf"
KEY = "Positive particle diffusivity [m2.s-1]"
SHAPE = {"Dp_scale": 1.0, "Dp_exp": 0.0}
_PREPARED = fast.prepared_parameter_values
_SOLVE = pybamm.Simulation.solve


def _prepared(params):
    """The fast simulator's values with the shaped positive diffusivity (and room above the OCV's top)."""
    pv = _PREPARED(params)
    base = pv[KEY]

    def diffusivity(sto, temperature):
        value = base(sto, temperature) if callable(base) else base
        return (value * pybamm.InputParameter("Dp_scale")
                * (pybamm.maximum(1 - sto, 1e-3) / 0.5) ** pybamm.InputParameter("Dp_exp"))

    pv[KEY] = diffusivity
    # the engine starts a fitted initial OCV above the params' 100 % voltage; PyBaMM's inversion needs the room
    pv["Open-circuit voltage at 100% SOC [V]"] = 4.35
    return pv


def _solve(self, *args, inputs=None, **kwargs):
    return _SOLVE(self, *args, inputs={**(inputs or {}), **SHAPE}, **kwargs)


def held_out(params, problem, simulator, coordinates) -> list[tuple]:
    """(R2_mod, RMSE mV, measured min, simulated end min) of Cycle1 and US06 from their own first voltage."""
    args = build_parser().parse_args(["simulate", "--params", str(params.source), "--data",
                                      str(DATA / "drive_T25C_Cycle1.csv"), str(DATA / "drive_T25C_US06.csv")])
    fitted = params.with_values(problem.values(coordinates)[0])
    out = []
    for rec in prepared_data(args, params, command="simulate"):
        req = request_for_recording(fitted, rec, initial_state="voltage", extend_s=0.5 * rec.duration_s)
        if not starts_at_rest(fitted, rec):
            req = replace(req, initial_pack_ocv_v=loaded_start_ocv_v(fitted, rec, simulator))
        res = simulator.simulate(fitted, req)
        t = rec.relative_time_s
        out.append((round(r2_mod(t, rec.voltage_v, res.time_s, res.pack_voltage_v, ends_at_cutoff(rec)), 4),
                    round(1e3 * rmse_v(t, rec.voltage_v, res.time_s, res.pack_voltage_v), 1),
                    round(rec.duration_s / 60, 1), round(res.end_time_s / 60, 1)))
    return out


def main() -> None:
    fast.prepared_parameter_values = _prepared
    pybamm.Simulation.solve = _solve
    fit_yaml = Path(sys.argv[1])
    p0 = float(sys.argv[2]) if len(sys.argv) > 2 else 0.5
    params = load_params(fit_yaml)
    args = build_parser().parse_args(["fit", "--params", str(fit_yaml), "--data", str(DATA / "drive_T25C_HWFET.csv"),
                                      str(DATA / "drive_T25C_LA92.csv"), "--out", "unused.yaml"])
    recs = prepared_data(args, params, command="fit")
    simulator = fast.FastPackSimulator(rtol=1e-5, atol=1e-7)
    problem = IdentificationProblem(params=params, recordings=recs, simulator=simulator,
                                    space=default_space(params, recs))
    n = len(problem.space)
    start = problem.unit(json.loads(fit_yaml.with_suffix(".json").read_text())["coordinates"])

    def residual(theta: np.ndarray) -> np.ndarray:
        SHAPE["Dp_scale"], SHAPE["Dp_exp"] = 10 ** theta[n], theta[n + 1]
        return problem.residuals(problem.coordinates(theta[:n]))

    tic = time.perf_counter()
    print("constant diffusivity: R2_mod", round(problem.score(problem.coordinates(start)).r2_mod, 4),
          f"({time.perf_counter() - tic:.1f} s)", "held out", held_out(params, problem, simulator,
                                                                       problem.coordinates(start)), flush=True)
    theta0 = np.concatenate([start, [0.0, p0]])
    low, high = np.concatenate([np.zeros(n), [-1.5, 0.0]]), np.concatenate([np.ones(n), [1.5, 3.0]])
    end = least_squares(residual, theta0, bounds=(low, high), diff_step=1e-3, max_nfev=40,
                        x_scale=np.concatenate([np.full(n, 0.05), [0.3, 0.5]]))
    SHAPE["Dp_scale"], SHAPE["Dp_exp"] = 10 ** end.x[n], end.x[n + 1]
    coordinates = problem.coordinates(end.x[:n])
    print(f"shaped diffusivity: scale {SHAPE['Dp_scale']:.3f}, exponent {SHAPE['Dp_exp']:.3f}, "
          f"{end.nfev} evaluations ({end.message}): R2_mod {problem.score(coordinates).r2_mod:.4f}, held out",
          held_out(params, problem, simulator, coordinates), flush=True)


if __name__ == "__main__":
    main()
