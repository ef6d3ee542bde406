"""Measured 1 s resistance of the Panasonic 18650PF drive cycles by discharged charge (docs/findings.md, issue 12).

For every 0.2 Ah window of a recording's discharge throughput: ``-sum(dI dV) / sum(dI^2)`` over the 1 s
current steps larger than 0.3 A (the ohmic and charge-transfer part of the cell's resistance; solid
diffusion does not act within a second), and the mean case temperature. Usage::

    python docs/diagnosis_issue12/resistance_by_charge.py drive_T25C_HWFET.csv drive_T10C_HWFET.csv drive_T00C_HWFET.csv
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "panasonic_18650pf"


def table(name: str, window_ah: float = 0.2) -> list[tuple[float, float, float]]:
    """(window start Ah, 1 s resistance mOhm, mean case temperature degC) of one recording."""
    d = np.genfromtxt(DATA / name, delimiter=",", names=True)
    t, i, v, temp = d["time_s"], d["current_A"], d["voltage_V"], d["temperature_C"]
    dt = np.diff(t, prepend=t[0])
    ah = np.cumsum(np.clip(i, 0.0, None) * dt) / 3600.0
    one_second = np.r_[False, np.diff(t) < 1.5]
    d_i, d_v = np.diff(i, prepend=i[0]), np.diff(v, prepend=v[0])
    rows = []
    for lo in np.arange(0.0, ah[-1], window_ah):
        inside = (ah >= lo) & (ah < lo + window_ah)
        steps = inside & one_second & (np.abs(d_i) > 0.3)
        if steps.sum() < 20:
            continue
        r_mohm = -1e3 * float(np.sum(d_i[steps] * d_v[steps]) / np.sum(d_i[steps] ** 2))
        rows.append((float(lo), r_mohm, float(temp[inside].mean())))
    return rows


if __name__ == "__main__":
    for name in sys.argv[1:]:
        print(name)
        for lo, r_mohm, temp_c in table(name):
            print(f"  {lo:.1f} Ah  {r_mohm:6.1f} mOhm  {temp_c:5.1f} degC")
