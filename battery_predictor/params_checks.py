"""Physical-range checks of pack params, and of recordings and node settings against a pack.

:func:`check_physical` runs on every params file :mod:`battery_predictor.params` loads. The rules:

* ``pack``: ``series`` 1..:data:`MAX_SERIES`, ``parallel`` 1..:data:`MAX_PARALLEL`; voltages and
  capacity > 0; ``min_voltage_v`` < ``nominal_voltage_v`` < ``max_voltage_v``; each pack voltage per
  cell in series within the cell's window ``[Lower voltage cut-off - CELL_VOLTAGE_SLACK_V,
  Upper voltage cut-off + CELL_VOLTAGE_SLACK_V]``; ``nominal_capacity_ah`` within a factor
  :data:`CAPACITY_FACTOR` of ``parallel x Nominal cell capacity [A.h]``.
* cell values (``manual``, ``fitted``, ``extra``), by unit: see :data:`POSITIVE_UNITS`,
  :data:`NON_NEGATIVE_UNITS`, :data:`TEMPERATURE_RANGE_K`, :data:`CELL_VOLTAGE_RANGE_V`; volume
  fractions, porosities and other fractions in (0, 1]; cut-offs and open-circuit voltages at 0 % /
  100 % SOC in increasing order; initial electrode concentrations at most the maximum.
* ``interconnect``: each resistance at most :data:`MAX_INTERCONNECT_OHM`.
* ``thresholds`` and ``operating``, by unit suffix: voltages (``*_voltage_v``) within the pack's voltage
  window (:func:`pack_voltage_window_v`), other ``_v`` values (differences) within +- its top, currents, durations, masses, lengths >= 0, temperatures
  (``_k``, ``_c``) within :data:`TEMPERATURE_RANGE_K`, ``_pct`` 0..100, ``_fraction`` 0..1,
  ``_c_rate`` and ``_hz`` > 0.

Every violation raises :class:`~battery_predictor.errors.ParamsError` with one line naming the file,
the key, the value and the allowed range.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING

import numpy as np

from battery_predictor.errors import InputDataError, ParamsError

if TYPE_CHECKING:
    from battery_predictor.params import PackParams
    from battery_predictor.recording import Recording

#: Cells in series: 250 x 4.2 V is above 1000 V, beyond any battery this package models.
MAX_SERIES = 250
#: Strings in parallel; liionpack simulates every cell, so a typo here costs minutes and gigabytes.
MAX_PARALLEL = 200
#: ``pack.nominal_capacity_ah`` may differ from ``parallel x`` the cell's nominal capacity by this factor.
CAPACITY_FACTOR = 2.0
#: A pack voltage per cell may lie this far outside the cell's cut-off window, V.
CELL_VOLTAGE_SLACK_V = 0.5
#: Largest plausible interconnect resistance (busbar, connection, internal, terminal), Ohm.
MAX_INTERCONNECT_OHM = 10.0
#: Plausible temperatures (ambient, initial, reference), K: -100 degC .. 200 degC.
TEMPERATURE_RANGE_K = (173.15, 473.15)
#: Cut-off and open-circuit voltages of a lithium-ion cell, V.
CELL_VOLTAGE_RANGE_V = (0.5, 5.5)
#: The median voltage per cell of a recording must lie within this factor range of the cell's cut-off window.
RECORDING_VOLTAGE_FACTORS = (0.75, 1.15)
#: PyBaMM units whose values must be > 0.
POSITIVE_UNITS = frozenset({
    "A.h", "m2", "m3", "m2.s-1", "S.m-1", "kg.m-3", "J.kg-1.K-1", "W.m-1.K-1", "m-1", "F.m-2", "m.s-1", "Pa",
    "kg.mol-1", "C.mol-1",
})
#: PyBaMM units whose values must be >= 0.
NON_NEGATIVE_UNITS = frozenset({"Ohm", "Ohm.m", "A.m-2", "J.mol-1", "mol.m-3", "W.m-2.K-1", "s-1", "m"})
#: Lengths that must be > 0 (a current collector may be 0 m thick).
_POSITIVE_LENGTH = re.compile(r"thickness|radius|height|width|length", re.IGNORECASE)
#: Dimensionless fractions in (0, 1].
_FRACTION = re.compile(r"volume fraction|porosity|transference number|capacity fraction|transport efficiency|"
                       r"emissivity|Initial SoC|Initial State of Charge", re.IGNORECASE)
_CELL_VOLTAGE_KEYS = frozenset({"Lower voltage cut-off [V]", "Open-circuit voltage at 0% SOC [V]",
                                "Open-circuit voltage at 100% SOC [V]", "Upper voltage cut-off [V]"})
_UNIT_BRACKET = re.compile(r"\[(?P<unit>[^\]]*)\]\s*$")


def _fail(source: str, key: str, value: float, rule: str) -> ParamsError:
    return ParamsError(f"{source}: key '{key}': {value:g} {rule}")


def _check_range(source: str, key: str, value: float, low: float | None, high: float | None, why: str = "",
                 *, low_open: bool = False) -> None:
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and value > high
    if not (too_low or too_high):
        return
    if low is not None and high is not None:
        rule = f"is outside {'(' if low_open else '['}{low:g}, {high:g}]"
    elif low is not None:
        rule = f"must be {'>' if low_open else '>='} {low:g}"
    else:
        rule = f"must be <= {high:g}"
    raise _fail(source, key, value, rule + (f" ({why})" if why else ""))


# ----------------------------------------------------------------------------------------- pack
def _check_counts(params: PackParams) -> None:
    _check_range(params.source, "pack.series", params.series, 1, MAX_SERIES, "cells in series")
    _check_range(params.source, "pack.parallel", params.parallel, 1, MAX_PARALLEL, "strings in parallel")


def _check_pack_voltages(params: PackParams, cell_low_v: float, cell_high_v: float) -> None:
    info = params.pack_info
    for key, value in info.items():
        _check_range(params.source, f"pack.{key}", value, 0.0, None, low_open=True)
    order = [k for k in ("min_voltage_v", "nominal_voltage_v", "max_voltage_v") if k in info]
    for lower, upper in zip(order, order[1:]):
        if not info[lower] < info[upper]:
            raise ParamsError(f"{params.source}: key 'pack.{upper}': {info[upper]:g} must be above "
                              f"pack.{lower} {info[lower]:g}")
    low = cell_low_v - CELL_VOLTAGE_SLACK_V
    high = cell_high_v + CELL_VOLTAGE_SLACK_V
    for key in order:
        per_cell = info[key] / params.series
        if not low <= per_cell <= high:
            raise ParamsError(
                f"{params.source}: key 'pack.{key}': {info[key]:g} V is {per_cell:.4g} V per cell for "
                f"{params.series} cells in series, outside the cell's {low:g}..{high:g} V (cut-offs "
                f"{cell_low_v:g}..{cell_high_v:g} V); check pack.series")


def _check_pack_capacity(params: PackParams, cell_capacity_ah: float | None) -> None:
    pack_ah = params.pack_info.get("nominal_capacity_ah")
    if pack_ah is None or cell_capacity_ah is None or cell_capacity_ah <= 0:
        return
    expected = params.parallel * cell_capacity_ah
    if not expected / CAPACITY_FACTOR <= pack_ah <= expected * CAPACITY_FACTOR:
        raise ParamsError(
            f"{params.source}: key 'pack.nominal_capacity_ah': {pack_ah:g} Ah does not match {params.parallel} "
            f"strings in parallel x {cell_capacity_ah:g} Ah per cell = {expected:g} Ah (allowed within a factor "
            f"{CAPACITY_FACTOR:g}); check pack.parallel and 'Nominal cell capacity [A.h]'")


# ----------------------------------------------------------------------------------------- cell
def _unit(key: str) -> str | None:
    m = _UNIT_BRACKET.search(key)
    return m.group("unit") if m else None


def check_cell_value(key: str, value: float, source: str) -> None:
    """Raise :class:`ParamsError` unless one PyBaMM value is physically possible for its unit and name."""
    unit = _unit(key)
    where = f"cell.{key}"
    if _FRACTION.search(key):
        _check_range(source, where, value, 0.0, 1.0, "a fraction", low_open=True)
    elif unit == "K":
        _check_range(source, where, value, *TEMPERATURE_RANGE_K, "a temperature in K")
    elif key in _CELL_VOLTAGE_KEYS:
        _check_range(source, where, value, *CELL_VOLTAGE_RANGE_V, "a lithium-ion cell voltage")
    elif unit == "m" and _POSITIVE_LENGTH.search(key) and "current collector" not in key:
        _check_range(source, where, value, 0.0, None, "a length", low_open=True)
    elif unit in POSITIVE_UNITS:
        _check_range(source, where, value, 0.0, None, f"a quantity in {unit}", low_open=True)
    elif unit in NON_NEGATIVE_UNITS:
        _check_range(source, where, value, 0.0, None, f"a quantity in {unit}")
    elif key.startswith("Number of"):
        _check_range(source, where, value, 1.0, None, "a count")


def _cell_value_source(params: PackParams, key: str) -> str:
    for section in ("extra", "fitted", "manual"):
        if key in getattr(params, section):
            return f"cell.{section}.{key}"
    return f"{params.base_parameter_set} '{key}'"


def _check_cell_order(params: PackParams, pv: Mapping[str, object]) -> None:
    """Cut-offs and open-circuit voltages at 0 % / 100 % SOC in increasing order; initial concentrations <= maximum."""
    pairs = (("Lower voltage cut-off [V]", "Upper voltage cut-off [V]"),
             ("Open-circuit voltage at 0% SOC [V]", "Open-circuit voltage at 100% SOC [V]"))
    for k_lo, k_hi in pairs:
        v_lo, v_hi = _cell_scalar(pv, k_lo), _cell_scalar(pv, k_hi)
        if v_lo is not None and v_hi is not None and not v_lo < v_hi:
            raise ParamsError(f"{params.source}: key '{_cell_value_source(params, k_hi)}': {v_hi:g} V must be above "
                              f"'{k_lo}' {v_lo:g} V")
    for domain in ("negative", "positive"):
        key = f"Initial concentration in {domain} electrode [mol.m-3]"
        c0 = _cell_scalar(pv, key)
        cmax = _cell_scalar(pv, f"Maximum concentration in {domain} electrode [mol.m-3]")
        if c0 is not None and cmax is not None and c0 > cmax:
            raise ParamsError(f"{params.source}: key '{_cell_value_source(params, key)}': {c0:g} is above the "
                              f"electrode's maximum concentration {cmax:g} mol.m-3")


def _cell_scalar(pv: Mapping[str, object], key: str) -> float | None:
    value = pv.get(key)
    return float(value) if isinstance(value, (int, float)) else None


# ------------------------------------------------------------------------ thresholds, operating
def pack_voltage_window_v(params: PackParams) -> tuple[float, float]:
    """The pack's voltage window, V: ``pack.min/max_voltage_v``, else ``series x`` the cell's cut-offs."""
    pv = params.parameter_values()
    cell_low = _cell_scalar(pv, "Lower voltage cut-off [V]") or CELL_VOLTAGE_RANGE_V[0]
    cell_high = _cell_scalar(pv, "Upper voltage cut-off [V]") or CELL_VOLTAGE_RANGE_V[1]
    low = params.pack_info.get("min_voltage_v", params.series * cell_low)
    high = params.pack_info.get("max_voltage_v", params.series * cell_high)
    return float(low), float(high)


def check_voltage_in_window(key: str, value_v: float, params: PackParams, source: str | None = None) -> None:
    """Raise :class:`ParamsError` unless ``value_v`` lies within the pack's voltage window.

    For decision thresholds (``runtime_cutoff_voltage_v``, ``route_min_voltage_v``...), here and in node
    parameters that override them (``source`` then names the node parameter's origin).
    """
    low, high = pack_voltage_window_v(params)
    if not low <= value_v <= high:
        raise ParamsError(f"{source or params.source}: key '{key}': {value_v:g} V is outside the pack's voltage "
                          f"window {low:g}..{high:g} V ({params.name}, {params.series} cells in series)")


def _check_suffixed(params: PackParams, section: str, values: Mapping[str, float]) -> None:
    src = params.source
    for key, value in values.items():
        where = f"{section}.{key}"
        if key.endswith("_m_s"):
            _check_range(src, where, value, 0.0, None)
        elif key.endswith("_voltage_v"):
            check_voltage_in_window(where, value, params)
        elif key.endswith("_v"):  # a voltage difference (margin, hysteresis)
            high = pack_voltage_window_v(params)[1]
            _check_range(src, where, value, -high, high, "a voltage difference within the pack's voltage")
        elif key.endswith("_k"):
            _check_range(src, where, value, *TEMPERATURE_RANGE_K, "a temperature in K")
        elif key.endswith("_c") and not key.endswith("_c_rate"):
            _check_range(src, where, value, TEMPERATURE_RANGE_K[0] - 273.15, TEMPERATURE_RANGE_K[1] - 273.15,
                         "a temperature in degC")
        elif key.endswith("_pct"):
            _check_range(src, where, value, 0.0, 100.0, "a percentage")
        elif key.endswith("_fraction"):
            _check_range(src, where, value, 0.0, 1.0, "a fraction")
        elif key.endswith(("_c_rate", "_hz")):
            _check_range(src, where, value, 0.0, None, low_open=True)
        else:  # _a, _s, _ah, _ohm, _kg, _m, _w: magnitudes
            _check_range(src, where, value, 0.0, None)


# ---------------------------------------------------------------------------------------- entry
def check_physical(params: PackParams) -> None:
    """Raise :class:`ParamsError` on the first physically impossible value (rules in the module docstring)."""
    _check_counts(params)
    for section in ("manual", "fitted", "extra"):
        for key, value in getattr(params, section).items():
            check_cell_value(key, value, params.source)
    pv = params.parameter_values()
    _check_cell_order(params, pv)
    cell_low = _cell_scalar(pv, "Lower voltage cut-off [V]")
    cell_high = _cell_scalar(pv, "Upper voltage cut-off [V]")
    if cell_low is not None and cell_high is not None:
        _check_pack_voltages(params, cell_low, cell_high)
    _check_pack_capacity(params, _cell_scalar(pv, "Nominal cell capacity [A.h]"))
    for key, value in params.interconnect.items():
        _check_range(params.source, f"interconnect.{key}", value, 0.0, MAX_INTERCONNECT_OHM, "Ohm",
                     low_open=True)
    _check_suffixed(params, "thresholds", params.thresholds)
    _check_suffixed(params, "operating", params.operating)


def check_recordings_against_pack(params: PackParams, recordings: Iterable[Recording]) -> None:
    """Raise :class:`InputDataError` when a recording's voltage cannot come from this pack.

    The median measured voltage per cell in series must lie within
    :data:`RECORDING_VOLTAGE_FACTORS` of the cell's cut-off window (a 4S recording against a
    15S pack, or a wrong ``pack.series``, fails).
    """
    pv = params.parameter_values()
    cell_low = _cell_scalar(pv, "Lower voltage cut-off [V]") or CELL_VOLTAGE_RANGE_V[0]
    cell_high = _cell_scalar(pv, "Upper voltage cut-off [V]") or CELL_VOLTAGE_RANGE_V[1]
    low, high = cell_low * RECORDING_VOLTAGE_FACTORS[0], cell_high * RECORDING_VOLTAGE_FACTORS[1]
    for rec in recordings:
        voltage = np.asarray(rec.voltage_v, dtype=float)
        if not len(voltage):
            continue
        median_v = float(np.median(voltage))
        per_cell = median_v / params.series
        if not (math.isfinite(per_cell) and low <= per_cell <= high):
            raise InputDataError(
                f"{rec.source}: median voltage {median_v:.4g} V is {per_cell:.4g} V per cell for the "
                f"{params.series} cells in series of {params.source}, outside the cell's plausible "
                f"{low:.3g}..{high:.3g} V: the recording is not of this pack (or pack.series is wrong)")


def check_node_voltages(source: str, params: PackParams, voltages: Mapping[str, float]) -> None:
    """Raise :class:`ParamsError` unless every set node voltage (``cutoff_voltage_v``...) lies in the pack's window.

    0 and NaN mean "from the params file" and are not checked.
    """
    for key, value in voltages.items():
        if value and math.isfinite(value):
            check_voltage_in_window(key, float(value), params, source=source)


def check_monitor_range(min_voltage_v: float, max_voltage_v: float, params: PackParams, source: str) -> None:
    """Raise :class:`ParamsError` unless the monitor's accepted voltages cover the pack's voltage window.

    A monitor range that misses the pack's window rejects the pack's own samples (a Ranger
    37.5-58 V monitor in front of a 12-16.4 V temi pack rejects every sample).
    """
    low, high = pack_voltage_window_v(params)
    if min_voltage_v > low or max_voltage_v < high:
        raise ParamsError(
            f"{source}: battery_monitor min_voltage_v..max_voltage_v {min_voltage_v:g}..{max_voltage_v:g} V does "
            f"not cover the voltage window {low:g}..{high:g} V of the pack {params.name} ({params.source}); "
            "the monitor would reject the pack's own samples")
