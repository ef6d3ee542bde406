"""Entry point of the ``predictor`` console script (``predictor --ros-args --params-file P.yaml``)."""

from __future__ import annotations

import sys


def main(args: list[str] | None = None) -> int:
    """Run the predictor node until Ctrl-C."""
    from battery_predictor.nodes._main import spin_nodes
    from battery_predictor.nodes.predictor_node import PredictorNode

    return spin_nodes([PredictorNode], args, threads=3)


if __name__ == "__main__":
    sys.exit(main())
