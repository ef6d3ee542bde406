"""Params files: where a bundled one is found, and the checks every YAML reader shares.

One search order for every bundled params file (pack models, load profiles, station maps, node
parameters): :func:`params_dirs`. The source tree's ``params/`` comes first (the editable install
of ``make setup`` reads the files you edit), then ``<prefix>/share/battery_predictor/params`` for
every prefix on ``AMENT_PREFIX_PATH`` (a colcon install) and for ``sys.prefix`` (where ``setup.py``
installs the data files).

The YAML checks (:func:`read_yaml_mapping`, :func:`require`, :func:`check_unknown`,
:func:`as_float`, :func:`as_float_list`) raise :class:`~battery_predictor.errors.ParamsError`
with a one-line message naming the file and the dotted key.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from battery_predictor.errors import ParamsError

PACKAGE = "battery_predictor"


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


def read_yaml_mapping(path: str | Path, *,
                      not_mapping: str = "top level must be a mapping of keys") -> tuple[Path, dict[str, Any]]:
    """Read a YAML file whose top level is a mapping; ParamsError (``not_mapping`` when it is not) otherwise."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ParamsError(f"{path}: cannot read params file ({exc.strerror})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ParamsError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
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


def as_float(value: Any, path: Path, key: str, *, minimum: float | None = None, strict: bool = False) -> float:
    """Convert to a finite float, optionally ``>= minimum`` (``> minimum`` if strict)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParamsError(f"{path}: {key} must be a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ParamsError(f"{path}: {key} must be finite, got {value!r}")
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
