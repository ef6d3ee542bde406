"""A second hidden-effect generator for the diagnosis, written from scratch (issue #12; test code only).

It shares nothing with :mod:`effect_generator` and the package never imports it. Only PyBaMM, the
shipped params files (read through the normal loader, for the base parameter set and the pack
layout) and CSV files are used; the diagnosis sees nothing but the CSV files.

* **Truth far from the shipped params**: per case the electrode height (x0.7-1.3), both active
  material fractions (x0.85-1.15 each), both particle diffusivities (x0.5-2, log-uniform), the
  initial lithium inventory (x0.95-1.02) and the pack's series resistance (x0.3-3 of the shipped
  interconnect) are drawn, so the reference fit starts far from the truth.
* **Cells**: PyBaMM SPM with a lumped thermal model (self-heating) and Arrhenius particle
  diffusivities (25-45 kJ/mol) on top of the base set's own exchange-current temperature
  dependence; the recording's temperature column is the simulated cell temperature.
* **Working days** of the robot's kind (:func:`working_day`): 6-7 h for temi (standby, driving,
  talking), 5-6 h for the luggage robot (standby, loaded and empty trips), with or without a
  charging stop of 20-40 min in the middle; the day draws 55-80 % of the truth's capacity.
* **Sensors**: 5 s (temi) / 10 s (ranger) samples, white voltage noise (2-5 mV) and quantisation
  (0.01 V, 0.1 A).
* **One effect per observed day** at a magnitude drawn uniformly in :data:`MAGNITUDES`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
ROBOTS = ("temi", "ranger_mini")
EFFECTS = ("temperature", "capacity_fade", "resistance_growth", "current_offset", "cell_imbalance",
           "electrolyte_transport", "hysteresis", "none")
#: Uniform ranges of every effect's magnitude.
MAGNITUDES = {
    "temperature": {"ambient_c": (-2.0, 8.0)},
    "capacity_fade": {"lithium_loss": (0.07, 0.15), "negative_loss": (0.0, 0.05), "positive_loss": (0.0, 0.05)},
    "resistance_growth": {"temi_ohm_per_cell": (0.02, 0.045), "ranger_mini_ohm_per_cell": (0.008, 0.016)},
    "current_offset": {"fraction_of_mean_current": (0.15, 0.3)},
    "cell_imbalance": {"weak_capacity": (0.72, 0.86)},
    "electrolyte_transport": {"transport_factor": (0.35, 0.6)},
    "hysteresis": {"half_width_v": (0.010, 0.022), "decay": (20.0, 60.0)},
}
#: The electrolyte's polarisation needs the temi's rates (the luggage robot stays below ~C/3).
ROBOT_EFFECTS = {"temi": EFFECTS, "ranger_mini": tuple(e for e in EFFECTS if e != "electrolyte_transport")}
GAS_J_MOL_K = 8.314462618
T_REF_K = 298.15
_SAMPLE_S = {"temi": 5.0, "ranger_mini": 10.0}
_EPS_S = 1e-3


@dataclass
class Cell:
    """What the truth simulation needs: PyBaMM values, pack layout and the effect's knobs."""

    robot: str
    values: dict
    series: int
    parallel: int
    r_pack_ohm: float
    ambient_k: float = T_REF_K
    model: str = "SPM"
    options: dict = field(default_factory=dict)
    lithium_scale: float = 1.0
    weak_capacity: float = 1.0
    contact_ohm: float = 0.0
    sensor_offset_a: float = 0.0
    hysteresis: tuple[float, float] | None = None
    capacity_scale: float = 1.0


def _params(robot: str):
    from battery_predictor.params import load_params

    return load_params(REPO / "params" / f"{robot}.yaml")


def far_truth(robot: str, rng: np.random.Generator) -> Cell:
    """A healthy cell and pack drawn far from the shipped params (see the module docstring)."""
    import pybamm

    params = _params(robot)
    pv = params.parameter_values()
    values = {}
    scales = [rng.uniform(0.7, 1.3)]
    values["Electrode height [m]"] = float(pv["Electrode height [m]"]) * scales[0]
    fractions = []
    for key in ("Negative electrode active material volume fraction", "Positive electrode active material volume fraction"):
        values[key] = min(float(pv[key]) * rng.uniform(0.85, 1.15), 0.9)
        fractions.append(values[key] / float(pv[key]))
    for key in ("Negative particle diffusivity [m2.s-1]", "Positive particle diffusivity [m2.s-1]"):
        d = float(pv[key]) * math.exp(rng.uniform(math.log(0.5), math.log(2.0)))
        ea = rng.uniform(25e3, 45e3)
        values[key] = _arrhenius(d, ea)
    chen = pybamm.ParameterValues("Chen2020")  # thermal values a base set lacks (Prada2013)
    for key in chen.keys():
        if key not in pv.keys() and ("thermal" in key or "heat" in key or "density" in key or "collector" in key
                                     or "cooling" in key or "Cell volume" in key):
            values[key] = chen[key]
    ic = params.interconnect
    r_ship = params.series / params.parallel * (ic["r_b_ohm"] + ic["r_c_ohm"]) + ic["r_t_ohm"]
    return Cell(robot=robot, values=values, series=params.series, parallel=params.parallel,
                r_pack_ohm=r_ship * rng.uniform(0.3, 3.0), lithium_scale=rng.uniform(0.95, 1.02),
                options={"thermal": "lumped"}, capacity_scale=scales[0] * min(fractions))


def _arrhenius(d_ref: float, ea: float):
    import pybamm

    def diffusivity(sto, T):
        return d_ref * pybamm.exp(ea / GAS_J_MOL_K * (1.0 / T_REF_K - 1.0 / T))

    return diffusivity


def with_effect(cell: Cell, effect: str, rng: np.random.Generator, mean_current_a: float) -> tuple[Cell, dict]:
    """``cell`` with one effect at a random magnitude; returns the cell and the drawn magnitude."""
    if effect == "none":
        return cell, {}
    ranges = MAGNITUDES[effect]
    if effect == "resistance_growth":
        key = f"{cell.robot}_ohm_per_cell"
        mag = {key: rng.uniform(*ranges[key])}
    else:
        mag = {k: rng.uniform(*r) for k, r in ranges.items()}
    values = dict(cell.values)
    if effect == "temperature":
        return replace(cell, ambient_k=273.15 + mag["ambient_c"]), mag
    if effect == "capacity_fade":
        for key, loss in (("Negative electrode active material volume fraction", mag["negative_loss"]),
                          ("Positive electrode active material volume fraction", mag["positive_loss"])):
            values[key] = values[key] * (1.0 - loss)
        return replace(cell, values=values, lithium_scale=cell.lithium_scale * (1.0 - mag["lithium_loss"])), mag
    if effect == "resistance_growth":
        return replace(cell, contact_ohm=mag[f"{cell.robot}_ohm_per_cell"]), mag
    if effect == "current_offset":
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        offset = sign * mag["fraction_of_mean_current"] * mean_current_a
        return replace(cell, sensor_offset_a=offset), {**mag, "offset_a": offset}
    if effect == "cell_imbalance":
        return replace(cell, weak_capacity=mag["weak_capacity"]), mag
    if effect == "electrolyte_transport":
        base = _params(cell.robot).parameter_values()
        f = mag["transport_factor"]
        for key in ("Electrolyte diffusivity [m2.s-1]", "Electrolyte conductivity [S.m-1]"):
            fn = base[key]
            values[key] = (lambda c, T, fn=fn: f * fn(c, T)) if callable(fn) else f * float(fn)
        return replace(cell, values=values, model="SPMe"), mag
    if effect == "hysteresis":
        return replace(cell, hysteresis=(mag["half_width_v"], mag["decay"])), mag
    raise KeyError(effect)


# ----------------------------------------------------------------------------- loads
def working_day(robot: str, rng: np.random.Generator, capacity_ah: float, charging_stop: bool
                ) -> tuple[np.ndarray, np.ndarray]:
    """Piecewise-constant pack current of one working day: (step start times in s, currents in A).

    temi: standby 0.5-0.8 A, driving 2-4 A, talking 1-1.6 A; ranger: standby 0.6-1 A, empty trips
    2-4 A, loaded trips 4-9 A. Segment lengths 20-600 s; the currents are scaled so that the day's
    discharge draws 55-80 % of ``capacity_ah``; with ``charging_stop`` a 20-40 min charge at 0.3-0.5 C
    sits between 40 and 60 % of the day.
    """
    hours = rng.uniform(6.0, 7.0) if robot == "temi" else rng.uniform(5.0, 6.0)
    kinds = ({"standby": (0.5, 0.8, 0.45), "drive": (2.0, 4.0, 0.25), "talk": (1.0, 1.6, 0.30)} if robot == "temi"
             else {"standby": (0.6, 1.0, 0.45), "empty": (2.0, 4.0, 0.25), "loaded": (4.0, 9.0, 0.30)})
    names = list(kinds)
    probs = np.array([kinds[k][2] for k in names])
    starts, currents, t = [], [], 0.0
    while t < hours * 3600.0:
        k = names[int(rng.choice(len(names), p=probs / probs.sum()))]
        lo, hi, _ = kinds[k]
        dur = float(rng.uniform(20.0, 600.0 if k == "standby" else 300.0))
        starts.append(t)
        currents.append(rng.uniform(lo, hi))
        t += dur
    starts, currents = np.array(starts), np.array(currents)
    durations = np.diff(np.append(starts, t))
    drawn_ah = float(np.sum(currents * durations)) / 3600.0
    currents *= rng.uniform(0.55, 0.8) * capacity_ah / drawn_ah
    if charging_stop:
        k = int(np.searchsorted(starts, rng.uniform(0.4, 0.6) * t))
        charge_s = rng.uniform(20.0, 40.0) * 60.0
        c_rate = rng.uniform(0.3, 0.5)
        starts = np.concatenate([starts[:k], [starts[k]], starts[k:] + charge_s])
        currents = np.concatenate([currents[:k], [-c_rate * capacity_ah], currents[k:]])
        # what was charged is discharged too (the day still ends at 55-80 % of capacity drawn net)
        durations = np.diff(np.append(starts, starts[-1] + durations[-1]))
        extra = c_rate * capacity_ah * charge_s / 3600.0
        dis = currents > 0
        currents[dis] *= 1.0 + extra / (float(np.sum(currents[dis] * durations[dis])) / 3600.0)
    return starts, currents


# ----------------------------------------------------------------------------- simulation
def _solve(cell: Cell, starts: np.ndarray, currents: np.ndarray, end_s: float, soc: float, height_scale: float = 1.0):
    import pybamm

    params = _params(cell.robot)
    pv = params.parameter_values()
    pv.update({k: v for k, v in cell.values.items()}, check_already_exists=False)
    if height_scale != 1.0:
        pv["Electrode height [m]"] = float(pv["Electrode height [m]"]) * height_scale
    x, y = pybamm.lithium_ion.get_initial_stoichiometries(soc, pv)
    c_n_max = float(pv["Maximum concentration in negative electrode [mol.m-3]"])
    c_p_max = float(pv["Maximum concentration in positive electrode [mol.m-3]"])
    if cell.lithium_scale != 1.0:  # the lithium lost comes out of the negative electrode at this SOC
        eps_l = {e: float(pv[f"{e.capitalize()} electrode active material volume fraction"])
                 * float(pv[f"{e.capitalize()} electrode thickness [m]"]) for e in ("negative", "positive")}
        li = eps_l["negative"] * float(x) * c_n_max + eps_l["positive"] * float(y) * c_p_max
        x = (li * cell.lithium_scale - eps_l["positive"] * float(y) * c_p_max) / (eps_l["negative"] * c_n_max)
    pv["Initial concentration in negative electrode [mol.m-3]"] = float(x) * c_n_max
    pv["Initial concentration in positive electrode [mol.m-3]"] = float(y) * c_p_max
    pv["Ambient temperature [K]"] = cell.ambient_k
    pv["Initial temperature [K]"] = cell.ambient_k
    options = dict(cell.options)
    if cell.contact_ohm:
        options["contact resistance"] = "true"
        pv.update({"Contact resistance [Ohm]": cell.contact_ohm}, check_already_exists=False)
    if cell.hysteresis is not None:
        half, decay = cell.hysteresis
        ocp = pv["Positive electrode OCP [V]"]
        options["open-circuit potential"] = ("single", "Axen")
        pv.update({"Positive electrode lithiation OCP [V]": lambda sto: ocp(sto) - half,
                   "Positive electrode delithiation OCP [V]": lambda sto: ocp(sto) + half,
                   "Positive particle lithiation hysteresis decay rate": decay,
                   "Positive particle delithiation hysteresis decay rate": decay,
                   "Initial hysteresis state in positive electrode": 1.0}, check_already_exists=False)
    ends = np.append(starts[1:], end_s)
    knots_t = np.column_stack([starts, ends - _EPS_S]).ravel()
    knots_i = np.repeat(currents / cell.parallel, 2)
    pv["Current function [A]"] = pybamm.Interpolant(knots_t, knots_i, pybamm.t, interpolator="linear")
    model = {"SPM": pybamm.lithium_ion.SPM, "SPMe": pybamm.lithium_ion.SPMe}[cell.model](options=options)
    sim = pybamm.Simulation(model, parameter_values=pv, solver=pybamm.IDAKLUSolver(rtol=1e-6, atol=1e-8))
    return sim.solve(t_eval=[0.0, end_s - 2 * _EPS_S])


def record(cell: Cell, starts: np.ndarray, currents: np.ndarray, soc: float, rng: np.random.Generator,
           path: Path) -> Path:
    """Simulate ``cell`` on the day, sample it like the robot's monitor and write the CSV (current > 0 = discharge)."""
    end_s = float(starts[-1]) + 300.0
    sample = _SAMPLE_S[cell.robot]
    sols = [_solve(cell, starts, currents, end_s, soc)]
    if cell.weak_capacity != 1.0:
        sols.append(_solve(cell, starts, currents, end_s, soc, height_scale=cell.weak_capacity))
    t_end = min(float(s.t[-1]) for s in sols)
    t = np.arange(0.0, t_end - 2 * _EPS_S, sample)
    i_pack = currents[np.searchsorted(starts, t, side="right") - 1]
    cells = [np.asarray(s["Terminal voltage [V]"](t + 2 * _EPS_S), dtype=float) for s in sols]
    v = (cell.series - len(cells) + 1) * cells[0] + (cells[1] if len(cells) > 1 else 0.0) - i_pack * cell.r_pack_ohm
    temp = np.asarray(sols[0]["Volume-averaged cell temperature [K]"](t + 2 * _EPS_S), dtype=float)
    noise = rng.uniform(0.002, 0.005)
    v_meas = np.round(v + rng.normal(0.0, noise, t.size), 2)
    i_meas = np.round(i_pack + cell.sensor_offset_a, 1)
    rows = ["time_s,voltage_V,current_A,temperature_C"]
    rows += [f"{a:.1f},{b:.2f},{c:.1f},{d - 273.15:.2f}" for a, b, c, d in zip(t, v_meas, i_meas, temp)]
    path.write_text("\n".join(rows) + "\n")
    return path


@dataclass(frozen=True)
class Case:
    """One generated case: files for ``diagnose`` and what was hidden."""

    effect: str
    robot: str
    seed: int
    params_path: Path
    reference_csv: Path
    observed_csv: Path
    magnitude: dict
    charging_stop: bool


def make_case(effect: str, robot: str, seed: int, out_dir: Path) -> Case:
    """Reference day (healthy truth) and observed day (the truth with ``effect``) of ``robot``."""
    rng = np.random.default_rng([12, EFFECTS.index(effect), ROBOTS.index(robot), seed])
    truth = far_truth(robot, rng)
    params = _params(robot)
    capacity = float(params.pack_info["nominal_capacity_ah"]) * truth.capacity_scale
    ref_day = working_day(robot, rng, capacity, charging_stop=bool(rng.uniform() < 0.5))
    charging_stop = bool(rng.uniform() < 0.5)
    obs_day = working_day(robot, rng, capacity, charging_stop=charging_stop)
    discharging = obs_day[1] > 0
    mean_a = float(np.mean(obs_day[1][discharging]))
    observed, magnitude = with_effect(truth, effect, rng, mean_a)
    out_dir.mkdir(parents=True, exist_ok=True)
    ref = record(truth, *ref_day, soc=rng.uniform(0.93, 1.0), rng=rng, path=out_dir / "reference.csv")
    obs = record(observed, *obs_day, soc=rng.uniform(0.93, 1.0), rng=rng, path=out_dir / "observed.csv")
    return Case(effect, robot, seed, REPO / "params" / f"{robot}.yaml", ref, obs, magnitude, charging_stop)
