"""Read and write measurement CSV files as :class:`~battery_predictor.recording.Recording`.

File format
-----------
A UTF-8 text file (a byte-order mark is accepted) with one header line and one
sample per line, comma separated. Lines starting with ``#`` *before* the header
are skipped. Columns may come in any order; unknown columns are ignored.

Required columns:

``time_s``
    Sample time in s, strictly increasing.
``voltage_V``
    Terminal voltage in V.
``current_A``
    Current in A, **positive while discharging** (the package-wide convention,
    see :mod:`battery_predictor.conventions`).

Temperature (optional). Unless ``temperature_column=`` names one explicitly, the
first column of :data:`TEMPERATURE_COLUMNS` that exists is used. Only these
exact names are recognised (cell/case/surface first, ambient/chamber last);
other ``*_C`` columns such as ``temperature_pos_C`` (tab sensors) are ignored
on purpose. Columns ending in ``_C`` are read as °C, columns ending in ``_K`` as
K. A temperature column that is empty on every row gives ``temperature_k=None``.

Series-group voltages (optional): columns ``group1_voltage_V``, ``group2_voltage_V``, ...
(:data:`GROUP_VOLTAGE_PATTERN`, in group order) become ``Recording.group_voltage_v``
(V, one column per group; their names in ``metadata["group_voltage_columns"]``). An empty
cell is NaN (a group reading never discards a V/I sample); see
:func:`~battery_predictor.io.validation.check_group_voltages` for the checks.

Checks
------
Every problem raises :class:`~battery_predictor.errors.InputDataError` with a
one-line message that names the file and either the column or the **CSV line
number** (physical lines of the file, so the header is line 1 unless comment
lines precede it), followed by the 1-based data row number in parentheses,
e.g. ``data.csv: line 3 (data row 2): ...``:

* file missing, a directory, not UTF-8, empty, or header without data rows;
* a required column missing (the message lists the columns found);
* a non-numeric cell;
* an empty/NaN/inf cell in ``time_s``, ``voltage_V`` or ``current_A``
  or a voltage <= 0 V (``drop_nan=True`` drops those rows instead) or a gap in the temperature
  column (``drop_nan=True`` fills it from the nearest measured sample in
  time instead, so that a missing auxiliary reading never discards a V/I
  sample);
* ``time_s`` not strictly increasing: the first offending line and both times
  are named. Repeated timestamps at step changes are common in cycler exports;
  ``duplicate_times="keep_last"`` (recommended: the later row is the start of
  the new step, which keeps the zero-order-hold current correct) or
  ``"keep_first"`` resolves them. Times that go backwards are always an error;
* voltages that look like millivolts (median >
  :data:`~battery_predictor.io.validation.MAX_PLAUSIBLE_VOLTAGE_V`),
  currents that look like milliamperes (median of the non-zero ``|current_A|``
  > :data:`~battery_predictor.io.validation.MAX_PLAUSIBLE_CURRENT_A`), implausible temperatures (kelvin in a ``_C`` column or vice versa);
* the wrong current sign convention, see
  :func:`battery_predictor.io.validation.check_current_sign`.

Long-format files that hold several records (for example one pulse test per
``soc_label``/``cell``) are read with :func:`load_csv_groups`.
"""

from __future__ import annotations

import csv
import math
import os
import re
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from battery_predictor.conventions import kelvin_to_celsius
from battery_predictor.errors import InputDataError, in_cli, option_hint
from battery_predictor.io.validation import check_group_voltages, check_samples
from battery_predictor.recording import Recording

#: Columns every measurement CSV must have.
REQUIRED_COLUMNS: tuple[str, ...] = ("time_s", "voltage_V", "current_A")

#: Temperature columns recognised automatically, in order of preference.
#: ``*_C`` columns are °C, ``*_K`` columns are K.
TEMPERATURE_COLUMNS: tuple[str, ...] = (
    "temperature_C",
    "temperature_K",
    "cell_temperature_C",
    "surface_temperature_C",
    "case_temperature_C",
    "pack_temperature_C",
    "battery_temperature_C",
    "temperature1_C",
    "ambient_temperature_C",
    "chamber_temperature_C",
)


#: Series-group voltage columns (V): ``group<k>_voltage_V``, k = 1, 2, ...
GROUP_VOLTAGE_PATTERN = re.compile(r"^group([0-9]+)_voltage_V$")

DUPLICATE_TIME_POLICIES = ("error", "keep_first", "keep_last")

_MISSING_STRINGS = frozenset({"", "nan", "na", "n/a", "null", "none"})
_MAX_HINT_COLUMNS = 20


# ---------------------------------------------------------------------------
# Reading the raw table
# ---------------------------------------------------------------------------


class _Table:
    """Raw CSV content: stripped header names, string rows and their line numbers."""

    def __init__(self, path: Path, header: list[str], rows: list[list[str]], lines: list[int]):
        self.path = path
        self.header = header
        self.rows = rows
        self.lines = lines
        self.index = {name: i for i, name in enumerate(header)}

    def column(self, name: str) -> list[str]:
        j = self.index[name]
        return [row[j] if j < len(row) else "" for row in self.rows]


def _read_table(path: Path) -> _Table:
    if not path.exists():
        raise InputDataError(f"{path}: file not found")
    if path.is_dir():
        raise InputDataError(f"{path}: is a directory, expected a CSV file")
    header: list[str] | None = None
    header_line = 0
    rows: list[list[str]] = []
    lines: list[int] = []
    try:
        with path.open("r", encoding="utf-8-sig", newline="") as fh:
            reader = csv.reader(fh)
            for row in reader:
                if header is None:
                    if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
                        continue
                    header = [name.strip() for name in row]
                    header_line = reader.line_num
                    continue
                rows.append(row)
                lines.append(reader.line_num)
    except UnicodeDecodeError as exc:
        raise InputDataError(f"{path}: not a UTF-8 text CSV file ({exc.reason} at byte {exc.start})") from None
    except csv.Error as exc:
        raise InputDataError(f"{path}: line {reader.line_num}: malformed CSV ({exc})") from None
    except OSError as exc:
        raise InputDataError(f"{path}: cannot read file ({exc.strerror or exc})") from None
    if header is None:
        raise InputDataError(f"{path}: file is empty (no header line)")
    # Trailing blank lines are harmless; blank lines in between are empty rows.
    while rows and not "".join(rows[-1]).strip():
        rows.pop()
        lines.pop()
    if not rows:
        raise InputDataError(f"{path}: line {header_line}: has a header but no data rows")
    seen: set[str] = set()
    for name in header:
        if name in seen:
            raise InputDataError(f"{path}: line {header_line}: column {name!r} appears more than once in the header")
        seen.add(name)
    for k, (row, line) in enumerate(zip(rows, lines)):
        if len(row) > len(header) and "".join(row[len(header):]).strip():
            raise InputDataError(
                f"{path}: line {line} (data row {k + 1}): has {len(row)} fields, the header has {len(header)}"
            )
    return _Table(path, header, rows, lines)


def _where(table: _Table, k: int, row_numbers: Sequence[int] | np.ndarray | None = None) -> str:
    """'line N (data row M)' for row index k of the (possibly filtered) table."""
    row = row_numbers[k] if row_numbers is not None else k + 1
    return f"line {table.lines[row - 1]} (data row {row})"


def _find_columns(table: _Table, temperature_column: str | None) -> tuple[str | None, str]:
    missing = [c for c in REQUIRED_COLUMNS if c not in table.index]
    if missing:
        found = table.header[:_MAX_HINT_COLUMNS]
        more = f" (+{len(table.header) - len(found)} more)" if len(table.header) > len(found) else ""
        hint = ""
        if len(table.header) == 1 and (";" in table.header[0] or "\t" in table.header[0]):
            hint = "; the file seems to use ';' or tab as delimiter, expected ','"
        else:
            lower = {name.lower(): name for name in table.header}
            near = [f"{lower[c.lower()]!r} (expected {c!r})" for c in missing if c.lower() in lower]
            if near:
                hint = "; column names are case-sensitive: found " + ", ".join(near)
        raise InputDataError(
            f"{table.path}: missing column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(c) for c in missing)}; found: {', '.join(found)}{more}{hint}"
        )
    if temperature_column is not None:
        if temperature_column not in table.index:
            raise InputDataError(
                f"{table.path}: temperature column {temperature_column!r} not found; found: {', '.join(table.header)}"
            )
        if not (temperature_column.endswith("_C") or temperature_column.endswith("_K")):
            raise InputDataError(
                f"{table.path}: temperature column {temperature_column!r} must end in _C (°C) or _K (K) to give its unit"
            )
        return temperature_column, temperature_column[-1]
    for name in TEMPERATURE_COLUMNS:
        if name in table.index:
            return name, name[-1]
    return None, ""


def _group_columns(table: _Table) -> list[str]:
    """The table's ``group<k>_voltage_V`` columns in group order."""
    found = [(int(m.group(1)), name) for name in table.header if (m := GROUP_VOLTAGE_PATTERN.match(name))]
    return [name for _, name in sorted(found)]


def _parse_column(table: _Table, name: str) -> np.ndarray:
    """Column as float array; missing cells -> NaN; non-numeric cells -> InputDataError."""
    cells = table.column(name)
    try:
        return np.asarray(cells, dtype=float)
    except ValueError:
        pass
    out = np.empty(len(cells))
    for k, cell in enumerate(cells):
        text = cell.strip()
        if text.lower() in _MISSING_STRINGS:
            out[k] = math.nan
            continue
        try:
            out[k] = float(text)
        except ValueError:
            shown = text if len(text) <= 30 else text[:27] + "..."
            raise InputDataError(
                f"{table.path}: {_where(table, k)}: column {name!r}: {shown!r} is not a number"
            ) from None
    return out


# ---------------------------------------------------------------------------
# Building a Recording
# ---------------------------------------------------------------------------


class _Rows(NamedTuple):
    """One record's rows: 1-based data row numbers, time, voltage, current, temperature column (or None),
    group voltages (n_rows, n_groups) (or None)."""

    rows: np.ndarray
    t: np.ndarray
    v: np.ndarray
    i: np.ndarray
    temp: np.ndarray | None
    groups: np.ndarray | None = None

    def take(self, keep: np.ndarray) -> _Rows:
        return _Rows(self.rows[keep], self.t[keep], self.v[keep], self.i[keep],
                     self.temp[keep] if self.temp is not None else None,
                     self.groups[keep] if self.groups is not None else None)


def _build(
    table: _Table,
    row_idx: np.ndarray,
    columns: dict[str, np.ndarray],
    temp_name: str | None,
    temp_unit: str,
    *,
    source: str,
    expect_discharge: bool,
    drop_nan: bool,
    duplicate_times: str,
    metadata: dict[str, Any],
) -> Recording:
    """Validate one record (the table rows ``row_idx``, 0-based) and make a Recording."""
    group_names = _group_columns(table)
    groups = np.column_stack([columns[g][row_idx] for g in group_names]) if group_names else None
    data = _Rows(row_idx + 1, columns["time_s"][row_idx], columns["voltage_V"][row_idx],
                 columns["current_A"][row_idx], columns[temp_name][row_idx] if temp_name else None, groups)
    meta = dict(metadata)
    data = _drop_bad_rows(table, row_idx, data, source=source, drop_nan=drop_nan, meta=meta)
    data = _drop_repeated_times(table, data, source=source, duplicate_times=duplicate_times, meta=meta)

    def gap_message(k: int, n: int) -> str:
        return (f"{source}: {_where(table, k, data.rows)}: column {temp_name!r} is empty or non-finite ({n} such "
                "row(s))" + option_hint("drop_nan", True, "to fill gaps from the nearest measured sample"))

    temperature_k, filled = check_samples(
        data.t, data.v, data.i, data.temp, source=source, column=str(temp_name), celsius=temp_unit == "C",
        drop_nan=drop_nan, gap_message=gap_message, expect_discharge=expect_discharge)
    if filled:
        meta["filled_temperature_rows"] = filled
    meta["temperature_column"] = temp_name if temperature_k is not None else None
    group_v = None
    if data.groups is not None:
        group_v = check_group_voltages(data.groups, source=source, columns=group_names, drop_nan=drop_nan,
                                       where=lambda k: _where(table, k, data.rows))
        if group_v is not None:
            meta["group_voltage_columns"] = group_names
    return Recording(
        time_s=np.ascontiguousarray(data.t),
        voltage_v=np.ascontiguousarray(data.v),
        current_a=np.ascontiguousarray(data.i),
        temperature_k=None if temperature_k is None else np.ascontiguousarray(temperature_k),
        source=source,
        metadata=meta,
        group_voltage_v=None if group_v is None else np.ascontiguousarray(group_v),
    )


def _drop_bad_rows(table: _Table, row_idx: np.ndarray, data: _Rows, *, source: str, drop_nan: bool,
                   meta: dict[str, Any]) -> _Rows:
    """Rows with an empty or non-finite time/voltage/current or a non-positive voltage: an error, or dropped
    (counted in ``meta``) with ``drop_nan``."""
    rows, t, v, i = data.rows, data.t, data.v, data.i
    bad = ~(np.isfinite(t) & np.isfinite(v) & np.isfinite(i))
    if bad.any() and not drop_nan:
        k = int(np.argmax(bad))
        cols = [name for name, arr in (("time_s", t), ("voltage_V", v), ("current_A", i)) if not np.isfinite(arr[k])]
        cells = table.rows[row_idx[k]]
        raw = [cells[table.index[c]] if table.index[c] < len(cells) else "" for c in cols]
        what = ", ".join(f"{c}={r.strip()!r}" for c, r in zip(cols, raw))
        raise InputDataError(
            f"{source}: {_where(table, k, rows)}: empty or non-finite value ({what}); "
            f"{int(bad.sum())} such row(s)" + option_hint("drop_nan", True, "to drop them")
        )
    nonpositive = np.isfinite(v) & (v <= 0)
    if nonpositive.any() and not drop_nan:
        k = int(np.argmax(nonpositive))
        raise InputDataError(
            f"{source}: {_where(table, k, rows)}: voltage_V {v[k]!r} is not positive "
            f"({int(nonpositive.sum())} such row(s))" + option_hint("drop_nan", True, "to drop them")
        )
    bad |= nonpositive
    if not bad.any():
        return data
    meta["dropped_nan_rows"] = int(bad.sum())
    kept = data.take(~bad)
    if not len(kept.t):
        raise InputDataError(f"{source}: no rows left after dropping rows with empty time_s/voltage_V/current_A")
    return kept


def _drop_repeated_times(table: _Table, data: _Rows, *, source: str, duplicate_times: str,
                         meta: dict[str, Any]) -> _Rows:
    """Time going backwards: an error; a repeated time: an error, or the first or last row of each kept
    (``duplicate_times``; counted in ``meta``)."""
    rows, t = data.rows, data.t
    dt = np.diff(t)
    if (dt < 0).any() or ((dt == 0).any() and duplicate_times == "error"):
        k = int(np.argmax(dt <= 0)) + 1 if duplicate_times == "error" else int(np.argmax(dt < 0)) + 1
        problem = _order_problem(table, t[k], t[k - 1], table.lines[rows[k - 1] - 1], meta)
        raise InputDataError(f"{source}: {_where(table, k, rows)}: {problem}")
    if not (dt == 0).any():
        return data
    same_next = np.append(dt == 0, False)  # row k has the same time as row k+1
    same_prev = np.insert(dt == 0, 0, False)  # row k has the same time as row k-1
    keep = ~same_next if duplicate_times == "keep_last" else ~same_prev
    meta["dropped_duplicate_time_rows"] = int((~keep).sum())
    return data.take(keep)


def _order_problem(table: _Table, t_now: float, t_prev: float, prev_line: int, meta: dict[str, Any]) -> str:
    """Why ``time_s`` ``t_now`` may not follow ``t_prev`` (given on ``prev_line``), with the way out."""
    if t_now == t_prev:
        return (f"time_s {t_now!r} repeats the time of line {prev_line} (time_s must be strictly increasing; "
                "repeated timestamps are common at step changes in cycler exports)"
                + option_hint("duplicate_times", "keep_last", "to keep the last row of each repeated time"))
    text = (f"time_s {t_now!r} is before {t_prev!r} on line {prev_line}: time goes backwards "
            "(time_s must be strictly increasing)")
    group_like = [c for c in ("soc_label", "cell", "cycle", "step", "test", "record", "run") if c in table.index]
    if group_like and "group" not in meta:
        split = "split the file by them" if in_cli() else "use load_csv_groups"
        text += f"; columns {', '.join(group_like)} suggest several records in one file: {split}"
    return text


def _check_options(duplicate_times: str) -> None:
    if duplicate_times not in DUPLICATE_TIME_POLICIES:
        raise InputDataError(
            f"duplicate_times must be one of {', '.join(DUPLICATE_TIME_POLICIES)}, got {duplicate_times!r}"
        )


def load_csv(
    path: str | os.PathLike[str],
    *,
    expect_discharge: bool = True,
    drop_nan: bool = False,
    duplicate_times: str = "error",
    temperature_column: str | None = None,
) -> Recording:
    """Load one recording from a measurement CSV (see the module docstring for the format).

    Parameters
    ----------
    path : str or os.PathLike
        CSV file with ``time_s``, ``voltage_V``, ``current_A`` columns.
    expect_discharge : bool
        Check that ``current_A > 0`` means discharge (:func:`~battery_predictor.io.validation.check_current_sign`).
        Pass False for recordings where the check cannot decide (pure charge
        with no usable voltage response, synthetic data with constant voltage).
    drop_nan : bool
        Drop rows with an empty/NaN/inf time, voltage or current or a voltage
        <= 0 V (a logging glitch), and fill
        temperature gaps from the nearest measured sample, instead of raising.
        The counts are in ``metadata["dropped_nan_rows"]`` and
        ``metadata["filled_temperature_rows"]``.
    duplicate_times : {"error", "keep_first", "keep_last"}
        What to do with consecutive rows that have the same ``time_s``.
    temperature_column : str, optional
        Use this column as temperature (name must end in ``_C`` or ``_K``)
        instead of the first match in :data:`TEMPERATURE_COLUMNS`.

    Returns
    -------
    Recording
        ``source`` is the path; ``metadata`` holds ``temperature_column`` and
        the counts of rows dropped or filled by the options above.

    Raises
    ------
    InputDataError
        One line naming the file, the line/column and the problem.
    """
    _check_options(duplicate_times)
    p = Path(path)
    table = _read_table(p)
    temp_name, temp_unit = _find_columns(table, temperature_column)
    names = [*REQUIRED_COLUMNS, *([temp_name] if temp_name else []), *_group_columns(table)]
    columns = {name: _parse_column(table, name) for name in names}
    return _build(
        table,
        np.arange(len(table.rows)),
        columns,
        temp_name,
        temp_unit,
        source=str(p),
        expect_discharge=expect_discharge,
        drop_nan=drop_nan,
        duplicate_times=duplicate_times,
        metadata={},
    )


def load_csv_groups(
    path: str | os.PathLike[str],
    by: Sequence[str],
    *,
    expect_discharge: bool = True,
    drop_nan: bool = False,
    duplicate_times: str = "error",
    temperature_column: str | None = None,
) -> dict[tuple[str, ...], Recording]:
    """Load a long-format CSV that holds several records, one per value of the ``by`` columns.

    Each record is validated like :func:`load_csv` (line numbers refer to the
    whole file). Records keep the order of their first row in the file.

    Returns
    -------
    dict
        ``{(value_of_by[0], ...): Recording}``; each Recording has
        ``metadata["group"] = {column: value}`` and a ``source`` like
        ``"file.csv [soc_label=SoC5, cell=Cell1]"``.
    """
    _check_options(duplicate_times)
    p = Path(path)
    by = [by] if isinstance(by, str) else list(by)
    if not by:
        raise InputDataError(f"{p}: load_csv_groups needs at least one grouping column")
    table = _read_table(p)
    missing = [c for c in by if c not in table.index]
    if missing:
        raise InputDataError(
            f"{p}: missing grouping column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(c) for c in missing)}; found: {', '.join(table.header)}"
        )
    temp_name, temp_unit = _find_columns(table, temperature_column)
    names = [*REQUIRED_COLUMNS, *([temp_name] if temp_name else []), *_group_columns(table)]
    columns = {name: _parse_column(table, name) for name in names}
    keys_per_column = [[cell.strip() for cell in table.column(c)] for c in by]
    groups: dict[tuple[str, ...], list[int]] = {}
    for k, key in enumerate(zip(*keys_per_column)):
        groups.setdefault(tuple(key), []).append(k)
    out: dict[tuple[str, ...], Recording] = {}
    for key, idx in groups.items():
        label = ", ".join(f"{c}={val}" for c, val in zip(by, key))
        out[key] = _build(
            table,
            np.asarray(idx),
            columns,
            temp_name,
            temp_unit,
            source=f"{p} [{label}]",
            expect_discharge=expect_discharge,
            drop_nan=drop_nan,
            duplicate_times=duplicate_times,
            metadata={"group": dict(zip(by, key))},
        )
    return out


def _default_file_mode() -> int:
    """The mode ``open()`` gives a new file (0666 less the umask); ``mkstemp`` would leave 0600."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def save_csv(recording: Recording, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write ``time_s,voltage_V,current_A[,temperature_C][,group1_voltage_V,...]`` (current positive = discharge).

    Floats are written with the shortest representation that reads back to
    the same value, so :func:`load_csv` returns identical time, voltage and
    current arrays (temperature goes through °C and back, equal to ~1e-13 K).
    NaN temperatures and group voltages are written as empty cells. ``recording.metadata`` is not
    stored (CSV has no place for it; use a bag to keep it). The file is written
    to a temporary file first and renamed, so a failed write leaves no partial
    CSV behind.
    """
    p = Path(path)
    if p.exists() and (p.is_dir() or not overwrite):
        if p.is_dir():
            raise InputDataError(f"{p}: is a directory, expected a CSV file name")
        raise InputDataError(f"{p}: already exists" + option_hint("overwrite", True, "to replace it"))
    if not p.parent.is_dir():
        raise InputDataError(f"{p}: directory {p.parent} does not exist")
    header = ["time_s", "voltage_V", "current_A"]
    cols = [np.asarray(recording.time_s, float), np.asarray(recording.voltage_v, float), np.asarray(recording.current_a, float)]
    if recording.temperature_k is not None:
        header.append("temperature_C")
        cols.append(np.asarray(kelvin_to_celsius(np.asarray(recording.temperature_k, float))))
    if recording.group_voltage_v is not None:
        groups = np.asarray(recording.group_voltage_v, float)
        header.extend(f"group{k + 1}_voltage_V" for k in range(groups.shape[1]))
        cols.extend(groups.T)

    def fmt(x: float) -> str:
        return repr(x) if math.isfinite(x) else ""

    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(",".join(header) + "\n")
            for values in zip(*(c.tolist() for c in cols)):
                fh.write(",".join(fmt(x) for x in values) + "\n")
        os.chmod(tmp, _default_file_mode())
        os.replace(tmp, p)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise InputDataError(f"{p}: cannot write CSV ({exc.strerror or exc})") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p
