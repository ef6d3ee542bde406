#!/usr/bin/env python3
"""Convert a drive-cycle file of the Panasonic 18650PF data set (Kollmeyer 2018, ``.mat``) to the CSV format.

Usage::

    python tools/panasonic_mat_to_csv.py "n10degC_US06_Pan18650PF.mat" drive_Tm10C_US06.csv [--raw]

The processing is the one ``../shared/data/panasonic_18650pf/PROVENANCE.md`` states for the
shared files: the first raw sample kept, then the mean of the raw samples in each 1 s window (its
mean time), the current sign flipped to ``current_A > 0`` = discharge, columns ``time_s``,
``current_A``, ``voltage_V``, ``temperature_C`` (the case thermocouple). ``--raw`` writes every raw sample
(about 0.1 s apart) instead of the 1 s means: the sub-second bursts that end the bursty drive cycles. Rests are logged slowly
in the source, so two windows can share a rounded time: read such files with
``--duplicate-times keep_last``. Source: doi:10.17632/wykht8y7tg.1 (CC BY 4.0), or the GitHub
copy ``fededc88/Panasonic-18650PF-Data``.
"""

from __future__ import annotations

import sys

import numpy as np
import scipy.io


def convert(mat_path: str, csv_path: str, raw: bool = False) -> None:
    """Write the 1 s window means (``raw``: every sample) of the ``meas`` struct in ``mat_path`` to ``csv_path``."""
    meas = scipy.io.loadmat(mat_path, squeeze_me=True, struct_as_record=False)["meas"]
    t = np.asarray(meas.Time, dtype=float)
    v = np.asarray(meas.Voltage, dtype=float)
    i = -np.asarray(meas.Current, dtype=float)  # the source: negative while discharging
    temp = np.asarray(meas.Battery_Temp_degC, dtype=float)
    if raw:
        keep = np.r_[True, np.diff(t) > 0]  # a repeated time keeps its first sample
        _write(csv_path, zip(t[keep], i[keep], v[keep], temp[keep], strict=True), time_format="{:.3f}")
        return
    window = np.floor(t[1:] - t[0]).astype(int)
    cuts = np.nonzero(np.diff(window))[0] + 1
    rows = [(t[0], i[0], v[0], temp[0])]
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, window.size], strict=True):
        part = slice(1 + a, 1 + b)
        rows.append((t[part].mean(), i[part].mean(), v[part].mean(), temp[part].mean()))
    _write(csv_path, rows, time_format="{:.2f}")


def _write(csv_path: str, rows, time_format: str) -> None:
    with open(csv_path, "w", encoding="utf-8") as out:
        out.write("time_s,current_A,voltage_V,temperature_C\n")
        out.writelines(f"{time_format.format(r[0])},{r[1]:.5f},{r[2]:.5f},{r[3]:.2f}\n" for r in rows)


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--raw"]
    if len(args) != 2:
        sys.exit(__doc__)
    convert(args[0], args[1], raw="--raw" in sys.argv[1:])
