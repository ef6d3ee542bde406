"""A fit problem: recordings, a pack model and a simulator, scored with R2_mod."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from battery_predictor.errors import InputDataError, SimulationError
from battery_predictor.fitting.cost import r2_mod, rmse_v
from battery_predictor.fitting.identifiable import FULL_OCV_MARGIN_V, highest_start_ocv_v
from battery_predictor.params import PackParams
from battery_predictor.recording import DROPPED_TAIL_S_KEY, Recording, discharge_threshold_a
from battery_predictor.simulation.base import PackSimResult, PackSimulator, SimulationRequest
from battery_predictor.simulation.extensions import current_offset_a
from battery_predictor.simulation.load import StepLoad

#: The padding past a recording's end continues the mean current of its last this many seconds (s).
END_LOAD_WINDOW_S = 60.0
#: Below this |current| / nominal capacity (1/h) a recording is taken to start at rest.
_REST_C_RATE = 0.02
#: A recording that starts at rest gives its open-circuit voltage as the mean of its rest samples within this
#: many seconds of its start (s): one sample carries the sensor's noise and quantisation whole.
REST_AVERAGE_S = 60.0
#: A charge held this long (s) ends a recording's discharge (:func:`trim_to_discharge`); regenerative braking
#: (the Panasonic drive cycles: at most about 15 s) and charging blips are shorter.
CHARGE_SESSION_S = 60.0


def trim_to_discharge(rec: Recording) -> Recording:
    """The recording up to the end of the discharge that holds its minimum voltage.

    That discharge runs on after the minimum until the first charge held for :data:`CHARGE_SESSION_S` (a
    recharge; regenerative pulses are shorter) or the recording's end, and ends at its last discharging sample:
    the rests and recharges after it are dropped, since the model is terminated at the cut-off as the
    experiment was. A bursty drive cycle's lowest voltage can come minutes before its end: the 25 degC US06
    of the shared Panasonic data reaches it in a 17 A burst and drives on for 5.4 min (0.21 Ah).
    A sample discharges or charges as :func:`~battery_predictor.recording.discharge_threshold_a` says. How long
    the recording went on after it is kept in its metadata (:data:`~battery_predictor.recording.DROPPED_TAIL_S_KEY`).
    """
    if len(rec.time_s) < 3:
        raise InputDataError(f"{rec.source}: too few samples ({len(rec.time_s)}) to simulate")
    i_min = int(np.argmin(rec.voltage_v))
    if i_min < 2:
        raise InputDataError(f"{rec.source}: the minimum voltage is at the start; no discharge to fit")
    t, i = rec.time_s, np.asarray(rec.current_a, dtype=float)
    threshold = discharge_threshold_a(i)
    stop = _first_charge_session(t, i < -threshold, i_min)
    discharging = np.nonzero(i[i_min:stop] > threshold)[0]
    last = i_min + int(discharging[-1]) if discharging.size else i_min
    trimmed = rec.slice_time(rec.time_s[0], rec.time_s[last])
    trimmed.metadata[DROPPED_TAIL_S_KEY] = float(t[-1] - t[last]) + float(rec.metadata.get(DROPPED_TAIL_S_KEY, 0.0))
    return trimmed


def _first_charge_session(time_s: np.ndarray, charging: np.ndarray, start: int) -> int:
    """Index of the first sample from ``start`` on of a charge held :data:`CHARGE_SESSION_S`, else the length."""
    flags = np.concatenate([[False], charging[start:], [False]]).astype(np.int8)
    edges = np.diff(flags)
    for first, end in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True):
        # the run's samples are start+first .. start+end-1; it lasts until the sample after it (or its last)
        after = min(start + end, time_s.size - 1)
        if time_s[after] - time_s[start + first] >= CHARGE_SESSION_S:
            return start + int(first)
    return int(time_s.size)


def request_for_recording(params: PackParams, rec: Recording, *, initial_state: str = "auto",
                          extend_s: float = 0.0) -> SimulationRequest:
    """Simulation request that drives the model with a recording's current and temperature.

    Parameters
    ----------
    initial_state : {"auto", "params", "voltage"}
        ``"params"``: the params' initial concentrations; ``"voltage"``: the starting voltage
        (:func:`initial_voltage_v`: the mean of a starting rest, else the first sample) taken as pack
        open-circuit voltage (valid when the recording starts at rest);
        ``"auto"``: ``"params"`` when initial concentrations are fitted or the recording does not
        start at rest, else ``"voltage"``.
    extend_s : float
        Continue past the recording for this many seconds at :func:`end_current_a`, so that a model
        which would end later than the measurement shows it (R2_mod's late case).
    """
    # extension current_offset: the cells carry the measured current minus the sensor's offset
    load = StepLoad.from_samples(rec.time_s, rec.current_a - current_offset_a(params))
    if extend_s > 0:
        load = load.append(StepLoad.constant(end_current_a(load), extend_s))
    if initial_state == "auto":
        at_rest = starts_at_rest(params, rec)
        fits_initial = any(p.startswith("Initial concentration") for p in params.fit.parameters)
        initial_state = "voltage" if at_rest and not fits_initial else "params"
    ocv = initial_voltage_v(params, rec) if initial_state == "voltage" else None
    out_t = rec.relative_time_s
    if extend_s > 0:
        dt = float(np.median(np.diff(out_t)))
        out_t = np.concatenate([out_t, np.arange(out_t[-1] + dt, load.end_s, dt)])
    return SimulationRequest(load=load, ambient_temperature_k=recording_temperature_k(params, rec),
                             initial_pack_ocv_v=ocv, output_time_s=out_t)


def end_current_a(load: StepLoad) -> float:
    """Current (A) a padding past a recording's end continues with.

    A recording that ends at its cut-off ends under the load that took the cell there: the padding
    continues the mean of the last :data:`END_LOAD_WINDOW_S` seconds, so a model that survives that
    load by a little ends a little later, and its padded error grows with how late it is. Never
    below the whole recording's mean (a tail of rest or regeneration would otherwise let a late
    model idle through the whole padding) nor below 0.
    """
    return max(load.mean_current_a(END_LOAD_WINDOW_S), load.mean_current_a(), 0.0)


def _at_rest(params: PackParams, current_a: np.ndarray) -> np.ndarray:
    """Which currents (A) are below :data:`_REST_C_RATE` of the pack's nominal capacity."""
    capacity_ah = float(params.pack_info.get("nominal_capacity_ah", 0.0)) or 1.0
    return np.abs(np.asarray(current_a, dtype=float)) / capacity_ah < _REST_C_RATE


def starts_at_rest(params: PackParams, rec: Recording) -> bool:
    """True when the recording's first current is below :data:`_REST_C_RATE` of the pack's nominal capacity."""
    return bool(_at_rest(params, rec.current_a[:1])[0])


def initial_voltage_v(params: PackParams, rec: Recording) -> float:
    """The recording's starting pack voltage (V) as an open-circuit voltage estimate.

    A recording that starts at rest: the mean voltage of its leading rest samples within
    :data:`REST_AVERAGE_S` of the first (up to the first sample under load), which averages the
    sensor's noise and quantisation out of the state it sets. Otherwise the first sample.
    """
    rest = _at_rest(params, rec.current_a)
    if not rest[0]:
        return float(rec.voltage_v[0])
    n_rest = int(np.argmin(rest)) if not rest.all() else rest.size
    n_window = int(np.searchsorted(rec.time_s, rec.time_s[0] + REST_AVERAGE_S, side="right"))
    return float(np.mean(rec.voltage_v[:max(1, min(n_rest, n_window))]))


#: Secant passes of :func:`loaded_start_ocv_v`.
_LOADED_START_PASSES = 4
#: :func:`loaded_start_ocv_v` stops when the simulated first voltage is this close to the measured one (V, pack).
_LOADED_START_TOLERANCE_V = 5e-4


def loaded_start_ocv_v(params: PackParams, rec: Recording, simulator: PackSimulator) -> float:
    """Pack open-circuit voltage at the start of a recording whose first sample is already under load.

    The first measured voltage of such a recording is the OCV minus the drop under its first current,
    not the OCV; taken as the OCV it puts the model's state of charge low by the drop over the OCV's
    slope (25 degC Panasonic Cycle1: 4.146 V at 1.8 A, about 85 mV below the model's OCV). This is the
    OCV at which the model's own first simulated voltage equals the measured one, found by fixed-point
    passes on a simulation of the first samples (the drop hardly depends on the state).

    The OCV stays between the first voltage and :data:`~battery_predictor.fitting.identifiable.FULL_OCV_MARGIN_V`
    per cell above the params' upper cut-off (the identification's bound): a model whose drop near
    full charge is larger than the cell's would otherwise be pushed to an OCV no cell has. When the
    bound is reached before the model's voltage matches, a warning says so and the bound is the answer.

    Parameters
    ----------
    params : PackParams
        The model.
    rec : Recording
        The recording (its first sample under load; at rest the answer is the first voltage).
    simulator : PackSimulator
        The simulator the recording will be run with.

    Returns
    -------
    float
        Initial pack OCV in V; the first measured voltage when a pass fails (e.g. the OCV would be
        above the model's range).
    """
    v_first = float(rec.voltage_v[0])
    if starts_at_rest(params, rec):
        return v_first
    n = min(len(rec.time_s), 3)
    load = StepLoad.from_samples(rec.time_s[:n], rec.current_a[:n])
    base = SimulationRequest(load=load, ambient_temperature_k=recording_temperature_k(params, rec),
                             output_time_s=np.array([0.0]))
    upper_v = float(params.parameter_values()["Upper voltage cut-off [V]"])
    cap = highest_start_ocv_v(upper_v, v_first / params.series) * params.series
    ocv, miss = v_first, 0.0
    for _ in range(_LOADED_START_PASSES):
        try:
            res = simulator.simulate(params, replace(base, initial_pack_ocv_v=ocv))
        except SimulationError:
            return v_first if ocv == v_first else ocv
        if res.pack_voltage_v.size == 0:
            return ocv
        miss = v_first - float(res.pack_voltage_v[0])
        if abs(miss) < _LOADED_START_TOLERANCE_V:
            return ocv
        step = min(max(ocv + miss, v_first), cap)
        if step == ocv:
            break
        ocv = step
    if ocv >= cap and miss > _LOADED_START_TOLERANCE_V:
        warnings.warn(f"{rec.source}: the model's first voltage under {float(rec.current_a[0]):.3g} A stays "
                      f"{miss * 1000:.0f} mV below the measured {v_first:.3f} V even from an OCV of {cap:.3f} V "
                      f"({FULL_OCV_MARGIN_V} V per cell above the upper cut-off); the model's drop near full "
                      "charge is larger than the cell's; starting from that OCV", UserWarning, stacklevel=2)
    return ocv


def recording_temperature_k(params: PackParams, rec: Recording) -> float:
    """The temperature (K) a recording is simulated at: its mean measured temperature for an isothermal cell; for
    a lumped thermal cell (which heats itself from the ambient) its first measured temperature (the cell at rest
    before the load, as the ambient); the params' ambient temperature when none is measured."""
    from battery_predictor.simulation.cell_setup import is_lumped_thermal

    if is_lumped_thermal(params) and rec.temperature_k is not None and np.isfinite(rec.temperature_k).any():
        return float(rec.temperature_k[np.isfinite(rec.temperature_k)][0])
    return rec.mean_temperature_k(params.ambient_temperature_k)


@dataclass(frozen=True)
class Evaluation:
    """Score of one candidate on every recording.

    Attributes
    ----------
    r2_mod : float
        Mean R2_mod over the recordings.
    per_recording : list of float
        R2_mod of each recording.
    rmse_mv : list of float
        RMS voltage error (mV) of each recording over the simulated span.
    results : list of PackSimResult
        The simulations.
    """

    r2_mod: float
    per_recording: list[float]
    rmse_mv: list[float]
    results: list[PackSimResult] = field(repr=False)


@dataclass
class FitProblem:
    """Recordings + base params + simulator; scores candidate parameter values.

    Parameters
    ----------
    params : PackParams
        The starting model.
    recordings : sequence of Recording
        Measured discharges (trimmed to the discharge by the caller if wanted).
    simulator : PackSimulator
        Fast or liionpack.
    initial_state : str
        See :func:`request_for_recording`.
    """

    params: PackParams
    recordings: Sequence[Recording]
    simulator: PackSimulator
    initial_state: str = "auto"
    extend_fraction: float = 0.2

    def __post_init__(self) -> None:
        if not self.recordings:
            raise InputDataError("no data to fit")

    def candidate(self, values: Mapping[str, float]) -> PackParams:
        """The params with ``values`` substituted."""
        return self.params.with_values(values)

    def evaluate(self, values: Mapping[str, float] | None = None) -> Evaluation:
        """Simulate every recording with ``values`` and score it.

        Raises
        ------
        SimulationError
            When any simulation fails (a fit records it as a failed trial).
        """
        params = self.candidate(values or {})
        scores, errors, results = [], [], []
        for rec in self.recordings:
            req = request_for_recording(params, rec, initial_state=self.initial_state,
                                        extend_s=self.extend_fraction * rec.duration_s)
            res = self.simulator.simulate(params, req)
            if res.time_s.size < 2:
                raise SimulationError(f"{rec.source}: simulation ended immediately (cut-off at start)")
            t = rec.relative_time_s
            scores.append(r2_mod(t, rec.voltage_v, res.time_s, res.pack_voltage_v))
            errors.append(1e3 * rmse_v(t, rec.voltage_v, res.time_s, res.pack_voltage_v))
            results.append(res)
        return Evaluation(r2_mod=float(np.mean(scores)), per_recording=scores, rmse_mv=errors, results=results)
