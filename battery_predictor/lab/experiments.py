"""The catalogue of emulated lab experiments and the deterministic generation of the shipped bags.

Every bag in ``bags/`` is produced here (``battery-predictor lab make-bags
--out bags``): a seeded load profile drives a seeded
:class:`~battery_predictor.lab.real_pack.RealPack` (liionpack, every cell),
the :mod:`~battery_predictor.lab.instruments` turn the noise-free trace into
10 Hz quantised samples averaged into 5 s windows, and the result is written
with :func:`~battery_predictor.io.bags.write_recording_bag` together with its
ground truth in the bag metadata. Nothing is measured; the same code and
versions give bit-identical data.

Experiments (seed paper sections 5.1.4, 5.1.6, 5.2.2, 5.2.4)
-------------------------------------------------------------
Information robot (Temi, ``params/temi.yaml``, topic style ``relay``):

* ``temi_static_0p5c_pack1``: constant 0.5 C (7.35 A) until 12.00 V.
* ``temi_dynamic_pack{1..4}``: stochastic usage profiles (one seed each)
  until 13.30 V on four different physical packs; the truth is the time
  until 13.30 V was measured (the remaining-runtime target of 5.1.6).

Luggage robot (Ranger Mini, ``params/ranger_mini.yaml``, style ``battery_state``):

* ``ranger_stepwise_pack1``: 0.5, 1, 2, ..., 8 A for 10 min each, repeated,
  until 45.00 V (5.2.2).
* ``ranger_route_{20,40,60,80}kg_pack{1,2,3}``: the longest route played
  twice in succession from a start SOC chosen so that the voltage at 1.70 A
  after the second cycle (its final 60 s standstill) is just above 46.31 V
  (5.2.4). The start SOC is found by bisection on a cheap model (the fast
  single-cell simulator with the real pack's mean cell) and then verified
  (and, if needed, corrected) with the real pack. A third cycle is simulated
  too (not recorded) to say whether a further cycle would have been
  feasible.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from battery_predictor import __version__
from battery_predictor.errors import BatteryPredictorError, SimulationError
from battery_predictor.jsonutil import json_default as _json_default
from battery_predictor.lab import LAB_VERSION
from battery_predictor.lab.instruments import InstrumentSpec, measure
from battery_predictor.lab.real_pack import SURFACE_18650_M2, SURFACE_32700_M2, RealPack, RealPackSpec
from battery_predictor.processes import ProcessPool
from battery_predictor.simulation.load import StepLoad

if TYPE_CHECKING:
    from battery_predictor.lab.real_pack import PackTrace
    from battery_predictor.params import PackParams
    from battery_predictor.profiles.load_profile import LoadProfile
    from battery_predictor.profiles.ranger import RangerCurrents, Route
    from battery_predictor.recording import Recording

#: liionpack step period of the real pack in s (= the averaging window, so windows and steps align).
PERIOD_S = 5.0
#: Voltage at 1.70 A after the last route cycle must not fall below this (paper 5.2, 5.2.4).
ROUTE_THRESHOLD_V = 46.31
#: The start SOC search aims at this much above the threshold after the second cycle ...
ROUTE_AIM_MARGIN_V = 0.10
#: ... and accepts a real-pack result within this band above the threshold.
ROUTE_ACCEPT_BAND_V = (0.03, 0.25)
#: Real-pack verification runs of the start SOC search at most.
ROUTE_MAX_ITERATIONS = 4
#: Bisection tolerance on the cheap model's end voltage in V.
BISECTION_TOL_V = 0.003
#: The real pack is simulated until a step voltage is this far below an experiment's end voltage (V).
STOP_MARGIN_V = 0.02
#: Largest bag the catalogue may produce (bytes).
MAX_BAG_BYTES = 2_000_000

TEMI = "temi"
RANGER = "ranger_mini"


@dataclass(frozen=True)
class ExperimentSpec:
    """One emulated experiment (one bag).

    Attributes
    ----------
    name : str
        Bag directory name.
    robot : str
        ``"temi"`` or ``"ranger_mini"`` (also the params file stem).
    kind : str
        ``"static"``, ``"dynamic"``, ``"stepwise"`` or ``"route"``.
    pack : int
        Physical pack number (1 = the pack used for model development).
    instrument_seed : int
        Seed of the instrument noise.
    ambient_temperature_k : float
        Lab temperature in K.
    profile_seed : int or None
        Seed of the stochastic profile (dynamic and route experiments).
    payload_kg : float or None
        Route payload in kg.
    """

    name: str
    robot: str
    kind: str
    pack: int
    instrument_seed: int
    ambient_temperature_k: float = 296.15
    profile_seed: int | None = None
    payload_kg: float | None = None

    @property
    def style(self) -> str:
        """Bag topic style of the robot."""
        return "relay" if self.robot == TEMI else "battery_state"

    @property
    def pack_id(self) -> str:
        """Physical pack name."""
        return f"{self.robot}_pack{self.pack}"

    def cost(self) -> float:
        """Rough relative cost (for scheduling the slow ones first)."""
        return {"static": 1.0, "dynamic": 3.0, "stepwise": 5.0, "route": 3.5}[self.kind]


#: Physical packs: (seed, pack-level capacity factor, mean contact resistance in Ohm).
_TEMI_PACKS = {1: (1001, 1.000, 0.0030), 2: (1002, 0.985, 0.0040), 3: (1003, 1.015, 0.0025), 4: (1004, 0.970, 0.0050)}
_RANGER_PACKS = {1: (2001, 1.000, 0.0020), 2: (2002, 0.980, 0.0025), 3: (2003, 1.020, 0.0015)}


def pack_spec(robot: str, pack: int) -> RealPackSpec:
    """The :class:`RealPackSpec` of physical pack ``pack`` of ``robot``."""
    if robot == TEMI:
        seed, factor, contact = _TEMI_PACKS[pack]
        return RealPackSpec(pack_id=f"{robot}_pack{pack}", seed=seed, pack_capacity_factor=factor,
                            contact_resistance_mean_ohm=contact, contact_resistance_sigma_ohm=0.0015,
                            cooling_surface_area_m2=SURFACE_18650_M2)
    if robot == RANGER:
        seed, factor, contact = _RANGER_PACKS[pack]
        return RealPackSpec(pack_id=f"{robot}_pack{pack}", seed=seed, pack_capacity_factor=factor,
                            contact_resistance_mean_ohm=contact, contact_resistance_sigma_ohm=0.0010,
                            cooling_surface_area_m2=SURFACE_32700_M2)
    raise BatteryPredictorError(f"lab: unknown robot {robot!r}")


def catalogue() -> list[ExperimentSpec]:
    """Every shipped experiment, in a fixed order."""
    out = [ExperimentSpec("temi_static_0p5c_pack1", TEMI, "static", 1, instrument_seed=11, ambient_temperature_k=296.65)]
    for pack, ambient in zip((1, 2, 3, 4), (296.15, 297.15, 295.65, 298.15)):
        out.append(ExperimentSpec(f"temi_dynamic_pack{pack}", TEMI, "dynamic", pack, instrument_seed=20 + pack,
                                  ambient_temperature_k=ambient, profile_seed=100 + pack))
    out.append(ExperimentSpec("ranger_stepwise_pack1", RANGER, "stepwise", 1, instrument_seed=31,
                              ambient_temperature_k=296.15))
    for pack, ambient in zip((1, 2, 3), (296.15, 297.15, 295.65)):
        for payload in (20, 40, 60, 80):
            out.append(ExperimentSpec(f"ranger_route_{payload}kg_pack{pack}", RANGER, "route", pack,
                                      instrument_seed=400 + 10 * pack + payload // 20, ambient_temperature_k=ambient,
                                      profile_seed=200 + 10 * pack + payload // 20, payload_kg=float(payload)))
    return out


def find_experiments(names: Iterable[str] | None) -> list[ExperimentSpec]:
    """The catalogue entries named in ``names`` (all when None); an unknown name raises."""
    cat = catalogue()
    if not names:
        return cat
    by_name = {e.name: e for e in cat}
    out = []
    for name in names:
        if name not in by_name:
            raise BatteryPredictorError(f"lab: unknown experiment {name!r} (known: {', '.join(by_name)})")
        out.append(by_name[name])
    return out


def load_robot_params(robot: str, params_dir: str | Path | None = None) -> PackParams:
    """The params file of ``robot`` (``params/<robot>.yaml``)."""
    from battery_predictor.config import default_params_file
    from battery_predictor.params import load_params

    path = Path(params_dir) / f"{robot}.yaml" if params_dir else default_params_file(f"{robot}.yaml")
    return load_params(path)


# ---------------------------------------------------------------------------
# Helpers shared with the tests
# ---------------------------------------------------------------------------


def standstill_voltage_v(time_s: npt.ArrayLike, voltage_v: npt.ArrayLike, cycle_end_s: float, standstill_s: float = 60.0,
                         window_s: float = PERIOD_S) -> float:
    """Mean voltage (V) over the samples whose 5 s window lies within the standstill ending at ``cycle_end_s``.

    This is "the voltage at 1.70 A after the cycle": the route's final curve
    point is a ``standstill_s`` standstill at 1.70 A.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_v, dtype=float)
    keep = (t >= cycle_end_s - standstill_s - 1e-6) & (t + window_s <= cycle_end_s + 1e-6)
    if not keep.any():
        raise SimulationError(f"no sample within the standstill {cycle_end_s - standstill_s:.0f}-{cycle_end_s:.0f} s")
    return float(np.mean(v[keep]))


def bisect_initial_soc(end_voltage: Callable[[float], float], target_v: float, *, low: float = 0.0,
                       high: float = 1.0, tol_v: float = BISECTION_TOL_V, min_width: float = 1e-5,
                       max_evaluations: int = 60) -> tuple[float, float, int]:
    """Smallest start SOC whose end voltage is at or just above ``target_v`` (bisection).

    Parameters
    ----------
    end_voltage : callable
        ``soc -> voltage`` (V), non-decreasing in the SOC; ``-inf`` for runs
        that end at a cut-off.
    target_v : float
        Voltage to reach.
    low, high : float
        SOC bracket.
    tol_v : float
        Stop once the upper bracket's voltage is within ``tol_v`` above the target.
    min_width : float
        ... or the bracket is narrower than this.

    Returns
    -------
    soc : float
        Upper end of the final bracket (its voltage is >= ``target_v``).
    voltage : float
        ``end_voltage(soc)``.
    evaluations : int
        Number of ``end_voltage`` calls.

    Raises
    ------
    SimulationError
        When ``high`` does not reach the target.
    """
    v_high = end_voltage(high)
    n = 1
    if not v_high >= target_v:
        raise SimulationError(f"start SOC {high:.3f} ends at {v_high:.3f} V, below the target {target_v:.3f} V")
    v_low = end_voltage(low)
    n += 1
    if v_low >= target_v:
        return low, v_low, n
    while n < max_evaluations and (v_high - target_v) > tol_v and (high - low) > min_width:
        mid = 0.5 * (low + high)
        v_mid = end_voltage(mid)
        n += 1
        if v_mid >= target_v:
            high, v_high = mid, v_mid
        else:
            low = mid
    return high, v_high, n




def _profile_record(profile: LoadProfile, end_s: float | None = None) -> dict[str, Any]:
    """The curve points actually applied (up to ``end_s``), for the bag metadata."""
    d = np.asarray(profile.duration_s, dtype=float)
    c = np.asarray(profile.current_a, dtype=float)
    assert profile.labels is not None  # LoadProfile fills in the labels it was not given
    labels = list(profile.labels)
    if end_s is not None:
        starts = np.concatenate([[0.0], np.cumsum(d)[:-1]])
        keep = starts < end_s
        d, c, labels = d[keep].copy(), c[keep], [lab for lab, k in zip(labels, keep) if k]
        d[-1] = min(d[-1], end_s - starts[keep][-1])
    meta = {}
    for key, value in profile.metadata.items():
        try:
            json.dumps(value, default=_json_default)
        except (TypeError, ValueError):
            value = repr(value)
        meta[str(key)] = value
    return {
        "n_points": len(d),
        "duration_s": float(d.sum()),
        "charge_ah": float(np.sum(d * c) / 3600.0),
        "metadata": meta,
        "curve_points": {
            "duration_s": [float(f"{x:.6g}") for x in d],
            "current_a": [float(f"{x:.6g}") for x in c],
            "label": labels,
        },
    }


def _base_metadata(exp: ExperimentSpec, pack: RealPack, instruments: InstrumentSpec) -> dict[str, Any]:
    return {
        "emulated": True,
        "generator": "battery_predictor.lab",
        "generator_version": {"battery_predictor": __version__, "lab": LAB_VERSION},
        "lab_version": LAB_VERSION,
        "experiment": exp.name,
        "robot": exp.robot,
        "kind": exp.kind,
        "pack_id": exp.pack_id,
        "pack_number": exp.pack,
        "profile_seed": exp.profile_seed,
        "instrument_seed": exp.instrument_seed,
        "ambient_temperature_k": exp.ambient_temperature_k,
        "real_pack": pack.describe(),
        "instruments": instruments.to_dict(),
        "simulation_period_s": PERIOD_S,
    }


def _thermal_summary(trace: PackTrace, end_s: float) -> dict[str, float]:
    keep = trace.time_s < end_s
    return {
        "ambient_temperature_k": trace.ambient_temperature_k,
        "final_mean_cell_temperature_k": float(trace.temperature_k[keep][-1]),
        "max_cell_temperature_k": float(trace.cell_temperature_k[keep].max()),
    }


# ---------------------------------------------------------------------------
# Experiments
# ---------------------------------------------------------------------------


def _run_to_stop_voltage(exp: ExperimentSpec, pack: RealPack, profile: LoadProfile, stop_v: float,
                         instruments: InstrumentSpec, initial_state: str) -> tuple[Recording, dict[str, Any]]:
    """Discharge until ``stop_v`` is measured; returns the recording and metadata."""
    load = StepLoad.from_profile(profile)
    # the simulation runs until a step voltage is STOP_MARGIN_V below the end voltage (plus one step), so the
    # first 5 s window whose mean reaches the end voltage is always simulated
    trace = pack.simulate(load, ambient_temperature_k=exp.ambient_temperature_k,
                          stop_pack_voltage_v=stop_v - STOP_MARGIN_V, stop_extra_steps=2, period_s=PERIOD_S)
    m = measure(trace, instruments, seed=exp.instrument_seed, stop_voltage_v=stop_v, source=exp.name)
    if not m.stopped or m.stop_time_s is None:
        raise SimulationError(f"{exp.name}: the real pack never reached {stop_v:.2f} V "
                              f"(simulation ended by {trace.termination} at {trace.end_s:.0f} s)")
    runtime = float(m.stop_time_s)
    rec = m.recording
    meta = {
        "stop_voltage_v": stop_v,
        "initial_state": initial_state,
        "profile": _profile_record(profile, m.acquisition_end_s),
        "truth": {
            "stop_voltage_v": stop_v,
            "runtime_s": runtime,
            "acquisition_end_s": m.acquisition_end_s,
            "runtime_noise_free_s": trace.time_to_voltage_s(stop_v),
            "charge_drawn_ah": float(load.cumulative_charge_as(runtime) / 3600.0),
            "end_voltage_measured_v": float(rec.voltage_v[-1]),
            "min_voltage_10hz_v": float(m.raw.voltage_v.min()),
            **_thermal_summary(trace, m.acquisition_end_s),
            "simulation_termination": trace.termination,
        },
        "_seconds": trace.seconds,
    }
    return rec, meta


def run_static(exp: ExperimentSpec, pack: RealPack, instruments: InstrumentSpec) -> tuple[Recording, dict[str, Any]]:
    """Temi static discharge at 0.5 C until 12.00 V (5.1.4)."""
    from battery_predictor.profiles import constant_current_profile

    params = pack.base_params
    current = 0.5 * float(params.pack_info["nominal_capacity_ah"])
    stop_v = float(params.thresholds.get("static_discharge_end_voltage_v", 12.0))
    profile = constant_current_profile(current, 8 * 3600.0, label="0.5C")
    return _run_to_stop_voltage(exp, pack, profile, stop_v, instruments, "params initial concentrations (charged)")


def run_dynamic(exp: ExperimentSpec, pack: RealPack, instruments: InstrumentSpec) -> tuple[Recording, dict[str, Any]]:
    """Temi usage profile until 13.30 V (5.1.4, 5.1.6)."""
    from battery_predictor.profiles import generate_usage_profile, load_usage_config

    config = load_usage_config()
    stop_v = float(pack.base_params.thresholds.get("runtime_cutoff_voltage_v", config.stop_voltage_v))
    profile = generate_usage_profile(config, exp.profile_seed, max_duration_s=16 * 3600.0)
    return _run_to_stop_voltage(exp, pack, profile, stop_v, instruments, "params initial concentrations (charged)")


def run_stepwise(exp: ExperimentSpec, pack: RealPack,
                 instruments: InstrumentSpec) -> tuple[Recording, dict[str, Any]]:
    """Ranger stepwise experiment until 45.00 V (5.2.2)."""
    from battery_predictor.profiles import stepwise_profile

    stop_v = float(pack.base_params.thresholds.get("terminal_voltage_v", 45.0))
    one_pass = stepwise_profile(stop_voltage_v=stop_v)
    return _run_to_stop_voltage(exp, pack, one_pass.repeat(8), stop_v, instruments,
                                "params initial concentrations (charged)")


@dataclass(frozen=True)
class _RouteCycle:
    """The route experiment's load: the longest route at a payload and its standstill, cycled."""

    route: Route
    currents: RangerCurrents
    cycle: LoadProfile
    threshold_v: float
    standstill_s: float
    period_s: float
    two: StepLoad
    three: StepLoad
    ends: list[float]


@dataclass
class _RouteSearch:
    """The start SOC found for the route experiment, and the real-pack run from it."""

    soc: float
    trace: PackTrace
    v_real: list[float]
    iterations: list[dict[str, Any]]
    seconds: float
    aim_v: float


def _route_cycle(exp: ExperimentSpec, pack: RealPack) -> _RouteCycle:
    from battery_predictor.profiles import load_ranger_currents, longest_route, route_profile

    threshold = float(pack.base_params.thresholds.get("route_min_voltage_v", ROUTE_THRESHOLD_V))
    currents = load_ranger_currents()
    if exp.payload_kg is None:
        raise SimulationError(f"{exp.name}: a route experiment needs a payload_kg")
    route = longest_route(exp.payload_kg)
    cycle = route_profile(route, currents, seed=exp.profile_seed, mode="sampled")
    if cycle.point_labels[-1] != "standstill":
        raise SimulationError(f"{exp.name}: the route profile does not end with a standstill")
    period = cycle.total_duration_s
    return _RouteCycle(route, currents, cycle, threshold, float(cycle.duration_s[-1]), period,
                       StepLoad.from_profile(cycle.repeat(2)), StepLoad.from_profile(cycle.repeat(3)),
                       [period * k for k in (1, 2, 3)])


def _cheap_voltage_after_two_cycles(exp: ExperimentSpec, pack: RealPack, rc: _RouteCycle) -> Callable[[float], float]:
    """Standstill voltage after the second cycle from a start SOC, on the fast simulator with the mean cell."""
    from battery_predictor.simulation.base import SimulationRequest
    from battery_predictor.simulation.fast import FastPackSimulator

    cheap = FastPackSimulator()
    cheap_params = pack.mean_params()
    grid = np.arange(0.0, rc.two.end_s - 1e-6, PERIOD_S)

    def cheap_v2(soc: float) -> float:
        try:
            res = cheap.simulate(cheap_params, SimulationRequest(load=rc.two, ambient_temperature_k=exp.ambient_temperature_k,
                                                                 initial_soc=soc, output_time_s=grid))
        except SimulationError:
            return -math.inf
        if res.reached_cutoff or len(res.time_s) < len(grid):
            return -math.inf
        return standstill_voltage_v(res.time_s, res.pack_voltage_v, rc.ends[1], rc.standstill_s)

    return cheap_v2


def _search_route_soc(exp: ExperimentSpec, pack: RealPack, rc: _RouteCycle) -> _RouteSearch:
    """Bisect the start SOC on the fast simulator, verify on the real pack, shift the target until it lands."""
    cheap_v2 = _cheap_voltage_after_two_cycles(exp, pack, rc)
    aim = rc.threshold_v + ROUTE_AIM_MARGIN_V
    target = aim
    iterations = []
    seconds = 0.0
    v_real = [math.nan, math.nan, math.nan]
    for _ in range(ROUTE_MAX_ITERATIONS):
        soc, v_cheap, n_eval = bisect_initial_soc(cheap_v2, target, low=0.0, high=1.0)
        trace = pack.simulate(rc.three, initial_soc=soc, ambient_temperature_k=exp.ambient_temperature_k,
                              period_s=PERIOD_S)
        seconds += trace.seconds
        v_real = []
        for end in rc.ends:
            try:
                v_real.append(trace.mean_voltage_v(end - rc.standstill_s, end))
            except SimulationError:
                v_real.append(math.nan)
        iterations.append({"cheap_target_v": target, "start_soc": soc, "cheap_v_after_cycle2": v_cheap,
                           "cheap_evaluations": n_eval, "real_v_after_cycle2": v_real[1]})
        if not math.isfinite(v_real[1]):
            raise SimulationError(f"{exp.name}: the real pack did not complete two cycles from SOC {soc:.4f}")
        if rc.threshold_v + ROUTE_ACCEPT_BAND_V[0] <= v_real[1] <= rc.threshold_v + ROUTE_ACCEPT_BAND_V[1]:
            return _RouteSearch(soc, trace, v_real, iterations, seconds, aim)
        target += aim - v_real[1]
    raise SimulationError(f"{exp.name}: no start SOC within {ROUTE_MAX_ITERATIONS} real-pack runs "
                          f"(last: {v_real[1]:.3f} V after cycle 2)")


def _route_truth(rc: _RouteCycle, found: _RouteSearch, v_meas: list[float]) -> dict[str, Any]:
    """The route experiment's ``truth`` metadata."""
    threshold, trace, ends, v_real = rc.threshold_v, found.trace, rc.ends, found.v_real
    third_done = bool(trace.time_s[-1] + trace.period_s >= ends[2] - 1e-6)
    further_ok = bool(third_done and math.isfinite(v_real[2]) and v_real[2] >= threshold)
    return {
        "threshold_v": threshold,
        "standstill_current_a": float(rc.currents.standstill_current_a),
        "standstill_s": rc.standstill_s,
        "cycle_duration_s": rc.period_s,
        "cycles": 2,
        "start_soc": found.soc,
        "voltage_at_1_70_a_after_cycle_v": v_meas,
        "voltage_at_1_70_a_after_cycle_noise_free_v": [None if not math.isfinite(x) else x for x in v_real],
        "second_cycle_ends_above_threshold": bool(v_meas[1] >= threshold),
        "further_cycle_completed": third_done,
        "further_cycle_stays_above_threshold": further_ok,
        "min_voltage_in_further_cycle_v": float(trace.voltage_v[trace.time_s >= ends[1] - 1e-6].min())
        if np.any(trace.time_s >= ends[1] - 1e-6) else None,
        **_thermal_summary(trace, ends[1]),
        "soc_search": {
            "method": "bisection on the fast single-cell simulator with the real pack's mean cell, "
                      "verified (and the target shifted) with the real pack",
            "aim_v": found.aim_v,
            "accept_band_v": [threshold + ROUTE_ACCEPT_BAND_V[0], threshold + ROUTE_ACCEPT_BAND_V[1]],
            "iterations": found.iterations,
        },
    }


def run_route(exp: ExperimentSpec, pack: RealPack, instruments: InstrumentSpec) -> tuple[Recording, dict[str, Any]]:
    """Ranger longest route twice in succession, ending just above 46.31 V at 1.70 A (5.2.4)."""
    rc = _route_cycle(exp, pack)
    found = _search_route_soc(exp, pack, rc)
    rec = measure(found.trace, instruments, seed=exp.instrument_seed, end_s=rc.ends[1], source=exp.name).recording
    v_meas = [standstill_voltage_v(rec.time_s, rec.voltage_v, end, rc.standstill_s) for end in rc.ends[:2]]
    route = rc.route
    meta = {
        "payload_kg": exp.payload_kg,
        "initial_state": "start_soc",
        "route": {
            "name": route.name,
            "payload_kg": exp.payload_kg,
            "length_m": route.length_m,
            "duration_s": route.duration_s,
            "sections": [dataclasses.asdict(s) for s in route.sections],
        },
        "profile": {**_profile_record(rc.cycle), "cycles_recorded": 2, "repeated_identically": True},
        "truth": _route_truth(rc, found, v_meas),
        "_seconds": found.seconds,
    }
    return rec, meta


_RUNNERS = {"static": run_static, "dynamic": run_dynamic, "stepwise": run_stepwise, "route": run_route}


def run_experiment(exp: ExperimentSpec, out_dir: str | Path, *, params_dir: str | Path | None = None,
                   overwrite: bool = True, instruments: InstrumentSpec | None = None) -> dict[str, Any]:
    """Run one experiment and write its bag to ``out_dir / exp.name``; returns a summary."""
    from battery_predictor.io.bags import write_recording_bag

    tic = time.perf_counter()
    instruments = instruments or InstrumentSpec()
    pack = RealPack(load_robot_params(exp.robot, params_dir), pack_spec(exp.robot, exp.pack))
    rec, meta = _RUNNERS[exp.kind](exp, pack, instruments)
    sim_seconds = meta.pop("_seconds", 0.0)
    metadata = {**_base_metadata(exp, pack, instruments), **meta}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = write_recording_bag(rec, out / exp.name, style=exp.style, metadata=metadata, overwrite=overwrite)
    size = sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
    if size > MAX_BAG_BYTES:
        raise BatteryPredictorError(f"{path}: {size} bytes, above the {MAX_BAG_BYTES} byte limit")
    return {
        "name": exp.name,
        "path": str(path),
        "bytes": size,
        "samples": len(rec.time_s),
        "duration_s": rec.duration_s,
        "seconds": time.perf_counter() - tic,
        "simulation_seconds": sim_seconds,
        "truth": metadata["truth"],
    }


def _run_one(args: tuple[ExperimentSpec, str, str | None]) -> dict[str, Any]:
    exp, out_dir, params_dir = args
    return run_experiment(exp, out_dir, params_dir=params_dir)


def make_bags(out_dir: str | Path, only: Sequence[str] | None = None, *, jobs: int = 1,
              params_dir: str | Path | None = None, progress: Callable[[dict[str, Any]], None] | None = None
              ) -> list[dict[str, Any]]:
    """Regenerate the catalogue's bags (or ``only`` those named) into ``out_dir``.

    ``jobs`` > 1 runs experiments in that many worker processes (each
    experiment is independent and seeded, so the result does not depend on
    ``jobs``). Returns the per-bag summaries in catalogue order.
    """
    exps = find_experiments(only)
    args = [(e, str(out_dir), None if params_dir is None else str(params_dir)) for e in exps]
    results: dict[str, dict[str, Any]] = {}
    workers = jobs if len(exps) > 1 else 1
    # several workers: the costliest experiments first, so that the workers finish together
    order = sorted(args, key=lambda a: -a[0].cost()) if workers > 1 else args
    with ProcessPool(workers, start_method="spawn") as pool:
        for res in pool.imap_unordered(_run_one, order):
            results[res["name"]] = res
            if progress:
                progress(res)
    return [results[e.name] for e in exps]
