"""A weak series group inferred from where the fit data stopped.

A pack of identical cells fitted on its pack voltage cannot tell where a pack with one weak series
group ends: the weak group reaches its cell cut-off (and the battery management stops the pack)
while the other groups still hold the pack voltage on its plateau: the pack voltage shows one
group's knee only, well above where the fitted pack of identical cells would stop. Data that stop so, above the route threshold, are explained by the weakest group that
makes the fitted model stop there: discharged from full at the deepest state's current and
temperature, the model with a weak group of capacity fraction ``f`` stops (its weak group at the
cell cut-off) at a pack voltage that rises as ``f`` falls; :func:`inferred_weak_fraction` bisects
``f`` to the deepest state's voltage.

The inference applies only where it is the conservative reading of the data
(:func:`weak_group_evidence`): a route threshold to protect, no weak group modelled yet, and data
whose deepest state is where a recording ends while discharging (the pack was switched off under
load; :func:`~battery_predictor.recording.ends_at_deepest`), above the threshold at the standstill
current. A pack of identical cells switched off on its knee there gets a group a few per cent weaker
that stops it there; a recording merely cut short under load reads as a stop too, and its answers
are then conservative (routes the pack could have driven are rejected).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from battery_predictor.errors import SimulationError
from battery_predictor.params import PackParams
from battery_predictor.prediction.pack_model import pack_model
from battery_predictor.prediction.safety import pulse_resistance_ohm, standstill_voltage_v
from battery_predictor.recording import DeepestState, Recording, ends_at_deepest
from battery_predictor.simulation.extensions import with_weak_group

#: Range of the capacity fraction the bisection searches (a group holding less than 30 % is a fault, not a
#: weak group: the inference then stops at the bound and says so).
FRACTION_BOUNDS = (0.3, 0.999)
#: Bisection steps: the fraction to within ``0.7 / 2**14``, below the spread of the cells it stands for.
BISECTION_STEPS = 14
#: Longest discharge the stop search runs, s (a stop comes well before at any current the fit data hold).
MAX_DISCHARGE_S = 48 * 3600.0


@dataclass(frozen=True)
class WeakGroupInference:
    """A weak series group that makes the fitted model stop where the fit data stopped.

    Attributes
    ----------
    fraction : float
        Capacity fraction of the weak group's cells relative to the others (``cell_imbalance``).
    deepest : DeepestState
        The fit data's deepest state the model stops at (V, A, K).
    stop_voltage_v : float
        Pack voltage (V) where the model with the group stops at the deepest state's current.
    at_bound : bool
        True when the fraction stopped at the bisection's lower bound (:data:`FRACTION_BOUNDS`).
    """

    fraction: float
    deepest: DeepestState
    stop_voltage_v: float
    at_bound: bool

    def describe(self) -> str:
        """One line for a user: the group and the stop it explains."""
        d = self.deepest
        bound = " (the search's lower bound: the data stop earlier still)" if self.at_bound else ""
        return (f"weak series group inferred: its cells hold {self.fraction:.3f} of the others' capacity{bound}; "
                f"the fitted pack then stops at {self.stop_voltage_v:.2f} V at {d.current_a:.2f} A, where the fit "
                f"data stopped under load ({d.voltage_v:.2f} V, above the route threshold)")


def stop_voltage_v(params: PackParams, fraction: float, deepest: DeepestState) -> float:
    """Pack voltage (V) where ``params`` with a weak group of ``fraction`` stops, discharged from full at the
    deepest state's current and temperature.

    Raises
    ------
    SimulationError
        When the model cannot run the discharge or does not stop within :data:`MAX_DISCHARGE_S`.
    """
    runner = pack_model(with_weak_group(params, fraction))[0]
    run = runner.run(1.0, [(MAX_DISCHARGE_S, max(deepest.current_a, 0.0))], deepest.temperature_k)
    if not run.reached_cutoff:
        raise SimulationError(f"the pack does not stop within {MAX_DISCHARGE_S / 3600:.0f} h at "
                              f"{deepest.current_a:.2f} A")
    return float(run.pack_voltage_v[-1])


def inferred_weak_fraction(params: PackParams, deepest: DeepestState) -> WeakGroupInference:
    """The weak group fraction at which ``params`` stops at ``deepest``'s voltage (bisection, see the module).

    Raises
    ------
    SimulationError
        When the model cannot run a discharge.
    """
    lo, hi = FRACTION_BOUNDS
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        if stop_voltage_v(params, mid, deepest) > deepest.voltage_v:
            lo = mid  # stops above the deepest state: the weak group holds more
        else:
            hi = mid
    fraction = 0.5 * (lo + hi)
    return WeakGroupInference(fraction, deepest, stop_voltage_v(params, fraction, deepest),
                              at_bound=lo == FRACTION_BOUNDS[0])


def weak_group_evidence(params: PackParams, recordings: Sequence[Recording], deepest: DeepestState | None) -> str:
    """Why the fit data do not call for a weak group ("" when they do; see the module).

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
        return "no route threshold"
    if params.series < 2:
        return "a single series group"
    if "cell_imbalance" in params.extensions:
        return "the params model a weak group already"
    if deepest is None:
        return "no deepest state"
    if not ends_at_deepest(recordings):
        return "the fit data do not end at their deepest state under load"
    standstill_a = float(params.thresholds.get("standstill_current_a", 0.0))
    r_ohm = pulse_resistance_ohm(pack_model(params)[0], deepest.temperature_k)
    if not standstill_voltage_v(deepest.voltage_v, deepest.current_a, standstill_a, r_ohm) > threshold_v:
        return "the fit data reach the route threshold"
    return ""
