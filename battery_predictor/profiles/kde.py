"""Gaussian kernel density estimates restricted to the range of their samples.

Sections 5.1.1, 5.1.3 and 5.2.1 of the seed paper describe currents and
durations by a Gaussian KDE (``scipy.stats.gaussian_kde``) over measured
samples. A KDE has unbounded Gaussian tails, which would occasionally propose
a negative duration or a current nobody measured. :class:`BoundedKde` keeps
draws inside ``[lower, upper]`` (by default the smallest and largest sample)
in one of two ways:

``"truncate"``
    out-of-range draws are rejected and drawn again: the KDE shape is kept
    inside the range and no value is drawn at a bound with positive
    probability (used for currents);
``"clip"``
    out-of-range draws are set to the nearest bound (:func:`numpy.clip`):
    the mean stays closer to the sample mean, at the price of probability
    atoms at the bounds (used for the Temi interaction durations, which the
    seed paper quotes as "ranging from 19 s to approximately 16 min").

Mean and standard deviation of the bounded distribution are computed
exactly (Gaussian mixture moments), for tests and for the predictor.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import special, stats

from battery_predictor.errors import ProfileError


def _norm_pdf(z: np.ndarray) -> np.ndarray:
    return np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)


def _norm_cdf(z: np.ndarray) -> np.ndarray:
    return special.ndtr(z)


class BoundedKde:
    """One-dimensional Gaussian KDE restricted to ``[lower, upper]``.

    Parameters
    ----------
    samples : sequence of float
        Measured values (any unit; the caller's name says which). At least two
        distinct finite values.
    lower, upper : float, optional
        Truncation bounds in the unit of ``samples``; default to the smallest
        and largest sample.
    name : str
        Used in error messages.
    mode : {"truncate", "clip"}
        How draws outside the bounds are handled (see the module docstring).
    bw_method : str, float or None
        Passed to :class:`scipy.stats.gaussian_kde` (default: Scott's rule).

    Attributes
    ----------
    mean, std : float
        Exact mean and standard deviation of the bounded distribution.

    Raises
    ------
    ProfileError
        If the samples are not finite, fewer than two distinct values, or
        ``lower >= upper``, or ``mode`` is unknown.
    """

    def __init__(
        self,
        samples: Sequence[float] | np.ndarray,
        *,
        lower: float | None = None,
        upper: float | None = None,
        name: str = "kde",
        mode: str = "truncate",
        bw_method: str | float | None = None,
    ) -> None:
        values = np.asarray(samples, dtype=float).ravel()
        if values.size < 2 or not np.all(np.isfinite(values)) or np.unique(values).size < 2:
            raise ProfileError(f"{name}: a KDE needs at least two distinct finite samples, got {values.tolist()}")
        if mode not in ("truncate", "clip"):
            raise ProfileError(f"{name}: unknown bounds mode {mode!r} (expected 'truncate' or 'clip')")
        self.name = name
        self.mode = mode
        self.samples = values
        self.lower = float(values.min() if lower is None else lower)
        self.upper = float(values.max() if upper is None else upper)
        if not self.lower < self.upper:
            raise ProfileError(f"{name}: truncation range [{self.lower}, {self.upper}] is empty")
        self.kde = stats.gaussian_kde(values, bw_method=bw_method)
        self.bandwidth = float(np.sqrt(self.kde.covariance[0, 0]))
        alpha = (self.lower - values) / self.bandwidth
        beta = (self.upper - values) / self.bandwidth
        mass = _norm_cdf(beta) - _norm_cdf(alpha)
        self.acceptance = float(np.mean(mass))
        if self.acceptance < 1e-6:
            raise ProfileError(f"{name}: almost no KDE mass inside [{self.lower}, {self.upper}]")
        # Exact partial moments of each Gaussian kernel over [lower, upper].
        z_mean = _norm_pdf(alpha) - _norm_pdf(beta)
        z_sq = mass + alpha * _norm_pdf(alpha) - beta * _norm_pdf(beta)
        first = values * mass + self.bandwidth * z_mean
        second = values**2 * mass + 2.0 * values * self.bandwidth * z_mean + self.bandwidth**2 * z_sq
        if mode == "truncate":
            total, first_total, second_total = np.sum(mass), np.sum(first), np.sum(second)
        else:  # clip: the tails sit on the bounds
            below, above = _norm_cdf(alpha), 1.0 - _norm_cdf(beta)
            total = float(values.size)
            first_total = np.sum(first + self.lower * below + self.upper * above)
            second_total = np.sum(second + self.lower**2 * below + self.upper**2 * above)
        self.mean = float(first_total / total)
        self.std = float(np.sqrt(max(second_total / total - self.mean**2, 0.0)))

    def sample(self, size: int, rng: np.random.Generator) -> np.ndarray:
        """Draw ``size`` values from the bounded KDE using ``rng``."""
        size = int(size)
        if self.mode == "clip":
            return np.clip(self.kde.resample(size, seed=rng)[0], self.lower, self.upper)
        out = np.empty(size)
        filled = 0
        while filled < size:
            need = size - filled
            batch = int(need / self.acceptance * 1.2) + 8
            draws = self.kde.resample(batch, seed=rng)[0]
            draws = draws[(draws >= self.lower) & (draws <= self.upper)][:need]
            out[filled : filled + draws.size] = draws
            filled += draws.size
        return out

    def __repr__(self) -> str:
        return (
            f"BoundedKde({self.name!r}, n={self.samples.size}, {self.mode} to [{self.lower:g}, {self.upper:g}], "
            f"bandwidth={self.bandwidth:.4g}, mean={self.mean:.4g})"
        )
