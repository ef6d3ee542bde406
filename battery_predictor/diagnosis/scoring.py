"""Fit residuals and held-out scores of a simulated recording (R2_mod alignment of the seed paper)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from battery_predictor.diagnosis.engine import Observed, SimOut


def padded_prediction(t_grid: np.ndarray, sim: SimOut, pad_v: float) -> np.ndarray:
    """The simulated pack voltage on ``t_grid``, ``pad_v`` after the simulation ended (cut-off)."""
    if sim.t.size == 0:
        return np.full(t_grid.size, pad_v)
    pred = np.interp(t_grid, sim.t, sim.v_pack)
    pred[t_grid > sim.t[-1] + 1e-6] = pad_v
    return pred


def fit_residual(obs: Observed, sim: SimOut) -> np.ndarray:
    """Residual (V) on the fit part, weighted 1/sqrt(n) so every recording counts the same.

    The prediction is padded with the fit part's minimum voltage where the model ended early
    (reached its cut-off), so that stopping early is not rewarded. The truncation of Eq. (1)
    is not applied here: it makes the objective discontinuous; held-out scores use it.
    """
    m = obs.fit_mask
    t, v = obs.t[m], obs.v[m]
    pred = padded_prediction(t, sim, float(v.min()))
    return (pred - v) / math.sqrt(max(t.size, 1))


@dataclass(frozen=True)
class HeldOut:
    """Held-out score of one recording.

    Attributes
    ----------
    sq_err_sum : float
        Sum of squared errors (V^2) on the aligned held-out grid.
    n : int
        Samples of that grid.
    r2_mod : float
        R2_mod (Eq. 3) of the held-out part.
    runtime_error_s : float or None
        Simulated minus measured time to first reach the recording's final voltage (recordings
        that end at their cut-off), else None.
    """

    sq_err_sum: float
    n: int
    r2_mod: float
    runtime_error_s: float | None

    @property
    def rmse_v(self) -> float:
        return math.sqrt(self.sq_err_sum / self.n) if self.n else float("nan")


def first_time_below(t: np.ndarray, v: np.ndarray, threshold: float) -> float | None:
    """First time (s, linear interpolation) at which ``v <= threshold``, or None."""
    below = np.nonzero(v <= threshold)[0]
    if below.size == 0:
        return None
    i = int(below[0])
    if i == 0:
        return float(t[0])
    v0, v1 = v[i - 1], v[i]
    frac = (v0 - threshold) / (v0 - v1) if v0 != v1 else 1.0
    return float(t[i - 1] + frac * (t[i] - t[i - 1]))


def held_out_score(obs: Observed, sim: SimOut, until_s: float = math.inf) -> HeldOut:
    """Score the held-out part (``t > t_split``); the squared errors only before ``until_s`` (s).

    RMSE: the prediction is padded with the held-out minimum voltage after it ended (a model that
    stops early is not rewarded) and, when it runs past the recording, the measurement is extended
    with that minimum until the prediction falls below it (a model that would run longer is
    penalised), as in R2_mod's Eq. (1)-(2). Unlike Eq. (1), a prediction that dips below the
    measured minimum on a current spike *before* the recording's end is not cut there: under a
    dynamic load such a dip says nothing about the end of the discharge, and cutting it would
    score an otherwise exact prediction as if it had stopped. R2_mod is the seed paper's, as defined.
    ``until_s`` restricts ``sq_err_sum`` and ``n`` to the aligned samples before that time (the part of
    the day the references cover, :mod:`battery_predictor.diagnosis.coverage`); R2_mod and the runtime
    error are those of the whole held-out part.
    """
    from battery_predictor.fitting.cost import r2_mod

    m = obs.held_mask
    t_h, v_h = obs.t[m], obs.v[m]
    keep = sim.t > obs.t_split
    tp, vp = sim.t[keep], sim.v_pack[keep]
    u_min = float(v_h.min())
    if tp.size and tp[-1] > t_h[-1] + 1e-9:  # late: count until the prediction reaches the minimum
        below = np.nonzero((tp > t_h[-1] + 1e-9) & (vp < u_min))[0]
        if below.size:
            tp, vp = tp[: below[0]], vp[: below[0]]
    grid, meas = t_h, v_h
    if tp.size and tp[-1] > t_h[-1] + 1e-9:
        dt = float(np.median(np.diff(t_h))) if t_h.size > 1 else 1.0
        extra = np.arange(t_h[-1] + dt, tp[-1] + 0.5 * dt, dt)
        grid = np.concatenate([t_h, extra])
        meas = np.concatenate([v_h, np.full(extra.size, u_min)])
    if tp.size:
        pred = np.interp(grid, tp, vp)
        pred[grid > tp[-1] + 1e-6] = u_min
    else:
        pred = np.full(grid.size, u_min)
    err = (meas - pred)[grid < until_s]
    ss_res = float(err @ err)
    r2 = r2_mod(t_h, v_h, sim.t[keep], sim.v_pack[keep]) if t_h.size else float("nan")
    runtime = None
    if obs.ends_at_cutoff:
        v_final = float(obs.v[-1])
        t_meas = first_time_below(obs.t, obs.v, v_final)
        t_sim = first_time_below(sim.t, sim.v_pack, v_final)
        if t_sim is None and sim.reached_cutoff:
            t_sim = sim.end_time_s
        if t_sim is not None and t_meas is not None:
            runtime = t_sim - t_meas
    return HeldOut(sq_err_sum=ss_res, n=int(err.size), r2_mod=r2, runtime_error_s=runtime)


class Pooled(TypedDict):
    """Held-out scores pooled over recordings (:func:`pooled`)."""

    heldout_rmse_mV: float
    heldout_r2_mod: float
    runtime_error_s: float | None


def pooled(scores: list[HeldOut]) -> Pooled:
    """Pool recordings: RMSE (mV) over all held-out samples, mean R2_mod, mean runtime error (s)."""
    n = sum(s.n for s in scores)
    rmse = math.sqrt(sum(s.sq_err_sum for s in scores) / n) if n else float("nan")
    runtimes = [s.runtime_error_s for s in scores if s.runtime_error_s is not None]
    return {"heldout_rmse_mV": 1e3 * rmse,
            "heldout_r2_mod": float(np.mean([s.r2_mod for s in scores])),
            "runtime_error_s": float(np.mean(runtimes)) if runtimes else None}


def current_resolution_a(obs_list: Sequence[Observed]) -> float:
    """The smallest step of the measured current between samples (A): the current reading's quantum.

    A reading quantised to ``q`` is biased by up to ``q / 2`` wherever the current stays between two
    levels, so a current offset within that is not resolved by the data. Continuous readings give a
    negligible step; 0.0 when the current never changes.
    """
    steps = [s for obs in obs_list if (s := _smallest_step(obs.i)) is not None]
    return min(steps) if steps else 0.0


def _smallest_step(values: np.ndarray) -> float | None:
    """The smallest non-zero change between consecutive samples of ``values`` (None when they never change)."""
    d = np.abs(np.diff(np.asarray(values, dtype=float)))
    nz = d[d > 1e-9]
    return float(np.min(nz)) if nz.size else None


def noise_level_v(obs_list: list[Observed]) -> float:
    """Measurement noise of the voltage (V): robust spread of second differences at constant current.

    Second differences ``v[k+1] - 2 v[k] + v[k-1]`` over three samples of the same current remove
    the slow drift of the state of charge; their standard deviation without outliers (/ sqrt(6)) is
    the noise. At least the quantisation noise of the recorded resolution (step / sqrt(12)).
    """
    d2s, steps = [], []
    for obs in obs_list:
        v, i = obs.v, obs.i
        tol = 1e-3 * max(float(np.max(np.abs(i))), 1e-9)
        same = (np.abs(i[1:-1] - i[:-2]) <= tol) & (np.abs(i[2:] - i[1:-1]) <= tol)
        d2 = (v[2:] - 2.0 * v[1:-1] + v[:-2])[same]
        if d2.size > 10:
            d2s.append(d2)
        step = _smallest_step(v)
        if step is not None:
            steps.append(step)
    sigma = 0.0
    if d2s:
        d = np.concatenate(d2s)
        for _ in range(3):  # standard deviation without the outliers (steps, spikes); the MAD of
            spread = float(np.std(d))  # voltages rounded to 10 mV is itself quantised
            d = d[np.abs(d - np.mean(d)) <= 4.0 * spread] if spread > 0 else d
        sigma = float(np.std(d)) / math.sqrt(6.0)
    quant = (min(steps) / math.sqrt(12.0)) if steps else 0.0
    return max(sigma, quant)
