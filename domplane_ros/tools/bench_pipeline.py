"""Pipeline benchmark: per-pair latency of the full pipeline, and end-to-end latency over DDS.

Run ``python -m domplane_ros.tools.bench_pipeline`` (or ``make bench``). One core (BLAS and OpenCV
pinned to one thread). It prints:

* per-pair latency of decode + features + warm-started estimate + mask on a rendered moving
  stereo sequence at 640x480 and 1280x720, median and p95 (and of the bad-input checks of
  :class:`~domplane_ros.stream.health.PairChecks` alone), beside a baseline run in the same
  process on the same messages: decode + ORB (1000 features) + brute-force Hamming matching +
  ``cv2.findHomography`` with USAC_MAGSAC;
* end-to-end latency through DDS on loopback (image header stamp to the mask's arrival at a
  subscriber) with a publisher at 30 Hz into a live ``plane_node`` in the same process.
"""

from __future__ import annotations

import sys
import time
from typing import Any, Callable

import cv2
from domplane_ros.config import PlaneNodeConfig, PriorConfig
from domplane_ros.core.image import message_to_gray
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.truth import every_floor_pixel, transfer_error_px
from domplane_ros.stream.health import PairChecks
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.common import (machine_name, mono8_message, one_core, prior_around,
                                       tool_parser)
import numpy as np


def _orb_pipeline(orb, matcher, left_msg, right_msg) -> np.ndarray | None:
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


def _error(h: np.ndarray | None, frame) -> float:
    """Return the transfer error over every 37th visible floor pixel (inf without H)."""
    return transfer_error_px(h, frame, every_floor_pixel(frame, 37))


def bench_latency(width: int, height: int, n_frames: int, seed: int) -> None:
    """Print full-pipeline latency (warm) and the ORB + MAGSAC baseline for one size."""
    frames = scene_sequence(n_frames, seed, width=width, height=height, floor='random')
    msgs = [(mono8_message(f.left), mono8_message(f.right)) for f in frames]
    config = PlaneNodeConfig(prior=prior_around(frames[0].setup))
    pipeline = PlanePipeline(config)
    ours, ours_err = [], []
    for i, (lm, rm) in enumerate(msgs):
        t = time.perf_counter()
        result = pipeline.process(message_to_gray(lm), message_to_gray(rm), i * 33_000_000)
        elapsed = time.perf_counter() - t
        if i > 0:  # the first pair is the cold start
            ours.append(elapsed)
            ours_err.append(_error(result.homography, frames[i]))
    # The bad-input checks alone (part of the pipeline's time): size, frozen camera, clipping.
    checks = PairChecks()
    check_times = []
    for i, (lm, rm) in enumerate(msgs):
        left, right = message_to_gray(lm), message_to_gray(rm)
        t = time.perf_counter()
        checks.check(left, right, i * 33_000_000, config.pipeline)
        check_times.append(time.perf_counter() - t)
    orb = cv2.ORB_create(nfeatures=1000)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)
    base, base_err = [], []
    for i, (lm, rm) in enumerate(msgs[1:], start=1):
        t = time.perf_counter()
        h = _orb_pipeline(orb, matcher, lm, rm)
        base.append(time.perf_counter() - t)
        base_err.append(_error(h, frames[i]))

    def row(name, times, errs=None):
        ms = 1e3 * np.asarray(times)
        line = f'{width}x{height:<5d} {name:28s} {np.median(ms):8.2f} {np.percentile(ms, 95):8.2f}'
        if errs is not None:
            errs = np.asarray(errs)
            line += f'   {np.median(errs):8.3f} {100 * np.mean(errs < 1.0):6.1f} %'
        print(line)

    row('domplane (warm, full)', ours, ours_err)
    row('  of which input checks', check_times[1:])
    row('ORB + BF + MAGSAC baseline', base, base_err)


def _plane_node(prior: PriorConfig) -> Any:
    """Return a live plane_node with ``prior``, in this process (rclpy initialised)."""
    from rclpy.parameter import Parameter

    from domplane_ros.ros.node import PlaneNode

    return PlaneNode(parameter_overrides=[
        Parameter('prior.focal_px', value=list(prior.focal_px)),
        Parameter('prior.baseline_over_height', value=list(prior.baseline_over_height)),
        Parameter('prior.tilt_deg', value=list(prior.tilt_deg)),
        Parameter('prior.vergence_deg', value=list(prior.vergence_deg))])


def _spin_until(executor: Any, done: Callable[[], bool], timeout_s: float,
                step_s: float) -> None:
    """Spin ``executor`` until ``done()`` or ``timeout_s`` seconds have passed."""
    deadline = time.monotonic() + timeout_s
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=step_s)


def bench_dds(seconds: float, rate_hz: float) -> None:
    """Print image-stamp-to-mask-arrival latency through DDS with a 30 Hz publisher."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from domplane_ros.ros.messages import image_msg, stamped_header

    frames = scene_sequence(30, 11, width=640, height=480, floor='random')
    rclpy.init()
    node = _plane_node(prior_around(frames[0].setup))
    driver = rclpy.create_node('bench_driver')
    pubs = [driver.create_publisher(Image, f'{side}/image_raw', qos_profile_sensor_data)
            for side in ('left', 'right')]
    latencies: list[float] = []
    sent = [0]
    driver.create_subscription(Image, 'plane/mask', lambda msg: latencies.append(
        time.time() - (msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)), 50)

    def tick() -> None:
        frame = frames[sent[0] % len(frames)]
        now_ns = time.time_ns()
        for pub, gray, side in zip(pubs, (frame.left, frame.right), ('left', 'right')):
            pub.publish(image_msg(gray, stamped_header(now_ns, side), 'mono8'))
        sent[0] += 1

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    executor.add_node(driver)
    _spin_until(executor, lambda: pubs[0].get_subscription_count() > 0, 3.0, 0.05)
    driver.create_timer(1.0 / rate_hz, tick)
    _spin_until(executor, lambda: False, seconds, 0.01)
    processed = node.session.counters.processed
    busy = node.slot.dropped
    executor.shutdown()
    node.destroy_node()
    driver.destroy_node()
    rclpy.shutdown()
    lat = 1e3 * np.asarray(latencies[5:] or [float('nan')])
    print(f'\nDDS end to end, 640x480 mono8 at {rate_hz:g} Hz for {seconds:g} s: sent {sent[0]} '
          f'pairs, masks received {len(latencies)}, processed {processed}, dropped while busy '
          f'{busy}')
    print(f'stamp -> mask arrival latency: median {np.median(lat):.2f} ms, '
          f'p95 {np.percentile(lat, 95):.2f} ms')


def main(argv: list[str] | None = None) -> int:
    """Run the pipeline benchmark and print its figures."""
    parser = tool_parser(__doc__)
    parser.add_argument('--frames', type=int, default=60, help='frames per image size')
    parser.add_argument('--dds-seconds', type=float, default=10.0)
    parser.add_argument('--no-dds', action='store_true', help='skip the DDS measurement')
    args = parser.parse_args(argv)
    print(f'machine: {machine_name()}')
    print(f'{"size":11s} {"pipeline":28s} {"med ms":>8s} {"p95 ms":>8s}   '
          f'{"med err":>8s} {"<1 px":>8s}')
    with one_core():
        bench_latency(640, 480, args.frames, seed=5)
        bench_latency(1280, 720, args.frames, seed=5)
        if not args.no_dds:
            bench_dds(args.dds_seconds, 30.0)
    return 0


if __name__ == '__main__':
    sys.exit(main())
