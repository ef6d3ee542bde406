"""Candidate causes: each a small, physically meaningful extension of the pack model.

Every candidate names its extra parameters with bounds that keep them physical, says how
it simulates a recording (through :class:`~battery_predictor.diagnosis.engine.Engine`) and
how its fitted values are written to a params file (``extensions: [name]`` plus
``cell.extra``), so that ``simulate``, ``fit`` and the predictor use the extended model
(:mod:`battery_predictor.simulation.extensions`).

The initial state of each observed recording (its SOC) is fitted by every candidate and by
the baseline alike (:data:`Baseline`, the ``none`` candidate has no other parameter).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from battery_predictor.diagnosis.engine import (
    C_N0,
    C_P0,
    EPS_N,
    EPS_P,
    L_N,
    L_P,
    Engine,
    Observed,
    Post,
    SimOut,
    discharge_throughput_ah,
)
from battery_predictor.diagnosis.scoring import current_resolution_a
from battery_predictor.fitting.space import unit_to_value, value_to_unit
from battery_predictor.params import PackParams, cached_parameter_values
from battery_predictor.simulation import extensions as ext


@dataclass(frozen=True)
class CandParam:
    """One extra parameter of a candidate.

    Attributes
    ----------
    name : str
        Identifier (used in the JSON ``fitted`` mapping).
    low, high, initial : float
        Bounds and starting value.
    log : bool
        Searched on a log scale.
    unit : str
        Unit for reports.
    """

    name: str
    low: float
    high: float
    initial: float
    log: bool = False
    unit: str = ""

    def to_unit(self, u: float) -> float:
        """Map ``u`` in [0, 1] to the parameter's value."""
        return unit_to_value(u, self.low, self.high, self.log)

    def from_value(self, value: float) -> float:
        """Map a value (clamped to the bounds) to [0, 1]."""
        return value_to_unit(min(max(float(value), self.low), self.high), self.low, self.high, self.log)


class Candidate:
    """Base class: the baseline itself (no extra parameter); subclasses add one cause each."""

    #: Cause name (one of :data:`battery_predictor.params.EXTENSION_NAMES`, or ``"none"``).
    name = "none"
    #: What the extension adds, for reports.
    title = "baseline SPM pack model (state of charge only)"
    #: Residual features that point to this cause (see :mod:`battery_predictor.diagnosis.residuals`).
    signature: tuple[str, ...] = ()
    #: Starts of the fit (the budget is shared among them).
    starts = 1

    def parameters(self, params: PackParams, observed: Sequence[Observed] | None = None) -> tuple[CandParam, ...]:
        """The extra parameters and their bounds for ``params`` (and the observed recordings, when given)."""
        return ()

    def start_points(self, params: PackParams, rng: np.random.Generator,
                     observed: Sequence[Observed] | None = None) -> list[dict[str, float]]:
        """Starting values of the extra parameters, one dict per start."""
        base = {p.name: p.initial for p in self.parameters(params, observed)}
        out = [base]
        for _ in range(self.starts - 1):
            out.append({p.name: p.to_unit(rng.uniform(0.15, 0.85)) for p in self.parameters(params, observed)})
        return out

    def applicable(self, params: PackParams, observed: list[Observed]) -> str | None:
        """None when the candidate applies, else the reason it does not."""
        return None

    def unresolved(self, fitted: dict[str, float], observed: Sequence[Observed]) -> str | None:
        """None when the fitted effect (:meth:`fitted`'s values) is larger than the instruments resolve,
        else why it is not: such a candidate is scored and reported but never named."""
        return None

    def sensor_offset_a(self, fitted: dict[str, float]) -> float:
        """The current sensor's offset (A, pack) this cause says the reading carries; 0 for causes in the cells."""
        return 0.0

    def structure(self, params: PackParams) -> PackParams:
        """The params whose model is built (with the extension's options active)."""
        return params

    def extra_inputs(self) -> tuple[str, ...]:
        """PyBaMM keys beyond the engine's base inputs that are ``[input]`` in this structure."""
        return ()

    def ambient_k(self, obs: Observed) -> float:
        """Ambient temperature (K) of the run: the recording's mean temperature (isothermal)."""
        return obs.mean_temperature_k

    def concentrations(self, engine: Engine, params: PackParams, theta: dict[str, float],
                       soc: float) -> tuple[float, float]:
        """Initial (c_n, c_p) in mol/m3 for ``soc``."""
        return engine.concentrations_for_soc(params, soc)

    def run_arguments(self, params: PackParams, theta: dict[str, float]) -> dict[str, Any]:
        """Keyword arguments of :meth:`Engine.simulate` (values, post, offset)."""
        return {}

    def simulate(self, engine: Engine, params: PackParams, obs: Observed, theta: dict[str, float], soc: float,
                 t_end: float | None = None, want_temperature: bool = False) -> SimOut:
        """Simulate ``obs`` from ``soc`` with the extra parameters ``theta``."""
        return engine.simulate(self.structure(params), obs, concentrations=self.concentrations(engine, params, theta, soc),
                               ambient_k=self.ambient_k(obs), t_end=t_end, extra_inputs=self.extra_inputs(),
                               want_temperature=want_temperature, **self.run_arguments(params, theta))

    def extended_params(self, params: PackParams, theta: dict[str, float], socs: list[float],
                        engine: Engine) -> PackParams:
        """``params`` with this extension active and its fitted values (for ``--write-params``)."""
        return params

    def _with_extension(self, params: PackParams, extra: dict[str, float]) -> PackParams:
        exts = tuple(dict.fromkeys([*params.extensions, self.name]))
        merged = dict(params.extra)
        merged.update({k: float(v) for k, v in extra.items()})
        return replace(params, extensions=exts, extra=merged)


Baseline = Candidate


class Temperature(Candidate):
    """What a cold (or warm) cell does differently, with the physics measured cells show.

    * **Accessible capacity** (equilibrium, at any rate): both electrodes' stoichiometry windows narrow
      in the cold, a fitted fraction per kelvin below the anchor temperature (``window_loss_per_k``,
      :func:`~battery_predictor.simulation.extensions.cold_window_scale`): the discharged end of each
      window becomes inaccessible, so the discharge reaches its knee earlier even at 0.1C (the LG M50
      cells deliver 5 % less at 10 degC and 10 % less at 0 degC at 0.1C, docs/findings.md), and the cell
      gets the capacity back as it warms (self-heating follows the measured temperature).
    * **Transport**: Arrhenius solid diffusion in both particles (one activation energy): in the cold
      the particle surface saturates early under load - the rate-dependent part of the capacity loss.
      The extension also offers a positive-particle activation energy that grows towards full
      lithiation (``EA_POS_FULL``); fitted here it extrapolated badly on held-out data
      (docs/findings.md), so the candidate does not fit it.
    * **Charge transfer**: a cell resistance that follows Arrhenius with 30 kJ/mol and the inverse of the
      exchange-current density's concentration dependence at the negative electrode's surface
      (``j0 ~ sqrt(x (1 - x))``, at the stoichiometry the cold window moves it to;
      :func:`~battery_predictor.simulation.extensions.charge_transfer_excess_ohm`), in PyBaMM's voltage. Only
      its excess over the anchor temperature is added (the identified model already carries the reference
      cells' drop), so it grows in the cold, most towards the end of the discharge, and shrinks as the cell
      warms (measured cold cells: docs/findings.md). Its one fitted value is the resistance at the anchor and
      half lithiation. The exchange-current densities keep the base set's own Arrhenius factor (an extra
      activation energy, ``EA_KINETICS``, fitted to ~0 on the Panasonic cell, docs/findings.md): under a
      drive cycle's currents the SPM's Butler-Volmer kinetics act near their Tafel regime, where a slower
      ``j0`` shifts the voltage rather than adding the resistance the measured cells show.
    * **Self-heating**: the cell follows its measured temperature; without one, a lumped thermal
      model from the first temperature with a fitted heat transfer coefficient.

    At the anchor temperature every factor is 1. The anchor (``Temperature extension anchor temperature
    [K]`` in the params, set by the diagnosis from measured references,
    :func:`~battery_predictor.diagnosis.diagnose.with_reference_anchor`; 298.15 K otherwise) is the mean
    measured temperature at the end of the reference discharges: the identified model carries the
    accessible capacity the reference cells had there (LG M50 25 degC references self-heat to 26-57 degC
    by their knee). The diffusivities keep the base set's reference temperature (they are not identified).
    """

    name = "temperature"
    title = ("both electrodes' stoichiometry windows narrowing below the references' end-of-discharge temperature "
             "(accessible capacity at any rate), Arrhenius "
             "solid diffusion and an Arrhenius charge-transfer resistance that grows as the negative surface empties "
             "(fitted), the cell following its measured temperature "
             "(or, unmeasured, a lumped thermal model with a fitted heat transfer coefficient: self-heating)")
    signature = ("temperature", "current")

    @staticmethod
    def _measured(obs: Observed) -> bool:
        return obs.temperature_k is not None and float(np.ptp(obs.temperature_k)) > 0.0

    def parameters(self, params: PackParams, observed: Sequence[Observed] | None = None) -> tuple[CandParam, ...]:
        out = (CandParam("diffusivity_activation_energy_J_mol", 0.0, 80000.0, 25000.0, unit="J/mol"),
               CandParam("charge_transfer_resistance_ohm", 1e-5, 0.2, 2e-3, log=True,
                         unit="Ohm per cell at the anchor temperature and half lithiation"),
               CandParam("window_loss_per_k", 0.0, 0.02, 0.002, unit="1/K below the anchor temperature"))
        if observed is not None and all(self._measured(o) for o in observed):
            return out
        return out + (CandParam("heat_transfer_coefficient_W_m2K", 0.5, 200.0, 10.0, log=True, unit="W/m2/K"),)

    def structure(self, params: PackParams) -> PackParams:
        return self._with_extension(params, {ext.HEAT_TRANSFER: 10.0})

    def extra_inputs(self) -> tuple[str, ...]:
        return (ext.EA_NEG, ext.EA_POS, ext.EA_POS_FULL, ext.COLD_WINDOW, ext.COLD_CHARGE_TRANSFER, ext.HEAT_TRANSFER)

    def ambient_k(self, obs: Observed) -> float:
        return obs.first_temperature_k

    def run_arguments(self, params: PackParams, theta: dict[str, float]) -> dict[str, Any]:
        ea = theta["diffusivity_activation_energy_J_mol"]
        values = {ext.EA_NEG: ea, ext.EA_POS: ea,
                  ext.EA_POS_FULL: theta.get("full_lithiation_activation_energy_J_mol", 0.0),
                  ext.COLD_WINDOW: theta.get("window_loss_per_k", 0.0),
                  ext.COLD_CHARGE_TRANSFER: theta["charge_transfer_resistance_ohm"]}
        if "heat_transfer_coefficient_W_m2K" in theta:
            values[ext.HEAT_TRANSFER] = theta["heat_transfer_coefficient_W_m2K"]
        return {"values": values}

    def simulate(self, engine: Engine, params: PackParams, obs: Observed, theta: dict[str, float], soc: float,
                 t_end: float | None = None, want_temperature: bool = False) -> SimOut:
        measured = self._measured(obs)
        args = self.run_arguments(params, theta)
        # the model with the charge-transfer term (its value is an input of the build)
        struct = self._with_extension(params, {ext.COLD_CHARGE_TRANSFER: 1e-3})
        if not measured:  # self-heating: the lumped thermal model from the params' ambient temperature
            struct = self._with_extension(struct, {ext.HEAT_TRANSFER: 10.0})
            args["values"].setdefault(ext.HEAT_TRANSFER, 10.0)
        else:
            args["values"].pop(ext.HEAT_TRANSFER, None)
        inputs = (ext.EA_NEG, ext.EA_POS, ext.EA_POS_FULL, ext.COLD_WINDOW, ext.COLD_CHARGE_TRANSFER) + (
            () if measured else (ext.HEAT_TRANSFER,))
        return engine.simulate(struct, obs, concentrations=self.concentrations(engine, params, theta, soc),
                               ambient_k=self.ambient_k(obs), t_end=t_end, extra_inputs=inputs,
                               want_temperature=want_temperature, temperature_trace=measured, **args)

    def extended_params(self, params: PackParams, theta: dict[str, float], socs: list[float],
                        engine: Engine) -> PackParams:
        values = {ext.EA_NEG: theta["diffusivity_activation_energy_J_mol"],
                  ext.EA_POS: theta["diffusivity_activation_energy_J_mol"],
                  ext.COLD_CHARGE_TRANSFER: theta["charge_transfer_resistance_ohm"],
                  ext.EA_POS_FULL: theta.get("full_lithiation_activation_energy_J_mol", 0.0),
                  ext.COLD_WINDOW: theta.get("window_loss_per_k", 0.0),
                  ext.ANCHOR_TEMPERATURE: ext.extension_value(params, ext.ANCHOR_TEMPERATURE)}
        if "heat_transfer_coefficient_W_m2K" in theta:  # fitted without a measured temperature: self-heating
            values[ext.HEAT_TRANSFER] = theta["heat_transfer_coefficient_W_m2K"]
        return self._with_extension(params, values)


class CapacityFade(Candidate):
    """Capacity fade as two losses that a partial day determines.

    ``cell_capacity_loss`` f removes the same fraction of both electrodes' active material and of the
    lithium they hold (the cell shrinks, its electrodes' balance kept: the open-circuit voltage against
    the normalised charge is unchanged, the charge in Ah and the active surface are scaled by 1 - f);
    ``lithium_inventory_loss`` g removes cyclable lithium beyond that (SEI growth), which shifts the
    negative electrode's stoichiometry window against the positive one. The loss of active material of
    each electrode is then ``f`` and the loss of lithium inventory ``1 - (1 - f)(1 - g)``.

    A separate loss per electrode is not fitted: on a working day that stops well above the cut-off,
    the electrode whose open-circuit potential is flat over the stoichiometries visited (graphite in an
    NMC cell above mid charge) hardly shows its own loss in the fitted part, and such a change of the
    balance between the electrodes moved the held-out part 12-26 times as much as the fitted part
    (docs/findings.md, "Capacity fade: two losses that a partial day determines").
    """

    name = "capacity_fade"
    title = ("loss of part of the cell (both electrodes' active material with its lithium) and of cyclable "
             "lithium beyond it")
    signature = ("charge_throughput", "soc")

    def parameters(self, params: PackParams, observed: Sequence[Observed] | None = None) -> tuple[CandParam, ...]:
        return (CandParam("cell_capacity_loss", 0.0, 0.4, 0.02),
                CandParam("lithium_inventory_loss", 0.0, 0.4, 0.02))

    @staticmethod
    def losses(theta: dict[str, float]) -> tuple[float, float, float]:
        """(loss of active material negative, positive, loss of lithium inventory), fractions of the params' values."""
        f, g = theta["cell_capacity_loss"], theta["lithium_inventory_loss"]
        return f, f, 1.0 - (1.0 - f) * (1.0 - g)

    @staticmethod
    def faded(params: PackParams, theta: dict[str, float]) -> PackParams:
        """``params`` with the volume fractions scaled and initial concentrations carrying the reduced inventory.

        The initial state is then an SOC of the *faded* cell's own window (PyBaMM's definition), so
        the fitted SOC keeps its meaning while the fade parameters change.
        """
        lam_n, lam_p, lli = CapacityFade.losses(theta)
        pv = cached_parameter_values(params)
        eps_n = float(pv[EPS_N]) * (1 - lam_n)
        eps_p = float(pv[EPS_P]) * (1 - lam_p)
        l_n, l_p = float(pv[L_N]), float(pv[L_P])
        c_n0, c_p0 = float(pv[C_N0]), float(pv[C_P0])
        li = (float(pv[EPS_N]) * l_n * c_n0 + float(pv[EPS_P]) * l_p * c_p0) * (1 - lli)
        k = li / (eps_n * l_n * c_n0 + eps_p * l_p * c_p0)
        return params.with_values({EPS_N: eps_n, EPS_P: eps_p, C_N0: c_n0 * k, C_P0: c_p0 * k})

    def concentrations(self, engine: Engine, params: PackParams, theta: dict[str, float],
                       soc: float) -> tuple[float, float]:
        return engine.concentrations_for_soc(self.faded(params, theta), soc)

    def run_arguments(self, params: PackParams, theta: dict[str, float]) -> dict[str, Any]:
        lam_n, lam_p, _ = self.losses(theta)
        pv = cached_parameter_values(params)
        return {"values": {EPS_N: float(pv[EPS_N]) * (1 - lam_n), EPS_P: float(pv[EPS_P]) * (1 - lam_p)}}

    def extended_params(self, params: PackParams, theta: dict[str, float], socs: list[float],
                        engine: Engine) -> PackParams:
        faded = self.faded(params, theta)
        values = {k: faded.fitted[k] for k in (EPS_N, EPS_P)}
        # initial concentrations: the first recording's fitted start state (same lithium inventory)
        values[C_N0], values[C_P0] = self.concentrations(engine, params, theta, socs[0] if socs else 1.0)
        return self._with_extension(params, values)


class ResistanceGrowth(Candidate):
    name = "resistance_growth"
    title = "film/contact resistance per cell (PyBaMM 'contact resistance' option)"
    signature = ("current",)

    def parameters(self, params: PackParams, observed: Sequence[Observed] | None = None) -> tuple[CandParam, ...]:
        return (CandParam("contact_resistance_ohm", 1e-5, 0.2, 2e-3, log=True, unit="Ohm per cell"),)

    def run_arguments(self, params: PackParams, theta: dict[str, float]) -> dict[str, Any]:
        return {"post": Post(contact_resistance_ohm=theta["contact_resistance_ohm"])}

    def extended_params(self, params: PackParams, theta: dict[str, float], socs: list[float],
                        engine: Engine) -> PackParams:
        return self._with_extension(params, {ext.CONTACT_RESISTANCE: theta["contact_resistance_ohm"]})


class CurrentOffset(Candidate):
    name = "current_offset"
    title = "constant bias of the current sensor (model driven by measured current - offset)"
    signature = ("time",)

    def parameters(self, params: PackParams, observed: Sequence[Observed] | None = None) -> tuple[CandParam, ...]:
        cap = float(params.pack_info.get("nominal_capacity_ah")
                    or float(params.parameter_values()["Nominal cell capacity [A.h]"]) * params.parallel)
        bound = 0.1 * cap  # 0.1 C: far above any healthy sensor
        return (CandParam("current_offset_a", -bound, bound, 0.0, unit="A (pack)"),)

    def run_arguments(self, params: PackParams, theta: dict[str, float]) -> dict[str, Any]:
        return {"offset_a": theta["current_offset_a"]}

    def unresolved(self, fitted: dict[str, float], observed: Sequence[Observed]) -> str | None:
        # a reading quantised to q is itself biased by up to q/2 wherever the current dwells between two levels
        quantum_a = current_resolution_a(observed)
        offset_a = abs(float(fitted.get("current_offset_a", 0.0)))
        if offset_a <= 0.5 * quantum_a:
            return (f"the fitted offset ({offset_a:.3f} A) is within half the current reading's {quantum_a:.3g} A "
                    "step, the bias quantisation alone gives a reading")
        return None

    def sensor_offset_a(self, fitted: dict[str, float]) -> float:
        return float(fitted.get("current_offset_a", 0.0))

    def extended_params(self, params: PackParams, theta: dict[str, float], socs: list[float],
                        engine: Engine) -> PackParams:
        return self._with_extension(params, {ext.CURRENT_OFFSET: theta["current_offset_a"]})


class CellImbalance(Candidate):
    name = "cell_imbalance"
    title = ("one series group of cells with less capacity than the others (electrode area scaled); "
             "per-cell values in liionpack")
    signature = ("soc", "charge_throughput")

    def parameters(self, params: PackParams, observed: Sequence[Observed] | None = None) -> tuple[CandParam, ...]:
        return (CandParam("weak_group_capacity_fraction", 0.4, 1.0, 0.95),)

    def applicable(self, params: PackParams, observed: list[Observed]) -> str | None:
        if params.series < 2:
            return "a single series group has no other group to differ from"
        return None

    def run_arguments(self, params: PackParams, theta: dict[str, float]) -> dict[str, Any]:
        return {"post": Post(weak_fraction=theta["weak_group_capacity_fraction"])}

    def extended_params(self, params: PackParams, theta: dict[str, float], socs: list[float],
                        engine: Engine) -> PackParams:
        return self._with_extension(params, {ext.WEAK_FRACTION: theta["weak_group_capacity_fraction"]})


class ElectrolyteTransport(Candidate):
    name = "electrolyte_transport"
    title = "electrolyte polarisation (SPMe) with a fitted Bruggeman exponent (tortuosity)"
    signature = ("current",)

    def parameters(self, params: PackParams, observed: Sequence[Observed] | None = None) -> tuple[CandParam, ...]:
        return (CandParam("bruggeman_exponent", 1.0, 6.0, 1.5),)

    def structure(self, params: PackParams) -> PackParams:
        return self._with_extension(params, {})

    def extra_inputs(self) -> tuple[str, ...]:
        return ext.BRUGGEMAN_KEYS

    def run_arguments(self, params: PackParams, theta: dict[str, float]) -> dict[str, Any]:
        return {"values": {k: theta["bruggeman_exponent"] for k in ext.BRUGGEMAN_KEYS}}

    def extended_params(self, params: PackParams, theta: dict[str, float], socs: list[float],
                        engine: Engine) -> PackParams:
        return self._with_extension(params, {ext.BRUGGEMAN: theta["bruggeman_exponent"]})


#: Hysteresis time constants (in charge) a discharge-only fit part must span: ``exp(-3)``, the state within
#: 5 % of its discharge branch (settled) by the end of the fit part.
SETTLING_TIME_CONSTANTS = 3.0
#: A fit part charges when its current goes below minus this C-rate (of the pack's nominal capacity).
CHARGE_C_RATE = 0.02
#: Bounds of the hysteresis decay rate K (per unit positive-electrode stoichiometry).
HYS_DECAY_BOUNDS = (1.0, 1000.0)


def fit_part_charges(params: PackParams, obs: Observed) -> bool:
    """Whether the fit part of ``obs`` holds a charge (current below ``-CHARGE_C_RATE`` C, A)."""
    cap = float(params.pack_info.get("nominal_capacity_ah") or 0.0) or 1.0
    return bool(np.any(obs.i[obs.fit_mask] < -CHARGE_C_RATE * cap))


def settling_decay_rate(params: PackParams, observed: Sequence[Observed]) -> float:
    """The smallest hysteresis decay rate K whose state settles within a discharge-only fit part (-).

    Discharging moves the one-state hysteresis towards its discharge branch as ``exp(-K q / Q_p)``
    (``q`` the charge discharged per cell, ``Q_p`` the positive electrode's theoretical charge,
    :func:`~battery_predictor.simulation.extensions.hysteresis_positive_charge_c`). When no fit part
    holds a charge, that relaxation from an unknown initial state is all the fit sees of a hysteresis:
    one that has not settled by the end of the fit part is an exponential drift over the whole
    discharge, a smooth function of the charge drawn that any error of the model's shape along the
    discharge (a weak series group diverging, an open-circuit voltage off) also is, and it carries
    that drift into the held-out part. The rate must then span :data:`SETTLING_TIME_CONSTANTS` time
    constants within the largest fit-part discharge, ``K >= n Q_p / q_fit``. A charge in a fit part
    reverses the state, which tells a hysteresis from a shape error; the rate is then free
    (the lower bound of :data:`HYS_DECAY_BOUNDS`).

    Parameters
    ----------
    params : PackParams
        The pack model (its positive electrode gives ``Q_p``, C).
    observed : sequence of Observed
        The recordings a fit sees (current in A, discharge positive; fit parts up to ``t_split``, s).

    Returns
    -------
    float
        The lower bound of the decay rate K (per unit stoichiometry).
    """
    low = HYS_DECAY_BOUNDS[0]
    if not observed or any(fit_part_charges(params, o) for o in observed):
        return low
    q_fit_c = max(float(discharge_throughput_ah(o.t[o.fit_mask], o.i[o.fit_mask])[-1]) for o in observed
                  ) * 3600.0 / params.parallel
    if q_fit_c <= 0.0:
        return low
    q_p_c = ext.hysteresis_positive_charge_c(cached_parameter_values(params))
    return max(low, SETTLING_TIME_CONSTANTS * q_p_c / q_fit_c)


class Hysteresis(Candidate):
    """PyBaMM's one-state OCP hysteresis in the positive electrode (the ``hysteresis`` extension).

    On recordings whose fit parts only discharge, the decay rate is bounded below so that the state
    settles within the fit part (:func:`settling_decay_rate`).
    """

    name = "hysteresis"
    title = ("one-state OCP hysteresis in the positive electrode (PyBaMM 'Axen' option): half-width, decay "
             "rate, initial branch")
    signature = ("direction",)
    starts = 2

    def parameters(self, params: PackParams, observed: Sequence[Observed] | None = None) -> tuple[CandParam, ...]:
        high = HYS_DECAY_BOUNDS[1]
        # beyond half the upper bound the candidate does not apply (:meth:`applicable`)
        low = min(settling_decay_rate(params, observed or ()), 0.5 * high)
        return (CandParam("hysteresis_half_width_v", 0.0, 0.05, 0.005, unit="V per cell"),
                CandParam("hysteresis_decay_rate", low, high, max(30.0, low), log=True, unit="per unit stoichiometry"),
                CandParam("initial_hysteresis_state", -1.0, 1.0, -0.9))

    def applicable(self, params: PackParams, observed: list[Observed]) -> str | None:
        if settling_decay_rate(params, observed) > 0.5 * HYS_DECAY_BOUNDS[1]:
            return ("the fit parts only discharge, and too little for a hysteresis to settle within them at a decay "
                    f"rate below half the largest ({0.5 * HYS_DECAY_BOUNDS[1]:.0f})")
        return None

    def start_points(self, params: PackParams, rng: np.random.Generator,
                     observed: Sequence[Observed] | None = None) -> list[dict[str, float]]:
        first = {p.name: p.initial for p in self.parameters(params, observed)}
        second = dict(first, initial_hysteresis_state=0.9)
        return [first, second][: max(self.starts, 1)]

    def structure(self, params: PackParams) -> PackParams:
        return self._with_extension(params, {})

    def extra_inputs(self) -> tuple[str, ...]:
        return (ext.HYS_HALF_WIDTH, *ext.PYBAMM_HYS_DECAY_KEYS, ext.PYBAMM_HYS_INITIAL_KEY)

    def run_arguments(self, params: PackParams, theta: dict[str, float]) -> dict[str, Any]:
        values = {ext.HYS_HALF_WIDTH: theta["hysteresis_half_width_v"],
                  ext.PYBAMM_HYS_INITIAL_KEY: theta["initial_hysteresis_state"]}
        for k in ext.PYBAMM_HYS_DECAY_KEYS:
            values[k] = theta["hysteresis_decay_rate"]
        return {"values": values}

    def extended_params(self, params: PackParams, theta: dict[str, float], socs: list[float],
                        engine: Engine) -> PackParams:
        # the predictor starts a discharge on the discharge branch
        return self._with_extension(params, {ext.HYS_HALF_WIDTH: theta["hysteresis_half_width_v"],
                                             ext.HYS_DECAY: theta["hysteresis_decay_rate"],
                                             ext.HYS_INITIAL: -1.0})


#: Every candidate cause, in the order of :data:`battery_predictor.params.EXTENSION_NAMES`.
CANDIDATES: tuple[Candidate, ...] = (
    Temperature(), CapacityFade(), ResistanceGrowth(), CurrentOffset(), CellImbalance(), ElectrolyteTransport(),
    Hysteresis(),
)


def candidate(name: str) -> Candidate:
    """The candidate called ``name`` (``"none"`` = the baseline)."""
    if name == "none":
        return Baseline()
    for c in CANDIDATES:
        if c.name == name:
            return c
    raise KeyError(name)
