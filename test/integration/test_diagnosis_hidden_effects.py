"""The diagnosis names a hidden effect: files in, the CLI as a subprocess, the named cause out.

For every entry of the catalogue (and ``none``) the generator (:mod:`effect_generator`, test code the
diagnosis never imports) writes a reference recording without the effect and an observed recording
with ONE effect of random realistic magnitude, on a working day of the robot's kind. Only the CSV
files cross over to ``battery-predictor diagnose``; the test asserts the named cause is the hidden
one with a held-out RMSE gain of at least 30 % (for ``none``: that nothing is claimed).

Seeds: the test parameter ``seed`` (``BP_DIAG_SEEDS``, comma separated, default ``0``) seeds every
draw (reference perturbation, magnitude, profile, noise) together with the cause and pack, and
also alternates the pack: causes alternate between the Temi and the Ranger pack and swap with the
seed's parity, so both packs are used in every run and every cause meets both packs over two
seeds. Exception: ``electrolyte_transport`` stays on the Temi pack, the only robot that draws a high
rate (the Ranger pack never exceeds about C/3, where electrolyte polarisation is below what a
held-out comparison can separate; see docs/findings.md).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from effect_generator import CAUSES, PACKS, make_scenario

SEEDS = [int(s) for s in os.environ.get("BP_DIAG_SEEDS", "0").split(",") if s.strip()]
CLI = str(Path(sys.executable).parent / "battery-predictor")
_ONLY_TEMI = {"electrolyte_transport"}


def pack_for(cause: str, seed: int) -> str:
    """Pack of a (cause, seed): alternating over the catalogue, swapped by the seed's parity."""
    if cause in _ONLY_TEMI:
        return "temi"
    return PACKS[(CAUSES.index(cause) + seed) % 2]


def test_every_run_uses_both_packs_and_every_cause():
    for seed in (0, 1):
        assert {pack_for(c, seed) for c in CAUSES} == set(PACKS)
    assert {pack_for(c, s) for c in CAUSES if c not in _ONLY_TEMI for s in (0, 1)} == set(PACKS)
    assert set(CAUSES) == {"temperature", "capacity_fade", "resistance_growth", "current_offset", "cell_imbalance",
                           "electrolyte_transport", "hysteresis", "none"}


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("cause", CAUSES)
def test_diagnose_names_the_hidden_effect(tmp_path, cause, seed, process_workers_args):
    pack = pack_for(cause, seed)
    sc = make_scenario(cause, pack, seed, tmp_path)
    cmd = [CLI, "diagnose", "--params", str(sc.params_path), "--reference", str(sc.reference_csv),
           "--data", str(sc.observed_csv), "--json", "--quiet", *process_workers_args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected exactly one JSON line, got {len(lines)}"
    result = json.loads(lines[0])
    for key in ("cause", "evidence", "baseline", "extended", "gain_pct", "candidates"):
        assert key in result
    for key in ("heldout_rmse_mV", "heldout_r2_mod", "runtime_error_s"):
        assert key in result["baseline"] and key in result["extended"]
    assert {c["cause"] for c in result["candidates"]} == set(CAUSES) - {"none"}
    table = {c["cause"]: c["heldout_rmse_mV"] for c in result["candidates"]}
    context = (f"hidden {cause} on {pack} (seed {seed}, magnitude {sc.magnitude}): named {result['cause']}, gain "
               f"{result['gain_pct']:.1f} %, baseline {result['baseline']['heldout_rmse_mV']:.1f} mV, "
               f"candidates {table}; {result['evidence']}")
    if cause == "none":
        assert result["cause"] == "none", context
    else:
        assert result["cause"] == cause, context
        assert result["gain_pct"] >= 30.0, context
