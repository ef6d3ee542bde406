"""Piecewise-constant pack current loads, the input of every pack simulation."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import ProfileError

if TYPE_CHECKING:
    from battery_predictor.profiles.load_profile import LoadProfile


@dataclass(frozen=True)
class StepLoad:
    """A pack current that is constant between step edges.

    The current ``current_a[k]`` (A, positive = discharge) holds from
    ``start_s[k]`` to ``start_s[k + 1]`` (or ``end_s`` for the last step).

    Attributes
    ----------
    start_s : numpy.ndarray
        Step start times in s, strictly increasing, ``start_s[0] == 0``.
    current_a : numpy.ndarray
        Pack current of each step in A (positive = discharge).
    end_s : float
        End of the last step in s.
    """

    start_s: np.ndarray
    current_a: np.ndarray
    end_s: float

    def __post_init__(self) -> None:
        start = np.asarray(self.start_s, dtype=float)
        cur = np.asarray(self.current_a, dtype=float)
        object.__setattr__(self, "start_s", start)
        object.__setattr__(self, "current_a", cur)
        if start.ndim != 1 or start.shape != cur.shape or start.size == 0:
            raise ProfileError(f"load: start_s and current_a must be 1-D of equal non-zero length, got "
                               f"{start.shape} and {cur.shape}")
        if not (np.all(np.isfinite(start)) and np.all(np.isfinite(cur)) and np.isfinite(self.end_s)):
            raise ProfileError("load: times and currents must be finite")
        if abs(start[0]) > 1e-9:
            raise ProfileError(f"load: first step must start at 0 s, got {start[0]}")
        if np.any(np.diff(start) <= 0) or self.end_s <= start[-1]:
            raise ProfileError("load: step start times must increase strictly and end after the last start")

    # ------------------------------------------------------------ constructors
    @classmethod
    def constant(cls, current_a: float, duration_s: float) -> StepLoad:
        """A constant current (A) for ``duration_s`` seconds."""
        return cls(np.array([0.0]), np.array([float(current_a)]), float(duration_s))

    @classmethod
    def from_durations(cls, duration_s: npt.ArrayLike, current_a: npt.ArrayLike) -> StepLoad:
        """From curve points: durations (s) and currents (A)."""
        d = np.asarray(duration_s, dtype=float)
        if d.size == 0 or np.any(~np.isfinite(d)) or np.any(d <= 0):
            raise ProfileError("load: curve-point durations must be finite and > 0")
        edges = np.concatenate([[0.0], np.cumsum(d)])
        return cls(edges[:-1], np.asarray(current_a, dtype=float), float(edges[-1]))

    @classmethod
    def from_samples(cls, time_s: npt.ArrayLike, current_a: npt.ArrayLike) -> StepLoad:
        """From measured samples: the current at ``time_s[i]`` holds until ``time_s[i + 1]``.

        The last sample holds for the median sample interval.
        """
        t = np.asarray(time_s, dtype=float)
        if t.size < 2:
            raise ProfileError("load: at least two samples are needed")
        t = t - t[0]
        dt = float(np.median(np.diff(t)))
        return cls(t, np.asarray(current_a, dtype=float), float(t[-1] + dt))

    @classmethod
    def from_profile(cls, profile: LoadProfile) -> StepLoad:
        """From a :class:`battery_predictor.profiles.load_profile.LoadProfile` (curve points)."""
        return cls.from_durations(profile.duration_s, profile.current_a)

    # ---------------------------------------------------------------- queries
    @property
    def duration_s(self) -> float:
        """Total duration in s."""
        return float(self.end_s)

    def edges_s(self) -> np.ndarray:
        """All step edges including the end, in s."""
        return np.append(self.start_s, self.end_s)

    def current_at(self, time_s: npt.ArrayLike) -> np.ndarray:
        """Current (A) in force at ``time_s`` (right-continuous)."""
        idx = np.searchsorted(self.start_s, np.asarray(time_s, dtype=float), side="right") - 1
        return self.current_a[np.clip(idx, 0, len(self.current_a) - 1)]

    def charge_ah(self) -> float:
        """Charge drawn over the whole load in Ah."""
        return float(np.sum(np.diff(self.edges_s()) * self.current_a) / 3600.0)

    def mean_current_a(self, last_s: float | None = None) -> float:
        """Time-averaged current in A, over the whole load or over its last ``last_s`` seconds."""
        if last_s is None or last_s >= self.duration_s:
            return self.charge_ah() * 3600.0 / self.duration_s
        if last_s <= 0:
            raise ProfileError(f"load: averaging window must be > 0 s, got {last_s}")
        before, total = self.cumulative_charge_as([self.end_s - last_s, self.end_s])
        return float(total - before) / last_s

    def resample(self, period_s: float) -> StepLoad:
        """Charge-conserving resampling onto a uniform grid of ``period_s`` seconds.

        Each new step carries the mean current over its period, so the charge
        drawn is unchanged (needed by liionpack, which steps at a fixed period).
        """
        if period_s <= 0:
            raise ProfileError(f"load: period must be > 0 s, got {period_s}")
        n = int(np.ceil(self.end_s / period_s - 1e-9))
        grid = np.arange(n + 1) * period_s
        grid[-1] = max(grid[-1], self.end_s)
        cum = self.cumulative_charge_as(np.minimum(grid, self.end_s))
        cur = np.diff(cum) / np.diff(grid)
        # a last period reaching past end_s carries the remaining charge spread over the period
        return StepLoad(grid[:-1], cur, float(grid[-1]))

    def cumulative_charge_as(self, time_s: npt.ArrayLike) -> np.ndarray:
        """Charge drawn from 0 to ``time_s`` in A·s (the last current continues past ``end_s``)."""
        t = np.asarray(time_s, dtype=float)
        edges = self.edges_s()
        cum_edges = np.concatenate([[0.0], np.cumsum(np.diff(edges) * self.current_a)])
        idx = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(self.current_a) - 1)
        return cum_edges[idx] + (t - edges[idx]) * self.current_a[idx]

    def truncate(self, end_s: float) -> StepLoad:
        """The load up to ``end_s`` seconds."""
        end_s = min(float(end_s), self.end_s)
        keep = self.start_s < end_s
        return StepLoad(self.start_s[keep], self.current_a[keep], end_s)

    def shift_current(self, offset_a: float) -> StepLoad:
        """The same load with ``offset_a`` added to every step (sensor bias)."""
        return StepLoad(self.start_s, self.current_a + float(offset_a), self.end_s)

    def scale_current(self, factor: float) -> StepLoad:
        """The same load with every current multiplied by ``factor``."""
        return StepLoad(self.start_s, self.current_a * float(factor), self.end_s)

    def append(self, other: StepLoad) -> StepLoad:
        """This load followed by ``other``."""
        return StepLoad(
            np.concatenate([self.start_s, other.start_s + self.end_s]),
            np.concatenate([self.current_a, other.current_a]),
            self.end_s + other.end_s,
        )

    def digest(self) -> str:
        """A short hash identifying the load (for caches)."""
        h = hashlib.sha1()
        h.update(self.start_s.tobytes())
        h.update(self.current_a.tobytes())
        h.update(np.float64(self.end_s).tobytes())
        return h.hexdigest()[:16]
