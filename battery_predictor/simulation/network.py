"""Equivalent interconnect resistance of a pack of identical cells (liionpack netlist)."""

from __future__ import annotations

import functools

#: Cell Thevenin resistance used when reducing the netlist (Ohm). The result barely
#: depends on it (busbar-induced current imbalance is second order).
_TYPICAL_CELL_RESISTANCE_OHM = 0.05


@functools.lru_cache(maxsize=256)
def equivalent_network_resistance_ohm(series: int, parallel: int, r_b_ohm: float, r_c_ohm: float,
                                      r_t_ohm: float) -> float:
    """Pack resistance in Ohm added by the interconnect, beyond ``series/parallel`` x cell resistance.

    Solves liionpack's own ``parallel-strings`` netlist (terminals left) with all
    cells identical, so that ``V_pack = series * V_cell(I / parallel) - I * R_eq``.

    Parameters
    ----------
    series, parallel : int
        Pack configuration.
    r_b_ohm, r_c_ohm, r_t_ohm : float
        Busbar, cell-connection and terminal resistances in Ohm.

    Returns
    -------
    float
        ``R_eq`` in Ohm.
    """
    import liionpack as lp

    v_cell = 3.6
    r_cell = _TYPICAL_CELL_RESISTANCE_OHM
    netlist = lp.setup_circuit(Np=parallel, Ns=series, Rb=r_b_ohm, Rc=r_c_ohm, Ri=r_cell, Rt=r_t_ohm, V=v_cell, I=1.0)
    _, _, _, v_term, _ = lp.solve_circuit(netlist, current=1.0)
    r_total = series * v_cell - float(v_term[0])
    return r_total - series * r_cell / parallel
