"""Sign and unit conventions, converted in exactly one place.

Inside battery_predictor, currents follow PyBaMM: ``current_a > 0`` means
discharge. ``sensor_msgs/BatteryState`` uses the opposite sign (negative while
discharging). Every conversion between the two goes through the functions here.
"""

from __future__ import annotations

import numpy as np

KELVIN_OFFSET = 273.15


def battery_state_current_to_internal(msg_current_a):
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
    return -np.asarray(msg_current_a, dtype=float) if np.ndim(msg_current_a) else -float(msg_current_a)


def internal_current_to_battery_state(current_a):
    """Convert an internal current (positive = discharge) to ``BatteryState`` sign."""
    return -np.asarray(current_a, dtype=float) if np.ndim(current_a) else -float(current_a)


def celsius_to_kelvin(temperature_c):
    """Convert °C to K."""
    return np.asarray(temperature_c, dtype=float) + KELVIN_OFFSET if np.ndim(temperature_c) else float(temperature_c) + KELVIN_OFFSET


def kelvin_to_celsius(temperature_k):
    """Convert K to °C."""
    return np.asarray(temperature_k, dtype=float) - KELVIN_OFFSET if np.ndim(temperature_k) else float(temperature_k) - KELVIN_OFFSET
