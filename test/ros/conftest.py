"""Fixtures for tests that talk over ROS 2 (rclpy with the pip wheels).

Every test gets its own ``rclpy.Context`` initialised with its own ROS domain
id, so tests never share DDS traffic with each other, with tests running in
parallel in other processes, or with anything else on domain 0. Discovery is
kept on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``).
"""

from __future__ import annotations

import itertools
import os
import uuid
from collections.abc import Iterator

import pytest
import rclpy
from rclpy.context import Context

# Fast DDS maps domain ids 0..232 to UDP ports; stay clear of 0 (the default).
_DOMAIN_MIN = 100
_DOMAIN_COUNT = 130
_counter = itertools.count()


def _next_domain_id() -> int:
    """A domain id distinct for each test of this process, spread over processes by pid."""
    return _DOMAIN_MIN + (os.getpid() * 31 + next(_counter)) % _DOMAIN_COUNT


@pytest.fixture
def ros_domain_id() -> int:
    """The ROS domain id of this test's context."""
    return _next_domain_id()


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
