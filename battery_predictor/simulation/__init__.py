"""Pack simulators: one interface (:class:`PackSimulator`), three implementations.

- :class:`~battery_predictor.simulation.engine.EngineSimulator` (``"engine"``, the CLI's
  default): PyBaMM's discretised SPM stepped exactly outside PyBaMM, milliseconds per day; it
  hands what it does not cover to the fast simulator and says so.
- :class:`~battery_predictor.simulation.liionpack_sim.LiionpackSimulator`: the
  reference, every cell simulated by liionpack, heterogeneous packs allowed.
- :class:`~battery_predictor.simulation.fast.FastPackSimulator`: one PyBaMM cell
  scaled to the pack with an equivalent interconnect resistance, for packs of
  identical cells; re-solved through ``[input]`` parameters where possible.
"""

from battery_predictor.simulation.base import PackSimResult, PackSimulator, SimulationRequest
from battery_predictor.simulation.load import StepLoad

__all__ = ["SIMULATORS", "PackSimResult", "PackSimulator", "SimulationRequest", "StepLoad", "get_simulator"]

#: Simulator names of :func:`get_simulator` (the first is the CLI's default).
SIMULATORS = ("engine", "fast", "liionpack")


def get_simulator(name: str) -> PackSimulator:
    """Return a simulator by name: ``"engine"``, ``"fast"`` or ``"liionpack"``."""
    from battery_predictor.errors import SimulationError

    if name == "engine":
        from battery_predictor.simulation.engine import EngineSimulator

        return EngineSimulator()
    if name == "fast":
        from battery_predictor.simulation.fast import FastPackSimulator

        return FastPackSimulator()
    if name == "liionpack":
        from battery_predictor.simulation.liionpack_sim import LiionpackSimulator

        return LiionpackSimulator()
    raise SimulationError(f"unknown simulator '{name}' (use one of {', '.join(SIMULATORS)})")
