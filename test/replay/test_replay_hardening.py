"""plane_replay against the hostile input of issue 16, each case with its exit code.

Parameters files (the probe's alias and size attacks, and a hypothesis fuzz), a bag without
pairs, a full disk under either storage (a real 300 KB tmpfs where the test may mount one,
else a file-size limit on a real file system), and an output inside the input bag's folder.
Every case: its documented exit code, one line on stderr, no traceback, nothing left written.
"""

from __future__ import annotations

import contextlib
import io
import os
from pathlib import Path
import resource
import shutil
import signal
import subprocess
import sys
import time

from bag_helpers import LEFT, read_bag, RIGHT, tree, TS, write_bag
from domplane_ros.replay.cli import EXIT_FAILED, EXIT_NO_PAIRS, EXIT_REFUSED, main
from hypothesis import given, HealthCheck, settings
from params_fuzz import hostile_params_files, snapshot, write_case
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from test_params_file import alias_bomb, huge_file

BIN = Path(sys.executable).parent


@pytest.fixture(scope='module')
def bag(tmp_path_factory, frames):
    path = tmp_path_factory.mktemp('input') / 'bag'
    write_bag(path, frames[:3])
    return path


def _run(argv):
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue(), time.perf_counter() - t0


def _one_error_line(err):
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith('plane_replay: error: '), err
    assert 'Traceback' not in err
    return lines[0]


# --- Parameters files ------------------------------------------------------------------------

@pytest.mark.parametrize('case', ['aliases', 'size', 'list', 'list under ros__parameters'])
def test_hostile_params_file_is_refused_in_one_line_within_2_s(tmp_path, bag, case):
    path = tmp_path / 'params.yaml'
    needle = {'aliases': 'uses the YAML alias', 'size': 'larger than the limit of 1.0 MB',
              'list': 'not a list', 'list under ros__parameters': 'must be a mapping'}[case]
    if case == 'aliases':
        path.write_text(alias_bomb())
    elif case == 'size':
        huge_file(path, 55_000_000)
    else:
        path.write_text('- 1\n- 2\n' if case == 'list'
                        else 'plane_node:\n  ros__parameters:\n    - 1\n')
    code, out, err, seconds = _run([bag, tmp_path / 'out', '--params-file', path])
    assert code == EXIT_REFUSED and out == ''
    assert needle in _one_error_line(err)
    assert seconds < 2.0, seconds
    assert not (tmp_path / 'out').exists() and tree(tmp_path) == {'params.yaml'}


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(case=hostile_params_files())
def test_fuzzed_params_files_exit_2_within_2_s_writing_nothing(tmp_path_factory, bag, case):
    folder = tmp_path_factory.mktemp('fuzz')
    path = write_case(folder / 'params.yaml', case)
    before = snapshot(folder)
    code, out, err, seconds = _run([bag, folder / 'out', '--params-file', path,
                                    '--csv', folder / 'pairs.csv'])
    assert code == EXIT_REFUSED, (case[0], err)
    assert 'params file' in _one_error_line(err) and out == ''
    assert seconds < 2.0, (case[0], seconds)
    assert snapshot(folder) == before
    shutil.rmtree(folder)


# --- Bags without pairs ------------------------------------------------------------------------

def _write_unpaired(path, frames, storage):
    """Right stamps 50 ms after the left ones: nothing pairs within sync.slop_s (10 ms)."""
    with Writer(path, version=9, storage_plugin=StoragePlugin[storage.upper()]) as writer:
        conns = {LEFT: writer.add_connection(LEFT, 'sensor_msgs/msg/Image', typestore=TS),
                 RIGHT: writer.add_connection(RIGHT, 'sensor_msgs/msg/Image', typestore=TS)}
        for k, frame in enumerate(frames[:3]):
            for topic, gray, offset in ((LEFT, frame.left, 0), (RIGHT, frame.right, 50)):
                stamp = 10**18 + k * 10**8 + offset * 10**6
                msg = TS.types['sensor_msgs/msg/Image'](
                    header=TS.types['std_msgs/msg/Header'](
                        stamp=TS.types['builtin_interfaces/msg/Time'](
                            sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id='cam'),
                    height=gray.shape[0], width=gray.shape[1], encoding='mono8',
                    is_bigendian=0, step=gray.shape[1], data=gray.ravel().copy())
                writer.write(conns[topic], stamp, TS.serialize_cdr(msg, 'sensor_msgs/msg/Image'))


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('content', ['no messages', 'no partner'])
def test_bag_without_pairs_exits_4_says_no_pairs_and_writes_nothing(tmp_path, frames, storage,
                                                                    content):
    bag = tmp_path / 'in'
    if content == 'no messages':
        write_bag(bag, [], storage=storage)
        reason = 'the bag has 0 readable messages on /left/image_raw and 0 on /right/image_raw'
    else:
        _write_unpaired(bag, frames, storage)
        reason = '3 left and 3 right messages, none within sync.slop_s 0.01 s of a partner'
    code, out, err, _ = _run([bag, tmp_path / 'out', '--csv', tmp_path / 'pairs.csv'])
    assert code == EXIT_NO_PAIRS
    assert _one_error_line(err) == f'plane_replay: error: no pairs: {reason}; nothing was written'
    assert f'  written:         nothing (no pairs: {reason})' in out.splitlines()
    assert 'latency:         n/a (no pair processed)' in out and 'nan' not in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ['in']


# --- A full disk ---------------------------------------------------------------------------------

@pytest.fixture
def small_disk(tmp_path):
    """Yield a folder on a real 300 KB tmpfs (needs mount rights; else the test is skipped)."""
    mount = tmp_path / 'disk'
    mount.mkdir()
    done = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=300k', 'tmpfs', str(mount)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f'cannot mount a tmpfs here: {done.stderr.strip()}')
    try:
        yield mount
    finally:
        subprocess.run(['umount', str(mount)], check=True)


def _replay_process(argv, file_size_limit=None):
    def limit():
        if file_size_limit is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_size_limit, file_size_limit))
    return subprocess.run([str(BIN / 'plane_replay'), *map(str, argv), '--no-progress'],
                          capture_output=True, text=True, preexec_fn=limit, timeout=120)


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_full_disk_fails_in_one_line_and_leaves_nothing(tmp_path, frames, small_disk, storage):
    bag = tmp_path / 'in'
    write_bag(bag, frames, storage=storage)   # 1.2 MB of images: 8 masks do not fit in 300 KB
    done = _replay_process([bag, small_disk / 'out', '--csv', small_disk / 'pairs.csv'])
    assert done.returncode == EXIT_FAILED, done.stderr
    line = _one_error_line(done.stderr)
    assert line.startswith("plane_replay: error: writing the output bag '")
    assert line.endswith('(disk full); the partial output was removed'), line
    assert list(small_disk.iterdir()) == []


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_file_size_limit_fails_in_one_line_and_leaves_nothing(tmp_path, frames, storage):
    bag = tmp_path / 'in'
    write_bag(bag, frames[:4], storage=storage)
    out = tmp_path / 'out_folder'
    out.mkdir()
    done = _replay_process([bag, out / 'out'], file_size_limit=200_000)
    assert done.returncode == EXIT_FAILED, done.stderr
    line = _one_error_line(done.stderr)
    # EFBIG: Python says 'File too large (disk full)'; sqlite3 says 'disk I/O error'.
    assert line.startswith(f"plane_replay: error: writing the output bag '{out / 'out'}' "
                           'failed: '), line
    assert line.endswith(('File too large (disk full); the partial output was removed',
                          'disk I/O error; the partial output was removed')), line
    assert list(out.iterdir()) == []


# --- Output inside the input -------------------------------------------------------------------

def test_output_inside_the_folder_of_a_storage_file_input_is_refused(tmp_path, bag):
    storage_file = next(bag.glob('*.db3'))
    link = tmp_path / 'link'
    os.symlink(bag, link)
    before = tree(bag)
    for given_input, output in ((storage_file, bag / 'out'),
                                (link / storage_file.name, bag / 'sub' / 'out'),
                                (storage_file, link / 'out')):
        code, out, err, _ = _run([given_input, output])
        assert code == EXIT_REFUSED
        assert 'would overwrite or nest in the input bag' in _one_error_line(err)
    code, _, err, _ = _run([storage_file, tmp_path / 'out', '--csv', bag / 'pairs.csv'])
    assert code == EXIT_REFUSED and 'would overwrite a bag' in err
    assert tree(bag) == before
    # A storage file on its own may have its output beside it.
    alone = tmp_path / 'alone.db3'
    shutil.copy(storage_file, alone)
    code, _, err, _ = _run([alone, tmp_path / 'beside'])
    assert code == 0, err
    assert read_bag(tmp_path / 'beside')['counts']['/plane/mask'] == 3
