"""What the baseline gets wrong: its residual against time, SOC, charge, current, temperature, direction.

The residual is ``measured - baseline`` on the observed recordings (baseline refitted over its
initial SOC only). It is related to each feature by

* the correlation ratio eta^2 (share of the residual variance explained by the feature's
  deciles, or by its three states for the direction of recent current), which catches
  non-linear dependences such as a residual that only grows at low SOC, and
* Pearson's r (sign and linear part).

Features (per sample):

``time``               hours since the start of the recording;
``soc``                the baseline model's state of charge (initial SOC minus charge drawn over capacity);
``charge_throughput``  signed charge drawn since the start, Ah (falls while charging);
``current``            pack current, A (positive = discharge);
``temperature``        measured temperature, K (only when measured and not constant);
``direction``          sign of the charge drawn over the last :data:`DIRECTION_WINDOW_S`
                       (+1 discharging, -1 charging, 0 at rest), the state a path-dependent
                       OCV (hysteresis) remembers.

Features that move together in a recording (time and charge in a constant discharge) cannot be
told apart by their residual; :attr:`ResidualAnalysis.collinear` lists such pairs, and the
evidence text says so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from battery_predictor.diagnosis.candidates import candidate

if TYPE_CHECKING:
    from battery_predictor.diagnosis.engine import Engine, Observed
    from battery_predictor.diagnosis.results import CandidateResult
    from battery_predictor.params import PackParams
from battery_predictor.diagnosis.decision import (
    BASELINE_FLOOR_FACTOR,
    GAIN_THRESHOLD_PCT,
    measured_causes,
)

#: Window (s) of the "direction of recent current" feature.
DIRECTION_WINDOW_S = 600.0
#: Features whose absolute correlation exceeds this are reported as not separable.
COLLINEAR_R = 0.95
FEATURES = ("time", "soc", "charge_throughput", "current", "temperature", "direction")
_LABELS = {"time": "time", "soc": "state of charge", "charge_throughput": "charge throughput",
           "current": "current", "temperature": "temperature", "direction": "direction of recent current"}


@dataclass
class ResidualAnalysis:
    """Residual statistics of the baseline on the observed data.

    Attributes
    ----------
    eta2 : dict
        Feature -> correlation ratio (0..1).
    pearson_r : dict
        Feature -> Pearson correlation with the residual.
    rmse_mV : float
        RMS of the residual (whole recordings, where the baseline ran).
    mean_mV : float
        Mean residual.
    collinear : list of (str, str)
        Feature pairs that move together in these recordings (|r| > 0.95).
    series : list of dict
        Per recording: the feature arrays and the residual (for the report plots).
    """

    eta2: dict[str, float]
    pearson_r: dict[str, float]
    rmse_mV: float
    mean_mV: float
    collinear: list[tuple[str, str]]
    series: list[dict[str, np.ndarray]] = field(default_factory=list, repr=False)

    def ranked(self) -> list[tuple[str, float]]:
        """Features by decreasing eta^2."""
        return sorted(self.eta2.items(), key=lambda kv: -kv[1])

    def to_json(self) -> dict:
        return {"eta2": {k: round(v, 4) for k, v in self.eta2.items()},
                "pearson_r": {k: round(v, 4) for k, v in self.pearson_r.items()},
                "rmse_mV": self.rmse_mV, "mean_mV": self.mean_mV,
                "collinear": [list(p) for p in self.collinear]}


def correlation_ratio(x: np.ndarray, y: np.ndarray, bins: int = 10) -> float:
    """eta^2 of ``y`` explained by ``x``: between-group variance over total (deciles of ``x``; few values as groups)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if y.size < 3 or float(np.var(y)) == 0.0:
        return 0.0
    values = np.unique(x)
    if values.size <= 5:
        groups = np.searchsorted(values, x)
    else:
        edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)[1:-1]))
        groups = np.searchsorted(edges, x, side="right")
    total = float(np.sum((y - y.mean()) ** 2))
    between = 0.0
    for g in np.unique(groups):
        sel = groups == g
        between += sel.sum() * (float(y[sel].mean()) - float(y.mean())) ** 2
    return float(between / total) if total > 0 else 0.0


def direction_of_recent_current(t: np.ndarray, charge_ah: np.ndarray, capacity_ah: float,
                                window_s: float = DIRECTION_WINDOW_S) -> np.ndarray:
    """+1 / -1 / 0: net discharge / charge / rest over the last ``window_s`` (dead band 0.2 % of capacity)."""
    past = np.interp(t - window_s, t, charge_ah, left=charge_ah[0])
    dq = charge_ah - past
    band = 0.002 * max(capacity_ah, 1e-9)
    return np.where(dq > band, 1.0, np.where(dq < -band, -1.0, 0.0))


def pack_capacity_ah(engine: Engine, params: PackParams) -> float:
    """Capacity (Ah) between 0 and 100 % SOC of the pack (negative electrode window)."""
    pv = params.parameter_values()
    x0, x100, _, _ = engine.stoichiometry_window(params)
    n_n, _, _ = engine.loadings(pv, {})
    area = float(pv["Electrode height [m]"]) * float(pv["Electrode width [m]"])
    return abs(x100 - x0) * n_n * area * 96485.33212 / 3600.0 * params.parallel


def analyse_residuals(engine: Engine, params: PackParams, observed: Sequence[Observed],
                      base: CandidateResult) -> ResidualAnalysis:
    """Residual of the baseline refit ``base`` on ``observed`` against the features."""
    capacity = pack_capacity_ah(engine, params)
    feats: dict[str, list[np.ndarray]] = {f: [] for f in FEATURES}
    resid = []
    series = []
    temps = [o.temperature_k for o in observed]
    has_temp = all(t is not None for t in temps) and any(
        float(np.ptp(t)) > 0.5 for t in temps if t is not None)
    for obs, sim, soc0 in zip(observed, base.sims, base.socs):
        n = int(np.searchsorted(obs.t, sim.t[-1], side="right")) if sim.t.size else 0
        if n < 3:
            continue
        q = obs.cumulative_charge_ah()[:n]
        r = obs.v[:n] - np.interp(obs.t[:n], sim.t, sim.v_pack)
        row = {"time": obs.t[:n] / 3600.0, "soc": soc0 - q / capacity, "charge_throughput": q,
               "current": obs.i[:n],
               "temperature": obs.temperature_k[:n] if obs.temperature_k is not None else np.full(n, np.nan),
               "direction": direction_of_recent_current(obs.t[:n], q, capacity)}
        for f in FEATURES:
            feats[f].append(row[f])
        resid.append(r)
        series.append({**row, "residual_v": r, "measured_v": obs.v[:n], "baseline_v": obs.v[:n] - r})
    if not resid:
        return ResidualAnalysis({}, {}, float("nan"), float("nan"), [], [])
    y = np.concatenate(resid)
    eta2, pr = {}, {}
    arrays = {}
    for f in FEATURES:
        if f == "temperature" and not has_temp:
            continue
        x = np.concatenate(feats[f])
        arrays[f] = x
        eta2[f] = correlation_ratio(x, y)
        pr[f] = float(np.corrcoef(x, y)[0, 1]) if np.std(x) > 0 and np.std(y) > 0 else 0.0
    collinear = []
    names = list(arrays)
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            xa, xb = arrays[names[a]], arrays[names[b]]
            if np.std(xa) > 0 and np.std(xb) > 0 and abs(float(np.corrcoef(xa, xb)[0, 1])) > COLLINEAR_R:
                collinear.append((names[a], names[b]))
    return ResidualAnalysis(eta2=eta2, pearson_r=pr, rmse_mV=1e3 * float(np.sqrt(np.mean(y ** 2))),
                            mean_mV=1e3 * float(np.mean(y)), collinear=collinear, series=series)


def _fmt_fitted(fitted: dict[str, float]) -> str:
    return ", ".join(f"{k} = {v:.4g}" for k, v in fitted.items())


#: Observed recordings whose mean measured temperature differs from the reference's by more than this (K)
#: get a caveat when a capacity-like cause is named (see :func:`evidence_text`).
TEMPERATURE_CAVEAT_K = 5.0
#: Causes that act as a capacity scale within a discharge.
CAPACITY_LIKE = ("current_offset", "capacity_fade")


def evidence_text(cause: str, base: CandidateResult, best: CandidateResult | None, results: Sequence[CandidateResult],
                  analysis: ResidualAnalysis, noise_mv: float,
                  close: list[str], floor_mv: float | None = None, temperature_shift_k: float | None = None,
                  refusal: str | None = None) -> str:
    """One paragraph: the baseline's error, the residual features that carry it, the verdict.

    ``temperature_shift_k`` (observed minus reference mean measured temperature): when it exceeds
    :data:`TEMPERATURE_CAVEAT_K` and the named cause is capacity-like (:data:`CAPACITY_LIKE`), the text
    says that the held-out comparison cannot tell that cause from a loss of accessible capacity with
    temperature. The caveat does not change the verdict, which rests on held-out prediction alone.
    ``refusal``: with cause ``none``, why a claim the held-out part would make was not made (the
    observed data go deeper than the references, :func:`~battery_predictor.diagnosis.coverage.refusal_text`).
    """
    noise = (f"voltage noise {noise_mv:.1f} mV" if noise_mv >= 0.05 else
             "voltage noise not measurable here: no three samples at one current and no quantisation step")
    parts = [f"Baseline held-out RMSE {base.heldout_rmse_mV:.1f} mV ({noise})."]
    ranked = [(f, e) for f, e in analysis.ranked() if e >= 0.05][:3]
    if ranked:
        desc = ", ".join(f"{_LABELS[f]} (eta2={e:.2f}, r={analysis.pearson_r.get(f, 0):+.2f})" for f, e in ranked)
        parts.append(f"The residual (measured - baseline, {analysis.rmse_mV:.1f} mV RMS) follows {desc}.")
    else:
        parts.append(f"The residual ({analysis.rmse_mV:.1f} mV RMS) follows none of the features (eta2 < 0.05).")
    pairs = [f"{_LABELS[a]} and {_LABELS[b]}" for a, b in analysis.collinear if "direction" not in (a, b)]
    if pairs:
        parts.append("Not separable in these recordings (they move together): " + "; ".join(pairs) + ".")
    if cause == "none" and refusal:
        parts.append(refusal)
        return " ".join(parts)
    if cause == "none":
        floor = noise_mv if floor_mv is None else floor_mv
        if base.heldout_rmse_mV <= BASELINE_FLOOR_FACTOR * floor:
            parts.append(f"The baseline predicts the held-out data within {BASELINE_FLOOR_FACTOR:g}x its error floor "
                         f"({floor:.1f} mV: noise, or its RMSE on the reference data), as well as a model without the "
                         "change predicts another day, so nothing is claimed"
                         + (f" (best candidate {best.cause}: {best.heldout_rmse_mV:.1f} mV)." if best else "."))
        elif best is not None:
            parts.append(f"No candidate predicts the held-out data meaningfully better: best is {best.cause} "
                         f"({best.heldout_rmse_mV:.1f} mV, gain {best.gain_pct:+.1f} %, threshold "
                         f"{GAIN_THRESHOLD_PCT:.0f} % and more than the noise).")
        return " ".join(parts)
    chosen = next(r for r in results if r.cause == cause)
    cand = candidate(cause)
    sig = [f for f in cand.signature if f in analysis.eta2]
    parts.append(f"Cause {cause}: {cand.title}; held-out RMSE {base.heldout_rmse_mV:.1f} -> "
                 f"{chosen.heldout_rmse_mV:.1f} mV (gain {chosen.gain_pct:.1f} %), fitted {_fmt_fitted(chosen.fitted)}.")
    if sig:
        parts.append("Its signature in the residual: " + ", ".join(
            f"{_LABELS[f]} eta2={analysis.eta2[f]:.2f}" for f in sig) + ".")
    others = sorted((r for r in results if r.applicable and r.cause != cause and math.isfinite(r.heldout_rmse_mV)),
                    key=lambda r: r.heldout_rmse_mV)[:2]
    if others:
        parts.append("Next best: " + ", ".join(f"{r.cause} {r.heldout_rmse_mV:.1f} mV ({r.gain_pct:+.1f} %)"
                                               for r in others) + ".")
    floor = noise_mv if floor_mv is None else floor_mv
    if (temperature_shift_k is not None and cause in measured_causes(temperature_shift_k)
            and base.heldout_rmse_mV <= BASELINE_FLOOR_FACTOR * floor):
        parts.append(f"The baseline is within {BASELINE_FLOOR_FACTOR:g}x its error floor ({floor:.1f} mV); the "
                     f"cause is named because the measured temperature differs from the reference's by "
                     f"{abs(temperature_shift_k):.0f} K and modelling it cuts the held-out error by more than the "
                     "noise.")
    if close:
        parts.append(f"Within 10 % of its error above the noise, hence not clearly separable on these data: "
                     f"{', '.join(close)}.")
    if (cause in CAPACITY_LIKE and temperature_shift_k is not None
            and abs(temperature_shift_k) > TEMPERATURE_CAVEAT_K):
        parts.append(f"Caveat: the observed recordings are {abs(temperature_shift_k):.0f} K "
                     f"{'colder' if temperature_shift_k < 0 else 'warmer'} than the reference; within a discharge "
                     f"{cause} acts as a capacity scale and cannot be told from a temperature-driven change of the "
                     "accessible capacity that the temperature candidate does not model (read it as a capacity-like "
                     "error, not as evidence of a sensor or ageing fault).")
    return " ".join(parts)
