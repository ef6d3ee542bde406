"""Re-apply the diagnosis's decision rule to stored diagnoses of known cases, with rule constants changed.

A rule change (``battery_predictor/diagnosis/decision.py``) can be tried on the candidates' held-out
errors a sweep already measured, in seconds, instead of re-running every diagnosis. The cases come from
``benchmarks/diagnosis_generator2.py --json-dir DIR`` (files ``{seed}_{robot}_{effect}.json``, the
effect being the truth); ``collect`` keeps the fields the decision reads in one JSON-lines file,
``score`` decides each case again and prints the right-cause count, the claims on ``none`` and the misses.

    python benchmarks/diagnosis_rescore.py collect DIR... --label tuning --out cases.jsonl
    python benchmarks/diagnosis_rescore.py score cases.jsonl [--label tuning] [--set BASELINE_FLOOR_FACTOR=3 ...]

The rescoring calls the diagnosis's own ``decision.name_cause`` (the simplest candidate within the
separability margin, a measured temperature shift first, then ``claim_allowed``). The coverage rule (no claim beyond
the references' depth) is applied from the recorded figures when the case's original claim was the same
cause; for another cause the recorded figures do not exist and the case is marked ``coverage?``.
Never tune a constant on the seeds that then judge it: label the verdict seeds and keep them out of the
tuning (``--label``).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from battery_predictor.diagnosis import decision

_NAME = re.compile(r"^(?P<seed>\d+)_(?P<robot>temi|ranger_mini)_(?P<effect>\w+)\.json$")


def case_record(path: Path, label: str) -> dict[str, Any] | None:
    """The decision's inputs of one stored diagnosis (None when the file name does not name a case)."""
    m = _NAME.match(path.name)
    if m is None:
        return None
    d = json.loads(path.read_text())
    cov = d.get("reference_coverage") or {}
    return {
        "label": label, "seed": int(m["seed"]), "robot": m["robot"], "truth": m["effect"], "named": d["cause"],
        "noise_mv": d["noise_mV"], "reference_rmse_mv": (d.get("reference_fit") or {}).get("rmse_mV"),
        "temperature_shift_k": d.get("temperature_shift_k"), "baseline_mv": d["baseline"]["heldout_rmse_mV"],
        "candidates": {c["cause"]: c["heldout_rmse_mV"] for c in d["candidates"]},
        "unresolved": sorted(c["cause"] for c in d["candidates"] if c.get("unresolved")),
        "coverage": {**{k: cov.get(k) for k in ("cause", "baseline_rmse_mV", "cause_rmse_mV",
                                                 "covered_heldout_samples")},
                     "leaves_range": _leaves_range(cov)} if cov else None,
    }


def _leaves_range(cov: dict[str, Any]) -> bool:
    """Whether an observed recording went deeper than the references (``Coverage.leaves_range`` from its JSON)."""
    return any(u is not None and math.isfinite(float(u)) for u in cov.get("covered_until_s") or ())


def decide(case: dict[str, Any]) -> str:
    """The cause named for ``case`` by the decision module's present rule and constants."""
    noise = float(case["noise_mv"])
    unresolved = set(case.get("unresolved", ()))  # below the instruments' resolution: never named
    valid = [SimpleNamespace(cause=c, heldout_rmse_mV=float(v)) for c, v in case["candidates"].items()
             if v is not None and math.isfinite(float(v)) and c not in unresolved]
    shift = case["temperature_shift_k"]
    ref = case["reference_rmse_mv"]
    floor = max(noise, float(ref) if ref is not None else 0.0)
    best, cause = decision.name_cause(valid, float(case["baseline_mv"]), noise, floor, shift)  # type: ignore[arg-type]
    if best is None or cause == "none":
        return "none"
    cov = case["coverage"]
    if cov and cov.get("leaves_range") and cov.get("covered_heldout_samples") == 0 \
            and best.cause not in decision.measured_causes(shift):
        return "none"  # no held-out sample within the references' depth: no claim can be checked there
    if cov and cov.get("baseline_rmse_mV") is not None and best.cause not in decision.measured_causes(shift):
        if cov.get("cause") != best.cause:
            return best.cause + " (coverage?)"
        if not decision.claim_allowed(cov["baseline_rmse_mV"], cov["cause_rmse_mV"], noise, floor, measured=True):
            return "none"
    return best.cause


def _collect(args: argparse.Namespace) -> int:
    records = [r for d in args.dirs for p in sorted(Path(d).glob("*.json")) if (r := case_record(p, args.label))]
    with open(args.out, "a" if args.append else "w") as fh:
        for r in records:
            fh.write(json.dumps(r) + "\n")
    print(f"{len(records)} cases -> {args.out}")
    return 0


def _score(args: argparse.Namespace) -> int:
    for item in args.set or []:
        name, _, value = item.partition("=")
        if not hasattr(decision, name):
            print(f"error: decision has no constant {name}", file=sys.stderr)
            return 2
        setattr(decision, name, float(value))
    cases = [json.loads(line) for line in Path(args.cases).read_text().splitlines() if line.strip()]
    cases = [c for c in cases if args.label is None or c["label"] == args.label]
    right = claims_on_none = 0
    for c in cases:
        named = decide(c)
        right += named == c["truth"]
        claims_on_none += c["truth"] == "none" and named != "none"
        if named != c["truth"] or args.all:
            print(f"{c['label']:8s} seed {c['seed']:3d} {c['robot']:11s} {c['truth']:22s} -> {named:22s} "
                  f"(recorded {c['named']})")
    share = 100.0 * right / len(cases) if cases else float("nan")
    print(f"right cause: {right} of {len(cases)} ({share:.0f} %); claims on none: {claims_on_none}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    col = sub.add_parser("collect", help="keep the decision's inputs of stored diagnoses")
    col.add_argument("dirs", nargs="+")
    col.add_argument("--label", required=True, help="e.g. tuning or verdict")
    col.add_argument("--out", required=True)
    col.add_argument("--append", action="store_true")
    sc = sub.add_parser("score", help="decide the stored cases again")
    sc.add_argument("cases")
    sc.add_argument("--label", default=None)
    sc.add_argument("--set", action="append", metavar="NAME=VALUE", help="a decision constant's value")
    sc.add_argument("--all", action="store_true", help="print every case, not only the misses")
    args = ap.parse_args(argv)
    return _collect(args) if args.command == "collect" else _score(args)


if __name__ == "__main__":
    raise SystemExit(main())
