"""EnginePack.run_end (a route decision's end of a run, no samples) equals the end of EnginePack.run."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from battery_predictor.simulation.engine.segments import EnginePack

REPO = Path(__file__).resolve().parents[2]
#: The fused kernel and the two-pass path evaluate the same expression; they differ by rounding only.
SAME_V = 1e-9
#: Cut-off times are located to 1e-7 s by both paths.
SAME_S = 1e-6


def _same_end(pack: EnginePack, start, segments, temperature_k: float) -> None:
    run = pack.run(start, segments, temperature_k)
    end = pack.run_end(start, segments, temperature_k)
    assert end.reached_cutoff == run.reached_cutoff
    assert end.end_time_s == pytest.approx(run.end_time_s, rel=0, abs=SAME_S)
    if run.reached_cutoff:
        assert end.pack_voltage_v != end.pack_voltage_v  # NaN
    else:
        assert end.pack_voltage_v == pytest.approx(float(run.pack_voltage_v[-1]), rel=0, abs=SAME_V)


@pytest.mark.parametrize("temperature_k", [278.15, 297.15, 298.15])
def test_run_end_equals_the_last_sample_of_a_run(ranger_params, longest_route_segments, temperature_k):
    pack = EnginePack(ranger_params)
    _same_end(pack, 0.4, longest_route_segments, temperature_k)
    _same_end(pack, pack.run(0.6, [(300.0, 2.0)], temperature_k).final_state, longest_route_segments, temperature_k)


def test_run_end_finds_the_same_cutoff(ranger_params):
    pack = EnginePack(ranger_params)
    _same_end(pack, 0.1, [(600.0, 20.0)] * 6, 298.15)
    below = pack.run(0.1, [(600.0, 20.0)] * 6, 298.15).final_state
    _same_end(pack, below, [(60.0, 30.0)], 298.15)  # below the cut-off as soon as the current flows


def test_run_end_with_a_weak_group_and_a_current_offset(ranger_params, longest_route_segments):
    from battery_predictor.simulation.extensions import weak_group_fraction

    params = ranger_params.with_values({"Weak series group capacity fraction": 0.8}, extensions=("cell_imbalance",))
    pack = EnginePack(params, weak_fraction=weak_group_fraction(params), current_offset_a=0.3)
    _same_end(pack, 0.3, longest_route_segments, 298.15)
    _same_end(pack, pack.run(0.5, [(120.0, 5.0)], 298.15).final_state, longest_route_segments, 290.0)
    _same_end(pack, 0.12, [(600.0, 20.0)] * 4, 298.15)  # the weak group reaches the cut-off first


def test_run_end_with_an_arrhenius_series_resistance(ranger_params, longest_route_segments):
    from battery_predictor.simulation.extensions import EA_SERIES, extension_value

    params = ranger_params.with_values({"Negative particle diffusivity activation energy [J.mol-1]": 30000.0,
                                 "Positive particle diffusivity activation energy [J.mol-1]": 25000.0,
                                 EA_SERIES: 20000.0}, extensions=("temperature",))
    pack = EnginePack(params, series_activation_j_mol=extension_value(params, EA_SERIES))
    _same_end(pack, 0.3, longest_route_segments, 278.15)


def test_run_end_of_thermal_cells_is_the_end_of_their_run(ranger_params, longest_route_segments):
    pack = EnginePack(replace(ranger_params, options={"thermal": "lumped"}))
    _same_end(pack, 0.4, longest_route_segments, 288.15)


def test_cached_per_temperature_arrays_give_the_same_answers(ranger_params, longest_route_segments):
    """EnginePack keeps the kernel's per-set arrays per temperature (route answers repeat a few): the
    runs with them are bit-identical to runs that compute them afresh, and the cached arrays are read-only."""
    import numpy as np

    from battery_predictor.simulation.extensions import weak_group_fraction

    params = ranger_params.with_values({"Weak series group capacity fraction": 0.8}, extensions=("cell_imbalance",))
    for pack in (EnginePack(ranger_params), EnginePack(params, weak_fraction=weak_group_fraction(params))):
        state = pack.run(0.6, [(300.0, 2.0)], 297.15).final_state
        for temperature_k in (297.15, 290.0, 297.15):
            cached = pack.run_end(state, longest_route_segments, temperature_k)
            run = pack.run(state, longest_route_segments, temperature_k)
            pack._sets.clear()  # the next runs compute the arrays afresh
            assert pack.run_end(state, longest_route_segments, temperature_k) == cached
            fresh = pack.run(state, longest_route_segments, temperature_k)
            assert np.array_equal(fresh.pack_voltage_v, run.pack_voltage_v)
            assert fresh.end_time_s == run.end_time_s
        _sets, batch = pack._sets_at(297.15)
        assert not batch.lam.flags.writeable and not batch.drive.flags.writeable
