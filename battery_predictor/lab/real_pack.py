"""The reference "real pack" of the emulation lab.

The shipped bags stand in for the paper's lab measurements, so the pack that
produces them must not be the model that is later fitted to them. The real
pack starts from a pack's params file (``params/temi.yaml``,
``params/ranger_mini.yaml``: SPM cells, identical, isothermal) and is made
richer in four ways:

1. **SPMe cells** instead of SPM: electrolyte concentration polarisation and
   electrolyte/electrode ohmic losses (tens of mV at the robots' currents,
   growing towards the end of discharge).
2. **Lumped thermal model** (PyBaMM option ``{"thermal": "lumped"}``): each
   cell warms up with its own heat generation and Newton cooling to the
   ambient, and its kinetics and transport follow the temperature (Arrhenius
   terms of the parameter set). Chen2020 has every thermal parameter;
   Prada2013 has none, so :data:`THERMAL_DEFAULTS` supplies them (Chen2020's
   current-collector, separator and graphite values, typical LiFePO4 coating
   values). The cooling surface is the cylinder surface of the cell format
   (18650 / 32700) and the heat transfer coefficient that of an enclosed pack.
3. **Contact resistance** (option ``{"contact resistance": "true"}``): a
   per-cell series resistance that the params file does not have.
4. **Seeded cell-to-cell spread** (liionpack simulates every cell):
   capacity through ``Electrode height [m]`` (relative sigma ~1.5 %, plus
   an optional pack-level capacity factor so that different physical packs
   differ), contact resistance (a few mOhm) and the heat transfer
   coefficient (inner cells cool worse). The same :class:`RealPackSpec`
   always gives the same cells.

liionpack 0.4.0 pitfall (worked around here)
--------------------------------------------
liionpack passes the per-cell inputs to the CasADi integrator positionally,
``"Current function [A]"`` first and then the user's inputs in dict order,
while PyBaMM orders a model's inputs alphabetically. Any input whose name
sorts before ``"Current function [A]"`` (``"Contact resistance [Ohm]"``,
``"Ambient temperature [K]"``...) or inputs given out of alphabetical order
are silently swapped (the current becomes the contact resistance and vice
versa). :func:`~battery_predictor.simulation.liionpack_sim.solve_liionpack` therefore passes the inputs sorted and
renames every parameter that would sort before the current (the parameter
is set to a :class:`pybamm.InputParameter` named ``"Per-cell <name>"``).

The lab stops like the bench supply: when the pack terminal voltage reaches
the experiment's end voltage (:meth:`RealPack.simulate` ``stop_pack_voltage_v``),
not at the cell-level cut-off, so the real pack's cells may go below the
params' cut-off (their own cut-off is lowered to ``lower_cutoff_v``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.params import PackParams
from battery_predictor.simulation.liionpack_sim import pack_terminal_nodes, solve_liionpack
from battery_predictor.simulation.load import StepLoad

#: Per-cell temperature variable recorded from every cell.
TEMPERATURE_VARIABLE = "Volume-averaged cell temperature [K]"

#: Thermal parameters of PyBaMM's lumped model, used when the base set lacks them (Prada2013).
#: Current collectors, separator and graphite electrode: Chen2020 values; LiFePO4 coating:
#: typical density and specific heat of an LFP composite electrode.
THERMAL_DEFAULTS: dict[str, float] = {
    "Negative current collector thickness [m]": 1.2e-05,
    "Positive current collector thickness [m]": 1.6e-05,
    "Negative current collector conductivity [S.m-1]": 58411000.0,
    "Positive current collector conductivity [S.m-1]": 36914000.0,
    "Negative current collector density [kg.m-3]": 8960.0,
    "Positive current collector density [kg.m-3]": 2700.0,
    "Negative current collector specific heat capacity [J.kg-1.K-1]": 385.0,
    "Positive current collector specific heat capacity [J.kg-1.K-1]": 897.0,
    "Negative current collector thermal conductivity [W.m-1.K-1]": 401.0,
    "Positive current collector thermal conductivity [W.m-1.K-1]": 237.0,
    "Negative electrode density [kg.m-3]": 1657.0,
    "Negative electrode specific heat capacity [J.kg-1.K-1]": 700.0,
    "Negative electrode thermal conductivity [W.m-1.K-1]": 1.7,
    "Separator density [kg.m-3]": 397.0,
    "Separator specific heat capacity [J.kg-1.K-1]": 700.0,
    "Separator thermal conductivity [W.m-1.K-1]": 0.16,
    "Positive electrode density [kg.m-3]": 2200.0,
    "Positive electrode specific heat capacity [J.kg-1.K-1]": 900.0,
    "Positive electrode thermal conductivity [W.m-1.K-1]": 1.0,
}


def cylinder_surface_m2(diameter_m: float, height_m: float) -> float:
    """Outer surface (mantle and both ends) of a cylindrical cell in m2."""
    return math.pi * diameter_m * height_m + 2.0 * math.pi * (diameter_m / 2.0) ** 2


#: Cooling surface of the two cell formats in m2.
SURFACE_18650_M2 = cylinder_surface_m2(0.018, 0.065)
SURFACE_32700_M2 = cylinder_surface_m2(0.032, 0.070)


@dataclass(frozen=True)
class RealPackSpec:
    """How an emulated physical pack differs from its params file.

    Attributes
    ----------
    pack_id : str
        Name of the physical pack (``"temi_pack1"``...).
    seed : int
        Seed of the cell-to-cell spread.
    model : str
        Cell model (``"SPMe"``; one step above the fitted SPM).
    thermal : str
        PyBaMM thermal option (``"lumped"``).
    capacity_sigma : float
        Relative standard deviation of the per-cell ``Electrode height [m]`` (capacity).
    pack_capacity_factor : float
        Pack-level factor on the electrode height (1.0 for the development pack).
    contact_resistance_mean_ohm, contact_resistance_sigma_ohm : float
        Mean and standard deviation of the per-cell contact resistance in Ohm.
    heat_transfer_w_m2_k : float
        Mean total heat transfer coefficient in W/(m2 K).
    heat_transfer_sigma : float
        Relative standard deviation of the per-cell heat transfer coefficient.
    cooling_surface_area_m2 : float or None
        Cooling surface of one cell in m2 (None keeps the base set's value).
    lower_cutoff_v : float
        Cell-level cut-off of the real pack in V (below the params' one: the lab stops on pack voltage).
    clip_sigma : float
        Per-cell draws are clipped to +-clip_sigma standard deviations.
    """

    pack_id: str
    seed: int
    model: str = "SPMe"
    thermal: str = "lumped"
    capacity_sigma: float = 0.015
    pack_capacity_factor: float = 1.0
    contact_resistance_mean_ohm: float = 0.003
    contact_resistance_sigma_ohm: float = 0.0015
    heat_transfer_w_m2_k: float = 7.0
    heat_transfer_sigma: float = 0.15
    cooling_surface_area_m2: float | None = None
    lower_cutoff_v: float = 2.5
    clip_sigma: float = 3.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class PackTrace:
    """A noise-free real-pack simulation, reported at the start of every liionpack step.

    Attributes
    ----------
    time_s : numpy.ndarray
        Step start times in s (uniform, ``period_s`` apart).
    current_a : numpy.ndarray
        Pack current of each step in A (charge-conserving mean of ``load`` over the step).
    voltage_v : numpy.ndarray
        Pack terminal voltage in V at each step start, under that step's current.
    temperature_k : numpy.ndarray
        Mean volume-averaged cell temperature in K.
    cell_temperature_k : numpy.ndarray
        Per-cell temperatures in K, shape (steps, cells).
    min_cell_voltage_v : numpy.ndarray
        Lowest cell terminal voltage in V.
    termination : str
        ``"pack_voltage"`` (the stop voltage was reached), ``"cell_cutoff"`` or ``"end_of_load"``.
    load : StepLoad
        The load as applied by the bench supply (before resampling to the step grid).
    period_s : float
        liionpack step period in s.
    ambient_temperature_k : float
        Ambient temperature in K.
    seconds : float
        Wall time of the simulation in s.
    extra : dict
        Per-cell voltages and currents (``cell_voltage_v``, ``cell_current_a``).
    """

    time_s: np.ndarray
    current_a: np.ndarray
    voltage_v: np.ndarray
    temperature_k: np.ndarray
    cell_temperature_k: np.ndarray
    min_cell_voltage_v: np.ndarray
    termination: str
    load: StepLoad
    period_s: float
    ambient_temperature_k: float
    seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def end_s(self) -> float:
        """End of the last reported step in s."""
        return float(self.time_s[-1] + self.period_s)

    def time_to_voltage_s(self, threshold_v: float) -> float | None:
        """First step start (s) with a pack voltage at or below ``threshold_v``, or None."""
        idx = np.flatnonzero(self.voltage_v <= threshold_v)
        return float(self.time_s[idx[0]]) if idx.size else None

    def mean_voltage_v(self, start_s: float, end_s: float) -> float:
        """Mean pack voltage (V) over the steps that lie entirely within ``[start_s, end_s]``."""
        keep = (self.time_s >= start_s - 1e-9) & (self.time_s + self.period_s <= end_s + 1e-9)
        if not keep.any():
            raise SimulationError(f"no simulated step lies within {start_s:.1f}-{end_s:.1f} s")
        return float(np.mean(self.voltage_v[keep]))


def real_pack_params(params: PackParams, spec: RealPackSpec) -> PackParams:
    """The params of the real pack's mean cell: model, options and extra values of ``spec``."""
    import pybamm

    base = pybamm.ParameterValues(params.base_parameter_set)
    manual = dict(params.manual)
    if spec.thermal != "isothermal":
        for key, value in THERMAL_DEFAULTS.items():
            if key not in base.keys():
                manual[key] = value
        manual["Total heat transfer coefficient [W.m-2.K-1]"] = float(spec.heat_transfer_w_m2_k)
        if spec.cooling_surface_area_m2 is not None:
            manual["Cell cooling surface area [m2]"] = float(spec.cooling_surface_area_m2)
        elif "Cell cooling surface area [m2]" not in base.keys():
            raise SimulationError(f"real pack {spec.pack_id}: {params.base_parameter_set} has no cooling surface; "
                                  "set RealPackSpec.cooling_surface_area_m2")
    manual["Lower voltage cut-off [V]"] = float(spec.lower_cutoff_v)
    options = dict(params.options)
    options["thermal"] = spec.thermal
    options["contact resistance"] = "true"
    manual["Contact resistance [Ohm]"] = float(spec.contact_resistance_mean_ohm)
    fitted = dict(params.fitted)
    height_key = "Electrode height [m]"
    height = float(params.value(height_key)) * float(spec.pack_capacity_factor)
    if height_key in fitted:
        fitted[height_key] = height
    else:
        manual[height_key] = height
    return dataclasses.replace(params, model=spec.model, options=options, manual=manual, fitted=fitted,
                               name=f"{params.name}_real_{spec.pack_id}")


def cell_spread(params: PackParams, spec: RealPackSpec) -> dict[str, np.ndarray]:
    """Seeded per-cell values ``{pybamm_key: array of n_cells}`` of the real pack.

    Draw order (fixed, so a seed always gives the same pack): capacity,
    contact resistance, heat transfer coefficient; standard normals clipped to
    ``+-clip_sigma``.
    """
    n = params.n_cells
    rng = np.random.default_rng(int(spec.seed))
    z = np.clip(rng.standard_normal((3, n)), -spec.clip_sigma, spec.clip_sigma)
    height = float(params.value("Electrode height [m]")) * float(spec.pack_capacity_factor)
    out = {
        "Electrode height [m]": height * (1.0 + spec.capacity_sigma * z[0]),
        "Contact resistance [Ohm]": np.maximum(
            spec.contact_resistance_mean_ohm + spec.contact_resistance_sigma_ohm * z[1],
            0.1 * spec.contact_resistance_mean_ohm,
        ),
    }
    if spec.thermal != "isothermal":
        out["Total heat transfer coefficient [W.m-2.K-1]"] = np.maximum(
            spec.heat_transfer_w_m2_k * (1.0 + spec.heat_transfer_sigma * z[2]), 0.2 * spec.heat_transfer_w_m2_k
        )
    return out


class RealPack:
    """An emulated physical pack (see the module docstring).

    Parameters
    ----------
    params : PackParams
        The pack's params file (the model that will be fitted).
    spec : RealPackSpec
        How the real pack differs from it.
    """

    def __init__(self, params: PackParams, spec: RealPackSpec) -> None:
        self.base_params = params
        self.spec = spec
        self.params = real_pack_params(params, spec)
        self.cell_inputs = cell_spread(params, spec)

    # ----------------------------------------------------------------- views
    def mean_params(self) -> PackParams:
        """Identical cells with the mean per-cell values: a cheap stand-in for this pack (fast simulator)."""
        updates = {k: float(np.mean(v)) for k, v in self.cell_inputs.items()}
        return self.params.with_values(updates)

    def describe(self) -> dict[str, Any]:
        """JSON-ready description: the spec, the params it starts from and the per-cell values."""
        cells = {}
        for key, values in self.cell_inputs.items():
            arr = np.asarray(values, dtype=float)
            cells[key] = {
                "mean": float(arr.mean()),
                "std": float(arr.std()),
                "min": float(arr.min()),
                "max": float(arr.max()),
                "values": [float(f"{v:.6g}") for v in arr],
            }
        return {
            "spec": self.spec.to_dict(),
            "params_file": str(self.base_params.source),
            "params_name": self.base_params.name,
            "configuration": f"{self.params.series}S{self.params.parallel}P",
            "model": self.params.model,
            "options": dict(self.params.options),
            "added_parameters": {k: v for k, v in self.params.manual.items() if k not in self.base_params.manual},
            "cells": cells,
        }

    # ------------------------------------------------------------ simulation
    def simulate(
        self,
        load: StepLoad,
        *,
        initial_soc: float | None = None,
        ambient_temperature_k: float | None = None,
        stop_pack_voltage_v: float | None = None,
        stop_extra_steps: int = 2,
        period_s: float = 5.0,
    ) -> PackTrace:
        """Run the pack through ``load`` cell by cell with liionpack.

        Parameters
        ----------
        load : StepLoad
            Pack current (A, discharge positive) as the bench supply applies it.
        initial_soc : float, optional
            Initial SOC of every cell; None keeps the params' initial concentrations.
        ambient_temperature_k : float, optional
            Ambient (and initial) temperature in K; None takes the params' default.
        stop_pack_voltage_v : float, optional
            Stop once a step's pack terminal voltage is at or below this (V) ...
        stop_extra_steps : int
            ... after this many more steps (the step that reached it and ``stop_extra_steps - 1``
            further ones are reported; at least 1).
        period_s : float
            liionpack step period in s (the load is resampled onto it, charge-conserving).

        Raises
        ------
        SimulationError
            When liionpack fails.
        """
        tic = time.perf_counter()
        params = self.params
        stepped = load.resample(period_s)
        temperature_k = float(ambient_temperature_k or params.ambient_temperature_k)
        state: dict[str, Any] = {"calls": 0, "trigger": None, "stopped": False}

        def node_termination(netlist: Any) -> Callable[[np.ndarray], bool]:
            node_a, node_b = pack_terminal_nodes(netlist)

            def stop(v_node: np.ndarray) -> bool:
                # liionpack calls this once per step with the node voltages under the step's current
                state["calls"] += 1
                if stop_pack_voltage_v is None:
                    return False
                if state["trigger"] is None and float(v_node[node_b] - v_node[node_a]) <= stop_pack_voltage_v:
                    state["trigger"] = state["calls"]
                if state["trigger"] is not None and state["calls"] - state["trigger"] >= max(1, int(stop_extra_steps)):
                    state["stopped"] = True
                    return True
                return False

            return stop

        out = solve_liionpack(params, stepped, period_s, temperature_k=temperature_k, initial_soc=initial_soc,
                              cell_inputs=self.cell_inputs, initial_cell_voltage_v=3.5,
                              output_variables=[TEMPERATURE_VARIABLE], node_termination=node_termination,
                              failure=f"real pack {self.spec.pack_id}: liionpack failed")
        t = np.asarray(out["Time [s]"], dtype=float)
        if t.size < 2:
            raise SimulationError(f"real pack {self.spec.pack_id}: liionpack produced {t.size} steps")
        cell_v = np.asarray(out["Terminal voltage [V]"], dtype=float)
        cell_t = np.asarray(out[TEMPERATURE_VARIABLE], dtype=float)
        if state["stopped"]:
            termination = "pack_voltage"
        elif t.size < len(stepped.start_s):
            termination = "cell_cutoff"
        else:
            termination = "end_of_load"
        return PackTrace(
            time_s=t,
            current_a=stepped.current_a[: t.size].copy(),
            voltage_v=np.asarray(out["Pack terminal voltage [V]"], dtype=float),
            temperature_k=cell_t.mean(axis=1),
            cell_temperature_k=cell_t,
            min_cell_voltage_v=cell_v.min(axis=1),
            termination=termination,
            load=load,
            period_s=float(period_s),
            ambient_temperature_k=temperature_k,
            seconds=time.perf_counter() - tic,
            extra={"cell_voltage_v": cell_v, "cell_current_a": np.asarray(out["Cell current [A]"], dtype=float)},
        )
