"""The battery monitor without ROS, beside the predictor's core (:mod:`battery_predictor.prediction`).

* :mod:`.core`: :class:`~.core.BatteryMonitor` (validate samples, average them into windows, detect
  stale input), its :class:`~.core.MonitorConfig`, :class:`~.core.PackSnapshot` and
  :func:`~.core.monitor_windows`.

The ``battery_monitor`` node (:mod:`battery_predictor.nodes.battery_monitor_node`) adapts it to ROS.
"""
