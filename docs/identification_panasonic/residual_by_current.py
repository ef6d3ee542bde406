"""Where a Panasonic fit misses: the simulated minus the measured voltage, by charge drawn and current level.

An analysis, not part of the package (docs/identification.md, "What remains of issue 17"). Each recording is
simulated as ``battery-predictor simulate --initial-state voltage --no-resample`` does (the 1 s samples as
measured, the loaded start corrected), and the residual (mV, model - cell) is averaged per 0.25 Ah of charge
drawn, separately for samples near rest (|I| < 0.5 A), at 2-6 A and above 6 A.

Run from the repository::

    .venv/bin/python docs/identification_panasonic/residual_by_current.py FIT.yaml \
        ../shared/data/panasonic_18650pf/drive_T25C_US06.csv ../shared/data/panasonic_18650pf/drive_T25C_Cycle1.csv
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from battery_predictor.cli.cmd_simulate import _score  # noqa: E402
from battery_predictor.cli.common import prepared_data  # noqa: E402
from battery_predictor.cli.fit_identify import simulator_named  # noqa: E402
from battery_predictor.cli.main import build_parser  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.simulation.cell_setup import with_thermal  # noqa: E402

BIN_AH = 0.25


def main() -> None:
    params_file, data = sys.argv[1], sys.argv[2:]
    args = build_parser().parse_args(["simulate", "--params", params_file, "--data", *data,
                                      "--initial-state", "voltage", "--no-resample"])
    params = with_thermal(load_params(args.params), args.thermal)
    recs = prepared_data(args, params, command="simulate")
    rows, results = _score(params, recs, simulator_named(args.simulator), args.initial_state)
    for rec, row, res in zip(recs, rows, results, strict=True):
        t, v, i = rec.relative_time_s, rec.voltage_v, rec.current_a
        residual_mv = 1e3 * (np.interp(t, res.time_s, res.pack_voltage_v) - v)
        drawn_ah = np.concatenate([[0.0], np.cumsum(i[:-1] * np.diff(t))]) / 3600.0
        print(f"{Path(str(rec.source)).name}: R2_mod {row['r2_mod']:.4f}, simulated end {res.end_time_s / 60:.1f} min, "
              f"measured {rec.duration_s / 60:.1f} min")
        for start in np.arange(0.0, drawn_ah.max(), BIN_AH):
            in_bin = (drawn_ah >= start) & (drawn_ah < start + BIN_AH) & (t < res.end_time_s)
            cells = []
            for label, level in (("|I|<0.5 A", np.abs(i) < 0.5), ("2-6 A", (i >= 2) & (i < 6)), (">6 A", i >= 6)):
                sel = in_bin & level
                cells.append(f"{label} {np.mean(residual_mv[sel]):+5.0f} ({sel.sum():4d})" if sel.any()
                             else f"{label}     - (   0)")
            print(f"  {start:.2f} Ah   " + "   ".join(cells))


if __name__ == "__main__":
    main()
