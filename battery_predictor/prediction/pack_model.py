"""The pack model the predictor runs: the SPM engine where it covers the params, else PyBaMM stepping.

Both answer ``run(start, segments, temperature_k)`` from an SOC or a carried state, with
``soc_of``, ``soc_bounds``, ``capacity_ah`` and ``concentrations``; they agree within 0.01 mV
(``test/unit/test_engine_segments.py``). The engine (exact stepping of PyBaMM's discretised SPM,
:mod:`battery_predictor.simulation.engine`) answers a route in milliseconds instead of about a
tenth of a second. It runs the extensions it covers (:func:`engine_pack`); params it does not
cover run on :class:`~.cell_runner.PackRunner` (PyBaMM's solver), and the predictor says so
(``PredictorCore.model_backend``, which the node logs as a warning and publishes in ``/diagnostics``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from battery_predictor.errors import SimulationError
from battery_predictor.params import PackParams
from battery_predictor.prediction.cell_runner import PackRunner, RunState
from battery_predictor.simulation.base import SegmentRun
from battery_predictor.simulation.engine.segments import EnginePack, EngineState
from battery_predictor.simulation.extensions import (
    EA_SERIES,
    current_offset_a,
    extension_value,
    series_resistance_factor,
    weak_group_fraction,
)

#: Values of ``PredictorConfig.simulator``.
BACKENDS = ("auto", "engine", "pybamm")


#: Where a run starts: an SOC, or the state a run of the same model returned.
RunStart = float | RunState | EngineState



class PackModel(Protocol):
    """The pack model the predictor runs: :class:`~.cell_runner.PackRunner` (PyBaMM stepping) or
    :class:`~battery_predictor.simulation.engine.segments.EnginePack` (the engine).

    A run starts from an SOC or from a state a run of the same model returned; each model has its own
    state type, so the state is ``Any`` here.
    """

    @property
    def soc_bounds(self) -> tuple[float, float]:
        """Widest SOC range (low, high) a run may start from (the scale may extend beyond 0..1)."""

    @property
    def capacity_ah(self) -> float:
        """Usable pack capacity between 0 % and 100 % SOC, Ah."""

    def concentrations(self, soc: float) -> tuple[float, float]:
        """Initial (c_n, c_p) in mol/m3 at ``soc``."""

    def soc_of(self, state: Any) -> float:
        """The SOC of a state a run returned."""

    def run(self, start: Any, segments: Sequence[tuple[float, float]], temperature_k: float) -> SegmentRun:
        """Run ``segments`` ((duration s, pack current A) pairs) from an SOC or a state at ``temperature_k`` (K)."""

    def __hash__(self) -> int:
        """Models are hashable: caches of the OCV slope are keyed on the model."""


def pack_model(params: PackParams, backend: str = "auto") -> tuple[PackModel, str]:
    """The pack model for ``params`` and a line saying which one it is and why.

    Parameters
    ----------
    params : PackParams
        The fitted pack.
    backend : {"auto", "engine", "pybamm"}
        ``auto``: the engine where it covers the params (:func:`engine_pack`), else PyBaMM stepping
        with the reason; ``engine``: the engine or an error; ``pybamm``: PyBaMM stepping.

    Raises
    ------
    SimulationError
        When ``backend`` is ``"engine"`` and the engine does not cover the params.
    """
    if backend not in BACKENDS:
        raise SimulationError(f"simulator {backend!r} is not one of {', '.join(BACKENDS)}")
    if backend == "pybamm":
        return PackRunner(params), "pybamm (as configured)"
    try:
        pack = engine_pack(params)
    except SimulationError as exc:
        if backend == "engine":
            raise
        return PackRunner(params), f"{FALLBACK_PREFIX}{exc})"
    extensions = f", extensions {', '.join(params.extensions)}" if params.extensions else ""
    return pack, f"engine (exact stepping of PyBaMM's discretised SPM{extensions})"


#: How :func:`pack_model`'s line starts when the engine could not run the params.
FALLBACK_PREFIX = "pybamm (the engine cannot run these params: "


def engine_pack(params: PackParams) -> EnginePack:
    """The engine's pack for ``params``, with the values its extensions need.

    ``current_offset`` (the cells carry reading - offset), ``cell_imbalance`` (the weak group),
    ``temperature`` (``R_eq``'s Arrhenius factor with the cold cell resistance; the window, kinetics
    and diffusivities are in PyBaMM's model the engine extracts), ``resistance_growth`` (PyBaMM's
    contact resistance, in the extracted voltage) and the lumped thermal option run on the engine
    within 0.02 mV of :class:`~.cell_runner.PackRunner` (``test/unit/test_pack_model_extensions.py``).

    Raises
    ------
    SimulationError
        When the engine does not cover the params (another model, ``electrolyte_transport``,
        ``hysteresis``, a diffusivity that depends on the stoichiometry such as the ``temperature``
        extension's extra activation energy at full lithiation).
    """
    temperature = "temperature" in params.extensions
    return EnginePack(params, current_offset_a=current_offset_a(params), weak_fraction=weak_group_fraction(params),
                      series_activation_j_mol=extension_value(params, EA_SERIES) if temperature else None,
                      resistance_factor=(lambda t: series_resistance_factor(params, t)) if temperature else None)
