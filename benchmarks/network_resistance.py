"""The interconnect's equivalent resistance per call: liionpack's own solve against the package's reduction.

A fit or a diagnosis that moves the interconnect resistances computes ``R_eq`` once per model evaluation
(the cache cannot help: every evaluation brings new values). This prints, per pack configuration, the time
per call of liionpack's ``setup_circuit`` + ``solve_circuit`` (what the package called before) and of
:func:`battery_predictor.simulation.network.equivalent_network_resistance_ohm` with its value cache cleared (its
topology, built once per pack configuration, kept), side by side, and the largest relative difference between the two over the calls.

Usage: .venv/bin/python benchmarks/network_resistance.py [--calls 200]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from battery_predictor.simulation.network import equivalent_network_resistance_ohm  # noqa: E402

CELL_OHM = 0.05
PACKS = {"Panasonic 1S1P": (1, 1), "Temi 4S6P": (4, 6), "Ranger 15S4P": (15, 4), "Leaf 6S2P": (6, 2)}


def liionpack_ohm(series: int, parallel: int, r_b: float, r_c: float, r_t: float) -> float:
    """``R_eq`` from liionpack's netlist and solver, the cells' sources at zero."""
    import liionpack as lp

    netlist = lp.setup_circuit(Np=parallel, Ns=series, Rb=r_b, Rc=r_c, Ri=CELL_OHM, Rt=r_t, V=0.0, I=1.0)
    _, _, _, terminal_v, _ = lp.solve_circuit(netlist, current=1.0)
    return -float(terminal_v[0]) - series * CELL_OHM / parallel


def per_call_ms(function, args: np.ndarray, series: int, parallel: int) -> tuple[float, list[float]]:
    """Mean wall time per call (ms) and the values."""
    start = time.perf_counter()
    values = [function(series, parallel, *row) for row in args]
    return (time.perf_counter() - start) / len(args) * 1e3, values


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=200)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    import liionpack  # noqa: F401  (its import time is not a call's)

    rng = np.random.default_rng(0)
    print(f"{'pack':16s} {'liionpack ms':>13s} {'package ms':>11s} {'ratio':>7s} {'max rel diff':>13s}")
    for name, (series, parallel) in PACKS.items():
        values = 10 ** rng.uniform(-6, -2, (args.calls, 3))
        equivalent_network_resistance_ohm(series, parallel, 1e-4, 1e-4, 1e-4)  # the topology, built once per pack
        equivalent_network_resistance_ohm.cache_clear()
        lp_ms, lp_values = per_call_ms(liionpack_ohm, values, series, parallel)
        own_ms, own_values = per_call_ms(equivalent_network_resistance_ohm, values, series, parallel)
        diff = max(abs(a - b) / abs(b) for a, b in zip(own_values, lp_values))
        print(f"{name:16s} {lp_ms:13.2f} {own_ms:11.3f} {lp_ms / own_ms:7.1f} {diff:13.1e}")


if __name__ == "__main__":
    main()
