"""A cell's open-circuit voltage from a low-rate test, and the positive OCP that reproduces it.

The base parameter sets' OCPs belong to other cells (Chen2020 is an LG M50, NMC/graphite); on
another chemistry they put the model's voltage tens of millivolts off at the same charge, and the
state of charge calibrated from a voltage inherits that error. A C/20 discharge (and charge)
measures the full cell's OCV against the charge drawn:

* :func:`pseudo_ocv` takes the low-rate discharge branch, raised by the voltage step at its start
  (the ohmic and kinetic drop the model adds itself). The discharge hysteresis stays in: the robots'
  predictions are discharges. The mean of the discharge and a following charge branch is the
  alternative for cells used both ways.
* :func:`positive_ocp_values` keeps the base set's negative OCP and electrode balance and writes
  the positive OCP that makes ``U_p(y(z)) - U_n(x(z))`` equal the measured OCV at every state of
  charge ``z`` (``x``, ``y`` linear in ``z`` between the params' 0 % and 100 % stoichiometries), as
  the series of :mod:`battery_predictor.ocp`. The electrode height is scaled so that the cell's
  capacity between the two ends is the measured one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from battery_predictor.errors import InputDataError, ParamsError
from battery_predictor.fitting.identifiable import FARADAY_C_MOL
from battery_predictor.io.ocv_table import OcvTable
from battery_predictor.ocp import CONSTANT_KEY, PREFIX, SLOPE_KEY, evaluate, ocp_curves, sto_grid
from battery_predictor.params import PackParams
from battery_predictor.recording import Recording

if TYPE_CHECKING:
    import pybamm

#: A test is "low rate" when its discharge current is at most this C-rate.
MAX_C_RATE = 0.1
#: Ends of each branch left out of the charge/discharge gap (fraction of the capacity): the
#: relaxation after a rest and the end-of-discharge knee do not belong to the steady gap.
GAP_EDGE_FRACTION = 0.05
#: The curve is extended beyond its measured ends by this fraction of the capacity, along its end
#: slopes, so the series stays steep where a loaded cell goes past the low-rate end.
EXTENSION_FRACTION = 0.04
#: Series terms.
DEFAULT_TERMS = 48
#: The series must reproduce the measured OCV to this RMS error (V).
MAX_RMS_ERROR_V = 0.005
#: Least steepness (V per unit stoichiometry) of the implied positive OCP over the measured window.
MIN_OCP_SLOPE_V = 0.1
#: Points of the state-of-charge grid the curve is given on.
GRID_POINTS = 401


@dataclass(frozen=True)
class OcvCurve:
    """A measured open-circuit voltage against state of charge (cell level).

    Attributes
    ----------
    soc : numpy.ndarray
        State of charge, 0 (end of the low-rate discharge) .. 1 (its start), increasing.
    ocv_v : numpy.ndarray
        Open-circuit voltage in V at ``soc``.
    capacity_ah : float
        Charge of the low-rate discharge in Ah (per cell).
    discharge_current_a : float
        Median discharge current in A (per cell).
    method : str
        ``"discharge branch"`` or ``"mean of discharge and charge branches"``.
    notes : list of str
        What the derivation assumed.
    """

    soc: np.ndarray
    ocv_v: np.ndarray
    capacity_ah: float
    discharge_current_a: float
    method: str
    notes: list[str] = field(default_factory=list)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) index pairs of the True runs of ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return list(zip(edges[::2], edges[1::2]))


def _branch_charge_ah(time_s: np.ndarray, current_a: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Charge (Ah, signed like the current) passed from sample ``start`` to each sample up to ``stop`` (inclusive)."""
    i = slice(start, stop + 1)
    t, cur = time_s[i], current_a[i]
    dq = np.concatenate([[0.0], cur[:-1] * np.diff(t)]) / 3600.0
    return np.cumsum(dq)


def pseudo_ocv(recording: Recording, nominal_capacity_ah: float, *, parallel: int = 1,
               branch: str = "discharge") -> OcvCurve:
    """The open-circuit voltage of a low-rate test recording (per cell).

    Parameters
    ----------
    recording : Recording
        A low-rate discharge from full (at most :data:`MAX_C_RATE`), optionally preceded by a rest
        and followed by a low-rate charge; current positive while discharging.
    nominal_capacity_ah : float
        Nominal cell capacity in Ah (for the C-rate check).
    parallel : int
        Cells in parallel (the recording's current is divided by it).
    branch : {"discharge", "mean"}
        ``"discharge"`` (default): the discharge branch raised by the voltage step at its start
        (the low-rate ohmic and kinetic drop, which the model adds itself); the discharge
        hysteresis stays in, as it does in every discharge the robots make. ``"mean"``: the mean of
        the discharge and charge branches at equal charge (needs a charge branch).

    Raises
    ------
    InputDataError
        No discharge, a discharge faster than :data:`MAX_C_RATE`, or ``"mean"`` without a charge.
    """
    if branch not in ("discharge", "mean"):
        raise InputDataError(f"unknown OCV branch '{branch}' (use 'discharge' or 'mean')")
    t = np.asarray(recording.time_s, dtype=float)
    cur = np.asarray(recording.current_a, dtype=float) / parallel
    volt = np.asarray(recording.voltage_v, dtype=float)
    scale = max(float(np.max(np.abs(cur))), 1e-9)
    dis_runs = [r for r in _runs(cur > 0.2 * scale) if r[1] - r[0] >= 3]
    if not dis_runs:
        raise InputDataError(f"{recording.source}: no discharge to take an open-circuit voltage from")
    q_runs = [float(_branch_charge_ah(t, cur, a, b)[-1]) for a, b in dis_runs]
    d0, d1 = dis_runs[int(np.argmax(q_runs))]
    i_dis = float(np.median(cur[d0:d1]))
    if i_dis > MAX_C_RATE * nominal_capacity_ah:
        raise InputDataError(f"{recording.source}: discharge at {i_dis:.3f} A is C/{nominal_capacity_ah / i_dis:.1f}; "
                             f"an open-circuit voltage needs C/{1 / MAX_C_RATE:.0f} or slower (e.g. a C/20 test)")
    stop = d1 - 1  # last loaded sample: the next one is already at rest
    q_dis = _branch_charge_ah(t, cur, d0, stop)
    capacity = float(q_dis[-1])
    if capacity <= 0.1 * nominal_capacity_ah:
        raise InputDataError(f"{recording.source}: the low-rate discharge draws only {capacity:.3f} Ah of a "
                             f"{nominal_capacity_ah:.3f} Ah cell; an open-circuit voltage needs a full discharge")
    soc = np.linspace(0.0, 1.0, GRID_POINTS)
    z_dis = 1.0 - q_dis / capacity
    v_dis = np.interp(soc, z_dis[::-1], volt[d0:stop + 1][::-1])
    notes = [f"low-rate discharge {capacity:.4f} Ah at {i_dis:.4f} A (C/{nominal_capacity_ah / i_dis:.0f})"]
    if branch == "discharge":
        return _discharge_branch(soc, v_dis, volt, cur, d0, capacity, i_dis, notes)
    return _mean_of_branches(recording.source, soc, v_dis, t, cur, volt, d1, capacity, i_dis, notes)


def ocv_from_table(table: OcvTable, capacity_ah: float, *, branch: str = "discharge") -> OcvCurve:
    """The open-circuit voltage of a tabulated OCV (per cell; :func:`~battery_predictor.io.ocv_table.load_ocv_table`).

    Parameters
    ----------
    table : OcvTable
        State of charge and OCV (and, optionally, the hysteresis: half the charge/discharge gap).
    capacity_ah : float
        The cell's capacity in Ah between the table's 0 % and 100 % (a table does not give it;
        :func:`params_capacity_ah` keeps the params').
    branch : {"discharge", "mean"}
        ``"discharge"`` (default): the table's mean minus its hysteresis (the branch every discharge
        of the robots follows; the mean when the table has no hysteresis column, with a note);
        ``"mean"``: the table's mean curve.

    Raises
    ------
    InputDataError
        An unknown branch, or a table that does not cover 0 .. 100 % (within 2 %).
    """
    if branch not in ("discharge", "mean"):
        raise InputDataError(f"unknown OCV branch '{branch}' (use 'discharge' or 'mean')")
    if table.soc[0] > 0.02 or table.soc[-1] < 0.98:
        raise InputDataError(f"{table.source}: the table covers {100 * table.soc[0]:.0f}..{100 * table.soc[-1]:.0f} % "
                             "of the state of charge; the OCV needs 0..100 %")
    soc = np.linspace(0.0, 1.0, GRID_POINTS)
    mean = np.interp(soc, table.soc, table.ocv_v)
    notes = [f"tabulated OCV ({table.soc.size} points); capacity {capacity_ah:.4f} Ah from the params"]
    if branch == "mean":
        return OcvCurve(soc, mean, capacity_ah, 0.0, "table, mean curve", notes)
    if table.hysteresis_v is None:
        notes.append("the table has no hysteresis column: its mean curve stands for the discharge branch")
        return OcvCurve(soc, mean, capacity_ah, 0.0, "table, mean curve (no hysteresis given)", notes)
    v_dis = mean - np.interp(soc, table.soc, table.hysteresis_v)
    return OcvCurve(soc, v_dis, capacity_ah, 0.0, "table, discharge branch (mean minus hysteresis)", notes)


def params_capacity_ah(params: PackParams) -> float:
    """The params' cell capacity in Ah between their 0 % and 100 % SOC open-circuit voltages."""
    import pybamm

    pv = params.parameter_values()
    try:
        x0, x100, _, _ = (float(v) for v in pybamm.lithium_ion.get_min_max_stoichiometries(pv))
    except (ValueError, pybamm.SolverError) as exc:
        raise ParamsError(f"{params.source}: no stoichiometry window for its OCV limits: {exc}") from None
    return _window_capacity_ah(pv, x0, x100)


def _discharge_branch(soc: np.ndarray, v_dis: np.ndarray, volt: np.ndarray, cur: np.ndarray, d0: int, capacity: float,
                      i_dis: float, notes: list[str]) -> OcvCurve:
    """The discharge branch raised by the step between the rest before it and its first sample."""
    rest = d0 > 0 and abs(float(cur[d0 - 1])) < 0.05 * i_dis
    step_v = float(volt[d0 - 1] - volt[d0]) if rest else 0.0
    if rest and 0.0 <= step_v < 0.1:
        notes.append(f"discharge branch raised by its starting step {1000 * step_v:.1f} mV (low-rate drop)")
    else:
        step_v = 0.0
        notes.append("discharge branch as measured (no rest before it to take the low-rate drop from)")
    return OcvCurve(soc, v_dis + step_v, capacity, i_dis, "discharge branch", notes)


def _mean_of_branches(source: str, soc: np.ndarray, v_dis: np.ndarray, t: np.ndarray, cur: np.ndarray,
                      volt: np.ndarray, d1: int, capacity: float, i_dis: float, notes: list[str]) -> OcvCurve:
    """Mean of the discharge and the following charge branch (half their gap added to the discharge)."""
    scale = max(float(np.max(np.abs(cur))), 1e-9)
    ch_runs = [r for r in _runs(cur < -0.2 * scale) if r[0] >= d1 and r[1] - r[0] >= 3]
    if not ch_runs:
        raise InputDataError(f"{source}: no charge branch after the discharge; use the discharge branch")
    c0, c1 = ch_runs[0]
    stop_c = c1 - 1
    z_ch = -_branch_charge_ah(t, cur, c0, stop_c) / capacity
    lo, hi = GAP_EDGE_FRACTION, min(float(z_ch[-1]), 1.0) - GAP_EDGE_FRACTION
    if hi - lo < 0.2:
        raise InputDataError(f"{source}: the charge branch reaches SOC {z_ch[-1]:.2f} only; use the discharge branch")
    inside = (soc >= lo) & (soc <= hi)
    gap = np.interp(soc[inside], z_ch, volt[c0:stop_c + 1]) - v_dis[inside]
    half_gap = np.interp(soc, soc[inside], gap) / 2.0  # held constant beyond the overlap
    notes.append(f"charge branch to SOC {z_ch[-1]:.2f}; half the charge/discharge gap added "
                 f"({1000 * half_gap.min():.0f}..{1000 * half_gap.max():.0f} mV)")
    return OcvCurve(soc, v_dis + half_gap, capacity, i_dis, "mean of discharge and charge branches", notes)


@dataclass(frozen=True)
class PositiveOcpFit:
    """A positive OCP derived from a measured OCV.

    Attributes
    ----------
    ocp_values : dict
        The series scalars (:mod:`battery_predictor.ocp` keys).
    manual_values : dict
        PyBaMM values that go with it (OCV at 0 % and 100 % SOC, electrode height).
    rms_error_v : float
        RMS error of the cell OCV rebuilt from the series against the measured one, in V.
    max_error_v : float
        Largest absolute error of the same, in V.
    stoichiometry_window : tuple of float
        ``(x_0, x_100, y_100, y_0)``: negative and positive stoichiometries at 0 % and 100 % SOC.
    """

    ocp_values: dict[str, float]
    manual_values: dict[str, float]
    rms_error_v: float
    max_error_v: float
    stoichiometry_window: tuple[float, float, float, float]


def _extended(curve: OcvCurve) -> tuple[np.ndarray, np.ndarray]:
    """The curve continued beyond both ends along its end slopes (see :data:`EXTENSION_FRACTION`)."""
    soc, v = curve.soc, curve.ocv_v
    n_end = max(3, len(soc) // 100)
    slope_lo = np.polyfit(soc[:n_end], v[:n_end], 1)[0]
    slope_hi = np.polyfit(soc[-n_end:], v[-n_end:], 1)[0]
    step = soc[1] - soc[0]
    n_ext = int(round(EXTENSION_FRACTION / step))
    below = soc[0] - step * np.arange(n_ext, 0, -1)
    above = soc[-1] + step * np.arange(1, n_ext + 1)
    z = np.concatenate([below, soc, above])
    ocv = np.concatenate([v[0] + slope_lo * (below - soc[0]), v, v[-1] + slope_hi * (above - soc[-1])])
    return z, ocv


def _fit_series(sto: np.ndarray, target_v: np.ndarray, terms: int) -> dict[str, float]:
    """Decreasing series through ``(sto, target_v)`` by non-negative least squares.

    Centres are spaced evenly in a length that weights the curve's slope, so the steep ends get
    more of them; every term's coefficient and the linear slope are constrained to be <= 0, so the
    series decreases in ``sto`` everywhere (an OCP must).
    """
    from scipy.optimize import nnls

    order = np.argsort(sto)
    sto, target_v = sto[order], target_v[order]
    slope = np.abs(np.gradient(target_v, sto))
    weight = (slope / max(slope.max(), 1e-12)) ** 0.75 + 0.03
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (weight[1:] + weight[:-1]) * np.diff(sto))])
    centres = np.interp(np.linspace(0.0, cum[-1], terms), cum, sto)
    widths = np.maximum(1.5 * np.gradient(centres), 1e-4)
    tanh = np.column_stack([np.tanh((sto - m) / w) for m, w in zip(centres, widths)])
    # Columns with non-negative weights: +1 and -1 (a free constant), -sto and -tanh (decreasing).
    basis = np.column_stack([np.ones_like(sto), -np.ones_like(sto), -sto, -tanh])
    coef, _ = nnls(basis, target_v, maxiter=50 * basis.shape[1])
    values = {CONSTANT_KEY: float(coef[0] - coef[1]), SLOPE_KEY: float(-coef[2])}
    for k, (m, w, c) in enumerate(zip(centres, widths, -coef[3:])):
        values[f"{PREFIX} centre {k:02d}"] = float(m)
        values[f"{PREFIX} width {k:02d}"] = float(w)
        values[f"{PREFIX} coefficient {k:02d} [V]"] = float(c)
    return values


def positive_ocp_values(params: PackParams, curve: OcvCurve, *, terms: int = DEFAULT_TERMS) -> PositiveOcpFit:
    """The positive OCP (series) that, with the params' negative OCP, gives the measured OCV.

    The fully charged end (stoichiometries ``x_100``, ``y_100``) and the ratio of the electrode
    capacities are the params'. The discharged end ``x_0`` is the lowest negative stoichiometry
    at which the positive OCP the measurement implies decreases with its stoichiometry
    (by at least :data:`MIN_OCP_SLOPE_V`): a lower one would put a knee of the negative's OCP
    into the cell that the measured curve does not have. ``y_0`` follows from the capacity ratio.
    The initial concentrations are set to the full cell, and the electrode height makes the
    capacity between the ends the measured one.

    Parameters
    ----------
    params : PackParams
        The cell (its negative OCP, electrode capacity ratio and geometry are kept).
    curve : OcvCurve
        The measured open-circuit voltage (cell level).
    terms : int
        Number of tanh terms of the series.

    Raises
    ------
    ParamsError
        No stoichiometry window for the params, no ``x_0`` with a decreasing positive OCP, or a
        series that does not reproduce the curve to within :data:`MAX_RMS_ERROR_V`.
    """
    import pybamm

    pv = params.parameter_values()
    try:
        x0_params, x100, y100, y0_params = (float(v) for v in pybamm.lithium_ion.get_min_max_stoichiometries(pv))
    except (ValueError, pybamm.SolverError) as exc:
        raise ParamsError(f"{params.source}: no stoichiometry window for its OCV limits: {exc}") from None
    ratio = (y0_params - y100) / (x100 - x0_params)  # Q_n / Q_p
    u_n, _ = ocp_curves(params, params.ambient_temperature_k)
    z, ocv = _extended(curve)
    measured = (z >= 0.0) & (z <= 1.0)

    def target(x0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = x0 + z * (x100 - x0)
        y = y100 + (1.0 - z) * (x100 - x0) * ratio
        return x, y, ocv + np.interp(x, sto_grid(), u_n)

    x0 = _lowest_monotone_x0(target, measured, x0_params, x100)
    x, y, u_p = target(x0)
    if y.max() >= 1.0:
        raise ParamsError(f"{params.source}: the measured OCV needs a positive stoichiometry of {y.max():.3f} at the "
                          "discharged end (> 1); the params' electrode capacity ratio does not fit this cell")
    values = _fit_series(y, u_p, terms)
    err = evaluate(values, y[measured]) - np.interp(x[measured], sto_grid(), u_n) - ocv[measured]
    rms, worst = float(np.sqrt(np.mean(err ** 2))), float(np.max(np.abs(err)))
    if rms > MAX_RMS_ERROR_V:
        raise ParamsError(f"the positive OCP series reproduces the measured OCV only to {1000 * rms:.1f} mV RMS "
                          f"(limit {1000 * MAX_RMS_ERROR_V:.0f} mV); use more terms")
    y0 = float(y100 + (x100 - x0) * ratio)
    c_n_max = float(pv["Maximum concentration in negative electrode [mol.m-3]"])
    c_p_max = float(pv["Maximum concentration in positive electrode [mol.m-3]"])
    height = float(pv["Electrode height [m]"]) * curve.capacity_ah / _window_capacity_ah(pv, x0, x100)
    manual = {
        "Open-circuit voltage at 0% SOC [V]": float(curve.ocv_v[0]),
        "Open-circuit voltage at 100% SOC [V]": float(curve.ocv_v[-1]),
        "Electrode height [m]": height,
        "Initial concentration in negative electrode [mol.m-3]": x100 * c_n_max,
        "Initial concentration in positive electrode [mol.m-3]": y100 * c_p_max,
    }
    return PositiveOcpFit(values, manual, rms, worst, (x0, x100, y100, y0))


def _lowest_monotone_x0(target: Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]], measured: np.ndarray,
                        x0_low: float, x100: float) -> float:
    """Lowest ``x_0`` (from ``x0_low`` up, steps of 0.0025) whose implied positive OCP decreases."""
    for x0 in np.arange(x0_low, x100 - 0.3, 0.0025):
        _, y, u_p = target(float(x0))
        slope = np.diff(u_p[measured]) / np.diff(y[measured])
        if np.all(slope <= -MIN_OCP_SLOPE_V):
            return float(x0)
    raise ParamsError("no electrode balance makes the measured OCV a decreasing positive OCP with the base set's "
                      "negative OCP; the curve is not a low-rate OCV of this cell type")


def _window_capacity_ah(pv: pybamm.ParameterValues, x0: float, x100: float) -> float:
    """Cell capacity (Ah) between the negative stoichiometries ``x0`` and ``x100``."""
    volume = (float(pv["Electrode height [m]"]) * float(pv["Electrode width [m]"])
              * float(pv["Negative electrode thickness [m]"])
              * float(pv["Negative electrode active material volume fraction"]))
    return FARADAY_C_MOL * volume * float(pv["Maximum concentration in negative electrode [mol.m-3]"]) \
        * (x100 - x0) / 3600.0


def cell_ocv_v(params: PackParams, soc: np.ndarray) -> np.ndarray:
    """The params' cell open-circuit voltage (V) at the states of charge ``soc`` (0..1).

    ``U_p(y) - U_n(x)`` with ``x``, ``y`` linear in the SOC between PyBaMM's 0 % and 100 %
    stoichiometries of the params.
    """
    import pybamm

    x0, x100, y100, y0 = (float(v) for v in pybamm.lithium_ion.get_min_max_stoichiometries(params.parameter_values()))
    u_n, u_p = ocp_curves(params, params.ambient_temperature_k)
    soc = np.asarray(soc, dtype=float)
    return np.interp(y0 + soc * (y100 - y0), sto_grid(), u_p) - np.interp(x0 + soc * (x100 - x0), sto_grid(), u_n)
