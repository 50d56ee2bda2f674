"""The launch file, and plane_node's command line as a user meets it (subprocesses over DDS).

``launch`` / ``launch_ros`` are not on PyPI, so where they are missing the launch file is
parsed and the node is started with the ``--ros-args`` that launch_ros's ``Node`` action
gives it (``-r __node:=``, ``-r __ns:=``, one ``--params-file`` per parameters entry, a dict
written as a ``/**`` file, ``-r from:=to`` per remapping).
"""

from __future__ import annotations

import ast
import importlib.util
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from domplane_ros.config import PARAMETERS
from domplane_ros.core.homography import apply_homography
from domplane_ros.sim.generators import random_scene
import numpy as np
from rcl_interfaces.srv import GetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage, Image
import yaml

ROOT = Path(__file__).resolve().parents[2]
LAUNCH_FILE = ROOT / 'launch' / 'plane_node.launch.py'
NODE = [sys.executable, '-m', 'domplane_ros.ros.node']
REPLAY = [sys.executable, '-m', 'domplane_ros.replay.cli']
EXPECTED_ARGUMENTS = {'params_file', 'namespace', 'node_name', 'left_image', 'right_image',
                      'image_transport'}


def _launch_importable() -> bool:
    try:
        return all(importlib.util.find_spec(name) is not None
                   for name in ('launch', 'launch_ros'))
    except (ImportError, ValueError):
        return False


def parsed_launch_file() -> tuple[dict[str, object], dict[str, object]]:
    """Return the launch file's arguments (name to default) and its Node call's fields.

    Node fields: ``package``, ``executable``, ``remap_from`` (the remapped names, in order)
    and ``parameter_dict_keys`` (the keys of dict entries in ``parameters``).
    """
    tree = ast.parse(LAUNCH_FILE.read_text(encoding='utf-8'))
    arguments: dict[str, object] = {}
    node: dict[str, object] = {}
    for item in ast.walk(tree):
        if isinstance(item, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == 'ARGUMENTS' for t in item.targets):
            arguments = {name: default for name, default, _ in ast.literal_eval(item.value)}
        if isinstance(item, ast.Call) and getattr(item.func, 'id', '') == 'Node':
            fields = {kw.arg: kw.value for kw in item.keywords}
            node['package'] = ast.literal_eval(fields['package']) \
                if isinstance(fields['package'], ast.Constant) else 'domplane_ros'
            node['executable'] = ast.literal_eval(fields['executable'])
            node['remap_from'] = [ast.literal_eval(pair.elts[0])
                                  for pair in fields['remappings'].elts]
            node['parameter_dict_keys'] = [ast.literal_eval(key)
                                           for entry in fields['parameters'].elts
                                           if isinstance(entry, ast.Dict)
                                           for key in entry.keys]
    return arguments, node


def test_launch_file_declares_the_arguments_and_starts_plane_node():
    arguments, node = parsed_launch_file()
    assert set(arguments) == EXPECTED_ARGUMENTS
    assert arguments['node_name'] == 'plane_node' and arguments['image_transport'] == 'raw'
    assert node['executable'] == 'plane_node'
    assert node['remap_from'] == ['left/image_raw', 'right/image_raw']
    assert node['parameter_dict_keys'] == ['image_transport']
    assert (ROOT / 'config' / 'plane_node.yaml').is_file()  # the params_file default
    if _launch_importable():
        from launch.actions import DeclareLaunchArgument

        spec = importlib.util.spec_from_file_location('plane_node_launch', LAUNCH_FILE)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        description = module.generate_launch_description()
        declared = {e.name for e in description.entities if isinstance(e, DeclareLaunchArgument)}
        assert declared == EXPECTED_ARGUMENTS


def launch_ros_arguments(values: dict[str, str], tmp_path: Path) -> list[str]:
    """Return the ``--ros-args`` that the launch file's Node action gives plane_node."""
    _, node = parsed_launch_file()
    dict_file = tmp_path / 'launch_params.yaml'
    dict_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        key: values[key] for key in node['parameter_dict_keys']}}}), encoding='utf-8')
    namespace = values['namespace'] if values['namespace'].startswith('/') \
        else '/' + values['namespace']
    remaps = dict(zip(node['remap_from'], (values['left_image'], values['right_image'])))
    args = ['--ros-args', '-r', f'__node:={values["node_name"]}', '-r', f'__ns:={namespace}',
            '--params-file', values['params_file'], '--params-file', str(dict_file)]
    for source, target in remaps.items():
        args += ['-r', f'{source}:={target}']
    return args


def _png(gray: np.ndarray, stamp_ns: int, frame_id: str) -> CompressedImage:
    msg = CompressedImage()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = frame_id
    msg.format = 'png'
    msg.data = cv2.imencode('.png', gray)[1].tobytes()
    return msg


def _spin_until(executor, predicate, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if predicate():
            return
    raise AssertionError('timed out')


def test_node_started_as_the_launch_file_does_publishes_under_its_name(
        ros_context, tmp_path, ros_domain_id):
    scene = random_scene(7, floor='random', n_boxes=3, gain=1.15, offset=-10.0)
    # The shipped file (the documented default prior) with one value changed, to show it
    # reached the renamed node.
    document = yaml.safe_load((ROOT / 'config' / 'plane_node.yaml').read_text(encoding='utf-8'))
    document['/**']['ros__parameters']['features.max_points'] = 123
    params_file = tmp_path / 'front.yaml'
    params_file.write_text(yaml.safe_dump(document), encoding='utf-8')
    values = {'params_file': str(params_file), 'namespace': 'robot', 'node_name': 'front_plane',
              'left_image': '/stereo/left/image_raw', 'right_image': '/stereo/right/image_raw',
              'image_transport': 'compressed'}
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain_id))
    proc = subprocess.Popen(NODE + launch_ros_arguments(values, tmp_path), env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    driver = Node('launch_driver', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(driver)
    try:
        pub_left = driver.create_publisher(CompressedImage, '/stereo/left/image_raw/compressed',
                                           qos_profile_sensor_data)
        pub_right = driver.create_publisher(CompressedImage,
                                            '/stereo/right/image_raw/compressed',
                                            qos_profile_sensor_data)
        results: list[DiagnosticArray] = []
        masks: list[Image] = []
        driver.create_subscription(DiagnosticArray, '/robot/plane/result', results.append, 20)
        driver.create_subscription(Image, '/robot/plane/mask', masks.append, 20)
        _spin_until(executor, lambda: pub_left.get_subscription_count()
                    and pub_right.get_subscription_count()
                    and driver.count_publishers('/robot/plane/result'), 30.0)
        stamp = 5_000_000_000

        def plane_found():
            nonlocal stamp
            pub_left.publish(_png(scene.left, stamp, 'left_cam'))
            pub_right.publish(_png(scene.right, stamp, 'right_cam'))
            stamp += 100_000_000
            return any(kv.key == 'plane' and kv.value == 'true'
                       for r in results for kv in r.status[0].values)

        _spin_until(executor, plane_found, 30.0)
        last = next(r for r in reversed(results)
                    if {kv.key: kv.value for kv in r.status[0].values}['plane'] == 'true')
        assert last.status[0].hardware_id == '/robot/front_plane'
        h = np.array(json.loads({kv.key: kv.value for kv in last.status[0].values}[
            'homography'])).reshape(3, 3)
        px = np.argwhere(scene.plane_left & scene.visible_in_right)[:, ::-1].astype(float)
        err = np.linalg.norm(apply_homography(h, px) - apply_homography(scene.homography, px),
                             axis=1)
        assert err.mean() < 1.0
        _spin_until(executor, lambda: any(m.header.stamp == last.header.stamp for m in masks),
                    5.0)

        client = driver.create_client(GetParameters, '/robot/front_plane/get_parameters')
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(GetParameters.Request(
            names=['features.max_points', 'image_transport']))
        _spin_until(executor, future.done, 10.0)
        got = future.result().values
        assert (got[0].integer_value, got[1].string_value) == (123, 'compressed')
    finally:
        executor.shutdown()
        driver.destroy_node()
        proc.send_signal(signal.SIGINT)
        try:
            proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0


def test_help_prints_usage_and_parameters_without_starting_a_node(tmp_path, ros_domain_id):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain_id))
    typo_file = tmp_path / 'typo.yaml'
    typo_file.write_text('/**:\n  ros__parameters:\n    estimator.threshhold_px: 2.0\n')
    cases = {
        'help': (NODE + ['--help'], 0, None),
        '-p typo': (NODE + ['--ros-args', '-p', 'prior.focal:=[500.0, 600.0]'], 2,
                    "unknown parameter 'prior.focal' (did you mean 'prior.focal_px'?)"),
        'file typo': (NODE + ['--ros-args', '--params-file', str(typo_file)], 2,
                      "(did you mean 'estimator.threshold_px'?)"),
        'replay file typo': (REPLAY + [str(tmp_path / 'in'), str(tmp_path / 'out'),
                                       '--params-file', str(typo_file)], 2,
                             "(did you mean 'estimator.threshold_px'?)"),
    }
    procs = {name: subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, text=True)
             for name, (cmd, _, _) in cases.items()}
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=60)
        _, code, needle = cases[name]
        assert proc.returncode == code, (name, err)
        if needle is None:
            assert out.startswith('usage: plane_node')
            listed = {line.split(' = ')[0].strip() for line in out.splitlines()
                      if line.startswith('  ') and ' = ' in line}
            assert listed == {spec.name for spec in PARAMETERS}
            assert err == ''  # no node was started: it would log 'plane_node ready'
        else:
            lines = [line for line in err.splitlines() if line.strip()]
            assert len(lines) == 1 and needle in lines[0], (name, err)
