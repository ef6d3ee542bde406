"""Export load profiles for the EA PSB 10060-120 bidirectional bench supply.

The paper (section 4) emulates the load profiles with EA Elektro-Automatik
PSB 10060-120 units (0-60 V, 0-120 A, up to 3000 W) whose arbitrary
function generator holds **at most 99 curve (sequence) points**, each with a
set value and a time of 0.1 ms to 36 000 s (10 h). A longer profile is
split into several consecutive sequences, loaded and run one after the
other. In sink mode, the voltage set value acts as the discharge limit: the
unit stops drawing current when the battery falls to it.

One CSV file is written per sequence, with the columns
``point,voltage_limit_v,current_a,duration_s``, numbered from 1.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from battery_predictor.errors import ProfileError
from battery_predictor.profiles.load_profile import LoadProfile

#: Curve points per sequence of the PSB 10000 arbitrary generator.
MAX_SEQUENCE_POINTS = 99
#: Rated limits of the PSB 10060-120.
MAX_VOLTAGE_V = 60.0
MAX_CURRENT_A = 120.0
#: Allowed time of one sequence point, s.
MIN_POINT_DURATION_S = 1e-4
MAX_POINT_DURATION_S = 36_000.0
#: Column names of the exported CSV files.
PSU_CSV_COLUMNS = ("point", "voltage_limit_v", "current_a", "duration_s")


@dataclass(frozen=True, eq=False)
class PsuSequence:
    """One sequence of at most 99 curve points for the bench supply.

    Attributes
    ----------
    index : int
        Position of the sequence in the run, from 0.
    voltage_limit_v : numpy.ndarray
        Voltage set value (discharge limit) per point in V.
    current_a : numpy.ndarray
        Sink current per point in A (>= 0, discharge).
    duration_s : numpy.ndarray
        Time per point in s.
    """

    index: int
    voltage_limit_v: np.ndarray
    current_a: np.ndarray
    duration_s: np.ndarray

    def __len__(self) -> int:
        return len(self.duration_s)

    @property
    def total_duration_s(self) -> float:
        """Duration of the sequence in s."""
        return float(np.sum(self.duration_s))


def psu_sequences(
    profile: LoadProfile,
    voltage_limit_v: float | None = None,
    *,
    max_points: int = MAX_SEQUENCE_POINTS,
    max_point_duration_s: float = MAX_POINT_DURATION_S,
) -> list[PsuSequence]:
    """Split ``profile`` into supply sequences of at most ``max_points`` points.

    Parameters
    ----------
    profile : LoadProfile
        Profile to export; all currents must be >= 0 (discharge only).
    voltage_limit_v : float, optional
        Discharge limit in V for every point; defaults to the profile's
        ``metadata["stop_voltage_v"]``.
    max_points : int
        Points per sequence (99 for the PSB 10060-120).
    max_point_duration_s : float
        Longest time of one point; longer curve points are split into equal
        parts first (36 000 s for the PSB 10060-120).

    Returns
    -------
    list of PsuSequence
        Consecutive sequences; all but the last have exactly ``max_points``
        points (250 points -> 99 + 99 + 52).

    Raises
    ------
    ProfileError
        If no voltage limit is known, a value exceeds the supply's ratings,
        a current is negative or a point is shorter than 0.1 ms.
    """
    if voltage_limit_v is None:
        voltage_limit_v = profile.metadata.get("stop_voltage_v")
        if voltage_limit_v is None:
            raise ProfileError("PSU export: no voltage_limit_v given and the profile has no stop_voltage_v metadata")
    voltage_limit_v = float(voltage_limit_v)
    if not (math.isfinite(voltage_limit_v) and 0.0 < voltage_limit_v <= MAX_VOLTAGE_V):
        raise ProfileError(f"PSU export: voltage_limit_v is {voltage_limit_v} V (must be in (0, {MAX_VOLTAGE_V:g}] V)")
    if isinstance(max_points, bool) or not isinstance(max_points, int) or max_points < 1:
        raise ProfileError(f"PSU export: max_points is {max_points!r} (must be an integer >= 1)")
    current = profile.current_a
    if np.any(current < 0.0):
        i = int(np.flatnonzero(current < 0.0)[0])
        raise ProfileError(f"PSU export: point {i} charges at {current[i]} A; only discharge (>= 0 A) can be exported")
    if np.any(current > MAX_CURRENT_A):
        i = int(np.flatnonzero(current > MAX_CURRENT_A)[0])
        raise ProfileError(f"PSU export: point {i} needs {current[i]} A, above the supply's {MAX_CURRENT_A:g} A")
    if np.any(profile.duration_s < MIN_POINT_DURATION_S):
        i = int(np.flatnonzero(profile.duration_s < MIN_POINT_DURATION_S)[0])
        raise ProfileError(f"PSU export: point {i} lasts {profile.duration_s[i]} s, below the supply's 0.1 ms")
    parts = np.maximum(1, np.ceil(profile.duration_s / max_point_duration_s)).astype(int)
    durations = np.repeat(profile.duration_s / parts, parts)
    currents = np.repeat(current, parts)
    sequences = []
    for index, first in enumerate(range(0, len(durations), max_points)):
        chunk = slice(first, first + max_points)
        n = len(durations[chunk])
        sequences.append(PsuSequence(index, np.full(n, voltage_limit_v), currents[chunk].copy(), durations[chunk].copy()))
    return sequences


def write_psu_csv(
    profile: LoadProfile,
    out_dir: str | Path,
    voltage_limit_v: float | None = None,
    *,
    stem: str = "sequence",
    max_points: int = MAX_SEQUENCE_POINTS,
) -> list[Path]:
    """Write one CSV per supply sequence into ``out_dir``.

    Files are named ``<stem>_001.csv``, ``<stem>_002.csv``... in run order,
    with columns ``point,voltage_limit_v,current_a,duration_s`` (point numbered
    from 1 within each sequence). Durations are written to the supply's
    0.1 ms resolution, voltages and currents to 1 mV / 1 mA.

    Returns
    -------
    list of pathlib.Path
        The files written, in run order.
    """
    sequences = psu_sequences(profile, voltage_limit_v, max_points=max_points)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for sequence in sequences:
        path = out_dir / f"{stem}_{sequence.index + 1:03d}.csv"
        with path.open("w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle)
            writer.writerow(PSU_CSV_COLUMNS)
            for point, (voltage, current, duration) in enumerate(
                zip(sequence.voltage_limit_v, sequence.current_a, sequence.duration_s), start=1
            ):
                writer.writerow((point, f"{voltage:.3f}", f"{current:.3f}", f"{duration:.4f}"))
        paths.append(path)
    return paths
