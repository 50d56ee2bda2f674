"""Load test: both cameras at 100 Hz into plane_node over DDS on loopback, for 60 s.

plane_node runs in its own process (started here, ``python -m domplane_ros.ros.node``), this
process publishes pre-rendered stereo pairs (``sim.generators``; a head standing still, each pair
with its own pixel noise, so every homography can be checked against the one true plane
without matching it to a frame: ``plane/homography`` carries no stamp) with wall-clock stamps
at ``--rate`` Hz, and listens to ``plane/mask``,
``plane/homography`` and ``/diagnostics``. Processing a 1280x720 pair takes about 20 ms, so the
node cannot keep up with 100 Hz: it must drop pairs (and count them), keep its queues bounded,
keep the latency bounded and its memory flat. Printed per ``--window`` seconds and in total:
pairs sent, processed and dropped (from /diagnostics), stamp-to-mask-arrival latency
median/p95/max, the node's RSS (and peak), and the homography error against the renderer's
truth. Run::

    python -m domplane_ros.tools.load_test            # 60 s, 100 Hz, 1280x720
    python -m domplane_ros.tools.load_test --duration 10 --width 640 --height 480
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
import random
import subprocess
import sys
import tempfile
import time
from types import SimpleNamespace
from typing import Any, Sequence

from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.model import StereoFrame
from domplane_ros.sim.truth import every_floor_pixel, transfer_error_px
from domplane_ros.tools.common import (add_size_arguments, machine_name, ONE_THREAD_ENV,
                                       rss_mb, stop_process, tool_parser)
import numpy as np


def _params_file(frame: StereoFrame, directory: str, period_s: float, slop_s: float,
                 depth: int) -> str:
    # The documented default prior: nothing set from the rendered set-up's truth.
    del frame
    text = ('/**:\n  ros__parameters:\n'
            f'    diagnostics.period_s: {period_s}\n'
            # Stamps 10 ms apart at 100 Hz: a slop below half the period, so a frame whose
            # partner was lost is never paired with the next frame's partner.
            f'    sync.slop_s: {slop_s}\n'
            f'    qos.depth: {depth}\n')
    path = Path(directory) / 'plane_node.yaml'
    path.write_text(text, encoding='utf-8')
    return str(path)


def _transfer_error_px(h: np.ndarray, frame: StereoFrame) -> float:
    return transfer_error_px(h, frame, every_floor_pixel(frame, 7))


class _Window:
    """Pairs sent and masks received in one report window."""

    def __init__(self) -> None:
        self.sent = 0
        self.latency_ms: list[float] = []


def _fmt_latency(values: list[float]) -> str:
    if not values:
        return 'median    n/a, p95    n/a, max    n/a'
    arr = np.asarray(values)
    return (f'median {np.median(arr):6.1f}, p95 {np.percentile(arr, 95):6.1f}, '
            f'max {arr.max():6.1f}')


def _ros() -> SimpleNamespace:
    """Import rclpy and the message types (only when the load test runs)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import Image
    from std_msgs.msg import Float64MultiArray

    return SimpleNamespace(rclpy=rclpy, executor_cls=SingleThreadedExecutor,
                           sensor_qos=qos_profile_sensor_data, diagnostic_cls=DiagnosticArray,
                           image_cls=Image, array_cls=Float64MultiArray)


def _dds_env(args: argparse.Namespace) -> dict[str, str]:
    """Return the DDS variables shared by both processes: domain, loopback, Fast DDS profile."""
    domain_id = args.domain_id if args.domain_id is not None else random.randint(101, 200)
    dds = {'ROS_DOMAIN_ID': str(domain_id), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    if args.fastdds_profile:
        profile = str(Path(args.fastdds_profile).resolve())
        dds.update(FASTDDS_DEFAULT_PROFILES_FILE=profile, FASTRTPS_DEFAULT_PROFILES_FILE=profile)
    print('Fast DDS profile: ' + (dds.get('FASTDDS_DEFAULT_PROFILES_FILE')
                                  or os.environ.get('FASTDDS_DEFAULT_PROFILES_FILE', 'default')))
    return dds


def run(args: argparse.Namespace) -> int:
    """Run the load test and print its figures; return the exit code."""
    ros = _ros()
    print(f'machine: {machine_name()}')
    print(f'rendering {args.frames} stereo pairs {args.width}x{args.height} ...', flush=True)
    frames = scene_sequence(args.frames, seed=args.seed, width=args.width, height=args.height,
                            floor='random', n_boxes=3, step=0.0, yaw_rate_deg=0.0,
                            tilt_jitter_deg=0.0, vergence_jitter_deg=0.0)
    dds = _dds_env(args)
    env = dict(os.environ, **dds, **ONE_THREAD_ENV)
    os.environ.update(dds)
    with tempfile.TemporaryDirectory(prefix='domplane_load_') as tmp:
        params = _params_file(frames[0], tmp, args.diagnostics_period, 0.4 / args.rate,
                              args.qos_depth)
        node_proc = subprocess.Popen(
            [sys.executable, '-m', 'domplane_ros.ros.node', '--ros-args', '--params-file', params,
             '--log-level', 'warn'], env=env)
        try:
            return _drive(args, frames, node_proc, ros)
        finally:
            stop_process(node_proc)


class _LoadDriver:
    """The publishing side: a driver node, pre-built messages, and what comes back.

    It publishes the pairs with wall-clock stamps and records the masks (stamp, plane found,
    latency per report window), the homographies (with their arrival time) and the node's
    diagnostics (with theirs).
    """

    def __init__(self, frames: Sequence[StereoFrame], ros: SimpleNamespace) -> None:
        """Create the driver node, its publishers and subscriptions, and the messages."""
        self.rclpy = ros.rclpy
        self.rclpy.init()
        self.node = self.rclpy.create_node('load_test_driver')
        self.pubs = {side: self.node.create_publisher(ros.image_cls, f'{side}/image_raw',
                                                      ros.sensor_qos)
                     for side in ('left', 'right')}
        self.messages = [{side: self._image(ros.image_cls, side, gray)
                          for side, gray in (('left', f.left), ('right', f.right))}
                         for f in frames]
        self.windows: list[_Window] = []
        self.masks: list[tuple[int, bool]] = []      # (stamp, plane found) in arrival order
        self.homographies: list[np.ndarray] = []
        self.h_times: list[float] = []
        self.diagnostics: list[dict[str, str]] = []
        self.clock0 = time.monotonic()               # start of the load, for arrival times
        self.node.create_subscription(ros.image_cls, 'plane/mask', self._on_mask, 50)
        self.node.create_subscription(ros.array_cls, 'plane/homography', self._on_homography,
                                      50)
        self.node.create_subscription(ros.diagnostic_cls, '/diagnostics', self._on_diag, 50)
        self.executor = ros.executor_cls()
        self.executor.add_node(self.node)

    @staticmethod
    def _image(image_cls: Any, side: str, gray: np.ndarray) -> Any:
        msg = image_cls()
        msg.header.frame_id = f'{side}_cam'
        msg.height, msg.width = gray.shape
        msg.encoding = 'mono8'
        msg.step = gray.shape[1]
        msg.data = gray.tobytes()
        return msg

    def _on_mask(self, msg: Any) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        latency = 1e-6 * (time.time_ns() - stamp)
        if self.windows:
            self.windows[-1].latency_ms.append(latency)
        self.masks.append((stamp, bool(np.frombuffer(bytes(msg.data), np.uint8).any())))

    def _on_diag(self, msg: Any) -> None:
        status = msg.status[0]
        values = {kv.key: kv.value for kv in status.values}
        values['_message'] = status.message
        values['_level'] = str(status.level[0] if isinstance(status.level, bytes)
                               else int(status.level))
        values['_t'] = f'{time.monotonic() - self.clock0:.3f}'
        self.diagnostics.append(values)

    def _on_homography(self, msg: Any) -> None:
        self.homographies.append(np.array(msg.data))
        self.h_times.append(time.monotonic() - self.clock0)

    def spin_for(self, seconds: float, step_s: float, until: Any = None) -> None:
        """Spin for ``seconds`` at most, or until ``until()`` is true."""
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (until is not None and until()):
            self.executor.spin_once(timeout_sec=step_s)

    def wait_for_node(self, node_proc: subprocess.Popen, timeout_s: float = 30.0) -> bool:
        """Return True once the node subscribes to both cameras and publishes diagnostics."""
        deadline = time.monotonic() + timeout_s
        while not (all(p.get_subscription_count() for p in self.pubs.values())
                   and self.node.count_publishers('/diagnostics')):
            if time.monotonic() > deadline or node_proc.poll() is not None:
                return False
            self.executor.spin_once(timeout_sec=0.05)
        return True

    def publish(self, index: int, sides: Sequence[str]) -> int:
        """Publish pair ``index`` on ``sides`` with one wall-clock stamp; return the images."""
        stamp = time.time_ns()
        for side in sides:
            msg = self.messages[index][side]
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            self.pubs[side].publish(msg)
        return len(sides)

    def wait_for_diagnostics(self, count: int, timeout_s: float) -> None:
        """Spin until ``count`` more diagnostics arrived (or ``timeout_s``)."""
        target = len(self.diagnostics) + count
        self.spin_for(timeout_s, 0.05, lambda: len(self.diagnostics) >= target)

    def warm_up(self) -> dict[str, str]:
        """Send pairs slowly until a homography comes; return the counters after warm-up."""
        t_warm = time.monotonic()
        while not self.homographies and time.monotonic() - t_warm < 20.0:
            self.publish(0, ('left', 'right'))
            self.spin_for(0.2, 0.01)
        # Counters from a diagnostics message that covers every warm-up image.
        self.wait_for_diagnostics(2, 10.0)
        base = dict(self.diagnostics[-1]) if self.diagnostics else {}
        self.masks.clear()
        self.homographies.clear()
        self.h_times.clear()
        return base

    def close(self) -> None:
        """Destroy the driver node and shut rclpy down."""
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown()


def _load(args: argparse.Namespace, driver: _LoadDriver, node_proc: subprocess.Popen
          ) -> tuple[int, int, list[tuple[float, float, float]]]:
    """Publish at ``--rate`` for ``--duration``; return pairs, images sent and RSS samples."""
    period = 1.0 / args.rate
    start = driver.clock0 = time.monotonic()
    sent = images_sent = 0
    next_window = start
    rss = [(0.0, *rss_mb(node_proc.pid))]     # (time, rss, peak)
    last_rss_t = start
    while True:
        now = time.monotonic()
        if now - start >= args.duration:
            break
        if now >= next_window:
            driver.windows.append(_Window())
            next_window += args.window
        silent = bool(args.dropout) and 0 <= now - start - args.dropout[0] < args.dropout[1]
        images_sent += driver.publish(sent % len(driver.messages),
                                      ('left',) if silent else ('left', 'right'))
        sent += 1
        driver.windows[-1].sent += 1
        if now - last_rss_t >= 1.0:
            rss.append((now - start, *rss_mb(node_proc.pid)))
            last_rss_t = now
        next_time = start + sent * period
        while time.monotonic() < next_time:
            driver.executor.spin_once(
                timeout_sec=max(0.0, min(0.002, next_time - time.monotonic())))
    # Let the last pair and two diagnostics periods arrive.
    driver.wait_for_diagnostics(2, 10.0)
    rss.append((time.monotonic() - start, *rss_mb(node_proc.pid)))
    return sent, images_sent, rss


def _drive(args: argparse.Namespace, frames: list[StereoFrame], node_proc: subprocess.Popen,
           ros: SimpleNamespace) -> int:
    driver = _LoadDriver(frames, ros)
    if not driver.wait_for_node(node_proc):
        print('plane_node did not come up', file=sys.stderr)
        return 1
    base = driver.warm_up()
    print(f'load: {args.rate:g} Hz on both cameras for {args.duration:g} s '
          f'({args.width}x{args.height} mono8), plane_node pid {node_proc.pid}', flush=True)
    sent, images_sent, rss = _load(args, driver, node_proc)
    driver.close()
    code = _report(args, frames, sent, images_sent, driver.windows, rss, rss[0][1],
                   driver.diagnostics, base, driver.masks, driver.homographies)
    if args.dropout:
        _report_dropout(args, frames, driver.diagnostics, driver.homographies, driver.h_times)
    return code


def _report_dropout(args, frames, diagnostics, homographies, h_times) -> None:
    t_stop, t_back = args.dropout[0], args.dropout[0] + args.dropout[1]
    during = [d for d in diagnostics
              if t_stop <= float(d['_t']) <= t_back + args.diagnostics_period]
    warn = [d for d in during if d['_level'] == '1' and 'no images on' in d['_message']
            and '/right/image_raw' in d['_message']]
    before = [d for d in diagnostics if 0 <= float(d['_t']) < t_stop]
    ok_after = [d for d in diagnostics if float(d['_t']) > t_back and d['_level'] == '0']
    h_after = [(t, h) for t, h in zip(h_times, homographies) if t > t_back]
    print(f'\ndrop-out: right camera silent from {t_stop:g} s to {t_back:g} s '
          f'(diagnostics.period_s {args.diagnostics_period:g}, silence_s 1)')
    if warn:
        print(f'  first WARN {float(warn[0]["_t"]) - t_stop:.2f} s after the stop: '
              f'"{warn[0]["_message"]}"; last WARN "{warn[-1]["_message"]}"')
    else:
        print('  no WARN naming the right camera')
    if ok_after:
        reinit = (int(ok_after[0]['re-initialisations']) - int(before[-1]['re-initialisations'])
                  if before else 'n/a')
        print(f'  status OK again {float(ok_after[0]["_t"]) - t_back:.2f} s after the return: '
              f'"{ok_after[0]["_message"]}"; re-initialisations across the gap: {reinit}')
    after = [d['_message'] for d in diagnostics if float(d['_t']) > t_back][:3]
    print('  statuses after the return: ' + ' | '.join(after))
    if h_after:
        err = _transfer_error_px(h_after[0][1].reshape(3, 3), frames[0])
        print(f'  first homography {h_after[0][0] - t_back:.2f} s after the return, transfer '
              f'error {err:.2f} px against the truth')


def _report(args, frames, sent, images_sent, windows, rss, rss_start, diagnostics, base,
            masks, homographies) -> int:
    final = diagnostics[-1] if diagnostics else {}

    def delta(key: str) -> int:
        return int(final.get(key, 0)) - int(base.get(key, 0))

    left_key = next((k for k in final if k.endswith('images received')), None)
    received = sum(delta(k) for k in final if k.endswith('images received'))
    processed = delta('processed pairs')
    paired = delta('pairs')
    busy = delta('dropped pairs (busy)')
    sync_frames = delta('dropped frames (sync)')
    lost = images_sent - received
    print('\nwindow [s]  sent  masks  latency stamp->mask [ms]                  node RSS [MB]')
    for i, window in enumerate(windows):
        t1 = (i + 1) * args.window
        at = [r for r in rss if r[0] <= t1]
        rss_now = at[-1][1] if at else float('nan')
        print(f'{i * args.window:4.0f}-{t1:<4.0f} {window.sent:6d} {len(window.latency_ms):6d}'
              f'  {_fmt_latency(window.latency_ms)}   {rss_now:8.1f}')
    all_latency = [v for w in windows for v in w.latency_ms]
    print(f'\npairs sent:            {sent} ({sent / args.duration:.1f} /s)')
    print(f'images received:       {received} of {images_sent} (lost before the node: {lost})'
          if left_key else 'images received:       n/a')
    print(f'pairs made by sync:    {paired}')
    print(f'processed:             {processed} ({processed / args.duration:.1f} /s)')
    print(f'dropped (busy):        {busy} pairs')
    print(f'dropped (sync):        {sync_frames} frames')
    not_sent = 2 * sent - images_sent         # right images held back by --dropout
    print(f'sent - processed:      {sent - processed} = busy {busy} + '
          f'{sent - processed - busy} not paired (sync drops, queued, lost in DDS or not sent: '
          f'{(sync_frames + lost + not_sent) / 2:.1f} pairs)')
    print(f'latency stamp->mask:   {_fmt_latency(all_latency)} ms over {len(all_latency)} '
          'masks')
    print(f'node processing:       median {final.get("processing latency median [ms]")} ms, '
          f'p95 {final.get("processing latency p95 [ms]")} ms (diagnostics, last 200 pairs)')
    print(f'node RSS:              start {rss_start:.1f} MB, end {rss[-1][1]:.1f} MB, '
          f'peak {max(r[2] for r in rss):.1f} MB')
    found = [stamp for stamp, ok in masks if ok]
    errs = np.array([_transfer_error_px(h.reshape(3, 3), frames[0]) for h in homographies]
                    or [np.nan])
    print(f'plane found:           {len(found)} of {len(masks)} masks; {len(homographies)} '
          f'homographies, transfer error vs truth median {np.median(errs):.2f} px, max '
          f'{np.max(errs):.2f} px, < 1 px {100 * np.mean(errs < 1):.1f} %')
    print(f'last diagnostics:      {final.get("_message", "none")}')
    return 0


def main(argv: list[str] | None = None) -> int:
    """Parse the arguments and run the load test."""
    parser = tool_parser(__doc__)
    parser.add_argument('--duration', type=float, default=60.0, help='seconds of load')
    parser.add_argument('--rate', type=float, default=100.0, help='pairs per second')
    add_size_arguments(parser, 1280, 720)
    parser.add_argument('--frames', type=int, default=8, help='pre-rendered pairs')
    parser.add_argument('--seed', type=int, default=11)
    parser.add_argument('--window', type=float, default=10.0, help='report window, seconds')
    parser.add_argument('--diagnostics-period', type=float, default=1.0)
    parser.add_argument('--qos-depth', type=int, default=2,
                        help="the node's qos.depth (subscription queue depth)")
    parser.add_argument('--dropout', type=float, nargs=2, metavar=('START_S', 'LENGTH_S'),
                        help='the right camera stops at START_S for LENGTH_S seconds')
    parser.add_argument('--fastdds-profile', metavar='XML',
                        help='Fast DDS profile for both processes, e.g. '
                             'config/fastdds_large_images.xml (default: none, stock Fast DDS)')
    parser.add_argument('--domain-id', type=int, default=None,
                        help='DDS domain (default: a random one in 101..200)')
    return run(parser.parse_args(argv))


if __name__ == '__main__':
    sys.exit(main())
