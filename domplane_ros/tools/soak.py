"""Soak run: 10,000 stereo pairs through the pipeline in-process, watching memory and time.

Pre-renders a modest set of pairs (``sim.generators``, played forwards and backwards), then feeds
``--pairs`` pairs with increasing stamps through the same path as plane_replay (duck-typed
``sensor_msgs/Image`` messages -> synchroniser -> decode -> :class:`PlanePipeline`), with a
bad frame mixed in every ``--bad-every`` pairs (an unsupported encoding, a black pair, a pair of
another size, a stamp going back, a 5 s gap), so that a cache or a list that grows with every
frame or every failure would show. Prints the process RSS at start and end (and peak), the
per-pair time of the first and last 1000 pairs (median, p95) and a least-squares slope of
per-pair time and RSS over the run, and writes a plot. Run::

    python -m domplane_ros.tools.soak                    # 10,000 pairs at 640x480, about 2 min
    python -m domplane_ros.tools.soak --pairs 2000 --output soak_output
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import gc
import os
from pathlib import Path
import sys
import time

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.replay.reader import ReplaySession
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.model import StereoFrame
from domplane_ros.sim.truth import every_floor_pixel, transfer_error_px
from domplane_ros.tools.common import (add_size_arguments, machine_name, mono8_message,
                                       one_core, progress, rss_mb, tool_parser)
import numpy as np

BAD_KINDS = ('bad_encoding', 'black', 'other_size', 'stamp_back', 'gap')
PERIOD_NS = 33_333_333


def _slope_per_1000(values: np.ndarray, step: int = 100) -> float:
    """Least-squares slope of per-block medians, per 1000 pairs."""
    n = len(values) // step
    if n < 2:
        return float('nan')
    blocks = np.median(values[:n * step].reshape(n, step), axis=1)
    x = (np.arange(n) + 0.5) * step
    return float(np.polyfit(x, blocks, 1)[0] * 1000.0)


@dataclass
class _Soak:
    """What the soak measures, pair by pair."""

    pairs: int
    times_ms: np.ndarray = field(init=False)
    cpu_ms: np.ndarray = field(init=False)   # thread CPU time: robust to a busy machine
    rss: list = field(default_factory=list)     # (pair index, rss MB, peak MB)
    errors: list = field(default_factory=list)  # transfer error of good pairs with a plane
    outcomes: dict = field(default_factory=lambda: {'plane': 0, 'no plane': 0,
                                                    'decode error': 0, 'not paired': 0})
    bad_counts: dict = field(default_factory=lambda: dict.fromkeys(BAD_KINDS, 0))
    start_rss: tuple | None = None

    def __post_init__(self) -> None:
        """Allocate the per-pair times."""
        self.times_ms = np.full(self.pairs, np.nan)
        self.cpu_ms = np.full(self.pairs, np.nan)


def _render(args: argparse.Namespace) -> tuple[list[StereoFrame], StereoFrame]:
    """Return the pre-rendered pairs and one pair of half the size."""
    print(f'rendering {args.frames} pairs {args.width}x{args.height} ...', flush=True)
    frames = scene_sequence(args.frames, seed=args.seed, width=args.width, height=args.height,
                            floor='random', n_boxes=3)
    small = scene_sequence(1, seed=args.seed + 1, width=args.width // 2,
                           height=args.height // 2, floor='random', n_boxes=3)[0]
    return frames, small


def _images(kind: str, frame: StereoFrame, small: StereoFrame, stamp: int
            ) -> tuple[np.ndarray, np.ndarray, str, int]:
    """Return ``(left, right, encoding, stamp)`` of a pair, spoilt as ``kind`` says."""
    left, right, encoding = frame.left, frame.right, 'mono8'
    if kind == 'bad_encoding':
        encoding = 'yuv_bogus'
    elif kind == 'black':
        left = right = np.zeros_like(frame.left)
    elif kind == 'other_size':
        left, right = small.left, small.right
    elif kind == 'stamp_back':
        stamp -= 1_000_000_000
    elif kind == 'gap':
        stamp += 5_000_000_000
    return left, right, encoding, stamp + PERIOD_NS


def _feed(session: ReplaySession, soak: _Soak, k: int, kind: str, frame: StereoFrame,
          images: tuple[np.ndarray, np.ndarray, str, int]) -> None:
    """Feed one pair through the session and record its time and outcome."""
    left, right, encoding, stamp = images
    t0, c0 = time.perf_counter(), time.thread_time()
    done = session.add('left', mono8_message(left, stamp, encoding))
    done += session.add('right', mono8_message(right, stamp + 1000))
    soak.times_ms[k] = 1e3 * (time.perf_counter() - t0)
    soak.cpu_ms[k] = 1e3 * (time.thread_time() - c0)
    if not done:
        soak.outcomes['decode error' if kind == 'bad_encoding' else 'not paired'] += 1
    for replayed in done:
        result = replayed.result
        soak.outcomes['plane' if result.ok else 'no plane'] += 1
        if result.ok and not kind:
            soak.errors.append(transfer_error_px(result.homography, frame,
                                                 every_floor_pixel(frame, 7)))


def run(args: argparse.Namespace) -> int:
    """Run the soak and print its figures."""
    print(f'machine: {machine_name()}')
    frames, small = _render(args)
    order = list(range(len(frames))) + list(range(len(frames) - 2, 0, -1))
    # The documented default prior: nothing set from the rendered set-up's truth.
    session = ReplaySession(PlaneNodeConfig())
    soak = _Soak(args.pairs)
    stamp = 1_700_000_000_000_000_000
    gc.collect()
    bar = progress(range(args.pairs), 'soak', unit='pair', disable=args.no_progress,
                   mininterval=1.0, leave=True)
    for k in bar:
        kind = ''
        if args.bad_every and k % args.bad_every == args.bad_every - 1:
            kind = BAD_KINDS[(k // args.bad_every) % len(BAD_KINDS)]
            soak.bad_counts[kind] += 1
        frame = frames[order[k % len(order)]]
        images = _images(kind, frame, small, stamp)
        stamp = images[3]
        _feed(session, soak, k, kind, frame, images)
        if k == 99:
            gc.collect()
            soak.start_rss = (k, *rss_mb(os.getpid()))
            soak.rss.append(soak.start_rss)
        elif k % 250 == 249:
            soak.rss.append((k, *rss_mb(os.getpid())))
        if k % 500 == 499 and hasattr(bar, 'set_postfix_str'):
            bar.set_postfix_str(f'RSS {soak.rss[-1][1]:.0f} MB', refresh=False)
    if hasattr(bar, 'close'):
        bar.close()
    gc.collect()
    soak.rss.append((args.pairs - 1, *rss_mb(os.getpid())))
    return _report(args, soak, session)


def _time_line(name: str, values: np.ndarray) -> str:
    n = len(values)
    first, last = values[:min(1000, n)], values[-min(1000, n):]
    return (f'{name}first 1000 median {np.median(first):.2f} ms (p95 '
            f'{np.percentile(first, 95):.2f}), last 1000 median {np.median(last):.2f} ms (p95 '
            f'{np.percentile(last, 95):.2f}); slope {_slope_per_1000(values):+.3f} ms per '
            '1000 pairs')


def _report(args: argparse.Namespace, soak: _Soak, session: ReplaySession) -> int:
    times_ms, cpu_ms, errors = soak.times_ms, soak.cpu_ms, soak.errors
    rss, start_rss, outcomes, bad_counts = soak.rss, soak.start_rss, soak.outcomes, soak.bad_counts
    n = len(times_ms)
    rss_arr = np.array(rss)
    rss_slope = (float(np.polyfit(rss_arr[:, 0], rss_arr[:, 1], 1)[0] * 1000.0)
                 if len(rss_arr) > 2 else float('nan'))
    errs = np.asarray(errors)
    print(f'\npairs fed:          {n} ({args.width}x{args.height}; one bad frame every '
          f'{args.bad_every}: ' + ', '.join(f'{k} {v}' for k, v in bad_counts.items()) + ')')
    print('outcomes:           ' + ', '.join(f'{k} {v}' for k, v in outcomes.items()))
    print(f'pipeline:           {session.pipeline.stats.reinitialisations} '
          f're-initialisations, {session.pipeline.stats.resets} warm-start resets, sync '
          f'resets {session.sync.stats().resets}, sync drops {session.sync.stats().dropped}')
    if errs.size:
        print(f'transfer error:     median {np.median(errs):.3f} px, p95 '
              f'{np.percentile(errs, 95):.3f} px, < 1 px {100 * np.mean(errs < 1):.2f} % of '
              f'{errs.size} good pairs with a plane')
    print(_time_line('per-pair wall:      ', times_ms))
    print(_time_line('per-pair CPU:       ', cpu_ms))
    print(f'RSS:                start {start_rss[1]:.1f} MB (after 100 pairs), end '
          f'{rss_arr[-1, 1]:.1f} MB, peak {rss_arr[:, 2].max():.1f} MB; slope '
          f'{rss_slope:+.3f} MB per 1000 pairs')
    if args.output:
        _plot(Path(args.output), times_ms, cpu_ms, rss_arr)
    return 0


def _plot(out: Path, times_ms: np.ndarray, cpu_ms: np.ndarray, rss_arr: np.ndarray) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    step = 100
    n = len(times_ms) // step
    blocks = times_ms[:n * step].reshape(n, step)
    cpu_blocks = cpu_ms[:n * step].reshape(n, step)
    x = (np.arange(n) + 0.5) * step
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax1.plot(x, np.median(blocks, axis=1), label='wall, median per 100 pairs')
    ax1.plot(x, np.percentile(blocks, 95, axis=1), label='wall, p95 per 100 pairs', alpha=0.6)
    ax1.plot(x, np.median(cpu_blocks, axis=1), label='CPU, median per 100 pairs')
    ax1.set_ylabel('per-pair time [ms]')
    ax1.legend()
    ax1.grid(alpha=0.3)
    ax2.plot(rss_arr[:, 0], rss_arr[:, 1], label='RSS')
    ax2.plot(rss_arr[:, 0], rss_arr[:, 2], label='peak RSS', alpha=0.7)
    ax2.set_ylabel('MB')
    ax2.set_xlabel('pair')
    ax2.legend()
    ax2.grid(alpha=0.3)
    fig.suptitle('soak: per-pair time and memory')
    fig.tight_layout()
    fig.savefig(out / 'soak.png', dpi=90)
    plt.close(fig)
    print(f'plot:               {out / "soak.png"}')


def main(argv: list[str] | None = None) -> int:
    """Parse the arguments and run the soak."""
    parser = tool_parser(__doc__)
    parser.add_argument('--pairs', type=int, default=10_000)
    parser.add_argument('--frames', type=int, default=12, help='pre-rendered pairs')
    add_size_arguments(parser)
    parser.add_argument('--seed', type=int, default=5)
    parser.add_argument('--bad-every', type=int, default=97,
                        help='one bad frame every this many pairs (0: none)')
    parser.add_argument('--output', default='soak_output', help='folder for soak.png')
    parser.add_argument('--no-progress', action='store_true')
    args = parser.parse_args(argv)
    with one_core():
        return run(args)


if __name__ == '__main__':
    sys.exit(main())
