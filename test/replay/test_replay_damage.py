"""plane_replay on damaged bags: real files written by rosbags, then truncated or corrupted.

Policy under test (README, "Offline replay"): a bag that cannot be opened is refused (exit 2,
nothing written); a read failure part-way aborts (exit 1, partial output removed); a single
message whose payload cannot be deserialised is skipped and counted (exit 3, a warning naming
it, the count in the output's metadata.yaml), or is fatal with --strict; Ctrl-C and SIGTERM
remove the partial output (exit 130 / 143).
"""

from __future__ import annotations

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from bag_helpers import (image_msg, LEFT, left_stamp, read_bag, RIGHT, RIGHT_OFFSET_NS, tree, TS,
                         write_bag)
from domplane_ros.config import PipelineConfig, PlaneNodeConfig
from domplane_ros.replay.cli import main, run_replay
from domplane_ros.sim.generators import scene_sequence
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from truth import transfer_error_px
import yaml


@pytest.fixture(scope='module')
def frames():
    return scene_sequence(6, seed=5, width=320, height=240, n_boxes=3)


def _storage_file(bag: Path) -> Path:
    return next(p for p in bag.iterdir() if p.suffix in ('.db3', '.mcap'))


def _run(capsys, *argv) -> tuple[int, list[str], str]:
    capsys.readouterr()
    rc = main([str(a) for a in argv] + ['--no-progress'])
    captured = capsys.readouterr()
    return rc, captured.err.strip().splitlines(), captured.out


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('damage,needles', [
    ('truncated', ['truncated']),
    ('missing_metadata', ['has no metadata.yaml', 'to read its storage file alone, give']),
])
def test_unopenable_bag_is_refused_naming_bag_and_problem(tmp_path, frames, capsys, storage,
                                                          damage, needles):
    inp = tmp_path / 'in'
    write_bag(inp, frames, storage)
    if damage == 'truncated':
        data = _storage_file(inp).read_bytes()
        _storage_file(inp).write_bytes(data[:len(data) // 2])
    else:
        (inp / 'metadata.yaml').unlink()
    before = tree(tmp_path)
    rc, err, out = _run(capsys, inp, tmp_path / 'out', '--csv', tmp_path / 'pairs.csv')
    assert rc == 2
    assert len(err) == 1 and err[0].startswith('plane_replay: error: ')
    assert str(inp) in err[0]
    for needle in needles:
        assert needle in err[0]
    assert out == ''
    assert tree(tmp_path) == before


def test_storage_file_of_a_folder_without_metadata_can_be_replayed(tmp_path, frames, capsys):
    inp = tmp_path / 'in'
    write_bag(inp, frames, 'mcap')
    (inp / 'metadata.yaml').unlink()
    rc, err, out = _run(capsys, _storage_file(inp), tmp_path / 'out')
    assert rc == 0, err
    assert len(read_bag(tmp_path / 'out')['messages']['/plane/mask']) == len(frames)


def test_truncated_sqlite_tail_fails_part_way_and_removes_output(tmp_path, frames, capsys):
    inp = tmp_path / 'in'
    write_bag(inp, frames, 'sqlite3')
    data = _storage_file(inp).read_bytes()
    _storage_file(inp).write_bytes(data[:-100])
    before = tree(tmp_path)
    rc, err, _ = _run(capsys, inp, tmp_path / 'out', '--csv', tmp_path / 'pairs.csv')
    assert rc == 1
    assert len(err) == 1 and 'failed after' in err[0] and str(inp) in err[0]
    assert 'partial output was removed' in err[0]
    assert tree(tmp_path) == before


def test_keep_partial_keeps_the_output_up_to_a_failure_marked_incomplete(tmp_path, frames,
                                                                         capsys):
    inp = tmp_path / 'in'
    write_bag(inp, frames, 'sqlite3')
    data = _storage_file(inp).read_bytes()
    _storage_file(inp).write_bytes(data[:-100])
    out, csv_path = tmp_path / 'out', tmp_path / 'pairs.csv'
    rc, err, _ = _run(capsys, inp, out, '--csv', csv_path, '--keep-partial')
    assert rc == 1
    kept = tmp_path / 'out.incomplete'
    assert len(err) == 1 and 'failed after' in err[0]
    assert repr(str(kept)) + ' (incomplete)' in err[0]
    assert not out.exists() and not csv_path.exists()
    assert not [p for p in tree(tmp_path) if 'partial' in p]
    meta = yaml.safe_load((kept / 'metadata.yaml').read_text())
    custom = meta['rosbag2_bagfile_information']['custom_data']
    assert custom['plane_replay.complete'] == 'false'
    assert 'failed after' in custom['plane_replay.error']
    masks = read_bag(kept)['messages']['/plane/mask']
    assert 0 < len(masks) < len(frames)
    rows = (tmp_path / 'pairs.csv.incomplete').read_text().splitlines()
    assert len(rows) == 1 + len(masks)
    # A second run does not silently replace the kept output.
    rc, err, _ = _run(capsys, inp, out, '--keep-partial')
    assert rc == 2 and 'out.incomplete' in err[0] and '--force' in err[0]


def _bag_with_bad_payloads(path: Path, frames, storage: str) -> None:
    """Write a bag whose left message 2 is garbage and right message 4 cut-off CDR."""
    with Writer(path, version=9, storage_plugin=StoragePlugin[storage.upper()]) as writer:
        conns = [writer.add_connection(t, 'sensor_msgs/msg/Image', typestore=TS)
                 for t in (LEFT, RIGHT)]
        for i, frame in enumerate(frames):
            for conn, gray, offset in ((conns[0], frame.left, 0),
                                       (conns[1], frame.right, RIGHT_OFFSET_NS)):
                _, msg = image_msg(gray, left_stamp(i) + offset, 'cam', False)
                raw = TS.serialize_cdr(msg, 'sensor_msgs/msg/Image')
                if i == 2 and conn is conns[0]:
                    raw = np.frombuffer(b'\x00\x01\x00\x00not an image' * 3, np.uint8)
                elif i == 4 and conn is conns[1]:
                    raw = raw[:40]
                writer.write(conn, left_stamp(i) + offset + 5_000_000, raw)


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_undecodable_message_mid_bag_is_skipped_counted_and_reported(tmp_path, frames, capsys,
                                                                     storage):
    inp = tmp_path / 'in'
    _bag_with_bad_payloads(inp, frames, storage)
    rc, err, out = _run(capsys, inp, tmp_path / 'out')
    assert rc == 3
    assert len(err) == 1 and err[0].startswith('plane_replay: warning: 2 message(s)')
    assert str(inp) in err[0] and f'{LEFT} message' in err[0]
    assert 'skipped' in err[0]
    assert '2 messages' in out            # the summary's decode-error count
    bag = read_bag(tmp_path / 'out')
    masks = bag['messages']['/plane/mask']
    # Pairs 2 and 4 lost one image each: every other pair was processed.
    assert [t for t, _ in masks] == [left_stamp(i) for i in (0, 1, 3, 5)]
    diag = {kv.key: kv.value for kv in bag['messages']['/diagnostics'][-1][1].status[0].values}
    assert diag['decode errors'] == '2'
    meta = yaml.safe_load((tmp_path / 'out' / 'metadata.yaml').read_text())
    custom = meta['rosbag2_bagfile_information']['custom_data']
    assert custom['plane_replay.skipped_messages'] == '2'
    assert not [p for p in tree(tmp_path) if 'partial' in p]


def test_strict_makes_an_undecodable_message_fatal(tmp_path, frames, capsys):
    inp = tmp_path / 'in'
    _bag_with_bad_payloads(inp, frames, 'mcap')
    before = tree(tmp_path)
    rc, err, out = _run(capsys, inp, tmp_path / 'out', '--strict')
    assert rc == 1
    assert len(err) == 1 and '--strict' in err[0] and f'{LEFT} message 5' in err[0]
    assert 'partial output was removed' in err[0]
    assert tree(tmp_path) == before


def test_clean_bag_records_zero_skipped(tmp_path, frames, capsys):
    write_bag(tmp_path / 'in', frames[:2], 'sqlite3')
    rc, err, _ = _run(capsys, tmp_path / 'in', tmp_path / 'out')
    assert rc == 0 and err == []
    meta = yaml.safe_load((tmp_path / 'out' / 'metadata.yaml').read_text())
    assert meta['rosbag2_bagfile_information']['custom_data'] == {
        'plane_replay.input_bag': str(tmp_path / 'in'), 'plane_replay.skipped_messages': '0',
        'plane_replay.complete': 'true'}


_SLOW_REPLAY = """
from domplane_ros.stream import pipeline
import sys, time
real = pipeline.PlanePipeline.process
def slow(self, *args, **kwargs):
    time.sleep(0.2)
    return real(self, *args, **kwargs)
pipeline.PlanePipeline.process = slow
from domplane_ros.replay.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize('sig,code,needle', [(signal.SIGTERM, 143, 'terminated (SIGTERM)'),
                                             (signal.SIGINT, 130, 'interrupted')])
def test_signal_mid_replay_removes_partial_output(tmp_path, frames, sig, code, needle):
    inp = tmp_path / 'in'
    write_bag(inp, frames, 'mcap')
    before = tree(tmp_path)
    env = dict(os.environ, OMP_NUM_THREADS='1', OPENBLAS_NUM_THREADS='1')
    # The replay starts with SIGINT at its default, as from a terminal: a test run started in
    # the background of a non-interactive shell ignores SIGINT, and a child inherits that
    # (Python then installs no KeyboardInterrupt handler, and the replay rightly ignores it).
    proc = subprocess.Popen([sys.executable, '-c', _SLOW_REPLAY, str(inp), str(tmp_path / 'out'),
                             '--csv', str(tmp_path / 'pairs.csv'), '--no-progress'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True,
                            preexec_fn=_default_sigint)
    try:
        deadline = time.monotonic() + 30.0
        while not list(tmp_path.glob('.out.partial-*')):   # the replay is under way
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.02)
        time.sleep(0.3)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and 'partial output was removed' in lines[0]
    assert out == ''
    assert tree(tmp_path) == before


def test_camera_dropout_in_a_bag_is_reported_and_the_warm_start_dropped(tmp_path, frames):
    # 10 Hz; the right camera is silent from 0.5 s to 2.5 s (bag time).
    path = tmp_path / 'in'
    period = 100_000_000
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [writer.add_connection(t, 'sensor_msgs/msg/Image', typestore=TS)
                 for t in (LEFT, RIGHT)]
        # frames[4]: its plane verifies (0.24 px from the truth); on frames[0] the search's
        # best plane is 2.3 px off and the verification refuses it (score 0.19 < 0.2), an
        # honest failure on every pair that would leave nothing to re-lock on.
        frame = frames[4]
        for i in range(40):
            stamp = left_stamp(0) + i * period
            for conn, gray, offset in ((conns[0], frame.left, 0),
                                       (conns[1], frame.right, RIGHT_OFFSET_NS)):
                if conn is conns[1] and 5 <= i < 25:
                    continue
                _, msg = image_msg(gray, stamp + offset, 'cam', False)
                writer.write(conn, stamp + offset, TS.serialize_cdr(msg, 'sensor_msgs/msg/Image'))
    config = PlaneNodeConfig(pipeline=PipelineConfig(max_stamp_jump_s=1.0))
    summary = run_replay(path, tmp_path / 'out', config)
    assert summary.processed == 20
    bag = read_bag(tmp_path / 'out')
    statuses = [(t, m.status[0]) for t, m in bag['messages']['/diagnostics']]
    warns = [(t, s) for t, s in statuses if f'no images on {RIGHT}' in s.message]
    assert warns and all(left_stamp(0) + 15 * period < t <= left_stamp(0) + 25 * period
                         for t, _ in warns), [(t, s.message) for t, s in statuses]
    assert LEFT not in warns[0][1].message
    values = {kv.key: kv.value for kv in warns[0][1].values}
    assert float(values[f'{RIGHT} last image age [s]']) > 1.0
    # Back: locked again (the left frames of the gap that found no partner may still be
    # reported as unpaired in the status after the return).
    assert statuses[-1][1].message.startswith('plane locked')
    homs = bag['messages']['/plane/homography']
    assert homs and all(transfer_error_px(frame, np.asarray(m.data).reshape(3, 3)) < 1.0
                        for _, m in homs)
    assert values[f'{LEFT} images received'] == str(
        sum(1 for i in range(40) if left_stamp(0) + i * period < warns[0][0]))
    # The 2 s gap is longer than pipeline.max_stamp_jump_s: the first pair after it
    # re-initialised.
    assert summary.reinitialisations == 2
