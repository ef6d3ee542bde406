"""The battery monitor's logic without ROS: validate samples, average them into windows, detect stale input.

The ``battery_monitor`` node (:mod:`battery_predictor.nodes.battery_monitor_node`)
is a thin adapter around :class:`BatteryMonitor`: it converts each incoming
message to internal units and signs (V, A positive = discharge, K; the only
sign conversion is :mod:`battery_predictor.conventions`), hands it to
:meth:`BatteryMonitor.add_sample` (``sensor_msgs/BatteryState``) or to
:meth:`~BatteryMonitor.add_voltage` / :meth:`~BatteryMonitor.add_current` /
:meth:`~BatteryMonitor.add_temperature` (the relay's separate topics), calls
:meth:`BatteryMonitor.tick` on a timer, and publishes what comes back.

Time
----
Every method takes the sample's time ``stamp_s`` and the monitor's present
time ``now_s`` on **one** time base (the node's ROS clock: wall time live,
the bag's time when a replay publishes ``/clock`` and the node runs with
``use_sim_time``). ``BatteryState`` samples are timed by ``header.stamp``
(the clock when the stamp is zero); the relay's ``Float64`` topics carry no
stamp and are timed by ``now_s`` at reception. Staleness is ``now_s`` minus
the time of the last accepted voltage/current sample, so it is judged on the
same time base as the stamps.

Validation
----------
A sample is rejected, and counted under one reason of :data:`REASONS`, when

* ``nan``: voltage or current (or a given temperature) is NaN or infinite;
* ``out_of_range``: outside the pack's physical range (``MonitorConfig``);
* ``out_of_order``: its time is before the previous accepted sample of the
  same input (time going backwards);
* ``duplicate``: its time equals that of the previous accepted sample of the
  same input;
* ``late``: it belongs to an averaging window that was already closed;
* ``future``: its time is more than ``max_future_s`` ahead of ``now_s``
  (a wrong clock would otherwise block every later sample as out of order).

A NaN temperature in a ``BatteryState`` means "not measured" (as the message
definition says) and is not a rejection; an out-of-range temperature drops
the temperature only (counted as ``out_of_range`` on the ``temperature`` input).
The same holds for the cell (series-group) voltages of ``BatteryState.cell_voltage``:
NaN entries are not measured; an entry that is infinite, <= 0 V or above
:data:`MAX_CELL_VOLTAGE_V` drops the sample's cell voltages only (counted on the
``cell_voltage`` input as ``nan`` / ``out_of_range``).

Windows
-------
Accepted samples are averaged over windows ``[k w, (k + 1) w)`` of
``window_s = w`` seconds on the time base above; the lowest measured cell voltage
of the window's accepted samples is kept (``PackSnapshot.min_cell_voltage_v``, the
route safety check of :mod:`battery_predictor.prediction.core`). A window is closed when a
sample of a later window arrives, or by :meth:`BatteryMonitor.tick` once
``now_s`` is ``late_allowance_s`` past its end. A closed window with at least
one voltage and one current sample becomes a :class:`PackSnapshot` stamped
with the window's end. While the input is stale, every ``window_s`` a stale
snapshot (``stale=True``, last known values, no samples) is emitted.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

#: Why a sample can be rejected (keys of the rejection counters).
REASONS = ("nan", "out_of_range", "out_of_order", "duplicate", "late", "future")
#: Reasons that mean the sensor delivers invalid values (diagnostics level ERROR).
INVALID_REASONS = ("nan", "out_of_range")
#: Input styles of :class:`MonitorConfig`.
STYLES = ("battery_state", "relay")

#: A cell (series-group) voltage above this (V) is no lithium-ion cell's: a millivolt reading or a broken sensor.
MAX_CELL_VOLTAGE_V = 10.0

#: Diagnostic levels (the values of diagnostic_msgs/DiagnosticStatus).
OK, WARN, ERROR = 0, 1, 2

_EPS = 1e-9


@dataclass(frozen=True)
class MonitorConfig:
    """Settings of the battery monitor (copied from ROS parameters by the node).

    Attributes
    ----------
    input_style : str
        ``"battery_state"`` (one ``sensor_msgs/BatteryState`` topic) or ``"relay"``
        (separate voltage / current / temperature topics).
    min_voltage_v, max_voltage_v : float
        Physical range of the pack voltage in V; samples outside are rejected.
    max_discharge_current_a, max_charge_current_a : float
        Largest plausible discharge and charge current in A (both >= 0); the
        accepted current range is ``[-max_charge_current_a, max_discharge_current_a]``
        (positive = discharge).
    min_temperature_k, max_temperature_k : float
        Plausible temperature range in K.
    window_s : float
        Averaging window in s.
    stale_after_s : float
        The input is stale when no voltage/current sample was accepted for this long (s).
    late_allowance_s : float
        A window without a later sample is closed this long (s) after its end.
    max_future_s : float
        Samples stamped more than this (s) ahead of the present time are rejected.
    error_hold_s : float
        Diagnostics stay at ERROR this long (s) after an invalid sample.
    """

    input_style: str = "battery_state"
    min_voltage_v: float = 0.0
    max_voltage_v: float = 100.0
    max_discharge_current_a: float = 50.0
    max_charge_current_a: float = 50.0
    min_temperature_k: float = 233.15
    max_temperature_k: float = 358.15
    window_s: float = 5.0
    stale_after_s: float = 15.0
    late_allowance_s: float = 1.0
    max_future_s: float = 2.0
    error_hold_s: float = 10.0

    def __post_init__(self) -> None:
        if self.input_style not in STYLES:
            raise ValueError(f"input_style is {self.input_style!r} (must be one of {', '.join(STYLES)})")
        for name in ("min_voltage_v", "max_voltage_v", "max_discharge_current_a", "max_charge_current_a",
                     "min_temperature_k", "max_temperature_k", "window_s", "stale_after_s", "late_allowance_s",
                     "max_future_s", "error_hold_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"{name} is {value!r} (must be a finite number)")
        if not 0.0 <= self.min_voltage_v < self.max_voltage_v:
            raise ValueError(f"voltage range {self.min_voltage_v}..{self.max_voltage_v} V is empty or negative")
        if self.max_discharge_current_a < 0 or self.max_charge_current_a < 0:
            raise ValueError("max_discharge_current_a and max_charge_current_a must be >= 0")
        if not 0.0 < self.min_temperature_k < self.max_temperature_k:
            raise ValueError(f"temperature range {self.min_temperature_k}..{self.max_temperature_k} K is invalid")
        if self.window_s <= 0 or self.stale_after_s <= 0:
            raise ValueError("window_s and stale_after_s must be > 0")
        if self.late_allowance_s < 0 or self.max_future_s < 0 or self.error_hold_s < 0:
            raise ValueError("late_allowance_s, max_future_s and error_hold_s must be >= 0")


@dataclass(frozen=True)
class PackSnapshot:
    """One clean pack state (what the node publishes as ``battery_predictor_msgs/PackState``).

    Attributes
    ----------
    stamp_s : float
        End of the averaging window (s), or the present time for a stale snapshot.
    voltage_v, current_a, temperature_k : float
        Window means in V, A (positive = discharge) and K (NaN when not measured).
    window_s : float
        Window length in s.
    samples_used, samples_rejected : int
        Samples (messages) accepted into / rejected from this window.
    stale : bool
        True when no fresh input arrived within ``stale_after_s`` (values are the last known ones).
    peak_current_a : float
        Largest sample current of the window in A (positive = discharge); NaN for a stale snapshot.
    min_cell_voltage_v : float
        Lowest cell (series-group) voltage measured in the window in V (``BatteryState.cell_voltage``);
        NaN when none was measured, and for a stale snapshot.
    """

    stamp_s: float
    voltage_v: float
    current_a: float
    temperature_k: float
    window_s: float
    samples_used: int
    samples_rejected: int
    stale: bool
    peak_current_a: float = math.nan
    min_cell_voltage_v: float = math.nan


@dataclass(frozen=True)
class SampleVerdict:
    """What happened to one sample: accepted, or rejected with a reason; and the snapshots it completed."""

    accepted: bool
    reason: str = ""
    snapshots: tuple[PackSnapshot, ...] = ()


@dataclass(frozen=True)
class MonitorStatus:
    """The monitor's health (what the node publishes on ``/diagnostics``).

    Attributes
    ----------
    level : int
        :data:`OK`, :data:`WARN` (stale input, or samples out of order) or :data:`ERROR` (invalid samples).
    message : str
        One-line summary.
    stale : bool
        True when the input is stale (or none was received yet).
    age_s : float
        Time since the last accepted voltage/current sample (s; inf if none).
    accepted : dict
        Accepted samples per input since start.
    rejected : dict
        ``{input: {reason: count}}`` since start (only non-zero counts).
    rejected_total : int
        All rejected samples since start.
    last_snapshot : PackSnapshot or None
        The latest snapshot emitted.
    """

    level: int
    message: str
    stale: bool
    age_s: float
    accepted: dict[str, int]
    rejected: dict[str, dict[str, int]]
    rejected_total: int
    last_snapshot: PackSnapshot | None

    def key_values(self) -> list[tuple[str, str]]:
        """Flat ``(key, value)`` pairs for ``diagnostic_msgs/KeyValue``."""
        out = [("stale", str(self.stale).lower()),
               ("input_age_s", "inf" if not math.isfinite(self.age_s) else f"{self.age_s:.3f}"),
               ("samples_rejected_total", str(self.rejected_total))]
        for reason in REASONS:
            out.append((f"rejected_{reason}", str(sum(r.get(reason, 0) for r in self.rejected.values()))))
        for name, counts in sorted(self.rejected.items()):
            for reason, n in sorted(counts.items()):
                out.append((f"rejected_{name}_{reason}", str(n)))
        for name, n in sorted(self.accepted.items()):
            out.append((f"accepted_{name}", str(n)))
        snap = self.last_snapshot
        if snap is not None:
            out += [("voltage_v", f"{snap.voltage_v:.4f}"), ("current_a", f"{snap.current_a:.4f}"),
                    ("temperature_k", f"{snap.temperature_k:.2f}"), ("last_stamp_s", f"{snap.stamp_s:.3f}")]
        return out


@dataclass
class _Window:
    index: int
    sums: dict[str, float] = field(default_factory=lambda: {"voltage": 0.0, "current": 0.0, "temperature": 0.0})
    counts: dict[str, int] = field(default_factory=lambda: {"voltage": 0, "current": 0, "temperature": 0})
    used: int = 0
    rejected: int = 0
    peak_current: float = -math.inf
    min_cell_voltage: float = math.inf


class BatteryMonitor:
    """Validates samples, averages them into windows and judges staleness (not thread-safe; the node serialises).

    Parameters
    ----------
    config : MonitorConfig
        Settings.
    """

    def __init__(self, config: MonitorConfig) -> None:
        self.config = config
        self.reset()

    # ----------------------------------------------------------------- state
    def reset(self) -> None:
        """Forget everything (used when the clock jumps backwards, e.g. a replay restarts)."""
        self._window: _Window | None = None
        self._closed_index: int | None = None  # highest window index already closed
        self._last_stamp: dict[str, float] = {}
        self._last_fresh: dict[str, float] = {}  # last accepted voltage / current times
        self._last_snapshot: PackSnapshot | None = None
        self._last_values: tuple[float, float, float] | None = None
        self._last_stale_emit: float | None = None
        self._last_invalid: float | None = None
        self._last_misordered: float | None = None
        self._last_now: float | None = None
        self.accepted: dict[str, int] = {}
        self.rejected: dict[str, dict[str, int]] = {}
        self.rejected_total = 0
        self.snapshots_emitted = 0

    def _index(self, t: float) -> int:
        return math.floor(t / self.config.window_s + _EPS)

    def _clock(self, now_s: float) -> None:
        if self._last_now is not None and now_s < self._last_now - self.config.window_s:
            self.reset()  # time went backwards on the clock itself: start over
        self._last_now = now_s if self._last_now is None else max(self._last_now, now_s)

    # ---------------------------------------------------------------- inputs
    def add_sample(self, stamp_s: float, voltage_v: float, current_a: float, temperature_k: float,
                   now_s: float, cell_voltages_v: Sequence[float] = ()) -> SampleVerdict:
        """One ``BatteryState`` sample (V, A positive = discharge, K or NaN = not measured) stamped ``stamp_s``.

        ``cell_voltages_v`` are the message's ``cell_voltage`` (V, NaN = not measured; empty: none).
        """
        cfg = self.config
        values = {"voltage": voltage_v, "current": current_a}
        if not all(_finite(v) for v in values.values()):
            return self._reject("battery_state", "nan", now_s)
        if not cfg.min_voltage_v <= voltage_v <= cfg.max_voltage_v or \
                not -cfg.max_charge_current_a <= current_a <= cfg.max_discharge_current_a:
            return self._reject("battery_state", "out_of_range", now_s)
        if _finite(temperature_k):
            if cfg.min_temperature_k <= temperature_k <= cfg.max_temperature_k:
                values["temperature"] = temperature_k
            else:
                self._count_rejection("temperature", "out_of_range", now_s)
        elif not (isinstance(temperature_k, float) and math.isnan(temperature_k)):
            self._count_rejection("temperature", "nan", now_s)  # +-inf: broken sensor, not "not measured"
        cells = self._min_cell_voltage(cell_voltages_v, now_s)
        if cells is not None:
            values["min_cell_voltage"] = cells
        return self._accept("battery_state", stamp_s, values, now_s)

    def _min_cell_voltage(self, cell_voltages_v: Sequence[float], now_s: float) -> float | None:
        """The lowest measured cell voltage (V) of one message; None when none is measured or any is invalid."""
        measured = [v for v in (float(x) for x in cell_voltages_v) if not math.isnan(v)]
        if not measured:
            return None
        if not all(math.isfinite(v) for v in measured):
            self._count_rejection("cell_voltage", "nan", now_s)
            return None
        if not all(0.0 < v <= MAX_CELL_VOLTAGE_V for v in measured):
            self._count_rejection("cell_voltage", "out_of_range", now_s)
            return None
        return min(measured)

    def add_voltage(self, stamp_s: float, voltage_v: float, now_s: float) -> SampleVerdict:
        """One relay voltage sample in V."""
        if not _finite(voltage_v):
            return self._reject("voltage", "nan", now_s)
        if not self.config.min_voltage_v <= voltage_v <= self.config.max_voltage_v:
            return self._reject("voltage", "out_of_range", now_s)
        return self._accept("voltage", stamp_s, {"voltage": voltage_v}, now_s)

    def add_current(self, stamp_s: float, current_a: float, now_s: float) -> SampleVerdict:
        """One relay current sample in A (positive = discharge)."""
        if not _finite(current_a):
            return self._reject("current", "nan", now_s)
        if not -self.config.max_charge_current_a <= current_a <= self.config.max_discharge_current_a:
            return self._reject("current", "out_of_range", now_s)
        return self._accept("current", stamp_s, {"current": current_a}, now_s)

    def add_temperature(self, stamp_s: float, temperature_k: float, now_s: float) -> SampleVerdict:
        """One relay temperature sample in K (NaN is rejected here: the relay topic exists only when measured)."""
        if not _finite(temperature_k):
            return self._reject("temperature", "nan", now_s)
        if not self.config.min_temperature_k <= temperature_k <= self.config.max_temperature_k:
            return self._reject("temperature", "out_of_range", now_s)
        return self._accept("temperature", stamp_s, {"temperature": temperature_k}, now_s)

    # ------------------------------------------------------------- internals
    def _count_rejection(self, name: str, reason: str, now_s: float) -> None:
        per = self.rejected.setdefault(name, {})
        per[reason] = per.get(reason, 0) + 1
        self.rejected_total += 1
        if self._window is not None:
            self._window.rejected += 1
        if reason in INVALID_REASONS:
            self._last_invalid = now_s
        else:
            self._last_misordered = now_s

    def _reject(self, name: str, reason: str, now_s: float) -> SampleVerdict:
        self._clock(now_s)
        self._count_rejection(name, reason, now_s)
        return SampleVerdict(False, reason)

    def _accept(self, name: str, stamp_s: float, values: dict[str, float], now_s: float) -> SampleVerdict:
        self._clock(now_s)
        if not _finite(stamp_s):
            return self._reject_counted(name, "nan", now_s)
        if stamp_s > now_s + self.config.max_future_s:
            return self._reject_counted(name, "future", now_s)
        last = self._last_stamp.get(name)
        if last is not None and stamp_s == last:
            return self._reject_counted(name, "duplicate", now_s)
        if last is not None and stamp_s < last:
            return self._reject_counted(name, "out_of_order", now_s)
        index = self._index(stamp_s)
        if self._closed_index is not None and index <= self._closed_index:
            return self._reject_counted(name, "late", now_s)
        snapshots: list[PackSnapshot] = []
        if self._window is not None and index > self._window.index:
            snapshots += self._close(now_s)
        if self._window is None:
            self._window = _Window(index)
        w = self._window
        for key, value in values.items():
            if key == "min_cell_voltage":
                w.min_cell_voltage = min(w.min_cell_voltage, value)
                continue
            w.sums[key] += value
            w.counts[key] += 1
        if "current" in values:
            w.peak_current = max(w.peak_current, values["current"])
        w.used += 1
        self._last_stamp[name] = stamp_s
        self.accepted[name] = self.accepted.get(name, 0) + 1
        for key in ("voltage", "current"):
            if key in values:
                self._last_fresh[key] = max(stamp_s, self._last_fresh.get(key, -math.inf))
        return SampleVerdict(True, "", tuple(snapshots))

    def _reject_counted(self, name: str, reason: str, now_s: float) -> SampleVerdict:
        self._count_rejection(name, reason, now_s)
        return SampleVerdict(False, reason)

    def _close(self, now_s: float) -> list[PackSnapshot]:
        """Close the open window; a snapshot when it holds a voltage and a current."""
        w = self._window
        self._window = None
        if w is None:
            return []
        self._closed_index = w.index if self._closed_index is None else max(self._closed_index, w.index)
        if w.counts["voltage"] == 0 or w.counts["current"] == 0:
            return []
        v = w.sums["voltage"] / w.counts["voltage"]
        i = w.sums["current"] / w.counts["current"]
        if w.counts["temperature"]:
            t_k = w.sums["temperature"] / w.counts["temperature"]
        else:
            t_k = self._last_values[2] if self._last_values is not None else math.nan
        self._last_values = (v, i, t_k)
        snap = PackSnapshot((w.index + 1) * self.config.window_s, v, i, t_k, self.config.window_s, w.used,
                            w.rejected, False, w.peak_current,
                            w.min_cell_voltage if math.isfinite(w.min_cell_voltage) else math.nan)
        self._last_snapshot = snap
        self._last_stale_emit = None
        self.snapshots_emitted += 1
        return [snap]

    # ------------------------------------------------------------------ time
    def age_s(self, now_s: float) -> float:
        """Time (s) since the last accepted voltage and current sample (the older of the two); inf if none."""
        if "voltage" not in self._last_fresh or "current" not in self._last_fresh:
            return math.inf
        return now_s - min(self._last_fresh["voltage"], self._last_fresh["current"])

    def is_stale(self, now_s: float) -> bool:
        """True when no fresh voltage/current arrived within ``stale_after_s`` (or none ever)."""
        return self.age_s(now_s) > self.config.stale_after_s

    def tick(self, now_s: float) -> list[PackSnapshot]:
        """Close a window whose time is over and emit stale snapshots; call periodically."""
        self._clock(now_s)
        cfg = self.config
        out: list[PackSnapshot] = []
        w = self._window
        if w is not None and now_s >= (w.index + 1) * cfg.window_s + cfg.late_allowance_s:
            out += self._close(now_s)
        if self.is_stale(now_s) and self._last_values is not None:
            if self._last_stale_emit is None or now_s - self._last_stale_emit >= cfg.window_s - _EPS:
                v, i, t_k = self._last_values
                snap = PackSnapshot(now_s, v, i, t_k, cfg.window_s, 0, 0, True)
                self._last_stale_emit = now_s
                self._last_snapshot = snap
                self.snapshots_emitted += 1
                out.append(snap)
        return out

    def status(self, now_s: float) -> MonitorStatus:
        """Health for ``/diagnostics``: ERROR after invalid samples, WARN when stale or misordered, else OK."""
        cfg = self.config
        age = self.age_s(now_s)
        stale = age > cfg.stale_after_s
        level, parts = OK, []
        if self._last_invalid is not None and now_s - self._last_invalid <= cfg.error_hold_s:
            level = ERROR
            n = sum(c.get(r, 0) for c in self.rejected.values() for r in INVALID_REASONS)
            parts.append(f"invalid samples (NaN or out of range; {n} rejected since start)")
        if stale:
            level = max(level, WARN)
            parts.append("no input received yet" if not math.isfinite(age)
                         else f"input stale ({age:.1f} s since the last valid sample, limit {cfg.stale_after_s:g} s)")
        if self._last_misordered is not None and now_s - self._last_misordered <= cfg.error_hold_s:
            level = max(level, WARN)
            n = sum(c.get(r, 0) for c in self.rejected.values() for r in REASONS if r not in INVALID_REASONS)
            parts.append(f"samples out of order, duplicated, late or from the future ({n} since start)")
        message = "; ".join(parts) if parts else f"ok ({self.rejected_total} samples rejected since start)"
        return MonitorStatus(level, message, stale, age, dict(self.accepted),
                             {k: dict(v) for k, v in self.rejected.items() if v}, self.rejected_total,
                             self._last_snapshot)


def _finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def monitor_windows(time_s: Sequence[float] | np.ndarray, voltage_v: Sequence[float] | np.ndarray,
                    current_a: Sequence[float] | np.ndarray, temperature_k: Sequence[float] | np.ndarray | None = None,
                    config: MonitorConfig | None = None,
                    cell_voltage_v: Sequence[Sequence[float]] | np.ndarray | None = None) -> list[PackSnapshot]:
    """The clean pack states a monitor publishes for a recorded series (offline, in time order).

    Each sample is handed to :meth:`BatteryMonitor.add_sample` at its own time, so the windows,
    rejections and stamps are those the ``battery_monitor`` node would publish in a replay.

    Parameters
    ----------
    time_s, voltage_v, current_a : array_like
        Samples in s, V and A (positive = discharge).
    temperature_k : array_like, optional
        Temperature in K per sample (None = not measured).
    config : MonitorConfig, optional
        Monitor settings (default: wide physical ranges, 5 s windows).
    cell_voltage_v : array_like, optional
        Cell (series-group) voltages in V per sample, shape (n_samples, n_cells), NaN = not measured
        (``Recording.group_voltage_v``).
    """
    monitor = BatteryMonitor(config or MonitorConfig())
    temps = [math.nan] * len(time_s) if temperature_k is None else temperature_k
    cells: Sequence[Sequence[float]] | np.ndarray = [()] * len(time_s) if cell_voltage_v is None else cell_voltage_v
    out: list[PackSnapshot] = []
    for t, v, i, t_k, c in zip(time_s, voltage_v, current_a, temps, cells):
        out += monitor.add_sample(float(t), float(v), float(i), float(t_k), float(t),
                                  [float(x) for x in c]).snapshots
    if len(time_s):
        out += monitor.tick(float(time_s[-1]) + monitor.config.window_s + monitor.config.late_allowance_s + 1e-6)
    return [s for s in out if not s.stale]
