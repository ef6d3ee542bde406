"""A depth resistance measured on the Panasonic 18650PF's 25 degC HPPC, tried in the model after the fact.

An analysis, not part of the package (docs/runtime_real_data/README.md, "A depth resistance from the HPPC, and the
largest sample as the peak"). Two steps:

``pulses PARAMS HPPC.csv``
    The cell's 1 s pulse resistance ``(V_rest - V(1 s)) / I`` at every discharge pulse of the HPPC recording
    (rest voltage, current), beside the model's at the same rest voltages (``PARAMS`` simulated from that open-
    circuit voltage with the engine, 10 s pulses at 2.9 / 5.8 / 11.6 / 17.4 A). The HPPC file holds the pulses but
    not the discharges between them, so the model is started from each rest voltage rather than driven by the file.

``run MAPPING_PARAMS -- battery-predictor arguments``
    Runs a ``battery-predictor`` command with the depth resistance added to the model's voltage: ``I x R_d(x)``,
    ``R_d = A exp(k x)`` with ``x`` the negative electrode's surface stoichiometry, least squares through
    :data:`DEPTH_POINTS` placed at the stoichiometries ``MAPPING_PARAMS`` gives those open-circuit voltages, times
    the ``temperature`` extension's Arrhenius ratio (30 kJ/mol). It rides on the extension's charge-transfer excess
    (``simulation.extensions.charge_transfer_excess_ohm``, replaced in this process), so it acts in the engine and
    in PyBaMM stepping, in ``fit``, ``simulate`` and ``evaluate-runtime`` alike, for params with the ``temperature``
    extension and a cold charge-transfer prior (``params/panasonic_18650pf.yaml``).

Run from the repository::

    .venv/bin/python docs/runtime_real_data/depth_resistance_posthoc.py pulses FIT.yaml $D/hppc_T25C.csv
    .venv/bin/python docs/runtime_real_data/depth_resistance_posthoc.py run FIT.yaml -- fit \
        --params params/panasonic_18650pf.yaml --data $D/drive_T25C_HWFET.csv $D/drive_T25C_LA92.csv --out DEPTH.yaml
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import battery_predictor.simulation.extensions as ext  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402
from battery_predictor.params import PackParams, load_params  # noqa: E402
from battery_predictor.simulation.base import SimulationRequest  # noqa: E402
from battery_predictor.simulation.engine.simulator import EngineSimulator  # noqa: E402
from battery_predictor.simulation.engine.state import StoichiometryWindow  # noqa: E402
from battery_predictor.simulation.load import StepLoad  # noqa: E402

#: (rest voltage V, resistance Ohm): the cell's 1 s resistance over the model's at 5.8 A (``pulses`` with the
#: default fit of 2026-11-29; at 3.22 V the cell's 97.7 against the model's 37.3), less that excess at mid charge
#: (2 mOhm at 3.60 V).
DEPTH_POINTS = ((3.51, 1.5e-3), (3.45, 4.0e-3), (3.38, 13.0e-3), (3.34, 36.0e-3), (3.22, 59.0e-3))
PULSE_CURRENTS_A = (2.9, 5.8, 11.6, 17.4)
MODEL_OCVS_V = (3.90, 3.60, 3.55, 3.51, 3.45, 3.43, 3.38, 3.34, 3.30, 3.22)
#: A depth resistance never exceeds this (Ohm), so that an empty surface cannot stall a solver.
DEPTH_CAP_OHM = 0.2


def cell_pulses(hppc_csv: str) -> None:
    """Print the cell's 1 s resistance at each discharge pulse of an HPPC recording."""
    rec = load_recording(Path(hppc_csv))
    t, v, i = rec.relative_time_s, rec.voltage_v, rec.current_a
    starts = np.nonzero((np.abs(i[:-1]) < 0.05) & (i[1:] > 1.0))[0] + 1
    for s in starts:
        j = int(np.searchsorted(t, t[s] + 1.0))
        if j < len(t) and i[j] > 1.0:
            print(f"cell  rest {v[s - 1]:.3f} V  {i[j]:5.2f} A  R1s {1e3 * (v[s - 1] - v[j]) / i[j]:5.1f} mOhm")


def model_pulses(params: PackParams) -> None:
    """Print the model's 1 s / 10 s resistance from rest at :data:`MODEL_OCVS_V` (25 degC)."""
    sim = EngineSimulator()
    for ocv in MODEL_OCVS_V:
        cells = []
        for amp in PULSE_CURRENTS_A:
            request = SimulationRequest(StepLoad.from_durations([10.0], [amp]), ambient_temperature_k=298.15,
                                        initial_pack_ocv_v=ocv * params.series, output_time_s=np.array([0.0, 1.0, 10.0]))
            v = sim.simulate(params, request).pack_voltage_v / params.series
            r = [1e3 * (ocv - v[k]) / amp if len(v) > k else float("nan") for k in (1, 2)]
            cells.append(f"{amp:4.1f} A {r[0]:5.1f}/{r[1]:5.1f}")
        print(f"model rest {ocv:.2f} V  R1s/R10s mOhm: " + "   ".join(cells))


def depth_law(params: PackParams) -> tuple[float, float]:
    """``(ln A, k)`` of ``R_d = A exp(k x)`` through :data:`DEPTH_POINTS` on ``params``' stoichiometries."""
    sim = EngineSimulator()
    model, _, _ = sim._model(params, 298.15)
    window = StoichiometryWindow(model, sim._parameter_values(params))
    xs = np.array([window.x_at_ocv(ocv) for ocv, _ in DEPTH_POINTS])
    rs = np.array([r for _, r in DEPTH_POINTS])
    k, ln_a = np.polyfit(xs, np.log(rs), 1)
    fitted = 1e3 * np.exp(ln_a + k * xs)
    sys.stderr.write(f"depth resistance: x {np.round(xs, 4)} -> {np.round(fitted, 1)} mOhm "
                     f"(R = {np.exp(ln_a):.3g} exp({k:.1f} x) Ohm)\n")
    return float(ln_a), float(k)


def with_depth_resistance(ln_a: float, k: float) -> None:
    """Replace the extension's charge-transfer excess by itself plus the Arrhenius depth resistance."""
    import pybamm

    original = ext.charge_transfer_excess_ohm

    def excess(r_anchor_ohm: Any, sto: Any, temperature_k: Any, anchor_k: Any = ext.COLD_REFERENCE_K,
               loss_per_k: Any = 0.0, sto_charged: float | None = None) -> Any:
        base = original(r_anchor_ohm, sto, temperature_k, anchor_k, loss_per_k, sto_charged)
        ratio = ext.arrhenius_ratio(ext.COLD_RESISTANCE_ACTIVATION_J_MOL, temperature_k, anchor_k)
        if isinstance(sto, pybamm.Symbol):
            depth = pybamm.minimum(np.exp(ln_a) * pybamm.exp(k * pybamm.maximum(sto, 1e-3)), DEPTH_CAP_OHM)
        else:
            depth = np.minimum(np.exp(ln_a) * np.exp(k * np.maximum(np.asarray(sto, float), 1e-3)), DEPTH_CAP_OHM)
        return base + depth * ratio

    ext.charge_transfer_excess_ohm = excess


def main(argv: list[str]) -> int:
    if len(argv) >= 3 and argv[0] == "pulses":
        cell_pulses(argv[2])
        model_pulses(load_params(argv[1]))
        return 0
    if len(argv) >= 3 and argv[0] == "run" and argv[2] == "--":
        with_depth_resistance(*depth_law(load_params(argv[1])))
        from battery_predictor.cli.main import main as cli

        return cli(argv[3:])
    sys.stderr.write(__doc__ or "")
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
