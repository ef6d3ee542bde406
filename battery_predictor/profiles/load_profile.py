"""Piecewise-constant load profiles made of curve points.

A curve point is what the EA PSB 10060-120 bench supply calls a sequence
point: a current held constant for a duration. A :class:`LoadProfile` is an
ordered list of such points, each with a label (usage state or route section).
Current is positive while discharging (PyBaMM convention, see
:mod:`battery_predictor.conventions`).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from battery_predictor.errors import ProfileError

#: Column names of the profile CSV format, in order.
CSV_COLUMNS = ("duration_s", "current_a", "label")


def _as_1d_float(values: Any, name: str) -> np.ndarray:
    try:
        arr = np.array(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ProfileError(f"load profile: {name} is not numeric ({exc})") from None
    if arr.ndim != 1:
        raise ProfileError(f"load profile: {name} must be one-dimensional, got shape {arr.shape}")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class LoadProfile:
    """An ordered sequence of constant-current curve points.

    Attributes
    ----------
    duration_s : numpy.ndarray
        Duration of each curve point in s, finite and > 0.
    current_a : numpy.ndarray
        Current of each curve point in A, **positive while discharging**.
    labels : tuple of str
        Usage state or route-section name of each point. ``None`` (the
        default) labels every point ``""``.
    metadata : dict
        Free-form provenance (robot, seed, generator settings,
        ``stop_voltage_v`` for whoever simulates or emulates the profile...).

    Raises
    ------
    ProfileError
        If the profile is empty, the arrays are not one-dimensional, of
        unequal length, not finite, or a duration is not > 0.

    Notes
    -----
    The arrays are stored as read-only float copies, so a profile cannot be
    changed after construction. Equality is identity (``eq=False``); compare
    the arrays with :func:`numpy.testing.assert_array_equal` instead.
    """

    duration_s: np.ndarray
    current_a: np.ndarray
    labels: tuple[str, ...] | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        duration_s = _as_1d_float(self.duration_s, "duration_s")
        current_a = _as_1d_float(self.current_a, "current_a")
        n = len(duration_s)
        if n == 0:
            raise ProfileError("load profile: it has no curve points")
        if len(current_a) != n:
            raise ProfileError(f"load profile: current_a has {len(current_a)} points, duration_s has {n}")
        labels = ("",) * n if self.labels is None else tuple(str(label) for label in self.labels)
        if len(labels) != n:
            raise ProfileError(f"load profile: labels has {len(labels)} entries, duration_s has {n}")
        for name, arr in (("duration_s", duration_s), ("current_a", current_a)):
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise ProfileError(f"load profile: {name}[{bad[0]}] is {arr[bad[0]]} (must be finite)")
        bad = np.flatnonzero(duration_s <= 0.0)
        if bad.size:
            raise ProfileError(f"load profile: duration_s[{bad[0]}] is {duration_s[bad[0]]} s (must be > 0)")
        object.__setattr__(self, "duration_s", duration_s)
        object.__setattr__(self, "current_a", current_a)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "metadata", dict(self.metadata))

    def __len__(self) -> int:
        return len(self.duration_s)

    @property
    def point_labels(self) -> tuple[str, ...]:
        """The label of every curve point (``labels`` as a tuple: never None once constructed)."""
        assert self.labels is not None  # set by __post_init__
        return self.labels

    @property
    def n_points(self) -> int:
        """Number of curve points."""
        return len(self.duration_s)

    @property
    def total_duration_s(self) -> float:
        """Total duration in s."""
        return float(np.sum(self.duration_s))

    @property
    def charge_ah(self) -> float:
        """Net charge drawn over the whole profile in Ah (discharge positive)."""
        return float(np.sum(self.duration_s * self.current_a)) / 3600.0

    @property
    def mean_current_a(self) -> float:
        """Time-weighted mean current in A."""
        return self.charge_ah * 3600.0 / self.total_duration_s

    def times_s(self) -> np.ndarray:
        """Start time of each curve point in s (the first one starts at 0)."""
        return np.concatenate(([0.0], np.cumsum(self.duration_s)[:-1]))

    def end_times_s(self) -> np.ndarray:
        """End time of each curve point in s (the last one is ``total_duration_s``)."""
        return np.cumsum(self.duration_s)

    def as_step_series(self) -> tuple[np.ndarray, np.ndarray]:
        """Describe the piecewise-constant current exactly as a polyline.

        Returns
        -------
        time_s : numpy.ndarray
            ``2 * n_points`` times in s: the start and the end of every curve
            point, ``[t0, t1, t1, t2, t2, ..., tn]``. Each step edge therefore
            appears twice (non-decreasing, not strictly increasing).
        current_a : numpy.ndarray
            ``[i0, i0, i1, i1, ...]`` in A, the current at those times.

        Notes
        -----
        Linear interpolation between consecutive pairs reproduces the step
        shape exactly, so the pair can be fed to a simulator that
        interpolates its drive cycle linearly (e.g. PyBaMM's ``Interpolant``)
        or plotted with ``plot(time_s, current_a)``.
        """
        ends = self.end_times_s()
        starts = ends - self.duration_s
        time_s = np.column_stack((starts, ends)).ravel()
        current_a = np.repeat(self.current_a, 2)
        return time_s, current_a

    def sample(self, period_s: float) -> np.ndarray:
        """Current in force at ``t = 0, period_s, 2 * period_s, ...``.

        Parameters
        ----------
        period_s : float
            Sampling period in s, > 0.

        Returns
        -------
        numpy.ndarray
            Current in A at ``t_k = k * period_s`` for every ``t_k`` strictly
            below ``total_duration_s``. At a step edge the new step is in
            force (curve point ``i`` covers ``[start_i, end_i)``). The sample
            times are ``numpy.arange(len(result)) * period_s``.
        """
        period_s = float(period_s)
        if not np.isfinite(period_s) or period_s <= 0.0:
            raise ProfileError(f"load profile: sampling period_s is {period_s} (must be finite and > 0)")
        ends = self.end_times_s()
        n_samples = int(np.ceil(ends[-1] / period_s))
        t = np.arange(n_samples) * period_s
        t = t[t < ends[-1]]
        index = np.searchsorted(ends, t, side="right")
        return self.current_a[np.minimum(index, len(ends) - 1)]

    def concatenate(self, other: LoadProfile) -> LoadProfile:
        """Return ``self`` followed by ``other`` (metadata of ``self`` is kept)."""
        if not isinstance(other, LoadProfile):
            raise ProfileError(f"load profile: cannot concatenate a {type(other).__name__}")
        return LoadProfile(
            duration_s=np.concatenate((self.duration_s, other.duration_s)),
            current_a=np.concatenate((self.current_a, other.current_a)),
            labels=self.point_labels + other.point_labels,
            metadata=dict(self.metadata),
        )

    def repeat(self, n: int) -> LoadProfile:
        """Return the profile played ``n`` times in a row (``n`` >= 1, metadata kept)."""
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise ProfileError(f"load profile: repeat count is {n!r} (must be an integer >= 1)")
        n = int(n)
        return LoadProfile(
            duration_s=np.tile(self.duration_s, n),
            current_a=np.tile(self.current_a, n),
            labels=self.point_labels * n,
            metadata=dict(self.metadata),
        )

    def to_csv(self, path: str | Path) -> Path:
        """Write the profile as CSV with columns ``duration_s,current_a,label``.

        Numbers are written with :func:`repr`, so :meth:`from_csv` reads back
        exactly the same floats. Metadata is not written.

        Returns
        -------
        pathlib.Path
            The path written.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle)
            writer.writerow(CSV_COLUMNS)
            for duration, current, label in zip(self.duration_s, self.current_a, self.point_labels):
                writer.writerow((repr(float(duration)), repr(float(current)), label))
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> LoadProfile:
        """Read a profile written by :meth:`to_csv`.

        Raises
        ------
        ProfileError
            If the file is missing, the header differs from
            ``duration_s,current_a,label``, or a row is malformed; the message
            names the file and the row.
        """
        path = Path(path)
        try:
            with path.open(newline="", encoding="utf-8") as handle:
                rows = list(csv.reader(handle))
        except OSError as exc:
            raise ProfileError(f"{path}: cannot read load profile ({exc.strerror})") from None
        if not rows or tuple(cell.strip() for cell in rows[0]) != CSV_COLUMNS:
            raise ProfileError(f"{path}: header must be {','.join(CSV_COLUMNS)}")
        durations, currents, labels = [], [], []
        for line_no, row in enumerate(rows[1:], start=2):
            if not row:
                continue
            if len(row) != len(CSV_COLUMNS):
                raise ProfileError(f"{path}: row {line_no} has {len(row)} columns, expected {len(CSV_COLUMNS)}")
            try:
                durations.append(float(row[0]))
                currents.append(float(row[1]))
            except ValueError:
                raise ProfileError(f"{path}: row {line_no} has a non-numeric duration_s or current_a") from None
            labels.append(row[2])
        try:
            return cls(np.array(durations), np.array(currents), tuple(labels), {"source": str(path)})
        except ProfileError as exc:
            raise ProfileError(f"{path}: {exc}") from None

    def label_summary(self) -> dict[str, dict[str, float]]:
        """Points, duration in s and charge in Ah per label, in order of first appearance."""
        summary: dict[str, dict[str, float]] = {}
        for label, duration, current in zip(self.point_labels, self.duration_s, self.current_a):
            entry = summary.setdefault(label, {"points": 0, "duration_s": 0.0, "charge_ah": 0.0})
            entry["points"] += 1
            entry["duration_s"] += float(duration)
            entry["charge_ah"] += float(duration * current) / 3600.0
        return summary


def constant_current_profile(current_a: float, duration_s: float, *, label: str = "constant") -> LoadProfile:
    """One curve point: ``current_a`` (A, discharge positive) for ``duration_s`` (s).

    Used for the static 0.5 C discharges of section 5.1.4 and for the
    standstill check at 1.70 A of section 5.2.4.
    """
    return LoadProfile(np.array([duration_s], dtype=float), np.array([current_a], dtype=float), (label,), {"kind": "constant"})
