"""Old import path of :mod:`battery_predictor.config` (the params-file locator and YAML checks).

Kept only for ``prediction/station_services.py`` and ``lab/experiments.py``, whose owners move
their imports to :mod:`battery_predictor.config`; delete this module then.
"""

from battery_predictor.config import (
    as_float,
    as_float_list,
    check_unknown,
    default_params_file,
    read_yaml_mapping,
    require,
)

__all__ = ["as_float", "as_float_list", "check_unknown", "default_params_file", "read_yaml_mapping", "require"]
