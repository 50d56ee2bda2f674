"""The live benchmarks: latency through DDS into plane_node, and where a pair's time goes.

Called by :mod:`~domplane_ros.tools.bench_pipeline` (its ``--dds-process``, ``--only-dds``
and ``--breakdown`` options; see its docstring): :func:`bench_dds` (the node in this process),
:func:`bench_dds_process` (the node in its own process on one core, the publisher here on the
other) and :func:`bench_breakdown` (the node's path, message in to mask out, stage by stage).
"""

from __future__ import annotations

import array
from dataclasses import dataclass, field
import os
from pathlib import Path
import random
import subprocess
import sys
import time
from typing import Any, Callable

import cv2
from domplane_ros.config import FeatureConfig, PlaneNodeConfig, PriorConfig
from domplane_ros.core.image import message_to_gray
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.session import LATENCY_WINDOW
from domplane_ros.tools.bench_frames import decode, sequence
from domplane_ros.tools.common import ONE_THREAD_ENV, stop_process
import numpy as np

# The documented Fast DDS profile for large images (a 32 MB shared-memory segment).
LARGE_IMAGES = str(Path(__file__).resolve().parents[2] / 'config' / 'fastdds_large_images.xml')


def _plane_node(prior: PriorConfig, features: FeatureConfig) -> Any:
    """Return a live plane_node with ``prior``, in this process (rclpy initialised)."""
    from rclpy.parameter import Parameter

    from domplane_ros.ros.node import PlaneNode

    return PlaneNode(parameter_overrides=[
        Parameter('prior.focal_px', value=list(prior.focal_px)),
        Parameter('prior.baseline_over_height', value=list(prior.baseline_over_height)),
        Parameter('prior.tilt_deg', value=list(prior.tilt_deg)),
        Parameter('prior.vergence_deg', value=list(prior.vergence_deg)),
        Parameter('features.max_width', value=features.max_width),
        Parameter('features.max_megapixels', value=features.max_megapixels)])


def _spin_until(executor: Any, done: Callable[[], bool], timeout_s: float,
                step_s: float) -> None:
    """Spin ``executor`` until ``done()`` or ``timeout_s`` seconds have passed."""
    deadline = time.monotonic() + timeout_s
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=step_s)


def bench_dds(seconds: float, rate_hz: float, width: int, height: int,
              encoding: str = 'mono8') -> None:
    """Print image-stamp-to-mask-arrival latency through DDS with a ``rate_hz`` publisher.

    The publisher and ``plane_node`` run in this process, on one executor.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from domplane_ros.ros.messages import image_msg, stamped_header

    frames, setup = sequence(width, height, 10, 11)
    images = [tuple(gray if encoding == 'mono8' else cv2.cvtColor(gray, cv2.COLOR_GRAY2RGB)
                    for gray in (message_to_gray(f.left), message_to_gray(f.right)))
              for f in frames]
    rclpy.init()
    node = _plane_node(PriorConfig(), FeatureConfig())
    driver = rclpy.create_node('bench_driver')
    pubs = [driver.create_publisher(Image, f'{side}/image_raw', qos_profile_sensor_data)
            for side in ('left', 'right')]
    latencies: list[float] = []
    sent = [0]
    driver.create_subscription(Image, 'plane/mask', lambda msg: latencies.append(
        time.time() - (msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)), 50)

    def tick() -> None:
        pair = images[sent[0] % len(images)]
        now_ns = time.time_ns()
        for pub, gray, side in zip(pubs, pair, ('left', 'right')):
            pub.publish(image_msg(gray, stamped_header(now_ns, side), encoding))
        sent[0] += 1

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    executor.add_node(driver)
    _spin_until(executor, lambda: pubs[0].get_subscription_count() > 0, 3.0, 0.05)
    driver.create_timer(1.0 / rate_hz, tick)
    _spin_until(executor, lambda: False, seconds, 0.005)
    processed = node.session.counters.processed
    busy = node.slot.dropped
    executor.shutdown()
    node.destroy_node()
    driver.destroy_node()
    rclpy.shutdown()
    lat = 1e3 * np.asarray(latencies[5:] or [float('nan')])
    print(f'DDS end to end, {width}x{height} {encoding} at {rate_hz:g} Hz for {seconds:g} s: sent '
          f'{sent[0]} pairs, masks received {len(latencies)}, processed {processed}, dropped '
          f'while busy {busy}; stamp -> mask arrival: median {np.median(lat):.1f} ms, '
          f'p95 {np.percentile(lat, 95):.1f} ms')


# --- The live node in its own process (--dds-process) -------------------------------------

@dataclass
class LiveRun:
    """What the driver saw of one live run: sends, mask arrivals, the node's diagnostics."""

    sent_at: list[float] = field(default_factory=list)
    latencies_ms: list[float] = field(default_factory=list)
    homographies: int = 0
    diagnostics: list[dict[str, str]] = field(default_factory=list)

    taken_late_ms: list[float] = field(default_factory=list)

    def on_mask(self, msg: Any, info: dict[str, int]) -> None:
        """Record a mask's latency: its image stamp to its arrival here, wall clock.

        The arrival is when the middleware received it (``received_timestamp``), so a
        publisher busy publishing does not add its own delay; how much later the callback
        ran is kept in :attr:`taken_late_ms`.
        """
        now = time.time_ns()
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        received = info.get('received_timestamp') or now
        self.latencies_ms.append(1e-6 * (received - stamp))
        self.taken_late_ms.append(1e-6 * (now - received))

    def on_diagnostics(self, msg: Any) -> None:
        """Keep the node's status values."""
        self.diagnostics.append({kv.key: kv.value for kv in msg.status[0].values})

    def count(self, key: str, base: dict[str, str]) -> int:
        """Return how much the node's counter ``key`` grew since ``base``."""
        last = self.diagnostics[-1] if self.diagnostics else {}
        return int(last.get(key, 0)) - int(base.get(key, 0))


def _image_messages(width: int, height: int, encoding: str, n_frames: int = 10,
                    seed: int = 11) -> list[tuple[Any, Any]]:
    """Return a bench sequence's pairs as rclpy Image messages (built once, restamped)."""
    from sensor_msgs.msg import Image

    frames, _ = sequence(width, height, n_frames, seed)
    pairs = []
    for frame in frames:
        pair = []
        for side, msg in (('left', frame.left), ('right', frame.right)):
            gray = message_to_gray(msg)
            image = gray if encoding == 'mono8' else cv2.cvtColor(gray, cv2.COLOR_GRAY2RGB)
            out = Image(height=height, width=width, encoding=encoding, is_bigendian=0,
                        step=image.strides[0])
            out.header.frame_id = f'{side}_cam'
            out.data = array.array('B', image.tobytes())
            pair.append(out)
        pairs.append(tuple(pair))
    return pairs


def _cpu_seconds(pid: int, tid: int | None = None) -> float:
    """Return the CPU seconds (user + system) a process (or its thread) has used (Linux)."""
    path = f'/proc/{pid}/stat' if tid is None else f'/proc/{pid}/task/{tid}/stat'
    with open(path, encoding='ascii', errors='replace') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def _thread_cpu(pid: int) -> dict[tuple[int, str], float]:
    """Return the CPU seconds of each thread of a process, keyed by (id, name) (Linux)."""
    out = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            with open(f'/proc/{pid}/task/{tid}/comm', encoding='ascii',
                      errors='replace') as stream:
                name = stream.read().strip()
            out[(int(tid), name)] = _cpu_seconds(pid, int(tid))
        except OSError:
            continue  # the thread ended
    return out


def _thread_shares(before: dict[tuple[int, str], float], after: dict[tuple[int, str], float],
                   seconds: float) -> str:
    """Return the busiest threads' shares of a core between two :func:`_thread_cpu` calls."""
    used = sorted(((after[key] - before.get(key, 0.0)) / seconds, key) for key in after)
    return ', '.join(f'{name} ({tid}) {100 * share:.0f} %'
                     for share, (tid, name) in reversed(used[-4:]) if share >= 0.01)


def bench_dds_process(seconds: float, rate_hz: float, width: int, height: int,
                      encoding: str = 'mono8', profile: str = '',
                      cores: tuple[int, int] = (0, 1)) -> None:
    """Print stamp-to-mask latency with ``plane_node`` in its own process on one core.

    The node runs as a user starts it (``python -m domplane_ros.ros.node``, documented
    defaults) under ``taskset -c cores[0]`` with one OpenCV and BLAS thread; this process,
    pinned to ``cores[1]``, publishes pre-built pairs with wall-clock stamps at ``rate_hz``
    (its own achieved rate is printed) and receives the masks and ``/diagnostics``. Both
    use the Fast DDS ``profile`` (an XML file; '' for stock Fast DDS, whose 512 KB
    shared-memory segment sends large images as fragmented best-effort UDP, docs/BENCHMARKS.md).
    """
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image
    from std_msgs.msg import Float64MultiArray

    pairs = _image_messages(width, height, encoding)
    dds = {'ROS_DOMAIN_ID': str(random.randint(101, 200)),
           'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    for name in ('FASTDDS_DEFAULT_PROFILES_FILE', 'FASTRTPS_DEFAULT_PROFILES_FILE'):
        dds[name] = str(Path(profile).resolve()) if profile else ''
    os.environ.update(dds)
    node_share, threads = float('nan'), ''
    node_proc = subprocess.Popen(
        ['taskset', '-c', str(cores[0]), sys.executable, '-m', 'domplane_ros.ros.node',
         '--ros-args', '-p', 'diagnostics.period_s:=1.0', '--log-level', 'warn'],
        env=dict(os.environ, **ONE_THREAD_ENV))
    affinity = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {cores[1]})
    rclpy.init()
    driver = rclpy.create_node('bench_live_driver')
    run = LiveRun()
    pubs = [driver.create_publisher(Image, f'{side}/image_raw', qos_profile_sensor_data)
            for side in ('left', 'right')]
    driver.create_subscription(Image, 'plane/mask', run.on_mask, 50)
    driver.create_subscription(DiagnosticArray, '/diagnostics', run.on_diagnostics, 50)
    driver.create_subscription(Float64MultiArray, 'plane/homography',
                               lambda msg: setattr(run, 'homographies', run.homographies + 1),
                               50)
    executor = SingleThreadedExecutor()
    executor.add_node(driver)

    def publish(pair: tuple[Any, Any]) -> None:
        stamp = time.time_ns()
        for pub, msg in zip(pubs, pair):
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            pub.publish(msg)
        run.sent_at.append(time.monotonic())

    def spin_until(deadline: float, done: Callable[[], bool] = lambda: False) -> None:
        # At least one callback each time, also when publishing is late (else a late
        # publisher would leave the masks waiting, and count its own delay as latency).
        while True:
            executor.spin_once(timeout_sec=max(0.0, min(0.002, deadline - time.monotonic())))
            if done() or time.monotonic() >= deadline:
                return

    try:
        spin_until(time.monotonic() + 60.0, lambda: all(
            p.get_subscription_count() for p in pubs) and driver.count_publishers(
                '/diagnostics') > 0)
        warm_deadline = time.monotonic() + 60.0
        while not run.homographies and time.monotonic() < warm_deadline:
            publish(pairs[0])   # slowly, until the node has its plane
            spin_until(time.monotonic() + 0.5, lambda: run.homographies > 0)
        spin_until(time.monotonic() + 3.0)
        base = dict(run.diagnostics[-1]) if run.diagnostics else {}
        run.latencies_ms.clear()
        run.taken_late_ms.clear()
        run.sent_at.clear()
        cpu_before, threads_before = _cpu_seconds(node_proc.pid), _thread_cpu(node_proc.pid)
        start = time.monotonic()
        while time.monotonic() - start < seconds:
            publish(pairs[len(run.sent_at) % len(pairs)])
            spin_until(start + len(run.sent_at) / rate_hz)
        node_share = (_cpu_seconds(node_proc.pid) - cpu_before) / (time.monotonic() - start)
        threads = _thread_shares(threads_before, _thread_cpu(node_proc.pid),
                                 time.monotonic() - start)
        spin_until(time.monotonic() + 2.5)
    finally:
        executor.shutdown()
        driver.destroy_node()
        rclpy.try_shutdown()
        os.sched_setaffinity(0, affinity)
        stop_process(node_proc)
    sent = len(run.sent_at)
    rate = (sent - 1) / max(run.sent_at[-1] - run.sent_at[0], 1e-9) if sent > 1 else 0.0
    lat = np.asarray(run.latencies_ms or [float('nan')])
    last = run.diagnostics[-1] if run.diagnostics else {}
    median = last.get('processing latency median [ms]', '?')
    p95 = last.get('processing latency p95 [ms]', '?')
    print(f'DDS, node in its own process (taskset -c {cores[0]}), Fast DDS profile '
          f'{profile or "stock"}, {width}x{height} {encoding} at {rate_hz:g} Hz for '
          f'{seconds:g} s: sent {sent} pairs (publisher, taskset -c {cores[1]}: {rate:.1f} '
          f'Hz), node made {run.count("pairs", base)} pairs, processed '
          f'{run.count("processed pairs", base)}, dropped while busy '
          f'{run.count("dropped pairs (busy)", base)}, dropped by the sync '
          f'{run.count("dropped frames (sync)", base)}; masks received {len(run.latencies_ms)}; '
          f'stamp -> mask arrival median {np.median(lat):.1f} ms, p95 '
          f'{np.percentile(lat, 95):.1f} ms, max {np.max(lat):.1f} ms (taken here a median '
          f'{np.median(run.taken_late_ms or [float("nan")]):.1f} ms later); in the node '
          f'(decode to publish, its last {LATENCY_WINDOW} pairs) median {median} ms, p95 '
          f'{p95} ms; the node used {100 * node_share:.0f} % of a core (threads: {threads})')


# --- Where a pair's time goes (--breakdown) -----------------------------------------------

class _Stopwatch:
    """Time calls of named functions, patched in for a measurement and restored after."""

    def __init__(self) -> None:
        self.spent: dict[str, float] = {}
        self._patched: list[tuple[Any, str, Any]] = []

    def wrap(self, owner: Any, name: str, label: str, static: bool = False) -> None:
        """Time every call of ``owner.name`` under ``label`` (``static``: keep it unbound)."""
        original = getattr(owner, name)
        raw = owner.__dict__[name] if isinstance(owner, type) else original

        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.process_time()
            try:
                return original(*args, **kwargs)
            finally:
                self.spent[label] = self.spent.get(label, 0.0) + time.process_time() - start

        self._patched.append((owner, name, raw))
        setattr(owner, name, staticmethod(timed) if static else timed)

    def restore(self) -> None:
        """Put every patched function back."""
        for owner, name, raw in reversed(self._patched):
            setattr(owner, name, raw)
        self._patched.clear()

    def take(self) -> dict[str, float]:
        """Return the milliseconds per label since the last take, and start again."""
        out = {label: 1e3 * seconds for label, seconds in self.spent.items()}
        self.spent = {}
        return out


def bench_breakdown(width: int, height: int, n_frames: int, seed: int) -> None:
    """Print where a warm pair's time goes on the node's path, message in to mask out.

    The node's steps on one core in this process, each pair's parts timed in CPU time
    (``process_time``, steadier than wall time on a shared machine; the median over the warm
    pairs): the serialised image messages read (:mod:`domplane_ros.ros.wire`, as the node's
    raw subscription does; rclpy's deserialisation timed beside it), decoded to numpy, the
    pipeline's stages, the mask message built and serialised (as its publisher does). Parts
    inside others are indented.
    """
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Image

    from domplane_ros.core import pyramid
    from domplane_ros.ros.messages import image_msg, stamped_header
    from domplane_ros.ros.wire import image_from_cdr
    from domplane_ros.stream import detection, health, pipeline as pipeline_module, trust

    pairs = _image_messages(width, height, 'mono8', n_frames, seed)
    wire = [tuple(serialize_message(msg) for msg in pair) for pair in pairs]
    watch = _Stopwatch()
    watch.wrap(health.PairChecks, 'check', 'input checks')
    watch.wrap(pyramid.WorkingImage, 'of', 'pyramid to the working level', static=True)
    watch.wrap(PlanePipeline, '_features', 'features + tracking (on the level)')
    watch.wrap(PlanePipeline, '_estimate', 'estimate, verification, challenge')
    watch.wrap(trust, 'working_pair', '  verification shrink')
    watch.wrap(trust, 'verify_plane', '  verifications (the shrink apart)')
    watch.wrap(PlanePipeline, '_challenge_step', '  the challenge (verifications incl.)')
    watch.wrap(PlanePipeline, '_publish', 'mask incl. upscale')
    watch.wrap(detection, 'parallax_mask', '  mask on the working level')
    watch.wrap(pipeline_module, 'full_mask', '  mask upscale to full size')
    node_pipeline = PlanePipeline(PlaneNodeConfig())
    rows: dict[str, list[float]] = {}
    try:
        for i in range(n_frames):
            data = wire[i]
            before = time.process_time()
            for raw in data:
                deserialize_message(raw, Image)
            t0 = time.process_time()
            msgs = [image_from_cdr(raw) for raw in data]
            t1 = time.process_time()
            left, right = decode(msgs[0]), decode(msgs[1])
            t2 = time.process_time()
            result = node_pipeline.process(left, right, (i + 1) * 33_000_000)
            t3 = time.process_time()
            serialize_message(image_msg(result.mask, stamped_header(i, 'left'), 'mono8'))
            t4 = time.process_time()
            parts = {'(rclpy deserialising both, not done)': 1e3 * (t0 - before),
                     'read both in place (ros/wire.py)': 1e3 * (t1 - t0),
                     'message -> numpy (both)': 1e3 * (t2 - t1),
                     **watch.take(),
                     'pipeline (whole)': 1e3 * (t3 - t2),
                     'mask message build + serialise': 1e3 * (t4 - t3),
                     'message in to mask out': 1e3 * (t4 - t0)}
            if i > 1:  # warm pairs only
                for label, ms in parts.items():
                    rows.setdefault(label, []).append(ms)
    finally:
        watch.restore()
    print(f'where a warm {width}x{height} pair goes ({n_frames - 2} warm pairs, ms):')
    print(f'{"part":44s} {"median":>8s} {"p95":>8s}')
    order = ['(rclpy deserialising both, not done)', 'read both in place (ros/wire.py)',
             'message -> numpy (both)', 'input checks', 'pyramid to the working level',
             'features + tracking (on the level)', 'estimate, verification, challenge',
             '  verification shrink', '  verifications (the shrink apart)',
             '  the challenge (verifications incl.)', 'mask incl. upscale',
             '  mask on the working level', '  mask upscale to full size', 'pipeline (whole)',
             'mask message build + serialise', 'message in to mask out']
    for label in sorted(rows, key=lambda name: order.index(name) if name in order else 99):
        values = rows[label]
        print(f'{label:44s} {np.median(values):8.2f} {np.percentile(values, 95):8.2f}')
