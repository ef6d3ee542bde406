"""The pack voltage of a pack of identical cells: the one implementation every simulator uses.

A pack of ``series`` groups of ``parallel`` identical cells, each cell carrying
``I_pack / parallel``, has the terminal voltage

    V_pack = series * V_cell - I_pack * R_eq(T)

where ``R_eq`` is the interconnect resistance of liionpack's netlist reduced for identical cells
(:func:`~battery_predictor.simulation.network.equivalent_network_resistance_ohm`). With a weak
series group (extension ``cell_imbalance``) one group's cell voltage ``V_weak`` replaces one of
the ``series`` normal ones. ``R_eq(T)`` follows an Arrhenius law when the series resistance has an
activation energy (extension ``temperature``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

#: Gas constant in J/(mol K).
GAS_CONSTANT_J_MOL_K = 8.314462618
#: Temperature at which a series resistance is stated (K).
REFERENCE_TEMPERATURE_K = 298.15


def series_resistance_factor(temperature_k: npt.ArrayLike, activation_energy_j_mol: float,
                             reference_temperature_k: float = REFERENCE_TEMPERATURE_K) -> np.ndarray:
    """Arrhenius factor ``exp(E/R (1/T - 1/T_ref))`` of the series resistance (1 when ``E`` is 0).

    Parameters
    ----------
    temperature_k : float or numpy.ndarray
        Cell temperature in K.
    activation_energy_j_mol : float
        Activation energy in J/mol.
    reference_temperature_k : float
        Temperature in K at which the resistance is stated.
    """
    temperature_k = np.asarray(temperature_k, dtype=float)
    if activation_energy_j_mol == 0.0:
        return np.ones_like(temperature_k)
    inverse_k = 1.0 / temperature_k - 1.0 / reference_temperature_k
    return np.exp(activation_energy_j_mol / GAS_CONSTANT_J_MOL_K * inverse_k)


def pack_voltage_v(cell_voltage_v: npt.ArrayLike, pack_current_a: npt.ArrayLike, *, series: int,
                   r_eq_ohm: npt.ArrayLike, weak_cell_voltage_v: npt.ArrayLike | None = None) -> np.ndarray:
    """Pack terminal voltage in V.

    Parameters
    ----------
    cell_voltage_v : float or numpy.ndarray
        Terminal voltage of a cell of the normal groups (V).
    pack_current_a : float or numpy.ndarray
        Pack current (A, positive = discharge).
    series : int
        Number of series groups.
    r_eq_ohm : float or numpy.ndarray
        Equivalent interconnect resistance (Ohm), already at the cell temperature
        (see :func:`series_resistance_factor`).
    weak_cell_voltage_v : float or numpy.ndarray, optional
        Terminal voltage of a cell of the one weak group; None when all groups are equal.

    Returns
    -------
    numpy.ndarray
        ``series * V_cell - I * R_eq``, or ``(series - 1) * V_cell + V_weak - I * R_eq``.
    """
    cell = np.asarray(cell_voltage_v, dtype=float)
    drop = np.asarray(pack_current_a, dtype=float) * np.asarray(r_eq_ohm, dtype=float)
    if weak_cell_voltage_v is None:
        return series * cell - drop
    return (series - 1) * cell + np.asarray(weak_cell_voltage_v, dtype=float) - drop
