"""Fixtures shared by every test tier; nothing here imports rclpy.

The ROS tests' own fixtures (private rclpy contexts) live in ``test/ros/conftest.py``, so the
core, stream, replay, sim and tools tests run where rclpy is not installed:
``pytest -m 'not ros'`` there leaves test/ros uncollected (without ``-m 'not ros'``, a missing
rclpy is an error, not a silent skip).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

from bag_helpers import make_frames
import pytest

_ROS_TESTS = Path(__file__).parent / 'ros'


def _rclpy_missing() -> bool:
    try:
        return importlib.util.find_spec('rclpy') is None
    except (ImportError, ValueError):
        return True


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """Leave test/ros uncollected when its tests are deselected and rclpy is missing."""
    if (collection_path == _ROS_TESTS and 'not ros' in (config.getoption('markexpr') or '')
            and _rclpy_missing()):
        return True
    return None


# The files that take longest (measured with ``--durations``), run first: ``make test``
# hands whole files to its two workers in collection order, so a long file collected last
# would keep one worker busy after the other has run out of work.
LONGEST_FIRST = (
    'stream/test_trust.py', 'stream/test_uniqueness.py', 'tools/test_evaluate.py',
    'test_flake8.py', 'tools/test_evaluate_lines.py', 'stream/test_drift.py',
    'stream/test_lock_reference.py', 'stream/test_head.py', 'replay/test_replay_refusals.py',
)


def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config,
                                  items: list[pytest.Item]) -> None:
    """Move the tests of the longest files to the front, each file's order unchanged."""
    root = Path(__file__).parent
    rank = {str(root / name): i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(str(item.path), len(rank)))


@pytest.fixture(scope='module')
def frames():
    """Return the short rendered sequence that the bag tests write and replay."""
    return make_frames()
