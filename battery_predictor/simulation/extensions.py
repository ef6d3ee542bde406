"""Model extensions: what each one a params file may activate changes in the PyBaMM model.

A params file activates extensions with ``extensions: [name, ...]`` (the names are
:data:`~battery_predictor.params.EXTENSION_NAMES`; ``battery-predictor diagnose`` names the one
that fixes a model error and writes it with ``--write-params``); their values live in
``cell.extra`` (PyBaMM ``"Name [unit]"`` keys, or our own keys with a unit where PyBaMM has
no parameter). Every simulator and the predictor's :class:`~battery_predictor.prediction.cell_runner.PackRunner`
build their model through :func:`battery_predictor.simulation.cell_setup.build_model` and their
parameter values through :func:`~battery_predictor.simulation.cell_setup.prepared_parameter_values`,
which call the hooks of this module:

=========================  =======================================================================
extension                  what it changes
=========================  =======================================================================
``temperature``            Arrhenius temperature dependence of both particle diffusivities (``...
                           diffusivity activation energy [J.mol-1]``), which Chen2020 and Prada2013
                           lack, with an extra positive-electrode activation energy towards full
                           lithiation (:data:`EA_POS_FULL`: a temperature-dependent accessible
                           capacity), an extra activation energy of both exchange-current densities
                           (:data:`EA_KINETICS`, on top of the base set's own), and of the pack's
                           series resistance ``R_eq`` the reference fit found (``Series resistance
                           activation energy [J.mol-1]``; :func:`series_resistance_factor`, applied by
                           the fast simulator and the predictor's runner); a stoichiometry window of
                           both electrodes that narrows below the anchor temperature and widens above it
                           (:data:`COLD_WINDOW`, :func:`cold_window_scale`: an accessible capacity
                           that follows the temperature at any rate); an Arrhenius charge-transfer
                           resistance that grows as the negative surface empties, whose excess over
                           the anchor temperature drops the voltage in PyBaMM's model
                           (:data:`COLD_CHARGE_TRANSFER`, :func:`charge_transfer_excess_ohm`). The cell is isothermal at
                           the given (measured) temperature, as the predictor runs at the last
                           measured temperature; with ``Total heat transfer coefficient [W.m-2.K-1]``
                           in ``cell.extra`` (fitted on data without a temperature measurement) the
                           PyBaMM ``{"thermal": "lumped"}`` option adds self-heating. Thermal values a
                           base set lacks (Prada2013) come from Chen2020 and the cell volume
                           (:data:`THERMAL_DEFAULTS`).
``capacity_fade``          no new physics: loss of active material and of cyclable lithium are the
                           PyBaMM volume fractions and initial concentrations written to
                           ``cell.extra`` by ``diagnose --write-params``.
``resistance_growth``      PyBaMM ``{"contact resistance": "true"}`` with ``Contact resistance [Ohm]``.
``current_offset``         the model is driven by (measured current - ``Current sensor offset [A]``)
                           (:func:`current_offset_a`, applied where a recording's current becomes a
                           load, ``fitting.problem.request_for_recording``, and to every current the
                           predictor's runner is given).
``cell_imbalance``         the cells of one series position hold ``Weak series group capacity
                           fraction`` of the others' capacity (their electrode area is scaled): per-cell
                           values for liionpack (:func:`imbalance_cell_inputs`); the fast simulator adds
                           a second cell for the weak group (:func:`weak_group_params`), the engine a
                           second parameter set of the same extraction (electrode height scaled), and
                           so does the predictor's runner (``prediction.cell_runner.PackRunner``). The
                           fit searches the fraction (``weak_group_capacity_fraction``).
``electrolyte_transport``  the SPMe (electrolyte concentration and potential) instead of the SPM,
                           with the fitted Bruggeman exponent ``Electrolyte Bruggeman coefficient
                           [-]`` (tortuosity: effective transport = eps ** b) in every region.
``hysteresis``             PyBaMM's one-state OCP hysteresis (``"open-circuit potential": ("single",
                           "Axen")``, Axen et al. 2022) in the positive electrode: lithiation and
                           delithiation OCP = OCP -/+ ``Positive electrode OCP hysteresis half-width
                           [V]``, decay rate ``Positive particle hysteresis decay rate [-]`` and
                           initial state ``Initial hysteresis state in positive electrode [-]``
                           (-1 = discharge branch, +1 = charge branch). In the SPM the positive
                           particles' interfacial current is uniform, so PyBaMM's hysteresis ODE is
                           ``dh/dt = K |I| / Q_p (s - h)`` with ``s = -sign(I)`` and ``Q_p`` the
                           positive electrode's theoretical charge (Plett's one-state hysteresis), and
                           the cell voltage moves by ``half-width * h``: the engine steps it exactly
                           on piecewise-constant currents (:func:`hysteresis_states`,
                           :mod:`battery_predictor.simulation.engine.hysteresis`).
=========================  =======================================================================
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from battery_predictor.errors import SimulationError
from battery_predictor.ocp import initial_stoichiometries
from battery_predictor.params import PackParams
from battery_predictor.simulation.engine.pack import series_resistance_factor as arrhenius_factor
from battery_predictor.simulation.network import equivalent_network_resistance_ohm

if TYPE_CHECKING:
    import pybamm

#: Gas constant in J/(mol K).
R_GAS = 8.314462618

EA_NEG = "Negative particle diffusivity activation energy [J.mol-1]"
EA_POS = "Positive particle diffusivity activation energy [J.mol-1]"
EA_SERIES = "Series resistance activation energy [J.mol-1]"
#: Activation energy (J/mol) added to the exchange-current densities of both electrodes (on top of the
#: Arrhenius factor a base set's own functions may carry): ``j0(T) = j0_set(T) exp(-E/R (1/T - 1/T_ref))``.
EA_KINETICS = "Exchange-current density extra activation energy [J.mol-1]"
#: Activation energy (J/mol) the positive particle diffusivity gains towards full lithiation, weighted
#: by :func:`lithiation_weight` (0 up to half lithiation, 1 at full): as the layered oxide runs out of
#: vacancies the hopping barrier rises, so in the cold the surface saturates early and the accessible
#: capacity falls, while at the reference temperature nothing changes.
EA_POS_FULL = "Positive particle diffusivity extra activation energy at full lithiation [J.mol-1]"
#: Stoichiometry above which :data:`EA_POS_FULL` starts to act.
LITHIATION_ONSET = 0.5
#: Ohmic cell resistance that follows Arrhenius (electrolyte, SEI) and that the SPM lacks, stated at the anchor
#: temperature (Ohm per cell; :data:`ANCHOR_TEMPERATURE`, 298.15 K when absent - the key keeps its name).
#: Only its *excess* over the anchor is added, ``R (exp(E/R (1/T - 1/T_anchor)) - 1)``: at the anchor the
#: identified model is unchanged.
COLD_RESISTANCE = "Arrhenius cell resistance at 298.15 K [Ohm]"
#: Activation energy of :data:`COLD_RESISTANCE` (J/mol): 30 kJ/mol, between the electrolyte's ionic
#: conductivity (10-20 kJ/mol) and the SEI / charge transfer (50-70 kJ/mol) of graphite cells.
COLD_RESISTANCE_ACTIVATION_J_MOL = 30000.0
#: Fraction of both electrodes' stoichiometry windows (from the charged end, 100 % SOC, towards the
#: discharged end) that becomes inaccessible per kelvin below the anchor temperature (1/K;
#: :data:`ANCHOR_TEMPERATURE`, 298.15 K when absent - the key keeps its name): the cell's accessible capacity
#: falls in the cold at any rate, whichever electrode ends the discharge. See :func:`cold_window_scale`.
COLD_WINDOW = "Stoichiometry window loss per kelvin below 298.15 K [K-1]"
#: Charge-transfer resistance of the cell (Ohm per cell) at the anchor temperature and at half lithiation of the
#: negative electrode's surface, Arrhenius with :data:`COLD_RESISTANCE_ACTIVATION_J_MOL` and following the inverse
#: of the exchange-current density's concentration dependence (:func:`charge_transfer_excess_ohm`). Only its excess
#: over the anchor temperature enters the cell voltage (:func:`apply_extension_model`): 0 at the anchor, and in the
#: cold it grows most towards the discharged end, where the negative surface empties.
COLD_CHARGE_TRANSFER = "Arrhenius charge-transfer resistance at the anchor temperature [Ohm]"
#: PyBaMM function parameter (of the negative surface stoichiometry and the cell temperature) that the model hook
#: subtracts, times the cell current, from the voltage; defined by :func:`apply_extension_parameter_values`.
CHARGE_TRANSFER_EXCESS = "Charge-transfer resistance excess over the anchor temperature [Ohm]"
#: Default reference temperature (K) of :data:`COLD_WINDOW` and :data:`COLD_RESISTANCE`, used when the params
#: carry no :data:`ANCHOR_TEMPERATURE`.
COLD_REFERENCE_K = 298.15
#: Temperature (K) at which the identified model holds, where the window and the Arrhenius cell resistance of
#: the extension ``temperature`` change nothing: the diagnosis sets it from the reference recordings
#: (:func:`~battery_predictor.diagnosis.reference.reference_anchor_k`); :data:`COLD_REFERENCE_K` when absent.
ANCHOR_TEMPERATURE = "Temperature extension anchor temperature [K]"
HEAT_TRANSFER = "Total heat transfer coefficient [W.m-2.K-1]"
CONTACT_RESISTANCE = "Contact resistance [Ohm]"
CURRENT_OFFSET = "Current sensor offset [A]"
WEAK_FRACTION = "Weak series group capacity fraction"
BRUGGEMAN = "Electrolyte Bruggeman coefficient [-]"
HYS_HALF_WIDTH = "Positive electrode OCP hysteresis half-width [V]"
HYS_DECAY = "Positive particle hysteresis decay rate [-]"
HYS_INITIAL = "Initial hysteresis state in positive electrode [-]"
#: Rate (1/s) at which the hysteresis state relaxes towards 0 (the mean of the two branches) on its own,
#: at rest as under load: ``dh/dt = K |I| / Q_p (s - h) - r h``. 0 (the default): no relaxation, PyBaMM's Axen model.
HYS_RELAX = "Positive electrode hysteresis relaxation rate [s-1]"
#: Activation energy (J/mol) of the hysteresis half-width: ``M(T) = M exp(E/R (1/T - 1/T_anchor))`` (``T_anchor``:
#: :data:`ANCHOR_TEMPERATURE`, 298.15 K when absent): positive = the hysteresis shrinks as the cell warms. 0 (the
#: default): the half-width does not depend on the temperature.
HYS_ACTIVATION = "Positive electrode OCP hysteresis half-width activation energy [J.mol-1]"

#: PyBaMM keys the Bruggeman exponent of :data:`BRUGGEMAN` is copied to.
BRUGGEMAN_KEYS = (
    "Negative electrode Bruggeman coefficient (electrolyte)",
    "Separator Bruggeman coefficient (electrolyte)",
    "Positive electrode Bruggeman coefficient (electrolyte)",
)
#: PyBaMM keys of the Axen hysteresis model in the positive electrode.
PYBAMM_HYS_DECAY_KEYS = ("Positive particle lithiation hysteresis decay rate",
                         "Positive particle delithiation hysteresis decay rate")
PYBAMM_HYS_INITIAL_KEY = "Initial hysteresis state in positive electrode"

_OPTIONS: dict[str, dict[str, Any]] = {
    "resistance_growth": {"contact resistance": "true"},
    "hysteresis": {"open-circuit potential": ("single", "Axen")},
}

#: Default values of each extension's own keys (the extension is then present but neutral, except
#: the hysteresis, whose neutral value would be no hysteresis).
EXTENSION_DEFAULTS: dict[str, dict[str, float]] = {
    "temperature": {EA_NEG: 0.0, EA_POS: 0.0, EA_SERIES: 0.0, EA_KINETICS: 0.0, EA_POS_FULL: 0.0, COLD_RESISTANCE: 0.0,
                    COLD_WINDOW: 0.0, COLD_CHARGE_TRANSFER: 0.0, ANCHOR_TEMPERATURE: COLD_REFERENCE_K},
    "resistance_growth": {CONTACT_RESISTANCE: 0.0},
    "current_offset": {CURRENT_OFFSET: 0.0},
    "cell_imbalance": {WEAK_FRACTION: 1.0},
    "electrolyte_transport": {BRUGGEMAN: 1.5},
    "hysteresis": {HYS_HALF_WIDTH: 0.0, HYS_DECAY: 50.0, HYS_INITIAL: -1.0, HYS_RELAX: 0.0, HYS_ACTIVATION: 0.0,
                   ANCHOR_TEMPERATURE: COLD_REFERENCE_K},
}

#: Thermal values a lumped model needs, taken from Chen2020 (LG M50) where the base set lacks them.
THERMAL_DEFAULTS = {
    "Negative current collector thickness [m]": 1.2e-05,
    "Positive current collector thickness [m]": 1.6e-05,
    "Negative current collector density [kg.m-3]": 8960.0,
    "Positive current collector density [kg.m-3]": 2700.0,
    "Negative current collector specific heat capacity [J.kg-1.K-1]": 385.0,
    "Positive current collector specific heat capacity [J.kg-1.K-1]": 897.0,
    "Negative current collector conductivity [S.m-1]": 58411000.0,
    "Positive current collector conductivity [S.m-1]": 36914000.0,
    "Negative electrode density [kg.m-3]": 1657.0,
    "Positive electrode density [kg.m-3]": 3262.0,
    "Separator density [kg.m-3]": 397.0,
    "Negative electrode specific heat capacity [J.kg-1.K-1]": 700.0,
    "Positive electrode specific heat capacity [J.kg-1.K-1]": 700.0,
    "Separator specific heat capacity [J.kg-1.K-1]": 700.0,
    "Total heat transfer coefficient [W.m-2.K-1]": 10.0,
}
#: Height / diameter of the cylindrical cell assumed when the cooling surface is derived from the
#: cell volume (18650: 3.6, 21700: 3.3, 32700: 2.2; 3.0 is within 10 % of the area for all).
_CYLINDER_ASPECT = 3.0


def extension_model_options(params: PackParams) -> dict[str, Any]:
    """PyBaMM model options implied by the params' active extensions."""
    opts: dict = {}
    for ext in params.extensions:
        opts.update(_OPTIONS.get(ext, {}))
    if "temperature" in params.extensions and HEAT_TRANSFER in params.extra:
        opts["thermal"] = "lumped"  # self-heating was fitted (no measured temperature)
    return opts


def series_resistance_factor(params: PackParams, temperature_k: ArrayLike) -> np.ndarray:
    """Arrhenius factor of the pack's series resistance ``R_eq`` at ``temperature_k`` (1 without the extension).

    The extension ``temperature`` makes the series resistance the reference fit found (interconnect
    plus the cell's ohmic part the SPM lacks) follow ``exp(E/R (1/T - 1/T_ref))``, T_ref = 298.15 K, and
    adds the Arrhenius cell resistance's excess over the anchor temperature (:data:`ANCHOR_TEMPERATURE`).
    """
    if "temperature" not in params.extensions:
        return np.ones_like(np.asarray(temperature_k, dtype=float))
    factor = arrhenius_factor(temperature_k, extension_value(params, EA_SERIES))
    r_cold = extension_value(params, COLD_RESISTANCE)
    if r_cold:  # the cells' Arrhenius excess, carried by the pack's series resistance
        ic = params.interconnect
        r_eq = equivalent_network_resistance_ohm(params.series, params.parallel, ic["r_b_ohm"], ic["r_c_ohm"],
                                                 ic["r_t_ohm"])
        if r_eq > 0:
            excess = cold_resistance_excess_ohm(r_cold, temperature_k, extension_value(params, ANCHOR_TEMPERATURE))
            factor = factor + params.series / params.parallel * excess / r_eq
    return factor


def cold_resistance_excess_ohm(r_ref_ohm: float, temperature_k: ArrayLike, anchor_k: float = COLD_REFERENCE_K) -> np.ndarray:
    """Excess of the Arrhenius cell resistance over its value at the anchor temperature (Ohm per cell).

    Parameters
    ----------
    r_ref_ohm : float
        The cell resistance at ``anchor_k`` (Ohm per cell) that follows Arrhenius with
        :data:`COLD_RESISTANCE_ACTIVATION_J_MOL`.
    temperature_k : float or numpy.ndarray
        Cell temperature (K).
    anchor_k : float
        Temperature (K) at which the identified model holds (:data:`ANCHOR_TEMPERATURE`): the excess is 0
        there, positive below, negative above.

    Returns
    -------
    numpy.ndarray
        ``R (exp(E/R (1/T - 1/T_anchor)) - 1)`` in Ohm per cell.
    """
    return r_ref_ohm * (arrhenius_factor(temperature_k, COLD_RESISTANCE_ACTIVATION_J_MOL, float(anchor_k)) - 1.0)


def extension_model_type(params: PackParams) -> str:
    """Model class name for ``params``: SPMe when ``electrolyte_transport`` is active on an SPM."""
    if "electrolyte_transport" in params.extensions and params.model == "SPM":
        return "SPMe"
    return params.model


def extension_value(params: PackParams, key: str) -> float:
    """Value of an extension key: ``cell.extra`` / fitted / manual, else the extension default."""
    vals = params.cell_values
    if key in vals:
        return float(vals[key])
    for defaults in EXTENSION_DEFAULTS.values():
        if key in defaults:
            return float(defaults[key])
    raise KeyError(key)


#: The stoichiometries each electrode's cold window narrows towards: the charged end of the cell they are
#: computed for (:func:`cold_window_anchors`), or fixed in ``cell.extra`` (:func:`with_cold_window_anchors`).
COLD_ANCHOR_KEYS = ("Negative electrode cold window anchor stoichiometry [-]",
                    "Positive electrode cold window anchor stoichiometry [-]")


def cold_window_active(params: PackParams) -> bool:
    """True when the ``temperature`` extension narrows the stoichiometry windows (a nonzero :data:`COLD_WINDOW`)."""
    return "temperature" in params.extensions and extension_value(params, COLD_WINDOW) != 0.0


def cold_window_anchors(params: PackParams, pv: pybamm.ParameterValues | None = None) -> tuple[float, float] | None:
    """(negative, positive) anchor stoichiometries of the cold window: ``cell.extra``'s, else the charged end.

    ``pv`` are the params' PyBaMM values when the caller has them. None when the cell has no
    electrode balance at its upper voltage (then no window narrows).
    """
    vals = params.cell_values
    if all(k in vals for k in COLD_ANCHOR_KEYS):
        return float(vals[COLD_ANCHOR_KEYS[0]]), float(vals[COLD_ANCHOR_KEYS[1]])
    return _charged_stoichiometries(params, pv if pv is not None else params.parameter_values())


def with_cold_window_anchors(params: PackParams) -> PackParams:
    """``params`` with its cold-window anchors fixed in ``cell.extra`` (unchanged without an active window).

    A fit moves the electrode capacities; with the anchors of its start fixed, every candidate narrows
    towards the same stoichiometries, so one engine extraction serves them all and the cost of a candidate
    does not depend on the candidates before it.
    """
    if not cold_window_active(params) or all(k in params.extra for k in COLD_ANCHOR_KEYS):
        return params
    anchors = cold_window_anchors(params)
    if anchors is None:
        return params
    return replace(params, extra={**params.extra, **dict(zip(COLD_ANCHOR_KEYS, anchors, strict=True))})


#: Extension keys a fit may search (``fitting.identifiable``), by extension.
FITTED_EXTENSION_KEYS: dict[str, tuple[str, ...]] = {"hysteresis": (HYS_HALF_WIDTH, HYS_DECAY, HYS_INITIAL, HYS_RELAX,
                                                                    HYS_ACTIVATION),
                                                     "cell_imbalance": (WEAK_FRACTION,),
                                                     "electrolyte_transport": (BRUGGEMAN,)}


def with_fitted_extension_keys(params: PackParams) -> PackParams:
    """``params`` with the keys a fit searches of its active extensions in ``cell.extra`` (their defaults when absent).

    :meth:`~battery_predictor.params.PackParams.with_values` then writes fitted values of these keys to
    ``cell.extra``, where a params file keeps the extensions' values (``cell.fitted`` takes PyBaMM keys only).
    """
    missing = {key: extension_value(params, key) for ext in params.extensions
               for key in FITTED_EXTENSION_KEYS.get(ext, ()) if key not in params.extra}
    return replace(params, extra={**params.extra, **missing}) if missing else params


def current_offset_a(params: PackParams) -> float:
    """Current sensor offset in A (pack level) when ``current_offset`` is active, else 0.

    The model is driven by ``measured current - offset``.
    """
    if "current_offset" not in params.extensions:
        return 0.0
    return extension_value(params, CURRENT_OFFSET)


def weak_group_fraction(params: PackParams) -> float:
    """Capacity fraction of the weak series group when ``cell_imbalance`` is active, else 1."""
    if "cell_imbalance" not in params.extensions or params.series < 2:
        return 1.0
    return extension_value(params, WEAK_FRACTION)


def group_socs(soc: float, weak_fraction: float) -> tuple[float, float]:
    """(normal groups' SOC, weak group's SOC) of a pack at ``soc`` whose groups were full together.

    Series groups carry the same current, so once they were all full at once (a charge to full, which
    the battery management's balancing brings about) each has given the same charge ``q`` since, and a
    group's SOC is ``1 - q / C_group``. The pack's ``soc`` is the SOC of the group that empties first
    (the weak group when ``weak_fraction`` < 1). A pack that drew charge since its groups were full is
    never at one SOC in all groups: the weak group is further down.

    Parameters
    ----------
    soc : float
        The pack's SOC (PyBaMM's linear scale of the limiting group; may lie outside 0..1).
    weak_fraction : float
        The weak group's capacity relative to a normal group's (> 0; 1: no weak group).
    """
    limiting = min(1.0, weak_fraction)
    return 1.0 - (1.0 - soc) * limiting, 1.0 - (1.0 - soc) * limiting / weak_fraction


def pack_soc_bounds(cell_bounds: tuple[float, float], weak_fraction: float) -> tuple[float, float]:
    """The pack SOCs (low, high) whose groups (:func:`group_socs`) all lie within a cell's ``cell_bounds``.

    Each group's SOC is ``1 - (1 - soc) a`` with ``a`` in (0, 1], so it lies within (low, high) for
    ``soc`` in ``(1 - (1 - low) / a, 1 - (1 - high) / a)``; the pack's range is where every group's is.
    """
    low, high = cell_bounds
    if weak_fraction == 1.0:
        return low, high
    limiting = min(1.0, weak_fraction)
    slopes = (limiting, limiting / weak_fraction)
    return max(1.0 - (1.0 - low) / a for a in slopes), min(1.0 - (1.0 - high) / a for a in slopes)


def with_weak_group(params: PackParams, fraction: float) -> PackParams:
    """``params`` with one weak series group whose cells hold ``fraction`` (0..1] of the others' capacity.

    The extension ``cell_imbalance`` is added when absent; its value is set in ``cell.extra``.
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"weak group fraction must lie in (0, 1], got {fraction}")
    extensions = tuple(dict.fromkeys((*params.extensions, "cell_imbalance")))
    return replace(params, extensions=extensions, extra={**params.extra, WEAK_FRACTION: float(fraction)})


def imbalance_cell_inputs(params: PackParams) -> dict[str, np.ndarray] | None:
    """Per-cell ``Electrode height [m]`` for liionpack: series position 0 of every string is weak.

    liionpack numbers cells string by string (``parallel-strings`` netlist), so cell
    ``k * series`` is the first cell of string ``k``. With every string holding one weak cell
    at the same position, the strings stay identical and the pack equals the two-group
    model of the fast paths. None when ``cell_imbalance`` is not active.
    """
    frac = weak_group_fraction(params)
    if frac == 1.0:
        return None
    height = float(params.parameter_values()["Electrode height [m]"])
    heights = np.full(params.n_cells, height)
    heights[:: params.series] = height * frac
    return {"Electrode height [m]": heights}


def weak_group_params(params: PackParams) -> PackParams:
    """The params of one cell of the weak group (electrode height scaled), extensions kept otherwise.

    The group's cells sit in parallel with identical per-area properties, so they share the current
    in proportion to their area and the group behaves as one cell of the scaled area.
    """
    frac = weak_group_fraction(params)
    height = float(params.parameter_values()["Electrode height [m]"])
    extra = dict(params.extra)
    extra["Electrode height [m]"] = height * frac
    extra[WEAK_FRACTION] = 1.0
    return replace(params, extra=extra)


def cooling_area_m2(volume_m3: float) -> float:
    """Surface of a cylinder of ``volume_m3`` with height = :data:`_CYLINDER_ASPECT` x diameter."""
    d = (4.0 * volume_m3 / (math.pi * _CYLINDER_ASPECT)) ** (1.0 / 3.0)
    return math.pi * d * (_CYLINDER_ASPECT * d) + 2.0 * math.pi * (d / 2.0) ** 2


def lithiation_weight(sto: Any) -> Any:
    """0 below :data:`LITHIATION_ONSET`, rising quadratically to 1 at full lithiation (numbers or PyBaMM symbols)."""
    import pybamm

    x = (sto - LITHIATION_ONSET) / (1.0 - LITHIATION_ONSET)
    if isinstance(x, pybamm.Symbol):
        return pybamm.maximum(x, 0.0) ** 2
    return np.maximum(x, 0.0) ** 2


def _arrhenius_diffusivity(d_ref: float, ea_key: str, t_ref: float,
                           full_key: str | None = None) -> Callable[[pybamm.Symbol, pybamm.Symbol], pybamm.Symbol]:
    import pybamm

    def diffusivity(sto: pybamm.Symbol, T: pybamm.Symbol) -> pybamm.Symbol:
        ea = pybamm.Parameter(ea_key)
        if full_key is not None:
            ea = ea + pybamm.Parameter(full_key) * lithiation_weight(sto)
        return d_ref * pybamm.exp(ea / R_GAS * (1.0 / t_ref - 1.0 / T))

    return diffusivity


def _arrhenius_exchange_current(j0: Callable[..., pybamm.Symbol], t_ref: float) -> Callable[..., pybamm.Symbol]:
    """``j0`` (a base-set function of c_e, c_s_surf, c_s_max, T) times the extra Arrhenius factor of :data:`EA_KINETICS`."""
    import pybamm

    def exchange_current(c_e: pybamm.Symbol, c_s_surf: pybamm.Symbol, c_s_max: pybamm.Symbol,
                         T: pybamm.Symbol) -> pybamm.Symbol:
        ea = pybamm.Parameter(EA_KINETICS)
        return j0(c_e, c_s_surf, c_s_max, T) * pybamm.exp(ea / R_GAS * (1.0 / t_ref - 1.0 / T))

    return exchange_current


def cold_window_scale(loss_per_k: Any, temperature_k: Any, anchor_k: Any = COLD_REFERENCE_K) -> Any:
    """How much faster the electrodes' stoichiometries advance in the cold: ``1 / (1 - loss (T_anchor - T))`` (-).

    With the window loss of :data:`COLD_WINDOW` each electrode's open-circuit potential is evaluated at
    its charged-end stoichiometry plus ``scale`` times the distance from it (:func:`_cold_window_ocp`):
    both windows, and with them the cell's open-circuit voltage over the charge drawn, are compressed
    by ``1 / scale`` - an equilibrium loss of accessible capacity, present at any rate, that comes back
    as the cell warms (and a wider window above the anchor). 1 at the anchor temperature ``anchor_k``
    (K, :data:`ANCHOR_TEMPERATURE`, default 298.15 K); numbers or PyBaMM symbols.
    """
    import pybamm

    if any(isinstance(x, pybamm.Symbol) for x in (loss_per_k, temperature_k, anchor_k)):
        below = anchor_k - temperature_k
        return 1.0 / pybamm.maximum(1.0 - loss_per_k * below, 0.2)
    below = float(anchor_k) - np.asarray(temperature_k, dtype=float)
    return 1.0 / np.maximum(1.0 - float(loss_per_k) * below, 0.2)


def arrhenius_ratio(activation_j_mol: Any, temperature_k: Any, anchor_k: Any = COLD_REFERENCE_K) -> Any:
    """``exp(E/R (1/T - 1/T_anchor))``: an Arrhenius resistance (or time constant) at ``temperature_k`` over its
    value at ``anchor_k`` (K; activation energy ``E`` in J/mol). Numbers (a numpy array) or PyBaMM symbols."""
    import pybamm

    if any(isinstance(x, pybamm.Symbol) for x in (activation_j_mol, temperature_k, anchor_k)):
        return pybamm.exp(activation_j_mol / R_GAS * (1.0 / temperature_k - 1.0 / anchor_k))
    return arrhenius_factor(temperature_k, float(activation_j_mol), float(anchor_k))


def charge_transfer_shape(sto: Any) -> Any:
    """``j0(1/2) / j0(sto)`` for an exchange-current density ``j0 ~ sqrt(sto (1 - sto))`` (Butler-Volmer, symmetric)
    (-): the charge-transfer resistance at stoichiometry ``sto`` over its value at half lithiation. 1 at 0.5, 2.1 at
    0.06. Numbers or PyBaMM symbols; ``sto`` is kept within 1e-3..1-1e-3."""
    import pybamm

    if isinstance(sto, pybamm.Symbol):
        s = pybamm.maximum(pybamm.minimum(sto, 1.0 - 1e-3), 1e-3)
        return 0.5 / pybamm.sqrt(s * (1.0 - s))
    s = np.clip(np.asarray(sto, dtype=float), 1e-3, 1.0 - 1e-3)
    return 0.5 / np.sqrt(s * (1.0 - s))


def charge_transfer_excess_ohm(r_anchor_ohm: Any, sto: Any, temperature_k: Any, anchor_k: Any = COLD_REFERENCE_K,
                               loss_per_k: Any = 0.0, sto_charged: float | None = None) -> Any:
    """Excess of the Arrhenius charge-transfer resistance over its value at the anchor temperature (Ohm per cell).

    ``R (exp(E/R (1/T - 1/T_anchor)) - 1) j0(1/2) / j0(s)`` with ``E`` = :data:`COLD_RESISTANCE_ACTIVATION_J_MOL` and
    ``s`` the negative electrode's surface stoichiometry, moved as the cold window moves its open-circuit potential
    (``sto_charged + (sto - sto_charged) * cold_window_scale``, when ``sto_charged`` is given): the resistance
    grows in the cold, and most where the accessible part of the electrode runs empty. 0 at the anchor.

    Parameters
    ----------
    r_anchor_ohm : float or pybamm.Symbol
        Charge-transfer resistance (Ohm per cell) at ``anchor_k`` and half lithiation (:data:`COLD_CHARGE_TRANSFER`).
    sto : float, numpy.ndarray or pybamm.Symbol
        Negative electrode surface stoichiometry (-).
    temperature_k : float, numpy.ndarray or pybamm.Symbol
        Cell temperature (K).
    anchor_k : float or pybamm.Symbol
        Temperature (K) at which the identified model holds (:data:`ANCHOR_TEMPERATURE`).
    loss_per_k : float or pybamm.Symbol
        Cold window loss (1/K, :data:`COLD_WINDOW`).
    sto_charged : float, optional
        The electrode's stoichiometry at 100 % SOC (the window's fixed end); None: no window.
    """
    if sto_charged is not None:
        sto = sto_charged + (sto - sto_charged) * cold_window_scale(loss_per_k, temperature_k, anchor_k)
    ratio = arrhenius_ratio(COLD_RESISTANCE_ACTIVATION_J_MOL, temperature_k, anchor_k)
    return r_anchor_ohm * (ratio - 1.0) * charge_transfer_shape(sto)


def _cold_window_ocp(ocp: Callable[[pybamm.Symbol], pybamm.Symbol],
                     sto_charged: float) -> Callable[[pybamm.Symbol], pybamm.Symbol]:
    """An electrode OCP with its window narrowed at the cell's (ambient) temperature (:data:`COLD_WINDOW`).

    ``sto_charged`` is the electrode's stoichiometry at 100 % SOC: the OCP is evaluated at
    ``sto_charged + (sto - sto_charged) * scale`` (clipped to the electrode's range). The temperature
    is PyBaMM's ``Ambient temperature [K]``: the cell's own temperature in the isothermal model, which
    the diagnosis drives with the measured temperature and the predictor runs at the last measured one
    (with the lumped thermal option the window follows the ambient, not the self-heated cell).
    """
    import pybamm

    def narrowed(sto: pybamm.Symbol) -> pybamm.Symbol:
        t_amb = pybamm.FunctionParameter("Ambient temperature [K]", {
            "Distance across electrode width [m]": pybamm.Scalar(0.0),
            "Distance across electrode height [m]": pybamm.Scalar(0.0),
            "Time [s]": pybamm.t})
        scale = cold_window_scale(pybamm.Parameter(COLD_WINDOW), t_amb, pybamm.Parameter(ANCHOR_TEMPERATURE))
        moved = sto_charged + (sto - sto_charged) * scale
        return ocp(pybamm.maximum(pybamm.minimum(moved, 1.0 - 1e-6), 1e-6))

    return narrowed


def _charge_transfer_excess_function(sto_charged: float | None) -> Callable[[pybamm.Symbol, pybamm.Symbol], pybamm.Symbol]:
    """:data:`CHARGE_TRANSFER_EXCESS` as PyBaMM function of (negative surface stoichiometry, cell temperature)."""
    import pybamm

    def excess(sto: pybamm.Symbol, temperature_k: pybamm.Symbol) -> pybamm.Symbol:
        return charge_transfer_excess_ohm(pybamm.Parameter(COLD_CHARGE_TRANSFER), sto, temperature_k,
                                          pybamm.Parameter(ANCHOR_TEMPERATURE), pybamm.Parameter(COLD_WINDOW),
                                          sto_charged)

    return excess


def _electrode_scale(pv: pybamm.ParameterValues, domain: str) -> float:
    """``eps L c_max`` of an electrode (its capacity up to the factor ``F A / 3600`` both share)."""
    return (float(pv[f"{domain} electrode active material volume fraction"])
            * float(pv[f"{domain} electrode thickness [m]"])
            * float(pv[f"Maximum concentration in {domain.lower()} electrode [mol.m-3]"]))


def _charged_stoichiometries(params: PackParams, pv: pybamm.ParameterValues) -> tuple[float, float] | None:
    """(x_100, y_100): both electrodes' stoichiometries at 100 % SOC of ``pv``, None when no such pair exists.

    The electrode balance of PyBaMM's ``get_min_max_stoichiometries`` (the cyclable lithium of the initial
    concentrations, the OCV at 100 % SOC, the OCPs at the reference temperature) solved on the OCP tables
    of :func:`battery_predictor.ocp.ocp_curves`: milliseconds instead of a PyBaMM solve per parameter set.
    """
    try:
        q_n, q_p = _electrode_scale(pv, "Negative"), _electrode_scale(pv, "Positive")
        q_li = (float(pv["Initial concentration in negative electrode [mol.m-3]"]) / float(
            pv["Maximum concentration in negative electrode [mol.m-3]"]) * q_n
                + float(pv["Initial concentration in positive electrode [mol.m-3]"]) / float(
                    pv["Maximum concentration in positive electrode [mol.m-3]"]) * q_p)
        keys = set(pv.keys())
        v_max = float(pv["Open-circuit voltage at 100% SOC [V]"] if "Open-circuit voltage at 100% SOC [V]" in keys
                      else pv["Upper voltage cut-off [V]"])
        t_ref = float(pv["Reference temperature [K]"]) if "Reference temperature [K]" in keys else 298.15
        return initial_stoichiometries(params, q_n, q_p, q_li, v_max, t_ref)
    except (TypeError, KeyError, SimulationError):  # function-valued inputs or no balance: no narrowing
        return None


def _shifted_ocp(ocp: Callable[[pybamm.Symbol], pybamm.Symbol], sign: float,
                 temperature_dependent: bool = False) -> Callable[[pybamm.Symbol], pybamm.Symbol]:
    """``ocp + sign M``, with ``M`` the half-width (at the ambient temperature when ``temperature_dependent``).

    As :func:`_cold_window_ocp`, the temperature is PyBaMM's ``Ambient temperature [K]``: the isothermal cell's,
    as the engine takes it (:func:`hysteresis_half_width_v`).
    """
    import pybamm

    def shifted(sto: pybamm.Symbol) -> pybamm.Symbol:
        m = pybamm.Parameter(HYS_HALF_WIDTH)
        if temperature_dependent:
            t_amb = pybamm.FunctionParameter("Ambient temperature [K]", {
                "Distance across electrode width [m]": pybamm.Scalar(0.0),
                "Distance across electrode height [m]": pybamm.Scalar(0.0),
                "Time [s]": pybamm.t})
            m = m * half_width_factor(pybamm.Parameter(HYS_ACTIVATION), t_amb, pybamm.Parameter(ANCHOR_TEMPERATURE))
        return ocp(sto) + sign * m

    return shifted


def half_width_factor(activation_j_mol: Any, temperature_k: Any, anchor_k: Any = COLD_REFERENCE_K) -> Any:
    """``exp(E/R (1/T - 1/T_anchor))``: the hysteresis half-width at ``temperature_k`` over its value at ``anchor_k``.

    Numbers (returns a numpy array) or PyBaMM symbols (:data:`HYS_ACTIVATION`).
    """
    return arrhenius_ratio(activation_j_mol, temperature_k, anchor_k)


def hysteresis_half_width_v(params: PackParams, temperature_k: float) -> float:
    """The hysteresis half-width ``M`` (V) of ``params`` at ``temperature_k`` (:data:`HYS_ACTIVATION`)."""
    m = extension_value(params, HYS_HALF_WIDTH)
    e = extension_value(params, HYS_ACTIVATION)
    if not e:
        return m
    return m * float(half_width_factor(e, temperature_k, extension_value(params, ANCHOR_TEMPERATURE)))


def apply_extension_model(params: PackParams, model: Any) -> Any:
    """Add what the active extensions change in the equations of PyBaMM ``model`` (modified and returned).

    Called by :func:`~battery_predictor.simulation.cell_setup.build_model`. ``hysteresis`` with a relaxation rate
    (:data:`HYS_RELAX`, not 0) adds ``- r h`` to the Axen model's hysteresis ODE of the positive electrode.
    ``temperature`` with a charge-transfer resistance (:data:`COLD_CHARGE_TRANSFER`, not 0) subtracts
    ``I`` times :data:`CHARGE_TRANSFER_EXCESS` (a function of the negative surface stoichiometry and the cell
    temperature) from the voltage and its cut-off events (:func:`_with_charge_transfer_excess`).
    """
    import pybamm

    if "temperature" in params.extensions and extension_value(params, COLD_CHARGE_TRANSFER):
        model = _with_charge_transfer_excess(model)
    if "hysteresis" not in params.extensions or not extension_value(params, HYS_RELAX):
        return model
    h = model.variables["Positive electrode hysteresis state"]
    model.rhs[h] = model.rhs[h] - pybamm.Parameter(HYS_RELAX) * h
    return model


#: PyBaMM's names of the cell voltage (the predictor's runner reads ``Terminal voltage [V]``, the engine ``Voltage [V]``).
_VOLTAGE_ALIASES = ("Voltage [V]", "Terminal voltage [V]", "Voltage expression [V]")


def _with_charge_transfer_excess(model: Any) -> Any:
    """``model`` (a PyBaMM battery model, not yet processed) whose voltage drops by ``I`` x :data:`CHARGE_TRANSFER_EXCESS`.

    The drop depends on the state only through the negative surface stoichiometry (as the Butler-Volmer
    overpotentials), so the SPM engine's extraction of the voltage covers it. The voltage's aliases and the
    voltage events see the same drop; its heat is not added to a lumped thermal model.
    """
    import pybamm

    v_old = model.variables["Voltage [V]"]
    drop = model.variables["Current [A]"] * pybamm.FunctionParameter(CHARGE_TRANSFER_EXCESS, {
        "Negative particle surface stoichiometry": model.variables["X-averaged negative particle surface stoichiometry"],
        "Temperature [K]": model.variables["Volume-averaged cell temperature [K]"]})
    v_new = v_old - drop
    for key in _VOLTAGE_ALIASES:  # separate (equal) expressions with a contact resistance
        if key in model.variables:
            model.variables[key] = v_new
    model.variables["Battery voltage [V]"] = v_new * pybamm.Parameter(
        "Number of cells connected in series to make a battery")
    events = []
    for event in model.events:
        if event.name.startswith("Minimum voltage"):  # V - V_min
            event = pybamm.Event(event.name, event.expression - drop, event.event_type)
        elif event.name.startswith("Maximum voltage"):  # V_max - V
            event = pybamm.Event(event.name, event.expression + drop, event.event_type)
        events.append(event)
    model.events = events
    return model


def apply_extension_parameter_values(params: PackParams, pv: Any) -> Any:
    """Add what the active extensions need to PyBaMM parameter values ``pv`` (modified and returned).

    Called by :func:`~battery_predictor.simulation.cell_setup.prepared_parameter_values`; a no-op
    for params without extensions.
    """
    exts = set(params.extensions)
    if not exts:
        return pv
    keys = set(pv.keys())
    for ext in exts:
        for key, val in EXTENSION_DEFAULTS.get(ext, {}).items():
            if key not in keys:
                pv.update({key: val}, check_already_exists=False)
    if "temperature" in exts:
        missing = {k: v for k, v in THERMAL_DEFAULTS.items() if k not in keys}
        if "Cell cooling surface area [m2]" not in keys:
            missing["Cell cooling surface area [m2]"] = cooling_area_m2(float(pv["Cell volume [m3]"]))
        pv.update(missing, check_already_exists=False)
        t_ref = float(pv["Reference temperature [K]"]) if "Reference temperature [K]" in keys else 298.15
        for domain, ea_key in (("Negative", EA_NEG), ("Positive", EA_POS)):
            key = f"{domain} particle diffusivity [m2.s-1]"
            d_ref = pv[key]
            if isinstance(d_ref, (int, float)):  # a base-set function already carries its own T dependence
                pv[key] = _arrhenius_diffusivity(float(d_ref), ea_key, t_ref,
                                                 EA_POS_FULL if domain == "Positive" else None)
            j0_key = f"{domain} electrode exchange-current density [A.m-2]"
            if j0_key in keys and callable(pv[j0_key]):
                pv[j0_key] = _arrhenius_exchange_current(pv[j0_key], t_ref)
        charged = cold_window_anchors(params, pv)
        ocp_keys = ("Negative electrode OCP [V]", "Positive electrode OCP [V]")
        if charged is not None and not all(callable(pv[k]) for k in ocp_keys):
            charged = None  # tabulated or constant OCPs: no window
        if charged is not None:
            for key, sto_charged in zip(ocp_keys, charged):
                pv[key] = _cold_window_ocp(pv[key], sto_charged)
        # the charge-transfer resistance follows the negative surface as the window moves it
        pv.update({CHARGE_TRANSFER_EXCESS: _charge_transfer_excess_function(charged[0] if charged else None)},
                  check_already_exists=False)
    if "electrolyte_transport" in exts:
        b = pv[BRUGGEMAN]
        for key in BRUGGEMAN_KEYS:
            pv[key] = b
    if "hysteresis" in exts:
        ocp = pv["Positive electrode OCP [V]"]
        if not callable(ocp):
            raise ValueError("the hysteresis extension needs a positive electrode OCP function")
        warm = bool(extension_value(params, HYS_ACTIVATION))
        pv.update({"Positive electrode lithiation OCP [V]": _shifted_ocp(ocp, -1.0, warm),
                   "Positive electrode delithiation OCP [V]": _shifted_ocp(ocp, +1.0, warm)},
                  check_already_exists=False)
        pv.update({k: pv[HYS_DECAY] for k in PYBAMM_HYS_DECAY_KEYS}, check_already_exists=False)
        pv.update({PYBAMM_HYS_INITIAL_KEY: pv[HYS_INITIAL]}, check_already_exists=False)
    return pv


#: Faraday constant in C/mol (PyBaMM's value).
FARADAY_C_MOL = 96485.33212


def hysteresis_positive_charge_c(pv: Any) -> float:
    """The positive electrode's theoretical charge ``Q_p = F c_max eps_p L_p A n`` (C) of parameter values ``pv``.

    ``A`` is the electrode area (height x width) and ``n`` the number of electrodes connected in parallel:
    PyBaMM's Axen rate ``|i_vol| K / (F c_max eps_p)`` is ``K |I| / Q_p`` in the SPM, whose volumetric
    interfacial current ``i_vol = I / (n A L_p)`` is uniform.
    """
    n_electrodes = float(pv["Number of electrodes connected in parallel to make a cell"])
    area_m2 = float(pv["Electrode height [m]"]) * float(pv["Electrode width [m]"])
    return (FARADAY_C_MOL * float(pv["Maximum concentration in positive electrode [mol.m-3]"])
            * float(pv["Positive electrode active material volume fraction"])
            * float(pv["Positive electrode thickness [m]"]) * area_m2 * n_electrodes)


def hysteresis_rate_per_c(params: PackParams, pv: Any) -> float:
    """Hysteresis rate per unit charge ``K / Q_p`` (1/C) of ``params`` (:data:`HYS_DECAY`, parameter values ``pv``)."""
    return extension_value(params, HYS_DECAY) / hysteresis_positive_charge_c(pv)


def hysteresis_step(h: ArrayLike, current_a: ArrayLike, duration_s: ArrayLike, rate_per_c: ArrayLike,
                    relax_per_s: ArrayLike = 0.0) -> np.ndarray:
    """The hysteresis state after a constant current, exactly.

    This is the solution of ``dh/dt = a (s - h) - b h``, ``a = rate |I|``, ``s = -sign(I)``, ``b`` the relaxation
    rate (a discharge, ``I > 0``, moves ``h`` towards -1, the lithiation branch of the positive electrode; a
    charge towards +1; ``b`` towards 0): ``h_inf + (h - h_inf) exp(-(a + b) dt)``, ``h_inf = a s / (a + b)``.
    Without relaxation (``b = 0``, PyBaMM's Axen model) that is ``s + (h - s) exp(-a dt)``, and at rest ``h`` stays.

    Parameters
    ----------
    h : float or numpy.ndarray
        Hysteresis state at the start (-1..1, dimensionless).
    current_a : float or numpy.ndarray
        Cell current in A (positive = discharge).
    duration_s : float or numpy.ndarray
        Time at that current in s (>= 0).
    rate_per_c : float or numpy.ndarray
        ``K / Q_p`` in 1/C (:func:`hysteresis_rate_per_c`).
    relax_per_s : float or numpy.ndarray
        ``b`` in 1/s (:data:`HYS_RELAX`, >= 0).

    Returns
    -------
    numpy.ndarray
        The state at the end (stays within [-1, 1] when it starts there).
    """
    current = np.asarray(current_a, dtype=float)
    a = np.asarray(rate_per_c, dtype=float) * np.abs(current)
    total = a + np.asarray(relax_per_s, dtype=float)
    h = np.asarray(h, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        h_inf = np.where(total > 0.0, a * -np.sign(current) / np.where(total > 0.0, total, 1.0), 0.0)
    decay = np.exp(-total * np.asarray(duration_s, dtype=float))
    return np.where(total == 0.0, h, h_inf + (h - h_inf) * decay)


def hysteresis_states(h0: float, duration_s: ArrayLike, current_a: ArrayLike, rate_per_c: float,
                      relax_per_s: float = 0.0) -> np.ndarray:
    """The hysteresis state at every boundary of piecewise-constant current steps (exact, :func:`hysteresis_step`).

    Parameters
    ----------
    h0 : float
        State at the start (-1..1).
    duration_s, current_a : array_like
        Step lengths (s) and cell currents (A, positive = discharge), shape (n_steps,).
    rate_per_c : float
        ``K / Q_p`` in 1/C.
    relax_per_s : float
        Relaxation rate ``b`` (1/s; 0: none).

    Returns
    -------
    numpy.ndarray
        Shape (n_steps + 1,): the state at the start of each step and at the end of the last.
    """
    current = np.asarray(current_a, dtype=float)
    duration = np.asarray(duration_s, dtype=float)
    a = float(rate_per_c) * np.abs(current)
    total = a + float(relax_per_s)
    safe = np.where(total > 0.0, total, 1.0)
    h_inf = np.where(total > 0.0, a * -np.sign(current) / safe, 0.0).tolist()
    decay = np.exp(-total * duration).tolist()
    out = [float(h0)]
    h = float(h0)
    for target, d in zip(h_inf, decay):  # h_{k+1} = h_inf,k + (h_k - h_inf,k) d_k (d_k = 1 at rest without relaxation)
        h = target + (h - target) * d
        out.append(h)
    return np.asarray(out)
