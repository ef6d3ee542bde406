"""After the fact: the first load state heavy enough to cross, with the threshold current from the model.

An experiment, not the predictor (docs/runtime_real_data/README.md, "The end event of a random usage"). It
follows ``end_event_posthoc.py`` with the two changes named there:

- **The threshold current from the model.** At each time ``tau`` ahead the answer's average-load run gives the
  pack voltage ``V(tau)`` and current ``I(tau)``; a 5 s window at ``I*`` crosses the cut-off where
  ``I* = I(tau) + (V(tau) - V_cut) / R(tau)``, with ``R`` the model's 5 s peak resistance: measured by the
  predictor's own run at ``tau = 0`` (``runtime.peak_voltage_drop_v``) and at its peak-load crossing (where ``I*``
  is the quantile peak), linear in between and held after it (``flat``: the crossing's value throughout).
- **A quantile of the first passage.** Window currents rise through a level at the upcrossing rate of the
  discharge's windows so far; the hazard ``rate(I*(tau))`` is integrated from now (or from the peak-load crossing)
  and the answer is where the passage probability reaches ``q`` (0.1, 0.25 or 0.5).

Each checkpoint of ``evaluate_recording`` (the predictor's core at its defaults) is captured once and the variants
are scored on the captures, beside the predictor's answer and the counters.

Run from the repository::

    nice .venv/bin/python docs/runtime_real_data/end_event_first_passage.py far 160 162 163      # far-truth Temi days
    nice .venv/bin/python docs/runtime_real_data/end_event_first_passage.py panasonic FIT.yaml 2.648 FILE.csv ...
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO))

import identification_far_truth as far  # noqa: E402

import battery_predictor.prediction.core as core_mod  # noqa: E402
import battery_predictor.prediction.runtime as runtime_mod  # noqa: E402
from battery_predictor.evaluation.runtime_eval import Windows, charge_to_end_ah, evaluate_recording  # noqa: E402
from battery_predictor.fitting.identifiable import pybamm_values  # noqa: E402
from battery_predictor.io.loader import load_recording  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402

CAPTURED: list[tuple] = []
SLOT: dict = {}
_PREDICT = core_mod.predict_remaining_runtime
_PEAK = runtime_mod.peak_crossing_s


def _peak_crossing(runner, start, average, peak_factor, temperature_k, cutoff_v, average_run, *, settle_s=5.0, **kw):
    """The predictor's peak-load crossing, kept with its average-load run and the peak resistance at now."""
    t_peak = _PEAK(runner, start, average, peak_factor, temperature_k, cutoff_v, average_run, settle_s=settle_s, **kw)
    t = np.asarray(average_run.time_s, dtype=float)
    first_a = average.current_at(0.0)
    drop_v = runtime_mod.peak_voltage_drop_v(runner, start, first_a, peak_factor * first_a, temperature_k, settle_s)
    SLOT.update(time_s=t, voltage_v=np.asarray(average_run.pack_voltage_v, dtype=float),
                current_a=np.array([average.current_at(x) for x in t]), factor=peak_factor, t_peak_s=t_peak,
                r0_ohm=drop_v / ((peak_factor - 1.0) * first_a), cutoff_v=cutoff_v)
    return t_peak


def _predict(*args, **kwargs):
    SLOT.clear()
    prediction = _PREDICT(*args, **kwargs)
    CAPTURED.append((prediction, dict(SLOT)))
    return prediction


def capture(fitted, rec, cutoff_v: float, capacities_ah: dict[str, float]) -> list[dict]:
    """One row per checkpoint: the answer, the truth, the counters and what the first passage needs."""
    CAPTURED.clear()
    result = evaluate_recording(fitted, rec, cutoff_v=cutoff_v, capacities_ah=capacities_ah)
    win = Windows.of(rec)
    rows = []
    for c in result.checkpoints:
        hits = [x for x in CAPTURED if abs(x[0].remaining_s - c.predicted_s) < 1e-6]
        prediction, slot = hits[-1] if hits else (None, {})
        now_s = result.discharge.start_s + c.time_s
        history = (win.time_s >= result.discharge.start_s) & (win.time_s <= now_s)
        rows.append({"fraction": c.fraction, "predicted_s": c.predicted_s, "true_s": c.true_remaining_s,
                     "counters_s": c.counters_s, "slot": slot,
                     "limited_by": prediction.limited_by if prediction else "?",
                     "t_avg_s": prediction.average_end_s if prediction else math.nan,
                     "history_s": float(np.ptp(win.time_s[history])) if history.any() else 0.0,
                     "history_a": win.current_a[history]})
    return rows


def first_passage_s(row: dict, q: float, from_peak: bool, resistance: str) -> float:
    """The time (s) by which the first passage has probability ``q``; the predictor's answer if not peak-limited."""
    slot, t_avg = row["slot"], row["t_avg_s"]
    t_peak = slot.get("t_peak_s")
    if row["limited_by"] != "peak_cutoff" or t_peak is None or not math.isfinite(t_avg) or t_avg <= t_peak:
        return row["predicted_s"]
    taus = np.linspace(0.0, t_avg, 400)
    v = np.interp(taus, slot["time_s"], slot["voltage_v"])
    i = np.interp(taus, slot["time_s"], slot["current_a"])
    i_peak = np.interp(t_peak, slot["time_s"], slot["current_a"])
    r_peak = (np.interp(t_peak, slot["time_s"], slot["voltage_v"]) - slot["cutoff_v"]) / max(
        (slot["factor"] - 1.0) * i_peak, 1e-9)
    if resistance == "interp":
        r = np.where(taus < t_peak, slot["r0_ohm"] + (r_peak - slot["r0_ohm"]) * taus / max(t_peak, 1e-9), r_peak)
    else:
        r = np.full(taus.size, r_peak)
    threshold_a = i + np.maximum(v - slot["cutoff_v"], 0.0) / np.maximum(r, 1e-6)
    hist = row["history_a"]
    duration_s = max(row["history_s"], 5.0)
    hazard, target, step_s = 0.0, -math.log(1.0 - q), taus[1] - taus[0]
    for tau, level in zip(taus, threshold_a, strict=True):
        if from_peak and tau < t_peak:
            continue
        hazard += np.sum((hist[:-1] < level) & (hist[1:] >= level)) / duration_s * step_s
        if hazard >= target:
            return float(tau)
    return float(t_avg)


def report(label: str, rows: list[dict]) -> None:
    """MAE, bias and the 50 % rule of the predictor, the counters and every first-passage variant."""
    def line(name: str, answer) -> None:
        err = np.array([(answer(r) - r["true_s"]) / 60.0 for r in rows])
        late = [r for r in rows if r["fraction"] >= 0.3 - 1e-9]
        off = sum(abs(answer(r) - r["true_s"]) > 0.5 * r["true_s"] for r in late)
        print(f"  {name:40s} MAE {np.mean(np.abs(err)):5.1f} min, bias {np.mean(err):+5.1f}, "
              f"off by > 50 % after 30 %: {off} of {len(late)}")

    print(f"{label}: {len(rows)} answers, {sum(r['limited_by'] == 'peak_cutoff' for r in rows)} peak-limited")
    line("predictor", lambda r: r["predicted_s"])
    for name in rows[0]["counters_s"]:
        line(f"counter ({name})", lambda r, name=name: r["counters_s"][name])
    for q in (0.1, 0.25, 0.5):
        for from_peak in (False, True):
            for resistance in ("interp", "flat"):
                line(f"q {q}, from {'peak' if from_peak else 'now'}, R {resistance}",
                     lambda r, q=q, f=from_peak, m=resistance: first_passage_s(r, q, f, m))


def far_rows(seed: int, work: Path) -> list[dict]:
    params = load_params(REPO / "params" / "temi.yaml")
    truth = far.draw_truth(params, np.random.default_rng(1000 + seed))
    truth_params = params.with_values(pybamm_values(params, truth)[0])
    fit_day, _, _ = far.day(truth_params, 2 * seed + 1, None, "temi")
    test_day, _, _ = far.day(truth_params, 2 * seed + 2, 4.0, "temi")
    below = np.flatnonzero(test_day.voltage_v <= 13.30)
    if not below.size:
        return []
    fit_csv, test_csv, fit_yaml = work / f"{seed}a.csv", work / f"{seed}b.csv", work / f"{seed}.yaml"
    far.write_day_csv(fit_day, fit_csv)
    far.write_day_csv(test_day, test_csv, int(below[0]) + 1)
    far.fit_with_cli(REPO / "params" / "temi.yaml", fit_csv, fit_yaml)
    fitted, rec = load_params(fit_yaml), load_recording(test_csv)
    return capture(fitted, rec, 13.30, {"oracle": charge_to_end_ah(fitted, rec, 13.30)})


def main() -> None:
    core_mod.predict_remaining_runtime = _predict
    runtime_mod.peak_crossing_s = _peak_crossing
    if sys.argv[1] == "far":
        with tempfile.TemporaryDirectory() as tmp:
            rows = [r for seed in map(int, sys.argv[2:]) for r in far_rows(seed, Path(tmp))]
        report("far-truth Temi days " + " ".join(sys.argv[2:]), rows)
    else:
        fitted, capacity_ah = load_params(sys.argv[2]), float(sys.argv[3])
        rows = [r for f in sys.argv[4:] for r in capture(fitted, load_recording(f), 2.5, {"measured": capacity_ah})]
        report(f"{len(sys.argv) - 4} Panasonic recordings", rows)


if __name__ == "__main__":
    main()
