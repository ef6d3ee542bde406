"""Test-data generator for the diagnosis: a reference recording without an effect and an observed
recording with ONE hidden effect, written as CSV files.

Test code only: ``battery_predictor.diagnosis`` never imports this module, and the truth models
below are built here directly from PyBaMM / liionpack (they do not use the diagnosis' candidate
or extension code), so the diagnosis cannot recognise its own implementation.

Truth models
------------
* Reference truth: the pack's params with small seeded perturbations of fitted values
  (electrode height +-4 %, positive volume fraction +-0.015, cell connection resistance
  x0.8-1.25) that the diagnosis' reference fit must recover. Isothermal SPM at 25 degC.
* Observed truth: the reference truth plus ONE effect, magnitude drawn uniformly in the range
  of :data:`EFFECT_RANGES`:

  ``temperature``           lumped thermal SPM (self-heating) at a low ambient (0-10 degC) with
                            Arrhenius particle diffusivities (separate activation energies for the
                            two electrodes); the CSV carries the cell temperature.
  ``capacity_fade``         loss of lithium inventory and of active material in both electrodes.
  ``resistance_growth``     PyBaMM contact resistance per cell.
  ``current_offset``        the CSV's current is the true current plus a sensor bias.
  ``cell_imbalance``        liionpack, series-groups netlist (parallel groups in series, as 18650 and
                            32700 packs are built): every cell with a +-1 % capacity spread, and one
                            group whose cells are aged to 70-88 % capacity each.
  ``electrolyte_transport`` SPMe with the electrolyte diffusivity and conductivity scaled down
                            (aged electrolyte) on a heavy-use profile.
  ``hysteresis``            PyBaMM one-state (Axen) OCP hysteresis in the positive electrode; the
                            recording starts right after charging (charge branch).
  ``none``                  the reference truth itself on a new profile.

Profiles (the robot's kind, a realistic working day): the observed recording is discharge ->
charge at the charger -> discharge to the cut-off: usage until the pack reaches its return
threshold, a constant-current charge, usage until the first cell reaches its cut-off. Temi:
the paper's stochastic usage at 3x current (heavy use), 10 s samples; Ranger: random
luggage jobs on the Minden station graph, 20 s samples. The reference recording is a
discharge to the cut-off from a high SOC with another seed. Noise: 3 mV (Temi) / 6 mV (Ranger)
Gaussian on the voltage, rounded to 10 mV (the paper's resolution), current rounded to 0.01 A.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from battery_predictor.io.csv_io import save_csv
from battery_predictor.params import PackParams, load_params
from battery_predictor.recording import Recording
from battery_predictor.simulation.load import StepLoad
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

REPO = Path(__file__).resolve().parents[2]
CAUSES = ("temperature", "capacity_fade", "resistance_growth", "current_offset", "cell_imbalance",
          "electrolyte_transport", "hysteresis", "none")
PACKS = ("temi", "ranger_mini")
#: Uniform ranges of each effect's magnitude (realistic for an aged / cold / faulty pack).
EFFECT_RANGES = {
    "temperature": {"ambient_c": (0.0, 10.0), "ea_neg_j_mol": (25e3, 45e3), "ea_pos_j_mol": (25e3, 45e3),
                    "h_w_m2k": (5.0, 20.0)},
    "capacity_fade": {"lli": (0.06, 0.14), "lam_neg": (0.0, 0.06), "lam_pos": (0.0, 0.06)},
    "resistance_growth": {"temi_ohm": (0.015, 0.040), "ranger_mini_ohm": (0.006, 0.015)},
    "current_offset": {"abs_a": (0.2, 0.5)},
    "cell_imbalance": {"weak_cell_fraction": (0.70, 0.88), "spread": (0.0, 0.01)},
    "electrolyte_transport": {"transport_scale": (0.45, 0.75)},
    "hysteresis": {"half_width_v": (0.008, 0.020), "decay": (20.0, 80.0)},
}
_EDGE_S = 1e-3
_STOP = {"temi": 13.30, "ranger_mini": 46.31}  # pack voltage at which the robot returns to its charger
_CHARGE_C_RATE = {"temi": 0.4, "ranger_mini": 0.5}
_CHARGE_MIN = {"temi": (30.0, 40.0), "ranger_mini": (15.0, 20.0)}
_SAMPLE_S = {"temi": 10.0, "ranger_mini": 20.0}
_NOISE_V = {"temi": 0.003, "ranger_mini": 0.006}


@dataclass
class Scenario:
    """One generated test case (the hidden truth stays in here; only the CSVs go to the CLI)."""

    cause: str
    pack: str
    seed: int
    params_path: Path
    reference_csv: Path
    observed_csv: Path
    magnitude: dict = field(default_factory=dict)
    reference_values: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- profiles
def temi_usage(rng: np.random.Generator, duration_s: float, scale: float = 3.0) -> StepLoad:
    from battery_predictor.profiles.temi import generate_usage_profile

    prof = generate_usage_profile(seed=int(rng.integers(1 << 30)), max_duration_s=duration_s)
    return StepLoad.from_profile(prof).scale_current(scale)


def ranger_jobs(rng: np.random.Generator, duration_s: float) -> StepLoad:
    from battery_predictor.profiles.ranger import route_from_station, route_profile
    from battery_predictor.profiles.station import load_station

    station = load_station()
    places = [n for n in station.nodes if n != "charger"]
    load = None
    while load is None or load.end_s < duration_s:
        pickup, dropoff = rng.choice(places, size=2, replace=False)
        payload = float(rng.choice([20.0, 40.0, 60.0, 80.0]))
        route = route_from_station(station, "charger", str(pickup), str(dropoff), payload)
        part = StepLoad.from_profile(route_profile(route, seed=int(rng.integers(1 << 30))))
        wait = StepLoad.constant(1.70, float(rng.uniform(60.0, 240.0)))  # waiting for the next job
        part = part.append(wait)
        load = part if load is None else load.append(part)
    return load.truncate(duration_s)


def usage(pack: str, rng: np.random.Generator, duration_s: float, heavy: bool = False) -> StepLoad:
    if pack == "temi":
        return temi_usage(rng, duration_s, scale=4.0 if heavy else 3.0)
    return ranger_jobs(rng, duration_s)


# --------------------------------------------------------------------------- truth simulation
@dataclass
class TruthModel:
    """How the observed truth differs from the plain isothermal SPM of ``params``."""

    params: PackParams
    model: str = "SPM"
    options: dict = field(default_factory=dict)
    pv_updates: dict = field(default_factory=dict)
    ambient_k: float = 298.15
    lli: float = 0.0
    liionpack_weak: np.ndarray | None = None  # per-cell electrode height factors (series-groups netlist)


def _prepared_pv(truth: TruthModel):
    import pybamm

    pv = truth.params.parameter_values()
    pv["Upper voltage cut-off [V]"] = 5.0
    pv.update(truth.pv_updates, check_already_exists=False)
    return pv, pybamm


def initial_concentrations(truth: TruthModel, soc: float) -> tuple[float, float]:
    """PyBaMM's initial stoichiometries at ``soc`` of the (possibly faded) truth cell."""
    import pybamm

    pv, _ = _prepared_pv(truth)
    if truth.lli:
        # loss of cyclable lithium: the initial concentrations carry the inventory (PyBaMM derives the
        # SOC window from it); the positive electrode keeps its concentration, the negative loses the rest
        base = truth.params.parameter_values()

        def loading(values, dom):
            return (float(values[f"{dom} electrode active material volume fraction"])
                    * float(values[f"{dom} electrode thickness [m]"]))

        c_n0 = float(base["Initial concentration in negative electrode [mol.m-3]"])
        c_p0 = float(base["Initial concentration in positive electrode [mol.m-3]"])
        li = (loading(base, "Negative") * c_n0 + loading(base, "Positive") * c_p0) * (1 - truth.lli)
        pv["Initial concentration in negative electrode [mol.m-3]"] = (
            (li - loading(pv, "Positive") * c_p0) / loading(pv, "Negative"))
    x, y = pybamm.lithium_ion.get_initial_stoichiometries(soc, pv)
    return (float(x) * float(pv["Maximum concentration in negative electrode [mol.m-3]"]),
            float(y) * float(pv["Maximum concentration in positive electrode [mol.m-3]"]))


def run_truth(truth: TruthModel, load: StepLoad, soc: float, t_out: np.ndarray) -> dict:
    """Simulate the truth pack on ``load`` from ``soc``; pack voltage and cell temperature at ``t_out``."""
    if truth.liionpack_weak is not None:
        return _run_liionpack(truth, load, soc, t_out)
    pv, pybamm = _prepared_pv(truth)
    params = truth.params
    c_n, c_p = initial_concentrations(truth, soc)
    pv["Initial concentration in negative electrode [mol.m-3]"] = c_n
    pv["Initial concentration in positive electrode [mol.m-3]"] = c_p
    pv["Ambient temperature [K]"] = truth.ambient_k
    pv["Initial temperature [K]"] = truth.ambient_k
    edges = load.edges_s()
    knots_t = np.column_stack([edges[:-1], edges[1:] - _EDGE_S]).ravel()
    knots_i = np.repeat(load.current_a / params.parallel, 2)
    pv["Current function [A]"] = pybamm.Interpolant(knots_t, knots_i, pybamm.t, interpolator="linear")
    cls = {"SPM": pybamm.lithium_ion.SPM, "SPMe": pybamm.lithium_ion.SPMe}[truth.model]
    sim = pybamm.Simulation(cls(options=truth.options), parameter_values=pv,
                            solver=pybamm.IDAKLUSolver(rtol=1e-7, atol=1e-9))
    sol = sim.solve(t_eval=[0.0, load.end_s - _EDGE_S])
    t_end = float(sol.t[-1])
    t_eval = np.minimum(t_out + 2 * _EDGE_S, load.end_s - 2 * _EDGE_S)
    keep = t_eval <= t_end
    t_out, t_eval = t_out[keep], t_eval[keep]
    v_cell = np.asarray(sol["Terminal voltage [V]"](t_eval))
    temp = np.asarray(sol["Volume-averaged cell temperature [K]"](t_eval))
    i_pack = load.current_at(t_out)
    p = params.interconnect
    r_eq = equivalent_network_resistance_ohm(params.series, params.parallel, p["r_b_ohm"], p["r_c_ohm"], p["r_t_ohm"])
    return {"t": t_out, "v": params.series * v_cell - i_pack * r_eq, "i": i_pack, "temp": temp,
            "cutoff": "Minimum voltage" in str(sol.termination)}


def _run_liionpack(truth: TruthModel, load: StepLoad, soc: float, t_out: np.ndarray) -> dict:
    import liionpack as lp
    import pybamm

    params = truth.params
    period = float(np.median(np.diff(t_out)))
    stepped = load.resample(period)
    pv, _ = _prepared_pv(truth)
    c_n, c_p = initial_concentrations(truth, soc)
    pv["Initial concentration in negative electrode [mol.m-3]"] = c_n
    pv["Initial concentration in positive electrode [mol.m-3]"] = c_p
    pv["Ambient temperature [K]"] = truth.ambient_k
    pv["Initial temperature [K]"] = truth.ambient_k
    height = float(pv["Electrode height [m]"])
    pv["Electrode height [m]"] = "[input]"
    inputs = {"Electrode height [m]": height * truth.liionpack_weak}
    p = params.interconnect
    netlist = lp.setup_circuit(Np=params.parallel, Ns=params.series, Rb=p["r_b_ohm"], Rc=p["r_c_ohm"],
                               Ri=p["r_i_ohm"], Rt=p["r_t_ohm"], I=float(stepped.current_a[0]),
                               V=float(pv["Lower voltage cut-off [V]"]) + 0.5, configuration="series-groups")
    experiment = pybamm.Experiment(
        [pybamm.step.current(np.column_stack([stepped.start_s, stepped.current_a]), period=period)],
        period=f"{period} seconds")

    def sim_func(parameter_values):
        model = lp.add_events_to_model(pybamm.lithium_ion.SPM())
        return pybamm.Simulation(model=model, parameter_values=parameter_values,
                                 solver=pybamm.CasadiSolver(mode="safe"))

    lp.set_logging_level("ERROR")
    out = lp.solve(netlist=netlist, sim_func=sim_func, parameter_values=pv, experiment=experiment, inputs=inputs,
                   initial_soc=None, nproc=1, manager="casadi")
    t_steps = np.asarray(out["Time [s]"], dtype=float)
    v_pack = np.asarray(out["Pack terminal voltage [V]"], dtype=float)
    cell_v = np.asarray(out["Terminal voltage [V]"], dtype=float)
    n = len(t_steps)
    cut = float(pv["Lower voltage cut-off [V]"])
    if np.any(cell_v[-1] < cut):
        n -= 1
    keep = t_out <= t_steps[n - 1] + 1e-9
    t_out = t_out[keep]
    idx = np.clip(np.searchsorted(t_steps, t_out + 1e-9, side="right") - 1, 0, n - 1)
    return {"t": t_out, "v": v_pack[idx], "i": load.current_at(t_out), "temp": np.full(t_out.size, truth.ambient_k),
            "cutoff": n < len(stepped.start_s)}


# --------------------------------------------------------------------------- recordings
def working_day(truth: TruthModel, pack: str, rng: np.random.Generator, soc0: float, heavy: bool = False) -> dict:
    """Usage until the return threshold, CC charge, usage until the cut-off (one truth run)."""
    dt = _SAMPLE_S[pack]
    cap = float(truth.params.pack_info["nominal_capacity_ah"])
    first = usage(pack, rng, 6 * 3600.0, heavy).resample(dt)
    probe_truth = TruthModel(**{**truth.__dict__, "liionpack_weak": None})
    probe = run_truth(probe_truth, first, soc0, np.arange(0.0, first.end_s, dt))
    below = np.nonzero(probe["v"] <= _STOP[pack])[0]
    t_stop = float(probe["t"][below[0]]) if below.size else float(probe["t"][-1])
    t_stop = max(dt, math.floor(t_stop / dt) * dt)
    charge_s = math.floor(float(rng.uniform(*_CHARGE_MIN[pack])) * 60.0 / dt) * dt
    head = first.truncate(t_stop).append(StepLoad.constant(0.0, 120.0))
    charge = StepLoad.constant(-_CHARGE_C_RATE[pack] * cap, charge_s).resample(dt)
    # the charger stops at the pack's maximum voltage (its CV phase is left out)
    probe = run_truth(probe_truth, head.append(charge), soc0, np.arange(0.0, head.end_s + charge_s, dt))
    full = np.nonzero((probe["t"] > head.end_s) & (probe["v"] >= truth.params.pack_info["max_voltage_v"]))[0]
    if full.size:
        charge_s = max(dt, math.floor((float(probe["t"][full[0]]) - head.end_s) / dt) * dt)
    load = (head.append(StepLoad.constant(-_CHARGE_C_RATE[pack] * cap, charge_s))
            .append(StepLoad.constant(0.0, 120.0))
            .append(usage(pack, rng, 6 * 3600.0, heavy).resample(dt)))
    return run_truth(truth, load, soc0, np.arange(0.0, load.end_s, dt))


def discharge(truth: TruthModel, pack: str, rng: np.random.Generator, soc0: float) -> dict:
    dt = _SAMPLE_S[pack]
    load = usage(pack, rng, 8 * 3600.0).resample(dt)
    return run_truth(truth, load, soc0, np.arange(0.0, load.end_s, dt))


def to_recording(run: dict, pack: str, rng: np.random.Generator, current_bias_a: float = 0.0) -> Recording:
    v = np.round(run["v"] + rng.normal(0.0, _NOISE_V[pack], run["v"].size), 2)
    i = np.round(run["i"] + current_bias_a, 2)
    temp = np.round(run["temp"] + rng.normal(0.0, 0.1, run["temp"].size), 1)
    return Recording(time_s=run["t"], voltage_v=v, current_a=i, temperature_k=temp, source="generated")


# --------------------------------------------------------------------------- scenarios
def perturbed_reference(params: PackParams, rng: np.random.Generator) -> tuple[PackParams, dict]:
    pv = params.parameter_values()
    values = {
        "Electrode height [m]": float(pv["Electrode height [m]"]) * rng.uniform(0.96, 1.04),
        "Positive electrode active material volume fraction":
            float(pv["Positive electrode active material volume fraction"]) + rng.uniform(-0.015, 0.015),
        "r_c_ohm": params.interconnect["r_c_ohm"] * float(np.exp(rng.uniform(np.log(0.8), np.log(1.25)))),
    }
    return params.with_values(values), values


def _draw(rng, lo_hi):
    return float(rng.uniform(*lo_hi))


def observed_truth(cause: str, pack: str, ref: PackParams, rng: np.random.Generator) -> tuple[TruthModel, dict, float]:
    """The observed truth model, its drawn magnitude, and the current sensor bias (A)."""
    rg = EFFECT_RANGES.get(cause, {})
    if cause == "none":
        return TruthModel(ref), {}, 0.0
    if cause == "temperature":
        mag = {k: _draw(rng, v) for k, v in rg.items()}
        pv = ref.parameter_values()
        updates = {}
        for dom, key in (("Negative", "ea_neg_j_mol"), ("Positive", "ea_pos_j_mol")):
            d0, ea = float(pv[f"{dom} particle diffusivity [m2.s-1]"]), mag[key]

            def diffusivity(sto, T, d0=d0, ea=ea):
                import pybamm
                return d0 * pybamm.exp(ea / 8.314462618 * (1 / 298.15 - 1 / T))

            updates[f"{dom} particle diffusivity [m2.s-1]"] = diffusivity
        updates["Total heat transfer coefficient [W.m-2.K-1]"] = mag["h_w_m2k"]
        if "Cell cooling surface area [m2]" not in pv.keys():  # Prada2013 lacks the thermal set
            chen = __import__("pybamm").ParameterValues("Chen2020")
            for k in ("Separator density [kg.m-3]", "Negative current collector thickness [m]",
                      "Positive electrode density [kg.m-3]", "Negative current collector density [kg.m-3]",
                      "Positive electrode specific heat capacity [J.kg-1.K-1]",
                      "Positive current collector conductivity [S.m-1]",
                      "Positive current collector specific heat capacity [J.kg-1.K-1]",
                      "Negative electrode density [kg.m-3]", "Positive current collector density [kg.m-3]",
                      "Separator specific heat capacity [J.kg-1.K-1]", "Positive current collector thickness [m]",
                      "Negative electrode specific heat capacity [J.kg-1.K-1]",
                      "Negative current collector specific heat capacity [J.kg-1.K-1]",
                      "Negative current collector conductivity [S.m-1]"):
                updates[k] = chen[k]
            updates["Cell cooling surface area [m2]"] = math.pi * 0.032 * 0.070 + 2 * math.pi * 0.016 ** 2
        return (TruthModel(ref, options={"thermal": "lumped"}, pv_updates=updates,
                           ambient_k=273.15 + mag["ambient_c"]), mag, 0.0)
    if cause == "capacity_fade":
        mag = {k: _draw(rng, v) for k, v in rg.items()}
        pv = ref.parameter_values()
        updates = {"Negative electrode active material volume fraction":
                   float(pv["Negative electrode active material volume fraction"]) * (1 - mag["lam_neg"]),
                   "Positive electrode active material volume fraction":
                   float(pv["Positive electrode active material volume fraction"]) * (1 - mag["lam_pos"])}
        return TruthModel(ref, pv_updates=updates, lli=mag["lli"]), mag, 0.0
    if cause == "resistance_growth":
        mag = {"contact_resistance_ohm": _draw(rng, rg[f"{pack}_ohm"])}
        return (TruthModel(ref, options={"contact resistance": "true"},
                           pv_updates={"Contact resistance [Ohm]": mag["contact_resistance_ohm"]}), mag, 0.0)
    if cause == "current_offset":
        bias = _draw(rng, rg["abs_a"]) * (1 if rng.random() < 0.5 else -1)
        return TruthModel(ref), {"current_offset_a": bias}, bias
    if cause == "cell_imbalance":
        weak = _draw(rng, rg["weak_cell_fraction"])
        spread = _draw(rng, rg["spread"])
        n = ref.n_cells
        factors = 1.0 + rng.uniform(-spread, spread, n)
        group = int(rng.integers(ref.series))
        idx = np.arange(group, n, ref.series)  # liionpack numbers cells string by string
        factors[idx] = weak * (1.0 + rng.uniform(-0.03, 0.03, idx.size))
        return TruthModel(ref, liionpack_weak=factors), {"weak_group": group, "weak_cell_fraction": weak,
                                                         "spread": spread}, 0.0
    if cause == "electrolyte_transport":
        mag = {k: _draw(rng, v) for k, v in rg.items()}
        pv = ref.parameter_values()
        kappa, diff = pv["Electrolyte conductivity [S.m-1]"], pv["Electrolyte diffusivity [m2.s-1]"]
        s = mag["transport_scale"]

        def scaled(f):
            if callable(f):
                return lambda c_e, T: s * f(c_e, T)
            return s * float(f)

        updates = {"Electrolyte conductivity [S.m-1]": scaled(kappa), "Electrolyte diffusivity [m2.s-1]": scaled(diff)}
        return TruthModel(ref, model="SPMe", pv_updates=updates), mag, 0.0
    if cause == "hysteresis":
        mag = {k: _draw(rng, v) for k, v in rg.items()}
        ocp = ref.parameter_values()["Positive electrode OCP [V]"]
        hw = mag["half_width_v"]
        updates = {"Positive electrode lithiation OCP [V]": lambda sto: ocp(sto) - hw,
                   "Positive electrode delithiation OCP [V]": lambda sto: ocp(sto) + hw,
                   "Positive particle lithiation hysteresis decay rate": mag["decay"],
                   "Positive particle delithiation hysteresis decay rate": mag["decay"],
                   "Initial hysteresis state in positive electrode": 1.0}  # fresh from the charger
        return TruthModel(ref, options={"open-circuit potential": ("single", "Axen")}, pv_updates=updates), mag, 0.0
    raise KeyError(cause)


def make_scenario(cause: str, pack: str, seed: int, out_dir: Path) -> Scenario:
    """Write ``reference.csv`` and ``observed.csv`` for ``cause`` on ``pack`` into ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([seed, CAUSES.index(cause), PACKS.index(pack)])
    params_path = REPO / "params" / f"{pack}.yaml"
    params = load_params(params_path)
    ref, ref_values = perturbed_reference(params, rng)
    ref_run = working_day(TruthModel(ref), pack, rng, soc0=float(rng.uniform(0.85, 0.95)) if pack == "temi"
                          else float(rng.uniform(0.3, 0.35)))
    reference = to_recording(ref_run, pack, rng)
    truth, mag, bias = observed_truth(cause, pack, ref, rng)
    soc0 = float(rng.uniform(0.6, 0.75)) if pack == "temi" else float(rng.uniform(0.2, 0.25))
    obs_run = working_day(truth, pack, rng, soc0, heavy=cause == "electrolyte_transport")
    observed = to_recording(obs_run, pack, rng, current_bias_a=bias)
    ref_csv = save_csv(reference, out_dir / "reference.csv", overwrite=True)
    obs_csv = save_csv(observed, out_dir / "observed.csv", overwrite=True)
    return Scenario(cause=cause, pack=pack, seed=seed, params_path=params_path, reference_csv=ref_csv,
                    observed_csv=obs_csv, magnitude=mag, reference_values=ref_values)
