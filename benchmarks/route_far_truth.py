"""Route answers for a Ranger pack whose truth is drawn far from the shipped params: how often wrong, which way.

For each seed: the truth LiFePO4 pack and its two days of ``identification_far_truth.py`` (lumped thermal
cells, recorded as the paper's instruments do (``--instrument``: 10 Hz averaged to 5 s by default, ``5s`` as
before 2026-11-28), longest routes at random payloads with
standstills between them). Day 1 is fitted with ``battery-predictor fit --params params/ranger_mini.yaml``
at its defaults. Along day 2, every ``--every`` minutes, the predictor's core (node defaults; fed day 2's
samples so far, as the monitor's windows) is asked ``/can_accept_route`` for the longest route with a
payload drawn from 0-80 kg. The truth answers the same question: the truth pack, driven by day 2's load up
to that moment and then by the route with each curve point's current drawn from the measured (payload,
slope) samples (as the paper's experiments), ends the route's last standstill at or above 46.31 V (a
cell reaching its cut-off during the route is a "no").

With ``--weak-group LO HI`` the truth pack has one weak series group (the ``cell_imbalance`` extension: its
cells hold a fraction drawn from LO..HI of the others' capacity), which the fitted params (``ranger_mini.yaml``:
identical cells) do not have: its battery management stops the pack when the weak cells reach their cut-off,
while the pack voltage is still above the route threshold.

Printed: accepted / rejected against the truth, **unsafe accepts** (yes where the truth says no; must be 0),
wasted rejects, and the error of the P50 voltage after the route against the truth's.

Run::

    nice .venv/bin/python benchmarks/route_far_truth.py --seeds 60 61 [--every 20] [--instrument paper|5s]
        [--drift-correction auto|full|smallest] [--weak-group LO HI] [--work DIR] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

import identification_far_truth as far  # noqa: E402

from battery_predictor.fitting.identifiable import pybamm_values  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.prediction.core import DRIFT_CORRECTIONS, PredictorConfig, PredictorCore  # noqa: E402
from battery_predictor.profiles import load_ranger_currents, longest_route, route_profile  # noqa: E402
from battery_predictor.simulation import SimulationRequest, StepLoad, get_simulator  # noqa: E402
from battery_predictor.simulation.extensions import with_weak_group  # noqa: E402

THRESHOLD_V = 46.31


def truth_after_route(truth_params, day_load: StepLoad, at_s: float, route_load: StepLoad) -> float:
    """The truth pack's voltage (V) at the end of the route started ``at_s`` into the day; NaN if it stops."""
    thermal = replace(truth_params, options={**truth_params.options, "thermal": "lumped"})
    load = day_load.truncate(at_s).append(route_load)
    end_s = load.duration_s - 1.0
    # a grid to the end: a pack that stops on the way returns the samples up to its stop
    req = SimulationRequest(load=load, output_time_s=np.append(np.arange(0.0, end_s, 30.0), end_s),
                            initial_pack_ocv_v=far.PACKS["ranger"][2] * truth_params.series)
    res = get_simulator("fast").simulate(thermal, req)
    if res.time_s.size < 2 or res.time_s[-1] < end_s - 1e-6:
        return math.nan
    return float(res.pack_voltage_v[-1])


def run_seed(seed: int, every_min: float, work: Path, instrument: str = far.INSTRUMENT,
             drift_correction: str = "full", weak_group: tuple[float, float] | None = None) -> dict:
    """Fit day 1 of ``seed``'s truth with the CLI, then score the route answers along day 2.

    ``weak_group`` (low, high): the truth has a weak series group of a capacity fraction drawn from that range.
    """
    params = load_params(REPO / "params" / "ranger_mini.yaml")
    truth = far.draw_truth(params, np.random.default_rng(1000 + seed))
    truth_params = params.with_values(pybamm_values(params, truth)[0])
    weak_fraction = 1.0
    if weak_group is not None:
        weak_fraction = float(np.random.default_rng(7000 + seed).uniform(*weak_group))
        truth_params = with_weak_group(truth_params, weak_fraction)
    fit_day, _, _ = far.day(truth_params, 2 * seed + 1, None, "ranger", instrument)
    test_day, _, test_load = far.day(truth_params, 2 * seed + 2, far.PACKS["ranger"][2], "ranger", instrument)
    fit_csv, fit_yaml = work / f"r{seed}_day1.csv", work / f"r{seed}_fit.yaml"
    if not fit_yaml.exists():  # a kept fit (--work) is the same day's: ask it again, do not fit again
        far.write_day_csv(fit_day, fit_csv)
        far.fit_with_cli(REPO / "params" / "ranger_mini.yaml", fit_csv, fit_yaml)
    core = PredictorCore(PredictorConfig(params_file=str(fit_yaml), drift_correction=drift_correction))
    currents = load_ranger_currents()
    rng = np.random.default_rng(5000 + seed)
    t, v, i = test_day.relative_time_s, test_day.voltage_v, test_day.current_a
    answers, k = [], 0
    for at_s in np.arange(every_min * 60.0, t[-1], every_min * 60.0):
        while k < t.size and t[k] <= at_s:
            core.update_state(float(t[k]), float(v[k]), float(i[k]), 298.15)
            core.precalibrate()
            k += 1
        payload = float(rng.uniform(0.0, 80.0))
        route = longest_route(payload)
        decision = core.can_accept_route(route.sections, float(t[k - 1]))
        route_load = StepLoad.from_profile(route_profile(route, currents, seed=rng, mode="sampled"))
        truth_v = truth_after_route(truth_params, test_load, float(t[k - 1]), route_load)
        answers.append({"at_min": round(float(t[k - 1]) / 60.0, 1), "payload_kg": round(payload, 1),
                        "accepted": decision.accepted, "truth_yes": bool(truth_v >= THRESHOLD_V),
                        "predicted_v": decision.predicted_voltage_v, "truth_v": truth_v,
                        "measured_v": float(v[k - 1]), "reason": decision.reason})
    return {"seed": seed, "weak_fraction": weak_fraction, "answers": answers}


def tally(answers: list[dict]) -> dict:
    """Counts of right and wrong answers and the P50 voltage error (V) where both ends are known."""
    unsafe = [a for a in answers if a["accepted"] and not a["truth_yes"]]
    wasted = [a for a in answers if not a["accepted"] and a["truth_yes"]]
    err = [a["predicted_v"] - a["truth_v"] for a in answers
           if math.isfinite(a["predicted_v"]) and math.isfinite(a["truth_v"])]
    return {"questions": len(answers), "truth_yes": sum(a["truth_yes"] for a in answers),
            "accepted": sum(a["accepted"] for a in answers), "unsafe_accepts": len(unsafe),
            "wasted_rejects": len(wasted), "voltage_mae_v": float(np.mean(np.abs(err))) if err else math.nan,
            "voltage_bias_v": float(np.mean(err)) if err else math.nan}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", nargs="+", type=int, default=[60])
    ap.add_argument("--every", type=float, default=20.0, help="minutes between route questions along day 2")
    ap.add_argument("--instrument", choices=far.INSTRUMENTS, default=far.INSTRUMENT)
    ap.add_argument("--drift-correction", choices=DRIFT_CORRECTIONS, default=PredictorConfig.drift_correction,
                    help="the predictor's drift_correction (node parameter; default: the node's default)")
    ap.add_argument("--weak-group", nargs=2, type=float, default=None, metavar=("LO", "HI"),
                    help="the truth pack has a weak series group of a capacity fraction drawn from LO..HI")
    ap.add_argument("--work", type=Path, default=None,
                    help="keep the days and fits here and reuse a kept fit (ask one fit several ways)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        rows = [run_seed(s, args.every, work, args.instrument, args.drift_correction,
                         None if args.weak_group is None else tuple(args.weak_group)) for s in args.seeds]
    pooled = tally([a for r in rows for a in r["answers"]])
    if args.json:
        print(json.dumps({"seeds": rows, "pooled": pooled}, indent=1, default=float))
        return
    for r in rows:
        s = tally(r["answers"])
        weak = f" (weak group {r['weak_fraction']:.3f})" if r["weak_fraction"] < 1.0 else ""
        print(f"seed {r['seed']}{weak}: {s['questions']} questions, truth yes {s['truth_yes']}, accepted {s['accepted']}, "
              f"unsafe accepts {s['unsafe_accepts']}, wasted rejects {s['wasted_rejects']}, P50 voltage error "
              f"{s['voltage_mae_v']:.3f} V (bias {s['voltage_bias_v']:+.3f} V)")
        for a in r["answers"]:
            if a["accepted"] != a["truth_yes"]:
                print(f"  {'UNSAFE' if a['accepted'] else 'wasted'} at {a['at_min']} min, {a['payload_kg']} kg: "
                      f"measured {a['measured_v']:.2f} V, predicted {a['predicted_v']:.2f} V, truth "
                      f"{a['truth_v']:.2f} V; {a['reason'][:140]}")
    print(f"pooled: {json.dumps(pooled)}")


if __name__ == "__main__":
    main()
