"""Plausibility checks shared by the CSV and bag readers, run on the parsed samples.

Both readers parse their format into time (s), voltage (V), current (A, > 0 = discharge) and an
optional temperature; :func:`check_samples` then checks units, fills or rejects temperature gaps,
converts the temperature to K and checks it, and (when asked) the current sign convention. Every
problem raises :class:`~battery_predictor.errors.InputDataError` with a one-line message.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from battery_predictor.conventions import celsius_to_kelvin
from battery_predictor.errors import InputDataError, option_hint

#: Robot packs stay below this; a larger median voltage means millivolts.
MAX_PLAUSIBLE_VOLTAGE_V = 100.0
#: A larger median of the non-zero |current| means milliamperes.
MAX_PLAUSIBLE_CURRENT_A = 1000.0
#: A larger median group (cell) voltage means millivolts (no lithium-ion cell reaches it).
MAX_PLAUSIBLE_GROUP_VOLTAGE_V = 10.0
#: Plausible range of a measured cell/ambient temperature in °C.
PLAUSIBLE_TEMPERATURE_RANGE_C = (-60.0, 150.0)


def voltage_response_score(voltage_v: np.ndarray, current_a: np.ndarray) -> float:
    """How well the voltage responds to the current as a discharge-positive current should.

    Two pieces of physics, both independent of the state of charge:

    * at current steps the terminal voltage jumps the other way (ohmic drop:
      ``dV ≈ -R dI``);
    * while current flows, the voltage drifts down when ``current_a > 0``
      (discharge) and up when ``current_a < 0`` (charge).

    Each gives a normalised score in [-1, 1] (sum of the signed voltage changes
    over the sum of their magnitudes); the result is their mean. It is
    antisymmetric in the current sign: about +1 for a correct recording, about
    -1 for one with the sign flipped, 0 when there is no evidence.
    """
    v = np.asarray(voltage_v, dtype=float)
    i = np.asarray(current_a, dtype=float)
    if len(i) < 3:
        return 0.0
    i_max = float(np.max(np.abs(i)))
    if not np.isfinite(i_max) or i_max <= 0.0:
        return 0.0
    a, b = i[:-1], i[1:]
    dv = np.diff(v)
    di = np.diff(i)
    scores = []
    flowing = (np.abs(a) > 0.05 * i_max) & (np.abs(b) > 0.05 * i_max) & (np.sign(a) == np.sign(b))
    den = float(np.sum(np.abs(dv[flowing])))
    if den > 0.0:
        scores.append(-float(np.sum(np.sign(a[flowing]) * dv[flowing])) / den)
    steps = np.abs(di) > 0.1 * i_max
    den = float(np.sum(np.abs(dv[steps])))
    if den > 0.0:
        scores.append(-float(np.sum(np.sign(di[steps]) * dv[steps])) / den)
    return float(np.mean(scores)) if scores else 0.0


def check_current_sign(time_s: np.ndarray, voltage_v: np.ndarray, current_a: np.ndarray, *, source: str) -> None:
    """Raise :class:`InputDataError` when ``current_a`` looks like it is negative while discharging.

    Rule (documented in the package README): the sign is rejected when

    * the recording looks like a *charge* by throughput -- the charge integral
      is negative **and** more than 60 % of the non-zero samples (``|I|`` above
      1 % of the peak) are negative -- and the voltage response
      (:func:`voltage_response_score`) does not clearly confirm the convention
      (score below +0.3); **or**
    * the voltage response clearly contradicts the convention (score below
      -0.3: the voltage rises while ``current_a > 0`` and jumps up when it
      steps up).

    So a constant-current discharge followed by a longer CC-CV recharge (net
    charge slightly negative, most samples negative, e.g. the LG M50 rate
    tests) passes because its voltage confirms the sign, while the same file
    with the sign flipped is rejected.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_v, dtype=float)
    i = np.asarray(current_a, dtype=float)
    if len(i) < 3:
        return
    i_max = float(np.max(np.abs(i)))
    if i_max <= 0.0:
        return
    charge_ah = float(np.sum(0.5 * (i[1:] + i[:-1]) * np.diff(t))) / 3600.0  # trapezoidal
    nonzero = i[np.abs(i) > 0.01 * i_max]
    negative_fraction = float(np.mean(nonzero < 0.0)) if len(nonzero) else 0.0
    score = voltage_response_score(v, i)
    looks_like_charge = charge_ah < 0.0 and negative_fraction > 0.6
    if (looks_like_charge and score < 0.3) or score < -0.3:
        raise InputDataError(
            f"{source}: current_A seems to use the wrong sign convention (net charge {charge_ah:+.4g} Ah, "
            f"{100 * negative_fraction:.0f} % of the non-zero samples negative, voltage-response score {score:+.2f}, "
            "where +1 means the voltage drops when current_A rises); current_A > 0 must mean DISCHARGE: "
            "flip the sign of the column (sensor_msgs/BatteryState and many cyclers use negative = discharge)"
            + option_hint("expect_discharge", False, "to skip this check")
        )


def check_units(voltage_v: np.ndarray, current_a: np.ndarray, *, source: str) -> None:
    """Raise :class:`InputDataError` when voltage/current look like mV/mA."""
    v_med = float(np.median(voltage_v)) if len(voltage_v) else 0.0
    if v_med > MAX_PLAUSIBLE_VOLTAGE_V:
        raise InputDataError(
            f"{source}: column voltage_V has median {v_med:.6g}, which looks like millivolts; convert to volts"
        )
    abs_i = np.abs(current_a)
    nonzero = abs_i[abs_i > 0.0]
    i_med = float(np.median(nonzero)) if len(nonzero) else 0.0
    if i_med > MAX_PLAUSIBLE_CURRENT_A:
        raise InputDataError(
            f"{source}: column current_A has median |I| {i_med:.6g}, which looks like milliamperes; convert to amperes"
        )


def check_temperature_k(temperature_k: np.ndarray, *, source: str, column: str) -> None:
    """Raise :class:`InputDataError` when a temperature (in K) is implausible for its declared unit."""
    finite = temperature_k[np.isfinite(temperature_k)]
    if not len(finite):
        return
    med_c = float(np.median(finite)) - 273.15
    lo, hi = PLAUSIBLE_TEMPERATURE_RANGE_C
    if not lo <= med_c <= hi:
        if column.endswith("_C") and med_c > hi:
            hint = "; the values look like kelvin: name the column temperature_K or convert to °C"
        elif column.endswith("_K") and med_c < lo:
            hint = "; the values look like °C: name the column temperature_C or convert to K"
        else:
            hint = ""
        raise InputDataError(
            f"{source}: column {column!r} has median {med_c:.4g} °C, outside the plausible {lo:g}..{hi:g} °C{hint}"
        )


def check_group_voltages(group_v: np.ndarray, *, source: str, columns: Sequence[str], drop_nan: bool,
                         where: Callable[[int], str]) -> np.ndarray | None:
    """The measured series-group voltages (V), checked; None when no group has a finite value.

    A missing or non-finite reading stays NaN (a group sensor that drops out never discards the
    pack's voltage/current sample). A reading <= 0 V is an error (``drop_nan``: made NaN); a median
    above :data:`MAX_PLAUSIBLE_GROUP_VOLTAGE_V` means millivolts.

    Parameters
    ----------
    group_v : numpy.ndarray
        Shape (n_samples, n_groups), NaN where missing.
    source : str
        The start of every message.
    columns : sequence of str
        The groups' names in messages (CSV columns, or e.g. ``cell_voltage[0]``).
    drop_nan : bool
        Make non-positive readings NaN instead of raising.
    where : callable
        ``where(k)``: the position of sample ``k`` in messages (a CSV line, a bag sample).
    """
    g = np.array(group_v, dtype=float, ndmin=2)
    g[~np.isfinite(g)] = np.nan
    if not np.isfinite(g).any():
        return None
    nonpositive = g <= 0.0
    if nonpositive.any():
        if not drop_nan:
            k, j = (int(x) for x in np.argwhere(nonpositive)[0])
            raise InputDataError(
                f"{source}: {where(k)}: {columns[j]} {g[k, j]!r} is not positive ({int(nonpositive.sum())} such "
                "reading(s))" + option_hint("drop_nan", True, "to ignore them")
            )
        g[nonpositive] = np.nan
    finite = g[np.isfinite(g)]
    med = float(np.median(finite)) if finite.size else 0.0
    if med > MAX_PLAUSIBLE_GROUP_VOLTAGE_V:
        raise InputDataError(
            f"{source}: group voltages ({columns[0]}...) have median {med:.6g}, which looks like millivolts; convert to volts"
        )
    return g if np.isfinite(g).any() else None


def nearest_index(t_src: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Index into the sorted times ``t_src`` (s) of the nearest sample to each of ``t_query`` (ties -> earlier)."""
    if len(t_src) == 1:
        return np.zeros(len(t_query), dtype=int)
    j = np.clip(np.searchsorted(t_src, t_query), 1, len(t_src) - 1)
    left = j - 1
    return np.where(np.abs(t_query - t_src[left]) <= np.abs(t_src[j] - t_query), left, j)


def fill_nearest(time_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` with each NaN/inf replaced by the value of the nearest finite sample in time (s)."""
    good = np.flatnonzero(np.isfinite(values))
    if len(good) == len(values):
        return values
    return values[good[nearest_index(time_s[good], time_s)]]


def check_samples(
    time_s: np.ndarray,
    voltage_v: np.ndarray,
    current_a: np.ndarray,
    temperature: np.ndarray | None,
    *,
    source: str,
    column: str,
    celsius: bool,
    drop_nan: bool,
    gap_message: Callable[[int, int], str],
    expect_discharge: bool,
) -> tuple[np.ndarray | None, int]:
    """The post-parse checks of a recording's samples; returns the temperature in K and the gaps filled.

    Parameters
    ----------
    time_s, voltage_v, current_a : numpy.ndarray
        Strictly increasing time (s), voltage (V), current (A, > 0 = discharge), all finite.
    temperature : numpy.ndarray or None
        Temperature as read (°C when ``celsius``, else K), NaN where missing; None: not measured.
    source : str
        Where the samples come from, the start of every message.
    column : str
        The temperature's name in messages (a CSV column, or e.g. ``"temperature (°C)"``).
    celsius : bool
        Whether ``temperature`` is in °C.
    drop_nan : bool
        Fill temperature gaps from the nearest measured sample instead of raising.
    gap_message : callable
        ``gap_message(k, n)``: the error for the first gap at sample ``k`` of ``n`` gaps.
    expect_discharge : bool
        Run :func:`check_current_sign`.

    Returns
    -------
    temperature_k : numpy.ndarray or None
        Temperature in K, None when there is none or it is missing on every sample.
    filled : int
        Temperature samples filled from their nearest neighbour.
    """
    check_units(voltage_v, current_a, source=source)
    temperature_k, filled = None, 0
    if temperature is not None and np.isfinite(temperature).any():
        finite = np.isfinite(temperature)
        if not finite.all():
            if not drop_nan:
                raise InputDataError(gap_message(int(np.argmax(~finite)), int((~finite).sum())))
            filled = int((~finite).sum())
            temperature = fill_nearest(time_s, temperature)
        temperature_k = np.asarray(celsius_to_kelvin(temperature) if celsius else temperature, dtype=float)
        check_temperature_k(temperature_k, source=source, column=column)
    if expect_discharge:
        check_current_sign(time_s, voltage_v, current_a, source=source)
    return temperature_k, filled
