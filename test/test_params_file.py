"""The guarded parameters-file reader: hostile files refused fast, real files accepted.

Each hostile file of issue 16 is here, refused with one line naming the problem within 2 s
(the 850-byte alias file kept the old reader busy for over 60 s at 1.2 GB, the 55 MB file for
93 s); the shipped config and the ``/**:`` and namespaced forms that rcl and launch files use
are accepted. The tools' exit codes are tested in test/replay and test/ros.
"""

from __future__ import annotations

import os
from pathlib import Path
import time

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.errors import ConfigError
from domplane_ros.params_file import (applies_to, load_params_file, MAX_PARAMS_FILE_BYTES,
                                      MAX_YAML_DEPTH, MAX_YAML_NODES, read_node_params,
                                      ros_params_files)
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / 'config' / 'plane_node.yaml'


def alias_bomb(levels: int = 26) -> str:
    """Return the probe's file: ``levels`` anchors, each used twice by the next (855 bytes).

    Mappings, so that flattening the parameter names walks 2**25 paths (the old reader).
    """
    lines = ['plane_node:', '  ros__parameters:', '    a0: &a0 {x: 1.0}']
    lines += [f'    a{i}: &a{i} {{x: *a{i - 1}, y: *a{i - 1}}}' for i in range(1, levels)]
    return '\n'.join(lines) + '\n'


def huge_file(path: Path, n_bytes: int) -> Path:
    """Write a parameters file of ``n_bytes``: a valid block padded with a comment."""
    head = b'plane_node:\n  ros__parameters:\n    estimator.threshold_px: 3.0\n#'
    with open(path, 'wb') as stream:
        stream.write(head)
        stream.write(b'x' * (n_bytes - len(head) - 1) + b'\n')
    return path


HOSTILE = {
    'nested aliases (850 bytes)': (alias_bomb(), 'uses the YAML alias *a0 (line 4)'),
    'merge key': ('base: &b {ros__parameters: {}}\nplane_node:\n  <<: *b\n', 'alias *b'),
    'a list': ('- plane_node\n- ros__parameters\n', 'not a list'),
    'a list under ros__parameters': ('plane_node:\n  ros__parameters:\n    - 1\n    - 2\n',
                                     'ros__parameters must be a mapping'),
    'null ros__parameters': ('plane_node:\n  ros__parameters:\n', 'not a null'),
    'scalar node block': ('plane_node: 3\n', 'expected a "ros__parameters:" mapping'),
    'key beside ros__parameters': (
        'plane_node:\n  ros__parameters: {}\n  other: 1\n', "'other' beside ros__parameters"),
    'empty file': ('', 'is empty'),
    'a scalar': ('hello\n', 'not a string'),
    'integer node name': ('1:\n  ros__parameters: {}\n', '1 is not a node name'),
    'not YAML': ('plane_node: [\n', 'is not valid YAML'),
    'python tag': ('plane_node: !!python/object:os.system {}\n', 'is not valid YAML'),
    'too deep': ('plane_node:\n  ros__parameters:\n    a: ' + '[' * (MAX_YAML_DEPTH + 5)
                 + ']' * (MAX_YAML_DEPTH + 5) + '\n', f'nests deeper than {MAX_YAML_DEPTH}'),
    'too many values': ('plane_node:\n  ros__parameters:\n    a: ['
                        + ', '.join(['1'] * (MAX_YAML_NODES + 10)) + ']\n',
                        f'more than {MAX_YAML_NODES} values'),
    'mixed list': ('plane_node:\n  ros__parameters:\n    a: [1, x]\n', 'of one type'),
    'nested list': ('plane_node:\n  ros__parameters:\n    a: [[1.0]]\n', 'of one type'),
    'no block for the node': ('other_node:\n  ros__parameters: {a: 1}\n',
                              'has no block for plane_node'),
    'unknown parameter': ('/**:\n  ros__parameters:\n    no_such.key: 1\n',
                          "unknown parameter 'no_such.key'"),
    'huge integer': ('plane_node:\n  ros__parameters:\n    estimator.threshold_px: 1' + '0' * 400
                     + '\n', "'estimator.threshold_px': expected a finite number"),
    'long string value': ('plane_node:\n  ros__parameters:\n    features.kind: ' + 'p' * 10_000
                          + '\n', '(10000 characters)'),
    'bad use_sim_time': ('plane_node:\n  ros__parameters:\n    use_sim_time: 3\n',
                         "'use_sim_time' must be a bool"),
    'singular initial_homography': (
        'plane_node:\n  ros__parameters:\n    initial_homography: [0, 0, 0, 0, 0, 0, 0, 0, 0]\n',
        'all zeros'),
    'wildcard and named block conflict': (
        '/**:\n  ros__parameters:\n    prior.tilt_deg: [10.0, 20.0]\nplane_node:\n'
        '  ros__parameters:\n    prior.tilt_deg: [30.0]\n', 'expected [min, max]'),
}


def _refused(path: Path) -> tuple[str, float]:
    t0 = time.perf_counter()
    with pytest.raises(ConfigError) as info:
        load_params_file(str(path))
    return str(info.value), time.perf_counter() - t0


@pytest.mark.parametrize('case', sorted(HOSTILE))
def test_hostile_file_is_refused_in_one_line_naming_the_problem(tmp_path, case):
    text, needle = HOSTILE[case]
    path = tmp_path / 'params.yaml'
    path.write_text(text, encoding='utf-8')
    message, seconds = _refused(path)
    assert needle in message, message
    assert '\n' not in message and len(message) < 400, message
    assert repr(str(path)) in message or str(path) in message
    assert seconds < 2.0, (case, seconds)


@pytest.mark.parametrize('n_bytes', [MAX_PARAMS_FILE_BYTES + 1, 55_000_000])
def test_file_over_the_size_limit_is_refused_before_it_is_read(tmp_path, n_bytes):
    path = huge_file(tmp_path / 'big.yaml', n_bytes)
    message, seconds = _refused(path)
    assert 'larger than the limit of 1.0 MB' in message, message
    assert seconds < 0.5, seconds


def test_file_at_the_size_limit_is_read(tmp_path):
    path = huge_file(tmp_path / 'limit.yaml', MAX_PARAMS_FILE_BYTES)
    t0 = time.perf_counter()
    assert load_params_file(str(path)) == PlaneNodeConfig()
    assert time.perf_counter() - t0 < 2.0


def test_special_files_and_bad_bytes_are_refused(tmp_path):
    fifo = tmp_path / 'fifo.yaml'
    os.mkfifo(fifo)
    assert 'is not a regular file' in _refused(fifo)[0]
    assert 'Is a directory' in _refused(tmp_path)[0]
    assert 'No such file' in _refused(tmp_path / 'missing.yaml')[0]
    binary = tmp_path / 'binary.yaml'
    binary.write_bytes(b'plane_node:\n  ros__parameters:\n    a: \xff\xfe\n')
    assert 'is not UTF-8 text (byte 38)' in _refused(binary)[0]


def _write(tmp_path: Path, text: str) -> str:
    path = tmp_path / 'params.yaml'
    path.write_text(text, encoding='utf-8')
    return str(path)


def test_shipped_file_and_the_forms_rcl_accepts_are_read(tmp_path):
    shipped = SHIPPED.read_text(encoding='utf-8')
    assert load_params_file(str(SHIPPED)) == PlaneNodeConfig()
    block = '  ros__parameters:\n    estimator.threshold_px: 4\n    use_sim_time: true\n'
    for key in ('/**', 'plane_node', '/plane_node', '/robot/plane_node', '/**/plane_node'):
        assert load_params_file(_write(tmp_path, f'{key}:\n{block}')).estimator.threshold_px \
            == 4.0, key
        assert read_node_params(_write(tmp_path, shipped.replace('plane_node:', f'{key}:', 1)))
    # Namespaces as nested keys, nested parameter names, and other nodes' blocks.
    text = ('robot:\n  plane_node:\n    ros__parameters:\n      prior:\n'
            '        tilt_deg: [5, 25]\ncamera_driver:\n  ros__parameters:\n'
            '    exposure: [1, 2]\n    mode: fast\n')
    assert load_params_file(_write(tmp_path, text)).prior.tilt_deg == (5.0, 25.0)


def test_blocks_merge_wildcards_first_then_named_blocks(tmp_path):
    text = ('plane_node:\n  ros__parameters:\n    estimator.threshold_px: 5.0\n'
            '/**:\n  ros__parameters:\n    estimator.threshold_px: 2.0\n'
            '    mask.scale: 0.25\n')
    config = load_params_file(_write(tmp_path, text))
    assert config.estimator.threshold_px == 5.0 and config.mask.scale == 0.25


def test_applies_to_and_ros_arguments():
    assert applies_to('/**', 'plane_node') and applies_to('ns/*', 'plane_node')
    assert applies_to('/a/plane_node', 'plane_node')
    assert not applies_to('/plane_node_2', 'plane_node')
    args = ['plane_node', '--params-file', 'not_ros.yaml', '--ros-args', '--params-file',
            'a.yaml', '-r', '__node:=left_plane', '-p', 'x:=1', '--', '--params-file', 'b.yaml',
            '--ros-args', '--params-file', 'c.yaml']
    assert ros_params_files(args) == (['a.yaml', 'c.yaml'], 'left_plane')
    with pytest.raises(ConfigError, match='needs a file name'):
        ros_params_files(['x', '--ros-args', '--params-file'])
