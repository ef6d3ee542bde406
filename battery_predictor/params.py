"""Pack parameter files (``params/*.yaml``): the one way to describe any pack.

A params file names the pack configuration (series x parallel), the PyBaMM base
parameter set of its cells, the values set by hand and the fitted values (as
PyBaMM ``"Name [unit]"`` keys), the liionpack interconnect resistances, the
decision thresholds and what a fit may vary. Every value carries its unit in its
key: PyBaMM keys keep their ``[unit]`` bracket, our own keys end in a unit suffix
(``_v``, ``_a``, ``_s``, ``_k``, ``_ah``, ``_ohm``...).
"""

from __future__ import annotations

import copy
import functools
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import yaml

from battery_predictor.config import read_yaml, yaml_number
from battery_predictor.errors import ParamsError
from battery_predictor.ocp import cell_parameter_values, section_to_values, values_to_section
from battery_predictor.params_checks import check_physical

if TYPE_CHECKING:
    import pybamm

#: Unit suffixes accepted on our own (non-PyBaMM) keys.
UNIT_SUFFIXES = (
    "_v", "_a", "_s", "_k", "_ah", "_ohm", "_pct", "_m", "_kg", "_m_s", "_w", "_c_rate", "_hz", "_fraction", "_c",
)
#: Model types a params file may ask for.
MODEL_TYPES = ("SPM", "SPMe", "DFN")
#: Model extensions a params file may activate (``extensions: [...]``), in the order the diagnosis reports
#: them. Each is a cause ``battery-predictor diagnose`` can name; what each one changes in the model is
#: :mod:`battery_predictor.simulation.extensions`.
EXTENSION_NAMES = (
    "temperature",
    "capacity_fade",
    "resistance_growth",
    "current_offset",
    "cell_imbalance",
    "electrolyte_transport",
    "hysteresis",
)
#: Interconnect resistances of the liionpack netlist (busbar, connection, internal guess, terminal).
INTERCONNECT_KEYS = ("r_b_ohm", "r_c_ohm", "r_i_ohm", "r_t_ohm")
#: The current (A) the route threshold applies at when ``thresholds.standstill_current_a`` is not given (paper 5.2).
DEFAULT_STANDSTILL_CURRENT_A = 1.70
_TOP_LEVEL = ("name", "description", "pack", "cell", "interconnect", "thresholds", "operating", "fit", "extensions",
              "provenance")
_PACK_KEYS = {"series": int, "parallel": int, "nominal_voltage_v": float, "nominal_capacity_ah": float,
              "min_voltage_v": float, "max_voltage_v": float}
_CELL_KEYS = ("model", "base_parameter_set", "options", "manual", "ocp", "fitted", "extra")
_FIT_KEYS = ("parameters", "bounds")
_UNIT_BRACKET = re.compile(r"^(?P<name>.*?)\s*\[(?P<unit>[^\]]*)\]\s*$")


@functools.lru_cache(maxsize=16)
def _base_keys(base_parameter_set: str) -> frozenset[str]:
    import pybamm

    return frozenset(pybamm.ParameterValues(base_parameter_set).keys())


@functools.lru_cache(maxsize=1)
def _all_pybamm_keys() -> frozenset[str]:
    """Every parameter name of every PyBaMM parameter set (keys a cell may add to its base set)."""
    import pybamm

    keys: set[str] = set()
    for name in pybamm.parameter_sets:
        try:
            keys |= set(pybamm.ParameterValues(name).keys())
        except Exception:  # noqa: BLE001 - a broken third-party set must not break validation
            continue
    return frozenset(keys)


def _strip_unit(key: str) -> str:
    m = _UNIT_BRACKET.match(key)
    return m.group("name") if m else key.strip()


def check_pybamm_key(key: str, base_parameter_set: str, source: str, extra_allowed: frozenset[str] = frozenset()) -> None:
    """Raise :class:`ParamsError` unless ``key`` is a parameter of the base set (with its unit).

    Parameters
    ----------
    key : str
        A PyBaMM parameter name such as ``"Electrode height [m]"``.
    base_parameter_set : str
        PyBaMM parameter set name (``"Chen2020"``...).
    source : str
        File name used in the message.
    extra_allowed : frozenset of str
        Keys that are valid although the base set lacks them (model-option parameters).
    """
    if key in _base_keys(base_parameter_set) or key in extra_allowed:
        return
    keys = _base_keys(base_parameter_set) | extra_allowed | _all_pybamm_keys()
    if key in keys:
        return
    bare = _strip_unit(key)
    same_name = sorted(k for k in keys if _strip_unit(k) == bare)
    if same_name:
        if "[" not in key:
            raise ParamsError(f"{source}: key '{key}': missing unit, use '{same_name[0]}'")
        raise ParamsError(f"{source}: key '{key}': wrong unit, {base_parameter_set} defines '{same_name[0]}'")
    raise ParamsError(f"{source}: unknown key '{key}': not a PyBaMM parameter (base set {base_parameter_set})")


def _check_unit_suffix(key: str, source: str, section: str) -> None:
    if not any(key.endswith(s) for s in UNIT_SUFFIXES):
        raise ParamsError(
            f"{source}: key '{section}.{key}': missing unit; our keys end in a unit suffix such as "
            f"{', '.join(UNIT_SUFFIXES[:6])}"
        )


@dataclass(frozen=True)
class FitSpec:
    """What a fit may vary and within which bounds.

    Attributes
    ----------
    parameters : tuple of str
        PyBaMM keys and/or interconnect names (``r_b_ohm``...).
    bounds : dict
        Optional explicit ``{name: (low, high)}`` bounds overriding the default rule.
    """

    parameters: tuple[str, ...] = ()
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)


@dataclass(frozen=True)
class PackParams:
    """A parsed, validated params file.

    Attributes
    ----------
    name : str
        Pack identifier.
    series, parallel : int
        Cells in series per string and strings in parallel.
    base_parameter_set : str
        PyBaMM parameter set the cell values start from.
    model : str
        ``"SPM"`` (default), ``"SPMe"`` or ``"DFN"``.
    options : dict
        PyBaMM model options (e.g. ``{"thermal": "lumped"}``).
    manual, fitted : dict
        PyBaMM ``"Name [unit]"`` values set by hand, and fitted values (fitted wins).
    ocp : dict
        A measured positive-electrode OCP as the scalars of :mod:`battery_predictor.ocp` (empty: the
        base set's OCP); ``ocp_source`` says where it was measured.
    interconnect : dict
        ``r_b_ohm``, ``r_c_ohm``, ``r_i_ohm``, ``r_t_ohm`` in Ohm.
    thresholds, operating, pack_info : dict
        Unit-suffixed scalars (decision thresholds, ambient temperature, nominal values).
    fit : FitSpec
        Fit parameters and bounds.
    extensions : tuple of str
        Active model extensions (see :data:`EXTENSION_NAMES`; the physics: :mod:`battery_predictor.simulation.extensions`).
    provenance : dict
        Free-form record of where fitted values came from.
    source : str
        File the params were loaded from.
    """

    name: str
    series: int
    parallel: int
    base_parameter_set: str
    model: str = "SPM"
    options: dict[str, Any] = field(default_factory=dict)
    manual: dict[str, float] = field(default_factory=dict)
    fitted: dict[str, float] = field(default_factory=dict)
    extra: dict[str, float] = field(default_factory=dict)
    ocp: dict[str, float] = field(default_factory=dict)
    ocp_source: str = ""
    interconnect: dict[str, float] = field(default_factory=dict)
    thresholds: dict[str, float] = field(default_factory=dict)
    operating: dict[str, float] = field(default_factory=dict)
    pack_info: dict[str, float] = field(default_factory=dict)
    fit: FitSpec = field(default_factory=FitSpec)
    extensions: tuple[str, ...] = ()
    provenance: dict[str, Any] = field(default_factory=dict)
    description: str = ""
    source: str = "<memory>"

    # ------------------------------------------------------------------ values
    @property
    def n_cells(self) -> int:
        """Number of cells in the pack."""
        return self.series * self.parallel

    @property
    def cell_values(self) -> dict[str, float]:
        """PyBaMM values that differ from the base set (manual, measured OCP, fitted, extension extras)."""
        out = dict(self.manual)
        out.update(self.ocp)
        out.update(self.fitted)
        out.update(self.extra)
        return out

    @property
    def ambient_temperature_k(self) -> float:
        """Default ambient temperature in K."""
        return float(self.operating.get("ambient_temperature_k", 298.15))

    @property
    def cell_lower_cutoff_v(self) -> float:
        """Cell-level lower voltage cut-off in V (the liionpack termination criterion)."""
        return float(self.parameter_values()["Lower voltage cut-off [V]"])

    def value(self, name: str) -> float:
        """Current value of a fit parameter (PyBaMM key or interconnect name)."""
        if name in INTERCONNECT_KEYS:
            return float(self.interconnect[name])
        vals = self.cell_values
        if name in vals:
            return float(vals[name])
        v = self.parameter_values()[name]
        if not isinstance(v, (int, float)):
            raise ParamsError(f"{self.source}: parameter '{name}' is a function in {self.base_parameter_set}, "
                              "it cannot be fitted as a scalar")
        return float(v)

    def parameter_values(self) -> pybamm.ParameterValues:
        """PyBaMM ``ParameterValues``: base set updated with manual, fitted and extension values."""
        return cell_parameter_values(self.base_parameter_set, self.cell_values)

    def fingerprint(self) -> tuple[str, str]:
        """What :meth:`parameter_values` depends on: the base set and the cell's own values (a hashable key)."""
        return self.base_parameter_set, repr(sorted(self.cell_values.items()))

    def with_values(self, updates: Mapping[str, float], **changes: Any) -> PackParams:
        """Return a copy with fit-parameter values replaced.

        PyBaMM keys go to ``fitted``; keys already in ``cell.extra`` (the extensions' values) stay in
        ``extra``, which :attr:`cell_values` applies last (a value written to ``fitted`` under such a key
        would have no effect).
        """
        fitted = dict(self.fitted)
        extra = dict(self.extra)
        interconnect = dict(self.interconnect)
        for key, val in updates.items():
            if key in INTERCONNECT_KEYS:
                interconnect[key] = float(val)
            elif key in extra:
                extra[key] = float(val)
                fitted.pop(key, None)
            else:
                fitted[key] = float(val)
        return replace(self, fitted=fitted, extra=extra, interconnect=interconnect, **changes)

    # ------------------------------------------------------------------ output
    def to_dict(self) -> dict[str, Any]:
        """The params as a YAML-ready dict (same layout as the files in ``params/``; provenance paths relative)."""
        out: dict[str, Any] = {
            "name": self.name,
            "description": self.description,
            "pack": {"series": self.series, "parallel": self.parallel, **self.pack_info},
            "cell": {
                "model": self.model,
                "base_parameter_set": self.base_parameter_set,
                "options": copy.deepcopy(self.options),
                "manual": dict(self.manual),
                "fitted": dict(self.fitted),
            },
            "interconnect": dict(self.interconnect),
            "thresholds": dict(self.thresholds),
            "operating": dict(self.operating),
            "fit": {"parameters": list(self.fit.parameters)},
            "extensions": list(self.extensions),
        }
        if self.ocp:
            out["cell"]["ocp"] = values_to_section(self.ocp, self.ocp_source)
        if self.extra:
            out["cell"]["extra"] = dict(self.extra)
        if self.fit.bounds:
            out["fit"]["bounds"] = {k: [float(lo), float(hi)] for k, (lo, hi) in self.fit.bounds.items()}
        if self.provenance:
            from battery_predictor.io.paths import portable_paths

            out["provenance"] = portable_paths(copy.deepcopy(self.provenance))
        return out

    def to_yaml(self, path: str | Path) -> Path:
        """Write the params to ``path`` (loadable by :func:`load_params`)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        header = (f"# Pack params '{self.name}' written by battery_predictor.\n"
                  "# Units are in the keys: PyBaMM '[unit]' brackets, or *_v/_a/_s/_k/_ah/_ohm suffixes.\n")
        path.write_text(header + yaml.safe_dump(self.to_dict(), sort_keys=False, allow_unicode=True))
        return path


def _section(data: Mapping[str, Any], key: str, source: str, required: bool = True) -> dict[str, Any]:
    if key not in data or data[key] is None:
        if required:
            raise ParamsError(f"{source}: missing section '{key}'")
        return {}
    val = data[key]
    if not isinstance(val, Mapping):
        raise ParamsError(f"{source}: section '{key}' must be a mapping, got {type(val).__name__}")
    return dict(val)


def _unit_scalars(section: Mapping[str, Any], name: str, source: str) -> dict[str, float]:
    out = {}
    for k, v in section.items():
        _check_unit_suffix(str(k), source, name)
        out[str(k)] = yaml_number(v, source, f"{name}.{k}")
    return out


def params_from_dict(data: Mapping[str, Any], source: str = "<memory>") -> PackParams:
    """Validate a params mapping (as read from YAML) and build :class:`PackParams`.

    The sections are checked in the file's order (top level, ``pack``, ``cell``, ``interconnect``,
    ``thresholds``, ``operating``, ``fit``, ``extensions``, ``provenance``), so the first error
    reported is the first one in the file.

    Raises
    ------
    ParamsError
        On an unknown key, a key without a unit, a wrong type or a physically impossible value
        (:func:`battery_predictor.params_checks.check_physical`); the message names ``source`` and the key.
    """
    _check_top_level(data, source)
    name = str(data.get("name") or Path(source).stem)
    series, parallel, pack_info = _pack_from(data, source)
    cell = _cell_from(data, source)
    interconnect = _interconnect_from(data, source)
    thresholds = _unit_scalars(_section(data, "thresholds", source, required=False), "thresholds", source)
    operating = _unit_scalars(_section(data, "operating", source, required=False), "operating", source)
    fit = _fit_from(data, source, cell.base, frozenset(cell.extra))
    extensions = _extensions_from(data, source)
    provenance = data.get("provenance") or {}
    if not isinstance(provenance, Mapping):
        raise ParamsError(f"{source}: key 'provenance' must be a mapping")
    params = PackParams(
        name=name,
        description=str(data.get("description") or ""),
        series=series,
        parallel=parallel,
        base_parameter_set=cell.base,
        model=cell.model,
        options=cell.options,
        manual=cell.manual,
        fitted=cell.fitted,
        extra=cell.extra,
        ocp=cell.ocp,
        ocp_source=cell.ocp_source,
        interconnect=interconnect,
        thresholds=thresholds,
        operating=operating,
        pack_info=pack_info,
        fit=fit,
        extensions=extensions,
        provenance=dict(provenance),
        source=source,
    )
    check_physical(params)
    return params


def _check_top_level(data: Any, source: str) -> None:
    """``data`` is a mapping whose keys are all known sections."""
    if not isinstance(data, Mapping):
        raise ParamsError(f"{source}: top level must be a mapping")
    for key in data:
        if key not in _TOP_LEVEL:
            raise ParamsError(f"{source}: unknown key '{key}' (allowed: {', '.join(_TOP_LEVEL)})")


def _pack_from(data: Mapping[str, Any], source: str) -> tuple[int, int, dict[str, float]]:
    """The ``pack`` section: (cells in series, strings in parallel, the other values by their unit-suffixed keys)."""
    pack = _section(data, "pack", source)
    for key in pack:
        if key not in _PACK_KEYS:
            if not any(str(key).endswith(s) for s in UNIT_SUFFIXES):
                raise ParamsError(f"{source}: key 'pack.{key}': missing unit or unknown key")
            raise ParamsError(f"{source}: unknown key 'pack.{key}' (allowed: {', '.join(_PACK_KEYS)})")
    for key in ("series", "parallel"):
        if key not in pack:
            raise ParamsError(f"{source}: missing key 'pack.{key}'")
        val = pack[key]
        if isinstance(val, bool) or not isinstance(val, int) or val < 1:
            raise ParamsError(f"{source}: key 'pack.{key}': expected a positive integer, got {val!r}")
    pack_info = {k: yaml_number(v, source, f"pack.{k}") for k, v in pack.items() if k not in ("series", "parallel")}
    return int(pack["series"]), int(pack["parallel"]), pack_info


class _Cell(NamedTuple):
    """The checked ``cell`` section."""

    base: str
    model: str
    options: dict[str, Any]
    extra: dict[str, float]
    manual: dict[str, float]
    fitted: dict[str, float]
    ocp: dict[str, float]
    ocp_source: str


def _cell_from(data: Mapping[str, Any], source: str) -> _Cell:
    """The ``cell`` section: base set, model, options, extra/manual/fitted PyBaMM values, measured OCP."""
    cell = _section(data, "cell", source)
    for key in cell:
        if key not in _CELL_KEYS:
            raise ParamsError(f"{source}: unknown key 'cell.{key}' (allowed: {', '.join(_CELL_KEYS)})")
    base = _base_parameter_set(cell, source)
    model = str(cell.get("model", "SPM"))
    if model not in MODEL_TYPES:
        raise ParamsError(f"{source}: key 'cell.model': '{model}' is not one of {', '.join(MODEL_TYPES)}")
    options = cell.get("options") or {}
    if not isinstance(options, Mapping):
        raise ParamsError(f"{source}: key 'cell.options' must be a mapping of PyBaMM model options")
    extra = {}
    for key, val in (cell.get("extra") or {}).items():
        if "[" not in str(key) and not str(key).endswith("fraction"):
            raise ParamsError(f"{source}: key 'cell.extra.{key}': missing unit (use a PyBaMM '[unit]' key)")
        extra[str(key)] = yaml_number(val, source, f"cell.extra.{key}")
    manual = _pybamm_values(cell, "manual", base, frozenset(extra), source)
    fitted = _pybamm_values(cell, "fitted", base, frozenset(extra), source)
    ocp_raw = cell.get("ocp") or {}
    if not isinstance(ocp_raw, Mapping):
        raise ParamsError(f"{source}: key 'cell.ocp' must be a mapping (see battery_predictor/ocp.py)")
    ocp = section_to_values(ocp_raw, source)
    ocp_source = str((ocp_raw.get("positive") or {}).get("source", "")) if ocp else ""
    return _Cell(base, model, dict(options), extra, manual, fitted, ocp, ocp_source)


def _base_parameter_set(cell: Mapping[str, Any], source: str) -> str:
    """``cell.base_parameter_set``: the name of one of PyBaMM's parameter sets."""
    base = cell.get("base_parameter_set")
    if not isinstance(base, str):
        raise ParamsError(f"{source}: missing key 'cell.base_parameter_set' (a PyBaMM parameter set name)")
    import pybamm

    if base not in pybamm.parameter_sets:
        raise ParamsError(f"{source}: key 'cell.base_parameter_set': unknown PyBaMM parameter set '{base}'")
    return base


def _pybamm_values(cell: Mapping[str, Any], section: str, base: str, extra_keys: frozenset[str],
                   source: str) -> dict[str, float]:
    """``cell.<section>`` (``manual`` or ``fitted``): PyBaMM keys of ``base`` (or of ``cell.extra``) to numbers."""
    raw = cell.get(section) or {}
    if not isinstance(raw, Mapping):
        raise ParamsError(f"{source}: key 'cell.{section}' must be a mapping of PyBaMM keys to numbers")
    out = {}
    for key, val in raw.items():
        check_pybamm_key(str(key), base, source, extra_keys)
        out[str(key)] = yaml_number(val, source, f"cell.{section}.{key}")
    return out


def _interconnect_from(data: Mapping[str, Any], source: str) -> dict[str, float]:
    """The ``interconnect`` section (Ohm, each > 0) over the defaults of a section left out."""
    interconnect = {"r_b_ohm": 1e-4, "r_c_ohm": 1e-2, "r_i_ohm": 1e-2, "r_t_ohm": 1e-5}
    for key, val in _section(data, "interconnect", source, required=False).items():
        if key not in INTERCONNECT_KEYS:
            if not any(str(key).endswith(s) for s in UNIT_SUFFIXES):
                raise ParamsError(f"{source}: key 'interconnect.{key}': missing unit (expected one of "
                                  f"{', '.join(INTERCONNECT_KEYS)})")
            raise ParamsError(f"{source}: unknown key 'interconnect.{key}' (allowed: {', '.join(INTERCONNECT_KEYS)})")
        v = yaml_number(val, source, f"interconnect.{key}")
        if v <= 0:
            raise ParamsError(f"{source}: key 'interconnect.{key}': resistance must be > 0 (liionpack's netlist "
                              f"needs a conductance), got {v}")
        interconnect[key] = v
    return interconnect


def _fit_from(data: Mapping[str, Any], source: str, base: str, extra_keys: frozenset[str]) -> FitSpec:
    """The ``fit`` section: the parameters to fit (PyBaMM or interconnect keys) and their [low, high] bounds."""
    fit_raw = _section(data, "fit", source, required=False)
    for key in fit_raw:
        if key not in _FIT_KEYS:
            raise ParamsError(f"{source}: unknown key 'fit.{key}' (allowed: {', '.join(_FIT_KEYS)})")
    fit_params = []
    for p in fit_raw.get("parameters") or []:
        p = str(p)
        if p not in INTERCONNECT_KEYS:
            check_pybamm_key(p, base, source, extra_keys)
        fit_params.append(p)
    bounds = {}
    for key, pair in (fit_raw.get("bounds") or {}).items():
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise ParamsError(f"{source}: key 'fit.bounds.{key}': expected [low, high]")
        lo, hi = (yaml_number(x, source, f"fit.bounds.{key}") for x in pair)
        if not lo < hi:
            raise ParamsError(f"{source}: key 'fit.bounds.{key}': low {lo} must be below high {hi}")
        bounds[str(key)] = (lo, hi)
    return FitSpec(parameters=tuple(fit_params), bounds=bounds)


def _extensions_from(data: Mapping[str, Any], source: str) -> tuple[str, ...]:
    """The ``extensions`` list: names of :data:`EXTENSION_NAMES`."""
    extensions = data.get("extensions") or []
    if not isinstance(extensions, list):
        raise ParamsError(f"{source}: key 'extensions' must be a list of extension names")
    for ext in extensions:
        if ext not in EXTENSION_NAMES:
            raise ParamsError(f"{source}: key 'extensions': unknown extension '{ext}' "
                              f"(known: {', '.join(EXTENSION_NAMES)})")
    return tuple(str(e) for e in extensions)


class _ByFingerprint:
    """A :class:`PackParams` that hashes and compares by :meth:`PackParams.fingerprint` (a cache key)."""

    __slots__ = ("key", "params")

    def __init__(self, params: PackParams) -> None:
        self.params = params
        self.key = params.fingerprint()

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _ByFingerprint) and other.key == self.key


@functools.lru_cache(maxsize=512)
def _parameter_values_of(keyed: _ByFingerprint) -> pybamm.ParameterValues:
    return keyed.params.parameter_values()


def cached_parameter_values(params: PackParams) -> pybamm.ParameterValues:
    """``params.parameter_values()``, cached on the params' fingerprint (building a PyBaMM set costs ~10 ms).

    Shared by every caller: do not modify the result.
    """
    return _parameter_values_of(_ByFingerprint(params))


def load_params(path: str | Path) -> PackParams:
    """Load and validate a params YAML file.

    Raises
    ------
    ParamsError
        Missing file, YAML syntax error, or any validation problem (message names the file and key).
    """
    path = Path(path)
    if path.is_dir():
        raise ParamsError(f"{path}: is a directory, expected a params YAML file such as params/temi.yaml")
    if not path.is_file():
        raise ParamsError(f"{path}: params file not found")
    path, data = read_yaml(path)
    if data is None:
        raise ParamsError(f"{path}: params file is empty")
    return params_from_dict(data, source=str(path))
