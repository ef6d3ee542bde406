"""What the fit data say about where the fitted pack stops, kept in the fitted params.

Every fit path (``battery-predictor fit`` in both methods, the paper's evaluation) passes its fitted
params through :func:`with_fit_data_limits`:

- the fit data's **deepest state** goes into ``thresholds`` (:func:`with_deepest_state`); the route
  check does not let a route draw the pack below it when it lies above the route threshold
  (:func:`~battery_predictor.prediction.safety.charge_floor`);
- where the data stop under load above the route threshold, the **weak series group** that makes the
  fitted model stop there is added (:func:`with_inferred_weak_group`, :mod:`.weak_group`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.fitting.weak_group import inferred_weak_fraction, weak_group_evidence
from battery_predictor.params import PackParams
from battery_predictor.params_checks import pack_voltage_window_v
from battery_predictor.recording import DeepestState, Recording, deepest_state
from battery_predictor.simulation.extensions import with_weak_group


@dataclass(frozen=True)
class FitDataLimits:
    """Fitted params with the fit data's limits, and what was kept.

    Attributes
    ----------
    params : PackParams
        The fitted params with the deepest state in ``thresholds`` and the inferred weak group, where any.
    deepest : DeepestState or None
        The deepest state kept (None: none, e.g. it lies outside the pack's voltage window).
    weak_group_line : str
        One line saying which weak group was inferred, or why none.
    """

    params: PackParams
    deepest: DeepestState | None
    weak_group_line: str


def with_deepest_state(params: PackParams, recordings: Sequence[Recording]) -> tuple[PackParams, DeepestState | None]:
    """``params`` keeping the fit data's deepest state in ``thresholds``, and that state (None: none kept).

    A state outside the pack's voltage window is not kept (it is below any threshold).
    """
    deepest = deepest_state(recordings, params.ambient_temperature_k)
    if deepest is None:
        return params, None
    low, high = pack_voltage_window_v(params)
    if not low <= deepest.voltage_v <= high:
        return params, None
    return replace(params, thresholds={**params.thresholds, **deepest.as_thresholds()}), deepest


def with_inferred_weak_group(params: PackParams, recordings: Sequence[Recording],
                             deepest: DeepestState | None) -> tuple[PackParams, str]:
    """``params`` with the weak series group the fit data's stop implies, and a line saying what was done.

    Only data that stop under load above the route threshold call for one (:func:`.weak_group_evidence`);
    otherwise ``params`` come back unchanged with the reason.

    Raises
    ------
    SimulationError
        When the model cannot run the recordings the inference needs.
    """
    stopped, why_not = weak_group_evidence(params, recordings, deepest)
    if stopped is None or deepest is None:
        return params, f"no weak series group inferred ({why_not})"
    inference = inferred_weak_fraction(params, stopped, deepest)
    return with_weak_group(params, inference.fraction), inference.describe()


def with_fit_data_limits(params: PackParams, recordings: Sequence[Recording], *,
                         infer_weak_group: bool = True) -> FitDataLimits:
    """The fitted ``params`` with the deepest state of ``recordings`` (the fit data) and the weak group they imply.

    A model failure of the weak-group inference keeps the params without a group and says so in the line
    (the fit is not lost); ``infer_weak_group=False`` skips the inference.
    """
    kept, deepest = with_deepest_state(params, recordings)
    if not infer_weak_group:
        return FitDataLimits(kept, deepest, "no weak series group inferred (--no-weak-group-inference)")
    try:
        grouped, line = with_inferred_weak_group(kept, recordings, deepest)
    except BatteryPredictorError as exc:
        return FitDataLimits(kept, deepest, f"no weak series group inferred (the model failed: {exc})")
    return FitDataLimits(grouped, deepest, line)
