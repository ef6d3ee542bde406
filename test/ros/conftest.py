"""Fixtures for tests that talk over ROS 2 (rclpy with the pip wheels).

Every test gets its own ``rclpy.Context`` initialised with a ROS domain id it
claims for its duration (:func:`battery_predictor.nodes.domains.claim_private_domain`,
a lock per id on this machine), so tests never share DDS traffic with each other,
with tests, replays or demos running in other processes, or with anything on
domain 0. Discovery is kept on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``).
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import pytest
import rclpy
from rclpy.context import Context

from battery_predictor.nodes.domains import claim_private_domain


@pytest.fixture
def ros_domain_id() -> Iterator[int]:
    """The ROS domain id of this test's context, held by no other process while the test runs."""
    claim = claim_private_domain()
    try:
        yield claim.domain_id
    finally:
        claim.release()


@pytest.fixture
def ros_context(ros_domain_id: int, monkeypatch: pytest.MonkeyPatch) -> Iterator[Context]:
    """An initialised rclpy context of its own (own domain id), shut down after the test."""
    # rcl reads these when the context is initialised; keep discovery local.
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    context = Context()
    rclpy.init(args=[], context=context, domain_id=ros_domain_id)
    try:
        yield context
    finally:
        context.try_shutdown()


@pytest.fixture
def unique_name() -> str:
    """A name unique to this test, for node, topic and service names."""
    return f"t_{uuid.uuid4().hex[:12]}"
