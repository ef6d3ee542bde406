"""Fit parameters, their bounds (seed paper, step 4) and the unit-cube mapping every search uses."""

from __future__ import annotations

import math
from dataclasses import dataclass

from battery_predictor.errors import ParamsError
from battery_predictor.params import INTERCONNECT_KEYS, PackParams

#: Active material volume fractions are searched in a physically meaningful range (paper step 4).
VOLUME_FRACTION_BOUNDS = (0.3, 0.75)
#: Other parameters: 50 % to 150 % of the initial value.
RELATIVE_BOUNDS = (0.5, 1.5)
#: liionpack interconnect resistances: 0.1x to 10x (searched on a log scale).
INTERCONNECT_FACTORS = (0.1, 10.0)
#: Initial electrode concentrations stay within this stoichiometry range of the electrode's
#: maximum concentration (the smallest maximum searched, when that is fitted too): outside it
#: the electrode is over-full or empty and no simulation can start.
INITIAL_STOICHIOMETRY_RANGE = (0.01, 0.99)


def unit_to_value(unit: float, low: float, high: float, log: bool = False) -> float:
    """The value at ``unit`` (clamped to 0..1) of the search interval ``low..high``; on a log scale when ``log``.

    Parameters
    ----------
    unit : float
        Position in the unit interval (0 = ``low``, 1 = ``high``).
    low, high : float
        The search bounds (the parameter's unit; both > 0 when ``log``).
    log : bool
        Search on a log scale.
    """
    unit = min(max(float(unit), 0.0), 1.0)
    if log:
        return math.exp(math.log(low) + unit * (math.log(high) - math.log(low)))
    return low + unit * (high - low)


def value_to_unit(value: float, low: float, high: float, log: bool = False) -> float:
    """Inverse of :func:`unit_to_value`: the position of ``value`` in ``low..high`` (not clamped)."""
    if log:
        return (math.log(value) - math.log(low)) / (math.log(high) - math.log(low))
    return (value - low) / (high - low)


@dataclass(frozen=True)
class FitParameter:
    """One searched parameter.

    Attributes
    ----------
    name : str
        PyBaMM key or interconnect name (``r_c_ohm``...).
    initial : float
        Value before the fit (in the key's unit).
    low, high : float
        Search bounds (same unit).
    log : bool
        Search on a log scale.
    """

    name: str
    initial: float
    low: float
    high: float
    log: bool = False


def default_bounds(name: str, initial: float) -> tuple[float, float, bool]:
    """Bounds ``(low, high, log)`` of the seed paper's rule for one parameter."""
    if name in INTERCONNECT_KEYS:
        base = initial if initial > 0 else 1e-4
        return base * INTERCONNECT_FACTORS[0], base * INTERCONNECT_FACTORS[1], True
    if "active material volume fraction" in name:
        return VOLUME_FRACTION_BOUNDS[0], VOLUME_FRACTION_BOUNDS[1], False
    lo, hi = sorted((initial * RELATIVE_BOUNDS[0], initial * RELATIVE_BOUNDS[1]))
    if lo == hi:
        raise ParamsError(f"fit parameter '{name}' has initial value 0; give explicit bounds in fit.bounds")
    return lo, hi, False


def _feasible_initial_concentration(name: str, lo: float, hi: float, params: PackParams,
                                    bounds: dict[str, tuple[float, float]]) -> tuple[float, float]:
    """Clip an initial concentration's default bounds to :data:`INITIAL_STOICHIOMETRY_RANGE`.

    ``bounds`` holds the already decided bounds of the other searched parameters, so that a
    fitted maximum concentration caps with its lowest searched value and every combination is
    feasible.
    """
    domain = "negative" if "negative" in name else "positive"
    max_key = f"Maximum concentration in {domain} electrode [mol.m-3]"
    try:
        c_max_low = bounds[max_key][0] if max_key in bounds else float(params.value(max_key))
        c_max_high = bounds[max_key][1] if max_key in bounds else c_max_low
    except (KeyError, TypeError, ValueError):
        return lo, hi
    new_lo = max(lo, INITIAL_STOICHIOMETRY_RANGE[0] * c_max_high)
    new_hi = min(hi, INITIAL_STOICHIOMETRY_RANGE[1] * c_max_low)
    return (new_lo, new_hi) if new_lo < new_hi else (lo, hi)


def fit_space(params: PackParams, names: tuple[str, ...] | None = None) -> list[FitParameter]:
    """The search space for ``names`` (default: the params' ``fit.parameters``).

    Default bounds follow the seed paper's rule (:func:`default_bounds`); initial electrode
    concentrations are additionally kept below their electrode's maximum concentration
    (:data:`INITIAL_STOICHIOMETRY_RANGE`), which the paper's 50-150 % rule violates for
    Chen2020's negative electrode (29866 of 33133 mol/m3); the params' own value always stays
    inside (a shipped value above the cap of the lowest searched maximum widens the range to it).
    Explicit ``fit.bounds`` are kept as given.
    """
    names = tuple(names if names is not None else params.fit.parameters)
    if not names:
        raise ParamsError(f"{params.source}: no fit parameters (set fit.parameters or run 'screen')")
    decided: dict[str, tuple[float, float, bool]] = {}
    for name in sorted(names, key=lambda n: n.startswith("Initial concentration")):
        initial = params.value(name)
        if name in params.fit.bounds:
            lo, hi = params.fit.bounds[name]
            log = name in INTERCONNECT_KEYS and lo > 0
        else:
            lo, hi, log = default_bounds(name, initial)
            if name.startswith("Initial concentration in"):
                lo, hi = _feasible_initial_concentration(name, lo, hi, params,
                                                         {k: v[:2] for k, v in decided.items()})
            lo, hi = min(lo, initial), max(hi, initial)  # the params' own value is always searchable
        decided[name] = (lo, hi, log)
    return [FitParameter(name=n, initial=params.value(n), low=decided[n][0], high=decided[n][1], log=decided[n][2])
            for n in names]
