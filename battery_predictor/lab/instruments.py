"""The emulated data acquisition of the lab (seed paper section 4, step 2).

The paper samples the bench supply's voltage and current and the type-K
thermocouples (MCC 134 HAT) at about 10 Hz, with a voltage resolution of
0.01 V and a current resolution of 0.1 A, and then resamples to 5 s by
time-window averaging "to suppress quantization-induced fluctuations". This
module does the same to a noise-free :class:`~battery_predictor.lab.real_pack.PackTrace`:

1. **10 Hz sampling** (``t = k / 10 s``). The current is the bench supply's
   set-point, i.e. the load *before* the simulator resampled it onto its
   step grid. The voltage is the simulated pack voltage of the step
   (zero-order hold) corrected for the difference between the true current
   and the step's mean current with the pack's small-signal resistance
   (estimated from the trace's own current steps), so a short navigation
   spike inside a 5 s step shows up in the 10 Hz voltage. The correction has
   zero mean over each step, so averaging over a step gives back the
   simulated voltage. The temperature is the mean cell temperature,
   linearly interpolated.
2. **Instrument noise** (Gaussian, seeded): voltage and current noise of
   about half a resolution step (so that quantisation toggles between
   neighbouring levels, as the paper describes), thermocouple noise of
   0.5 K plus one constant offset per experiment within +-0.5 K (type-K
   tolerance).
3. **Quantisation** to the resolution: ``round(x / resolution) * resolution``
   (0.01 V, 0.1 A; temperature 0.01 K).
4. **5 s time-window averaging**: windows ``[5 j, 5 j + 5)`` s, each labelled
   with its start (as ``pandas.DataFrame.resample("5s").mean()`` does).
   Labelling by the window start keeps the averaged current consistent with
   :meth:`~battery_predictor.simulation.load.StepLoad.from_samples` (the
   current at ``time_s[i]`` holds until ``time_s[i + 1]``).
5. **Stop rule**: the discharge ends with the first 5 s window whose mean
   voltage is at or below the end voltage (that window is the last one
   kept). The rule is applied to the window means, not to single 10 Hz
   samples: under the Temi's dynamic load a single sample during a
   navigation current spike dips 0.3-0.4 V below the window mean, and a
   robot's battery monitor (which the 13.30 V return-to-charger threshold
   stands for) filters such spikes. With a constant current both rules agree
   to within the noise. So the recorded voltage crosses the end voltage
   exactly at the recorded end of the discharge.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import SimulationError
from battery_predictor.recording import Recording

if TYPE_CHECKING:
    from battery_predictor.lab.real_pack import PackTrace

#: Minimum current change (A) between steps used to estimate the pack resistance.
_MIN_STEP_A = 0.3


@dataclass(frozen=True)
class InstrumentSpec:
    """The emulated measurement chain.

    Attributes
    ----------
    sample_rate_hz : float
        Acquisition rate (paper: ~10 Hz).
    voltage_resolution_v, current_resolution_a : float
        Quantisation steps (paper: 0.01 V, 0.1 A).
    temperature_resolution_k : float
        Quantisation step of the thermocouple reading.
    voltage_noise_v, current_noise_a, temperature_noise_k : float
        Standard deviations of the white noise added to each 10 Hz sample.
    temperature_offset_max_k : float
        The thermocouple's constant offset is drawn uniformly in +-this.
    window_s : float
        Averaging window (paper: 5 s).
    """

    sample_rate_hz: float = 10.0
    voltage_resolution_v: float = 0.01
    current_resolution_a: float = 0.1
    temperature_resolution_k: float = 0.01
    voltage_noise_v: float = 0.005
    current_noise_a: float = 0.05
    temperature_noise_k: float = 0.5
    temperature_offset_max_k: float = 0.5
    window_s: float = 5.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class RawSamples:
    """The 10 Hz acquisition before averaging.

    Attributes
    ----------
    time_s, voltage_v, current_a, temperature_k : numpy.ndarray
        Quantised samples (s, V, A positive = discharge, K).
    temperature_offset_k : float
        The thermocouple offset drawn for this experiment.
    resistance_ohm : float
        Pack small-signal resistance used for the intra-step voltage correction.
    """

    time_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    temperature_k: np.ndarray
    temperature_offset_k: float
    resistance_ohm: float
    voltage_noise_free_v: np.ndarray


@dataclass(frozen=True)
class Measurement:
    """What the emulated acquisition produced.

    Attributes
    ----------
    recording : Recording
        5 s window means (time = window start, from 0 s), up to the stop.
    raw : RawSamples
        The 10 Hz samples up to the end of the last kept window.
    stopped : bool
        True when a window mean reached the stop voltage.
    stop_time_s : float or None
        Start (label) of the first window whose mean voltage is at or below
        the stop voltage: the measured time until the stop voltage.
    acquisition_end_s : float
        End of the last kept window in s (when the bench supply stopped).
    """

    recording: Recording
    raw: RawSamples
    stopped: bool
    stop_time_s: float | None
    acquisition_end_s: float


def quantise(values: npt.ArrayLike, resolution: float) -> np.ndarray:
    """Round ``values`` to the nearest multiple of ``resolution``."""
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0, got {resolution}")
    arr = np.asarray(values, dtype=float)
    return np.round(arr / resolution) * resolution


def pack_resistance_ohm(time_s: npt.ArrayLike, current_a: npt.ArrayLike, voltage_v: npt.ArrayLike,
                        default_ohm: float = 0.0) -> float:
    """Pack small-signal resistance (Ohm) from the voltage jumps at current steps of a stepped trace.

    The median of ``-dV / dI`` over consecutive steps whose current changes by
    more than 0.3 A; ``default_ohm`` when there are fewer than three such steps.
    """
    i = np.asarray(current_a, dtype=float)
    v = np.asarray(voltage_v, dtype=float)
    di = np.diff(i)
    dv = np.diff(v)
    big = np.abs(di) > _MIN_STEP_A
    if np.count_nonzero(big) < 3:
        return float(default_ohm)
    r = -dv[big] / di[big]
    r = r[np.isfinite(r) & (r > 0)]
    return float(np.median(r)) if r.size else float(default_ohm)


def sample_trace(trace: PackTrace, spec: InstrumentSpec, rng: np.random.Generator, *,
                 end_s: float | None = None) -> RawSamples:
    """10 Hz noisy, quantised samples of a :class:`~battery_predictor.lab.real_pack.PackTrace`.

    Parameters
    ----------
    trace : PackTrace
        Noise-free simulation.
    spec : InstrumentSpec
        Measurement chain.
    rng : numpy.random.Generator
        Randomness (draw order: temperature offset, then voltage, current and
        temperature noise of every sample).
    end_s : float, optional
        Sample only ``t < end_s`` (default: the end of the trace).
    """
    end = trace.end_s if end_s is None else min(float(end_s), trace.end_s)
    n = int(np.ceil(end * spec.sample_rate_hz - 1e-9))
    if n < 1:
        raise SimulationError("instruments: nothing to sample (empty trace)")
    t = np.arange(n) / spec.sample_rate_hz
    step_t = np.asarray(trace.time_s, dtype=float)
    k = np.clip(np.searchsorted(step_t, t + 1e-9, side="right") - 1, 0, len(step_t) - 1)
    i_true = trace.load.current_at(t)
    r = pack_resistance_ohm(step_t, trace.current_a, trace.voltage_v)
    v_true = trace.voltage_v[k] - r * (i_true - trace.current_a[k])
    temp_true = np.interp(t, step_t, trace.temperature_k)

    offset = float(rng.uniform(-spec.temperature_offset_max_k, spec.temperature_offset_max_k))
    v = quantise(v_true + spec.voltage_noise_v * rng.standard_normal(n), spec.voltage_resolution_v)
    i = quantise(i_true + spec.current_noise_a * rng.standard_normal(n), spec.current_resolution_a)
    temp = quantise(temp_true + offset + spec.temperature_noise_k * rng.standard_normal(n),
                    spec.temperature_resolution_k)
    return RawSamples(t, v, i, temp, offset, r, v_true)


def window_average(time_s: npt.ArrayLike, *columns: npt.ArrayLike,
                   window_s: float = 5.0) -> tuple[np.ndarray, list[np.ndarray]]:
    """Time-window averaging: mean of every column over ``[j w, j w + w)``, labelled ``j w``.

    Empty windows are omitted; the last window may be partial.

    Returns
    -------
    window_start_s : numpy.ndarray
        Start of each non-empty window in s.
    means : list of numpy.ndarray
        Per-column window means.
    """
    t = np.asarray(time_s, dtype=float)
    if t.size == 0:
        return t.copy(), [np.asarray(c, dtype=float)[:0] for c in columns]
    idx = np.floor(t / window_s + 1e-9).astype(np.int64)
    idx -= idx.min()
    base = np.floor(t[0] / window_s + 1e-9)
    counts = np.bincount(idx)
    present = counts > 0
    means = []
    for col in columns:
        sums = np.bincount(idx, weights=np.asarray(col, dtype=float), minlength=counts.size)
        means.append(sums[present] / counts[present])
    starts = (np.flatnonzero(present) + base) * window_s
    return starts, means


def measure(trace: PackTrace, spec: InstrumentSpec | None = None, *, seed: int, stop_voltage_v: float | None = None,
            end_s: float | None = None, source: str = "<lab>") -> Measurement:
    """A "measured" recording of ``trace``: 10 Hz acquisition, 5 s window means, stop rule.

    Parameters
    ----------
    trace : PackTrace
        Noise-free real-pack simulation.
    spec : InstrumentSpec, optional
        Measurement chain (default: the paper's).
    seed : int
        Seed of the noise (same seed, same recording).
    stop_voltage_v : float, optional
        End voltage: keep the windows up to the first one whose mean is at or below it.
    end_s : float, optional
        Acquire only ``t < end_s``.
    source : str
        Source name of the recording.
    """
    spec = spec or InstrumentSpec()
    raw = sample_trace(trace, spec, np.random.default_rng(int(seed)), end_s=end_s)
    t, (v, i, temp) = window_average(raw.time_s, raw.voltage_v, raw.current_a, raw.temperature_k,
                                     window_s=spec.window_s)
    stopped = False
    stop_time = None
    if stop_voltage_v is not None:
        hit = np.flatnonzero(v <= stop_voltage_v + 1e-9)
        if hit.size:
            keep = int(hit[0]) + 1
            t, v, i, temp = t[:keep], v[:keep], i[:keep], temp[:keep]
            stopped = True
            stop_time = float(t[-1])
    acquisition_end = float(min(t[-1] + spec.window_s, raw.time_s[-1] + 1.0 / spec.sample_rate_hz))
    if stopped:
        sel = raw.time_s < acquisition_end - 1e-9
        raw = dataclasses.replace(raw, time_s=raw.time_s[sel], voltage_v=raw.voltage_v[sel],
                                  current_a=raw.current_a[sel], temperature_k=raw.temperature_k[sel],
                                  voltage_noise_free_v=raw.voltage_noise_free_v[sel])
    rec = Recording(time_s=t, voltage_v=v, current_a=i, temperature_k=temp, source=source,
                    metadata={"instrument_seed": int(seed)})
    return Measurement(rec, raw, stopped, stop_time, acquisition_end)
