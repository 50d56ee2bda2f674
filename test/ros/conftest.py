"""Fixtures of the ROS tests (the only conftest that imports rclpy); every test here is ``ros``.

``ros_context`` gives each test a private, initialised ``rclpy`` context, so node tests run
in-process without touching the global context. DDS discovery is kept on loopback and every
test session picks its own random domain, so test runs on the same machine do not see each
other's nodes.
"""

from __future__ import annotations

import os
from pathlib import Path
import random
from typing import Iterator

import pytest
import rclpy
from rclpy.context import Context

# Jazzy's replacement for ROS_LOCALHOST_ONLY (which it still honours, with a warning).
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'


def _session_domain_id() -> int:
    """Return this test process's DDS domain id, distinct between pytest-xdist workers.

    Without xdist: a random id in [1, 200]. Under xdist the workers of one run share a run id
    (``PYTEST_XDIST_TESTRUNUID``); the base comes from it and each worker adds its index, so two
    workers of one run never share a domain (their nodes would see each other's topics).
    """
    run_uid = os.environ.get('PYTEST_XDIST_TESTRUNUID')
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    if not run_uid or not worker.startswith('gw'):
        return random.SystemRandom().randint(1, 200)
    return (int(run_uid, 16) + int(worker[2:])) % 200 + 1


_SESSION_DOMAIN_ID = _session_domain_id()
_HERE = Path(__file__).parent


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test under test/ros ``ros``, so that ``-m 'not ros'`` runs the rest."""
    for item in items:
        if _HERE in Path(str(item.fspath)).parents:
            item.add_marker(pytest.mark.ros)


@pytest.fixture(scope='session')
def ros_domain_id() -> int:
    """Return the DDS domain id that this test session's private contexts use.

    Returns:
        A random domain id in [1, 200], fixed for the session.

    """
    return _SESSION_DOMAIN_ID


@pytest.fixture
def ros_context(ros_domain_id: int) -> Iterator[object]:
    """Yield a private, initialised ``rclpy.context.Context``; shut it down afterwards.

    Create nodes with ``rclpy.create_node(name, context=ros_context)`` (or ``Node(...,
    context=ros_context)``) and spin them with an executor made with
    ``context=ros_context``. Nodes left over are destroyed by the context's shutdown.

    Args:
        ros_domain_id: The session's DDS domain id (fixture).

    Yields:
        The initialised context.

    """
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    context = Context()
    rclpy.init(context=context, domain_id=ros_domain_id)
    try:
        yield context
    finally:
        if context.ok():
            rclpy.shutdown(context=context)
