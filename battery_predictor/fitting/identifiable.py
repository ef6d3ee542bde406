"""Identifiable coordinates of a pack model and their one mapping back to PyBaMM parameters.

Drive cycles determine a handful of combinations of the SPM's parameters, not the raw values
(thickness and active fraction of an electrode enter only as their product, electrode height
trades against both, a maximum concentration against its initial concentration). The fit
therefore searches in the combinations themselves:

========================== ====== ===================================================================
coordinate                 scale  meaning (per cell unless stated)
========================== ====== ===================================================================
negative_capacity_ah       log    ``F eps_n L_n A c_n,max / 3600``: the negative electrode's capacity
positive_capacity_ah       log    same for the positive electrode
negative_stoichiometry     lin    negative stoichiometry ``x`` at the start of the first recording
series_resistance_ohm      log    pack series resistance outside the cell model (interconnect ``R_eq``)
negative_diffusivity_m2_s  log    optional transport group (particle diffusivity)
positive_diffusivity_m2_s  log    optional transport group
negative_kinetic_scale     log    optional kinetic group: reaction area (so exchange current) factor
positive_kinetic_scale     log    optional kinetic group
hysteresis_half_width_v    lin    with the ``hysteresis`` extension: its half-width ``M`` (V), searched in
                                  :data:`HYSTERESIS_HALF_WIDTH_RANGE_V`
hysteresis_decay_rate      log    with the ``hysteresis`` extension: its rate ``K`` (per unit charge of the
                                  positive electrode), searched in :data:`HYSTERESIS_DECAY_RANGE`
hysteresis_relaxation_     log    optional, with the ``hysteresis`` extension: the rate (1/s) at which its
rate_s                            state relaxes towards 0 (:data:`HYSTERESIS_RELAX_RANGE_S`)
hysteresis_activation_     lin    optional, with the ``hysteresis`` extension: the activation energy of its
energy_j_mol                      half-width (:data:`HYSTERESIS_ACTIVATION_RANGE_J_MOL`)
electrolyte_bruggeman      lin    with the ``electrolyte_transport`` extension (SPMe): the electrolyte's Bruggeman
                                  exponent ``b`` of every region (effective conductivity and diffusivity
                                  ``eps ** b`` times the bulk's), searched in :data:`ELECTROLYTE_BRUGGEMAN_RANGE`
weak_group_capacity_      lin    with the ``cell_imbalance`` extension: the capacity of the one weak series
fraction                          group as a fraction of the others' (:data:`WEAK_GROUP_FRACTION_RANGE`); a
                                  pack whose test or BMS stops on its weakest group ends where that group
                                  reaches the cell cut-off, which the data's end determines
initial_ocv_v:<k>          lin    open-circuit cell voltage at the start of recording ``k`` (state)
========================== ====== ===================================================================

The two hysteresis coordinates are searched whenever the params activate the extension (its initial
state, ``Initial hysteresis state in positive electrode [-]``, stays as the params say: where the
recordings start after a full charge, +1).

The first recording's positive stoichiometry follows from its initial OCV (``U_p(y) - U_n(x) =
OCV``); together they fix the cyclable lithium ``Q_Li = x Q_n + y Q_p``, which is shared: every
further recording starts at the pair ``(x, y)`` on ``x Q_n + y Q_p = Q_Li`` with its own OCV. So
each electrode's initial stoichiometry and capacity and the series resistance - the combinations
an analysis of the model's sensitivities finds determined by drive cycles - are coordinates, and
every point of the search box with a plausible OCV is a feasible cell.
:func:`pybamm_values` maps coordinates to PyBaMM / interconnect values; it is the only place
that does so. Geometry (electrode height, width, thickness) and maximum concentrations stay as
in the params; capacities move the active material volume fractions (and the thickness only
where a fraction would exceed :data:`MAX_ACTIVE_FRACTION`).

A kinetic scale ``s`` multiplies an electrode's reaction area ``3 eps L / R`` (and with it the
kinetic overpotential's exchange current) and nothing else: the particle radius becomes ``R / s``
and the diffusivity ``D / s**2``, so the capacity and the diffusion time ``R**2 / D`` stay. Drive
cycles sampled at 1 s resolve the instantaneous voltage step of a current step, which the
series resistance alone (temperature-independent) and the kinetics (Arrhenius, rising towards
the end of discharge) share; the kinetic scales let the fit put it where the cell has it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from battery_predictor.errors import ParamsError, SimulationError
from battery_predictor.fitting.space import unit_to_value, value_to_unit
from battery_predictor.ocp import STO_GRID, initial_stoichiometries, ocp_curves
from battery_predictor.params import INTERCONNECT_KEYS, PackParams
from battery_predictor.recording import Recording, step_resistance_ohm

#: Faraday constant in C/mol.
FARADAY_C_MOL = 96485.33212
#: Active material volume fractions above this are written as a thicker electrode instead.
MAX_ACTIVE_FRACTION = 0.85
#: Electrode capacities and lithium inventory: searched within these multiples of the nominal
#: cell capacity (and never below the charge the data draw from one cell).
CAPACITY_FACTORS = (0.3, 5.0)
#: Series resistance: from ~0 (this many Ohm per cell) ...
MIN_RESISTANCE_OHM_PER_CELL = 1e-5
#: ... to the larger of this many times the params' value and this many Ohm per cell.
RESISTANCE_FACTOR_HIGH = 10.0
MAX_RESISTANCE_OHM_PER_CELL = 0.2
#: Diffusivities: searched within these multiples of the params' value (log scale).
DIFFUSIVITY_FACTORS = (0.01, 100.0)
#: Kinetic scales (reaction area factors, 1 = the params' own): searched within this range (log scale).
KINETIC_SCALE_RANGE = (0.02, 50.0)
#: Initial OCV of a recording: searched this far (V per cell) below and above its first voltage.
#: The box is wide also for recordings that start at rest: a 50 mV box there is the worse choice
#: on far-truth Temi draws (docs/identification.md).
INITIAL_OCV_MARGIN_V = (0.15, 0.35)
#: ... but never more than this above the params' upper cut-off (V per cell; above the first voltage when
#: the data start higher): a cell's open-circuit voltage does not exceed its charged one. Without it a fit
#: of the Panasonic drive cycles found an optimum that starts at 4.32 V with a 13 Ah negative electrode.
FULL_OCV_MARGIN_V = 0.05

CORE_COORDINATES = ("negative_capacity_ah", "positive_capacity_ah", "negative_stoichiometry",
                    "series_resistance_ohm")
#: Negative stoichiometry at the start of the first recording: searched within this range.
NEGATIVE_STOICHIOMETRY_RANGE = (0.2, 0.999)
OPTIONAL_COORDINATES = ("negative_diffusivity_m2_s", "positive_diffusivity_m2_s", "negative_kinetic_scale",
                        "positive_kinetic_scale", "hysteresis_relaxation_rate_s", "hysteresis_activation_energy_j_mol")
#: Both particle diffusivities: the transport ``fit`` searches by default on params with a measured OCP
#: (:func:`default_optional_coordinates`) and the diagnosis's reference fit where they fit separably better.
TRANSPORT_COORDINATES = ("negative_diffusivity_m2_s", "positive_diffusivity_m2_s")
_ELECTRODES = {"negative": "Negative", "positive": "Positive"}
_DIFFUSIVITY_KEYS = {"negative_diffusivity_m2_s": "Negative particle diffusivity [m2.s-1]",
                     "positive_diffusivity_m2_s": "Positive particle diffusivity [m2.s-1]"}
_KINETIC_ELECTRODES = {"negative_kinetic_scale": "Negative", "positive_kinetic_scale": "Positive"}
#: Search range of the hysteresis half-width (V per cell; linear).
HYSTERESIS_HALF_WIDTH_RANGE_V = (0.0, 0.06)
#: Search range of the hysteresis rate ``K`` (dimensionless, log scale): ``K = 100`` moves the state by
#: ``1 - exp(-1)`` of its way to a branch while 1 % of the positive electrode's charge flows.
HYSTERESIS_DECAY_RANGE = (1.0, 1.0e4)
#: Hysteresis coordinates -> extension keys (``simulation.extensions``).
_HYSTERESIS_KEYS = {"hysteresis_half_width_v": "Positive electrode OCP hysteresis half-width [V]",
                    "hysteresis_decay_rate": "Positive particle hysteresis decay rate [-]"}
HYSTERESIS_COORDINATES = tuple(_HYSTERESIS_KEYS)
#: Search range of the hysteresis relaxation rate (1/s, log scale): a time constant from 10 s to about 28 h
#: (the low end is the params' value 0, no relaxation, for the start).
HYSTERESIS_RELAX_RANGE_S = (1.0e-5, 1.0e-1)
#: Search range of the activation energy of the hysteresis half-width (J/mol, linear).
HYSTERESIS_ACTIVATION_RANGE_J_MOL = (0.0, 80000.0)
#: Search range of the weak series group's capacity fraction (extension ``cell_imbalance``; linear).
WEAK_GROUP_FRACTION_RANGE = (0.5, 1.0)
_IMBALANCE_KEYS = {"weak_group_capacity_fraction": "Weak series group capacity fraction"}
#: Search range of the electrolyte's Bruggeman exponent (extension ``electrolyte_transport``; linear): from the
#: ideal packing's 1.0 to 4.0, where Chen2020's negative electrode (porosity 0.25) conducts 0.4 % of the bulk
#: electrolyte (an electrolyte resistance of about 0.1 Ohm in an 18650).
ELECTROLYTE_BRUGGEMAN_RANGE = (1.0, 4.0)
_ELECTROLYTE_KEYS = {"electrolyte_bruggeman": "Electrolyte Bruggeman coefficient [-]"}
#: Extension -> its always-searched coordinates (name -> extension key in ``cell.extra``).
_EXTENSION_KEYS = {"hysteresis": _HYSTERESIS_KEYS, "cell_imbalance": _IMBALANCE_KEYS,
                   "electrolyte_transport": _ELECTROLYTE_KEYS}
#: Optional hysteresis coordinates -> (extension key, search range, log scale).
_HYSTERESIS_OPTIONAL = {
    "hysteresis_relaxation_rate_s": ("Positive electrode hysteresis relaxation rate [s-1]", HYSTERESIS_RELAX_RANGE_S, True),
    "hysteresis_activation_energy_j_mol": ("Positive electrode OCP hysteresis half-width activation energy [J.mol-1]",
                                           HYSTERESIS_ACTIVATION_RANGE_J_MOL, False),
}


@dataclass(frozen=True)
class Coordinate:
    """One searched coordinate.

    Attributes
    ----------
    name : str
        Coordinate name (see the module table); state coordinates end in ``:<recording index>``.
    initial : float
        Start value (from the params, or from the data for a state).
    low, high : float
        Search bounds in the coordinate's unit.
    log : bool
        Searched on a log scale.
    recording : int or None
        Index of the recording a state coordinate belongs to; None for shared coordinates.
    """

    name: str
    initial: float
    low: float
    high: float
    log: bool
    recording: int | None = None

    def to_unit(self, value: float) -> float:
        """Position of ``value`` in the unit interval of the search box (0 = low, 1 = high)."""
        return value_to_unit(value, self.low, self.high, self.log)

    def from_unit(self, unit: float) -> float:
        """Inverse of :meth:`to_unit`."""
        return unit_to_value(unit, self.low, self.high, self.log)

    def contains(self, value: float) -> bool:
        """True when ``low <= value <= high``."""
        return self.low <= value <= self.high


@dataclass(frozen=True)
class ElectrodeBasis:
    """The parts of the params the mapping keeps fixed (per cell).

    Attributes
    ----------
    ah_per_m : dict
        ``F A c_max / 3600`` per electrode (Ah per metre of ``eps * L``).
    thickness_m, fraction : dict
        The params' thickness (m) and active material volume fraction per electrode.
    c_max_mol_m3 : dict
        Maximum concentration per electrode (mol/m3).
    r_eq_ohm : float
        The params' interconnect ``R_eq`` (Ohm, pack).
    """

    ah_per_m: dict[str, float]
    thickness_m: dict[str, float]
    fraction: dict[str, float]
    c_max_mol_m3: dict[str, float]
    r_eq_ohm: float


def electrode_basis(params: PackParams) -> ElectrodeBasis:
    """The fixed geometry of ``params`` that :func:`pybamm_values` scales."""
    from battery_predictor.simulation.network import equivalent_network_resistance_ohm

    pv = params.parameter_values()
    area_m2 = float(pv["Electrode height [m]"]) * float(pv["Electrode width [m]"])
    ah_per_m, thickness, fraction, c_max = {}, {}, {}, {}
    for key, cap in _ELECTRODES.items():
        c_max[key] = float(pv[f"Maximum concentration in {key} electrode [mol.m-3]"])
        thickness[key] = float(pv[f"{cap} electrode thickness [m]"])
        fraction[key] = float(pv[f"{cap} electrode active material volume fraction"])
        ah_per_m[key] = FARADAY_C_MOL * area_m2 * c_max[key] / 3600.0
    ic = params.interconnect
    r_eq = equivalent_network_resistance_ohm(params.series, params.parallel, ic["r_b_ohm"], ic["r_c_ohm"],
                                             ic["r_t_ohm"])
    return ElectrodeBasis(ah_per_m, thickness, fraction, c_max, float(r_eq))


def shipped_coordinates(params: PackParams) -> dict[str, float]:
    """The params' own values in identifiable coordinates (shared coordinates only)."""
    pv = params.parameter_values()
    basis = electrode_basis(params)
    cap = {k: basis.ah_per_m[k] * basis.fraction[k] * basis.thickness_m[k] for k in _ELECTRODES}
    sto = {k: float(pv[f"Initial concentration in {k} electrode [mol.m-3]"]) / basis.c_max_mol_m3[k]
           for k in _ELECTRODES}
    out = {
        "negative_capacity_ah": cap["negative"],
        "positive_capacity_ah": cap["positive"],
        "negative_stoichiometry": sto["negative"],
        "series_resistance_ohm": basis.r_eq_ohm,
    }
    for name, key in _DIFFUSIVITY_KEYS.items():
        val = pv[key]
        if isinstance(val, (int, float)):
            out[name] = float(val)
    searched = [keys for ext, keys in _EXTENSION_KEYS.items() if ext in params.extensions]
    if searched:
        from battery_predictor.simulation.extensions import extension_value

        for keys in searched:
            out.update({name: extension_value(params, key) for name, key in keys.items()})
    return out


def cell_capacity_ah(params: PackParams) -> float:
    """Nominal cell capacity in Ah (params' nominal cell capacity, else pack capacity / parallel)."""
    pv = params.parameter_values()
    try:
        return float(pv["Nominal cell capacity [A.h]"])
    except KeyError:
        return float(params.pack_info.get("nominal_capacity_ah", 1.0)) / params.parallel


def _cell_charge_drawn_ah(params: PackParams, recordings: Sequence[Recording]) -> float:
    """Largest charge (Ah per cell) any recording draws below its starting point."""
    out = 0.0
    for rec in recordings:
        if len(rec.time_s) < 2:
            continue
        dt = np.diff(rec.time_s)
        q = np.concatenate([[0.0], np.cumsum(rec.current_a[:-1] * dt) / 3600.0])
        out = max(out, float(q.max() - min(q.min(), 0.0)))
    return out / params.parallel


def default_optional_coordinates(params: PackParams) -> tuple[str, ...]:
    """The optional coordinates ``fit`` searches when none are asked for.

    Both particle diffusivities (:data:`TRANSPORT_COORDINATES`) where the params carry a measured OCP
    (``cell.ocp``, written by ``battery-predictor ocv``) and give both diffusivities as scalars; none otherwise.
    With the cell's own open-circuit voltage the thermodynamics is measured, and what drive cycles determine
    beyond the capacities, the stoichiometry and the series resistance is the particles' transport. With a
    base set's OCPs (another chemistry's) the diffusivities take up the OCPs' error instead: on the Panasonic
    18650PF they raise the fit's R2_mod and worsen the held-out runtime (docs/identification.md).
    """
    if not params.ocp:
        return ()
    shipped = shipped_coordinates(params)
    return TRANSPORT_COORDINATES if all(name in shipped for name in TRANSPORT_COORDINATES) else ()


def default_space(params: PackParams, recordings: Sequence[Recording] = (),
                  extra: Sequence[str] = ()) -> list[Coordinate]:
    """Search box of the shared coordinates (plus one initial OCV per recording).

    Capacities and the lithium inventory lie within :data:`CAPACITY_FACTORS` of the nominal cell
    capacity and never below the charge the data draw per cell (a cell cannot deliver more than
    either electrode holds); the series resistance from ~0 (log scale) to the larger of 10x the
    params' value and :data:`MAX_RESISTANCE_OHM_PER_CELL` per cell; each recording's initial OCV
    around its first voltage. Without data the params' own values always lie inside (the box is
    widened to include them); the charge drawn by the data overrides that for the lower bounds.

    Parameters
    ----------
    params : PackParams
        The starting model.
    recordings : sequence of Recording
        The fit data (state coordinates and the charge-drawn bound); may be empty.
    extra : sequence of str
        Optional coordinates from :data:`OPTIONAL_COORDINATES` to search as well.
    """
    unknown = [e for e in extra if e not in OPTIONAL_COORDINATES]
    if unknown:
        raise ParamsError(f"unknown fit coordinate(s) {unknown}; optional ones are {list(OPTIONAL_COORDINATES)}")
    shipped = shipped_coordinates(params)
    q_cell = cell_capacity_ah(params)
    q_drawn = _cell_charge_drawn_ah(params, recordings)
    cap_lo = CAPACITY_FACTORS[0] * q_cell
    cap_hi = max(CAPACITY_FACTORS[1] * q_cell, 2.0 * q_drawn)
    cell_ratio = params.series / params.parallel
    r_lo = MIN_RESISTANCE_OHM_PER_CELL * cell_ratio
    r_hi = max(RESISTANCE_FACTOR_HIGH * shipped["series_resistance_ohm"], MAX_RESISTANCE_OHM_PER_CELL * cell_ratio)
    space = []
    for name in ("negative_capacity_ah", "positive_capacity_ah"):
        coord = _widened(name, shipped[name], cap_lo, cap_hi, log=True)
        low = max(coord.low, q_drawn)
        space.append(Coordinate(name, max(coord.initial, low), low, coord.high, coord.log))
    space.append(_widened("negative_stoichiometry", shipped["negative_stoichiometry"],
                          *NEGATIVE_STOICHIOMETRY_RANGE, log=False))
    space.append(_widened("series_resistance_ohm", max(shipped["series_resistance_ohm"], r_lo), r_lo, r_hi, log=True))
    for name in extra:
        if name in _KINETIC_ELECTRODES:
            _check_kinetic_scalable(params, name)
            space.append(Coordinate(name, 1.0, *KINETIC_SCALE_RANGE, True))
            continue
        if name in _HYSTERESIS_OPTIONAL:
            space.append(_hysteresis_optional_coordinate(params, name))
            continue
        if name not in shipped:
            raise ParamsError(f"{params.source}: {_DIFFUSIVITY_KEYS[name]} is a function in "
                              f"{params.base_parameter_set}; it cannot be searched as a scalar")
        lo, hi = (f * shipped[name] for f in DIFFUSIVITY_FACTORS)
        space.append(Coordinate(name, shipped[name], lo, hi, True))
    if "hysteresis" in params.extensions:
        space.append(_widened("hysteresis_half_width_v", shipped["hysteresis_half_width_v"],
                              *HYSTERESIS_HALF_WIDTH_RANGE_V, log=False))
        space.append(_widened("hysteresis_decay_rate", shipped["hysteresis_decay_rate"], *HYSTERESIS_DECAY_RANGE,
                              log=True))
    if "electrolyte_transport" in params.extensions:
        space.append(_widened("electrolyte_bruggeman", shipped["electrolyte_bruggeman"], *ELECTROLYTE_BRUGGEMAN_RANGE,
                              log=False))
    if "cell_imbalance" in params.extensions:
        space.append(_widened("weak_group_capacity_fraction", shipped["weak_group_capacity_fraction"],
                              *WEAK_GROUP_FRACTION_RANGE, log=False))
    space.extend(initial_ocv_coordinates(params, recordings))
    return space


def _hysteresis_optional_coordinate(params: PackParams, name: str) -> Coordinate:
    """The optional hysteresis coordinate ``name``, starting from the params' value (clipped into its range)."""
    from battery_predictor.simulation.extensions import extension_value

    if "hysteresis" not in params.extensions:
        raise ParamsError(f"{params.source}: {name} needs the hysteresis extension (extensions: [hysteresis])")
    key, (low, high), log = _HYSTERESIS_OPTIONAL[name]
    return Coordinate(name, min(max(extension_value(params, key), low), high), low, high, log)


def _check_kinetic_scalable(params: PackParams, name: str) -> None:
    """Raise unless the electrode of kinetic coordinate ``name`` has a scalar radius and diffusivity."""
    pv = params.parameter_values()
    cap = _KINETIC_ELECTRODES[name]
    for key in (f"{cap} particle radius [m]", f"{cap} particle diffusivity [m2.s-1]"):
        if not isinstance(pv[key], (int, float)):
            raise ParamsError(f"{params.source}: {key} is a function in {params.base_parameter_set}; "
                              f"{name} needs it as a scalar")


def kinetic_values(params: PackParams, coordinates: Mapping[str, float]) -> dict[str, float]:
    """Particle radius (m) and diffusivity (m2/s) for the kinetic scales in ``coordinates``.

    A scale ``s`` gives the radius ``R / s`` and the diffusivity ``D / s**2`` (``D`` from a
    diffusivity coordinate when one is given, else the params'): the reaction area grows by ``s``,
    the diffusion time ``R**2 / D`` and the capacity stay.
    """
    pv = params.parameter_values()
    out: dict[str, float] = {}
    for name, cap in _KINETIC_ELECTRODES.items():
        if name not in coordinates:
            continue
        _check_kinetic_scalable(params, name)
        s = float(coordinates[name])
        diff_name = f"{cap.lower()}_diffusivity_m2_s"
        d = float(coordinates[diff_name]) if diff_name in coordinates else float(pv[_DIFFUSIVITY_KEYS[diff_name]])
        out[f"{cap} particle radius [m]"] = float(pv[f"{cap} particle radius [m]"]) / s
        out[_DIFFUSIVITY_KEYS[diff_name]] = d / s**2
    return out


def ohmic_structure(params: PackParams, recordings: Sequence[Recording]) -> tuple[PackParams, float] | None:
    """The params with the step of the data carried by the series resistance, or None when the data show no step.

    A current step shows the cell's instantaneous voltage step (:func:`~battery_predictor.recording.step_resistance_ohm`,
    at the data's own resolution). The SPM splits it between the series resistance and the Butler-Volmer
    overpotential; a search from the params' kinetics keeps it in the overpotential, whose basin it does
    not leave, while many cells' step is ohmic (current-independent). This structure gives every electrode
    whose particle radius and diffusivity are scalars the fastest kinetics of :data:`KINETIC_SCALE_RANGE`
    (its reaction area scaled, the capacity and the diffusion time kept, :func:`kinetic_values`), so the
    kinetic overpotential is a small part of the step, and starts the series resistance at the measured step.

    Parameters
    ----------
    params : PackParams
        The starting model.
    recordings : sequence of Recording
        The fit data (voltage in V, current in A).

    Returns
    -------
    tuple of (PackParams, float) or None
        The params with the fast kinetics and the step resistance (Ohm, pack terminals) to start the
        series resistance from; None without at least three current steps or without a scalable electrode.
    """
    step_ohm = step_resistance_ohm(recordings)
    if step_ohm <= 0.0:
        return None
    scales = {}
    for name in _KINETIC_ELECTRODES:
        try:
            _check_kinetic_scalable(params, name)
        except ParamsError:
            continue
        scales[name] = KINETIC_SCALE_RANGE[1]
    if not scales:
        return None
    return params.with_values(kinetic_values(params, scales)), step_ohm


def with_start_value(space: Sequence[Coordinate], name: str, value: float) -> list[Coordinate]:
    """``space`` with coordinate ``name`` started at ``value`` (clipped into its box); the others unchanged."""
    return [replace(c, initial=min(max(float(value), c.low), c.high)) if c.name == name else c for c in space]


def _widened(name: str, initial: float, low: float, high: float, log: bool) -> Coordinate:
    return Coordinate(name, initial, min(low, initial), max(high, initial), log)


def highest_start_ocv_v(upper_cutoff_v: float, first_voltage_v: float) -> float:
    """Highest plausible open-circuit cell voltage (V) at the start of a recording.

    :data:`FULL_OCV_MARGIN_V` above the upper cut-off ``upper_cutoff_v`` (V per cell), or above the
    first measured cell voltage ``first_voltage_v`` where the data start higher.
    """
    return max(upper_cutoff_v, first_voltage_v) + FULL_OCV_MARGIN_V


def initial_ocv_coordinates(params: PackParams, recordings: Sequence[Recording]) -> list[Coordinate]:
    """One initial-OCV coordinate per recording, around its first cell voltage.

    The box reaches :data:`INITIAL_OCV_MARGIN_V` below and above the first voltage, but at most
    :data:`FULL_OCV_MARGIN_V` above the params' upper cut-off. A recording that starts above that
    cut-off gets a warning: its box follows the data (the discharge simulation does not use the upper
    cut-off).
    """
    upper_v = float(params.parameter_values()["Upper voltage cut-off [V]"])
    lower_v = params.cell_lower_cutoff_v
    out = []
    for k, rec in enumerate(recordings):
        v_first = float(rec.voltage_v[0]) / params.series
        if v_first > upper_v + 1e-3:
            warnings.warn(f"{rec.source}: starts at {v_first:.3f} V per cell, above the params' upper cut-off "
                          f"{upper_v:.3f} V; its initial state is searched around the measured voltage",
                          UserWarning, stacklevel=2)
        lo = max(lower_v, v_first - INITIAL_OCV_MARGIN_V[0])
        hi = min(v_first + INITIAL_OCV_MARGIN_V[1], highest_start_ocv_v(upper_v, v_first))
        start = v_first + 0.02 if float(rec.current_a[0]) > 0 else v_first
        out.append(Coordinate(f"initial_ocv_v:{k}", min(max(start, lo), hi), lo, hi, False, recording=k))
    return out


# ----------------------------------------------------------------------------- OCP and state
# ----------------------------------------------------------------------------- the mapping
def _electrode_values(basis: ElectrodeBasis, electrode: str, capacity_ah: float) -> dict[str, float]:
    cap = _ELECTRODES[electrode]
    eps_l_m = capacity_ah / basis.ah_per_m[electrode]
    fraction = eps_l_m / basis.thickness_m[electrode]
    thickness = basis.thickness_m[electrode]
    if fraction > MAX_ACTIVE_FRACTION and fraction > basis.fraction[electrode]:
        fraction = max(MAX_ACTIVE_FRACTION, basis.fraction[electrode])
        thickness = eps_l_m / fraction
    return {f"{cap} electrode active material volume fraction": fraction,
            f"{cap} electrode thickness [m]": thickness}


def pybamm_values(params: PackParams, coordinates: Mapping[str, float], n_recordings: int = 1,
                  basis: ElectrodeBasis | None = None) -> list[dict[str, float]]:
    """Map identifiable coordinates to PyBaMM and interconnect values, one dict per recording.

    Shared coordinates missing from ``coordinates`` keep the params' values. Without an
    ``initial_ocv_v:0`` coordinate the first recording starts at the params' initial OCV; a
    further recording without its own OCV starts where the first does.

    Parameters
    ----------
    params : PackParams
        The model the coordinates refer to.
    coordinates : mapping
        Coordinate name -> value (units in the names).
    n_recordings : int
        Number of value dicts to return.
    basis : ElectrodeBasis, optional
        :func:`electrode_basis` of ``params`` (computed when omitted).

    Returns
    -------
    list of dict
        For each recording: values for :meth:`PackParams.with_values` (PyBaMM keys and
        interconnect names).

    Raises
    ------
    SimulationError
        When the coordinates admit no initial state (see :func:`initial_stoichiometries`).
    """
    basis = basis or electrode_basis(params)
    shipped = shipped_coordinates(params)
    c = {**shipped, **{k: float(v) for k, v in coordinates.items()}}
    shared: dict[str, float] = {}
    shared.update(_electrode_values(basis, "negative", c["negative_capacity_ah"]))
    shared.update(_electrode_values(basis, "positive", c["positive_capacity_ah"]))
    scale = c["series_resistance_ohm"] / basis.r_eq_ohm if basis.r_eq_ohm > 0 else 1.0
    for key in ("r_b_ohm", "r_c_ohm", "r_t_ohm"):
        shared[key] = params.interconnect[key] * scale
    for name, key in _DIFFUSIVITY_KEYS.items():
        if name in coordinates:
            shared[key] = c[name]
    shared.update(kinetic_values(params, coordinates))
    for name, key in {**_HYSTERESIS_KEYS, **_IMBALANCE_KEYS, **_ELECTROLYTE_KEYS}.items():
        if name in coordinates:
            shared[key] = c[name]
    for name, (key, _, _) in _HYSTERESIS_OPTIONAL.items():
        if name in coordinates:
            shared[key] = float(coordinates[name])
    x_0, y_0 = _first_state(params, basis, c, shipped, "initial_ocv_v:0" in c)
    q_li_ah = x_0 * c["negative_capacity_ah"] + y_0 * c["positive_capacity_ah"]
    out = []
    for k in range(n_recordings):
        values = dict(shared)
        ocv_key = f"initial_ocv_v:{k}"
        x, y = x_0, y_0
        if k > 0 and ocv_key in c:
            x, y = initial_stoichiometries(params, c["negative_capacity_ah"], c["positive_capacity_ah"], q_li_ah,
                                           c[ocv_key])
        values["Initial concentration in negative electrode [mol.m-3]"] = x * basis.c_max_mol_m3["negative"]
        values["Initial concentration in positive electrode [mol.m-3]"] = y * basis.c_max_mol_m3["positive"]
        out.append(values)
    return out


def _positive_stoichiometry_at(params: PackParams, potential_v: float) -> float:
    """Positive stoichiometry whose OCP is ``potential_v`` (the OCP made monotone decreasing)."""
    _, u_p = ocp_curves(params)
    falling = np.minimum.accumulate(u_p)
    if not falling[-1] <= potential_v <= falling[0]:
        raise SimulationError(f"positive electrode potential {potential_v:.3f} V is outside its OCP range "
                              f"{falling[-1]:.3f}-{falling[0]:.3f} V")
    return float(np.interp(potential_v, falling[::-1], STO_GRID[::-1]))


def _first_state(params: PackParams, basis: ElectrodeBasis, c: Mapping[str, float], shipped: Mapping[str, float],
                 has_ocv: bool) -> tuple[float, float]:
    """Stoichiometries ``(x, y)`` at the start of the first recording.

    ``x`` is the coordinate; ``y`` follows from the recording's initial OCV, or without one from
    the params' own initial OCV (the params' own ``y`` when ``x`` is unchanged).
    """
    pv = params.parameter_values()
    x_s = float(pv["Initial concentration in negative electrode [mol.m-3]"]) / basis.c_max_mol_m3["negative"]
    y_s = float(pv["Initial concentration in positive electrode [mol.m-3]"]) / basis.c_max_mol_m3["positive"]
    x = c["negative_stoichiometry"]
    u_n, u_p = ocp_curves(params)
    if has_ocv:
        ocv = c["initial_ocv_v:0"]
    elif math.isclose(x, x_s, rel_tol=1e-12):
        return x_s, y_s
    else:
        ocv = float(np.interp(y_s, STO_GRID, u_p) - np.interp(x_s, STO_GRID, u_n))
    return x, _positive_stoichiometry_at(params, ocv + float(np.interp(x, STO_GRID, u_n)))


def fitted_parameter_names(values: Mapping[str, float]) -> list[str]:
    """PyBaMM keys and interconnect names a mapped value dict sets (for ``fit.parameters``)."""
    return [k for k in values if k in INTERCONNECT_KEYS or "[" in k]


__all__ = [
    "CORE_COORDINATES", "HYSTERESIS_COORDINATES", "OPTIONAL_COORDINATES", "Coordinate", "ElectrodeBasis", "default_space", "electrode_basis",
    "initial_stoichiometries", "kinetic_values", "ocp_curves", "ohmic_structure", "with_start_value", "pybamm_values", "shipped_coordinates", "fitted_parameter_names",
]
