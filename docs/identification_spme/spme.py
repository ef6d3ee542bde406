"""The SPMe (extension ``electrolyte_transport``) against the SPM on the Panasonic fit data (issue 17, 2026-11-27).

Three subcommands, run from the repository root with ``PYTHONPATH=$PWD``:

``fit ARGS...``
    ``battery-predictor fit ARGS...`` with two changes for the SPMe: what the engine does not cover (the
    SPMe) is solved by PyBaMM's solver at ``rtol 1e-4 / atol 1e-6`` instead of the fast simulator's
    ``1e-6 / 1e-8`` (2.8x faster; 0.13 mV RMS, 0.85 mV at most on the two 10 s fit recordings), and,
    with ``--arrhenius`` (default), the electrolyte's conductivity and diffusivity follow Arrhenius
    (below). The SPM runs on the engine as in ``fit``.
``simulate ARGS...``
    ``battery-predictor simulate ARGS...`` with the same two changes.
``score --params SPME --at FIT --data ...``
    R2_mod of the SPMe params at the coordinates (initial OCVs included) of a fit of the same data, for each
    ``--bruggeman`` exponent.
``frozen --params SPME --data ...``
    The electrolyte concentration's range and what freezing its diffusivity at the initial concentration
    changes in the voltage (see :func:`frozen_diffusivity_effect`).
``step PARAMS...``
    The model's step resistance: 0.7 A until 1.0 (2.2) Ah are drawn from the params' initial state (the
    last 60 s of it the 0.7 A the step starts from), then 10.7 A for 1 s; ``(V before - V after 1 s) / 10 A``
    at 25 / 12 / 2 degC (isothermal), on PyBaMM's solver (the fast simulator, ``rtol 1e-6``).

Arrhenius electrolyte: Chen2020 (the Panasonic params' base set) takes the electrolyte's conductivity and
diffusivity from Nyman et al. 2008 without temperature dependence; PyBaMM's OKane2022 set (Chen2020's cell)
multiplies the same functions by ``exp(E / R (1/298.15 - 1/T))`` with E = 17.0 kJ/mol for both (Ecker et al.
2015). ``--arrhenius`` swaps OKane2022's functions in wherever the ``electrolyte_transport`` extension is
active; ``--no-arrhenius`` runs PyBaMM's Chen2020 SPMe as it is.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

RTOL, ATOL = 1e-4, 1e-6
STEP_TEMPERATURES_C = (25.0, 12.0, 2.0)
STEP_DRAWN_AH = (1.0, 2.2)
BASE_A, PEAK_A, BASE_S, PEAK_S = 0.7, 10.7, 60.0, 1.0


def _initial_concentrations_beyond_the_cutoff(pybamms: Any) -> Any:
    """The fast simulator's initial state, which also starts above the OCV at 100 % SOC as the engine does.

    PyBaMM's ``get_initial_stoichiometries`` refuses an open-circuit voltage above the params' OCV at
    100 % SOC (4.2 V here); ``simulate --initial-state voltage`` asks 4.247 V of the Chen2020 SPMe fit on
    Cycle1. The engine then solves ``U_p(y) - U_n(x) = OCV`` on the line of the params' cyclable lithium
    (``StoichiometryWindow``); this does the same with :func:`battery_predictor.ocp.initial_stoichiometries`
    when PyBaMM refuses, and is PyBaMM's answer otherwise.
    """
    from battery_predictor.errors import SimulationError
    from battery_predictor.ocp import initial_stoichiometries

    def initial_concentrations(params: Any, pv: Any, *, initial_soc: float | None,
                               initial_cell_ocv_v: float | None) -> tuple[float, float]:
        try:
            return pybamms(params, pv, initial_soc=initial_soc, initial_cell_ocv_v=initial_cell_ocv_v)
        except SimulationError:
            if initial_cell_ocv_v is None:
                raise
        area = float(pv["Electrode height [m]"]) * float(pv["Electrode width [m]"])
        c_max, q, c_0 = [], [], []
        for cap, low in (("Negative", "negative"), ("Positive", "positive")):
            c_max.append(float(pv[f"Maximum concentration in {low} electrode [mol.m-3]"]))
            q.append(96485.33212 * area * c_max[-1] * float(pv[f"{cap} electrode thickness [m]"])
                     * float(pv[f"{cap} electrode active material volume fraction"]) / 3600.0)
            c_0.append(float(pv[f"Initial concentration in {low} electrode [mol.m-3]"]))
        q_li = c_0[0] / c_max[0] * q[0] + c_0[1] / c_max[1] * q[1]
        x, y = initial_stoichiometries(params, q[0], q[1], q_li, float(initial_cell_ocv_v))
        return x * c_max[0], y * c_max[1]

    initial_concentrations.spme_patched = True  # type: ignore[attr-defined]
    return initial_concentrations


def _patch(arrhenius: bool, loose: bool) -> None:
    """Swap the electrolyte functions (``arrhenius``) and the fallback solver's tolerances (``loose``)."""
    import battery_predictor.cli.fit_identify as fit_identify
    import battery_predictor.simulation.cell_setup as cell_setup

    if arrhenius:
        from pybamm.input.parameters.lithium_ion import OKane2022

        applied = cell_setup.apply_extension_parameter_values

        def with_arrhenius_electrolyte(params: Any, pv: Any) -> Any:
            pv = applied(params, pv)
            if "electrolyte_transport" in params.extensions:
                pv.update({"Electrolyte conductivity [S.m-1]": OKane2022.electrolyte_conductivity_Nyman2008_arrhenius,
                           "Electrolyte diffusivity [m2.s-1]": OKane2022.electrolyte_diffusivity_Nyman2008_arrhenius})
            return pv

        cell_setup.apply_extension_parameter_values = with_arrhenius_electrolyte  # type: ignore[assignment]
    import battery_predictor.simulation.fast as fast

    if not getattr(fast.initial_concentrations, "spme_patched", False):
        fast.initial_concentrations = _initial_concentrations_beyond_the_cutoff(fast.initial_concentrations)
    if loose:
        from battery_predictor.simulation.engine import EngineSimulator
        from battery_predictor.simulation.fast import FastPackSimulator

        named = fit_identify.simulator_named

        def simulator_named(name: str) -> Any:
            if name == "engine":
                return EngineSimulator(fallback=FastPackSimulator(rtol=RTOL, atol=ATOL))
            return named(name)

        fit_identify.simulator_named = simulator_named  # type: ignore[assignment]


def _cli(argv: list[str], arrhenius: bool) -> int:
    from battery_predictor.cli.main import main

    _patch(arrhenius, loose=True)
    tic = time.perf_counter()
    code = main(argv)
    sys.stderr.write(f"spme.py: {argv[0]} took {time.perf_counter() - tic:.0f} s wall\n")
    return code


def step_resistance_mohm(params_path: str, arrhenius: bool) -> dict[str, list[float]]:
    """Step resistance (mOhm) per temperature (degC) at :data:`STEP_DRAWN_AH` of ``params_path``."""
    from battery_predictor.params import load_params
    from battery_predictor.simulation.base import SimulationRequest
    from battery_predictor.simulation.fast import FastPackSimulator
    from battery_predictor.simulation.load import StepLoad

    _patch(arrhenius, loose=False)
    params = load_params(params_path)
    sim = FastPackSimulator()
    out: dict[str, list[float]] = {}
    for t_c in STEP_TEMPERATURES_C:
        row = []
        for drawn in STEP_DRAWN_AH:
            t_step = drawn * 3600.0 / BASE_A  # the peak starts when `drawn` Ah have flowed at 0.7 A
            load = StepLoad(np.array([0.0, t_step]), np.array([BASE_A, PEAK_A]) * params.parallel, t_step + 2.0)
            before, after = t_step - 0.01, t_step + PEAK_S
            req = SimulationRequest(load=load, ambient_temperature_k=273.15 + t_c,
                                    output_time_s=np.array([t_step - BASE_S, before, after]))
            res = sim.simulate(params, req)
            v = np.interp([before, after], res.time_s, res.pack_voltage_v)
            row.append(1e3 * float(v[0] - v[1]) / ((PEAK_A - BASE_A) * params.parallel))
        out[f"{t_c:g}"] = row
    return out


def frozen_diffusivity_effect(params_path: str, data: list[str], resample_s: float | None) -> list[str]:
    """How far the electrolyte moves from its initial concentration, and what freezing ``D_e`` there changes.

    For each recording (simulated from the params' initial state, Arrhenius electrolyte): the range of the
    electrolyte concentration (mol/m3) over the run and the RMS / largest voltage difference (mV) between the
    SPMe with Nyman's ``D_e(c_e, T)`` and the same SPMe with ``D_e(c_e_init, T)`` (the linear block an engine
    would step exactly).
    """
    import pybamm
    from pybamm.input.parameters.lithium_ion import OKane2022

    import battery_predictor.simulation.cell_setup as cell_setup
    from battery_predictor.cli.common import load_data
    from battery_predictor.fitting.problem import request_for_recording
    from battery_predictor.fitting.resample import as_the_monitor_sees
    from battery_predictor.params import load_params
    from battery_predictor.simulation.fast import FastPackSimulator

    _patch(True, loose=False)
    params = load_params(params_path)
    recs, _, _ = as_the_monitor_sees(load_data(data, pack=params), resample_s)
    arrhenius = cell_setup.apply_extension_parameter_values
    lines = []
    for rec in recs:
        runs = []
        for frozen in (False, True):
            def values(p: Any, pv: Any, frozen: bool = frozen) -> Any:
                pv = arrhenius(p, pv)
                if frozen:
                    c_0 = float(pv["Initial concentration in electrolyte [mol.m-3]"])
                    pv["Electrolyte diffusivity [m2.s-1]"] = (
                        lambda c_e, T: OKane2022.electrolyte_diffusivity_Nyman2008_arrhenius(pybamm.Scalar(c_0), T))
                return pv

            cell_setup.apply_extension_parameter_values = values  # type: ignore[assignment]
            sim = FastPackSimulator()
            res = sim.simulate(params, request_for_recording(params, rec, initial_state="params"))
            built = next(iter(sim._cache.values()))[0]
            c_e = built.solution["Electrolyte concentration [mol.m-3]"].entries
            runs.append((res, float(c_e.min()), float(c_e.max())))
        cell_setup.apply_extension_parameter_values = arrhenius  # type: ignore[assignment]
        (a, lo, hi), (b, _, _) = runs
        n = min(a.time_s.size, b.time_s.size)
        diff = 1e3 * (a.pack_voltage_v[:n] - b.pack_voltage_v[:n])
        lines.append(f"{rec.source}: c_e {lo:.0f}..{hi:.0f} mol/m3; frozen D_e changes the voltage by "
                     f"{float(np.sqrt(np.mean(diff ** 2))):.2f} mV RMS, {float(np.abs(diff).max()):.1f} mV at most; "
                     f"2.5 V at {a.end_time_s / 60:.1f} / {b.end_time_s / 60:.1f} min")
    return lines


def scores_at(start: str, fit: str, data: list[str], resample_s: float, exponents: list[float]) -> list[str]:
    """R2_mod of the SPMe params ``start`` at the coordinates (initial OCVs included) a ``fit`` of the same data
    found, for each Bruggeman exponent (Arrhenius electrolyte, the fit's solver tolerances)."""
    import yaml

    from battery_predictor.cli.common import load_data
    from battery_predictor.fitting.identifiable import default_space
    from battery_predictor.fitting.identification import IdentificationProblem
    from battery_predictor.fitting.resample import as_the_monitor_sees
    from battery_predictor.params import load_params
    from battery_predictor.simulation.extensions import with_cold_window_anchors, with_fitted_extension_keys
    from battery_predictor.simulation.fast import FastPackSimulator

    _patch(True, loose=False)
    params = with_fitted_extension_keys(with_cold_window_anchors(load_params(start)))
    recs, _, _ = as_the_monitor_sees(load_data(data, pack=params), resample_s)
    problem = IdentificationProblem(params=params, recordings=recs, simulator=FastPackSimulator(rtol=RTOL, atol=ATOL),
                                    space=default_space(params, recs))
    provenance = yaml.safe_load(Path(fit).read_text())["provenance"]
    coordinates = dict(provenance["coordinates"])
    coordinates.update({f"initial_ocv_v:{k}": v for k, v in enumerate(provenance["initial_ocv_v_per_file"].values())})
    lines = []
    for b in exponents:
        s = problem.score({**coordinates, "electrolyte_bruggeman": b})
        lines.append(f"b {b:g}: R2_mod {' / '.join(f'{r:.4f}' for r in s.per_recording)}, mean {s.r2_mod:.4f} "
                     f"(RMSE {' / '.join(f'{r:.0f}' for r in s.rmse_mv)} mV)")
    return lines


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    arrhenius = "--no-arrhenius" not in argv
    argv = [a for a in argv if a not in ("--arrhenius", "--no-arrhenius")]
    os.environ.setdefault("TQDM_DISABLE", "1")
    if not argv or argv[0] not in ("fit", "simulate", "step", "frozen", "score"):
        print(__doc__)
        return 2
    if argv[0] in ("fit", "simulate"):
        return _cli(argv, arrhenius)
    if argv[0] == "score":
        parser = argparse.ArgumentParser(prog="spme.py score")
        parser.add_argument("--params", required=True, help="SPMe params (electrolyte_transport)")
        parser.add_argument("--at", required=True, help="fitted params whose provenance holds the coordinates")
        parser.add_argument("--data", nargs="+", required=True)
        parser.add_argument("--resample", type=float, default=10.0)
        parser.add_argument("--bruggeman", type=float, nargs="+", default=[1.0, 1.5])
        args = parser.parse_args(argv[1:])
        print("\n".join(scores_at(args.params, args.at, args.data, args.resample, args.bruggeman)))
        return 0
    if argv[0] == "frozen":
        parser = argparse.ArgumentParser(prog="spme.py frozen")
        parser.add_argument("--params", required=True)
        parser.add_argument("--data", nargs="+", required=True)
        parser.add_argument("--resample", type=float, default=None)
        args = parser.parse_args(argv[1:])
        print("\n".join(frozen_diffusivity_effect(args.params, args.data, args.resample)))
        return 0
    parser = argparse.ArgumentParser(prog="spme.py step")
    parser.add_argument("params", nargs="+")
    args = parser.parse_args(argv[1:])
    print(f"step resistance (mOhm), 0.7 A -> 10.7 A for 1 s, at {' / '.join(f'{d:g}' for d in STEP_DRAWN_AH)} Ah "
          f"drawn; electrolyte {'Arrhenius 17 kJ/mol' if arrhenius else 'as Chen2020 (no T dependence)'}")
    print("params | " + " | ".join(f"{t:g} degC" for t in STEP_TEMPERATURES_C))
    for path in args.params:
        r = step_resistance_mohm(path, arrhenius)
        print(f"{path} | " + " | ".join(" / ".join(f"{x:.1f}" for x in r[f'{t:g}']) for t in STEP_TEMPERATURES_C))
    return 0


if __name__ == "__main__":
    sys.exit(main())
