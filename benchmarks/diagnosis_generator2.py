"""Sweep the diagnosis over the second, independent hidden-effect generator (issue #12).

For every seed, robot and effect of the catalogue (``test/integration/diagnosis_generator2.py``), generate a
reference day and an observed day, run ``battery-predictor diagnose`` as a subprocess, and print one
Markdown row per case plus the share named right, the claims on ``none`` and the median held-out gain
of the named effects.

    nice .venv/bin/python benchmarks/diagnosis_generator2.py --seeds 0 1 2 [--robots temi] [--effects none]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "test" / "integration"))

from diagnosis_generator2 import ROBOT_EFFECTS, ROBOTS, make_case  # noqa: E402

#: The CLI run by this interpreter (its PYTHONPATH and environment), not the venv's entry-point script.
CLI = [sys.executable, "-m", "battery_predictor.cli.main"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--robots", nargs="+", choices=ROBOTS, default=list(ROBOTS))
    ap.add_argument("--effects", nargs="+", default=None)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--json-dir", type=Path, default=None, help="keep each case's diagnose JSON here")
    args = ap.parse_args(argv)
    rows, right, total, claims_on_none, gains = [], 0, 0, 0, []
    print("| seed | robot | effect | magnitude | charging stop | named | gain (%) | baseline (mV) | reference RMSE (mV) | "
          "best candidate (gain %) | time (s) |")
    print("|---|---|---|---|---|---|---:|---:|---:|---|---:|")
    for seed in args.seeds:
        for robot in args.robots:
            for effect in ROBOT_EFFECTS[robot]:
                if args.effects and effect not in args.effects:
                    continue
                with tempfile.TemporaryDirectory() as tmp:
                    case = make_case(effect, robot, seed, Path(tmp))
                    cmd = [*CLI, "diagnose", "--params", str(case.params_path), "--reference", str(case.reference_csv),
                           "--data", str(case.observed_csv), "--json", "--quiet"]
                    if args.workers:
                        cmd += ["--workers", str(args.workers)]
                    tic = time.perf_counter()
                    proc = subprocess.run(cmd, capture_output=True, text=True)
                    seconds = time.perf_counter() - tic
                if proc.returncode != 0:
                    named, gain, base, ref = "error: " + proc.stderr.strip().splitlines()[-1][:80], 0.0, float("nan"), float("nan")
                    best = ""
                else:
                    out = json.loads(proc.stdout)
                    named, gain = out["cause"], out["gain_pct"]
                    base = out["baseline"]["heldout_rmse_mV"]
                    ref = (out.get("reference_fit") or {}).get("rmse_mV", float("nan"))
                    scored = [c for c in out["candidates"] if c["cause"] != "none" and "not_applicable" not in c]
                    top = max(scored, key=lambda c: c["gain_pct"], default=None)
                    best = "" if top is None else f"{top['cause']} ({top['gain_pct']:.1f})"
                    if args.json_dir:
                        args.json_dir.mkdir(parents=True, exist_ok=True)
                        (args.json_dir / f"{seed}_{robot}_{effect}.json").write_text(proc.stdout)
                total += 1
                right += named == effect
                if effect == "none" and named != "none":
                    claims_on_none += 1
                if named == effect and effect != "none":
                    gains.append(gain)
                mag = ", ".join(f"{k} {v:.3g}" for k, v in case.magnitude.items())
                print(f"| {seed} | {robot} | {effect} | {mag} | {case.charging_stop} | {named} | {gain:.1f} | "
                      f"{base:.1f} | {ref:.1f} | {best} | {seconds:.0f} |", flush=True)
                rows.append((seed, robot, effect, named))
    print(f"\nright cause: {right} of {total} ({100.0 * right / max(total, 1):.0f} %); claims on none: {claims_on_none}; "
          f"median held-out gain of the named effects: {statistics.median(gains) if gains else float('nan'):.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
