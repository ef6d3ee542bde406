"""The decision rule of the diagnosis: which candidate, if any, is named, and the thresholds it uses.

Candidates are compared by their *excess* held-out error, the part of the RMSE
above the voltage noise (:func:`excess_mv`), which no model can predict. Among the candidates
whose excess error is within :data:`SEPARABILITY_FACTOR` (plus :data:`NEAR_NOISE_FRACTION` of
the noise) of the lowest, the simplest (:data:`SIMPLICITY_ORDER`) is the best one. It is named
when it cuts the baseline's held-out RMSE by at least :data:`GAIN_THRESHOLD_PCT` and by more
than :data:`NOISE_FACTOR` times the voltage noise, and the baseline's error is clearly above its
floor (:data:`BASELINE_FLOOR_FACTOR`, :func:`claim_allowed`); otherwise the cause is ``none``. A
change the measurements show directly (a measured temperature unlike the reference's) needs only a
baseline above its floor (:data:`FLOOR_MARGIN`), not several times it.

The procedure that fits and scores the candidates is :mod:`battery_predictor.diagnosis.diagnose`;
the evidence text that states the verdict is :func:`battery_predictor.diagnosis.residuals.evidence_text`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the result type only: results -> residuals -> decision must not come back here
    from battery_predictor.diagnosis.results import CandidateResult

#: A candidate must cut the baseline's held-out RMSE by at least this much (%) to be named.
#: (Why each threshold has its value: docs/findings.md, "Code notes (issue 15)".)
GAIN_THRESHOLD_PCT = 20.0
#: ... and by more than this many times the voltage noise (absolute improvement) ...
NOISE_FACTOR = 1.0
#: ... and the baseline's held-out RMSE must exceed this many times its error floor: the larger of
#: the voltage noise and the baseline's RMSE on the reference data (what the model achieves when
#: nothing has changed). Below that, the residual left by the reference fit itself is what a
#: candidate would explain. The floor is an in-sample figure; on another day a correct model's
#: held-out error is larger: 0.87-1.82 times the floor on the second generator's days without an
#: effect (tuning seeds 0-2 and 100-109, 18 days); 2.5 lies above all of them by a third.
BASELINE_FLOOR_FACTOR = 2.5
#: A baseline within this factor of its floor shows nothing to explain, even for a measured change.
#: (A candidate that merely brings the held-out error back near the in-sample floor is not evidence
#: of a cause: any fitted knob absorbs part of a correct model's larger error on another day.)
FLOOR_MARGIN = 1.10
#: Candidates whose excess held-out error (above the noise) is within this factor of the lowest, plus
#: :data:`NEAR_NOISE_FRACTION` of the noise, are not separable; the simplest of them is named.
SEPARABILITY_FACTOR = 1.10
#: Absolute slack of the separability margin, as a fraction of the voltage noise: near the noise
#: floor the excess errors themselves are uncertain by about that much.
NEAR_NOISE_FRACTION = 0.25
#: From the smallest change of the model to the largest: one post-processed parameter (contact
#: resistance, current offset), a second cell (imbalance), a model change (SPMe), a thermal model
#: with two parameters, two degradation parameters that move the electrodes' state windows, an extra
#: state with three parameters.
SIMPLICITY_ORDER = ("resistance_growth", "current_offset", "cell_imbalance", "electrolyte_transport",
                    "temperature", "capacity_fade", "hysteresis")


def excess_mv(rmse_mv: float, noise_mv: float) -> float:
    """The part of a held-out RMSE above the voltage noise (mV): ``sqrt(max(rmse^2 - noise^2, 0))``.

    White measurement noise adds in quadrature and no model can predict it, so two models are
    compared by what they leave on top of it.
    """
    return math.sqrt(max(rmse_mv * rmse_mv - noise_mv * noise_mv, 0.0))


def near_lowest(valid: Sequence[CandidateResult], noise_mv: float) -> list[CandidateResult]:
    """The candidates not separable from the lowest held-out error (see :data:`SEPARABILITY_FACTOR`)."""
    if not valid:
        return []
    lowest = min(excess_mv(r.heldout_rmse_mV, noise_mv) for r in valid)
    margin = SEPARABILITY_FACTOR * lowest + NEAR_NOISE_FRACTION * noise_mv
    return [r for r in valid if excess_mv(r.heldout_rmse_mV, noise_mv) <= margin]


def choose_best(valid: Sequence[CandidateResult], noise_mv: float,
                measured_first: Sequence[str] = ()) -> CandidateResult | None:
    """The simplest candidate whose excess held-out error is within the margin of the lowest one.

    Excess errors closer than :data:`SEPARABILITY_FACTOR` (plus :data:`NEAR_NOISE_FRACTION` of the
    noise) do not tell two causes apart; the one that changes the model least
    (:data:`SIMPLICITY_ORDER`) is named, e.g. a contact resistance before the SPMe, whose
    electrolyte resistance also grows the ohmic drop. Causes in ``measured_first`` come first among
    the inseparable ones: a cause the measurements show directly (a measured temperature unlike the
    reference's, :data:`MEASURED_SHIFT_K`) is named before a hidden one that predicts as well.
    """
    near = near_lowest(valid, noise_mv)
    if not near:
        return None
    return min(near, key=lambda r: (r.cause not in measured_first, SIMPLICITY_ORDER.index(r.cause),
                                    r.heldout_rmse_mV))


#: Observed recordings whose mean measured temperature differs from the references' by more than this
#: (K) put ``temperature`` first among candidates that predict equally well (:func:`choose_best`). 5 K
#: changes an Arrhenius rate with a typical battery activation energy (20-50 kJ/mol) by 15-40 %, far
#: beyond the +-1 K of a chamber or of the self-heating difference between reference runs.
MEASURED_SHIFT_K = 5.0


def measured_causes(temperature_shift_k: float | None) -> tuple[str, ...]:
    """The causes the measurements show directly: ``temperature`` when the observed recordings' mean
    measured temperature differs from the references' by more than :data:`MEASURED_SHIFT_K` (K)."""
    if temperature_shift_k is not None and abs(temperature_shift_k) > MEASURED_SHIFT_K:
        return ("temperature",)
    return ()


def name_cause(valid: Sequence[CandidateResult], base_rmse_mv: float, noise_mv: float, floor_mv: float,
               temperature_shift_k: float | None) -> tuple[CandidateResult | None, str]:
    """The best candidate (:func:`choose_best`) and the cause named on the whole held-out part (mV, K).

    The cause is the best candidate's when :func:`claim_allowed` lets it over the baseline, else ``none``.
    """
    measured = measured_causes(temperature_shift_k)
    best = choose_best(valid, noise_mv, measured)
    if best is not None and claim_allowed(base_rmse_mv, best.heldout_rmse_mV, noise_mv, floor_mv,
                                          measured=best.cause in measured):
        return best, best.cause
    return best, "none"


def claim_allowed(base_rmse_mv: float, best_rmse_mv: float, noise_mv: float, floor_mv: float,
                  measured: bool = False) -> bool:
    """Whether a candidate with held-out RMSE ``best_rmse_mv`` may be named over the baseline (mV).

    It must cut the baseline's error by :data:`GAIN_THRESHOLD_PCT` and by more than :data:`NOISE_FACTOR`
    noise levels, and the baseline must be clearly above its floor (:data:`BASELINE_FLOOR_FACTOR`).

    ``measured``: the candidate's cause is shown by the measurements themselves (a measured
    temperature unlike the reference's, :data:`MEASURED_SHIFT_K`). The floor factor guards against
    naming a hypothetical knob that only fits what the reference fit leaves on another day; a
    measured change is not hypothetical, so a baseline above its floor (:data:`FLOOR_MARGIN`)
    suffices. The same weaker test decides whether a claim still holds on the part of the data the
    references cover (:func:`~battery_predictor.diagnosis.coverage.covered_claim`): there the claim
    on the whole held-out part has already passed.
    """
    if not (math.isfinite(base_rmse_mv) and math.isfinite(best_rmse_mv)) or base_rmse_mv <= 0:
        return False
    gain_pct = 100.0 * (base_rmse_mv - best_rmse_mv) / base_rmse_mv
    if gain_pct < GAIN_THRESHOLD_PCT or base_rmse_mv - best_rmse_mv <= NOISE_FACTOR * noise_mv:
        return False
    return base_rmse_mv > (FLOOR_MARGIN if measured else BASELINE_FLOOR_FACTOR) * floor_mv
