"""The modified R2 score of the seed paper (Eq. 1-3) and plain error measures."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class AlignedSignals:
    """Measured and predicted voltage on the common (extended) measurement grid.

    Attributes
    ----------
    time_s : numpy.ndarray
        Measurement times, extended to the common horizon ``t_max`` when the prediction ends later.
    measured_v, predicted_v : numpy.ndarray
        Voltages in V on that grid, both padded with ``u_min_v`` where they had no data.
    u_min_v : float
        Minimum measured voltage in V.
    """

    time_s: np.ndarray
    measured_v: np.ndarray
    predicted_v: np.ndarray
    u_min_v: float


def align_for_r2_mod(measured_time_s: npt.ArrayLike, measured_v: npt.ArrayLike, predicted_time_s: npt.ArrayLike,
                     predicted_v: npt.ArrayLike, ends_at_cutoff: bool = True) -> AlignedSignals:
    """Truncate, extend and interpolate as Eq. (1) and (2) of the seed paper.

    1. ``U_min = min_i U_i``; the prediction is truncated where it first falls below ``U_min``
       (Eq. 1: only ``U~_j >= U_min`` is kept, the prediction ends there).
    2. ``t_max = max(max t_i, max t~_j)`` (Eq. 2). Both signals are extended to ``t_max``,
       padded with ``U_min``: the measurement grid is extended beyond ``max t_i`` with its
       median sampling interval (so that a prediction ending late is penalised), the
       prediction is padded after its end (so that a prediction ending early is penalised).
    3. The prediction is interpolated linearly onto the (extended) measurement grid.

    Steps 1 and 2's late-end part hold for a recording that ends at its cut-off (the paper's
    discharges): its ``U_min`` is where the cell stopped. A recording that stops above it (a working
    day that ends at 40 % SOC, :func:`~battery_predictor.recording.ends_at_cutoff`) says nothing
    about later voltages, and a load peak of the model may dip below its ``U_min`` without the model
    having ended: with ``ends_at_cutoff=False`` the prediction is neither truncated nor compared past
    the measurement's end (a prediction that ends early is still padded with ``U_min``).

    Parameters
    ----------
    measured_time_s, measured_v : array_like
        Measured times (s, increasing) and voltages (V).
    predicted_time_s, predicted_v : array_like
        Predicted times (s, increasing) and voltages (V); may be empty (treated as all ``U_min``).
    ends_at_cutoff : bool
        Whether the measurement ends at its cut-off (default: the paper's case).
    """
    t = np.asarray(measured_time_s, dtype=float)
    u = np.asarray(measured_v, dtype=float)
    tp = np.asarray(predicted_time_s, dtype=float)
    up = np.asarray(predicted_v, dtype=float)
    if t.size == 0:
        raise ValueError("no measured samples")
    u_min = float(np.min(u))
    below = np.nonzero(up < u_min)[0] if ends_at_cutoff else np.empty(0, dtype=int)
    if below.size:
        tp, up = tp[: below[0]], up[: below[0]]
    t_max = max(float(t[-1]), float(tp[-1]) if tp.size and ends_at_cutoff else -np.inf)
    if t_max > t[-1]:
        dt = float(np.median(np.diff(t))) if t.size > 1 else max(t_max - t[-1], 1.0)
        extra = np.arange(t[-1] + dt, t_max + 0.5 * dt, dt)
        t = np.concatenate([t, extra])
        u = np.concatenate([u, np.full(extra.size, u_min)])
    if tp.size == 0:
        pred = np.full(t.size, u_min)
    else:
        pred = np.interp(t, tp, up, left=up[0], right=u_min)
        pred[t > tp[-1]] = u_min
    return AlignedSignals(time_s=t, measured_v=u, predicted_v=pred, u_min_v=u_min)


def r2_mod(measured_time_s: npt.ArrayLike, measured_v: npt.ArrayLike, predicted_time_s: npt.ArrayLike,
           predicted_v: npt.ArrayLike, ends_at_cutoff: bool = True) -> float:
    """Modified R2 (Eq. 3) of a predicted against a measured voltage curve.

    ``R2_mod = 1 - sum (U_i - U~_i)^2 / sum (U_i - mean U)^2`` on the grid of
    :func:`align_for_r2_mod` (``ends_at_cutoff``: see there). 1 is perfect; it can be negative.
    """
    a = align_for_r2_mod(measured_time_s, measured_v, predicted_time_s, predicted_v, ends_at_cutoff)
    ss_res = float(np.sum((a.measured_v - a.predicted_v) ** 2))
    ss_tot = float(np.sum((a.measured_v - np.mean(a.measured_v)) ** 2))
    if ss_tot == 0.0:
        return 1.0 if ss_res == 0.0 else -np.inf
    return 1.0 - ss_res / ss_tot


def rmse_v(measured_time_s: npt.ArrayLike, measured_v: npt.ArrayLike, predicted_time_s: npt.ArrayLike,
           predicted_v: npt.ArrayLike) -> float:
    """Root-mean-square voltage error in V over the overlap of both signals (no padding)."""
    t = np.asarray(measured_time_s, dtype=float)
    u = np.asarray(measured_v, dtype=float)
    tp = np.asarray(predicted_time_s, dtype=float)
    up = np.asarray(predicted_v, dtype=float)
    if tp.size == 0:
        return float("inf")
    mask = (t >= tp[0]) & (t <= tp[-1])
    if not mask.any():
        return float("inf")
    return float(np.sqrt(np.mean((u[mask] - np.interp(t[mask], tp, up)) ** 2)))
