"""Which fitted quantities the data determine: a Jacobian (Fisher information) analysis at an optimum.

With residuals ``r`` and their Jacobian ``J`` with respect to parameters ``theta`` (the logarithm
of log-scaled coordinates, the value itself otherwise), the Gauss-Newton covariance is
``s^2 (J^T J)^-1`` with ``s^2 = |r|^2 / (m - n)``. The residuals at an optimum include the model's
structural error, so the intervals describe how far a parameter can move before the fit gets
noticeably worse, not a measurement-noise confidence in the strict sense.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Correlations above this (in absolute value) are reported as compensating pairs.
CORRELATION_THRESHOLD = 0.95
#: An eigen-direction of the Fisher matrix in normalised units (ln for log parameters, the search
#: range for the others) is undetermined when its 95 % half-interval exceeds this: a factor e, or
#: the whole search range. (A ratio of eigenvalues is not used: it compares coordinates of
#: different units, and a well-measured resistance looked undetermined beside a capacity.)
UNDETERMINED_HALF_WIDTH = 1.0
#: A parameter is "determined" when its 95 % half-interval is below this (relative for log
#: parameters, fraction of the search range otherwise).
DETERMINED_HALF_WIDTH = 0.1
_Z95 = 1.959963984540054


@dataclass(frozen=True)
class IdentifiabilityReport:
    """Result of :func:`analyse`.

    Attributes
    ----------
    names : list of str
        Parameter names.
    values : list of float
        Values at the optimum.
    ci95_low, ci95_high : list of float
        Approximate 95 % intervals (inf when undetermined).
    determined : list of bool
        Whether the data pin each parameter (see :data:`DETERMINED_HALF_WIDTH`).
    correlated_pairs : list of tuple
        ``(name_a, name_b, correlation)`` with ``|correlation| > CORRELATION_THRESHOLD``.
    eigen_directions : list of dict
        Eigenvalue and normalised components of ``J^T J`` (weakest first), with a flag for
        undetermined directions.
    sigma : float
        Residual scale ``s``.
    """

    names: list[str]
    values: list[float]
    ci95_low: list[float]
    ci95_high: list[float]
    determined: list[bool]
    correlated_pairs: list[tuple[str, str, float]]
    eigen_directions: list[dict]
    sigma: float

    def to_dict(self) -> dict:
        """JSON-ready dict."""
        return {
            "parameters": [
                {"name": n, "value": v, "ci95": [lo, hi], "determined": d}
                for n, v, lo, hi, d in zip(self.names, self.values, self.ci95_low, self.ci95_high, self.determined,
                                           strict=True)
            ],
            "correlated_pairs": [{"a": a, "b": b, "correlation": c} for a, b, c in self.correlated_pairs],
            "eigen_directions": self.eigen_directions,
            "residual_scale": self.sigma,
        }

    def relative_half_widths(self) -> list[float]:
        """Each parameter's 95 % half-interval relative to its value (inf when undetermined or at 0)."""
        out = []
        for v, lo, hi in zip(self.values, self.ci95_low, self.ci95_high, strict=True):
            half = 0.5 * (hi - lo)
            out.append(abs(half / v) if v != 0 and math.isfinite(half) else math.inf)
        return out

    def plot_rows(self) -> tuple[list[tuple[str, float, bool]], list[tuple[str, str, float]]]:
        """``(rows, pairs)`` for :func:`battery_predictor.plots.plot_voltage_fit`'s identifiability panel."""
        rows = list(zip(self.names, self.relative_half_widths(), self.determined, strict=True))
        return rows, list(self.correlated_pairs)

    def summary_lines(self) -> list[str]:
        """Console summary (one line per parameter, then pairs and weak directions)."""
        lines = ["identifiability (Jacobian at the optimum, approximate 95 % intervals):"]
        for n, v, lo, hi, d in zip(self.names, self.values, self.ci95_low, self.ci95_high, self.determined,
                                   strict=True):
            tag = "determined" if d else "NOT determined"
            lines.append(f"  {n:<34} {v:>12.5g}  [{lo:.4g}, {hi:.4g}]  {tag}")
        for a, b, c in self.correlated_pairs:
            lines.append(f"  compensate: {a} ~ {b} (correlation {c:+.3f})")
        for e in self.eigen_directions:
            if e["undetermined"]:
                comps = ", ".join(f"{k} {w:+.2f}" for k, w in e["components"].items() if abs(w) >= 0.2)
                lines.append(f"  undetermined direction: {comps}")
        return lines


def analyse(names: Sequence[str], values: Sequence[float], log_scale: Sequence[bool], residuals: np.ndarray,
            jacobian_theta: np.ndarray, ranges: Sequence[tuple[float, float]]) -> IdentifiabilityReport:
    """Identifiability from residuals and their Jacobian with respect to ``theta``.

    Parameters
    ----------
    names, values : sequence
        Parameter names and values at the optimum.
    log_scale : sequence of bool
        True where ``theta = ln(value)`` (intervals are then relative).
    residuals : numpy.ndarray
        Residual vector (length ``m``) at the optimum.
    jacobian_theta : numpy.ndarray
        ``m x n`` Jacobian with respect to ``theta``.
    ranges : sequence of (float, float)
        Search bounds of each parameter (scale for "determined" of linear parameters).
    """
    jac = np.asarray(jacobian_theta, dtype=float)
    m, n = jac.shape
    sigma2 = float(residuals @ residuals) / max(m - n, 1)
    fisher = jac.T @ jac
    cov = sigma2 * np.linalg.pinv(fisher, rcond=1e-12)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    unit = np.array([1.0 if log_scale[i] else float(ranges[i][1] - ranges[i][0]) for i in range(n)])
    eigval, eigvec = np.linalg.eigh(fisher * np.outer(unit, unit))
    half_dir = _Z95 * np.sqrt(sigma2 / np.maximum(eigval, 1e-300))
    undetermined_dir = half_dir > UNDETERMINED_HALF_WIDTH
    lows, highs, determined = [], [], []
    for i in range(n):
        weak = bool(np.any(undetermined_dir & (np.abs(eigvec[i, :]) > 0.3)))
        half = _Z95 * sd[i]
        if log_scale[i]:  # a half-width beyond e^700 is no bound at all (and overflows exp)
            lo, hi = (values[i] * math.exp(-half), values[i] * math.exp(half)) if half < 700.0 else (0.0, math.inf)
            pinned = half < DETERMINED_HALF_WIDTH
        else:
            lo, hi = values[i] - half, values[i] + half
            pinned = half < DETERMINED_HALF_WIDTH * (ranges[i][1] - ranges[i][0])
        if weak:
            lo, hi = -math.inf, math.inf
        lows.append(float(lo))
        highs.append(float(hi))
        determined.append(bool(pinned and not weak))
    corr = _correlation(cov)
    pairs = [(names[i], names[j], float(corr[i, j])) for i in range(n) for j in range(i + 1, n)
             if abs(corr[i, j]) > CORRELATION_THRESHOLD]
    directions = [{"eigenvalue": float(eigval[k]),
                   "components": {names[i]: float(eigvec[i, k]) for i in range(n)},
                   "undetermined": bool(undetermined_dir[k])} for k in range(n)]
    return IdentifiabilityReport(list(names), [float(v) for v in values], lows, highs, determined, pairs,
                                 directions, math.sqrt(sigma2))


def _correlation(cov: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(d, d)
    return np.nan_to_num(corr, nan=0.0)


def theta_jacobian(jacobian_unit: np.ndarray, spans: Sequence[float]) -> np.ndarray:
    """Jacobian with respect to ``theta`` from one on the unit cube.

    ``spans[i]`` is ``d theta_i / d unit_i``: ``ln(high / low)`` for log coordinates, ``high - low``
    otherwise.
    """
    return np.asarray(jacobian_unit, dtype=float) / np.asarray(spans, dtype=float)[None, :]


__all__ = ["IdentifiabilityReport", "analyse", "theta_jacobian", "CORRELATION_THRESHOLD"]
