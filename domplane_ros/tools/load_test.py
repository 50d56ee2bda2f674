"""Load test: both cameras at 100 Hz into plane_node over DDS on loopback, for 60 s.

plane_node runs in its own process (started here, ``python -m domplane_ros.ros.node``), this
process publishes pre-rendered stereo pairs (``scene.py``; a head standing still, each pair
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
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any

from domplane_ros.core.homography import apply_homography
from domplane_ros.sim.scene import scene_sequence
from domplane_ros.tools.bench import machine_name
import numpy as np

_THREAD_ENV = {'OMP_NUM_THREADS': '1', 'OPENBLAS_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1',
               'OPENCV_FOR_THREADS_NUM': '1'}


def rss_mb(pid: int) -> tuple[float, float]:
    """Return ``(VmRSS, VmHWM)`` of a process in MB (current and peak resident memory)."""
    values = {}
    with open(f'/proc/{pid}/status', encoding='ascii') as stream:
        for line in stream:
            key, _, rest = line.partition(':')
            if key in ('VmRSS', 'VmHWM'):
                values[key] = int(rest.split()[0]) / 1024.0
    return values.get('VmRSS', float('nan')), values.get('VmHWM', float('nan'))


def _params_file(frame, directory: str, period_s: float, slop_s: float, depth: int) -> str:
    s = frame.setup
    text = ('plane_node:\n  ros__parameters:\n'
            f'    prior.focal_px: [{s.focal_px * 0.8}, {s.focal_px * 1.2}]\n'
            f'    prior.baseline_over_height: [{s.baseline_over_height * 0.7}, '
            f'{s.baseline_over_height * 1.3}]\n'
            f'    prior.tilt_deg: [{s.tilt_deg - 8.0}, {s.tilt_deg + 8.0}]\n'
            f'    prior.vergence_deg: [{s.vergence_deg - 2.0}, {s.vergence_deg + 2.0}]\n'
            f'    diagnostics.period_s: {period_s}\n'
            # Stamps 10 ms apart at 100 Hz: a slop below half the period, so a frame whose
            # partner was lost is never paired with the next frame's partner.
            f'    sync.slop_s: {slop_s}\n'
            f'    qos.depth: {depth}\n')
    path = Path(directory) / 'plane_node.yaml'
    path.write_text(text, encoding='utf-8')
    return str(path)


def _transfer_error_px(h: np.ndarray, frame) -> float:
    px = np.argwhere(frame.plane_left & frame.visible_in_right)[::7, ::-1].astype(float)
    return float(np.linalg.norm(apply_homography(h, px)
                                - apply_homography(frame.homography, px), axis=1).mean())


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


def run(args: argparse.Namespace) -> int:
    """Run the load test and print its figures; return the exit code."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import Image
    from std_msgs.msg import Float64MultiArray

    print(f'machine: {machine_name()}')
    print(f'rendering {args.frames} stereo pairs {args.width}x{args.height} ...', flush=True)
    frames = scene_sequence(args.frames, seed=args.seed, width=args.width, height=args.height,
                            floor='random', n_boxes=3, step=0.0, yaw_rate_deg=0.0,
                            tilt_jitter_deg=0.0, vergence_jitter_deg=0.0)
    order = list(range(len(frames)))
    domain_id = args.domain_id if args.domain_id is not None else random.randint(101, 200)
    dds = {'ROS_DOMAIN_ID': str(domain_id), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    if args.fastdds_profile:
        profile = str(Path(args.fastdds_profile).resolve())
        dds.update(FASTDDS_DEFAULT_PROFILES_FILE=profile, FASTRTPS_DEFAULT_PROFILES_FILE=profile)
    print('Fast DDS profile: ' + (dds.get('FASTDDS_DEFAULT_PROFILES_FILE')
                                  or os.environ.get('FASTDDS_DEFAULT_PROFILES_FILE', 'default')))
    env = dict(os.environ, **dds, **_THREAD_ENV)
    os.environ.update(dds)
    with tempfile.TemporaryDirectory(prefix='domplane_load_') as tmp:
        params = _params_file(frames[0], tmp, args.diagnostics_period, 0.4 / args.rate,
                              args.qos_depth)
        node_proc = subprocess.Popen(
            [sys.executable, '-m', 'domplane_ros.ros.node', '--ros-args', '--params-file', params,
             '--log-level', 'warn'], env=env)
        try:
            return _drive(args, frames, order, node_proc, rclpy, SingleThreadedExecutor,
                          qos_profile_sensor_data, DiagnosticArray, Image, Float64MultiArray)
        finally:
            if node_proc.poll() is None:
                node_proc.send_signal(signal.SIGINT)
                try:
                    node_proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    node_proc.kill()
                    node_proc.wait()


def _drive(args: argparse.Namespace, frames: list, order: list[int],
           node_proc: subprocess.Popen, rclpy: Any, executor_cls: Any, sensor_qos: Any,
           diagnostic_cls: Any, image_cls: Any, array_cls: Any) -> int:
    rclpy.init()
    driver = rclpy.create_node('load_test_driver')
    pubs = {side: driver.create_publisher(image_cls, f'{side}/image_raw', sensor_qos)
            for side in ('left', 'right')}
    messages = []
    for frame in frames:
        pair = {}
        for side, gray in (('left', frame.left), ('right', frame.right)):
            msg = image_cls()
            msg.header.frame_id = f'{side}_cam'
            msg.height, msg.width = gray.shape
            msg.encoding = 'mono8'
            msg.step = gray.shape[1]
            msg.data = gray.tobytes()
            pair[side] = msg
        messages.append(pair)

    windows: list[_Window] = []
    masks: list[tuple[int, bool]] = []          # (stamp, plane found) in arrival order
    homographies: list[np.ndarray] = []
    diagnostics: list[dict[str, str]] = []
    rss: list[tuple[float, float, float]] = []  # (time, rss, peak)

    def on_mask(msg: Any) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        latency = 1e-6 * (time.time_ns() - stamp)
        if windows:
            windows[-1].latency_ms.append(latency)
        masks.append((stamp, bool(np.frombuffer(bytes(msg.data), np.uint8).any())))

    clock0 = [time.monotonic()]         # start of the load, for arrival times
    h_times: list[float] = []

    def on_diag(msg: Any) -> None:
        status = msg.status[0]
        values = {kv.key: kv.value for kv in status.values}
        values['_message'] = status.message
        values['_level'] = str(status.level[0] if isinstance(status.level, bytes)
                               else int(status.level))
        values['_t'] = f'{time.monotonic() - clock0[0]:.3f}'
        diagnostics.append(values)

    def on_homography(msg: Any) -> None:
        homographies.append(np.array(msg.data))
        h_times.append(time.monotonic() - clock0[0])

    driver.create_subscription(image_cls, 'plane/mask', on_mask, 50)
    driver.create_subscription(array_cls, 'plane/homography',
                               on_homography, 50)
    driver.create_subscription(diagnostic_cls, '/diagnostics', on_diag, 50)
    executor = executor_cls()
    executor.add_node(driver)
    deadline = time.monotonic() + 30.0
    while not (all(p.get_subscription_count() for p in pubs.values())
               and driver.count_publishers('/diagnostics')):
        if time.monotonic() > deadline or node_proc.poll() is not None:
            print('plane_node did not come up', file=sys.stderr)
            return 1
        executor.spin_once(timeout_sec=0.05)
    # Warm-up: a few pairs slowly, so the cold start is not counted as load.
    t_warm = time.monotonic()
    k = 0
    while not homographies and time.monotonic() - t_warm < 20.0:
        stamp = time.time_ns()
        for side in ('left', 'right'):
            msg = messages[order[k % len(order)]][side]
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            pubs[side].publish(msg)
        end = time.monotonic() + 0.2
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
    # Counters from a diagnostics message that covers every warm-up image.
    n_diag = len(diagnostics)
    end = time.monotonic() + 10.0
    while len(diagnostics) < n_diag + 2 and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    base = dict(diagnostics[-1]) if diagnostics else {}
    masks.clear()
    homographies.clear()
    h_times.clear()

    print(f'load: {args.rate:g} Hz on both cameras for {args.duration:g} s '
          f'({args.width}x{args.height} mono8), plane_node pid {node_proc.pid}', flush=True)
    period = 1.0 / args.rate
    start = time.monotonic()
    sent = 0
    images_sent = 0
    clock0[0] = start
    next_window = start
    rss.append((0.0, *rss_mb(node_proc.pid)))
    rss_start = rss[0][1]
    last_rss_t = start
    while True:
        now = time.monotonic()
        if now - start >= args.duration:
            break
        if now >= next_window:
            windows.append(_Window())
            next_window += args.window
        index = order[sent % len(order)]
        stamp = time.time_ns()
        silent = bool(args.dropout) and 0 <= now - start - args.dropout[0] < args.dropout[1]
        for side in ('left',) if silent else ('left', 'right'):
            msg = messages[index][side]
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
            pubs[side].publish(msg)
            images_sent += 1
        sent += 1
        windows[-1].sent += 1
        if now - last_rss_t >= 1.0:
            rss.append((now - start, *rss_mb(node_proc.pid)))
            last_rss_t = now
        next_time = start + sent * period
        while time.monotonic() < next_time:
            executor.spin_once(timeout_sec=max(0.0, min(0.002, next_time - time.monotonic())))
    t_end = time.monotonic()
    # Let the last pair and two diagnostics periods arrive.
    n_diag = len(diagnostics)
    while len(diagnostics) < n_diag + 2 and time.monotonic() - t_end < 10.0:
        executor.spin_once(timeout_sec=0.05)
    rss.append((time.monotonic() - start, *rss_mb(node_proc.pid)))
    executor.shutdown()
    driver.destroy_node()
    rclpy.try_shutdown()
    code = _report(args, frames, sent, images_sent, windows, rss, rss_start, diagnostics, base,
                   masks, homographies)
    if args.dropout:
        _report_dropout(args, frames, diagnostics, homographies, h_times)
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
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, default=60.0, help='seconds of load')
    parser.add_argument('--rate', type=float, default=100.0, help='pairs per second')
    parser.add_argument('--width', type=int, default=1280)
    parser.add_argument('--height', type=int, default=720)
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
