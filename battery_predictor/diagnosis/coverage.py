"""How deep the observed recordings go compared with the reference recordings the baseline was fitted on.

The reference fit is shown the reference recordings only: down to the lowest state of charge they
reached, the reference model is identified by data; below it (a working day that stopped before
its end-of-discharge knee) the model *extrapolates*: where the knee lies follows from the fitted
capacities and open-circuit potentials, not from any measurement. An observed day that goes
deeper than every reference shows the baseline's error there whether or not anything changed in
the battery, and a candidate with a capacity knob (capacity fade above all) moves the knee and
fits it. That error is not evidence of a change.

The depth is measured as the reference model's state of charge (its 0-100 % window,
:func:`~battery_predictor.diagnosis.residuals.pack_capacity_ah`): a recording's initial SOC (for
a reference its identified initial open-circuit voltage; for an observed recording the
baseline's fitted initial SOC) minus the net charge drawn since, over the model's capacity. The
observed recording is *covered* until it first goes below the lowest SOC any reference reached.
A reference that stopped at its cut-off (kept padded by the reference fit) covers everything the
pack can deliver.

The guard (:func:`covered_claim`): a cause named from the whole held-out part is named only when
the same claim holds (:func:`~battery_predictor.diagnosis.decision.claim_allowed`, same noise and
floor) on the held-out samples the references cover. A real change shows there too: capacity
fade shifts the open-circuit voltage at a given charge drawn and brings the knee forward into
the covered range; a resistance, an offset, a temperature or a hysteresis act all day.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.diagnosis.decision import claim_allowed
from battery_predictor.diagnosis.scoring import held_out_score

if TYPE_CHECKING:
    from battery_predictor.diagnosis.engine import Engine, Observed, SimOut
    from battery_predictor.diagnosis.reference import ReferenceFit
    from battery_predictor.params import PackParams


@dataclass
class Coverage:
    """The observed recordings' depth against the references' (SOC of the reference model, 0..1).

    Attributes
    ----------
    reference_min_soc : float or None
        Lowest SOC the reference recordings reached; None when a reference stopped at its cut-off
        (everything covered).
    observed_min_soc : list of float
        Lowest SOC of each observed recording (baseline's initial SOC).
    covered_until_s : list of float
        Per observed recording, the time (s from its start) at which it first goes below
        ``reference_min_soc`` (``inf``: never).
    heldout_samples, covered_heldout_samples : int
        Held-out samples of all observed recordings, and those before ``covered_until_s``.
    cause : str or None
        The cause the whole held-out part would name (set by :func:`covered_claim`).
    baseline_rmse_mV, cause_rmse_mV : float or None
        Held-out RMSE (mV) of the baseline and of ``cause`` on the covered held-out samples.
    refused : bool
        The claim of ``cause`` did not hold on the covered samples: ``none`` is named.
    """

    reference_min_soc: float | None
    observed_min_soc: list[float]
    covered_until_s: list[float]
    heldout_samples: int = 0
    covered_heldout_samples: int = 0
    cause: str | None = None
    baseline_rmse_mV: float | None = None
    cause_rmse_mV: float | None = None
    refused: bool = False
    notes: list[str] = field(default_factory=list)

    @property
    def leaves_range(self) -> bool:
        """Whether some observed recording goes deeper than every reference."""
        return any(math.isfinite(u) for u in self.covered_until_s)

    def to_json(self) -> dict[str, Any]:
        return {"reference_min_soc": self.reference_min_soc, "observed_min_soc": list(self.observed_min_soc),
                "covered_until_s": [u if math.isfinite(u) else None for u in self.covered_until_s],
                "heldout_samples": self.heldout_samples, "covered_heldout_samples": self.covered_heldout_samples,
                "cause": self.cause, "baseline_rmse_mV": self.baseline_rmse_mV, "cause_rmse_mV": self.cause_rmse_mV,
                "refused": self.refused}


def soc_trace(obs: Observed, soc0: float, capacity_ah: float) -> np.ndarray:
    """SOC (0..1 of the model's window) at each sample: ``soc0`` minus the net charge drawn over ``capacity_ah``."""
    return soc0 - obs.cumulative_charge_ah() / max(capacity_ah, 1e-12)


def first_time_below(obs: Observed, soc: np.ndarray, min_soc: float | None) -> float:
    """Time (s) of the first sample whose SOC is below ``min_soc`` (``inf``: none, or ``min_soc`` None)."""
    if min_soc is None:
        return math.inf
    deeper = np.nonzero(soc < min_soc)[0]
    return float(obs.t[deeper[0]]) if deeper.size else math.inf


def reference_coverage(engine: Engine, params: PackParams, refs: Sequence[Observed], reference: ReferenceFit,
                       observed: Sequence[Observed], observed_socs: Sequence[float]) -> Coverage:
    """How deep the observed recordings go against the references (see the module docstring).

    Parameters
    ----------
    engine : Engine
        The simulator (its SOC window of ``params``).
    params : PackParams
        The reference-identified params.
    refs : sequence of Observed
        The reference recordings.
    reference : ReferenceFit
        The reference fit (initial open-circuit voltage per cell of each reference, V; end padding).
    observed : sequence of Observed
        The observed recordings.
    observed_socs : sequence of float
        The baseline's initial SOC (0..1) of each observed recording.
    """
    from battery_predictor.diagnosis.engine import soc_from_voltage
    from battery_predictor.diagnosis.residuals import pack_capacity_ah

    capacity = pack_capacity_ah(engine, params)
    ref_min: float | None
    if reference.end_padding and any(r.ends_at_cutoff for r in refs):
        ref_min = None  # a reference that stopped at its cut-off: the model was shown the end
    else:
        ref_min = min(float(np.min(soc_trace(r, soc_from_voltage(engine, params, float(ocv)), capacity)))
                      for r, ocv in zip(refs, reference.socs))
    traces = [soc_trace(o, float(s), capacity) for o, s in zip(observed, observed_socs)]
    until = [first_time_below(o, tr, ref_min) for o, tr in zip(observed, traces)]
    held = sum(int(o.held_mask.sum()) for o in observed)
    covered = sum(int((o.held_mask & (o.t < u)).sum()) for o, u in zip(observed, until))
    return Coverage(reference_min_soc=ref_min, observed_min_soc=[float(np.min(tr)) for tr in traces],
                    covered_until_s=until, heldout_samples=held, covered_heldout_samples=covered)


def covered_rmse_mv(observed: Sequence[Observed], sims: Sequence[SimOut], until_s: Sequence[float]) -> float:
    """Held-out RMSE (mV) pooled over the held-out samples before each recording's ``until_s`` (nan: none)."""
    scores = [held_out_score(o, s, until_s=u) for o, s, u in zip(observed, sims, until_s)]
    n = sum(s.n for s in scores)
    return 1e3 * math.sqrt(sum(s.sq_err_sum for s in scores) / n) if n else float("nan")


def covered_claim(coverage: Coverage, cause: str, observed: Sequence[Observed], base_sims: Sequence[SimOut],
                  cause_sims: Sequence[SimOut], noise_mv: float, floor_mv: float) -> bool:
    """Whether the claim of ``cause`` holds on the held-out samples the references cover.

    Always true when no observed recording goes deeper than the references. Otherwise the baseline's
    and the cause's held-out RMSEs are recomputed on the covered samples and the claim must pass
    :func:`~battery_predictor.diagnosis.decision.claim_allowed` there with the same noise and floor;
    with no covered held-out sample it fails. Records the figures and the outcome in ``coverage``.
    """
    if not coverage.leaves_range:
        return True
    coverage.cause = cause
    if coverage.covered_heldout_samples == 0:
        coverage.refused = True
        return False
    b = covered_rmse_mv(observed, base_sims, coverage.covered_until_s)
    c = covered_rmse_mv(observed, cause_sims, coverage.covered_until_s)
    coverage.baseline_rmse_mV, coverage.cause_rmse_mV = b, c
    coverage.refused = not claim_allowed(b, c, noise_mv, floor_mv)
    return not coverage.refused


def refusal_text(coverage: Coverage, cause: str, whole_gain_pct: float) -> str:
    """The evidence sentence of a claim refused because it rests on depths no reference reached."""
    ref = coverage.reference_min_soc if coverage.reference_min_soc is not None else float("nan")
    deepest = min(coverage.observed_min_soc) if coverage.observed_min_soc else float("nan")
    starts = [u for u in coverage.covered_until_s if math.isfinite(u)]
    where = f" from {min(starts) / 3600.0:.2f} h on" if starts else ""
    text = (f"No claim: the observed data go deeper than the reference recordings did{where} (down to "
            f"{100 * deepest:.0f} % SOC of the reference model; the references reached {100 * ref:.0f} %), where "
            f"the reference model extrapolates (e.g. where the end-of-discharge knee lies). {cause} cuts the "
            f"baseline's held-out error by {whole_gain_pct:.1f} % over the whole held-out part, ")
    if coverage.covered_heldout_samples == 0 or coverage.baseline_rmse_mV is None or coverage.cause_rmse_mV is None:
        text += "but no held-out sample lies within the references' depth. "
    else:
        b, c = coverage.baseline_rmse_mV, coverage.cause_rmse_mV
        gain = 100.0 * (b - c) / b if b > 0 else 0.0
        text += (f"but on the {coverage.covered_heldout_samples} of {coverage.heldout_samples} held-out samples "
                 f"within the references' depth only from {b:.1f} to {c:.1f} mV ({gain:+.1f} %), which is no claim "
                 "by the same rule. ")
    return text + ("To judge the deeper part, fit the reference on a recording that goes at least as deep "
                   "(ideally one that ends at its cut-off) and diagnose again.")
