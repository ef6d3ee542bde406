"""The pack-simulator interface and its request/result types."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from battery_predictor.simulation.load import StepLoad

if TYPE_CHECKING:
    from battery_predictor.params import PackParams

@dataclass(frozen=True)
class SegmentRun:
    """A run of constant-current segments (the predictor's pack models: PyBaMM stepping and the engine).

    Attributes
    ----------
    time_s : numpy.ndarray
        Sample times in s from the start.
    pack_voltage_v : numpy.ndarray
        Pack voltage in V at those times.
    pack_current_a : numpy.ndarray
        Pack current in A (positive = discharge) of the segment each sample belongs to.
    segment_end_index : list of int
        Index into ``time_s`` of the last sample of each completed segment.
    reached_cutoff : bool
        True when a cell reached its lower cut-off before the end.
    end_time_s : float
        Time in s at which the run ended.
    final_state : object or None
        The state at the end (at the cut-off when reached), to continue from: the model's own type
        (``prediction.cell_runner.RunState``, ``simulation.engine.segments.EngineState``), or None.
    """

    time_s: np.ndarray
    pack_voltage_v: np.ndarray
    pack_current_a: np.ndarray
    segment_end_index: list[int]
    reached_cutoff: bool
    end_time_s: float
    final_state: Any = None


@dataclass(frozen=True)
class SimulationRequest:
    """What to simulate.

    Attributes
    ----------
    load : StepLoad
        Pack current (A, positive = discharge), piecewise constant.
    ambient_temperature_k : float or None
        Ambient temperature in K; None takes the params' default.
    initial_soc : float or None
        Initial state of charge (0..1) of every cell; None uses the params'
        initial concentrations. Mutually exclusive with ``initial_pack_ocv_v``.
        With a weak series group (``cell_imbalance``) every group starts at it: a pack
        balanced where the recording starts. The predictor's pack models instead start
        from an SOC as a discharge from a full, balanced pack leaves the groups
        (:func:`~battery_predictor.simulation.extensions.group_socs`); both agree from full.
    initial_pack_ocv_v : float or None
        Initial pack open-circuit voltage in V (divided by the series count; every group
        at it, as for ``initial_soc``).
    output_time_s : numpy.ndarray or None
        Times (s from the load start) to report; None reports every step start and at least every 10 s.
    cell_inputs : dict or None
        Per-cell values ``{pybamm_key: array of n_cells}`` for heterogeneous
        packs (liionpack only).
    """

    load: StepLoad
    ambient_temperature_k: float | None = None
    initial_soc: float | None = None
    initial_pack_ocv_v: float | None = None
    output_time_s: np.ndarray | None = None
    cell_inputs: dict[str, np.ndarray] | None = None

    def output_times(self, max_spacing_s: float = 10.0) -> np.ndarray:
        """Report times in s: ``output_time_s``, or every step start plus a grid of ``max_spacing_s``."""
        if self.output_time_s is not None:
            return np.asarray(self.output_time_s, dtype=float)
        grid = np.arange(0.0, self.load.end_s, max_spacing_s)
        return np.union1d(self.load.start_s, grid)


@dataclass(frozen=True)
class PackSimResult:
    """A simulated pack discharge.

    Attributes
    ----------
    time_s : numpy.ndarray
        Report times in s (only times before the termination).
    pack_voltage_v : numpy.ndarray
        Pack terminal voltage in V.
    pack_current_a : numpy.ndarray
        Pack current in A (positive = discharge).
    min_cell_voltage_v : numpy.ndarray
        Lowest cell terminal voltage in V.
    termination : str
        ``"cell_cutoff"`` (any cell reached its lower cut-off) or ``"end_of_load"``.
    end_time_s : float
        Time in s at which the simulation ended.
    seconds : float
        Wall time of the simulation in s.
    extra : dict
        Implementation-specific outputs (per-cell arrays...).
    """

    time_s: np.ndarray
    pack_voltage_v: np.ndarray
    pack_current_a: np.ndarray
    min_cell_voltage_v: np.ndarray
    termination: str
    end_time_s: float
    seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def reached_cutoff(self) -> bool:
        """True when a cell reached the lower cut-off."""
        return self.termination == "cell_cutoff"

    def time_to_pack_voltage_s(self, threshold_v: float) -> float | None:
        """First time (s) the pack voltage is at or below ``threshold_v`` (linear interpolation), or None."""
        v = self.pack_voltage_v
        below = np.nonzero(v <= threshold_v)[0]
        if below.size == 0:
            return None
        i = int(below[0])
        if i == 0:
            return float(self.time_s[0])
        v0, v1 = v[i - 1], v[i]
        t0, t1 = self.time_s[i - 1], self.time_s[i]
        frac = (v0 - threshold_v) / (v0 - v1) if v0 != v1 else 1.0
        return float(t0 + frac * (t1 - t0))


class PackSimulator(Protocol):
    """Simulates a pack described by :class:`~battery_predictor.params.PackParams`."""

    name: str

    def simulate(self, params: PackParams, request: SimulationRequest) -> PackSimResult:
        """Run one simulation; raise :class:`~battery_predictor.errors.SimulationError` on failure."""
        ...
