"""A tabulated open-circuit voltage (state of charge -> V), as cell data sets publish it.

Some data sets give the cell's OCV as a table instead of the low-rate test behind it (the LG M50 set
of ``../shared/data/lgm50_wmg``: ``soc_percent, ocv_mean_V, hysteresis_V``). :func:`load_ocv_table`
reads such a CSV: a state-of-charge column (``soc_percent`` in %, or ``soc`` as a fraction) and a
voltage column (``ocv_V``, ``ocv_mean_V`` or ``voltage_V``), optionally a hysteresis column
(``hysteresis_V``: half the gap between the charge and discharge branches, so the discharge branch
is the mean minus it).
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from battery_predictor.errors import InputDataError

#: Accepted state-of-charge columns and the factor to a fraction.
SOC_COLUMNS = {"soc_percent": 0.01, "soc": 1.0}
#: Accepted voltage columns (the first present is read).
VOLTAGE_COLUMNS = ("ocv_V", "ocv_mean_V", "voltage_V")
HYSTERESIS_COLUMN = "hysteresis_V"


@dataclass(frozen=True)
class OcvTable:
    """A tabulated cell OCV.

    Attributes
    ----------
    soc : numpy.ndarray
        State of charge (fraction, 0..1), increasing.
    ocv_v : numpy.ndarray
        Open-circuit voltage in V at ``soc`` (the table's mean curve).
    hysteresis_v : numpy.ndarray or None
        Half the charge/discharge gap in V at ``soc`` (None when the table has none).
    source : str
        The file.
    """

    soc: np.ndarray
    ocv_v: np.ndarray
    hysteresis_v: np.ndarray | None
    source: str


def is_ocv_table(path: str | os.PathLike[str]) -> bool:
    """True when ``path`` is a CSV whose header has a state-of-charge column and no ``time_s``."""
    p = Path(path)
    if p.suffix.lower() != ".csv" or not p.is_file():
        return False
    with p.open(newline="") as fh:
        header = next(csv.reader(fh), [])
    names = {h.strip() for h in header}
    return "time_s" not in names and bool(names & set(SOC_COLUMNS))


def load_ocv_table(path: str | os.PathLike[str]) -> OcvTable:
    """Read a tabulated OCV (see the module docstring).

    Raises
    ------
    InputDataError
        A missing column, a non-numeric or non-finite entry, a state of charge outside 0..1 or not
        strictly increasing, fewer than 10 rows, or voltages outside 0.5..6 V.
    """
    p = Path(path)
    with p.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise InputDataError(f"{p}: an OCV table needs a header and rows")
    names = set(rows[0])
    soc_col = next((c for c in SOC_COLUMNS if c in names), None)
    v_col = next((c for c in VOLTAGE_COLUMNS if c in names), None)
    if soc_col is None or v_col is None:
        raise InputDataError(f"{p}: an OCV table needs a state-of-charge column ({' or '.join(SOC_COLUMNS)}) and a "
                             f"voltage column ({' or '.join(VOLTAGE_COLUMNS)}); found {', '.join(sorted(names))}")
    soc = _column(p, rows, soc_col) * SOC_COLUMNS[soc_col]
    ocv = _column(p, rows, v_col)
    hys = _column(p, rows, HYSTERESIS_COLUMN) if HYSTERESIS_COLUMN in names else None
    if soc.size < 10:
        raise InputDataError(f"{p}: an OCV table needs at least 10 rows, got {soc.size}")
    if np.any(np.diff(soc) <= 0):
        order = np.argsort(soc)
        soc, ocv = soc[order], ocv[order]
        hys = None if hys is None else hys[order]
        if np.any(np.diff(soc) <= 0):
            raise InputDataError(f"{p}: the state of charge repeats a value")
    if soc[0] < -1e-9 or soc[-1] > 1.0 + 1e-9:
        raise InputDataError(f"{p}: the state of charge runs {soc[0]:.3f}..{soc[-1]:.3f}, outside 0..1")
    if np.any((ocv < 0.5) | (ocv > 6.0)):
        raise InputDataError(f"{p}: cell voltages {ocv.min():.3f}..{ocv.max():.3f} V are not a cell's OCV (0.5..6 V)")
    return OcvTable(soc=np.clip(soc, 0.0, 1.0), ocv_v=ocv, hysteresis_v=hys, source=str(p))


def _column(p: Path, rows: list[dict[str, str]], name: str) -> np.ndarray:
    out = np.empty(len(rows))
    for k, row in enumerate(rows):
        try:
            out[k] = float(row[name])
        except (TypeError, ValueError):
            raise InputDataError(f"{p}: line {k + 2}: {name} {row.get(name)!r} is not a number") from None
        if not math.isfinite(out[k]):
            raise InputDataError(f"{p}: line {k + 2}: {name} is not finite")
    return out
