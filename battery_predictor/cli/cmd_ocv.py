"""``battery-predictor ocv``: a measured open-circuit voltage as the cell's positive OCP.

Reads a low-rate (C/10 or slower) discharge test, derives the cell's open-circuit voltage against
state of charge and writes a params file whose positive OCP reproduces it with the base set's
negative OCP (see :mod:`battery_predictor.fitting.ocv`). Fit the result as usual afterwards.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from battery_predictor.cli.common import add_input_check_arguments, check_output_file, print_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ocv", help="take a cell's open-circuit voltage from a low-rate test into its params")
    p.add_argument("--params", required=True, help="pack params YAML (its negative OCP and balance are kept)")
    p.add_argument("--data", required=True, metavar="FILE",
                   help="low-rate test (CSV or rosbag2): a C/20-like discharge from full, optionally a charge after; "
                        "or an OCV table (CSV: soc_percent or soc, ocv_V or ocv_mean_V, optional hysteresis_V)")
    p.add_argument("--branch", choices=("discharge", "mean"), default="discharge",
                   help="discharge branch raised by its starting step (default; the robots discharge), or the "
                        "mean of the discharge and charge branches")
    p.add_argument("--terms", type=int, default=None, metavar="N", help="tanh terms of the OCP series (default 48)")
    p.add_argument("--out", required=True, metavar="FILE", help="params YAML to write")
    p.add_argument("--plot", default=None, metavar="FILE", help="measured vs model OCV figure")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_input_check_arguments(p)
    p.set_defaults(func=run, expect_discharge=False)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from battery_predictor.errors import InputDataError
    from battery_predictor.fitting import ocv
    from battery_predictor.io.loader import load_recording
    from battery_predictor.io.ocv_table import is_ocv_table, load_ocv_table
    from battery_predictor.params import load_params

    out = check_output_file(args.out, "--out", suffixes=(".yaml", ".yml"))
    plot = None
    if args.plot:
        from battery_predictor.cli.common import check_plot_file

        plot = check_plot_file(args.plot)
    terms = args.terms if args.terms is not None else ocv.DEFAULT_TERMS
    if not 4 <= terms <= 64:
        raise InputDataError(f"--terms {terms}: use 4..64")
    params = load_params(args.params)
    if is_ocv_table(args.data):
        curve = ocv.ocv_from_table(load_ocv_table(args.data), ocv.params_capacity_ah(params), branch=args.branch)
    else:
        recording = load_recording(args.data, expect_discharge=args.expect_discharge, drop_nan=args.drop_nan,
                                   duplicate_times=args.duplicate_times)
        nominal = float(params.parameter_values()["Nominal cell capacity [A.h]"])
        curve = ocv.pseudo_ocv(recording, nominal, parallel=params.parallel, branch=args.branch)
    fit = ocv.positive_ocp_values(params, curve, terms=terms)
    manual = dict(params.manual)
    manual.update(fit.manual_values)
    source = f"{Path(args.data).name}: {curve.method}, {curve.capacity_ah:.4f} Ah (battery-predictor ocv)"
    new = replace(params, manual=manual, ocp=fit.ocp_values, ocp_source=source,
                  fitted={k: v for k, v in params.fitted.items() if k not in fit.manual_values})
    new.to_yaml(out)
    x0, x100, y100, y0 = fit.stoichiometry_window
    summary = {
        "out": str(out), "method": curve.method, "capacity_ah": curve.capacity_ah,
        "discharge_current_a": curve.discharge_current_a, "notes": curve.notes,
        "series_rms_error_mv": 1000 * fit.rms_error_v, "series_max_error_mv": 1000 * fit.max_error_v,
        "stoichiometry_window": {"x_0": x0, "x_100": x100, "y_100": y100, "y_0": y0},
    }
    if plot is not None:
        from battery_predictor.plots import ocv_figure

        title = f"{new.name}: measured OCV ({curve.method}) vs the model's OCPs"
        ocv_figure(curve.soc, curve.ocv_v, ocv.cell_ocv_v(new, curve.soc), title=title).savefig(plot, dpi=120)
        summary["plot"] = str(plot)
    if args.json:
        print_json(summary)
        return 0
    rate = f" at {curve.discharge_current_a:.4f} A" if curve.discharge_current_a > 0 else ""
    print(f"OCV from {args.data}: {curve.method}; {curve.capacity_ah:.4f} Ah{rate}")
    for note in curve.notes:
        print(f"  {note}")
    print(f"positive OCP: {terms}-term series, {1000 * fit.rms_error_v:.1f} mV RMS "
          f"({1000 * fit.max_error_v:.1f} mV max) against the measured OCV")
    print(f"stoichiometries 0 %..100 %: negative {x0:.4f}..{x100:.4f}, positive {y0:.4f}..{y100:.4f}")
    print(f"wrote {out}" + (f" and {plot}" if plot else ""))
    return 0
