"""The pack model the predictor runs: the SPM engine where it covers the params, else PyBaMM stepping.

Both answer ``run(start, segments, temperature_k)`` from an SOC or a carried state, with
``soc_of``, ``soc_bounds``, ``capacity_ah`` and ``concentrations``; they agree within 0.01 mV
(``test/unit/test_engine_segments.py``). The engine (exact stepping of PyBaMM's discretised SPM,
:mod:`battery_predictor.simulation.engine`) answers a route in milliseconds instead of about a
tenth of a second. Params with extensions run on :class:`~.cell_runner.PackRunner` (PyBaMM's
solver), and the predictor says so (``PredictorCore.model_backend``).
"""

from __future__ import annotations

from battery_predictor.errors import SimulationError
from battery_predictor.params import PackParams
from battery_predictor.prediction.cell_runner import PackRunner

#: Values of ``PredictorConfig.simulator``.
BACKENDS = ("auto", "engine", "pybamm")


def pack_model(params: PackParams, backend: str = "auto"):
    """The pack model for ``params`` and a line saying which one it is and why.

    Parameters
    ----------
    params : PackParams
        The fitted pack.
    backend : {"auto", "engine", "pybamm"}
        ``auto``: the engine unless the params activate extensions (or it cannot be built);
        ``engine``: the engine or an error; ``pybamm``: PyBaMM stepping.

    Raises
    ------
    SimulationError
        When ``backend`` is ``"engine"`` and the engine does not cover the params.
    """
    if backend not in BACKENDS:
        raise SimulationError(f"simulator {backend!r} is not one of {', '.join(BACKENDS)}")
    if backend == "pybamm":
        return PackRunner(params), "pybamm (as configured)"
    if params.extensions and backend == "auto":
        return PackRunner(params), f"pybamm (the engine here runs no extensions: {', '.join(params.extensions)})"
    from battery_predictor.simulation.engine.segments import EnginePack

    try:
        return EnginePack(params), "engine (exact stepping of PyBaMM's discretised SPM)"
    except SimulationError as exc:
        if backend == "engine":
            raise
        return PackRunner(params), f"pybamm (the engine cannot run these params: {exc})"
