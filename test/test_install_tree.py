"""Install the package with pip into a temporary prefix and check the ROS install layout.

``ros2 run domplane_ros plane_node`` needs ``<prefix>/lib/domplane_ros/plane_node``, and
``ros2 launch`` / ``get_package_share_directory`` need the ament index marker and
``<prefix>/share/domplane_ros``. colcon and pip must both produce them.
"""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
PACKAGE = 'domplane_ros'
# Work-tree folders that are no part of the source (virtual environment, build trees, outputs).
NOT_SOURCE = shutil.ignore_patterns(
    '.git', '.venv', '.hypothesis', '.pytest_cache', '__pycache__', '*.egg-info', 'build',
    'install', 'log', 'demo_output', 'bench_output', 'eval_output')
LAUNCHERS = ('plane_node', 'plane_replay', 'plane_pair')


@pytest.fixture(scope='module')
def install_prefix(tmp_path_factory) -> Path:
    """Pip-install a copy of the source tree into a fresh prefix, offline.

    The copy keeps setuptools' build/ and egg-info folders out of the work tree.

    Args:
        tmp_path_factory: pytest's temporary directory factory.

    Returns:
        The install prefix.

    """
    root = tmp_path_factory.mktemp('install_tree')
    source, prefix = root / 'src', root / 'prefix'
    shutil.copytree(REPO_ROOT, source, ignore=NOT_SOURCE)
    command = [
        sys.executable, '-m', 'pip', 'install', '--quiet', '--disable-pip-version-check',
        '--no-deps', '--no-build-isolation', '--no-index', '--ignore-installed',
        '--prefix', str(prefix), str(source),
    ]
    result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, f'pip install failed:\n{result.stdout}\n{result.stderr}'
    return prefix


def test_ament_index_marker_and_share_files(install_prefix):
    marker = install_prefix / 'share/ament_index/resource_index/packages' / PACKAGE
    assert marker.is_file()
    package_xml = install_prefix / 'share' / PACKAGE / 'package.xml'
    assert ElementTree.parse(package_xml).getroot().findtext('name') == PACKAGE
    assert (install_prefix / 'share' / PACKAGE / 'config/plane_node.yaml').is_file()
    assert (install_prefix / 'share' / PACKAGE / 'launch/plane_node.launch.py').is_file()


@pytest.mark.parametrize('name', LAUNCHERS)
def test_ros2_run_launchers_are_executable(install_prefix, name):
    launcher = install_prefix / 'lib' / PACKAGE / name
    assert launcher.is_file()
    assert os.access(launcher, os.X_OK)


@pytest.mark.parametrize('name', LAUNCHERS)
def test_console_scripts_use_this_interpreter(install_prefix, name):
    script = install_prefix / 'bin' / name
    assert script.is_file() and os.access(script, os.X_OK)
    shebang = script.read_text().splitlines()[0]
    assert Path(shebang[2:].strip()).resolve() == Path(sys.executable).resolve()


def test_ament_index_finds_the_share_directory(install_prefix):
    pytest.importorskip('ament_index_python')
    code = (
        'from ament_index_python.packages import get_package_share_directory; '
        f'print(get_package_share_directory({PACKAGE!r}))')
    env = dict(os.environ, AMENT_PREFIX_PATH=str(install_prefix))
    result = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 0, result.stderr
    assert Path(result.stdout.strip()) == install_prefix / 'share' / PACKAGE


@pytest.mark.parametrize('name', LAUNCHERS)
def test_launcher_execs_the_console_script_of_its_prefix(install_prefix, tmp_path, name):
    # A stand-in console script shows that the launcher forwards to <prefix>/bin/<name> with
    # its arguments, without starting a node.
    fake_prefix = tmp_path / 'prefix'
    (fake_prefix / 'lib' / PACKAGE).mkdir(parents=True)
    (fake_prefix / 'bin').mkdir()
    launcher = fake_prefix / 'lib' / PACKAGE / name
    shutil.copy2(install_prefix / 'lib' / PACKAGE / name, launcher)
    fake_script = fake_prefix / 'bin' / name
    fake_script.write_text('#!/bin/sh\necho "console script $0 got: $*"\n')
    fake_script.chmod(0o755)
    result = subprocess.run(
        [str(launcher), '--ros-args', '-p', 'a:=1'], capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == f'console script {fake_script} got: --ros-args -p a:=1'
