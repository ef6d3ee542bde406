"""Declaring ROS parameters with descriptors (description and range); params files are found by :mod:`battery_predictor.config`.

Parameters declared here are read-only: the nodes read them once at start-up, so a parameter service
call (``ros2 param set``) is refused instead of being accepted and ignored. Pass ``read_only=False``
for a parameter the node applies when it changes.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from battery_predictor.config import resolve_params_file
from battery_predictor.errors import ParamsError


def declare_float(node: Node, name: str, default: float, description: str, low: float, high: float, *,
                  read_only: bool = True) -> float:
    """Declare a double parameter with a FloatingPointRange ``[low, high]``; returns its value.

    An integer given for it (``window_s: 5`` in a params file, ``-p window_s:=5``) is taken as a double
    instead of failing with rclpy's "expecting type DOUBLE".
    """
    overrides = node._parameter_overrides  # rclpy has no public accessor
    given = overrides.get(name)
    if given is not None and given.type_ == Parameter.Type.INTEGER:
        overrides[name] = Parameter(name, Parameter.Type.DOUBLE, float(given.value))
    descriptor = ParameterDescriptor(description=description, read_only=read_only, floating_point_range=[
        FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)])
    return float(node.declare_parameter(name, float(default), descriptor).value)


def declare_str(node: Node, name: str, default: str, description: str, choices: tuple[str, ...] = (), *,
                read_only: bool = True) -> str:
    """Declare a string parameter (``choices`` are listed in the description and enforced)."""
    text = description + (f" One of: {', '.join(choices)}." if choices else "")
    descriptor = ParameterDescriptor(description=text, read_only=read_only, additional_constraints=(
        f"one of {', '.join(choices)}" if choices else ""))
    value = str(node.declare_parameter(name, default, descriptor).value)
    if choices and value not in choices:
        raise ValueError(f"parameter {name} is {value!r} (must be one of {', '.join(choices)})")
    return value


def declare_bool(node: Node, name: str, default: bool, description: str, *, read_only: bool = True) -> bool:
    """Declare a boolean parameter."""
    descriptor = ParameterDescriptor(description=description, read_only=read_only)
    return bool(node.declare_parameter(name, bool(default), descriptor).value)


@dataclass(frozen=True)
class FloatParameter:
    """A double parameter that fills the config field of the same name (:func:`declare_config_fields`).

    ``default`` None takes the config field's default; with ``zero_means_unset`` a value of 0 becomes NaN
    ("take it from the params file": ROS parameters cannot default to NaN within a range).
    """

    name: str
    description: str
    low: float
    high: float
    default: float | None = None
    zero_means_unset: bool = False


@dataclass(frozen=True)
class StrParameter:
    """A string parameter that fills the config field of the same name (:func:`declare_config_fields`).

    ``default`` None takes the config field's default; with ``params_file`` the value is a params file,
    resolved with :func:`battery_predictor.config.resolve_params_file` (a bundled name or a path).
    """

    name: str
    description: str
    choices: tuple[str, ...] = ()
    default: str | None = None
    params_file: bool = False


def declare_config_fields(node: Node, specs: Sequence[FloatParameter | StrParameter],
                          config_type: type) -> dict[str, Any]:
    """Declare every parameter of ``specs`` on ``node``; returns the config fields (name -> value) they give.

    ``config_type`` is the frozen dataclass the values are for; its field defaults are the parameters'
    defaults unless a spec gives its own.
    """
    fields = config_type.__dataclass_fields__
    values: dict[str, Any] = {}
    for spec in specs:
        default = spec.default if spec.default is not None else fields[spec.name].default
        if isinstance(spec, FloatParameter):
            number = declare_float(node, spec.name, float(default), spec.description, spec.low, spec.high)
            values[spec.name] = math.nan if spec.zero_means_unset and number == 0.0 else number
        else:
            text = declare_str(node, spec.name, str(default), spec.description, spec.choices)
            values[spec.name] = resolve_params_file(text) if spec.params_file else text
    return values


def undeclared_overrides(node: Node) -> list[str]:
    """Parameter names given to the node (params file, ``-p``) that it never declared: typos, usually."""
    declared = set(node._parameters)  # rclpy has no public accessor
    return sorted(name for name in node._parameter_overrides if name not in declared)


def reject_undeclared(node: Node) -> None:
    """Raise :class:`ParamsError` naming every parameter given to ``node`` that it does not declare.

    Call it after the last ``declare_*``: a misspelled parameter stops the node at start-up (with the
    declared name it most resembles) instead of leaving the default in force.
    """
    unknown = undeclared_overrides(node)
    if not unknown:
        return
    declared = sorted(node._parameters)  # rclpy has no public accessor
    named = []
    for name in unknown:
        close = difflib.get_close_matches(name, declared, n=1)
        named.append(f"'{name}'" + (f" (did you mean '{close[0]}'?)" if close else ""))
    raise ParamsError(f"{node.get_name()}: unknown parameter{'s' if len(named) > 1 else ''} {', '.join(named)}; "
                      f"see 'ros2 param describe' or params/ros/*.yaml for the declared ones")
