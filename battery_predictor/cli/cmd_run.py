"""``battery-predictor run``: the battery monitor and the predictor in one process.

    battery-predictor run --params params/ros/temi_nodes.yaml [--pack FITTED.yaml] [--use-sim-time]
                          [--ros-args ...]

Same as starting the ``battery_monitor`` and ``predictor`` console scripts with
``--ros-args --params-file P.yaml``, on one StartedMultiThreadedExecutor (``nodes/executor.py``). Ctrl-C stops.
"""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run the battery monitor and predictor nodes in one process (Ctrl-C stops)",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--params", required=True, metavar="P.yaml",
                   help="node parameters (battery_monitor: / predictor: ros__parameters), e.g. params/ros/temi_nodes.yaml")
    p.add_argument("--pack", default=None, metavar="PACK.yaml",
                   help="fitted pack params file; overrides predictor.params_file")
    p.add_argument("--use-sim-time", action="store_true", help="follow /clock (e.g. while a bag is played)")
    p.add_argument("--threads", type=int, default=4, help="executor threads (default 4)")
    p.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=[],
                   help="further ROS arguments (-p name:=value, -r from:=to, --log-level ...)")
    p.set_defaults(func=run)


def ros_arguments(params: str, *, pack: str | None = None, use_sim_time: bool = False,
                  extra: list[str] | None = None) -> list[str]:
    """The rclpy argument list for ``params`` (+ overrides)."""
    from battery_predictor.cli._ros_params import check_node_params_file

    check_node_params_file(params, pack=pack)
    args = ["battery-predictor", "--ros-args", "--params-file", str(params)]
    if pack:
        args += ["-p", f"predictor:params_file:={pack}"]
    if use_sim_time:
        args += ["-p", "use_sim_time:=true"]
    return args + list(extra or [])


def run(args: argparse.Namespace) -> int:
    from battery_predictor.nodes._main import spin_nodes
    from battery_predictor.nodes.battery_monitor_node import BatteryMonitorNode
    from battery_predictor.nodes.predictor_node import PredictorNode

    ros_args = ros_arguments(args.params, pack=args.pack, use_sim_time=args.use_sim_time, extra=args.ros_args)
    return spin_nodes([BatteryMonitorNode, PredictorNode], ros_args, threads=max(2, args.threads))
