"""Parameter screening (seed paper, step 4).

Each scalar SPM parameter is raised by 10 % (except constants, temperatures,
the number of electrodes in parallel and the electrode width), a 0.5C discharge
is simulated to the cut-off, and the runtime change and the R2 against the
unchanged run are recorded. A parameter is relevant when the runtime changes by
more than 1 % or the R2 falls below 0.99.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from battery_predictor.errors import SimulationError
from battery_predictor.fitting.cost import r2_mod
from battery_predictor.params import INTERCONNECT_KEYS, PackParams
from battery_predictor.simulation.base import PackSimulator, SimulationRequest
from battery_predictor.simulation.load import StepLoad

if TYPE_CHECKING:
    import numpy as np

#: Relative raise of each parameter.
RAISE_FRACTION = 0.10
#: Relevance thresholds (paper step 4).
RUNTIME_CHANGE_THRESHOLD_PCT = 1.0
R2_THRESHOLD = 0.99
#: Parameters never screened: constants, ambient/initial/reference temperatures, number of
#: electrodes in parallel, electrode width (fixed by the cell geometry), and values that only
#: define the experiment or SOC scale rather than the cell's physics.
EXCLUDED_SUBSTRINGS = (
    "constant", "Electron charge", "Avogadro", "temperature [K]", "Number of electrodes", "Electrode width", "Number of cells",
    "Current function", "Lower voltage cut-off", "Upper voltage cut-off", "Nominal cell capacity",
    "Open-circuit voltage at", "Typical", "Ratio of lithium moles to SEI moles",
)


@dataclass(frozen=True)
class ScreeningRow:
    """Screening result of one parameter.

    Attributes
    ----------
    name : str
        PyBaMM key or interconnect name.
    base_value : float
        Value before the raise.
    runtime_change_pct : float
        Runtime change in % (NaN when the raised simulation failed).
    r2 : float
        R2_mod of the raised run against the unchanged run.
    relevant : bool
        Runtime change > 1 % or R2 < 0.99.
    error : str
        Why the raised run failed, if it did.
    """

    name: str
    base_value: float
    runtime_change_pct: float
    r2: float
    relevant: bool
    error: str = ""


def screenable_parameters(params: PackParams) -> list[str]:
    """Scalar parameters of the params' cell that screening raises, plus R_b, R_c, R_i."""
    pv = params.parameter_values()
    names = []
    for key in sorted(pv.keys()):
        if any(s in key for s in EXCLUDED_SUBSTRINGS):
            continue
        val = pv[key]
        if isinstance(val, bool) or not isinstance(val, (int, float)) or val == 0 or not math.isfinite(val):
            continue
        names.append(key)
    return names + ["r_b_ohm", "r_c_ohm", "r_i_ohm"]


def screening_load(params: PackParams, c_rate: float | None = None) -> StepLoad:
    """A constant-current discharge at ``c_rate`` (default from params, 0.5C) long enough to reach cut-off."""
    c_rate = float(c_rate if c_rate is not None else params.operating.get("screening_c_rate", 0.5))
    capacity_ah = float(params.pack_info.get("nominal_capacity_ah")
                        or params.parameter_values()["Nominal cell capacity [A.h]"] * params.parallel)
    current_a = c_rate * capacity_ah
    return StepLoad.constant(current_a, 3.0 * 3600.0 / c_rate)


def screen(params: PackParams, simulator: PackSimulator, names: Iterable[str] | None = None,
           c_rate: float | None = None,
           progress: Callable[[ScreeningRow], None] | None = None) -> list[ScreeningRow]:
    """Raise each parameter by 10 % and rank them by effect (most relevant first).

    Parameters
    ----------
    params : PackParams
        The pack model.
    simulator : PackSimulator
        Usually the fast simulator (identical cells).
    names : iterable of str, optional
        Parameters to screen (default: :func:`screenable_parameters`).
    c_rate : float, optional
        Discharge rate in 1/h (default: params ``operating.screening_c_rate`` or 0.5).
    progress : callable, optional
        Called with each finished row.
    """
    load = screening_load(params, c_rate)
    times = load.start_s
    out_times = None
    base_req = SimulationRequest(load=StepLoad(times, load.current_a, load.end_s),
                                 output_time_s=_grid(load.end_s))
    base = simulator.simulate(params, base_req)
    if base.termination != "cell_cutoff":
        raise SimulationError("the unchanged model did not reach its cut-off in the screening discharge")
    base_runtime = base.end_time_s
    out_times = base_req.output_time_s
    rows = []
    for name in (list(names) if names is not None else screenable_parameters(params)):
        value = params.value(name)
        raised = params.with_values({name: value * (1.0 + RAISE_FRACTION)})
        try:
            res = simulator.simulate(raised, SimulationRequest(load=base_req.load, output_time_s=out_times))
            if res.termination != "cell_cutoff":
                runtime_change = 100.0 * (load.end_s - base_runtime) / base_runtime
            else:
                runtime_change = 100.0 * (res.end_time_s - base_runtime) / base_runtime
            r2 = r2_mod(base.time_s, base.pack_voltage_v, res.time_s, res.pack_voltage_v)
            row = ScreeningRow(name, value, runtime_change, r2,
                               abs(runtime_change) > RUNTIME_CHANGE_THRESHOLD_PCT or r2 < R2_THRESHOLD)
        except SimulationError as exc:
            row = ScreeningRow(name, value, float("nan"), float("nan"), True, error=str(exc))
        rows.append(row)
        if progress is not None:
            progress(row)
    return rank(rows)


def rank(rows: Iterable[ScreeningRow]) -> list[ScreeningRow]:
    """Relevant first, then by |runtime change| and 1 - R2 (failed raises first among relevant)."""
    def key(r: ScreeningRow) -> tuple[bool, float]:
        rt = abs(r.runtime_change_pct) if math.isfinite(r.runtime_change_pct) else math.inf
        r2 = (1.0 - r.r2) if math.isfinite(r.r2) else math.inf
        return (not r.relevant, -max(rt / RUNTIME_CHANGE_THRESHOLD_PCT, r2 / (1 - R2_THRESHOLD)))

    return sorted(rows, key=key)


def relevant_names(rows: Iterable[ScreeningRow]) -> list[str]:
    """Names of the relevant parameters (interconnect names included only when relevant)."""
    return [r.name for r in rows if r.relevant and not r.error]


def _grid(end_s: float, step_s: float = 30.0) -> np.ndarray:
    import numpy as np

    return np.arange(0.0, end_s, step_s)


__all__ = ["ScreeningRow", "screen", "screenable_parameters", "relevant_names", "rank", "INTERCONNECT_KEYS"]
