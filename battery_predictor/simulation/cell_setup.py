"""PyBaMM cell model and parameter values for a pack's cells (shared by both simulators)."""

from __future__ import annotations

import contextlib
import logging
import os
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np

from battery_predictor.errors import SimulationError
from battery_predictor.params import PackParams
from battery_predictor.simulation.extensions import (
    THERMAL_DEFAULTS,
    apply_extension_model,
    apply_extension_parameter_values,
    cooling_area_m2,
    extension_model_options,
    extension_model_type,
)

#: PyBaMM parameters that may be turned into ``[input]`` parameters without a rebuild
#: (they do not change the mesh or the model structure). Geometric lengths (thickness,
#: particle radius) shape the mesh and need a rebuild.
INPUT_SAFE_KEYS = frozenset({
    "Electrode height [m]",
    "Electrode width [m]",
    "Initial concentration in negative electrode [mol.m-3]",
    "Initial concentration in positive electrode [mol.m-3]",
    "Maximum concentration in negative electrode [mol.m-3]",
    "Maximum concentration in positive electrode [mol.m-3]",
    "Negative electrode active material volume fraction",
    "Positive electrode active material volume fraction",
    "Negative particle diffusivity [m2.s-1]",
    "Positive particle diffusivity [m2.s-1]",
    "Ambient temperature [K]",
    "Initial temperature [K]",
    "Contact resistance [Ohm]",
    "Total heat transfer coefficient [W.m-2.K-1]",
})
#: Always passed as inputs (state initialisation and temperature).
ALWAYS_INPUT_KEYS = (
    "Initial concentration in negative electrode [mol.m-3]",
    "Initial concentration in positive electrode [mol.m-3]",
    "Ambient temperature [K]",
    "Initial temperature [K]",
)
#: Discharge simulations do not use the upper cut-off; the event is moved out of the way
#: (some published fits start above their own upper cut-off, e.g. the paper's Table 3).
RELAXED_UPPER_CUTOFF_V = 5.0


@contextlib.contextmanager
def quiet_pybamm() -> Iterator[None]:
    """Silence PyBaMM/liionpack loggers and tqdm bars inside the block."""
    import pybamm

    old_level = pybamm.logger.level
    old_tqdm = os.environ.get("TQDM_DISABLE")
    pybamm.logger.setLevel(logging.ERROR)
    os.environ["TQDM_DISABLE"] = "1"
    _silence_liionpack_tqdm()
    try:
        yield
    finally:
        pybamm.logger.setLevel(old_level)
        if old_tqdm is None:
            os.environ.pop("TQDM_DISABLE", None)
        else:
            os.environ["TQDM_DISABLE"] = old_tqdm


def _silence_liionpack_tqdm() -> None:
    """liionpack shows a tqdm bar per solve; its ``tqdm`` is replaced by a disabled one."""
    import functools
    import sys

    solvers = sys.modules.get("liionpack.solvers")
    if solvers is not None and not isinstance(getattr(solvers, "tqdm", None), functools.partial):
        import tqdm

        vars(solvers)["tqdm"] = functools.partial(tqdm.tqdm, disable=True)


def model_options(params: PackParams) -> dict[str, Any]:
    """PyBaMM model options for ``params`` (file options plus active extensions)."""
    opts = dict(params.options)
    opts.update(extension_model_options(params))
    return opts


def build_model(params: PackParams, *, for_liionpack: bool = False) -> Any:
    """A fresh PyBaMM model of the params' type (SPM, SPMe or DFN) with its options."""
    import pybamm

    cls = {"SPM": pybamm.lithium_ion.SPM, "SPMe": pybamm.lithium_ion.SPMe, "DFN": pybamm.lithium_ion.DFN}[
        extension_model_type(params)
    ]
    try:
        model = cls(options=model_options(params))
    except pybamm.OptionError as exc:
        raise SimulationError(f"{params.source}: invalid model options: {exc}") from None
    model = apply_extension_model(params, model)
    if for_liionpack:
        import liionpack as lp

        model = lp.add_events_to_model(model)
    return model


def prepared_parameter_values(params: PackParams) -> Any:
    """Parameter values ready to simulate a discharge (upper cut-off event relaxed).

    A lumped thermal cell (:func:`is_lumped_thermal`) whose base set lacks thermal values (Prada2013)
    gets those of the extension ``temperature`` (Chen2020's, the cooling surface of a cylinder of the
    cell volume; :data:`~battery_predictor.simulation.extensions.THERMAL_DEFAULTS`).
    """
    pv = apply_extension_parameter_values(params, params.parameter_values())
    pv["Upper voltage cut-off [V]"] = max(float(pv["Upper voltage cut-off [V]"]), RELAXED_UPPER_CUTOFF_V)
    if is_lumped_thermal(params):
        keys = set(pv.keys())
        missing = {k: v for k, v in THERMAL_DEFAULTS.items() if k not in keys}
        if "Cell cooling surface area [m2]" not in keys and "Cell volume [m3]" in keys:
            missing["Cell cooling surface area [m2]"] = cooling_area_m2(float(pv["Cell volume [m3]"]))
        if missing:
            pv.update(missing, check_already_exists=False)
    return pv


#: Values of the ``--thermal`` option of ``simulate`` and ``fit``.
THERMAL_MODES = ("params", "isothermal", "lumped")


def is_lumped_thermal(params: PackParams) -> bool:
    """True when ``params`` ask PyBaMM's lumped thermal model (``cell.options: {thermal: lumped}``)."""
    return model_options(params).get("thermal", "isothermal") == "lumped"


def with_thermal(params: PackParams, mode: str) -> PackParams:
    """``params`` with the cell's thermal model set by a command line's ``--thermal``.

    ``"params"`` keeps the params' own (``cell.options``; isothermal unless they say
    ``thermal: lumped``), ``"lumped"`` sets PyBaMM's ``{"thermal": "lumped"}``, ``"isothermal"``
    removes it.
    """
    from dataclasses import replace

    if mode not in THERMAL_MODES:
        raise SimulationError(f"thermal model {mode!r} is not one of {', '.join(THERMAL_MODES)}")
    if mode == "params":
        return params
    options = {k: v for k, v in params.options.items() if k != "thermal"}
    if mode == "lumped":
        options["thermal"] = "lumped"
    return replace(params, options=options)


#: A measured open-circuit voltage at most this far (V per cell) outside the params' range (the OCV
#: at 0 and 100 % SOC) starts the cell at that end of the range, with a warning; sensor offset and
#: quantisation put a full pack's rest voltage a few mV above a model's 100 % OCV.
OCV_CLAMP_TOLERANCE_V = 0.03
#: ... and within this much (V per cell) without the warning: an averaged rest reading of a full (or empty)
#: cell lands this close to the edge by its noise alone.
OCV_CLAMP_SILENT_V = 5e-4


def _clamped_ocv_v(pv: Any, ocv_v: float) -> float:
    """``ocv_v`` moved into the params' OCV range when it lies within :data:`OCV_CLAMP_TOLERANCE_V` outside it
    (with a warning beyond :data:`OCV_CLAMP_SILENT_V`)."""
    try:
        v_min = float(pv["Open-circuit voltage at 0% SOC [V]"])
        v_max = float(pv["Open-circuit voltage at 100% SOC [V]"])
    except (KeyError, TypeError, ValueError):
        return ocv_v
    for edge, outside in ((v_max, ocv_v > v_max), (v_min, ocv_v < v_min)):
        if outside and abs(ocv_v - edge) <= OCV_CLAMP_TOLERANCE_V:
            if abs(ocv_v - edge) <= OCV_CLAMP_SILENT_V:
                return edge
            warnings.warn(f"initial open-circuit voltage {ocv_v:.4f} V per cell lies {1e3 * abs(ocv_v - edge):.1f} mV "
                          f"outside the params' range; starting at {edge:.4f} V "
                          f"({'full' if edge == v_max else 'empty'})", UserWarning, stacklevel=3)
            return edge
    return ocv_v


def initial_concentrations(params: PackParams, pv: Any, *, initial_soc: float | None,
                           initial_cell_ocv_v: float | None) -> tuple[float, float]:
    """Initial electrode concentrations (mol/m3) for an SOC or an open-circuit voltage.

    Returns the params' own initial concentrations when both are None. An open-circuit voltage
    just outside the params' range (:data:`OCV_CLAMP_TOLERANCE_V`) starts at its end, with a warning.
    """
    import pybamm

    c_n_max = float(pv["Maximum concentration in negative electrode [mol.m-3]"])
    c_p_max = float(pv["Maximum concentration in positive electrode [mol.m-3]"])
    if initial_soc is None and initial_cell_ocv_v is None:
        return (float(pv["Initial concentration in negative electrode [mol.m-3]"]),
                float(pv["Initial concentration in positive electrode [mol.m-3]"]))
    if initial_soc is not None and not (0.0 <= initial_soc <= 1.0):
        raise SimulationError(f"initial SOC must be within 0..1, got {initial_soc}")
    value: float | str
    if initial_soc is not None:
        value = initial_soc
    else:
        assert initial_cell_ocv_v is not None
        value = f"{_clamped_ocv_v(pv, float(initial_cell_ocv_v))} V"
    try:
        x, y = pybamm.lithium_ion.get_initial_stoichiometries(value, pv)
    except (ValueError, pybamm.SolverError, ZeroDivisionError) as exc:
        raise SimulationError(f"cannot set the initial state {value!r}: {exc}") from None
    x, y = float(x), float(y)
    if not (0 < x < 1 and 0 < y < 1 and np.isfinite(x) and np.isfinite(y)):
        raise SimulationError(f"initial state {value!r} gives stoichiometries outside (0, 1): {x:.3f}, {y:.3f}")
    return x * c_n_max, y * c_p_max
