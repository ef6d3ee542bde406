"""Initial electrode concentrations for a state of charge or an open-circuit voltage, in milliseconds.

PyBaMM's ``get_initial_stoichiometries`` (what :func:`~battery_predictor.simulation.cell_setup.initial_concentrations`
calls) solves its electrode state-of-health model each time, which costs far more than an engine
run. The same equations are solved here on the engine's voltage function at zero current, which
is the open-circuit voltage ``U_p(y) - U_n(x)`` of PyBaMM's expression:

* the lithium inventory ``n_Li = eps_n L_n c_n0 + eps_p L_p c_p0`` (per electrode area) is kept,
  so ``y = (n_Li - n_n x) / n_p`` with ``n_e = eps_e L_e c_e,max``;
* ``x_100`` and ``x_0`` are where the open-circuit voltage equals the params' ``Open-circuit
  voltage at 100% / 0% SOC [V]`` (at the reference temperature, as PyBaMM);
* an SOC is ``x = x_0 + SOC (x_100 - x_0)`` (PyBaMM's linear SOC), a voltage the ``x`` whose
  open-circuit voltage it is.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.engine.model import LinearSpm

if TYPE_CHECKING:
    import pybamm

_GRID_POINTS = 513
_ZOOMS = 3
#: Stoichiometries are kept this far inside (0, 1).
_EDGE = 1e-6


class StoichiometryWindow:
    """The electrode balance of one cell: capacities, lithium inventory, SOC window.

    Parameters
    ----------
    model : LinearSpm
        The extracted cell (its voltage function gives the open-circuit voltage).
    pv : pybamm.ParameterValues
        The cell's parameter values (volume fractions, thicknesses, maximum and initial
        concentrations, OCV limits, reference temperature).
    """

    def __init__(self, model: LinearSpm, pv: pybamm.ParameterValues) -> None:
        def get(key: str) -> float:
            return float(pv[key])

        self.model = model
        self.c_max_mol_m3 = (get("Maximum concentration in negative electrode [mol.m-3]"),
                             get("Maximum concentration in positive electrode [mol.m-3]"))
        self.n_n = get("Negative electrode active material volume fraction") * get("Negative electrode thickness [m]") \
            * self.c_max_mol_m3[0]
        self.n_p = get("Positive electrode active material volume fraction") * get("Positive electrode thickness [m]") \
            * self.c_max_mol_m3[1]
        self.n_li = (self.n_n * get("Initial concentration in negative electrode [mol.m-3]") / self.c_max_mol_m3[0]
                     + self.n_p * get("Initial concentration in positive electrode [mol.m-3]") / self.c_max_mol_m3[1])
        self.reference_temperature_k = get("Reference temperature [K]")
        lo = max(_EDGE, (self.n_li - self.n_p * (1.0 - _EDGE)) / self.n_n)
        hi = min(1.0 - _EDGE, (self.n_li - self.n_p * _EDGE) / self.n_n)
        if not lo < hi:
            raise SimulationError("the lithium inventory does not fit into the electrodes")
        self._range = (lo, hi)
        self.x_100 = self.x_at_ocv(get("Open-circuit voltage at 100% SOC [V]"))
        self.x_0 = self.x_at_ocv(get("Open-circuit voltage at 0% SOC [V]"))

    def y_of(self, x: npt.ArrayLike) -> np.ndarray:
        """Positive stoichiometry that keeps the lithium inventory at negative stoichiometry ``x``."""
        return (self.n_li - self.n_n * np.asarray(x, dtype=float)) / self.n_p

    def ocv_v(self, x: npt.ArrayLike) -> np.ndarray:
        """Open-circuit voltage (V) at negative stoichiometry ``x`` (PyBaMM's voltage at zero current)."""
        x = np.asarray(x, dtype=float)  # the engine's surface values are stoichiometries
        return self.model.cell_voltage_v(x, self.y_of(x), 0.0, self.reference_temperature_k)

    def x_at_ocv(self, ocv_v: float) -> float:
        """Negative stoichiometry whose open-circuit voltage is ``ocv_v`` (grid, then zoomed grids)."""
        lo, hi = self._range
        for _ in range(_ZOOMS + 1):
            x = np.linspace(lo, hi, _GRID_POINTS)
            f = self.ocv_v(x) - ocv_v
            change = np.nonzero(np.diff(np.sign(f)) != 0)[0]
            if change.size == 0:
                raise SimulationError(f"no state of the electrodes has an open-circuit voltage of {ocv_v:.4f} V")
            i = int(change[0])
            lo, hi = float(x[i]), float(x[i + 1])
            f_lo, f_hi = float(f[i]), float(f[i + 1])
        return lo - f_lo * (hi - lo) / (f_hi - f_lo) if f_hi != f_lo else lo

    def concentrations(self, *, soc: float | None = None, ocv_v: float | None = None) -> tuple[float, float]:
        """Initial (c_n, c_p) in mol/m3 at an SOC (0..1) or an open-circuit voltage (V)."""
        if (soc is None) == (ocv_v is None):
            raise SimulationError("give exactly one of an SOC and an open-circuit voltage")
        if soc is not None:
            if not 0.0 <= soc <= 1.0:
                raise SimulationError(f"initial SOC must be within 0..1, got {soc}")
            x = self.x_0 + soc * (self.x_100 - self.x_0)
        else:
            assert ocv_v is not None  # exactly one of the two is given (checked above)
            x = self.x_at_ocv(float(ocv_v))
        y = float(self.y_of(x))
        if not (0.0 < x < 1.0 and 0.0 < y < 1.0):
            raise SimulationError(f"the initial state gives stoichiometries outside (0, 1): {x:.3f}, {y:.3f}")
        return x * self.c_max_mol_m3[0], y * self.c_max_mol_m3[1]
