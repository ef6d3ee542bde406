"""Entry point of the ``battery_monitor`` console script (``battery_monitor --ros-args --params-file P.yaml``)."""

from __future__ import annotations

import sys


def main(args: list[str] | None = None) -> int:
    """Run the battery monitor node until Ctrl-C."""
    from battery_predictor.nodes._main import spin_nodes
    from battery_predictor.nodes.battery_monitor_node import BatteryMonitorNode

    return spin_nodes([BatteryMonitorNode], args, threads=2)


if __name__ == "__main__":
    sys.exit(main())
