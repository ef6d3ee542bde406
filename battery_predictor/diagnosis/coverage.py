"""How deep the observed recordings go compared with the reference recordings the baseline was fitted on.

The reference fit is shown the reference recordings only: down to the deepest discharge they
reached, the reference model is identified by data; beyond it (a working day that stopped before
its end-of-discharge knee) the model *extrapolates*: where the knee lies follows from the fitted
capacities and open-circuit potentials, not from any measurement. An observed day that goes
deeper than every reference shows the baseline's error there whether or not anything changed in
the battery, and a candidate with a capacity knob (capacity fade above all) moves the knee and
fits it. That error is not evidence of a change.

The depth is the net charge drawn since the start of the recording (Ah, measured): the observed
recording is *covered* until it first has drawn more than any reference drew. The charge is the
one the named cause implies: a current sensor offset (cause ``current_offset``) is taken off the
observed reading before its depth is measured, as the extension drives the cells; read as it is,
the biased reading would put a day with a positive offset deeper than the pack can go (a 0.8 A
offset over 6 h reads 18.7 Ah from a 14.7 Ah pack) and refuse the very cause that explains it.
Not the model's
state of charge: the baseline's fitted initial SOC absorbs the effect itself (a faded or a cold
cell looks like one that started less charged), so a day with a real loss of capacity would look
deeper than it is (measured: the Ranger seed-2 capacity-fade and temperature cases of the second
generator, docs/findings.md). The charge drawn takes the recordings to start from comparable
states, as a robot's working days do after their charge; an observed day that starts less
charged than the references makes the guard less strict, not more. A reference that stopped at
its cut-off (kept padded by the reference fit) covers everything the pack can deliver.

The guard (:func:`covered_claim`): a cause named from the whole held-out part is named only when
the same claim holds (:func:`~battery_predictor.diagnosis.decision.claim_allowed`, same noise and
floor) on the held-out samples the references cover. A real change shows there too: capacity
fade lowers the voltage at a given charge drawn and brings the knee forward into the covered
range; a resistance, an offset or a hysteresis act all day. The one exception is a cause the
measurements show directly: a measured temperature unlike the references' (the decision's
``measured_first``) is a change whether or not the covered part shows it (on LFP the cold acts
mostly near the knee); it is named with a caveat giving its gain on the covered part
(:func:`measured_text`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.diagnosis.decision import claim_allowed
from battery_predictor.diagnosis.scoring import held_out_score

if TYPE_CHECKING:
    from battery_predictor.diagnosis.engine import Observed, SimOut
    from battery_predictor.diagnosis.reference import ReferenceFit


@dataclass
class Coverage:
    """The observed recordings' depth (net charge drawn since their start, Ah) against the references'.

    Attributes
    ----------
    reference_drawn_ah : float or None
        Most charge any reference recording drew; None when a reference stopped at its cut-off
        (everything covered).
    observed_drawn_ah : list of float
        Most charge each observed recording drew.
    covered_until_s : list of float
        Per observed recording, the time (s from its start) at which it first has drawn more than
        ``reference_drawn_ah`` (``inf``: never).
    sensor_offset_a : float
        The current sensor offset (A) taken off the observed readings (the named cause's; 0 for
        causes in the cells).
    heldout_samples, covered_heldout_samples : int
        Held-out samples of all observed recordings, and those before ``covered_until_s``.
    cause : str or None
        The cause the whole held-out part would name (set by :func:`covered_claim`).
    baseline_rmse_mV, cause_rmse_mV : float or None
        Held-out RMSE (mV) of the baseline and of ``cause`` on the covered held-out samples.
    refused : bool
        The claim of ``cause`` did not hold on the covered samples: ``none`` is named.
    measured : bool
        The claim did not hold on the covered samples but stands: the cause is measured (a
        temperature unlike the references', :data:`~battery_predictor.diagnosis.decision.MEASURED_SHIFT_K`),
        not inferred from the error alone (:func:`measured_text`).
    """

    reference_drawn_ah: float | None
    observed_drawn_ah: list[float]
    covered_until_s: list[float]
    sensor_offset_a: float = 0.0
    heldout_samples: int = 0
    covered_heldout_samples: int = 0
    cause: str | None = None
    baseline_rmse_mV: float | None = None
    cause_rmse_mV: float | None = None
    refused: bool = False
    measured: bool = False

    @property
    def leaves_range(self) -> bool:
        """Whether some observed recording goes deeper than every reference."""
        return any(math.isfinite(u) for u in self.covered_until_s)

    def to_json(self) -> dict[str, Any]:
        return {"reference_drawn_ah": self.reference_drawn_ah, "observed_drawn_ah": list(self.observed_drawn_ah),
                "covered_until_s": [u if math.isfinite(u) else None for u in self.covered_until_s],
                "sensor_offset_a": self.sensor_offset_a,
                "heldout_samples": self.heldout_samples, "covered_heldout_samples": self.covered_heldout_samples,
                "cause": self.cause, "baseline_rmse_mV": self.baseline_rmse_mV, "cause_rmse_mV": self.cause_rmse_mV,
                "refused": self.refused, "kept_as_measured": self.measured}


def first_time_beyond(obs: Observed, drawn_ah: float | None, sensor_offset_a: float = 0.0) -> float:
    """Time (s) of the first sample at which ``obs`` has drawn more than ``drawn_ah`` (``inf``: none, or None),
    its reading less ``sensor_offset_a`` (A)."""
    if drawn_ah is None:
        return math.inf
    deeper = np.nonzero(obs.cumulative_charge_ah(sensor_offset_a) > drawn_ah)[0]
    return float(obs.t[deeper[0]]) if deeper.size else math.inf


def reference_coverage(refs: Sequence[Observed], reference: ReferenceFit, observed: Sequence[Observed],
                       sensor_offset_a: float = 0.0) -> Coverage:
    """How deep the observed recordings go against the references (see the module docstring).

    Parameters
    ----------
    refs : sequence of Observed
        The reference recordings (current in A, discharge positive).
    reference : ReferenceFit
        The reference fit (whether it kept the end padding of references that stopped at their cut-off).
    observed : sequence of Observed
        The observed recordings.
    sensor_offset_a : float
        A current sensor offset (A, pack) the named cause says the observed readings carry; taken off
        them (the references are read as they are: the cause is a change since them).
    """
    ref_drawn: float | None
    if reference.end_padding and any(r.ends_at_cutoff for r in refs):
        ref_drawn = None  # a reference that stopped at its cut-off: the model was shown the end
    else:
        ref_drawn = max(float(np.max(r.cumulative_charge_ah())) for r in refs)
    until = [first_time_beyond(o, ref_drawn, sensor_offset_a) for o in observed]
    held = sum(int(o.held_mask.sum()) for o in observed)
    covered = sum(int((o.held_mask & (o.t < u)).sum()) for o, u in zip(observed, until))
    return Coverage(reference_drawn_ah=ref_drawn,
                    observed_drawn_ah=[float(np.max(o.cumulative_charge_ah(sensor_offset_a))) for o in observed],
                    covered_until_s=until, sensor_offset_a=sensor_offset_a, heldout_samples=held,
                    covered_heldout_samples=covered)


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
    :func:`~battery_predictor.diagnosis.decision.claim_allowed` there with the same noise and floor (the
    test for a change shown directly: the claim on the whole held-out part has already passed);
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
    coverage.refused = not claim_allowed(b, c, noise_mv, floor_mv, measured=True)  # the whole part passed
    return not coverage.refused


def _deeper_from(coverage: Coverage) -> str:
    """`` from H h on``: when the first observed recording leaves the references' depth ("" when none does)."""
    starts = [u for u in coverage.covered_until_s if math.isfinite(u)]
    return f" from {min(starts) / 3600.0:.2f} h on" if starts else ""


def refusal_text(coverage: Coverage, cause: str, whole_gain_pct: float) -> str:
    """The evidence sentence of a claim refused because it rests on depths no reference reached."""
    ref = coverage.reference_drawn_ah if coverage.reference_drawn_ah is not None else float("nan")
    deepest = max(coverage.observed_drawn_ah) if coverage.observed_drawn_ah else float("nan")
    where = _deeper_from(coverage)
    text = (f"No claim: the observed data go deeper than the reference recordings did{where} (up to "
            f"{deepest:.2f} Ah drawn since their start; the references drew at most {ref:.2f} Ah), where "
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


def measured_text(coverage: Coverage, cause: str, shift_k: float | None) -> str:
    """The caveat of a measured cause kept although its claim does not hold on the covered samples."""
    where = _deeper_from(coverage)
    shift = f"{abs(shift_k):.0f} K" if shift_k is not None else "a measured shift"
    text = (f"Caveat: the observed data go deeper than the reference recordings did{where}, where the reference "
            f"model extrapolates; {cause} is named because the measured temperature differs from the references' by "
            f"{shift}, ")
    b, c = coverage.baseline_rmse_mV, coverage.cause_rmse_mV
    if coverage.covered_heldout_samples and b is not None and c is not None and b > 0:
        text += (f"but within the references' depth ({coverage.covered_heldout_samples} of {coverage.heldout_samples} "
                 f"held-out samples) it cuts the error only from {b:.1f} to {c:.1f} mV ({100.0 * (b - c) / b:+.1f} %): "
                 "part of the gain may be the reference model's extrapolation.")
    else:
        text += "but no held-out sample lies within the references' depth: the gain may be the reference model's extrapolation."
    return text
