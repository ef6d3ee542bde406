"""Fit parameters and their bounds (seed paper, step 4)."""

from __future__ import annotations

from dataclasses import dataclass

from battery_predictor.errors import ParamsError
from battery_predictor.params import INTERCONNECT_KEYS, PackParams

#: Active material volume fractions are searched in a physically meaningful range (paper step 4).
VOLUME_FRACTION_BOUNDS = (0.3, 0.75)
#: Other parameters: 50 % to 150 % of the initial value.
RELATIVE_BOUNDS = (0.5, 1.5)
#: liionpack interconnect resistances: 0.1x to 10x (searched on a log scale).
INTERCONNECT_FACTORS = (0.1, 10.0)


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


def fit_space(params: PackParams, names: tuple[str, ...] | None = None) -> list[FitParameter]:
    """The search space for ``names`` (default: the params' ``fit.parameters``)."""
    names = tuple(names if names is not None else params.fit.parameters)
    if not names:
        raise ParamsError(f"{params.source}: no fit parameters (set fit.parameters or run 'screen')")
    space = []
    for name in names:
        initial = params.value(name)
        if name in params.fit.bounds:
            lo, hi = params.fit.bounds[name]
            log = name in INTERCONNECT_KEYS and lo > 0
        else:
            lo, hi, log = default_bounds(name, initial)
        space.append(FitParameter(name=name, initial=initial, low=lo, high=hi, log=log))
    return space
