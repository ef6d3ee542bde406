"""The SPM pack engine: PyBaMM's discretised SPM stepped exactly on piecewise-constant currents.

- :mod:`~battery_predictor.simulation.engine.model`: the linear particle blocks and the voltage
  expression taken from PyBaMM's discretised model;
- :mod:`~battery_predictor.simulation.engine.modal`: exact zero-order-hold stepping in modal
  coordinates (Numba kernel when installed, NumPy otherwise);
- :mod:`~battery_predictor.simulation.engine.run`: cell runs with the voltage at every step and the
  exact cut-off time, batched over parameter sets and initial states;
- :mod:`~battery_predictor.simulation.engine.thermal`: the lumped thermal cell (PyBaMM's
  ``{"thermal": "lumped"}`` heat equation, temperature stepped with the particles);
- :mod:`~battery_predictor.simulation.engine.state`: initial concentrations for an SOC or an
  open-circuit voltage;
- :mod:`~battery_predictor.simulation.engine.pack`: the pack voltage (the one implementation);
- :mod:`~battery_predictor.simulation.engine.simulator`: ``EngineSimulator``, the pack-simulator
  interface (and ``simulate_batch``) with a visible fallback;
- :mod:`~battery_predictor.simulation.engine.segments`: ``EnginePack``, segment runs from an SOC
  or a carried state for predictions.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from battery_predictor.simulation.engine.pack import pack_voltage_v, series_resistance_factor

if TYPE_CHECKING:
    from battery_predictor.simulation.engine.segments import EnginePack
    from battery_predictor.simulation.engine.simulator import EngineSimulator

__all__ = ["EnginePack", "EngineSimulator", "pack_voltage_v", "series_resistance_factor"]


def __getattr__(name: str) -> type[EngineSimulator] | type[EnginePack]:
    """``EngineSimulator`` and ``EnginePack`` on first use (the pack voltage alone stays a light import)."""
    if name == "EngineSimulator":
        from battery_predictor.simulation.engine.simulator import EngineSimulator

        return EngineSimulator
    if name == "EnginePack":
        from battery_predictor.simulation.engine.segments import EnginePack

        return EnginePack
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
