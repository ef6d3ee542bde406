"""ROS for the command line's ``replay`` and ``demo``: their rclpy contexts and service calls.

The commands parse, call and print; this module is where they touch rclpy and the interface
messages (the rule that only :mod:`battery_predictor.nodes` imports ROS, checked by
``test/unit/test_import_structure.py``).
"""

from __future__ import annotations

import contextlib
import functools
import os
import time
from collections.abc import Iterator, Sequence
from typing import Any

import rclpy
from battery_predictor_msgs.msg import PlannedRoute, Task
from battery_predictor_msgs.srv import CanAcceptRoute, FeasibleTasks, PlanRoute
from rclpy.context import Context

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.nodes.domains import DomainClaim, claim_private_domain
from battery_predictor.nodes.messages import route_section_msgs
from battery_predictor.profiles.ranger import RouteSection

#: Task kinds of :func:`feasible_tasks` -> ``Task.msg`` constants.
TASK_KINDS = {"information": Task.KIND_INFORMATION, "navigation": Task.KIND_NAVIGATION}
#: ``PlannedRoute.msg`` kinds -> the names the demo prints.
PLANNED_ROUTE_KINDS = {PlannedRoute.KIND_SHORTEST: "shortest", PlannedRoute.KIND_LEAST_CHARGE_PATH: "least-charge path",
                       PlannedRoute.KIND_CHARGE_FIRST: "charge first"}


@contextlib.contextmanager
def ros_context(context: Context | None = None) -> Iterator[Context | None]:
    """``context`` as it is, or (None) rclpy's global context, initialised for the block and shut down after it."""
    if context is not None:
        yield context
        return
    rclpy.init(args=["battery-predictor"])
    try:
        yield None
    finally:
        rclpy.try_shutdown()


def isolated_context() -> Context:
    """An rclpy context on a ROS domain of its own on this machine, discovery on this machine only.

    The domain is claimed with :func:`~battery_predictor.nodes.domains.claim_private_domain` and
    given back when the context shuts down.
    """
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_STATIC_PEERS", None)
    claim = claim_private_domain()
    context = Context()
    try:
        rclpy.init(args=["battery-predictor"], context=context, domain_id=claim.domain_id)
    except Exception:
        claim.release()
        raise
    context.on_shutdown(functools.partial(DomainClaim.release, claim))
    return context


def call_service(session: Any, srv_type: Any, srv_name: str, request: Any, timeout_s: float = 60.0) -> Any:
    """Call a service of the session's predictor over the middleware from the session's client node.

    Parameters
    ----------
    session : battery_predictor.nodes.replay_session.ReplaySession
        The open replay session (its ``client_node`` makes the call).
    srv_type : type
        The service type.
    srv_name : str
        The service's name.
    request : object
        The request message.
    timeout_s : float
        Wall time (s) to wait for the service and then for its answer.

    Returns
    -------
    object
        The response message.
    """
    client = session.client_node.create_client(srv_type, srv_name)
    try:
        deadline = time.monotonic() + timeout_s
        while not client.service_is_ready():
            if time.monotonic() > deadline:
                raise BatteryPredictorError(f"demo: service {srv_name} not found")
            time.sleep(0.01)
        future = client.call_async(request)
        while not future.done():
            if time.monotonic() > deadline:
                raise BatteryPredictorError(f"demo: no answer from {srv_name}")
            time.sleep(0.005)
        return future.result()
    finally:
        session.client_node.destroy_client(client)


def feasible_tasks(session: Any, tasks: Sequence[tuple[str, str, float, str]], location: str) -> Any:
    """Ask the session's ``/feasible_tasks`` (greedy policy) for ``tasks`` = (name, kind, duration_s, destination)."""
    request = FeasibleTasks.Request(
        tasks=[Task(name=n, kind=TASK_KINDS[k], duration_s=d, destination=dest) for n, k, d, dest in tasks],
        location=location, policy=FeasibleTasks.Request.POLICY_GREEDY)
    return call_service(session, FeasibleTasks, session.predictor.tasks_service.srv_name, request)


def plan_route(session: Any, job: dict[str, Any]) -> Any:
    """Ask the session's ``/plan_route`` for ``job`` (the request's fields)."""
    return call_service(session, PlanRoute, session.predictor.plan_service.srv_name, PlanRoute.Request(**job))


def can_accept_route(session: Any, sections: Sequence[RouteSection]) -> Any:
    """Ask the session's ``/can_accept_route`` for a route of ``sections``."""
    return session.call_route(CanAcceptRoute.Request(sections=route_section_msgs(sections)))
