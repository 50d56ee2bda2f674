"""plane_replay: bags in, the node's outputs out; equal to the pipeline and to the live node."""

from __future__ import annotations

import csv
import os
from pathlib import Path
import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from domplane_ros.config import PlaneNodeConfig
from domplane_ros.node import PlaneNode
from domplane_ros.pipeline import PlanePipeline
from domplane_ros.replay import (BagInput, main, pair_messages, replay_frames, ReplaySession,
                                 run_replay)
from domplane_ros.scene import scene_sequence
from domplane_ros.sync import ApproximateTimeSync
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import Image
from std_msgs.msg import Float64MultiArray

N_FRAMES = 8
STAMP0_NS = 1_700_000_000_000_000_000
PERIOD_NS = 33_333_333          # 30 Hz
RIGHT_OFFSET_NS = 1_000         # the right camera's stamps lag by 1 us
LEFT, RIGHT = '/left/image_raw', '/right/image_raw'

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types


@pytest.fixture(scope='module')
def frames():
    return scene_sequence(N_FRAMES, seed=5, width=320, height=240, n_boxes=3)


def _left_stamp(i: int) -> int:
    return STAMP0_NS + i * PERIOD_NS


def _header(stamp_ns: int, frame_id: str):
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
        frame_id=frame_id)


def _image_msg(gray: np.ndarray, stamp_ns: int, frame_id: str, compressed: bool):
    if compressed:
        ok, png = cv2.imencode('.png', gray)
        assert ok
        return 'sensor_msgs/msg/CompressedImage', T['sensor_msgs/msg/CompressedImage'](
            header=_header(stamp_ns, frame_id), format='mono8; png compressed mono8',
            data=png.ravel())
    height, width = gray.shape
    return 'sensor_msgs/msg/Image', T['sensor_msgs/msg/Image'](
        header=_header(stamp_ns, frame_id), height=height, width=width, encoding='mono8',
        is_bigendian=0, step=width, data=gray.ravel().copy())


def write_bag(path: Path, frames, storage: str = 'sqlite3', compressed: bool = False,
              order=None) -> list[int]:
    """Write a stereo bag (plus a non-image topic); return the left stamps in bag order."""
    order = list(range(len(frames))) if order is None else order
    stamps = []
    with Writer(path, version=9, storage_plugin=StoragePlugin[storage.upper()]) as writer:
        kind = 'sensor_msgs/msg/CompressedImage' if compressed else 'sensor_msgs/msg/Image'
        conn_left = writer.add_connection(LEFT, kind, typestore=TS)
        conn_right = writer.add_connection(RIGHT, kind, typestore=TS)
        conn_text = writer.add_connection('/chatter', 'std_msgs/msg/String', typestore=TS)
        for k, i in enumerate(order):
            stamp = _left_stamp(i)
            stamps.append(stamp)
            for conn, gray, frame_id, offset in ((conn_left, frames[i].left, 'left_cam', 0),
                                                 (conn_right, frames[i].right, 'right_cam',
                                                  RIGHT_OFFSET_NS)):
                msgtype, msg = _image_msg(gray, stamp + offset, frame_id, compressed)
                # Bag time: recorded a little after the stamp, in order.
                writer.write(conn, _left_stamp(k) + offset + 5_000_000,
                             TS.serialize_cdr(msg, msgtype))
            writer.write(conn_text, _left_stamp(k) + 6_000_000,
                         TS.serialize_cdr(T['std_msgs/msg/String'](data=f'frame {k}'),
                                          'std_msgs/msg/String'))
    return stamps


def read_bag(path: Path) -> dict:
    """Return {topic: [(bag_time, msg)]}, the topic types and the storage of a bag."""
    out: dict = {}
    with Reader(path) as reader:
        types = {name: info.msgtype for name, info in reader.topics.items()}
        counts = {name: info.msgcount for name, info in reader.topics.items()}
        for conn, bag_time, raw in reader.messages():
            out.setdefault(conn.topic, []).append(
                (bag_time, TS.deserialize_cdr(raw, conn.msgtype)))
    storage = 'mcap' if list(path.glob('*.mcap')) else 'sqlite3'
    return {'messages': out, 'types': types, 'counts': counts, 'storage': storage}


def expected_results(frames, stamps, resets=()):
    """Call the pipeline directly on the frames, as the replay should."""
    pipeline = PlanePipeline(PlaneNodeConfig())
    results = []
    for k, stamp in enumerate(stamps):
        i = (stamp - STAMP0_NS) // PERIOD_NS
        results.append(pipeline.process(frames[i].left, frames[i].right, stamp,
                                        reset=k in resets))
    return results


def tree(path: Path) -> set[str]:
    return {str(p.relative_to(path)) for p in path.rglob('*')}


def _mask_array(msg) -> np.ndarray:
    return np.asarray(msg.data, np.uint8).reshape(msg.height, msg.width)


def check_output(out: Path, expected, stamps, storage: str) -> None:
    bag = read_bag(out)
    assert bag['storage'] == storage
    assert bag['types'] == {'/plane/homography': 'std_msgs/msg/Float64MultiArray',
                            '/plane/mask': 'sensor_msgs/msg/Image',
                            '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray'}
    msgs = bag['messages']
    masks = msgs['/plane/mask']
    assert [t for t, _ in masks] == stamps
    assert len(masks) == len(expected)
    for (bag_time, msg), result in zip(masks, expected):
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == bag_time
        assert msg.header.frame_id == 'left_cam'
        assert msg.encoding == 'mono8'
        assert np.array_equal(_mask_array(msg), result.mask)
    ok_stamps = [s for s, r in zip(stamps, expected) if r.ok]
    assert ok_stamps, 'the scene should give some planes'
    homs = msgs.get('/plane/homography', [])
    assert [t for t, _ in homs] == ok_stamps
    for (_, msg), result in zip(homs, [r for r in expected if r.ok]):
        assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == [
            ('rows', 3, 9), ('cols', 3, 3)]
        h = np.asarray(msg.data).reshape(3, 3)
        assert np.array_equal(h, result.homography)
        assert h[2, 2] == 1.0
    diags = msgs['/diagnostics']
    assert 1 <= len(diags) <= 2
    keys = [kv.key for kv in diags[-1][1].status[0].values]
    assert 'input rate [pairs/s]' in keys and 'dropped frames (sync)' in keys
    values = {kv.key: kv.value for kv in diags[-1][1].status[0].values}
    assert values['processed pairs'] == str(len(expected))


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_replay_equals_pipeline(tmp_path, frames, storage, capsys):
    stamps = write_bag(tmp_path / 'in', frames, storage)
    expected = expected_results(frames, stamps)
    csv_path = tmp_path / 'pairs.csv'
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--csv', str(csv_path),
               '--no-progress'])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert 'pairs processed: 8' in out.out
    check_output(tmp_path / 'out', expected, stamps, storage)
    with open(csv_path, newline='') as stream:
        rows = list(csv.DictReader(stream))
    assert [int(r['stamp_ns']) for r in rows] == stamps
    assert [r['ok'] for r in rows] == [str(int(r.ok)) for r in expected]
    for row, result in zip(rows, expected):
        assert int(row['n_inliers']) == result.n_inliers
        if result.ok:
            assert float(row['h01']) == result.homography[0, 1]
    assert not [p for p in tree(tmp_path) if 'partial' in p]


def test_compressed_png_input_and_storage_override(tmp_path, frames):
    stamps = write_bag(tmp_path / 'in', frames, 'sqlite3', compressed=True)
    expected = expected_results(frames, stamps)
    rc = main([str(tmp_path / 'in'), str(tmp_path / 'out'), '--storage', 'mcap',
               '--no-progress'])
    assert rc == 0
    check_output(tmp_path / 'out', expected, stamps, 'mcap')


def test_bag_loop_resets_like_the_node(tmp_path, frames):
    # Stamps go back after frame 4 (a looping bag): the replay drops the warm start there.
    order = [0, 1, 2, 3, 4, 0, 1, 2]
    stamps = write_bag(tmp_path / 'in', frames, 'mcap', order=order)
    expected = expected_results(frames, stamps, resets={5})
    session = ReplaySession(PlaneNodeConfig())
    with BagInput(tmp_path / 'in', LEFT, RIGHT) as bag:
        got = [f for m in bag.messages() for f in session.add(m.side, m.msg)]
    assert [f.pair.after_reset for f in got] == [k == 5 for k in range(8)]
    assert [f.result.reinitialised for f in got][5]
    for frame, result in zip(got, expected):
        assert np.array_equal(frame.result.mask, result.mask)
        assert (frame.result.homography is None) == (result.homography is None)
        if result.ok:
            assert np.array_equal(frame.result.homography, result.homography)
    # The generator API gives the same results.
    with BagInput(tmp_path / 'in', LEFT, RIGHT) as bag:
        sync = ApproximateTimeSync(0.01, 5)
        results = list(replay_frames(pair_messages(((m.side, m.msg) for m in bag.messages()),
                                                   sync), PlanePipeline()))
    assert [r.stamp_ns for r in results] == stamps
    assert all(np.array_equal(a.mask, b.mask) for a, b in zip(results, expected))


def _params(tmp_path: Path, body: str) -> Path:
    path = tmp_path / 'params.yaml'
    path.write_text('plane_node:\n  ros__parameters:\n' + body)
    return path


def _garbage_file(tmp_path: Path, name: str) -> Path:
    path = tmp_path / name
    path.write_bytes(b'this is not a bag\n' * 200)
    return path


def _garbage_in_folder(tmp_path: Path) -> Path:
    # A bag folder whose metadata is fine but whose database is garbage.
    bag = tmp_path / 'broken'
    write_bag(bag, [], 'sqlite3')
    (bag / 'broken.db3').write_bytes(os.urandom(4096))
    return bag


@pytest.mark.parametrize('case,needles', [
    ('missing', ['does not exist', 'nope']),
    ('garbage_db3', ['cannot read bag', 'junk.db3']),
    ('garbage_mcap', ['cannot read bag', 'junk.mcap']),
    ('garbage_folder', ['cannot read bag', 'broken']),
    ('truncated_mcap', ['cannot read bag']),
    ('missing_topic', ["'/nope'", 'image topics in the bag: /left/image_raw (Image), '
                                  '/right/image_raw (Image)']),
    ('not_an_image_topic', ["'/chatter'", 'std_msgs/msg/String']),
    ('existing_output', ['exists', '--force']),
    ('unknown_parameter', ["unknown parameter 'estimator.bogus'", 'params.yaml']),
    ('invalid_parameter', ["'estimator.lambda_weight'", 'above the maximum']),
])
def test_refusals_exit_2_with_one_line_and_write_nothing(tmp_path, frames, capsys, case,
                                                         needles):
    inp = tmp_path / 'in'
    write_bag(inp, frames[:2], 'mcap')
    out = tmp_path / 'out'
    extra: list[str] = []
    if case == 'missing':
        inp = tmp_path / 'nope'
    elif case == 'garbage_db3':
        inp = _garbage_file(tmp_path, 'junk.db3')
    elif case == 'garbage_mcap':
        inp = _garbage_file(tmp_path, 'junk.mcap')
    elif case == 'garbage_folder':
        inp = _garbage_in_folder(tmp_path)
    elif case == 'truncated_mcap':
        data = (inp / 'in.mcap').read_bytes()
        (inp / 'in.mcap').write_bytes(data[:len(data) // 2])
    elif case == 'missing_topic':
        extra = ['--left-topic', '/nope']
    elif case == 'not_an_image_topic':
        extra = ['--right-topic', '/chatter']
    elif case == 'existing_output':
        out.mkdir()
        (out / 'keep.txt').write_text('mine')
    elif case == 'unknown_parameter':
        extra = ['--params-file', str(_params(tmp_path, '    estimator.bogus: 1\n'))]
    elif case == 'invalid_parameter':
        extra = ['--params-file', str(_params(tmp_path, '    estimator:\n'
                                                        '      lambda_weight: 1.5\n'))]
    capsys.readouterr()
    before = tree(tmp_path)
    rc = main([str(inp), str(out), '--csv', str(tmp_path / 'pairs.csv'), '--no-progress']
              + extra)
    captured = capsys.readouterr()
    assert rc == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith('plane_replay: error: ')
    for needle in needles:
        assert needle in lines[0]
    assert captured.out == ''
    assert tree(tmp_path) == before
    if case == 'existing_output':
        assert (out / 'keep.txt').read_text() == 'mine'


def test_force_replaces_existing_output(tmp_path, frames):
    write_bag(tmp_path / 'in', frames[:3], 'sqlite3')
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'old.txt').write_text('old')
    assert main([str(tmp_path / 'in'), str(out), '--force', '--no-progress']) == 0
    assert not (out / 'old.txt').exists()
    assert len(read_bag(out)['messages']['/plane/mask']) == 3
    inputs = {'in'} | {f'in/{p}' for p in tree(tmp_path / 'in')}
    assert tree(tmp_path) == inputs | {'out', 'out/metadata.yaml', 'out/out.db3'}


def test_failure_mid_bag_leaves_no_output_that_looks_complete(tmp_path, frames, capsys):
    inp = tmp_path / 'in'
    write_bag(inp, frames, 'sqlite3')
    db3 = inp / 'in.db3'
    size = db3.stat().st_size
    with open(db3, 'r+b') as stream:   # overwrite pages in the middle of the message data
        stream.seek(size // 2 // 4096 * 4096)
        stream.write(b'\xff' * 3 * 4096)
    out = tmp_path / 'out'
    csv_path = tmp_path / 'pairs.csv'
    before = tree(tmp_path)
    rc = main([str(inp), str(out), '--csv', str(csv_path), '--no-progress'])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    assert len(err) == 1 and 'failed after' in err[0] and 'removed' in err[0]
    assert tree(tmp_path) == before   # no output, no CSV, no partial folder


def test_interrupted_replay_removes_partial_output(tmp_path, frames):
    write_bag(tmp_path / 'in', frames, 'mcap')
    before = tree(tmp_path)

    def crash(frame):
        if frame.result.stamp_ns >= _left_stamp(3):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_replay(tmp_path / 'in', tmp_path / 'out', on_frame=crash)
    assert tree(tmp_path) == before


def test_decode_error_mid_bag_is_counted_not_fatal(tmp_path, frames, capsys):
    path = tmp_path / 'in'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [writer.add_connection(t, 'sensor_msgs/msg/Image', typestore=TS)
                 for t in (LEFT, RIGHT)]
        for i in range(4):
            for conn, gray, offset in ((conns[0], frames[i].left, 0),
                                       (conns[1], frames[i].right, RIGHT_OFFSET_NS)):
                _, msg = _image_msg(gray, _left_stamp(i) + offset, 'cam', False)
                if i == 2 and offset == 0:
                    msg = T['sensor_msgs/msg/Image'](
                        header=msg.header, height=msg.height, width=msg.width,
                        encoding='yuv_bogus', is_bigendian=0, step=msg.step, data=msg.data)
                writer.write(conn, _left_stamp(i) + offset,
                             TS.serialize_cdr(msg, 'sensor_msgs/msg/Image'))
    rc = main([str(path), str(tmp_path / 'out'), '--no-progress'])
    captured = capsys.readouterr()
    assert rc == 0
    assert 'decode errors: 1 pairs' in captured.out
    assert 'yuv_bogus' in captured.out
    bag = read_bag(tmp_path / 'out')
    assert len(bag['messages']['/plane/mask']) == 3
    values = {kv.key: kv.value for kv in bag['messages']['/diagnostics'][-1][1].status[0].values}
    assert values['decode errors'] == '1'


# --- The same bag through the live node over DDS ------------------------------------------


def _to_rclpy(msg) -> Image:
    out = Image()
    out.header.stamp.sec = int(msg.header.stamp.sec)
    out.header.stamp.nanosec = int(msg.header.stamp.nanosec)
    out.header.frame_id = msg.header.frame_id
    out.height, out.width = int(msg.height), int(msg.width)
    out.encoding = msg.encoding
    out.is_bigendian = int(msg.is_bigendian)
    out.step = int(msg.step)
    out.data = np.asarray(msg.data, np.uint8).tobytes()
    return out


def test_live_node_gives_the_replay_results(ros_context, tmp_path, frames):
    write_bag(tmp_path / 'in', frames, 'mcap')
    replayed = []
    run_replay(tmp_path / 'in', tmp_path / 'out', on_frame=replayed.append)
    with BagInput(tmp_path / 'in', LEFT, RIGHT) as bag:
        pairs = list(pair_messages(((m.side, m.msg) for m in bag.messages()),
                                   ApproximateTimeSync(0.01, 5)))
    assert len(pairs) == len(replayed) == N_FRAMES

    node = PlaneNode(context=ros_context,
                     parameter_overrides=[Parameter('diagnostics.period_s', value=0.2)])
    driver = Node('replay_driver', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    try:
        pub_left = driver.create_publisher(Image, 'left/image_raw', qos_profile_sensor_data)
        pub_right = driver.create_publisher(Image, 'right/image_raw', qos_profile_sensor_data)
        homographies: list[Float64MultiArray] = []
        masks: list[Image] = []
        diagnostics: list[DiagnosticArray] = []
        driver.create_subscription(Float64MultiArray, 'plane/homography',
                                   homographies.append, 10)
        driver.create_subscription(Image, 'plane/mask', masks.append, 10)
        driver.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
        executor.add_node(node)
        executor.add_node(driver)

        def spin_until(predicate, timeout):
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                if predicate():
                    return True
                executor.spin_once(timeout_sec=0.02)
            return predicate()

        assert spin_until(lambda: pub_left.get_subscription_count()
                          and pub_right.get_subscription_count()
                          and node._pub_mask.get_subscription_count()
                          and node._pub_h.get_subscription_count(), 15.0), 'no discovery'

        def mask_stamps():
            return [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in masks]

        for pair in pairs:
            # Send the pair, and wait for the node's mask for it before the next one, so that
            # no pair is replaced before the node's worker takes it. A pair lost on the
            # best-effort link is sent again: the node's sync ignores a stamp it has paired.
            for _attempt in range(5):
                pub_left.publish(_to_rclpy(pair.left))
                pub_right.publish(_to_rclpy(pair.right))
                if spin_until(lambda: pair.left_stamp_ns in mask_stamps(), 5.0):
                    break
            else:
                raise AssertionError(f'no mask from the node for {pair.left_stamp_ns}')
        expected_h = [f.result.homography for f in replayed if f.result.ok]
        spin_until(lambda: len(homographies) >= len(expected_h)
                   and diagnostics and diagnostics[-1].status[0].values
                   and node._counters['processed'] == N_FRAMES, 5.0)
        spin_until(lambda: False, 0.3)   # anything late would show up as an extra message
    finally:
        executor.shutdown()
        node.destroy_node()
        driver.destroy_node()

    assert node._counters['processed'] == N_FRAMES
    assert node._counters['dropped_busy'] == 0
    assert mask_stamps() == [f.pair.left_stamp_ns for f in replayed]
    for msg, frame in zip(masks, replayed):
        assert np.array_equal(np.frombuffer(bytes(msg.data), np.uint8).reshape(
            msg.height, msg.width), frame.result.mask)
    assert len(homographies) == len(expected_h)
    for msg, h in zip(homographies, expected_h):
        assert np.allclose(np.array(msg.data).reshape(3, 3), h, rtol=0, atol=1e-9)
    # The replay's diagnostics carry the node's keys.
    node_keys = [kv.key for kv in diagnostics[-1].status[0].values]
    replay_diag = read_bag(tmp_path / 'out')['messages']['/diagnostics'][-1][1]
    assert [kv.key for kv in replay_diag.status[0].values] == node_keys


def test_demo_writes_its_outputs(tmp_path, capsys):
    from domplane_ros.demo import DEMO_OUTPUTS, main as demo_main

    out = tmp_path / 'demo'
    out.mkdir()
    (out / 'notes.txt').write_text('not from the demo')
    (out / 'overlay.png').write_text('stale')
    argv = ['--output', str(out), '--frames', '4', '--width', '192', '--height', '144']
    assert demo_main(argv) == 0
    printed = capsys.readouterr().out
    assert 'Refreshing the previous demo outputs' in printed
    assert 'plane found in' in printed and 'mean transfer error' in printed
    assert (out / 'notes.txt').read_text() == 'not from the demo'
    for name in DEMO_OUTPUTS:
        assert (out / name).exists(), name
    assert cv2.imread(str(out / 'overlay.png')).shape[1] == 192
    assert cv2.imread(str(out / 'contact_sheet.png')) is not None
    assert cv2.imread(str(out / 'energy_inliers.png')) is not None
    bag = read_bag(out / 'plane_bag')
    assert len(bag['messages']['/plane/mask']) == 4
