"""Checks of the model's state against the measurements, applied before any answer is given.

Three rules guard the predictor's answers:

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

The resistance used is the pack's response to a ``pulse_s`` current step at mid charge, from the
model (:func:`pulse_resistance_ohm`). It is lowest at mid charge, so the standstill correction of a
discharging pack is on the low side and the measured check stays conservative.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from battery_predictor.errors import SimulationError

if TYPE_CHECKING:
    from battery_predictor.prediction.pack_model import PackModel


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
