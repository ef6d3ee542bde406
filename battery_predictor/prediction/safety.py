"""Checks of the model's state against the measurements, applied before any answer is given.

Four rules guard the predictor's answers:

- **The measurement has the last word on routes.** The latest measured pack voltage, moved to the
  standstill current with the pack's resistance (:func:`standstill_voltage_v`), already below the
  route threshold rejects any route, whatever the model's state says.
- **A jump the current does not explain is a new pack state** (a battery swap, a restart on the
  charger, a sensor reconnected): the voltage change between two windows, less the change the
  current step causes through the resistance, beyond a tolerance (:func:`unexplained_jump_v`)
  discards the history before it and forces a fresh calibration.
- **A propagated state must stay on the measurement.** The calibrated state carried forward by
  charge counting is checked against every new measurement; beyond the state tolerance it is
  dropped and the state recalibrated (see ``PredictorCore.calibration``).
- **No route goes deeper than the fit data when they stopped above the threshold.** A pack whose
  fit data never came down to the route threshold (their deepest state, moved to the standstill
  current, is above it) was never seen below that state: its end may lie there (a weak cell that
  trips the battery management while the other cells hold the pack voltage up, which the pack
  voltage alone does not show). A route that would draw the pack below the state of charge the
  model calibrates from that deepest state is rejected (:func:`charge_floor`).

The resistance used is the pack's response to a ``pulse_s`` current step at mid charge, from the
model (:func:`pulse_resistance_ohm`). It is lowest at mid charge, so the standstill correction of a
discharging pack is on the low side and the measured check stays conservative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from battery_predictor.errors import SimulationError
from battery_predictor.prediction.calibration import calibrate_soc

if TYPE_CHECKING:
    from battery_predictor.prediction.pack_model import PackModel
    from battery_predictor.recording import DeepestState


def pulse_resistance_ohm(runner: PackModel, temperature_k: float, *, soc: float = 0.5, current_a: float | None = None,
                         pulse_s: float = 5.0) -> float:
    """Pack resistance (Ohm) to a ``pulse_s`` current step from rest at ``soc``.

    Parameters
    ----------
    runner : PackModel
        The pack model.
    temperature_k : float
        Temperature, K.
    soc : float
        State of charge the step starts from.
    current_a : float, optional
        Step current, A (default: a C/2 step of the pack).
    pulse_s : float
        Step length, s (the monitor's window).

    Raises
    ------
    SimulationError
        When the model cannot run the step.
    """
    step_a = current_a if current_a is not None else 0.5 * runner.capacity_ah
    rest = runner.run(soc, [(pulse_s, 0.0)], temperature_k)
    loaded = runner.run(soc, [(pulse_s, step_a)], temperature_k)
    if loaded.reached_cutoff or rest.reached_cutoff:
        raise SimulationError(f"cannot measure the pack resistance: the {step_a:.2f} A step reaches a cut-off")
    r_ohm = (float(rest.pack_voltage_v[-1]) - float(loaded.pack_voltage_v[-1])) / step_a
    if not (math.isfinite(r_ohm) and r_ohm >= 0):
        raise SimulationError(f"cannot measure the pack resistance: got {r_ohm} Ohm")
    return r_ohm


def standstill_voltage_v(voltage_v: float, current_a: float, standstill_current_a: float,
                         resistance_ohm: float) -> float:
    """Measured pack voltage moved to the standstill current, V.

    ``V + (I - I_standstill) * R`` (currents positive = discharge).
    """
    return voltage_v + (current_a - standstill_current_a) * resistance_ohm


def unexplained_jump_v(previous: tuple[float, float], latest: tuple[float, float], resistance_ohm: float) -> float:
    """Voltage change between two measurements that their current change does not explain, V.

    Parameters
    ----------
    previous, latest : tuple of float
        ``(voltage_v, current_a)`` of two consecutive windows (current positive = discharge).
    resistance_ohm : float
        Pack resistance, Ohm.
    """
    (v0, i0), (v1, i1) = previous, latest
    return abs((v1 - v0) + (i1 - i0) * resistance_ohm)


@dataclass(frozen=True)
class ChargeFloor:
    """The lowest state of charge a route may end at: the model's at the fit data's deepest state.

    Attributes
    ----------
    soc : float
        The model's state of charge calibrated from ``deepest`` (its SOC scale, may lie below 0).
    deepest : DeepestState
        The fit data's deepest sample (V, A, K).
    standstill_voltage_v : float
        Its voltage moved to the standstill current, V (above the route threshold).
    """

    soc: float
    deepest: DeepestState
    standstill_voltage_v: float

    def reason(self, end_soc: float) -> str:
        """Why a route that ends at ``end_soc`` is rejected."""
        d = self.deepest
        return (f"the route would end at model SOC {end_soc:.3f}, below {self.soc:.3f}, the deepest state of the fit "
                f"data ({d.voltage_v:.2f} V at {d.current_a:.2f} A, {self.standstill_voltage_v:.2f} V at the "
                "standstill current, above the threshold): the pack was never seen below it, and a pack whose "
                "recordings stop above the threshold may stop there (a weak cell)")


def charge_floor(runner: PackModel, deepest: DeepestState | None, *, threshold_v: float, standstill_current_a: float,
                 resistance_ohm: float) -> ChargeFloor | None:
    """The fit data's deepest state as a floor for routes; None when there is none or it lies at or below the threshold.

    Parameters
    ----------
    runner : PackModel
        The fitted pack model.
    deepest : DeepestState or None
        The fit data's deepest sample (``thresholds`` of a fitted params file), None when not recorded.
    threshold_v, standstill_current_a : float
        The route threshold (V) and the standstill current (A) it applies at.
    resistance_ohm : float
        The pack's resistance (Ohm) that moves the sample to the standstill current.

    Raises
    ------
    SimulationError
        When the model cannot calibrate the deepest state.
    """
    if deepest is None:
        return None
    if not math.isfinite(resistance_ohm):
        raise SimulationError(f"no pack resistance at the deepest state's {deepest.temperature_k:.1f} K")
    v_standstill = standstill_voltage_v(deepest.voltage_v, deepest.current_a, standstill_current_a, resistance_ohm)
    if not v_standstill > threshold_v:
        return None
    cal = calibrate_soc(runner, deepest.voltage_v, deepest.current_a, deepest.temperature_k)
    return ChargeFloor(cal.soc, deepest, v_standstill)
