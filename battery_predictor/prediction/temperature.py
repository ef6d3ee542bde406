"""The cell temperature ahead of a forecast: integrated with the params' lumped thermal cell, or held.

A cell discharged at a high rate warms: the LG M50 at 0 degC and 2C goes from 3 to 39 degC in its
27 min discharge (docs/runtime_real_data/other_cells.md). A forecast that holds the latest measured
temperature keeps the cold cell's resistance to the end and stops early.

When the params carry a lumped thermal cell (``cell.options: {thermal: lumped}``, e.g. ``fit
--thermal lumped``) and the engine runs it, the forecast starts the cells at the latest *measured*
cell temperature and lets the engine's lumped thermal model
(:mod:`battery_predictor.simulation.engine.thermal`: PyBaMM's heat equation, heat from the load,
Newton exchange with the ambient, the params' heat capacity and heat-transfer coefficient)
integrate it forward. This module only chooses the starting temperature and the ambient; it holds
no heat equation of its own.

The ambient is the stated one (``PredictorConfig.ambient_temperature_k``) or, when none is stated,
:class:`AmbientEstimate`: the lowest cell temperature measured since the present discharge cycle
began. A cell that only heats itself is never colder than its ambient, so this is the warmest
ambient the measurements allow; it equals the ambient for a cycle that starts from a rested cell,
and errs warm (a shorter cool-down ahead, so a warmer, longer forecast) when the cycle starts from
a cell still warm from charging or driving.

Fallbacks, each stated in :attr:`TemperatureAhead.note` and never an error: params without a thermal
cell hold the latest measured temperature, as before (a thermal cell on PyBaMM stepping, which the engine
does not cover, runs as before: from its carried temperature with the measured one as the ambient); no
usable ambient takes the cell's own temperature as the ambient; ``thermal_forecast:
held`` asks for the held temperature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from battery_predictor.simulation.cell_setup import is_lumped_thermal

if TYPE_CHECKING:
    from battery_predictor.prediction.pack_model import PackModel, RunStart

#: Values of ``PredictorConfig.thermal_forecast``.
THERMAL_FORECASTS = ("auto", "held")
#: Temperatures (K) taken as measurements of a cell; others (a missing sensor, a glitch) are ignored.
PLAUSIBLE_TEMPERATURE_K = (200.0, 400.0)


def plausible_temperature(temperature_k: float) -> bool:
    """True when ``temperature_k`` (K) is finite and within :data:`PLAUSIBLE_TEMPERATURE_K`."""
    lo, hi = PLAUSIBLE_TEMPERATURE_K
    return math.isfinite(temperature_k) and lo < temperature_k < hi


def self_heating(runner: PackModel) -> bool:
    """True when ``runner``'s cells are lumped thermal cells whose start temperature can be set.

    The engine's pack (:class:`~battery_predictor.simulation.engine.segments.EnginePack`) with params
    that ask for ``{"thermal": "lumped"}``; PyBaMM stepping and isothermal params are False.
    """
    return bool(getattr(runner, "thermal", False)) and hasattr(runner, "at_cell_temperature")


class AmbientEstimate:
    """The lowest plausible cell temperature (K) measured since the last :meth:`reset` (NaN before any)."""

    def __init__(self) -> None:
        self._lowest_k = math.nan

    def add(self, temperature_k: float) -> None:
        """Take a measured cell temperature (K; NaN or implausible values are ignored)."""
        if plausible_temperature(temperature_k) and not self._lowest_k <= temperature_k:
            self._lowest_k = float(temperature_k)

    def reset(self) -> None:
        """Forget the measurements (a new discharge cycle, a charging session, another pack)."""
        self._lowest_k = math.nan

    @property
    def value_k(self) -> float:
        """The estimate, K (NaN when nothing plausible was measured)."""
        return self._lowest_k


@dataclass(frozen=True)
class TemperatureAhead:
    """How a forecast treats the cell temperature ahead.

    Attributes
    ----------
    cell_temperature_k : float
        Latest measured cell temperature, K: where the forecast's cells start.
    ambient_k : float
        Ambient temperature of a self-heating forecast, K (the cell temperature when held).
    self_heating : bool
        True: the lumped thermal cell integrates the temperature from ``cell_temperature_k``;
        False: the temperature is held at ``cell_temperature_k``.
    note : str
        What was assumed, and why a fallback was taken.
    """

    cell_temperature_k: float
    ambient_k: float
    self_heating: bool
    note: str

    @property
    def run_temperature_k(self) -> float:
        """The ``temperature_k`` a model run takes (the ambient of a thermal cell, else the cell's), K."""
        return self.ambient_k if self.self_heating else self.cell_temperature_k

    def start(self, runner: PackModel, start: RunStart) -> RunStart:
        """``start`` with its cells at :attr:`cell_temperature_k` when self-heating (else unchanged)."""
        if not self.self_heating:
            return start
        return runner.at_cell_temperature(start, self.cell_temperature_k)  # type: ignore[attr-defined]


def temperature_ahead(runner: PackModel, cell_temperature_k: float, ambient_k: float, mode: str = "auto", *,
                      ambient_source: str = "the lowest cell temperature measured in this discharge cycle"
                      ) -> TemperatureAhead:
    """The temperature treatment of a forecast (see the module docstring for the fallbacks).

    Parameters
    ----------
    runner : PackModel
        The pack model.
    cell_temperature_k : float
        Latest cell temperature, K (measured, or the configured default when none is).
    ambient_k : float
        Ambient temperature, K (stated or estimated; NaN when unknown).
    mode : {"auto", "held"}
        ``auto``: self-heating when the model has a lumped thermal cell; ``held``: never.
    ambient_source : str
        Where ``ambient_k`` came from, for the note.

    Raises
    ------
    ValueError
        When ``mode`` is not one of :data:`THERMAL_FORECASTS`.
    """
    if mode not in THERMAL_FORECASTS:
        raise ValueError(f"thermal_forecast {mode!r} is not one of {', '.join(THERMAL_FORECASTS)}")
    if mode == "held":
        return TemperatureAhead(cell_temperature_k, cell_temperature_k, False,
                                "temperature held (thermal_forecast held)")
    if not self_heating(runner):
        params = getattr(runner, "params", None)
        if params is not None and is_lumped_thermal(params):  # PyBaMM stepping of a thermal cell: as before
            return TemperatureAhead(cell_temperature_k, cell_temperature_k, False,
                                    "the lumped thermal cell runs on PyBaMM stepping, which heats it from its "
                                    "carried temperature with the measured one as the ambient")
        return TemperatureAhead(cell_temperature_k, cell_temperature_k, False,
                                "temperature held (the params carry no lumped thermal cell on the engine)")
    if not plausible_temperature(cell_temperature_k):
        return TemperatureAhead(cell_temperature_k, cell_temperature_k, False,
                                f"temperature held (cell temperature {cell_temperature_k} K is not usable)")
    if not plausible_temperature(ambient_k):
        return TemperatureAhead(cell_temperature_k, cell_temperature_k, True,
                                "self-heating, ambient unknown: taken as the cell's temperature")
    return TemperatureAhead(cell_temperature_k, float(ambient_k), True,
                            f"self-heating, ambient {ambient_k - 273.15:.1f} degC ({ambient_source})")
