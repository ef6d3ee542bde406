"""What a diagnosis returns: each fitted candidate's held-out scores and the verdict (the CLI's JSON)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from battery_predictor.diagnosis.candidates import candidate
from battery_predictor.diagnosis.coverage import Coverage
from battery_predictor.diagnosis.engine import Engine, Observed, SimOut
from battery_predictor.diagnosis.reference import ReferenceFit
from battery_predictor.diagnosis.residuals import ResidualAnalysis
from battery_predictor.params import PackParams

#: The cause reported when the reference fit is too poor to judge any candidate
#: (:func:`~battery_predictor.diagnosis.reference.reference_verdict`): neither a cause nor ``none``.
NOT_JUDGED = "not_judged"


@dataclass
class CandidateResult:
    """A fitted candidate (or the baseline, ``cause == "none"``) and its held-out scores."""

    cause: str
    fitted: dict[str, float]
    socs: list[float]
    heldout_rmse_mV: float
    heldout_r2_mod: float
    runtime_error_s: float | None
    fit_rmse_mV: float
    evaluations: int
    failures: int
    seconds: float
    gain_pct: float = 0.0
    applicable: bool = True
    reason: str = ""
    #: Why a fitted candidate is not named although it applies: its effect is below what the instruments
    #: resolve (:meth:`~battery_predictor.diagnosis.candidates.Candidate.unresolved`); empty otherwise.
    unresolved: str = ""
    sims: list[SimOut] = field(default_factory=list, repr=False)
    fitted_folds: list[dict[str, float]] = field(default_factory=list)
    #: Which solver ran the fit's simulations (:meth:`~battery_predictor.diagnosis.engine.Engine.usage_since`).
    simulator: dict[str, Any] = field(default_factory=dict)

    def metrics(self) -> dict[str, Any]:
        return {"heldout_rmse_mV": self.heldout_rmse_mV, "heldout_r2_mod": self.heldout_r2_mod,
                "runtime_error_s": self.runtime_error_s}

    def row(self) -> dict[str, Any]:
        out = {"cause": self.cause, "heldout_rmse_mV": self.heldout_rmse_mV, "gain_pct": self.gain_pct,
               "fitted": dict(self.fitted), "heldout_r2_mod": self.heldout_r2_mod,
               "runtime_error_s": self.runtime_error_s, "fit_rmse_mV": self.fit_rmse_mV,
               "initial_soc": list(self.socs), "evaluations": self.evaluations, "seconds": self.seconds}
        if self.fitted_folds:
            out["fitted_folds"] = [dict(f) for f in self.fitted_folds]
        if self.simulator:
            out["simulator"] = dict(self.simulator)
        if not self.applicable:
            out["not_applicable"] = self.reason
        if self.unresolved:
            out["unresolved"] = self.unresolved
        return out


@dataclass
class Diagnosis:
    """Result of :func:`~battery_predictor.diagnosis.diagnose.diagnose`; :meth:`to_json` gives the CLI's JSON object."""

    cause: str
    evidence: str
    baseline: CandidateResult
    extended: CandidateResult
    gain_pct: float
    candidates: list[CandidateResult]
    residuals: ResidualAnalysis
    noise_mV: float
    params: PackParams
    observed: list[Observed]
    reference: ReferenceFit | None
    seconds: float
    budget: int
    fit_fraction: float
    separable_with: list[str] = field(default_factory=list)
    split: str = "time"
    temperature_shift_k: float | None = None
    #: False when the reference fit was too poor to judge candidates (``cause == NOT_JUDGED``).
    judged: bool = True
    #: The observed recordings' depth against the references' and the claim on the covered part
    #: (:mod:`~battery_predictor.diagnosis.coverage`); None without references.
    coverage: Coverage | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "cause": self.cause,
            "evidence": self.evidence,
            "baseline": self.baseline.metrics(),
            "extended": self.extended.metrics(),
            "gain_pct": self.gain_pct,
            "candidates": [c.row() for c in self.candidates],
            "residuals": self.residuals.to_json(),
            "noise_mV": self.noise_mV,
            "not_separable_from": list(self.separable_with),
            "reference_fit": None if self.reference is None else self.reference.to_json(),
            "judged": self.judged,
            "budget": self.budget,
            "fit_fraction": self.fit_fraction,
            "split": self.split,
            "temperature_shift_k": self.temperature_shift_k,
            "reference_coverage": None if self.coverage is None else self.coverage.to_json(),
            "seconds": self.seconds,
        }

    def candidate(self, cause: str) -> CandidateResult:
        for c in self.candidates:
            if c.cause == cause:
                return c
        if cause == "none":
            return self.baseline
        raise KeyError(cause)

    def extended_params(self, engine: Engine | None = None) -> PackParams:
        """The params with the named extension active and its fitted values (the baseline for ``none``)."""
        if self.cause == "none":
            return self.params
        res = self.candidate(self.cause)
        return candidate(self.cause).extended_params(self.params, res.fitted, res.socs, engine or Engine())
