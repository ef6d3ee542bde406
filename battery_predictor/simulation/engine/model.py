"""The SPM as PyBaMM discretises it, split into linear particle blocks and a voltage function.

PyBaMM's discretised single particle model (finite volumes on a uniform mesh of each particle,
default 20 cells) is, in its own state vector ``y`` (concentrations divided by their scale),

* two decoupled linear blocks, one per electrode: ``dy_e/dt = A_e y_e + b_e I`` with the cell
  current ``I`` (A) as input;
* a surface stoichiometry per electrode, ``s_e = m_e . y_e`` (PyBaMM's extrapolation row);
* a terminal voltage that depends on the state only through ``s_n``, ``s_p`` (open-circuit
  potentials, Butler-Volmer overpotentials and whatever else the built expression holds).

:func:`extract_linear_spm` builds the params' model with PyBaMM, discretises it with the model's
default mesh and spatial methods (``pybamm.Simulation.build``), reads ``A_e``, ``b_e`` and
``m_e`` off the discretised right-hand side and surface variables by evaluating them on unit
vectors, checks that they are exactly linear, and rewrites PyBaMM's discretised voltage
expression so that its surface values, current, temperature, active material volume fractions
and electrode height are rows of a small input array. The physics therefore has one source:
PyBaMM's expression tree, evaluated by PyBaMM.

Geometric scaling rules used to vary parameter sets without a rebuild (checked against PyBaMM
rebuilds in the tests): on PyBaMM's uniform ``r`` mesh from 0 to the particle radius ``R``,
``A_e`` scales with ``D / R**2`` (a diffusivity that depends on the temperature only is taken at the
isothermal cell's temperature); ``b_e`` with ``1 / (eps L H)`` (active fraction, thickness,
electrode height); the surface row is scale-free; the voltage sees ``R``, ``L`` and ``eps`` only
through the reaction area ``3 eps L / R``, so a set is evaluated with the equivalent volume
fraction ``eps L R_0 / (L_0 R)``. A maximum concentration ``c_max`` scales ``b_e`` with
``1 / c_max`` (the state is the stoichiometry) and, where the exchange-current density is
homogeneous of degree one in the surface and maximum concentrations (as in the parameter sets
shipped with PyBaMM that the project uses), the voltage's current density with ``1 / c_max``:
:func:`c_max_scaling_holds` checks that rule on a PyBaMM rebuild before it is used.

A model built with the option ``{"thermal": "lumped"}`` has one more state, the cell temperature.
The extraction takes the particle equations at the built temperature (their temperature
dependence, the diffusivities', is a factor on the eigenvalues), puts the temperature state into the
voltage's temperature row, and rewrites PyBaMM's discretised heat equation on the same rows plus
the ambient temperature (:class:`LumpedThermal`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from battery_predictor.errors import SimulationError
from battery_predictor.simulation.cell_setup import build_model, prepared_parameter_values, quiet_pybamm

if TYPE_CHECKING:
    import pybamm

    from battery_predictor.params import PackParams

CURRENT = "Current function [A]"
C_N0 = "Initial concentration in negative electrode [mol.m-3]"
C_P0 = "Initial concentration in positive electrode [mol.m-3]"
T_AMB = "Ambient temperature [K]"
T_INIT = "Initial temperature [K]"
EPS_N = "Negative electrode active material volume fraction"
EPS_P = "Positive electrode active material volume fraction"
HEIGHT = "Electrode height [m]"
C_MAX_N = "Maximum concentration in negative electrode [mol.m-3]"
C_MAX_P = "Maximum concentration in positive electrode [mol.m-3]"
#: PyBaMM keys that become ``[input]`` parameters of the extracted model.
INPUT_KEYS = (CURRENT, C_N0, C_P0, T_AMB, T_INIT, EPS_N, EPS_P, HEIGHT)
#: Rows of the voltage function's input array, in order. The temperature row is the cell's
#: temperature: the ambient one of an isothermal cell, the lumped temperature state of a thermal one.
VOLTAGE_ROWS = ("surface_n", "surface_p", CURRENT, T_AMB, EPS_N, EPS_P, HEIGHT)
#: Row of the ambient temperature in the lumped heat equation's input array (after the voltage rows).
AMBIENT_ROW = "ambient temperature"
#: Rows of the heat equation's input array: the voltage rows (row 3 the cell temperature) and the ambient.
THERMAL_ROWS = VOLTAGE_ROWS + (AMBIENT_ROW,)
#: PyBaMM's lumped temperature state.
_TEMPERATURE_VARIABLE = "Volume-averaged cell temperature [K]"
_PARTICLE_VARIABLES = {
    "negative": "X-averaged negative particle concentration [mol.m-3]",
    "positive": "X-averaged positive particle concentration [mol.m-3]",
}
_SURFACE_VARIABLES = {
    "negative": "X-averaged negative particle surface concentration [mol.m-3]",
    "positive": "X-averaged positive particle surface concentration [mol.m-3]",
}
#: Voltage evaluation points per NumPy call.
_VOLTAGE_CHUNK = 16384
#: Largest relative deviation from linearity accepted in the extracted particle equations.
_LINEARITY_RTOL = 1e-9


@dataclass(frozen=True)
class ParticleBlock:
    """One electrode's discretised particle: ``dy/dt = A y + b I``, surface ``s = m . y``.

    Attributes
    ----------
    electrode : str
        ``"negative"`` or ``"positive"``.
    state_slice : slice
        Where the block sits in PyBaMM's state vector.
    a_matrix_per_s : numpy.ndarray
        ``A`` (1/s), shape (n, n).
    b_vector_per_a_s : numpy.ndarray
        ``b`` (1/(A s)), shape (n,).
    surface_row : numpy.ndarray
        ``m`` (dimensionless), shape (n,).
    scale_mol_m3 : float
        PyBaMM's scale of the block's state (concentration = scale x state), mol/m3.
    """

    electrode: str
    state_slice: slice
    a_matrix_per_s: np.ndarray
    b_vector_per_a_s: np.ndarray
    surface_row: np.ndarray
    scale_mol_m3: float


def _evaluate_rows(evaluator: Callable[[float, np.ndarray], Any], rows: Sequence[npt.ArrayLike]) -> np.ndarray:
    """An expression on stacked input rows, elementwise over the rows broadcast together."""
    shape = np.broadcast_shapes(*(np.shape(row) for row in rows))
    size = int(np.prod(shape)) if shape else 1
    aux = np.empty((len(rows), size))
    stacked = aux.reshape((len(rows), *shape))  # a view: assigning broadcasts each row into aux
    for k, row in enumerate(rows):
        stacked[k] = row
    out = np.empty(size)
    for first in range(0, size, _VOLTAGE_CHUNK):  # chunks keep the temporaries in cache
        cols = slice(first, min(first + _VOLTAGE_CHUNK, size))
        out[cols] = np.asarray(evaluator(0.0, aux[:, cols]), dtype=float).ravel()
    return out.reshape(shape)


@dataclass(frozen=True, eq=False)
class LumpedThermal:
    """PyBaMM's lumped heat equation of the cell, ``dT/dt = (Q - h A (T - T_amb)) / (rho c_p V)``.

    The right-hand side is PyBaMM's own discretised expression (option ``{"thermal": "lumped"}``:
    Ohmic, irreversible reaction and reversible entropic heat, contact-resistance heat when that
    option is on, Newton cooling through the cell's cooling surface, the volume-averaged effective
    heat capacity), rewritten like the voltage so that it depends on rows of :data:`THERMAL_ROWS`.

    Attributes
    ----------
    rate_symbol : object
        PyBaMM expression of ``dT/dt`` (K/s) whose ``y`` is the input array of :data:`THERMAL_ROWS`.
    """

    rate_symbol: object

    def temperature_rate_k_s(self, surface_n: npt.ArrayLike, surface_p: npt.ArrayLike, current_a: npt.ArrayLike,
                             temperature_k: npt.ArrayLike, ambient_temperature_k: npt.ArrayLike,
                             eps_n: npt.ArrayLike, eps_p: npt.ArrayLike, height_m: npt.ArrayLike) -> np.ndarray:
        """``dT/dt`` in K/s, elementwise over broadcast arguments (surface stoichiometries, cell current in A,
        cell and ambient temperature in K, the voltage's volume fractions and electrode height in m)."""
        rows = (surface_n, surface_p, current_a, temperature_k, eps_n, eps_p, height_m, ambient_temperature_k)
        return _evaluate_rows(self._evaluator, rows)

    @functools.cached_property
    def _evaluator(self) -> pybamm.EvaluatorPython:
        import pybamm

        return pybamm.EvaluatorPython(self.rate_symbol)


@dataclass(frozen=True, eq=False)
class LinearSpm:
    """PyBaMM's discretised SPM of one cell split into linear blocks and a voltage function.

    Attributes
    ----------
    blocks : tuple of ParticleBlock
        Negative and positive particle.
    voltage_symbol : object
        PyBaMM expression of the terminal voltage (V) whose ``y`` is the input array of
        :data:`VOLTAGE_ROWS` (one column per evaluation point).
    built_values : dict
        Values of the built cell: the :data:`INPUT_KEYS` defaults, particle radii (m),
        diffusivities (m2/s), thicknesses (m).
    lower_cutoff_v : float
        Lower voltage cut-off of the cell (V).
    thermal : LumpedThermal or None
        PyBaMM's lumped heat equation when the model has the option ``{"thermal": "lumped"}``;
        None for an isothermal cell.
    """

    blocks: tuple[ParticleBlock, ParticleBlock]
    voltage_symbol: object
    built_values: dict
    lower_cutoff_v: float
    thermal: LumpedThermal | None = None

    def cell_voltage_v(self, surface_n: np.ndarray, surface_p: np.ndarray, current_a: np.ndarray | float,
                       temperature_k: npt.ArrayLike, eps_n: npt.ArrayLike | None = None,
                       eps_p: npt.ArrayLike | None = None, height_m: npt.ArrayLike | None = None) -> np.ndarray:
        """Terminal voltage (V) of the cell at surface states and cell currents (A), elementwise.

        ``surface_*`` are surface stoichiometries (PyBaMM's state is the concentration over its
        maximum). The optional values default to the built cell's and broadcast against the
        surface arrays.
        """
        b = self.built_values
        rows = (surface_n, surface_p, current_a, temperature_k,
                b[EPS_N] if eps_n is None else eps_n, b[EPS_P] if eps_p is None else eps_p,
                b[HEIGHT] if height_m is None else height_m)
        return _evaluate_rows(self._evaluator, rows)

    @functools.cached_property
    def _evaluator(self) -> pybamm.EvaluatorPython:
        """The voltage expression as generated NumPy code (PyBaMM's ``EvaluatorPython``)."""
        import pybamm

        return pybamm.EvaluatorPython(self.voltage_symbol)

    def initial_state(self, c_n0_mol_m3: float, c_p0_mol_m3: float) -> tuple[np.ndarray, np.ndarray]:
        """Uniform particle states (PyBaMM's scaled ``y`` of each block) for initial concentrations."""
        return tuple(np.full(blk.b_vector_per_a_s.size, c / blk.scale_mol_m3)  # type: ignore[return-value]
                     for blk, c in zip(self.blocks, (c_n0_mol_m3, c_p0_mol_m3)))


def _built_simulation(params: PackParams) -> tuple[pybamm.BaseModel, dict[str, float], float]:
    import pybamm

    if params.model != "SPM":
        raise SimulationError(f"{params.source}: the engine handles the SPM, not the {params.model}")
    pv = prepared_parameter_values(params)
    built = {key: float(pv[key]) for key in (C_N0, C_P0, T_AMB, EPS_N, EPS_P, HEIGHT, C_MAX_N, C_MAX_P)}
    for electrode in ("Negative", "Positive"):
        for key in (f"{electrode} particle radius [m]", f"{electrode} electrode thickness [m]"):
            value = pv[key]
            if not isinstance(value, (int, float)):
                raise SimulationError(f"{params.source}: '{key}' is not a constant; the engine needs a constant")
            built[key] = float(value)
        key = f"{electrode} particle diffusivity [m2.s-1]"
        # a diffusivity that depends on the stoichiometry is refused here (and by the linearity check)
        built[key] = diffusivity_m2_s(pv, key, built[T_AMB])
    built[T_INIT] = built[T_AMB]
    built[CURRENT] = 0.0
    cutoff = float(pv["Lower voltage cut-off [V]"])
    for key in INPUT_KEYS:
        pv[key] = "[input]"
    try:
        with quiet_pybamm():
            sim = pybamm.Simulation(build_model(params), parameter_values=pv)
            sim.build()
    except (pybamm.ModelError, pybamm.DiscretisationError, KeyError, ValueError) as exc:
        raise SimulationError(f"cannot build the cell model: {str(exc).splitlines()[0]}") from None
    return sim.built_model, built, cutoff


def diffusivity_m2_s(pv: pybamm.ParameterValues, key: str, temperature_k: float) -> float:
    """A particle diffusivity of parameter values ``pv`` (m2/s) at ``temperature_k`` (a constant or PyBaMM's function).

    Functions are evaluated at the stoichiometries :data:`STOICHIOMETRY_PROBES` and must not depend on
    them at ``temperature_k``: the extraction's linearity check sees the built temperature only, and a
    diffusivity constant there may depend on the stoichiometry elsewhere (the ``temperature``
    extension's extra activation energy at full lithiation vanishes at its reference temperature).

    Raises
    ------
    SimulationError
        When the value cannot be evaluated or depends on the stoichiometry at ``temperature_k``.
    """
    import pybamm

    value = pv[key]
    if isinstance(value, (int, float)):
        return float(value)
    if not callable(value):
        raise SimulationError(f"'{key}' is neither a number nor a function")
    try:
        out = pv.evaluate(value(pybamm.Vector(np.array(STOICHIOMETRY_PROBES)), pybamm.Scalar(float(temperature_k))))
    except (KeyError, ValueError, TypeError, NotImplementedError) as exc:
        raise SimulationError(f"cannot evaluate '{key}': {str(exc).splitlines()[0]}") from None
    out = np.broadcast_to(np.asarray(out, dtype=float).ravel(), (len(STOICHIOMETRY_PROBES),))
    require_constant_in_stoichiometry(key, out, f"at {float(temperature_k):.2f} K")
    return float(out[1])


#: Stoichiometries at which a diffusivity function is evaluated (the middle one is its value).
STOICHIOMETRY_PROBES = (0.05, 0.5, 0.95)
#: Largest relative spread of a diffusivity over :data:`STOICHIOMETRY_PROBES` still taken as constant.
STOICHIOMETRY_CONSTANT_RTOL = 1e-9


def require_constant_in_stoichiometry(key: str, values: np.ndarray, where: str) -> None:
    """Raise when ``values`` (a diffusivity at :data:`STOICHIOMETRY_PROBES`, along the first axis) differ."""
    spread = np.max(np.abs(values - values[1]), axis=0) / np.maximum(np.abs(values[1]), 1e-300)
    if np.max(spread) > STOICHIOMETRY_CONSTANT_RTOL:
        raise SimulationError(f"'{key}' depends on the stoichiometry {where} (by up to {100 * np.max(spread):.3g} %; "
                              "e.g. the temperature extension's extra activation energy at full lithiation): the "
                              "engine needs a diffusivity constant in it")


def _block_slices(model: pybamm.BaseModel) -> dict[str, slice]:
    slices = {}
    for var, sl in model.y_slices.items():
        for electrode, name in _PARTICLE_VARIABLES.items():
            if var.name == name:
                slices[electrode] = sl[0]
    if set(slices) != set(_PARTICLE_VARIABLES):
        raise SimulationError("the built model has no x-averaged particle concentrations (not an SPM?)")
    return slices


def _linear_map(symbol: pybamm.Symbol, n_states: int, inputs: dict) -> tuple[np.ndarray, np.ndarray]:
    """(Jacobian, value at y = 0 with the current 1 A) of a symbol that must be affine in y and I."""
    zero = np.zeros((n_states, 1))
    idle = dict(inputs, **{CURRENT: 0.0})
    base = np.asarray(symbol.evaluate(0.0, zero, inputs=idle), dtype=float).ravel()
    jac = np.asarray(symbol.evaluate(0.0, np.eye(n_states), inputs=idle), dtype=float)
    jac = jac.reshape(base.size, n_states) - base[:, None]
    unit = np.asarray(symbol.evaluate(0.0, zero, inputs=dict(inputs, **{CURRENT: 1.0})), dtype=float).ravel() - base
    rng = np.random.default_rng(0)
    y_test = rng.uniform(0.1, 0.9, (n_states, 1))
    current_a = 3.7
    got = np.asarray(symbol.evaluate(0.0, y_test, inputs=dict(inputs, **{CURRENT: current_a})), dtype=float).ravel()
    want = base + jac @ y_test.ravel() + unit * current_a
    if not np.allclose(got, want, rtol=_LINEARITY_RTOL, atol=_LINEARITY_RTOL * max(1.0, float(np.abs(want).max()))):
        raise SimulationError("the discretised particle equations are not linear in the state (concentration-"
                              "dependent diffusivity?); use the fast simulator")
    if np.abs(base).max() > _LINEARITY_RTOL * max(1.0, float(np.abs(jac).max())):
        raise SimulationError("the discretised particle equations have a source term at rest")
    return jac, unit


def _replace(symbol: pybamm.Symbol, rule: Callable[[pybamm.Symbol], pybamm.Symbol | None]) -> pybamm.Symbol:
    """A copy of ``symbol`` with every subtree for which ``rule`` returns a symbol replaced by it."""
    new = rule(symbol)
    if new is not None:
        return new
    if not symbol.children:
        return symbol
    children = [_replace(child, rule) for child in symbol.children]
    if all(c is o for c, o in zip(children, symbol.children)):
        return symbol
    return symbol.create_copy(new_children=children)


@dataclass(frozen=True)
class _TemperatureState:
    """Where PyBaMM keeps the lumped temperature: ``T = reference + scale * y[start]``."""

    start: int
    scale_k: float
    reference_k: float


def _temperature_state(model: pybamm.BaseModel) -> _TemperatureState | None:
    for var, sl in model.y_slices.items():
        if var.name == _TEMPERATURE_VARIABLE:
            if sl[0].stop - sl[0].start != 1:
                raise SimulationError("the lumped temperature is not a single state")
            scale = float(var.scale.evaluate()) if hasattr(var.scale, "evaluate") else float(var.scale)
            ref = float(var.reference.evaluate()) if hasattr(var.reference, "evaluate") else float(var.reference)
            return _TemperatureState(sl[0].start, scale, ref)
    return None


def _temperature_as(symbol: pybamm.Symbol, temperature: _TemperatureState | None,
                    value: pybamm.Symbol) -> pybamm.Symbol:
    """``symbol`` with PyBaMM's temperature state replaced by its scaled form of ``value`` (a symbol in K)."""
    import pybamm

    if temperature is None:
        return symbol

    def rule(sym: pybamm.Symbol) -> pybamm.Symbol | None:
        if isinstance(sym, pybamm.StateVector) and sym.y_slices[0].start == temperature.start:
            scaled = (value - pybamm.Scalar(temperature.reference_k)) / pybamm.Scalar(temperature.scale_k)
            return pybamm.Vector(np.ones(1)) * scaled  # a column like the state it replaces
        return None

    return _replace(symbol, rule)


def _rows_symbol(expression: pybamm.Symbol, slices: dict[str, slice], rows_names: tuple[str, ...],
                 temperature: _TemperatureState | None,
                 ambient_row: str | None) -> tuple[pybamm.Symbol, dict[str, np.ndarray]]:
    """A discretised expression with surface values, inputs and the temperature as rows of ``rows_names``.

    The temperature state (a thermal model) becomes the row ``T_AMB`` (the cell temperature);
    the input ``T_AMB`` becomes ``ambient_row`` when given, else the same row.
    """
    import pybamm

    rows = {name: pybamm.StateVector(slice(k, k + 1)) for k, name in enumerate(rows_names)}
    by_start = {sl.start: electrode for electrode, sl in slices.items()}
    surface_rows: dict[str, np.ndarray] = {}
    inputs = dict(zip(rows_names, rows_names))
    if ambient_row is not None:
        inputs[T_AMB] = ambient_row
    elif temperature is not None:
        inputs.pop(T_AMB)  # the cell temperature is the state: the ambient must not enter

    def rule(sym: pybamm.Symbol) -> pybamm.Symbol | None:
        if isinstance(sym, pybamm.MatrixMultiplication) and isinstance(sym.right, pybamm.StateVector):
            start = sym.right.y_slices[0].start
            if start not in by_start or sym.shape != (1, 1):
                raise SimulationError("the voltage depends on the state other than through surface values")
            electrode = by_start[start]
            row = np.asarray(sym.left.entries.toarray() if hasattr(sym.left.entries, "toarray")
                             else sym.left.entries, dtype=float).ravel()
            factor = float(row.sum())  # extrapolation rows of the scaled state sum to one
            if factor == 0.0:
                raise SimulationError(f"the voltage uses a {electrode} state row that is not a surface value")
            unit_row = row / factor
            if electrode in surface_rows and not np.allclose(surface_rows[electrode], unit_row, rtol=1e-13, atol=0):
                raise SimulationError(f"the voltage uses two different {electrode} surface rows")
            surface_rows.setdefault(electrode, unit_row)
            placeholder = rows[f"surface_{electrode[0]}"]
            return placeholder if factor == 1.0 else pybamm.Scalar(factor) * placeholder
        if isinstance(sym, pybamm.StateVector):
            if temperature is not None and sym.y_slices[0].start == temperature.start and sym.shape == (1, 1):
                return (rows[T_AMB] - pybamm.Scalar(temperature.reference_k)) / pybamm.Scalar(temperature.scale_k)
            raise SimulationError("the voltage depends on the state other than through surface values")
        if isinstance(sym, pybamm.InputParameter):
            if sym.name not in inputs:
                raise SimulationError(f"the expression depends on the input '{sym.name}'")
            return rows[inputs[sym.name]]
        return None

    return _replace(expression, rule), surface_rows


def _voltage_symbol(model: pybamm.BaseModel, slices: dict[str, slice],
                    temperature: _TemperatureState | None = None) -> tuple[pybamm.Symbol, dict[str, np.ndarray]]:
    """PyBaMM's discretised voltage with surface values and inputs as rows of :data:`VOLTAGE_ROWS`."""
    return _rows_symbol(model.variables["Voltage [V]"], slices, VOLTAGE_ROWS, temperature, None)


def _lumped_thermal(model: pybamm.BaseModel, slices: dict[str, slice], temperature: _TemperatureState,
                    voltage_rows: dict[str, np.ndarray]) -> LumpedThermal:
    """PyBaMM's lumped heat equation as ``dT/dt`` (K/s) on the rows of :data:`THERMAL_ROWS`."""
    import pybamm

    var = next(v for v in model.rhs if v.name == _TEMPERATURE_VARIABLE)
    rate, surface_rows = _rows_symbol(model.rhs[var], slices, THERMAL_ROWS, temperature, AMBIENT_ROW)
    for electrode, row in surface_rows.items():
        if not np.allclose(row, voltage_rows[electrode], rtol=1e-13, atol=0):
            raise SimulationError(f"the heat equation uses another {electrode} surface row than the voltage")
    return LumpedThermal(rate_symbol=pybamm.Scalar(temperature.scale_k) * rate)


def extract_linear_spm(params: PackParams) -> LinearSpm:
    """PyBaMM's discretised SPM of ``params``' cell as a :class:`LinearSpm`.

    Model options and extensions are taken as PyBaMM builds them; the extraction checks what it
    relies on.

    Raises
    ------
    SimulationError
        When the model is not an SPM whose particle equations are linear with constant
        coefficients and whose voltage depends on the state through the two surface values only.
    """
    import pybamm

    model, built, cutoff = _built_simulation(params)
    slices = _block_slices(model)
    temperature = _temperature_state(model)
    if temperature is None and "thermal" in model.options and model.options["thermal"] != "isothermal":
        raise SimulationError(f"the engine covers isothermal and lumped thermal cells, not "
                              f"'{model.options['thermal']}'")
    n_states = model.concatenated_rhs.shape[0]
    inputs = {key: built[key] for key in INPUT_KEYS}
    voltage, surface_rows = _voltage_symbol(model, slices, temperature)
    if set(surface_rows) != set(slices):
        raise SimulationError("the voltage does not depend on both surface values")
    # particle equations of a thermal cell at the built temperature (its diffusivities' own
    # temperature dependence is a factor on the eigenvalues, see engine.thermal)
    cell_temperature = pybamm.InputParameter(T_AMB)
    blocks = []
    for electrode, sl in slices.items():
        var = next(v for v in model.y_slices if v.name == _PARTICLE_VARIABLES[electrode])
        jac, unit = _linear_map(_temperature_as(model.rhs[var], temperature, cell_temperature), n_states, inputs)
        outside = np.delete(jac, np.arange(sl.start, sl.stop), axis=1)
        if np.abs(outside).max(initial=0.0) > 0.0:
            raise SimulationError(f"the {electrode} particle is coupled to other states")
        scale = float(var.scale.evaluate()) if hasattr(var.scale, "evaluate") else float(var.scale)
        row = surface_rows[electrode]
        _check_surface(model.variables[_SURFACE_VARIABLES[electrode]], sl, row * scale, n_states, inputs, electrode)
        blocks.append(ParticleBlock(electrode=electrode, state_slice=sl, a_matrix_per_s=jac[:, sl],
                                    b_vector_per_a_s=unit, surface_row=row, scale_mol_m3=scale))
    thermal = None if temperature is None else _lumped_thermal(model, slices, temperature, surface_rows)
    return LinearSpm(blocks=(blocks[0], blocks[1]), voltage_symbol=voltage, built_values=built,
                     lower_cutoff_v=cutoff, thermal=thermal)


def _check_surface(surface: pybamm.Symbol, sl: slice, row_mol_m3: np.ndarray, n_states: int, inputs: dict, electrode: str) -> None:
    """The surface concentration variable must be the voltage's surface row times the scale, without feed-through."""
    jac, unit = _linear_map(surface, n_states, inputs)
    want = np.zeros(n_states)
    want[sl] = row_mol_m3
    if np.abs(unit).max() > 0.0 or not np.allclose(jac.ravel(), want, rtol=1e-12, atol=1e-9):
        raise SimulationError(f"the {electrode} surface concentration is not the voltage's surface row")


#: Relative change of the maximum concentrations in the check of their scaling rule.
_C_MAX_CHECK_FACTORS = (1.13, 0.91)


def c_max_scaling_holds(params: PackParams) -> bool:
    """True when changing ``params``' maximum concentrations is the scaling of the module docstring.

    Compares a PyBaMM rebuild with changed maximum concentrations against the scaled extraction:
    the particle input vectors and the voltage at several stoichiometries and currents. Returns
    False (maximum concentrations then need a rebuild) when the model cannot be extracted either.
    """
    keys = (C_MAX_N, C_MAX_P)
    try:
        base = extract_linear_spm(params)
        pv = params.parameter_values()
        changed_values = {k: float(pv[k]) * f for k, f in zip(keys, _C_MAX_CHECK_FACTORS)}
        changed = extract_linear_spm(params.with_values(changed_values))
    except SimulationError:
        return False
    for blk, other, f in zip(base.blocks, changed.blocks, _C_MAX_CHECK_FACTORS):
        if not np.allclose(other.b_vector_per_a_s, blk.b_vector_per_a_s / f, rtol=1e-10, atol=0.0):
            return False
        if not np.allclose(other.a_matrix_per_s, blk.a_matrix_per_s, rtol=1e-10, atol=0.0):
            return False
    grid = np.linspace(0.05, 0.95, 7)
    s_n, s_p, current = np.meshgrid(grid, grid[::-1], np.array([-3.0, 0.5, 4.0]))
    t_k = base.built_values[T_AMB]
    want = changed.cell_voltage_v(s_n, s_p, current, t_k)
    got = base.cell_voltage_v(s_n, s_p, current, t_k, eps_n=base.built_values[EPS_N] * _C_MAX_CHECK_FACTORS[0],
                              eps_p=base.built_values[EPS_P] * _C_MAX_CHECK_FACTORS[1])
    return bool(np.allclose(got, want, rtol=0.0, atol=1e-10))
