"""Both structures of ``fit`` identified on data that the ohmic one made (issue 17; engine simulations)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from battery_predictor.fitting.identifiable import default_space, ohmic_structure
from battery_predictor.fitting.identification import (
    STRUCTURE_AS_GIVEN,
    STRUCTURE_OHMIC,
    IdentificationProblem,
    identify_structures,
)
from battery_predictor.params import load_params
from battery_predictor.recording import Recording, step_resistance_ohm
from battery_predictor.simulation import get_simulator

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def panasonic():
    return load_params(REPO / "params" / "panasonic_18650pf.yaml")


def _stepped_recording(n: int, seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(float(n))
    i = np.repeat(rng.choice([0.5, 2.0, 5.0, 8.0, -2.0], size=n // 20), 20)[:n]
    return Recording(t, np.full(n, 4.0), i, source=f"stepped{seed}.csv")


def test_both_structures_are_identified_with_the_same_budget_and_ranked_by_r2_mod(panasonic):
    """A recording made by the ohmic structure: its identification scores higher, and comes first."""
    rec = _stepped_recording(600)
    fast, _ = ohmic_structure(panasonic, [Recording(rec.time_s, 4.0 - 0.03 * rec.current_a, rec.current_a)])
    truth = IdentificationProblem(fast, [rec], get_simulator("engine"), default_space(fast, [rec]))
    coords = {c.name: c.initial for c in truth.space}
    coords["series_resistance_ohm"] = 0.040
    result, _ = truth.simulate(coords)
    made = Recording(rec.relative_time_s, np.interp(rec.relative_time_s, result[0].time_s, result[0].pack_voltage_v),
                     rec.current_a, source="made.csv")
    seen: list[str] = []
    fits = identify_structures(panasonic, [made], get_simulator("engine"), lambda p: default_space(p, [made]),
                               ohmic=True, progress=lambda phase, n, cost: seen.append(phase), evaluations=12, seed=0,
                               tpe_fraction=0.0, starts=1)
    assert [f.label for f in fits] == [STRUCTURE_OHMIC, STRUCTURE_AS_GIVEN]
    assert fits[0].r2_mod > fits[1].r2_mod
    assert all(f.result.evaluations <= 12 for f in fits)
    assert any(p.startswith(STRUCTURE_OHMIC) for p in seen) and any(p.startswith(STRUCTURE_AS_GIVEN) for p in seen)
    ohmic_space = {c.name: c for c in fits[0].problem.space}
    assert ohmic_space["series_resistance_ohm"].initial == pytest.approx(step_resistance_ohm([made]))
    only = identify_structures(panasonic, [made], get_simulator("engine"), lambda p: default_space(p, [made]),
                               ohmic=False, evaluations=4, seed=0, tpe_fraction=0.0, starts=1)
    assert [f.label for f in only] == [STRUCTURE_AS_GIVEN]
