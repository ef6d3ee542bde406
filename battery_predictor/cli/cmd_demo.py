"""``battery-predictor demo``: the main job on bundled data.

Fits the information robot's pack (paper params as the start) to a bundled
dynamic discharge with TPE, validates the fit on the bundled static discharge,
and prints both (the seed paper's Table 2 kind).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / "bags"
DEMO_FIT_BAG = "temi_dynamic_pack1"
DEMO_VALIDATION_BAG = "temi_static_0p5c_pack1"


def register(sub) -> None:
    p = sub.add_parser("demo", help="fit the information robot's pack to bundled data and print the fit")
    p.add_argument("--trials", type=int, default=200, help="TPE trials (default 200; the paper uses 1000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="directory for the fitted params and plot (default: temp dir)")
    p.set_defaults(func=run)


def run(args) -> int:
    from battery_predictor.errors import InputDataError
    from battery_predictor.fitting.cost import r2_mod
    from battery_predictor.fitting.optimiser import TPEOptimiser
    from battery_predictor.fitting.problem import FitProblem, request_for_recording, trim_to_discharge
    from battery_predictor.fitting.space import fit_space
    from battery_predictor.io.loader import load_recording
    from battery_predictor.params import load_params
    from battery_predictor.plots import plot_voltage_fit
    from battery_predictor.simulation import get_simulator

    fit_path, val_path = BAGS / DEMO_FIT_BAG, BAGS / DEMO_VALIDATION_BAG
    for path in (fit_path, val_path):
        if not path.exists():
            raise InputDataError(f"{path}: bundled bag missing (regenerate with 'make bags')")
    params = load_params(REPO / "params" / "temi.yaml")
    fit_rec = trim_to_discharge(load_recording(fit_path))
    val_rec = trim_to_discharge(load_recording(val_path))
    sim = get_simulator("fast")
    print(f"demo: information robot ({params.series}S{params.parallel}P, {params.base_parameter_set} SPM)")
    print(f"  fit data:        {fit_path.name} ({fit_rec.duration_s / 60:.0f} min, "
          f"{fit_rec.charge_drawn_ah():.2f} Ah)  [emulated recording, see bags/README.md]")
    print(f"  validation data: {val_path.name} ({val_rec.duration_s / 60:.0f} min)")

    def score(p, rec) -> float:
        res = sim.simulate(p, request_for_recording(p, rec, initial_state="params",
                                                    extend_s=0.2 * rec.duration_s))
        return r2_mod(rec.relative_time_s, rec.voltage_v, res.time_s, res.pack_voltage_v), res

    before_fit, _ = score(params, fit_rec)
    before_val, _ = score(params, val_rec)
    out_dir = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="battery-predictor-demo-"))
    out_dir.mkdir(parents=True, exist_ok=True)
    problem = FitProblem(params, [fit_rec], sim, initial_state="params")
    space = fit_space(params)
    print(f"  fitting {len(space)} parameters with TPE, {args.trials} trials (seed {args.seed}) ...")
    result = TPEOptimiser(n_trials=args.trials, seed=args.seed, storage=f"sqlite:///{out_dir / 'demo.optuna.db'}",
                          progress=True).run(problem, space)
    fitted = params.with_values(result.best_values)
    after_fit, res_fit = score(fitted, fit_rec)
    after_val, res_val = score(fitted, val_rec)
    fitted.to_yaml(out_dir / "temi_fit.yaml")
    plot_voltage_fit([fit_rec, val_rec], [res_fit, res_val], out_dir / "temi_fit.png",
                     title=f"temi: fit R2_mod {after_fit:.3f}, validation R2_mod {after_val:.3f}",
                     labels=[f"fit: {fit_path.name}", f"validation: {val_path.name}"])
    print(f"\n{'':28}{'paper params':>14}{'fitted':>10}")
    print(f"{'R2_mod on fit data':28}{before_fit:>14.4f}{after_fit:>10.4f}")
    print(f"{'R2_mod on validation data':28}{before_val:>14.4f}{after_val:>10.4f}")
    print(f"(seed paper, Table 2, Chen2020 dynamic -> static: 0.97 / 0.95)\n\nfitted parameters "
          f"({result.trials} trials, {result.failed_trials} failed, {result.seconds:.0f} s):")
    for p in space:
        print(f"  {p.name:<58}{p.initial:>12.5g} -> {result.best_values[p.name]:>12.5g}")
    print(f"\nwrote {out_dir / 'temi_fit.yaml'} and {out_dir / 'temi_fit.png'}")
    return 0
