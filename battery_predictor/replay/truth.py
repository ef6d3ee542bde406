"""The ground truth of a discharge bag and the predicted-vs-true remaining runtime (the paper's metrics)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Remaining-runtime checkpoints of the issue and the paper's evaluation (min).
DEFAULT_CHECKPOINTS_MIN = tuple(range(30, 301, 30))


@dataclass(frozen=True)
class RuntimeTruth:
    """True runtime of a discharge bag: the time (recording axis, s) at which ``stop_voltage_v`` was measured.

    Attributes
    ----------
    stop_voltage_v : float
        Pack voltage that ends the discharge, V.
    runtime_s : float
        Recording time of the end, s.
    source : str
        Where the truth comes from: ``"metadata"`` (the lab's, stored in the bag) or
        ``"recording: <how the end is known>"`` (found in the measured samples).
    checkpoints_min : tuple of float
        Recording times (min) at which predictions are compared with the truth.
    """

    stop_voltage_v: float
    runtime_s: float
    source: str = "metadata"
    checkpoints_min: tuple[float, ...] = DEFAULT_CHECKPOINTS_MIN

    def remaining_s(self, recording_time_s: float) -> float:
        """True remaining runtime (s) at a recording time."""
        return self.runtime_s - recording_time_s


def runtime_truth(metadata: dict[str, Any]) -> RuntimeTruth | None:
    """The runtime truth stored by the lab in a bag's metadata, or None (e.g. route bags)."""
    truth = metadata.get("truth") if isinstance(metadata, dict) else None
    if not isinstance(truth, dict):
        return None
    try:
        runtime = float(truth["runtime_s"])
        stop = float(truth["stop_voltage_v"])
    except (KeyError, TypeError, ValueError):
        return None
    return RuntimeTruth(stop, runtime) if math.isfinite(runtime) else None


@dataclass(frozen=True)
class RuntimePoint:
    """One published remaining-runtime message, on the recording time axis.

    Attributes
    ----------
    time_s : float
        Recording time of the pack state the prediction is based on (its header stamp), s.
    remaining_s : float
        Predicted remaining runtime, s (NaN when invalid).
    valid : bool
        The message's ``valid``.
    status : int
        The message's ``status``.
    reason : str
        The message's ``reason``.
    p10_s, p90_s : float
        The message's ``remaining_p10_s`` and ``remaining_p90_s``, s (NaN when unknown).
    cutoff_voltage_v : float
        The message's ``cutoff_voltage_v``, V (NaN when unknown).
    """

    time_s: float
    remaining_s: float
    valid: bool
    status: int
    reason: str = ""
    p10_s: float = math.nan
    p90_s: float = math.nan
    cutoff_voltage_v: float = math.nan


@dataclass(frozen=True)
class Checkpoint:
    """Prediction vs truth at one checkpoint (the latest valid prediction at or before it)."""

    checkpoint_min: float
    time_s: float
    predicted_min: float
    true_min: float
    p10_min: float = math.nan
    p90_min: float = math.nan

    @property
    def error_min(self) -> float:
        """Predicted minus true remaining runtime, min."""
        return self.predicted_min - self.true_min


def compare_at_checkpoints(points: Sequence[RuntimePoint], truth: RuntimeTruth,
                           checkpoints_min: Sequence[float] | None = None,
                           max_age_s: float = 600.0) -> list[Checkpoint]:
    """For each checkpoint (min from the recording start), the latest valid prediction at or before it.

    ``checkpoints_min`` defaults to the truth's own (``truth.checkpoints_min``). Checkpoints after
    the true end of the discharge, or with no valid prediction within ``max_age_s`` before them,
    are left out.
    """
    if checkpoints_min is None:
        checkpoints_min = truth.checkpoints_min
    valid = sorted((p for p in points if p.valid and math.isfinite(p.remaining_s)), key=lambda p: p.time_s)
    times = np.array([p.time_s for p in valid])
    out = []
    for cp in checkpoints_min:
        t_cp = 60.0 * float(cp)
        if t_cp >= truth.runtime_s or not len(times):
            continue
        k = int(np.searchsorted(times, t_cp + 1e-6, side="right")) - 1
        if k < 0 or t_cp - times[k] > max_age_s:
            continue
        p = valid[k]
        out.append(Checkpoint(float(cp), p.time_s, p.remaining_s / 60.0, truth.remaining_s(p.time_s) / 60.0,
                              p.p10_s / 60.0, p.p90_s / 60.0))
    return out


def error_summary(checkpoints: Sequence[Checkpoint], truth: RuntimeTruth | None = None) -> dict[str, float]:
    """MAE (min), max |error| (min) and MAPE (%) over checkpoints (the paper's metrics)."""
    if not checkpoints:
        return {"n": 0, "mae_min": math.nan, "max_abs_error_min": math.nan, "mape_pct": math.nan}
    err = np.array([c.error_min for c in checkpoints])
    true = np.array([c.true_min for c in checkpoints])
    return {"n": len(checkpoints), "mae_min": float(np.mean(np.abs(err))),
            "max_abs_error_min": float(np.max(np.abs(err))),
            "mape_pct": float(100.0 * np.mean(np.abs(err) / np.maximum(true, 1e-9)))}
