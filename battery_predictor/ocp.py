"""A measured open-circuit potential as a smooth series: the one formula, in NumPy and PyBaMM form.

A cell's positive-electrode OCP can come from a measurement (see
:mod:`battery_predictor.fitting.ocv`) instead of the base parameter set. It is stored as

.. math::

    U(s) = a + b\\,s + \\sum_k c_k \\tanh\\!\\left(\\frac{s - m_k}{w_k}\\right)

with the stoichiometry ``s``. The series is smooth, has a closed form (so PyBaMM's code printer and
the engine's compiled kernel handle it like the published OCPs, which have the same form), and
its terms are plain scalars: they live among the cell's PyBaMM values under the keys of
:func:`series_keys`, so every cache keyed on the cell values sees them. :func:`series_value` is the
formula; :func:`pybamm_ocp` and :func:`evaluate` call it with PyBaMM's or NumPy's ``tanh``.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.config import yaml_number
from battery_predictor.errors import ParamsError, SimulationError

if TYPE_CHECKING:
    import pybamm

    from battery_predictor.params import PackParams

#: PyBaMM key of the OCP a series replaces.
POSITIVE_OCP_KEY = "Positive electrode OCP [V]"
#: Prefix of the scalar keys that hold the series.
PREFIX = "Positive electrode OCP series"
CONSTANT_KEY = f"{PREFIX} constant [V]"
SLOPE_KEY = f"{PREFIX} slope [V]"
#: Most terms a series may have (the YAML is checked against it).
MAX_TERMS = 64
#: Stoichiometry grid on which :func:`ocp_curves` tabulates the OCPs.
STO_GRID = np.linspace(1e-4, 1.0 - 1e-4, 2001)
_ELECTRODE_NAMES = {"negative": "Negative", "positive": "Positive"}


def series_keys(n_terms: int) -> list[str]:
    """Scalar keys of a series with ``n_terms`` terms (constant, slope, then centre/width/coefficient per term)."""
    keys = [CONSTANT_KEY, SLOPE_KEY]
    for k in range(n_terms):
        keys += [f"{PREFIX} centre {k:02d}", f"{PREFIX} width {k:02d}", f"{PREFIX} coefficient {k:02d} [V]"]
    return keys


def n_terms(values: Mapping[str, Any]) -> int:
    """Number of series terms among ``values`` (0 when no series is present)."""
    return sum(1 for key in values if key.startswith(f"{PREFIX} coefficient "))


def has_series(values: Mapping[str, Any]) -> bool:
    """True when ``values`` hold a positive-OCP series."""
    return CONSTANT_KEY in values


def series_value(sto: Any, values: Mapping[str, Any], tanh: Callable[[Any], Any]) -> Any:
    """The series at stoichiometry ``sto`` (V), with ``tanh`` from NumPy or PyBaMM.

    Parameters
    ----------
    sto : array_like or pybamm.Symbol
        Positive-electrode stoichiometry (dimensionless).
    values : mapping
        The series' scalars by :func:`series_keys` (numbers, or PyBaMM parameters).
    tanh : callable
        ``numpy.tanh`` or ``pybamm.tanh``.
    """
    out = values[CONSTANT_KEY] + values[SLOPE_KEY] * sto
    for k in range(n_terms(values)):
        centre = values[f"{PREFIX} centre {k:02d}"]
        width = values[f"{PREFIX} width {k:02d}"]
        out = out + values[f"{PREFIX} coefficient {k:02d} [V]"] * tanh((sto - centre) / width)
    return out


def evaluate(values: Mapping[str, float], sto: np.ndarray) -> np.ndarray:
    """The series (V) at the stoichiometries ``sto``, in NumPy."""
    return np.asarray(series_value(np.asarray(sto, dtype=float), values, np.tanh), dtype=float)


def pybamm_ocp(count: int) -> Callable:
    """PyBaMM OCP function ``U(sto)`` of a ``count``-term series whose scalars are PyBaMM parameters."""
    import pybamm

    params = {key: pybamm.Parameter(key) for key in series_keys(count)}

    def positive_ocp_series(sto: pybamm.Symbol) -> pybamm.Symbol:
        return series_value(sto, params, pybamm.tanh)

    return positive_ocp_series


def apply_series(pv: pybamm.ParameterValues, values: Mapping[str, Any]) -> None:
    """Point ``pv``'s positive OCP at the series held in ``values`` (no-op without one)."""
    if has_series(values):
        pv.update({POSITIVE_OCP_KEY: pybamm_ocp(n_terms(values))}, check_already_exists=False)


def cell_parameter_values(base_parameter_set: str, cell_values: Mapping[str, float]) -> pybamm.ParameterValues:
    """PyBaMM ``ParameterValues``: ``base_parameter_set`` updated with ``cell_values`` (and their series).

    The one place a params file's cell values become PyBaMM values.
    """
    import pybamm

    pv = pybamm.ParameterValues(base_parameter_set)
    pv.update(dict(cell_values), check_already_exists=False)
    apply_series(pv, cell_values)
    return pv


def ocp_origin(params: PackParams) -> str:
    """Where the params' OCPs come from, for reports: ``"OCPs of Chen2020"`` or the measured positive's source."""
    if has_series(params.ocp):
        source = f" ({params.ocp_source})" if params.ocp_source else ""
        return f"measured positive OCP{source}, negative OCP of {params.base_parameter_set}"
    return f"OCPs of {params.base_parameter_set}"


# ----------------------------------------------------------------------------- YAML form
def section_to_values(section: Mapping[str, Any], source: str) -> dict[str, float]:
    """The scalar keys of a ``cell.ocp`` YAML section.

    The section is ``{positive: {constant_v, slope_v, centres, widths, coefficients_v, source}}``.
    """
    unknown = set(section) - {"positive"}
    if unknown:
        raise ParamsError(f"{source}: unknown key 'cell.ocp.{sorted(unknown)[0]}' (allowed: positive)")
    pos = section.get("positive")
    if pos is None:
        return {}
    if not isinstance(pos, Mapping):
        raise ParamsError(f"{source}: key 'cell.ocp.positive' must be a mapping")
    allowed = {"constant_v", "slope_v", "centres", "widths", "coefficients_v", "source"}
    for key in pos:
        if key not in allowed:
            raise ParamsError(f"{source}: unknown key 'cell.ocp.positive.{key}' (allowed: {', '.join(sorted(allowed))})")
    for key in ("constant_v", "slope_v", "centres", "widths", "coefficients_v"):
        if key not in pos:
            raise ParamsError(f"{source}: missing key 'cell.ocp.positive.{key}'")
    where = "cell.ocp.positive"
    constant = yaml_number(pos["constant_v"], source, f"{where}.constant_v")
    slope = yaml_number(pos["slope_v"], source, f"{where}.slope_v")
    centres, widths, coefs = (_number_list(pos[k], source, f"{where}.{k}") for k in ("centres", "widths",
                                                                                      "coefficients_v"))
    if not (len(centres) == len(widths) == len(coefs)) or len(centres) > MAX_TERMS:
        raise ParamsError(f"{source}: key 'cell.ocp.positive': centres, widths and coefficients_v must have the "
                          f"same length (at most {MAX_TERMS}), got {len(centres)}, {len(widths)}, {len(coefs)}")
    numbers = [constant, slope, *centres, *widths, *coefs]
    if not all(np.isfinite(numbers)) or any(w <= 0 for w in widths):
        raise ParamsError(f"{source}: key 'cell.ocp.positive': values must be finite and widths > 0")
    values = {CONSTANT_KEY: constant, SLOPE_KEY: slope}
    for k, (m, w, c) in enumerate(zip(centres, widths, coefs)):
        values[f"{PREFIX} centre {k:02d}"] = m
        values[f"{PREFIX} width {k:02d}"] = w
        values[f"{PREFIX} coefficient {k:02d} [V]"] = c
    return values


def _number_list(value: Any, source: str, key: str) -> list[float]:
    if not isinstance(value, list):
        raise ParamsError(f"{source}: key '{key}': expected a list of numbers, got {value!r}")
    return [yaml_number(x, source, f"{key}[{i}]") for i, x in enumerate(value)]


def values_to_section(values: Mapping[str, float], source: str = "") -> dict[str, Any]:
    """The ``cell.ocp`` YAML section of the series in ``values`` (empty without one)."""
    if not has_series(values):
        return {}
    count = n_terms(values)
    pos: dict[str, Any] = {
        "constant_v": float(values[CONSTANT_KEY]),
        "slope_v": float(values[SLOPE_KEY]),
        "centres": [float(values[f"{PREFIX} centre {k:02d}"]) for k in range(count)],
        "widths": [float(values[f"{PREFIX} width {k:02d}"]) for k in range(count)],
        "coefficients_v": [float(values[f"{PREFIX} coefficient {k:02d} [V]"]) for k in range(count)],
    }
    if source:
        pos["source"] = source
    return {"positive": pos}


# ----------------------------------------------------------------------------- tables and the balance
@functools.lru_cache(maxsize=32)
def _ocp_table(base_parameter_set: str, cell_values: tuple, electrode: str, temperature_k: float) -> np.ndarray:
    import pybamm

    pv = cell_parameter_values(base_parameter_set, dict(cell_values))
    key = f"{_ELECTRODE_NAMES[electrode]} electrode OCP [V]"
    fn = pv[key]
    if not callable(fn):
        raise ParamsError(f"{key} of {base_parameter_set} is not a function of stoichiometry")
    n_args = len(inspect.signature(fn).parameters)
    sto = pybamm.Vector(STO_GRID)
    args = {"Stoichiometry": sto} if n_args == 1 else {"Stoichiometry": sto, "Temperature [K]": pybamm.Scalar(
        temperature_k)}
    sym = pybamm.FunctionParameter(key, args)
    return np.asarray(pv.process_symbol(sym).evaluate(), dtype=float).ravel()


def sto_grid() -> np.ndarray:
    """The stoichiometry grid (dimensionless) on which :func:`ocp_curves` tabulates the OCPs."""
    return STO_GRID.copy()


def ocp_curves(params: PackParams, temperature_k: float = 298.15) -> tuple[np.ndarray, np.ndarray]:
    """Negative and positive OCP (V) of ``params`` on the stoichiometry grid :data:`STO_GRID` (cached)."""
    key = tuple(sorted((k, v) for k, v in params.cell_values.items() if "OCP" in k))
    return (_ocp_table(params.base_parameter_set, key, "negative", temperature_k),
            _ocp_table(params.base_parameter_set, key, "positive", temperature_k))


def initial_stoichiometries(params: PackParams, q_n_ah: float, q_p_ah: float, q_li_ah: float,
                            ocv_v: float, temperature_k: float = 298.15) -> tuple[float, float]:
    """Stoichiometries ``(x, y)`` with ``U_p(y) - U_n(x) = ocv_v`` and ``x Q_n + y Q_p = Q_Li``.

    Parameters
    ----------
    params : PackParams
        Whose OCPs (base set and measured series) are used.
    q_n_ah, q_p_ah : float
        Each electrode's capacity over its full stoichiometry range, Ah (any common scale).
    q_li_ah : float
        Cyclable lithium, Ah (same scale).
    ocv_v : float
        Cell open-circuit voltage, V.
    temperature_k : float
        Temperature at which the OCPs are evaluated, K.

    Raises
    ------
    SimulationError
        When no such pair lies inside (0, 1) x (0, 1).
    """
    u_n, u_p = ocp_curves(params, temperature_k)
    x_lo = max(STO_GRID[0], (q_li_ah - STO_GRID[-1] * q_p_ah) / q_n_ah)
    x_hi = min(STO_GRID[-1], (q_li_ah - STO_GRID[0] * q_p_ah) / q_n_ah)
    if not x_lo < x_hi:
        raise SimulationError(f"lithium inventory {q_li_ah:.3g} Ah does not fit electrodes of {q_n_ah:.3g} and "
                              f"{q_p_ah:.3g} Ah")
    x = np.linspace(x_lo, x_hi, 801)
    y = (q_li_ah - x * q_n_ah) / q_p_ah
    ocv = np.interp(y, STO_GRID, u_p) - np.interp(x, STO_GRID, u_n)
    order = np.argsort(ocv)
    if not ocv[order[0]] <= ocv_v <= ocv[order[-1]]:
        raise SimulationError(f"initial OCV {ocv_v:.3f} V is outside the cell's range "
                              f"{ocv[order[0]]:.3f}-{ocv[order[-1]]:.3f} V for these capacities")
    x0 = float(np.interp(ocv_v, ocv[order], x[order]))
    return x0, (q_li_ah - x0 * q_n_ah) / q_p_ah
