"""SOC calibration from the latest measured voltage, current and temperature (paper 5.1.5, step 1).

The model's SOC is the one whose short simulation at the measured current and
temperature reproduces the measured pack voltage (root of a monotone function,
found with :func:`scipy.optimize.brentq`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.optimize import brentq

from battery_predictor.errors import SimulationError
from battery_predictor.prediction.cell_runner import PackRunner

#: SOC search interval.
SOC_LOW, SOC_HIGH = 0.0, 1.0


@dataclass(frozen=True)
class Calibration:
    """A calibrated state of charge.

    Attributes
    ----------
    soc : float
        State of charge (0..1).
    residual_v : float
        Simulated minus measured pack voltage at ``soc`` in V.
    clipped : str
        ``""``, or ``"below_empty"`` / ``"above_full"`` when the measurement lies outside the model's range.
    """

    soc: float
    residual_v: float
    clipped: str = ""


def calibrate_soc(runner: PackRunner, voltage_v: float, current_a: float, temperature_k: float,
                  settle_s: float = 60.0, tol_soc: float = 1e-4) -> Calibration:
    """SOC whose ``settle_s`` simulation at ``current_a`` ends at the measured ``voltage_v``.

    Parameters
    ----------
    runner : PackRunner
        The pack model.
    voltage_v : float
        Measured pack voltage in V.
    current_a : float
        Measured pack current in A (positive = discharge).
    temperature_k : float
        Measured temperature in K.
    settle_s : float
        Length of the short simulation in s.
    """
    for name, val in (("voltage", voltage_v), ("current", current_a), ("temperature", temperature_k)):
        if not math.isfinite(val):
            raise SimulationError(f"cannot calibrate: {name} is not finite ({val})")

    def f(soc: float) -> float:
        v = runner.settled_voltage_v(soc, current_a, temperature_k, settle_s)
        return (v if math.isfinite(v) else -1e3) - voltage_v

    # the empty end may hit the cut-off during the settle: search from a small SOC upwards
    lo = SOC_LOW
    f_lo = f(lo)
    if f_lo < -1e2:
        for lo in (0.002, 0.01, 0.03, 0.06, 0.1):
            f_lo = f(lo)
            if f_lo > -1e2:
                break
    f_hi = f(SOC_HIGH)
    if f_lo >= 0:
        return Calibration(lo, f_lo, "below_empty")
    if f_hi <= 0:
        return Calibration(SOC_HIGH, f_hi, "above_full")
    soc = brentq(f, lo, SOC_HIGH, xtol=tol_soc)
    return Calibration(float(soc), float(f(soc)))
