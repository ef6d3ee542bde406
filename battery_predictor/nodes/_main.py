"""The Jazzy ``main()`` idiom shared by the node entry points and ``battery-predictor run``."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

import rclpy
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.nodes.executor import StartedMultiThreadedExecutor
from battery_predictor.nodes.memory import configure_process

#: Errors in the configuration (parameters, names): one line on stderr and exit code 2, no traceback.
CONFIG_ERRORS = (ValueError, BatteryPredictorError, ParameterException, NameValidationException)


def spin_nodes(factories: Sequence[Callable[[], Node]], args: list[str] | None = None, *, threads: int = 4) -> int:
    """``rclpy.init``, build the nodes, spin a StartedMultiThreadedExecutor until Ctrl-C or shutdown, clean up.

    Parameters
    ----------
    factories : sequence of callables
        Each builds one node (after ``rclpy.init``).
    args : list of str, optional
        Command line including ROS arguments (``--ros-args --params-file P.yaml``); default ``sys.argv``.
    threads : int
        Executor threads (the predictor needs >= 2 so the service answers during a runtime update).
    """
    configure_process()  # memory back after large requests (nodes/memory.py); before rclpy.init
    rclpy.init(args=sys.argv if args is None else args)
    nodes: list[Node] = []
    executor = StartedMultiThreadedExecutor(num_threads=threads)
    code = 0
    try:
        for factory in factories:
            nodes.append(factory())
            executor.add_node(nodes[-1])
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except CONFIG_ERRORS as exc:
        print(f"{sys.argv[0].rsplit('/', 1)[-1]}: error: {exc}", file=sys.stderr)
        code = 2
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
