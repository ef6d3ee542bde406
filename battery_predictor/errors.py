"""All exceptions raised by battery_predictor.

Every error carries a one-line, user-facing message that names the file, row
or key and the problem. The CLI prints ``str(err)`` and exits with code 2.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar


class BatteryPredictorError(Exception):
    """Base class of every error this package raises on purpose."""


class InputDataError(BatteryPredictorError):
    """A measurement file or sample is unusable (missing column, NaN, units, order...)."""


class ParamsError(BatteryPredictorError):
    """A params YAML file is malformed (unknown key, missing unit, bad value)."""


class SimulationError(BatteryPredictorError):
    """A simulation failed (solver error, infeasible parameters, empty result)."""


class BagError(BatteryPredictorError):
    """A rosbag2 file is corrupt, truncated, or holds unsupported topics/types."""


class ProfileError(BatteryPredictorError):
    """A load profile or route description is invalid."""


class RequestError(BatteryPredictorError):
    """A service request is malformed (no sections, NaN length, absurd payload...)."""


#: Under the CLI: the running command's flags per Python option name and value (see :func:`option_hint`).
_CLI_FLAGS: ContextVar[Mapping[str, Mapping[object, str]] | None] = ContextVar("cli_flags", default=None)


@contextmanager
def cli_flags(flags: Mapping[str, Mapping[object, str]]) -> Iterator[None]:
    """Within the block, :func:`option_hint` names the flags in ``flags`` instead of Python options.

    ``flags`` maps a Python option name to ``{value: flag}``, e.g. ``{"drop_nan": {True: "--drop-nan"}}``;
    the value ``None`` stands for any value (``{"topic": {None: "--topic TOPIC"}}``).
    """
    token = _CLI_FLAGS.set(flags)
    try:
        yield
    finally:
        _CLI_FLAGS.reset(token)


def in_cli() -> bool:
    """True while the ``battery-predictor`` command runs (inside :func:`cli_flags`)."""
    return _CLI_FLAGS.get() is not None


def option_hint(option: str, value: object, effect: str) -> str:
    """The hint ``"; pass drop_nan=True to drop them"`` for one way out of an error.

    Under the CLI it names the running command's flag instead (``"; use --drop-nan to drop them"``),
    or is empty when that command has no such flag, so that no hint names an argument the user
    cannot give.
    """
    flags = _CLI_FLAGS.get()
    if flags is None:
        shown = f"{option}=" if value is None else f"{option}={value!r}"
        return f"; pass {shown} {effect}"
    by_value = flags.get(option, {})
    flag = by_value.get(value, by_value.get(None))
    return f"; use {flag} {effect}" if flag else ""
