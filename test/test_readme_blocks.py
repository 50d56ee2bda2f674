"""Every code block of the README runs (fast ones here; slow ones are marked and skipped).

A block is run as it stands, in a scratch folder that links the checkout's ``test/``,
``config/`` and ``docs/``, with ``plane_pair``, ``plane_replay`` and ``plane_node`` on PATH
running this work tree's code. A comment line right before a block's fence says when it
cannot simply run here:

* ``<!-- readme-test: slow REASON -->``: not run (set ``README_SLOW=1`` to run it too, in the
  checkout itself, as a user would: ``make demo`` first, then the blocks that need its output);
* ``<!-- readme-test: until-stopped -->``: a node that runs until stopped; it must still be
  running, without an error, after a few seconds;
* ``<!-- readme-test: needs-ros REASON -->``: needs a ROS install (ros2 CLI, colcon); only
  its bash syntax is checked unless ``ros2`` is on PATH.

``python`` blocks run in one namespace per block, ``bash`` blocks with ``bash -e -o pipefail``,
``yaml`` blocks are loaded as a parameters file; other blocks (``text``) are not code.
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys

from domplane_ros.params_file import load_params_file
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
RUN_LANGUAGES = ('bash', 'python', 'yaml')
KINDS = ('slow', 'until-stopped', 'needs-ros')
_FENCE = re.compile(r'(?:<!-- readme-test: (\S+)([^>]*)-->\n)?```(\w*)\n(.*?)```', re.S)
_SCRIPTS = {'plane_pair': 'domplane_ros.pair.cli', 'plane_replay': 'domplane_ros.replay.cli',
            'plane_node': 'domplane_ros.ros.node'}
_UNTIL_STOPPED_S = 8.0


@dataclass(frozen=True)
class Block:
    """One fenced code block of the README."""

    line: int
    language: str
    code: str
    kind: str = ''
    reason: str = ''

    @property
    def test_id(self) -> str:
        """Return a test id: language and line."""
        return f'{self.language}-line{self.line}'


def readme_blocks(text: str) -> list[Block]:
    """Return the README's fenced code blocks in the languages that are run."""
    blocks = []
    for match in _FENCE.finditer(text):
        kind, reason, language, code = match.groups()
        if language in RUN_LANGUAGES:
            line = text.count('\n', 0, match.start(3)) + 1
            blocks.append(Block(line, language, code, kind or '', (reason or '').strip()))
    return blocks


BLOCKS = readme_blocks(README.read_text(encoding='utf-8'))


def test_readme_has_code_blocks_and_every_mark_is_known():
    assert len(BLOCKS) >= 5
    assert {b.kind for b in BLOCKS} <= {''} | set(KINDS)
    assert all(b.reason for b in BLOCKS if b.kind in ('slow', 'needs-ros'))


@pytest.fixture()
def scratch(tmp_path) -> tuple[Path, dict[str, str]]:
    """Return a scratch folder like the checkout's root and the environment to run in."""
    for name in ('test', 'config', 'docs'):
        (tmp_path / name).symlink_to(ROOT / name)
    bin_dir = tmp_path / '.bin'
    bin_dir.mkdir()
    for name, module in _SCRIPTS.items():
        script = bin_dir / name
        script.write_text(f'#!/bin/sh\nexec {sys.executable} -m {module} "$@"\n')
        script.chmod(0o755)
    env = dict(os.environ, PATH=f'{bin_dir}{os.pathsep}{os.environ.get("PATH", "")}',
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get('PYTHONPATH', '')]),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    return tmp_path, env


def _skip_reason(block: Block) -> str:
    if block.kind == 'slow' and os.environ.get('README_SLOW') != '1':
        return f'slow: {block.reason} (README_SLOW=1 runs it)'
    if block.kind == 'needs-ros' and shutil.which('ros2') is None:
        return ''   # syntax only, below
    return ''


@pytest.mark.parametrize('block', BLOCKS, ids=[b.test_id for b in BLOCKS])
def test_readme_block_runs(block, scratch):
    reason = _skip_reason(block)
    if reason:
        pytest.skip(reason)
    folder, env = scratch
    if block.language == 'python':
        result = subprocess.run([sys.executable, '-c', block.code], cwd=folder, env=env,
                                capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
    elif block.language == 'yaml':
        path = folder / 'block.yaml'
        path.write_text(block.code, encoding='utf-8')
        load_params_file(str(path))
    elif block.kind == 'needs-ros' and shutil.which('ros2') is None:
        result = subprocess.run(['bash', '-n', '-c', block.code], capture_output=True,
                                text=True, timeout=10)
        assert result.returncode == 0, result.stderr
    elif block.kind == 'until-stopped':
        _runs_until_stopped(block.code, folder, env)
    else:
        slow = block.kind == 'slow'
        # A slow block may run `make test`: its own README blocks must not recurse.
        result = subprocess.run(['bash', '-e', '-o', 'pipefail', '-c', block.code],
                                cwd=ROOT if slow else folder,
                                env=dict(env, README_SLOW='0'), capture_output=True,
                                text=True, timeout=3600 if slow else 300)
        assert result.returncode == 0, f'{result.stdout}\n{result.stderr}'


def _runs_until_stopped(code: str, folder: Path, env: dict[str, str]) -> None:
    process = subprocess.Popen(['bash', '-e', '-c', code], cwd=folder, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    try:
        process.wait(timeout=_UNTIL_STOPPED_S)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGINT)
        _, err = process.communicate(timeout=20)
        assert 'error' not in err.lower(), err
        return
    _, err = process.communicate()
    pytest.fail(f'the block stopped by itself (exit {process.returncode}): {err}')
