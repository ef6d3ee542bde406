"""Where a stored K2 fit's 20 degC HPPC error sits: ``1 - R2_mod`` split over parts of the recording.

    PYTHONPATH=. .venv/bin/python docs/identification_k2/hppc_residual_split.py docs/identification_k2/k2_fit_T20C_hysteresis.yaml

Scores the fit at its stored coordinates on the engine (both 20 degC files, as ``fit`` does) and splits the
HPPC's squared error (measured - simulated) by the share of ``1 - R2_mod``: rests 0-300 s after a charge pulse,
rests 0-300 s after a discharge pulse or a 3 A step, under load, rests after 300 s. Prints the share and the
mean error of each part, and the mean error at the ends of the long rests.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

from battery_predictor.fitting.cost import align_for_r2_mod
from battery_predictor.fitting.identifiable import default_space
from battery_predictor.fitting.identification import IdentificationProblem
from battery_predictor.fitting.problem import trim_to_discharge
from battery_predictor.io.loader import load_recording
from battery_predictor.params import load_params
from battery_predictor.simulation import get_simulator

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "k2_lfp26650_arts"


def main(fit_path: str) -> None:
    warnings.filterwarnings("ignore")
    params = load_params(fit_path)
    recs = [trim_to_discharge(load_recording(DATA / f)) for f in ("cc_discharge_T20C.csv", "hppc_T20C.csv")]
    coords = dict(params.provenance["coordinates"])
    coords.update({f"initial_ocv_v:{k}": v for k, v in enumerate(params.provenance["initial_ocv_v_per_file"].values())})
    problem = IdentificationProblem(params=params, recordings=recs, simulator=get_simulator("engine"),
                                    space=default_space(params, recs))
    score = problem.score(coords)
    print(f"R2_mod mean {score.r2_mod:.4f}, per file {[round(r, 4) for r in score.per_recording]}, "
          f"RMSE {[round(r, 1) for r in score.rmse_mv]} mV")
    rec, res = recs[1], score.results[1]
    t = rec.relative_time_s
    a = align_for_r2_mod(t, rec.voltage_v, res.time_s, res.pack_voltage_v)
    n = t.size
    err = (a.measured_v - a.predicted_v)[:n]
    ss_tot = float(np.sum((a.measured_v - np.mean(a.measured_v)) ** 2))
    current = rec.current_a
    rest = np.abs(current) < 0.05
    # time since the last load sample, and the sign of that load
    since = np.full(n, np.inf)
    last_sign = np.zeros(n)
    t_last, s_last = -np.inf, 0.0
    for k in range(n):
        if not rest[k]:
            t_last, s_last = t[k], np.sign(current[k])
        since[k] = t[k] - t_last
        last_sign[k] = s_last
    parts = {
        "rest 0-300 s after a charge pulse": rest & (since <= 300.0) & (last_sign < 0),
        "rest 0-300 s after a discharge pulse or a 3 A step": rest & (since <= 300.0) & (last_sign > 0),
        "under load": ~rest,
        "rest after 300 s": rest & (since > 300.0),
    }
    total = float(np.sum((a.measured_v - a.predicted_v) ** 2)) / ss_tot
    print(f"HPPC 1 - R2_mod {total:.4f}")
    for name, mask in parts.items():
        share = float(np.sum(err[mask] ** 2)) / ss_tot
        print(f"  {name:<52} {share:.4f}  mean {1e3 * float(np.mean(err[mask])):+.1f} mV  ({mask.sum()} samples)")
    ends = np.nonzero(rest[:-1] & ~rest[1:] & (since[:-1] > 1800.0))[0]
    if ends.size:
        print(f"  ends of rests > 30 min ({ends.size}): mean {1e3 * float(np.mean(err[ends])):+.1f} mV, "
              f"min {1e3 * float(np.min(err[ends])):+.1f}, max {1e3 * float(np.max(err[ends])):+.1f}")


if __name__ == "__main__":
    main(sys.argv[1])
