"""Run ament_pep257 (pydocstyle) over the package and its tests."""

from __future__ import annotations

from pathlib import Path

from ament_pep257.main import main
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]

# ament_pep257's default 'ament' convention enables every check it does not list, among them
# the numpy section rules (D406, D407) and D213 (summary on the second line), which contradict
# the Google-style docstrings of the house style. So we check the Google convention, and, as
# the 'ament' convention and ament_flake8 do, leave missing docstrings (D100-D107) to review.
ARGV = [
    '.', 'test',
    '--exclude', 'build', 'install', 'log',
    '--convention', 'google',
    '--add-ignore', 'D100', 'D101', 'D102', 'D103', 'D104', 'D105', 'D106', 'D107',
]


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257(monkeypatch):
    # Folders starting with '.' or '_' (.venv among them) are skipped by ament_pep257 itself.
    monkeypatch.chdir(REPO_ROOT)
    rc = main(argv=ARGV)
    assert rc == 0, 'Found code style errors / warnings'
