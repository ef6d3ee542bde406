"""Helper process of ``benchmarks/route_trace.py``: a traced predictor, or an empty route service.

``python benchmarks/_route_trace_node.py predictor TRACE.json --ros-args ...`` runs the predictor node
exactly as the ``predictor`` console script does (``battery_predictor`` imported from ``PYTHONPATH``,
so a snapshot of another commit can be traced), with timestamps (``time.monotonic_ns``, one clock for
all processes on the machine) taken at each step of a ``can_accept_route`` call on the server side:

- ``ready``: the executor's spinning thread made the handler of the ready service (the wait set woke);
- ``take0``/``take1``: a worker took the request from the middleware (deserialised into Python);
- ``cb0``/``cb1``: the node's service callback entered/returned;
- ``core0``/``core1``: ``PredictorCore.can_accept_route`` entered/returned;
- ``sent``: the response was handed to the middleware.

``... echo TRACE.json --ros-args ...`` runs an empty ``CanAcceptRoute`` service (a fixed answer, no
model) on the same executor as the nodes, the floor of the middleware and rclpy's executor for the
same request and response. The trace is written when the process ends (SIGINT).
"""

from __future__ import annotations

import json
import sys
import threading
import time


def _patch_core(core_class, local, busy: dict[str, list]) -> None:
    """Inside the route answer: the calibration and the route runs; the node's other model work as intervals."""
    from battery_predictor.prediction import core as core_module

    def inside(name, function):
        def traced(*args, **kwargs):
            record = getattr(local, "record", None)
            if record is not None:
                record[name + "0"] = time.monotonic_ns()
            try:
                return function(*args, **kwargs)
            finally:
                if record is not None:
                    record[name + "1"] = time.monotonic_ns()
        return traced

    def interval(name, function):
        busy[name] = []

        def traced(*args, **kwargs):
            t0 = time.monotonic_ns()
            try:
                return function(*args, **kwargs)
            finally:
                busy[name].append((t0, time.monotonic_ns()))
        return traced

    core_class.calibration = inside("cal", core_class.calibration)
    core_module.evaluate_route_at_risk = inside("eval", core_module.evaluate_route_at_risk)
    core_class.precalibrate = interval("precalibrate", core_class.precalibrate)
    core_class.remaining_runtime = interval("remaining_runtime", core_class.remaining_runtime)


def _patch(trace: list[dict], with_core: bool, trace_busy: dict[str, list]) -> None:
    from rclpy.executors import Executor
    from rclpy.service import Service

    lock = threading.Lock()
    local = threading.local()
    pending_ready: list[int] = []

    make_handler = Executor._make_handler

    def traced_make_handler(self, entity, node, take_from_wait_list):
        if isinstance(entity, Service) and entity.srv_name.endswith("can_accept_route"):
            with lock:
                pending_ready.append(time.monotonic_ns())
        return make_handler(self, entity, node, take_from_wait_list)

    take_service = Executor._take_service

    def traced_take_service(self, srv):
        if not srv.srv_name.endswith("can_accept_route"):
            return take_service(self, srv)
        t0 = time.monotonic_ns()
        execute = take_service(self, srv)
        t1 = time.monotonic_ns()
        with lock:
            ready = pending_ready.pop(0) if pending_ready else 0
        record = {"ready": ready, "take0": t0, "take1": t1}
        if execute is None:
            return None

        async def run():
            local.record = record
            await execute()
            record["sent"] = time.monotonic_ns()
            local.record = None
            with lock:
                trace.append(record)
        return run

    original_send = Service.send_response

    def traced_send(self, response, header):
        record = getattr(local, "record", None)
        if record is not None:
            record["send0"] = time.monotonic_ns()
        return original_send(self, response, header)

    Executor._make_handler = traced_make_handler
    Executor._take_service = traced_take_service
    Service.send_response = traced_send

    if with_core:
        from battery_predictor.prediction.core import PredictorCore

        core_call = PredictorCore.can_accept_route

    def traced_core(self, *args, **kwargs):
        record = getattr(local, "record", None)
        if record is not None:
            record["core0"] = time.monotonic_ns()
        try:
            return core_call(self, *args, **kwargs)
        finally:
            if record is not None:
                record["core1"] = time.monotonic_ns()

    if with_core:
        PredictorCore.can_accept_route = traced_core
        _patch_core(PredictorCore, local, trace_busy)

    def wrap_callback(callback):
        def traced_callback(request, response):
            record = getattr(local, "record", None)
            if record is not None:
                record["cb0"] = time.monotonic_ns()
            try:
                return callback(request, response)
            finally:
                if record is not None:
                    record["cb1"] = time.monotonic_ns()
        return traced_callback

    create_service = __import__("rclpy.node", fromlist=["Node"]).Node.create_service

    def traced_create_service(self, srv_type, srv_name, callback, **kwargs):
        if srv_name.endswith("can_accept_route"):
            callback = wrap_callback(callback)
        return create_service(self, srv_type, srv_name, callback, **kwargs)

    __import__("rclpy.node", fromlist=["Node"]).Node.create_service = traced_create_service


def _echo_node():
    from battery_predictor_msgs.srv import CanAcceptRoute
    from rclpy.node import Node

    class EchoNode(Node):
        """A can_accept_route service with a fixed answer: the middleware and executor floor."""

        def __init__(self) -> None:
            super().__init__("route_echo")
            self.create_service(CanAcceptRoute, "can_accept_route", self._answer)

        def _answer(self, request, response):
            response.accepted = True
            response.predicted_voltage_v = 49.0
            response.reason = "x" * 200  # about the length of a real reason
            return response

    return EchoNode()


def main() -> int:
    kind, path = sys.argv[1], sys.argv[2]
    args = [sys.argv[0], *sys.argv[3:]]
    trace: list[dict] = []
    busy: dict[str, list] = {}
    _patch(trace, kind == "predictor", busy)
    from battery_predictor.nodes._main import spin_nodes

    try:
        if kind == "predictor":
            from battery_predictor.nodes.predictor_main import main as predictor_main

            return predictor_main(args)
        return spin_nodes([_echo_node], args, threads=3)
    finally:
        with open(path, "w") as f:
            json.dump({"calls": trace, "busy": busy}, f)


if __name__ == "__main__":
    sys.exit(main())
