"""The interconnect's equivalent resistance: liionpack's netlist reduced by nodal analysis."""

from __future__ import annotations

import liionpack as lp
import numpy as np
import pytest

from battery_predictor.simulation.network import equivalent_network_resistance_ohm

CELL_OHM = 0.05  # the cell resistance the reduction assumes


def liionpack_resistance_ohm(series: int, parallel: int, r_b: float, r_c: float, r_t: float) -> float:
    """The same quantity from liionpack's own solver: cells' sources at zero, 1 A drawn at the terminals."""
    netlist = lp.setup_circuit(Np=parallel, Ns=series, Rb=r_b, Rc=r_c, Ri=CELL_OHM, Rt=r_t, V=0.0, I=1.0)
    _, _, _, terminal_v, _ = lp.solve_circuit(netlist, current=1.0)
    return -float(terminal_v[0]) - series * CELL_OHM / parallel


@pytest.mark.parametrize(("series", "parallel"), [(4, 6), (15, 4), (1, 1), (2, 3), (6, 2), (1, 5), (5, 1)])
def test_the_reduction_equals_liionpacks_solution_of_its_netlist(series, parallel):
    rng = np.random.default_rng(series * 100 + parallel)
    for r_b, r_c, r_t in 10 ** rng.uniform(-6, -1, (4, 3)):
        assert equivalent_network_resistance_ohm(series, parallel, r_b, r_c, r_t) == pytest.approx(
            liionpack_resistance_ohm(series, parallel, r_b, r_c, r_t), rel=1e-6)


def test_uniform_strings_with_negligible_busbars_add_series_connection_resistance_over_parallel():
    r = equivalent_network_resistance_ohm(4, 6, 1e-9, 0.09, 1e-9)
    assert r == pytest.approx(4 * 0.09 / 6, rel=1e-4)
    assert equivalent_network_resistance_ohm(4, 6, 1e-3, 0.09, 1e-9) > r


def test_a_zero_resistance_is_a_short_not_a_failure():
    assert equivalent_network_resistance_ohm(4, 6, 0.0, 0.0, 0.0) == pytest.approx(0.0, abs=1e-7)
    # liionpack cannot take a zero (it divides by it); a busbar of 0.1 uOhm is as good as none at 1e-3 relative
    assert equivalent_network_resistance_ohm(15, 4, 0.0, 1e-3, 1e-4) == pytest.approx(
        liionpack_resistance_ohm(15, 4, 1e-7, 1e-3, 1e-4), rel=1e-3)
