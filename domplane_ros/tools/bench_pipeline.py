"""Pipeline benchmark: every per-pair cost beside ORB + BF + MAGSAC++ on the same frames.

Run ``python -m domplane_ros.tools.bench_pipeline`` (or ``make bench``). One core (BLAS and OpenCV
pinned to one thread, :func:`~domplane_ros.tools.common.one_core`); the machine is named. Each
row times domplane_ros and the baseline (decode + ORB, 1000 features + brute-force Hamming
matching with cross-check + ``cv2.findHomography`` USAC_MAGSAC) on the same messages, pair by
pair interleaved, so a noisy machine slows both alike; ratios are ORB / ours. Rows:

* ``warm WxH``: decode + the whole ``PlanePipeline.process`` (features, tracking and
  prediction, warm-started estimate, verification, mask) on a rendered moving sequence at
  640x480, 1280x720 and 3840x2160 (the 4K frames are the 1280x720 renders upscaled 3x, bicubic,
  with the truth scaled: the renderer is too slow at 4K), with the median transfer error;
* ``of which tracker`` / ``of which mask`` / ``of which challenge``: those stages' own times
  in the same pairs (the challenge: the lock's challenge task of the pair, if any,
  :mod:`~domplane_ros.stream.challenge`; with how many pairs carried one over 2 ms);
* ``cold 640x480``: a fresh pipeline per pair (the whole prior search, the coarse candidates and
  the verification) on rendered scenes, with how many pairs published a plane on that first
  pair, how many of those are correct (< 1 px) and the precision (correct / published);
* ``lines (both)``: the warm 640x480 pair with ``features.kind: both`` beside ``points``
  (the ratio is both / points);
* end-to-end latency through DDS on loopback (image header stamp to the mask's arrival) with a
  publisher at 30 Hz into a live ``plane_node`` in this process, at 640x480 and 3840x2160;
  with ``--dds-process``, ``plane_node`` runs as a user starts it, in its own process on one
  core (``taskset -c 0``), the publisher here on the other (with the documented Fast DDS
  profile for large images, ``--fastdds-profile``), mono8 or rgb8 (``--encodings``).

``--breakdown`` prints instead where a warm pair's CPU time goes on the node's path, from the
serialised image messages to the serialised mask message, stage by stage.

Every pipeline and the node use the documented default configuration and prior (nothing is
set from a rendered scene's truth). A PNG bar chart of the medians (p95 as whiskers) is written
to ``--out``.
"""

from __future__ import annotations

import array
from dataclasses import dataclass, field, replace
import functools
import os
from pathlib import Path
import random
import subprocess
import sys
import time
from typing import Any, Callable

import cv2
from domplane_ros.config import FeatureConfig, PlaneNodeConfig, PriorConfig
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.image import message_to_gray
from domplane_ros.core.pyramid import working_level
from domplane_ros.sim.generators import random_scene, scene_sequence
from domplane_ros.sim.truth import every_floor_pixel
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.stream.session import LATENCY_WINDOW
from domplane_ros.tools.common import (add_output_argument, machine_name, mono8_message,
                                       one_core, ONE_THREAD_ENV, stop_process, tool_parser)
import numpy as np

_RENDER_LIMIT = (1280, 720)  # larger sizes are upscaled renders (the renderer is slow)
# The documented Fast DDS profile for large images (a 32 MB shared-memory segment).
_LARGE_IMAGES = str(Path(__file__).resolve().parents[2] / 'config' / 'fastdds_large_images.xml')


@dataclass
class BenchFrame:
    """One stereo pair as messages, with its truth in the pair's own pixels."""

    left: Any
    right: Any
    homography: np.ndarray
    floor: np.ndarray

    def error(self, h: np.ndarray | None) -> float:
        """Return the mean transfer error over the floor pixels (inf without H)."""
        if h is None:
            return float('inf')
        diff = apply_homography(h, self.floor) - apply_homography(self.homography, self.floor)
        return float(np.mean(np.linalg.norm(diff, axis=1)))


@dataclass
class Row:
    """One benchmark row: our times, the baseline's on the same pairs, errors, a note."""

    name: str
    ours: list[float] = field(default_factory=list)
    base: list[float] = field(default_factory=list)
    ours_err: list[float] = field(default_factory=list)
    base_err: list[float] = field(default_factory=list)
    note: str = ''
    base_name: str = 'ORB + BF + MAGSAC++'


def _bench_frames(frames: list, scale: int) -> list[BenchFrame]:
    out = []
    for f in frames:
        left, right, h = f.left, f.right, f.homography
        if scale != 1:
            size = (left.shape[1] * scale, left.shape[0] * scale)
            left = cv2.resize(left, size, interpolation=cv2.INTER_CUBIC)
            right = cv2.resize(right, size, interpolation=cv2.INTER_CUBIC)
            s = np.diag([scale, scale, 1.0])
            # Upscaling maps pixel centre x to scale x + (scale - 1) / 2.
            shift = np.array([[1.0, 0, (scale - 1) / 2], [0, 1.0, (scale - 1) / 2], [0, 0, 1]])
            to_big = shift @ s
            h = to_big @ h @ np.linalg.inv(to_big)
            floor = apply_homography(to_big, every_floor_pixel(f, 37))
        else:
            floor = every_floor_pixel(f, 37)
        out.append(BenchFrame(mono8_message(left), mono8_message(right), h, floor))
    return out


@functools.lru_cache(maxsize=4)
def _rendered(n_frames: int, seed: int, width: int, height: int) -> list:
    return scene_sequence(n_frames, seed, width=width, height=height, floor='random')


def sequence(width: int, height: int, n_frames: int, seed: int) -> tuple[list[BenchFrame], Any]:
    """Return a rendered moving sequence at ``width`` x ``height`` and its camera set-up."""
    scale = max(1, int(round(width / _RENDER_LIMIT[0])))
    frames = _rendered(n_frames, seed, width // scale, height // scale)
    return _bench_frames(frames, scale), frames[0].setup


def _decode(msg: Any) -> np.ndarray:
    """Decode an image message as the node's session does (read-only, uncopied if it can)."""
    gray = message_to_gray(msg, copy=False)
    gray.flags.writeable = False
    return gray


def orb_pair(orb: Any, matcher: Any, left_msg: Any, right_msg: Any) -> np.ndarray | None:
    """Return the baseline's homography for one pair of messages (decode included)."""
    left = message_to_gray(left_msg)
    right = message_to_gray(right_msg)
    kl, dl = orb.detectAndCompute(left, None)
    kr, dr = orb.detectAndCompute(right, None)
    if dl is None or dr is None or len(kl) < 4 or len(kr) < 4:
        return None
    matches = matcher.match(dl, dr)
    if len(matches) < 4:
        return None
    src = np.float32([kl[m.queryIdx].pt for m in matches])
    dst = np.float32([kr[m.trainIdx].pt for m in matches])
    h, _ = cv2.findHomography(src, dst, cv2.USAC_MAGSAC, 2.0)
    return h


def _orb() -> tuple[Any, Any]:
    return cv2.ORB_create(nfeatures=1000), cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)


def _timed(call: Callable[[], Any]) -> tuple[Any, float]:
    t = time.perf_counter()
    out = call()
    return out, time.perf_counter() - t


def bench_warm(width: int, height: int, n_frames: int, seed: int,
               config: PlaneNodeConfig | None = None) -> list[Row]:
    """Return the warm rows of one size: the whole pair, the tracker, the mask, the challenge."""
    frames, setup = sequence(width, height, n_frames, seed)
    config = config or PlaneNodeConfig()
    pipeline = PlanePipeline(config)
    orb, matcher = _orb()
    size = f'{width}x{height}'
    whole = Row(f'warm {size}')
    tracker = Row(f'  of which tracker {size}', base_name='')
    mask = Row(f'  of which mask {size}', base_name='')
    challenge = Row(f'  of which challenge {size}', base_name='')
    for i, frame in enumerate(frames):
        result, ours = _timed(lambda: pipeline.process(
            _decode(frame.left), _decode(frame.right), i * 33_000_000))
        h, base = _timed(lambda: orb_pair(orb, matcher, frame.left, frame.right))
        if i == 0:  # the first pair is the cold start
            continue
        whole.ours.append(ours)
        whole.base.append(base)
        whole.ours_err.append(frame.error(result.homography))
        whole.base_err.append(frame.error(h))
        tracker.ours.append(1e-3 * result.timings_ms['tracking'])
        mask.ours.append(1e-3 * result.timings_ms['mask'])
        challenge.ours.append(1e-3 * result.timings_ms['challenge'])
    features = config.features
    level = working_level(width, features.max_width, height, features.max_megapixels)
    whole.note = (f'working {-(-width >> level)}x{-(-height >> level)} (features.max_width '
                  f'{features.max_width}, max_megapixels {features.max_megapixels:g})')
    busy = sum(t > 0.002 for t in challenge.ours)
    challenge.note = f'a task over 2 ms in {busy} of {len(challenge.ours)} pairs'
    return [whole, tracker, mask, challenge]


def bench_cold(n_pairs: int, seed: int) -> Row:
    """Return the cold-start row: a fresh pipeline per rendered 640x480 pair."""
    orb, matcher = _orb()
    row = Row('cold 640x480 (first pair)')
    published = correct = 0
    for k in range(n_pairs):
        scene = random_scene(seed + k, floor='random')
        frame = _bench_frames([scene], 1)[0]
        pipeline = PlanePipeline(PlaneNodeConfig())
        result, ours = _timed(lambda: pipeline.process(
            _decode(frame.left), _decode(frame.right), 0))
        h, base = _timed(lambda: orb_pair(orb, matcher, frame.left, frame.right))
        row.ours.append(ours)
        row.base.append(base)
        err = frame.error(result.homography)
        row.ours_err.append(err)
        row.base_err.append(frame.error(h))
        published += result.homography is not None
        correct += err < 1.0
    precision = correct / published if published else float('nan')
    row.note = (f'published on the first pair {published}/{n_pairs}, correct (< 1 px) '
                f'{correct}/{n_pairs}, precision {precision:.2f}')
    return row


def bench_lines(n_frames: int, seed: int) -> Row:
    """Return the lines row: warm 640x480 with ``features.kind`` both beside points."""
    frames, setup = sequence(640, 480, n_frames, seed)
    base_config = PlaneNodeConfig()
    both_config = replace(base_config, features=replace(base_config.features, kind='both'))
    points, both = PlanePipeline(base_config), PlanePipeline(both_config)
    row = Row('warm 640x480 kind both', base_name='points only')
    for i, frame in enumerate(frames):
        left, right = _decode(frame.left), _decode(frame.right)
        res_both, t_both = _timed(lambda: both.process(left, right, i * 33_000_000))
        res_pts, t_pts = _timed(lambda: points.process(left, right, i * 33_000_000))
        if i:
            row.ours.append(t_both)
            row.base.append(t_pts)
            row.ours_err.append(frame.error(res_both.homography))
            row.base_err.append(frame.error(res_pts.homography))
    return row


def _stats(times: list[float]) -> tuple[float, float]:
    if not times:  # a row with nothing timed (--cold-pairs 0)
        return float('nan'), float('nan')
    ms = 1e3 * np.asarray(times)
    return float(np.median(ms)), float(np.percentile(ms, 95))


def _err(errs: list[float]) -> str:
    if not errs:
        return ''
    e = np.asarray(errs)
    return f'{np.median(e):7.3f} {100 * np.mean(e < 1.0):5.0f} %'


def print_row(row: Row) -> None:
    """Print one row: ours, the baseline, the ratio baseline / ours of the medians."""
    med, p95 = _stats(row.ours)
    line = f'{row.name:32s} {med:8.2f} {p95:8.2f} {_err(row.ours_err):>15s}'
    if row.base:
        bmed, bp95 = _stats(row.base)
        line += (f'   {row.base_name:20s} {bmed:8.2f} {bp95:8.2f} {_err(row.base_err):>15s}'
                 f'   x{bmed / med:5.2f}')
    print(line + (f'   {row.note}' if row.note else ''))


def bar_chart(rows: list[Row], path: Path, title: str) -> None:
    """Write a horizontal bar chart of the rows' medians (p95 as whiskers) to ``path``."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 0.55 * len(rows) + 1.5))
    y = np.arange(len(rows))
    ours = np.array([_stats(r.ours) for r in rows])
    base = np.array([_stats(r.base) if r.base else (np.nan, np.nan) for r in rows])
    ax.barh(y - 0.2, ours[:, 0], 0.4, xerr=[np.zeros(len(rows)), ours[:, 1] - ours[:, 0]],
            label='domplane_ros', color='tab:blue')
    ax.barh(y + 0.2, base[:, 0], 0.4, xerr=[np.zeros(len(rows)), base[:, 1] - base[:, 0]],
            label='baseline (ORB + BF + MAGSAC++; for kind both: points only)',
            color='tab:orange')
    ax.set_yticks(y, [r.name.strip() for r in rows])
    ax.invert_yaxis()
    ax.set_xscale('log')
    ax.set_xlabel('ms per pair, one core (bar: median, whisker: p95; log scale)')
    ax.set_title(title, fontsize=9)
    ax.legend(loc='upper center', bbox_to_anchor=(0.5, -0.12), ncol=2, fontsize=8)
    ax.grid(axis='x', which='both', alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
    from domplane_ros.stream import health, pipeline as pipeline_module, trust

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
    watch.wrap(pipeline_module, 'parallax_mask', '  mask on the working level')
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
            left, right = _decode(msgs[0]), _decode(msgs[1])
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


def _pair_rows(args: Any, machine: str) -> None:
    """Print the per-pair rows (warm, cold, lines) and write the bar chart."""
    print(f'{"row (domplane_ros)":32s} {"med ms":>8s} {"p95 ms":>8s} {"err px  <1px":>15s}   '
          f'{"baseline":20s} {"med ms":>8s} {"p95 ms":>8s} {"err px  <1px":>15s}   ratio')
    rows: list[Row] = []
    with one_core():
        for size in args.sizes.split(','):
            width, height = (int(v) for v in size.lower().split('x'))
            for row in bench_warm(width, height, args.frames, seed=5):
                print_row(row)
                rows.append(row)
        for row in (bench_cold(args.cold_pairs, seed=100), bench_lines(args.frames, seed=5)):
            print_row(row)
            rows.append(row)
    chart = args.out / 'bench_pipeline.png'
    bar_chart(rows, chart, machine)
    print(f'bar chart: {chart}')


def main(argv: list[str] | None = None) -> int:
    """Run the pipeline benchmark, print its rows and write the bar chart."""
    parser = tool_parser(__doc__)
    parser.add_argument('--frames', type=int, default=30, help='frames per warm sequence')
    parser.add_argument('--cold-pairs', type=int, default=10, help='rendered cold-start pairs')
    parser.add_argument('--sizes', default='640x480,1280x720,3840x2160',
                        help='comma-separated warm sizes WxH')
    parser.add_argument('--dds-seconds', type=float, default=10.0)
    parser.add_argument('--no-dds', action='store_true', help='skip the DDS measurement')
    parser.add_argument('--dds-process', action='store_true',
                        help='run plane_node in its own process (taskset -c 0; this process, '
                        'the publisher, on core 1) instead of in this process')
    parser.add_argument('--dds-sizes', default='640x480,3840x2160',
                        help='comma-separated DDS sizes WxH')
    parser.add_argument('--encodings', default='mono8',
                        help='comma-separated encodings of the DDS images (mono8, rgb8)')
    parser.add_argument('--fastdds-profile', default=_LARGE_IMAGES,
                        help="Fast DDS profile of both processes with --dds-process ('' for "
                        f'stock Fast DDS; default {_LARGE_IMAGES})')
    parser.add_argument('--breakdown', action='store_true',
                        help='only print where a warm pair goes on the node path, per --sizes')
    parser.add_argument('--only-dds', action='store_true', help='skip the per-pair rows')
    add_output_argument(parser, 'bench_output', 'the bar chart')
    args = parser.parse_args(argv)
    machine = machine_name()
    print(f'machine: {machine}')
    if args.breakdown:
        with one_core():
            for size in args.sizes.split(','):
                width, height = (int(v) for v in size.lower().split('x'))
                bench_breakdown(width, height, args.frames, seed=5)
        return 0
    if not args.only_dds:
        _pair_rows(args, machine)
    if args.no_dds:
        return 0
    for size in args.dds_sizes.split(','):
        width, height = (int(v) for v in size.lower().split('x'))
        for encoding in args.encodings.split(','):
            if args.dds_process:
                bench_dds_process(args.dds_seconds, 30.0, width, height, encoding,
                                  args.fastdds_profile)
            else:
                with one_core():
                    bench_dds(args.dds_seconds, 30.0, width, height, encoding)
    return 0


if __name__ == '__main__':
    sys.exit(main())
