"""All exceptions raised by battery_predictor.

Every error carries a one-line, user-facing message that names the file, row
or key and the problem. The CLI prints ``str(err)`` and exits with code 2.
"""

from __future__ import annotations


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
