"""Bag helpers shared by the replay tests, the node-vs-replay test and the demo test.

A short rendered sequence written as a stereo rosbag2 file (sqlite3 or MCAP), read back, and
the pipeline's own results for it.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
from domplane_ros.config import PlaneNodeConfig
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.stream.pipeline import PlanePipeline
import numpy as np
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

N_FRAMES = 8
STAMP0_NS = 1_700_000_000_000_000_000
PERIOD_NS = 33_333_333          # 30 Hz
RIGHT_OFFSET_NS = 1_000         # the right camera's stamps lag by 1 us
LEFT, RIGHT = '/left/image_raw', '/right/image_raw'

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types


def make_frames():
    """Return the short rendered sequence the bag tests use."""
    return scene_sequence(N_FRAMES, seed=5, width=320, height=240, n_boxes=3)


def left_stamp(i: int) -> int:
    return STAMP0_NS + i * PERIOD_NS


def _header(stamp_ns: int, frame_id: str):
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
        frame_id=frame_id)


def image_msg(gray: np.ndarray, stamp_ns: int, frame_id: str, compressed: bool):
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
            stamp = left_stamp(i)
            stamps.append(stamp)
            for conn, gray, frame_id, offset in ((conn_left, frames[i].left, 'left_cam', 0),
                                                 (conn_right, frames[i].right, 'right_cam',
                                                  RIGHT_OFFSET_NS)):
                msgtype, msg = image_msg(gray, stamp + offset, frame_id, compressed)
                # Bag time: recorded a little after the stamp, in order.
                writer.write(conn, left_stamp(k) + offset + 5_000_000,
                             TS.serialize_cdr(msg, msgtype))
            writer.write(conn_text, left_stamp(k) + 6_000_000,
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


def mask_array(msg) -> np.ndarray:
    return np.asarray(msg.data, np.uint8).reshape(msg.height, msg.width)


def check_output(out: Path, expected, stamps, storage: str) -> None:
    bag = read_bag(out)
    assert bag['storage'] == storage
    assert bag['types'] == {'/plane/homography': 'std_msgs/msg/Float64MultiArray',
                            '/plane/mask': 'sensor_msgs/msg/Image',
                            '/plane/result': 'diagnostic_msgs/msg/DiagnosticArray',
                            '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray'}
    msgs = bag['messages']
    masks = msgs['/plane/mask']
    assert [t for t, _ in masks] == stamps
    assert len(masks) == len(expected)
    for (bag_time, msg), result in zip(masks, expected):
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == bag_time
        assert msg.header.frame_id == 'left_cam'
        assert msg.encoding == 'mono8'
        assert np.array_equal(mask_array(msg), result.mask)
    results = msgs['/plane/result']
    assert [t for t, _ in results] == stamps
    for (bag_time, msg), result in zip(results, expected):
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == bag_time
        values = {kv.key: kv.value for kv in msg.status[0].values}
        assert values['state'] == result.state
        assert values['plane'] == ('true' if result.ok else 'false')
        h = json.loads(values['homography'])
        assert (np.array_equal(np.reshape(h, (3, 3)), result.homography) if result.ok
                else h == [])
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
