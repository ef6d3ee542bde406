"""Window averages of a recording, as the battery monitor makes them (``--resample SECONDS``)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from battery_predictor.errors import InputDataError
from battery_predictor.monitor.core import MonitorConfig
from battery_predictor.recording import AS_MEASURED_STEP_RESISTANCE_KEY, Recording, as_measured_steps

#: The battery monitor's default averaging window (s): what the predictor nodes are fed.
MONITOR_WINDOW_S: float = MonitorConfig.window_s


def _hold_durations_s(time_s: np.ndarray) -> np.ndarray:
    """How long each sample holds (s): until the next sample; the last one for the median interval."""
    dt = np.diff(time_s)
    return np.append(dt, np.median(dt) if dt.size else 1.0)


def resample_windows(rec: Recording, window_s: float) -> Recording:
    """Average a recording over consecutive windows of ``window_s`` seconds.

    The first sample is kept unchanged (it carries the state before the load); the windows
    ``(t0 + k w, t0 + (k + 1) w]`` follow it. Current and temperature are
    averaged weighted by each sample's hold time (so the charge drawn is kept, with the current of
    a sample held until the next one, as :meth:`StepLoad.from_samples` reads it); voltage and each
    series group's voltage are the plain mean of the window's samples (a group's over its measured
    samples: NaN only when the group has none in the window). Each window is stamped at its first sample's time, so a
    window's mean current holds until the next window. Windows without samples are dropped. The current
    steps of the samples as measured are kept in the metadata
    (:data:`~battery_predictor.recording.AS_MEASURED_STEP_RESISTANCE_KEY`, read by
    :func:`~battery_predictor.recording.step_resistance_ohm`).

    Parameters
    ----------
    rec : Recording
        Samples at any (irregular) spacing.
    window_s : float
        Window length in s (> 0). Windows shorter than the sampling leave the data unchanged.

    Returns
    -------
    Recording
        One sample per non-empty window, same source and metadata.

    Raises
    ------
    InputDataError
        When ``window_s`` is not a positive finite number.
    """
    if not (np.isfinite(window_s) and window_s > 0):
        raise InputDataError(f"{rec.source}: --resample must be a positive number of seconds, got {window_s}")
    t = np.asarray(rec.time_s, dtype=float)
    if t.size < 2:
        return rec
    hold_s = _hold_durations_s(t)
    index = np.ceil((t - t[0]) / window_s).astype(np.int64)
    starts = np.flatnonzero(np.diff(index, prepend=-1))
    counts = np.diff(np.append(starts, t.size))
    weight_s = np.add.reduceat(hold_s, starts)

    def weighted_mean(values: np.ndarray) -> np.ndarray:
        return np.add.reduceat(values * hold_s, starts) / weight_s

    temperature_k = None
    if rec.temperature_k is not None:
        temperature_k = weighted_mean(np.asarray(rec.temperature_k, dtype=float))
    group_v = None
    if rec.group_voltage_v is not None:
        g = np.asarray(rec.group_voltage_v, dtype=float)
        measured = np.isfinite(g)
        n_measured = np.add.reduceat(measured.astype(float), starts, axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            group_v = np.add.reduceat(np.where(measured, g, 0.0), starts, axis=0) / n_measured
        group_v[n_measured == 0] = np.nan
    return Recording(
        time_s=t[starts],
        voltage_v=np.add.reduceat(np.asarray(rec.voltage_v, dtype=float), starts) / counts,
        current_a=weighted_mean(np.asarray(rec.current_a, dtype=float)),
        temperature_k=temperature_k,
        source=rec.source,
        metadata={**rec.metadata, "resample_window_s": float(window_s),
                  AS_MEASURED_STEP_RESISTANCE_KEY: (rec.metadata[AS_MEASURED_STEP_RESISTANCE_KEY]
                                                    if AS_MEASURED_STEP_RESISTANCE_KEY in rec.metadata
                                                    else as_measured_steps(rec))},
        group_voltage_v=group_v,
    )


def resample_all(recordings: Iterable[Recording], window_s: float | None) -> list[Recording]:
    """:func:`resample_windows` on every recording; ``None`` keeps them unchanged."""
    if window_s is None:
        return list(recordings)
    return [resample_windows(r, window_s) for r in recordings]


def median_interval_s(rec: Recording) -> float:
    """Median spacing of a recording's samples in s (``inf`` for fewer than two samples)."""
    t = np.asarray(rec.time_s, dtype=float)
    return float(np.median(np.diff(t))) if t.size > 1 else float("inf")


def as_the_monitor_sees(recordings: Sequence[Recording], window_s: float | None = None, *,
                        as_measured: bool = False,
                        monitor_window_s: float = MONITOR_WINDOW_S) -> tuple[list[Recording], float | None, str | None]:
    """``fit``'s data preparation: an explicit window, or the monitor's window when the data are denser.

    The predictor nodes never see samples faster than the battery monitor's window averages, so a
    fit of denser data averages them the same way unless told otherwise.

    Parameters
    ----------
    recordings : Sequence[Recording]
        The data as loaded.
    window_s : float or None
        ``--resample SECONDS``: average over windows of this length (s), whatever the sampling.
    as_measured : bool
        ``--no-resample``: keep the samples as measured.
    monitor_window_s : float
        The monitor's averaging window in s (default :data:`MONITOR_WINDOW_S`).

    Returns
    -------
    recordings : list[Recording]
        The prepared recordings.
    window_s : float or None
        The window applied in s (``None``: as measured).
    notice : str or None
        A console line when the default window was applied, saying how to turn it off.

    Raises
    ------
    InputDataError
        When ``window_s`` is not a positive finite number, or both ``window_s`` and ``as_measured`` are given.
    """
    if window_s is not None:
        if as_measured:
            raise InputDataError("--resample and --no-resample exclude each other")
        return resample_all(recordings, window_s), float(window_s), None
    recs = list(recordings)
    denser = [median_interval_s(r) for r in recs if median_interval_s(r) < monitor_window_s * (1.0 - 1e-3)]
    if as_measured or not denser:
        return recs, None, None
    notice = (f"averaging the data over {monitor_window_s:g} s windows, as the battery monitor feeds the predictor "
              f"(samples every {min(denser):g} s, median); --resample SECONDS for another window, "
              "--no-resample to fit the samples as measured")
    return resample_all(recs, monitor_window_s), float(monitor_window_s), notice
