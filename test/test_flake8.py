"""Run ament_flake8 (the ROS 2 flake8 configuration) over the package and its tests."""

from __future__ import annotations

from pathlib import Path

from ament_flake8.main import main_with_errors
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8(monkeypatch):
    # ament_flake8 checks the working directory; it skips folders starting with '.' or '_'
    # (.venv among them) by itself, and colcon or pip may leave build trees behind.
    monkeypatch.chdir(REPO_ROOT)
    rc, errors = main_with_errors(argv=['--exclude', 'build', 'install', 'log'])
    assert rc == 0, \
        'Found %d code style errors / warnings:\n' % len(errors) + \
        '\n'.join(errors)
