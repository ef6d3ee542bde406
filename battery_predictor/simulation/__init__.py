"""Pack simulators: one interface (:class:`PackSimulator`), two implementations.

- :class:`~battery_predictor.simulation.liionpack_sim.LiionpackSimulator`: the
  reference, every cell simulated by liionpack, heterogeneous packs allowed.
- :class:`~battery_predictor.simulation.fast.FastPackSimulator`: one PyBaMM cell
  scaled to the pack with an equivalent interconnect resistance, for packs of
  identical cells; re-solved through ``[input]`` parameters where possible.
"""

from battery_predictor.simulation.base import PackSimResult, PackSimulator, SimulationRequest
from battery_predictor.simulation.load import StepLoad

__all__ = ["PackSimResult", "PackSimulator", "SimulationRequest", "StepLoad", "get_simulator"]


def get_simulator(name: str) -> PackSimulator:
    """Return a simulator by name: ``"fast"`` or ``"liionpack"``."""
    from battery_predictor.errors import SimulationError

    if name == "fast":
        from battery_predictor.simulation.fast import FastPackSimulator

        return FastPackSimulator()
    if name == "liionpack":
        from battery_predictor.simulation.liionpack_sim import LiionpackSimulator

        return LiionpackSimulator()
    raise SimulationError(f"unknown simulator '{name}' (use 'fast' or 'liionpack')")
