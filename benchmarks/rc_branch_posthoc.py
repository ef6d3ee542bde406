"""An RC relaxation branch added to a fitted SPM after the fact: is it worth building (issue 17)?

A first-order polarisation ``dV_rc/dt = (R_rc I - V_rc) / tau`` (cell current ``I`` = pack current /
parallel, subtracted ``series`` times from the pack voltage) is linear in the current and independent of
the SPM's state, so on a recording's piecewise-constant current (the current of sample ``k`` holds until
sample ``k + 1``, as ``StepLoad.from_samples``) it is exact in closed form:
``V_rc(t_k+1) = V_rc(t_k) exp(-dt/tau) + R_rc (1 - exp(-dt/tau)) I_k``, and within a step likewise.

Every simulation runs with the lower cut-off :data:`BELOW_V` lower than the params', so the model goes past
its cut-off; the post-processed voltage is then truncated where it first falls below the params' cut-off
(the end the engine would have found with the branch inside), and scored with ``fit``'s own R2_mod
(``IdentificationProblem``'s residual grid and ``cost.r2_mod``, Eq. 1-3 of the seed paper).

Three modes:

``posthoc``
    The SPM at a stored ``fit --json`` result's coordinates, (R_rc, tau) and, with ``--joint``, a change of
    the pack's series resistance (scaled by the params' Arrhenius factor at each recording's temperature)
    fitted by ``scipy.optimize.least_squares`` on ``fit``'s residual (9 starts).
``refit``
    ``identify`` (``fit``'s default search: 1000 evaluations, TPE then least squares) over the params'
    coordinates plus ``rc_resistance_ohm`` (log, ``--r-range``) and ``rc_time_constant_s`` (log,
    ``--tau-range``), the branch applied inside every evaluation; ``--ohmic`` starts from
    ``identifiable.ohmic_structure`` (the fastest kinetics, the series resistance at the data's step),
    ``--from-json`` from a stored fit's coordinates.

``split``
    Where a stored fit's ``1 - R2_mod`` sits in time (the last 20 / 5 min, the padding past the end).

``posthoc`` and ``refit`` print R2_mod per fit file and, for ``--heldout`` files, R2_mod / RMSE / time to the file's last
voltage as ``simulate`` scores them (``--states``: ``voltage`` and/or ``params``), with the branch.

Usage (from the repository root, data under ``../shared/data``)::

    D=../shared/data/panasonic_18650pf
    .venv/bin/python -m battery_predictor.cli.main fit --params params/panasonic_18650pf.yaml \\
        --data $D/drive_T25C_HWFET.csv $D/drive_T25C_LA92.csv --out pana.yaml --json > pana.json
    .venv/bin/python benchmarks/rc_branch_posthoc.py posthoc params/panasonic_18650pf.yaml --fit-json pana.json \\
        --data $D/drive_T25C_HWFET.csv $D/drive_T25C_LA92.csv --heldout $D/drive_T25C_Cycle1.csv $D/drive_T25C_US06.csv
    .venv/bin/python benchmarks/rc_branch_posthoc.py refit params/panasonic_18650pf.yaml --ohmic \\
        --data $D/drive_T25C_HWFET.csv $D/drive_T25C_LA92.csv --heldout $D/drive_T25C_Cycle1.csv $D/drive_T25C_US06.csv
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from scipy.optimize import least_squares  # noqa: E402

from battery_predictor.cli.common import prepared_data  # noqa: E402
from battery_predictor.cli.fit_identify import _space, simulator_named  # noqa: E402
from battery_predictor.cli.main import build_parser  # noqa: E402
from battery_predictor.errors import SimulationError  # noqa: E402
from battery_predictor.fitting.cost import r2_mod, rmse_v  # noqa: E402
from battery_predictor.fitting.identifiable import Coordinate, ohmic_structure, with_start_value  # noqa: E402
from battery_predictor.fitting.identification import IdentificationProblem, identify  # noqa: E402
from battery_predictor.fitting.problem import (  # noqa: E402
    loaded_start_ocv_v,
    request_for_recording,
    starts_at_rest,
)
from battery_predictor.params import PackParams, load_params  # noqa: E402
from battery_predictor.recording import Recording, ends_at_cutoff  # noqa: E402
from battery_predictor.simulation.base import PackSimResult, SimulationRequest  # noqa: E402
from battery_predictor.simulation.cell_setup import with_thermal  # noqa: E402
from battery_predictor.simulation.extensions import (  # noqa: E402
    series_resistance_factor,
    with_cold_window_anchors,
    with_fitted_extension_keys,
)
from battery_predictor.simulation.load import StepLoad  # noqa: E402

CUTOFF_KEY = "Lower voltage cut-off [V]"
#: Simulations run this far (V per cell) below the params' lower cut-off; the branch's voltage ends them.
BELOW_V = 0.4
R_NAME, TAU_NAME = "rc_resistance_ohm", "rc_time_constant_s"


def rc_voltage_v(load: StepLoad, time_s: np.ndarray, r_ohm: float, tau_s: float) -> np.ndarray:
    """The RC branch's voltage (V) at ``time_s`` (s) under ``load`` (A), from 0 V at t = 0, exact per step."""
    edges = load.edges_s()
    decay = np.exp(-np.diff(edges) / tau_s)
    v_edge = np.zeros(edges.size)
    for k in range(load.current_a.size):
        v_edge[k + 1] = v_edge[k] * decay[k] + r_ohm * (1.0 - decay[k]) * load.current_a[k]
    idx = np.clip(np.searchsorted(load.start_s, time_s, side="right") - 1, 0, load.current_a.size - 1)
    e = np.exp(-(time_s - edges[idx]) / tau_s)
    return np.asarray(v_edge[idx] * e + r_ohm * (1.0 - e) * load.current_a[idx])


@dataclass
class Branch:
    """One recording's simulation past the cut-off, post-processed with an RC branch and a series-resistance change."""

    params: PackParams
    request: SimulationRequest
    result: PackSimResult
    cutoff_pack_v: float
    arrhenius: bool = False

    def with_branch(self, r_ohm: float, tau_s: float, d_series_ohm: float = 0.0) -> PackSimResult:
        """The pack voltage minus the branch (cell ``r_ohm``, ``tau_s``) and ``d_series_ohm`` (pack, Arrhenius-scaled),
        ended where it first falls below the params' cut-off (time interpolated between report points)."""
        p, res = self.params, self.result
        t = res.time_s
        i_pack = self.request.load.current_at(t)
        v = res.pack_voltage_v.copy()
        factor = float(series_resistance_factor(p, self.request.ambient_temperature_k))
        if r_ohm > 0:
            r_cell = r_ohm * factor if self.arrhenius else r_ohm
            v -= p.series * rc_voltage_v(self.request.load, t, r_cell / p.parallel, tau_s)
        if d_series_ohm:
            v -= i_pack * d_series_ohm * factor
        below = np.nonzero(v < self.cutoff_pack_v)[0]
        if below.size:
            k = max(int(below[0]), 1)
            te = t[k - 1] + (t[k] - t[k - 1]) * (v[k - 1] - self.cutoff_pack_v) / (v[k - 1] - v[k])
            return PackSimResult(t[:k], v[:k], i_pack[:k], v[:k] / p.series, "cell_cutoff", float(te))
        return PackSimResult(t, v, i_pack, v / p.series, res.termination, res.end_time_s)


def lowered(params: PackParams) -> tuple[PackParams, float]:
    """The params with the lower cut-off :data:`BELOW_V` lower, and the params' own pack cut-off (V)."""
    cut = float(params.parameter_values()[CUTOFF_KEY])
    return params.with_values({CUTOFF_KEY: cut - BELOW_V}), cut * params.series


@dataclass
class RCProblem(IdentificationProblem):
    """``fit``'s identification problem with the branch's two coordinates applied after every simulation."""

    cutoff_pack_v: float = 0.0
    arrhenius: bool = False

    def simulate(self, coordinates: dict[str, float]) -> tuple[list[PackSimResult], list[dict[str, float]]]:
        values = self.values(coordinates)
        results = []
        for rec, vals in zip(self.recordings, values, strict=True):
            params = self.params.with_values(vals)
            req = request_for_recording(params, rec, initial_state="params", extend_s=self._padding_s(rec))
            res = Branch(params, req, self.simulator.simulate(params, req), self.cutoff_pack_v,
                         self.arrhenius).with_branch(
                coordinates.get(R_NAME, 0.0), coordinates.get(TAU_NAME, 1.0))
            if res.time_s.size < 2:
                raise SimulationError(f"{rec.source}: ended at once")
            results.append(res)
        return results, values


def _fit_data(start: str, data: list[str]) -> tuple[PackParams, list[Recording]]:
    """The start params and the fit files prepared as ``fit`` prepares them (5 s monitor window)."""
    with tempfile.TemporaryDirectory() as tmp:
        args = build_parser().parse_args(["fit", "--params", start, "--data", *data, "--out", str(Path(tmp) / "x.yaml")])
        params = with_fitted_extension_keys(with_cold_window_anchors(with_thermal(load_params(start), "params")))
        return params, prepared_data(args, params, command="fit")


def _scores(problem: IdentificationProblem, results: list[PackSimResult]) -> str:
    r2 = [r2_mod(r.relative_time_s, r.voltage_v, s.time_s, s.pack_voltage_v, ends_at_cutoff(r))
          for r, s in zip(problem.recordings, results, strict=True)]
    rms = [1e3 * rmse_v(r.relative_time_s, r.voltage_v, s.time_s, s.pack_voltage_v)
           for r, s in zip(problem.recordings, results, strict=True)]
    return (f"R2_mod {np.mean(r2):.4f} (" + " / ".join(f"{v:.4f}" for v in r2) + "), RMSE "
            + " / ".join(f"{v:.1f}" for v in rms) + " mV")


def _heldout(fitted: PackParams, start: str, files: list[str], states: list[str],
             branch: tuple[float, float, float], arrhenius: bool = False) -> None:
    """Score ``files`` as ``simulate`` does (its 50 % padding and loaded start), with and without the branch."""
    sim = simulator_named("engine")
    recs = prepared_data(build_parser().parse_args(["simulate", "--params", start, "--data", *files]), fitted,
                         command="simulate")
    low, cut = lowered(fitted)
    for state in states:
        for rec in recs:
            req = request_for_recording(fitted, rec, initial_state=state, extend_s=0.5 * rec.duration_s)
            if req.initial_pack_ocv_v is not None and not starts_at_rest(fitted, rec):
                req = replace(req, initial_pack_ocv_v=loaded_start_ocv_v(fitted, rec, sim))
            b = Branch(low, req, sim.simulate(low, req), cut, arrhenius)
            row = []
            for x in ((0.0, 1.0, 0.0), branch):
                res = b.with_branch(*x)
                t_end = res.time_to_pack_voltage_s(float(rec.voltage_v.min()))
                if t_end is None and res.reached_cutoff:
                    t_end = res.end_time_s
                t = rec.relative_time_s
                row.append(f"{r2_mod(t, rec.voltage_v, res.time_s, res.pack_voltage_v, ends_at_cutoff(rec)):.4f} / "
                           f"{1e3 * rmse_v(t, rec.voltage_v, res.time_s, res.pack_voltage_v):.1f} mV / "
                           + ("-" if t_end is None else f"{t_end / 60:.1f} min"))
            print(f"held out ({state}) {Path(str(rec.source)).name} (measured {rec.duration_s / 60:.1f} min): "
                  f"without {row[0]}; with the branch {row[1]}")


def posthoc(a: argparse.Namespace) -> None:
    """The SPM fixed at a stored fit; (R_rc, tau[, dR_s]) by least squares on ``fit``'s residual."""
    fit = json.loads(Path(a.fit_json).read_text())
    params, recs = _fit_data(a.start, a.data)
    sim = simulator_named("engine")
    space = _space(params, recs, ())
    coords = fit["coordinates"]
    base = IdentificationProblem(params=params, recordings=recs, simulator=sim, space=space)
    print("fit as stored:", _scores(base, base.score(coords).results))
    low, cut = lowered(params)
    prob = IdentificationProblem(params=low, recordings=recs, simulator=sim, space=space)
    branches = []
    for rec, vals in zip(recs, prob.values(coords), strict=True):
        p = low.with_values(vals)
        req = request_for_recording(p, rec, initial_state="params", extend_s=prob._padding_s(rec))
        branches.append(Branch(p, req, sim.simulate(p, req), cut, a.arrhenius))
    grids = prob._grids
    print("past the cut-off, truncated after:", _scores(prob, [b.with_branch(0.0, 1.0) for b in branches]))
    r_eq = float(coords["series_resistance_ohm"])

    def unpack(z: np.ndarray) -> tuple[float, float, float]:
        return (10 ** z[0] if z[0] > -5.9 else 0.0, 10 ** z[1], float(z[2]) if a.joint else 0.0)

    def residual(z: np.ndarray) -> np.ndarray:
        x = unpack(z)
        return np.concatenate([g.residuals(b.with_branch(*x)) for g, b in zip(grids, branches, strict=True)])

    lo = [-6.0, 0.0, -r_eq if a.joint else -1e-12]
    hi = [np.log10(0.05), 3.0, 0.05 if a.joint else 1e-12]
    best: tuple[float, np.ndarray] | None = None
    for r0 in (-3.0, -2.3, -1.8):
        for t0 in (0.5, 1.5, 2.5):
            sol = least_squares(residual, np.array([r0, t0, 0.0]), bounds=(lo, hi), x_scale=[1.0, 1.0, 0.01],
                                diff_step=1e-3)
            cost = float(np.sum(sol.fun ** 2))
            if best is None or cost < best[0]:
                best = (cost, sol.x)
    assert best is not None
    x = unpack(best[1])
    print(f"with the branch: R_rc {x[0] * 1e3:.2f} mOhm, tau {x[1]:.1f} s, series resistance change "
          f"{x[2] * 1e3:+.2f} mOhm:", _scores(prob, [b.with_branch(*x) for b in branches]))
    if a.heldout:
        _heldout(params.with_values(base.values(coords)[0]), a.start, a.heldout, a.states, x, a.arrhenius)


def split(a: argparse.Namespace) -> None:
    """Where a stored fit's ``1 - R2_mod`` sits in time: before the last 20 min, 20-5 min and 5-0 min before the
    recording's end, and on the padding after it (Eq. 2), with the mean error (measured - simulated)."""
    from battery_predictor.fitting.cost import align_for_r2_mod

    params, recs = _fit_data(a.start, a.data)
    prob = IdentificationProblem(params=params, recordings=recs, simulator=simulator_named("engine"),
                                 space=_space(params, recs, ()))
    score = prob.score(json.loads(Path(a.fit_json).read_text())["coordinates"])
    for rec, res, r2 in zip(recs, score.results, score.per_recording, strict=True):
        al = align_for_r2_mod(rec.relative_time_s, rec.voltage_v, res.time_s, res.pack_voltage_v, ends_at_cutoff(rec))
        err = al.measured_v - al.predicted_v
        ss_tot = float(np.sum((al.measured_v - al.measured_v.mean()) ** 2))
        end = float(rec.relative_time_s[-1])
        print(f"{Path(str(rec.source)).name}: R2_mod {r2:.4f}, measured end {end / 60:.1f} min, model end "
              f"{res.end_time_s / 60:.1f} min")
        for lo, hi, label in ((-1.0, end - 1200, "to 20 min before the end"), (end - 1200, end - 300, "20-5 min before"),
                              (end - 300, end + 0.5, "last 5 min"), (end + 0.5, np.inf, "after the end (padding)")):
            m = (al.time_s > lo) & (al.time_s <= hi)
            mean = f"{1e3 * float(err[m].mean()):+.1f} mV" if m.any() else "-"
            print(f"  {label:<26} share of 1 - R2_mod {float(np.sum(err[m] ** 2)) / ss_tot:.4f}, mean error {mean}")


def refit(a: argparse.Namespace) -> None:
    """``identify`` with the branch's coordinates inside every evaluation."""
    params, recs = _fit_data(a.start, a.data)
    if a.ohmic:
        structure = ohmic_structure(params, recs)
        if structure is None:
            raise SystemExit("the data have no current steps for the ohmic structure")
        params, step_ohm = structure
        print(f"ohmic structure: series resistance started at the data's step, {step_ohm * 1e3:.1f} mOhm")
        space = with_start_value(_space(params, recs, ()), "series_resistance_ohm", step_ohm)
    else:
        space = _space(params, recs, ())
    if a.from_json:
        start: dict[str, Any] = json.loads(Path(a.from_json).read_text())["coordinates"]
        space = [replace(c, initial=min(max(float(start.get(c.name, c.initial)), c.low), c.high)) for c in space]
    n_states = sum(c.recording is not None for c in space)
    branch = [] if a.no_branch or a.plain else [Coordinate(R_NAME, a.r0, a.r_range[0], a.r_range[1], True),
                                     Coordinate(TAU_NAME, a.tau0, a.tau_range[0], a.tau_range[1], True)]
    space = space[:len(space) - n_states] + branch + space[len(space) - n_states:]
    low, cut = lowered(params)
    prob: IdentificationProblem = RCProblem(params=low, recordings=recs, simulator=simulator_named("engine"),
                                            space=space, cutoff_pack_v=cut, arrhenius=a.arrhenius)
    if a.plain:  # fit's own problem: no branch, the params' cut-off
        prob = IdentificationProblem(params=params, recordings=recs, simulator=simulator_named("engine"), space=space)
    tic = time.perf_counter()
    coarse: dict[str, Any] = {} if a.coarse_window is None else {"coarse_window_s": a.coarse_window or None}
    result = identify(prob, evaluations=a.evaluations, seed=a.seed, **coarse)
    wall = time.perf_counter() - tic
    score = prob.score(result.coordinates)
    co = result.coordinates
    what = "with the branch" if branch else "without a branch"
    print(f"refit {what} ({result.evaluations} evaluations, {wall:.0f} s):", _scores(prob, score.results))
    print("coordinates:", json.dumps({k: round(v, 6) for k, v in co.items()}))
    if a.save_json:
        Path(a.save_json).write_text(json.dumps({"coordinates": co, "r2_mod": score.r2_mod}))
    if a.heldout:
        fitted = params.with_values(score.values[0])
        _heldout(fitted, a.start, a.heldout, a.states, (co.get(R_NAME, 0.0), co.get(TAU_NAME, 1.0), 0.0), a.arrhenius)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mode", choices=("posthoc", "refit", "split"))
    ap.add_argument("start", help="the params fit started from")
    ap.add_argument("--data", nargs="+", required=True, help="the fit files")
    ap.add_argument("--heldout", nargs="+", default=[])
    ap.add_argument("--states", nargs="+", default=["voltage"], choices=("voltage", "params"))
    ap.add_argument("--fit-json", help="posthoc, split: `fit --json` output of the stored fit")
    ap.add_argument("--joint", action="store_true", help="posthoc: fit a series-resistance change too")
    ap.add_argument("--arrhenius", action="store_true",
                    help="the branch's resistance scaled with temperature as the series resistance (params' factor)")
    ap.add_argument("--ohmic", action="store_true", help="refit: from the ohmic structure")
    ap.add_argument("--from-json", help="refit: start from a `fit --json` output's coordinates")
    ap.add_argument("--r0", type=float, default=5e-3)
    ap.add_argument("--tau0", type=float, default=30.0)
    ap.add_argument("--r-range", type=float, nargs=2, default=[1e-4, 0.05])
    ap.add_argument("--tau-range", type=float, nargs=2, default=[1.0, 1000.0])
    ap.add_argument("--evaluations", type=int, default=1000)
    ap.add_argument("--coarse-window", type=float, default=None,
                    help="refit: identify's coarse window in s (0: none; default: identify's own)")
    ap.add_argument("--no-branch", action="store_true", help="refit: without the branch (still past the cut-off)")
    ap.add_argument("--plain", action="store_true",
                    help="refit: fit's own problem (no branch, simulations end at the params' cut-off)")
    ap.add_argument("--save-json", help="refit: write the coordinates here (a --fit-json for posthoc)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    if a.mode in ("posthoc", "split") and not a.fit_json:
        raise SystemExit(f"{a.mode} needs --fit-json")
    if a.mode == "posthoc":
        posthoc(a)
    elif a.mode == "split":
        split(a)
    else:
        refit(a)


if __name__ == "__main__":
    main()
