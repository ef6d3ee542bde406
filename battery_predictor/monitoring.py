"""Old import path of :mod:`battery_predictor.monitor.core` (the battery monitor's ROS-free core).

Kept only for ``evaluation/runtime_eval.py``, which another change has open; delete this module
once it imports :mod:`battery_predictor.monitor.core`.
"""

from battery_predictor.monitor.core import MonitorConfig, monitor_windows

__all__ = ["MonitorConfig", "monitor_windows"]
