"""A weak series group inferred from where the fit data stopped.

A pack of identical cells fitted on its pack voltage cannot tell where a pack with one weak series
group ends: the weak group reaches its cell cut-off (and the battery management stops the pack)
while the other groups still hold the pack voltage on its plateau: the pack voltage shows one
group's knee only, well above where the fitted pack of identical cells would stop. Data that stop
so, above the route threshold, are explained by the weak group that makes the fitted model stop
where they stopped: replaying the recording that stopped (its current and temperature, from its
start as the fit simulates it, :func:`~battery_predictor.fitting.problem.request_for_recording`),
the model with a weak group of capacity fraction ``f`` reaches the cell cut-off earlier the smaller
``f`` is; :func:`inferred_weak_fraction` bisects ``f`` to the recording's end.

The inference applies only where it is the conservative reading of the data
(:func:`weak_group_evidence`): a route threshold to protect, no weak group modelled yet, and data
whose deepest state is where a recording ends while discharging (the pack was switched off under
load; :func:`~battery_predictor.recording.recording_ending_at_deepest`), above the threshold at the
standstill current. A pack of identical cells switched off on its knee there gets a group a few per
cent weaker that stops it there; a recording merely cut short under load reads as a stop too, and
its answers are then conservative (routes the pack could have driven are rejected).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from battery_predictor.fitting.problem import request_for_recording
from battery_predictor.params import DEFAULT_STANDSTILL_CURRENT_A, PackParams
from battery_predictor.prediction.pack_model import pack_model
from battery_predictor.prediction.safety import pulse_resistance_ohm, standstill_voltage_v
from battery_predictor.recording import DeepestState, Recording, recording_ending_at_deepest
from battery_predictor.simulation import PackSimulator, SimulationRequest, get_simulator
from battery_predictor.simulation.extensions import with_weak_group

#: Range of the capacity fraction the bisection searches (a group holding less than 30 % is a fault, not a
#: weak group: the inference then stops at the bound and says so).
FRACTION_BOUNDS = (0.3, 0.999)
#: Bisection steps: the fraction to within ``0.7 / 2**12``, below the spread of the cells it stands for.
BISECTION_STEPS = 12


@dataclass(frozen=True)
class WeakGroupInference:
    """A weak series group that makes the fitted model stop where the fit data stopped.

    Attributes
    ----------
    fraction : float
        Capacity fraction of the weak group's cells relative to the others (``cell_imbalance``).
    deepest : DeepestState
        The fit data's deepest state, where the recording that stopped ends (V, A, K).
    end_s : float
        Length of that recording, s.
    stop_s : float
        When the model with the group stops replaying it, s (``inf``: it does not).
    at_bound : bool
        True when the fraction stopped at the bisection's lower bound (:data:`FRACTION_BOUNDS`).
    """

    fraction: float
    deepest: DeepestState
    end_s: float
    stop_s: float
    at_bound: bool

    def describe(self) -> str:
        """One line for a user: the group and the stop it explains."""
        d = self.deepest
        bound = " (the search's lower bound: the data stop earlier still)" if self.at_bound else ""
        return (f"weak series group inferred: its cells hold {self.fraction:.3f} of the others' capacity{bound}; "
                f"replaying the fit data, the fitted pack then stops {self.stop_s / 60:.1f} min in, where they "
                f"stopped under load ({self.end_s / 60:.1f} min, {d.voltage_v:.2f} V at {d.current_a:.2f} A, "
                "above the route threshold; if that recording was cut short rather than stopped by the pack, fit "
                "with --no-weak-group-inference)")


def stop_time_s(params: PackParams, fraction: float, recording: Recording, simulator: PackSimulator) -> float:
    """When ``params`` with a weak group of ``fraction`` reach a cell cut-off replaying ``recording``, s
    (``inf`` when they do not).

    Raises
    ------
    SimulationError
        When the model cannot run the recording.
    """
    return _stop_s(params, fraction, request_for_recording(params, recording), simulator)


def _stop_s(params: PackParams, fraction: float, request: SimulationRequest, simulator: PackSimulator) -> float:
    """:func:`stop_time_s` of a recording's request (the same for every fraction: built once per bisection)."""
    result = simulator.simulate(with_weak_group(params, fraction), request)
    return float(result.end_time_s) if result.reached_cutoff else math.inf


def inferred_weak_fraction(params: PackParams, recording: Recording, deepest: DeepestState,
                           simulator: PackSimulator | None = None) -> WeakGroupInference:
    """The weak group fraction at which ``params`` stop where ``recording`` ends (bisection, see the module).

    Parameters
    ----------
    params : PackParams
        The fitted params (identical cells).
    recording : Recording
        The fit recording that stopped (voltage V, current A, discharge positive).
    deepest : DeepestState
        Where it stopped.
    simulator : PackSimulator, optional
        The simulator that replays it (default: the engine, as ``fit``).

    Raises
    ------
    SimulationError
        When the model cannot run the recording.
    """
    simulator = simulator or get_simulator("engine")
    end_s = float(recording.relative_time_s[-1])
    request = request_for_recording(params, recording)
    lo, hi = FRACTION_BOUNDS
    lo_stop_s = math.nan  # the stop at ``lo`` once ``lo`` has been a midpoint
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        stop_s = _stop_s(params, mid, request, simulator)
        if stop_s < end_s:
            lo, lo_stop_s = mid, stop_s  # stops before the data did: the weak group holds more
        else:
            hi = mid
    at_bound = lo == FRACTION_BOUNDS[0]
    if at_bound:
        lo_stop_s = _stop_s(params, lo, request, simulator)
    # the lower end of the last interval: the model stops at or just before the data's end (the safe side)
    return WeakGroupInference(lo, deepest, end_s, lo_stop_s, at_bound=at_bound)


def weak_group_evidence(params: PackParams, recordings: Sequence[Recording],
                        deepest: DeepestState | None) -> tuple[Recording | None, str]:
    """The recording whose stop calls for a weak group, or None and why the fit data do not (see the module).

    Parameters
    ----------
    params : PackParams
        The fitted params (``thresholds.route_min_voltage_v`` and ``standstill_current_a`` name the route
        threshold).
    recordings : sequence of Recording
        The fit data.
    deepest : DeepestState or None
        Their deepest state (:func:`~battery_predictor.recording.deepest_state`).

    Raises
    ------
    SimulationError
        When the model cannot measure the pack resistance.
    """
    threshold_v = params.thresholds.get("route_min_voltage_v")
    if threshold_v is None or not math.isfinite(threshold_v):
        return None, "no route threshold"
    if params.series < 2:
        return None, "a single series group"
    if "cell_imbalance" in params.extensions:
        return None, "the params model a weak group already"
    if deepest is None:
        return None, "no deepest state kept: the fit data reach below the pack's voltage window"
    stopped = recording_ending_at_deepest(recordings)
    if stopped is None:
        return None, "the fit data do not end at their deepest state under load"
    standstill_a = float(params.thresholds.get("standstill_current_a", DEFAULT_STANDSTILL_CURRENT_A))
    r_ohm = pulse_resistance_ohm(pack_model(params)[0], deepest.temperature_k)
    if not standstill_voltage_v(deepest.voltage_v, deepest.current_a, standstill_a, r_ohm) > threshold_v:
        return None, "the fit data reach the route threshold"
    return stopped, ""

