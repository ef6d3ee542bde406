"""Equivalent interconnect resistance of a pack of identical cells (liionpack's netlist).

liionpack builds the ``parallel-strings`` netlist; its resistive network is reduced here by nodal analysis (the
cells' sources shorted, their nodes merged) with the element values substituted per kind (busbar, cell
connection, cell, terminal), so that a fit that moves the resistances solves a small dense system (0.1-0.7 ms)
instead of liionpack's general sparse set-up and solve (9-15 ms) at every model evaluation
(``benchmarks/network_resistance.py``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.linalg

#: Cell Thevenin resistance used when reducing the netlist (Ohm). The result barely
#: depends on it (busbar-induced current imbalance is second order).
_TYPICAL_CELL_RESISTANCE_OHM = 0.05
#: Resistance (Ohm) that stands for a resistance of zero (a short) in the nodal matrix; its share of ``R_eq``
#: is of this order, far below any measurable interconnect.
_SHORT_OHM = 1e-9
#: Element kinds of liionpack's netlist, by the first letters of their ``desc``.
_KINDS = ("Rb", "Rc", "Ri", "Rt")


@dataclass(frozen=True)
class _Topology:
    """The netlist's resistive network with the cells' sources shorted (their nodes merged) and the negative
    terminal as ground: per element kind, the nodal conductance pattern of one unit conductance."""

    patterns: dict[str, np.ndarray]
    terminal_node: int


@functools.lru_cache(maxsize=16)
def _topology(series: int, parallel: int) -> _Topology:
    """The ``series`` x ``parallel`` netlist of liionpack as nodal-analysis patterns (no values)."""
    import liionpack as lp

    netlist = lp.setup_circuit(Np=parallel, Ns=series, Rb=1.0, Rc=1.0, Ri=1.0, Rt=1.0, V=1.0, I=1.0)
    desc = netlist["desc"].astype(str).to_numpy()
    ends = netlist[["node1", "node2"]].to_numpy(dtype=int)
    merged = list(range(int(ends.max()) + 1))  # node 0 is ground

    def root(node: int) -> int:
        while merged[node] != node:
            node = merged[node]
        return node

    for (a, b) in ends[[d[0] == "V" for d in desc]]:
        low, high = sorted((root(a), root(b)))
        merged[high] = low
    roots = sorted({root(n) for n in range(len(merged))} - {0})
    index = {r: i for i, r in enumerate(roots)}
    patterns = {kind: np.zeros((len(roots), len(roots))) for kind in _KINDS}
    for d, (a, b) in zip(desc, ends):
        if d[0] != "R":
            continue
        ia, ib = index.get(root(a)), index.get(root(b))
        for p, q, sign in ((ia, ia, 1.0), (ib, ib, 1.0), (ia, ib, -1.0), (ib, ia, -1.0)):
            if p is not None and q is not None:
                patterns[d[:2]][p, q] += sign
    (terminal,) = ends[desc == "I0", 0]
    return _Topology(patterns, index[root(int(terminal))])


@functools.lru_cache(maxsize=256)
def equivalent_network_resistance_ohm(series: int, parallel: int, r_b_ohm: float, r_c_ohm: float,
                                      r_t_ohm: float) -> float:
    """Pack resistance in Ohm added by the interconnect, beyond ``series/parallel`` x cell resistance.

    Reduces liionpack's own ``parallel-strings`` netlist (terminals left) with all cells identical, so
    that ``V_pack = series * V_cell(I / parallel) - I * R_eq``. The network is linear, so its resistance
    is the terminal voltage drop at 1 A with the cells' sources at zero. A resistance of zero is a short.

    Parameters
    ----------
    series, parallel : int
        Pack configuration.
    r_b_ohm, r_c_ohm, r_t_ohm : float
        Busbar, cell-connection and terminal resistances in Ohm (>= 0).

    Returns
    -------
    float
        ``R_eq`` in Ohm.
    """
    topology = _topology(series, parallel)
    values = {"Rb": r_b_ohm, "Rc": r_c_ohm, "Ri": _TYPICAL_CELL_RESISTANCE_OHM, "Rt": r_t_ohm}
    n_nodes = len(topology.patterns["Rb"])
    conductance = np.zeros((n_nodes, n_nodes))
    for kind in _KINDS:
        conductance += topology.patterns[kind] / max(float(values[kind]), _SHORT_OHM)
    injection = np.zeros(n_nodes)
    injection[topology.terminal_node] = 1.0
    terminal_v = scipy.linalg.solve(conductance, injection, assume_a="pos", check_finite=False)[topology.terminal_node]
    return float(terminal_v) - series * _TYPICAL_CELL_RESISTANCE_OHM / parallel
