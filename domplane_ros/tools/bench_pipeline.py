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

from dataclasses import dataclass, field, replace
from pathlib import Path
import sys
import time
from typing import Any, Callable

import cv2
from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.image import message_to_gray
from domplane_ros.core.pyramid import working_level
from domplane_ros.sim.generators import random_scene
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.bench_frames import bench_frames, decode, sequence
from domplane_ros.tools.bench_live import (bench_breakdown, bench_dds, bench_dds_process,
                                           LARGE_IMAGES)
from domplane_ros.tools.common import (add_output_argument, machine_name, one_core,
                                       tool_parser)
import numpy as np


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
            decode(frame.left), decode(frame.right), i * 33_000_000))
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
        frame = bench_frames([scene], 1)[0]
        pipeline = PlanePipeline(PlaneNodeConfig())
        result, ours = _timed(lambda: pipeline.process(
            decode(frame.left), decode(frame.right), 0))
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
        left, right = decode(frame.left), decode(frame.right)
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
    parser.add_argument('--fastdds-profile', default=LARGE_IMAGES,
                        help="Fast DDS profile of both processes with --dds-process ('' for "
                        f'stock Fast DDS; default {LARGE_IMAGES})')
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
