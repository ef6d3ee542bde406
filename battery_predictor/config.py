"""Params files: where a bundled one is found, and the checks every YAML reader shares.

One search order for every bundled params file (pack models, load profiles, station maps, node
parameters): :func:`params_dirs`. The source tree's ``params/`` comes first (the editable install
of ``make setup`` reads the files you edit), then ``<prefix>/share/battery_predictor/params`` for
every prefix on ``AMENT_PREFIX_PATH`` (a colcon install) and for ``sys.prefix`` (where ``setup.py``
installs the data files).

The YAML checks (:func:`read_yaml`, :func:`read_yaml_mapping`, :func:`require`, :func:`check_unknown`,
:func:`yaml_number`, :func:`as_float`, :func:`as_float_list`) raise
:class:`~battery_predictor.errors.ParamsError` with a one-line message naming the file and the
dotted key. Every reader of a YAML file of this package (pack params, load profiles, station maps,
node params) converts numbers with :func:`yaml_number`, so one rule holds everywhere: a YAML number,
or a string that YAML 1.2 reads as a decimal number (``1e-3``, which PyYAML's YAML 1.1 loads as the
string ``"1e-3"``); any other string is refused (docs/decisions.md, "Numbers in YAML files").
"""

from __future__ import annotations

import math
import os
import re
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from battery_predictor.errors import ParamsError

PACKAGE = "battery_predictor"

#: A decimal number as YAML 1.2's core schema reads it: ``1e-3``, ``-2.5E+4``, ``.5``, ``3``, ``4.``.
#: PyYAML (YAML 1.1) loads the forms without a dot or without an exponent sign as strings.
YAML12_DECIMAL = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?")


def params_dirs() -> list[Path]:
    """Where bundled params files are looked for, in order (see the module docstring)."""
    dirs = [Path(__file__).resolve().parents[1] / "params"]
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    dirs += [Path(prefix) / "share" / PACKAGE / "params" for prefix in prefixes]
    return dirs


def default_params_file(filename: str) -> Path:
    """Path of a shipped params file (``filename`` relative to ``params/``).

    The first of :func:`params_dirs` that has it; the source-tree path when none has, so that the
    error message names the expected location.
    """
    dirs = params_dirs()
    for directory in dirs:
        if (directory / filename).is_file():
            return directory / filename
    return dirs[0] / filename


def resolve_params_file(value: str) -> str:
    """A params file path: absolute, relative to the working directory, or a bundled file name.

    ``temi.yaml`` resolves to the bundled ``params/temi.yaml`` (:func:`params_dirs`) when no such
    file is in the working directory. An unresolvable path is returned unchanged (the predictor
    then reports the model as not loaded, with the path in the reason).
    """
    if not value:
        return value
    path = Path(value).expanduser()
    if path.is_absolute() or path.exists():
        return str(path)
    for directory in params_dirs():
        if (directory / path).exists():
            return str(directory / path)
    return value


def read_yaml(path: str | Path) -> tuple[Path, Any]:
    """Read a YAML file (any content); ParamsError naming the file when it is a directory, cannot be read,
    or is not valid YAML (with the line of the syntax error)."""
    path = Path(path)
    if path.is_dir():
        raise ParamsError(f"{path}: is a directory, expected a YAML file")
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ParamsError(f"{path}: cannot read params file ({exc.strerror})") from None
    try:
        return path, yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise ParamsError(f"{path}:{where} YAML syntax error: {getattr(exc, 'problem', exc)}") from None


def read_yaml_mapping(path: str | Path, *,
                      not_mapping: str = "top level must be a mapping of keys") -> tuple[Path, dict[str, Any]]:
    """Read a YAML file (:func:`read_yaml`) whose top level is a mapping; ParamsError (``not_mapping``) otherwise."""
    path, data = read_yaml(path)
    if not isinstance(data, dict):
        raise ParamsError(f"{path}: {not_mapping}")
    return path, data


def require(mapping: Mapping[str, Any], key: str, path: Path, where: str) -> Any:
    """``mapping[key]`` or a ParamsError naming the file and the dotted key."""
    if not isinstance(mapping, Mapping):
        raise ParamsError(f"{path}: {where or 'top level'} must be a mapping")
    if key not in mapping:
        raise ParamsError(f"{path}: missing key {_join(where, key)}")
    return mapping[key]


def check_unknown(mapping: Mapping[str, Any], allowed: set[str], path: Path, where: str) -> None:
    """Reject keys not in ``allowed`` (catches typos such as ``lenght_m``)."""
    unknown = sorted(set(mapping) - allowed)
    if unknown:
        raise ParamsError(f"{path}: unknown key {_join(where, str(unknown[0]))} (allowed: {', '.join(sorted(allowed))})")


def yaml_number(value: Any, source: str | Path, key: str, *, allow_nan: bool = False) -> float:
    """A YAML value as a finite float; ParamsError naming ``source`` and the dotted ``key`` otherwise.

    Accepted: a number (not a boolean), or a string that YAML 1.2 reads as a decimal number
    (:data:`YAML12_DECIMAL`, e.g. ``1e-3``). Refused: any other string (``"1,5"``, ``"3.7 V"``,
    ``"0x10"``, ``"1_000"``), booleans, lists, mappings, and infinite or NaN values (NaN passes with
    ``allow_nan``: node parameters where ``.nan`` means "from the params file").
    """
    if isinstance(value, str):
        if not YAML12_DECIMAL.fullmatch(value):
            raise ParamsError(f"{source}: key '{key}': expected a number, got the string {value!r}; write a plain "
                              "decimal number without quotes or units, such as 0.001 or 1e-3")
    elif isinstance(value, bool) or value is None:
        raise ParamsError(f"{source}: key '{key}': expected a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParamsError(f"{source}: key '{key}': expected a number, got {value!r}") from None
    if not math.isfinite(number) and not (allow_nan and math.isnan(number)):
        raise ParamsError(f"{source}: key '{key}': value {value!r} is not finite")
    return number


def as_float(value: Any, path: Path, key: str, *, minimum: float | None = None, strict: bool = False) -> float:
    """Convert to a finite float (:func:`yaml_number`), optionally ``>= minimum`` (``> minimum`` if strict)."""
    number = yaml_number(value, path, key)
    if minimum is not None and (number <= minimum if strict else number < minimum):
        relation = ">" if strict else ">="
        raise ParamsError(f"{path}: {key} must be {relation} {minimum:g}, got {number:g}")
    return number


def as_float_list(value: Any, path: Path, key: str, *, minimum: float | None = None, strict: bool = False,
                  min_length: int = 2) -> list[float]:
    """Convert a YAML list to finite floats (each checked like :func:`as_float`)."""
    if not isinstance(value, list) or len(value) < min_length:
        raise ParamsError(f"{path}: {key} must be a list of at least {min_length} numbers")
    return [as_float(v, path, f"{key}[{i}]", minimum=minimum, strict=strict) for i, v in enumerate(value)]


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key
