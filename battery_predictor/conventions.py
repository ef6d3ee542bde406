"""Sign and unit conventions, converted in exactly one place.

Inside battery_predictor, currents follow PyBaMM: ``current_a > 0`` means
discharge. ``sensor_msgs/BatteryState`` uses the opposite sign (negative while
discharging). Every conversion between the two goes through the functions here.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

KELVIN_OFFSET = 273.15

#: A float for a scalar input, an array of floats for an array input.
FloatOrArray = float | npt.NDArray[np.float64]


def _scalar(value: npt.ArrayLike) -> float:
    """``float(value)`` of a 0-dimensional input (a number or a 0-d array; anything else raises as float() does)."""
    return float(value)  # type: ignore[arg-type]  # ArrayLike includes sequences; callers pass only 0-d values


def battery_state_current_to_internal(msg_current_a: npt.ArrayLike) -> FloatOrArray:
    """Convert a ``BatteryState.current`` value (negative = discharge) to the internal sign.

    Parameters
    ----------
    msg_current_a : float or array_like
        Current in A as published in ``sensor_msgs/BatteryState``.

    Returns
    -------
    float or numpy.ndarray
        Current in A, positive while discharging.
    """
    return -np.asarray(msg_current_a, dtype=float) if np.ndim(msg_current_a) else -_scalar(msg_current_a)


def internal_current_to_battery_state(current_a: npt.ArrayLike) -> FloatOrArray:
    """Convert an internal current (positive = discharge) to ``BatteryState`` sign."""
    return -np.asarray(current_a, dtype=float) if np.ndim(current_a) else -_scalar(current_a)


def celsius_to_kelvin(temperature_c: npt.ArrayLike) -> FloatOrArray:
    """Convert °C to K."""
    return np.asarray(temperature_c, dtype=float) + KELVIN_OFFSET if np.ndim(temperature_c) else _scalar(temperature_c) + KELVIN_OFFSET


def kelvin_to_celsius(temperature_k: npt.ArrayLike) -> FloatOrArray:
    """Convert K to °C."""
    return np.asarray(temperature_k, dtype=float) - KELVIN_OFFSET if np.ndim(temperature_k) else _scalar(temperature_k) - KELVIN_OFFSET
