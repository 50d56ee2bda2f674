"""Evaluate the lock under active head motion: three warm starts side by side.

Run ``python -m domplane_ros.tools.evaluate_head [--frames 300] [--speeds 2,5,10,20,30,45,60]
[--out eval_output/head]``. For every speed, rendered stereo sequences
(:func:`domplane_ros.sim.head.head_sequence`, 30 Hz) show a head panning at that speed, tilting
between 15 and 45 degrees with that peak speed and verging between -1.5 and 3.5 degrees with a
fifth of it, over floors with boxes all around (two thirds of the frames on the ``'random'``
floor, one third on ``'tiles'``, whose periodic joints invite look-alike solutions). Each frame
goes, in the same process and on the same images, to three pipelines:

* ``prediction``: the product's default: warm start from the last homography moved through
  both cameras' tracked motion (``tracking.enabled``);
* ``last``: warm start from the last homography as is (``tracking.enabled: false``);
* ``cold``: the prior search in every frame (the pipeline is reset before each frame and
  refines all ``prior.refine_best`` candidates at once).

Reported per speed and method: the share of frames *locked* (a plane whose mean transfer error
over the visible floor, against the rendered truth, is below 1 px), the share of wrong locks
(a plane published with an error of 1 px or more), the losses (a frame not locked after a
locked one) and the frames to re-lock after each loss (max and mean), and the per-frame time
(median and p95 of ``PlanePipeline.process``, one thread). Frames before the first lock of a
sequence (the initial search) are not counted.

Outputs in ``--out``: ``summary.md`` (the table and the machine), ``frames.csv`` (every frame),
``locked.png`` (locked share per speed), ``times.png`` (time per frame), ``errors.png`` (the
error over time at the fastest speeds) and ``contact_sheet.png``.
"""

from __future__ import annotations

import argparse
import csv
from dataclasses import dataclass, replace
from pathlib import Path
import sys
import time
from typing import Any, Iterable, Sequence

import cv2
from domplane_ros.config import one_shot_search, PlaneNodeConfig, TrackingConfig
from domplane_ros.core.mask import overlay
from domplane_ros.sim import truth
from domplane_ros.sim.head import head_sequence, HeadMotion
from domplane_ros.sim.model import StereoFrame
from domplane_ros.sim.truth import relock_runs, transfer_error_px
from domplane_ros.stream.pipeline import FrameResult, PlanePipeline
from domplane_ros.tools.common import machine_name, one_core, progress, tool_parser
import numpy as np

SPEEDS_DEG_S = (2.0, 5.0, 10.0, 20.0, 30.0, 45.0, 60.0)
METHODS = ('prediction', 'last', 'cold')
LOCK_ERROR_PX = 1.0
RATE_HZ = 30.0
# (floor kind, share of the frames) of each speed's sequences.
FLOORS = (('random', 2.0 / 3.0), ('tiles', 1.0 / 3.0))


def method_config(method: str, base: PlaneNodeConfig | None = None) -> PlaneNodeConfig:
    """Return the pipeline configuration of one warm-start method.

    Args:
        method: ``'prediction'``, ``'last'`` or ``'cold'``.
        base: The configuration to start from (default: the defaults).

    Returns:
        The configuration.

    Raises:
        ValueError: On an unknown method.

    """
    base = base or PlaneNodeConfig()
    if method == 'prediction':
        return replace(base, tracking=replace(base.tracking, enabled=True))
    if method == 'last':
        return replace(base, tracking=replace(base.tracking, enabled=False))
    if method == 'cold':
        return replace(one_shot_search(base), tracking=TrackingConfig(enabled=False))
    raise ValueError(f'unknown method {method!r}; expected one of {", ".join(METHODS)}')


class MethodRunner:
    """One method's pipeline over a sequence (``cold`` resets before every frame)."""

    def __init__(self, method: str, base: PlaneNodeConfig | None = None) -> None:
        """Build the pipeline of ``method``."""
        self.method = method
        self.pipeline = PlanePipeline(method_config(method, base))

    def process(self, frame: StereoFrame, index: int) -> tuple[FrameResult, float]:
        """Process one frame; return the result and the wall time in ms."""
        start = time.perf_counter()
        result = self.pipeline.process(frame.left, frame.right, index * int(1e9 / RATE_HZ),
                                       reset=self.method == 'cold')
        return result, 1e3 * (time.perf_counter() - start)


def floor_points(frame: StereoFrame, step: int = 8) -> np.ndarray:
    """Return (N, 2) float64 left pixels on the floor and seen by the right camera (grid)."""
    return truth.floor_points(frame, step, step // 2)


@dataclass
class FrameRecord:
    """One method's outcome on one frame."""

    speed: float
    floor: str
    sequence: int
    index: int
    method: str
    ok: bool
    error_px: float
    state: str
    warm_start: str
    candidates: int
    time_ms: float
    dropout: bool = False

    @property
    def locked(self) -> bool:
        """Return True if a plane was found within :data:`LOCK_ERROR_PX` of the truth."""
        return self.ok and self.error_px < LOCK_ERROR_PX


def summarise(records: Sequence[FrameRecord]) -> dict[str, float]:
    """Summarise one method at one speed: lock share, wrong locks, re-lock frames, times."""
    by_sequence: dict[int, list[FrameRecord]] = {}
    for rec in records:
        by_sequence.setdefault(rec.sequence, []).append(rec)
    counted = []
    runs: list[int] = []
    for seq in by_sequence.values():
        seq.sort(key=lambda r: r.index)
        flags = [r.locked for r in seq]
        first = flags.index(True) if True in flags else len(flags)
        counted.extend(seq[first:])
        runs.extend(relock_runs(flags, [r.dropout for r in seq]))
    times = np.array([r.time_ms for r in records]) if records else np.zeros(1)
    n = max(len(counted), 1)
    return {
        'frames': float(len(counted)),
        'locked': sum(r.locked for r in counted) / n,
        'wrong': sum(r.ok and not r.locked for r in counted) / n,
        'losses': float(len(runs)),
        'relock_max': float(max(runs)) if runs else 0.0,
        'relock_mean': float(np.mean(runs)) if runs else 0.0,
        'time_median_ms': float(np.median(times)),
        'time_p95_ms': float(np.percentile(times, 95)),
    }


def dropout_frames(n_frames: int, every: int, lengths: Sequence[int]) -> set[int]:
    """Return the frame indices replaced by blank input: a drop-out every ``every`` frames.

    The k-th drop-out starts at ``every * k + every // 2`` and lasts ``lengths[k % len]``
    frames.
    """
    out: set[int] = set()
    if every <= 0 or not lengths:
        return out
    for k, start in enumerate(range(every // 2, n_frames, every)):
        out.update(range(start, min(n_frames, start + lengths[k % len(lengths)])))
    return out


def run(speeds: Sequence[float], n_frames: int, seed: int = 0,
        methods: Sequence[str] = METHODS, keep_every: int = 0, supersample: int = 1,
        dropout_every: int = 0, dropout_lengths: Sequence[int] = (1, 3)
        ) -> tuple[list[FrameRecord], list[tuple[str, np.ndarray]]]:
    """Render the sequences and run every method on every frame.

    Args:
        speeds: Head speeds, degrees per second.
        n_frames: Frames per speed, split over the floors of :data:`FLOORS`.
        seed: Seed of the first sequence.
        methods: Methods to run.
        keep_every: Keep an overlay of the ``prediction`` result every this many frames
            (0: none) for the contact sheet.
        supersample: Rays per pixel along each axis of the renderer.
        dropout_every: Replace both images by blank grey input (a camera drop-out) every this
            many frames (0: never), for ``dropout_lengths`` frames in turn.
        dropout_lengths: Lengths of the drop-outs, frames.

    Returns:
        The per-frame records and ``(label, rgb image)`` overlays.

    """
    records: list[FrameRecord] = []
    sheet: list[tuple[str, np.ndarray]] = []
    jobs = _sequences(speeds, n_frames, seed)
    bar = progress(None, 'head sequences (frames)', total=sum(job[3] for job in jobs),
                   leave=True)
    for speed, floor, sequence, count in jobs:
        frames = head_sequence(count, sequence, HeadMotion.at_speed(speed, RATE_HZ), floor=floor,
                               supersample=supersample)
        blank = dropout_frames(count, dropout_every, dropout_lengths)
        runners = [MethodRunner(m) for m in methods]
        for index, frame in enumerate(frames):
            _run_frame(frame, index, (speed, floor, sequence), runners, index in blank,
                       records, sheet if keep_every and index % keep_every == keep_every // 2
                       else None)
            bar.update(1)
    bar.close()
    return records, sheet


def _sequences(speeds: Sequence[float], n_frames: int, seed: int
               ) -> list[tuple[float, str, int, int]]:
    """Return ``(speed, floor, sequence seed, frames)`` of every sequence to render."""
    jobs = []
    for s_index, speed in enumerate(speeds):
        for f_index, (floor, share) in enumerate(FLOORS):
            count = int(round(share * n_frames)) if f_index < len(FLOORS) - 1 else (
                n_frames - sum(int(round(sh * n_frames)) for _, sh in FLOORS[:-1]))
            if count > 0:
                jobs.append((speed, floor, seed + 10 * s_index + f_index, count))
    return jobs


def _run_frame(frame: StereoFrame, index: int, where: tuple[float, str, int],
               runners: Sequence[MethodRunner], dropout: bool, records: list[FrameRecord],
               sheet: list[tuple[str, np.ndarray]] | None) -> None:
    """Run every method on one frame (blank if ``dropout``); keep an overlay if ``sheet``."""
    speed, floor, sequence = where
    points = floor_points(frame)
    shown = frame
    if dropout:
        grey = np.full_like(frame.left, 128)
        shown = replace(frame, left=grey, right=grey.copy())
    for runner in runners:
        result, ms = runner.process(shown, index)
        error = transfer_error_px(result.homography, frame, points)
        records.append(FrameRecord(speed, floor, sequence, index, runner.method, result.ok,
                                   error, result.state, result.warm_start, result.candidates,
                                   ms, dropout))
        if sheet is not None and runner.method == 'prediction':
            label = (f'{speed:g} deg/s {floor} #{index}: '
                     + (f'{error:.2f} px' if result.ok else result.state))
            sheet.append((label, overlay(frame.left, result.mask)))


def table(records: Sequence[FrameRecord], speeds: Iterable[float],
          methods: Sequence[str] = METHODS) -> tuple[str, dict]:
    """Return the markdown table per speed and method, and the summaries."""
    rows = ['| speed [deg/s] | warm start | frames | locked (< 1 px) | wrong lock | losses | '
            're-lock frames max / mean | time median / p95 [ms] |',
            '|---|---|---|---|---|---|---|---|']
    summaries = {}
    for speed in speeds:
        for method in methods:
            recs = [r for r in records if r.speed == speed and r.method == method]
            if not recs:
                continue
            s = summarise(recs)
            summaries[(speed, method)] = s
            rows.append(f'| {speed:g} | {method} | {int(s["frames"])} | '
                        f'{100 * s["locked"]:.1f} % | {100 * s["wrong"]:.1f} % | '
                        f'{int(s["losses"])} | {s["relock_max"]:.0f} / {s["relock_mean"]:.1f} | '
                        f'{s["time_median_ms"]:.1f} / {s["time_p95_ms"]:.1f} |')
    return '\n'.join(rows) + '\n', summaries


def write_csv(path: Path, records: Sequence[FrameRecord]) -> None:
    """Write every frame record to a CSV file."""
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(['speed_deg_s', 'floor', 'sequence', 'index', 'method', 'ok',
                         'error_px', 'locked', 'state', 'warm_start', 'candidates',
                         'time_ms'])
        for r in records:
            writer.writerow([r.speed, r.floor, r.sequence, r.index, r.method, int(r.ok),
                             f'{r.error_px:.4f}', int(r.locked), r.state, r.warm_start,
                             r.candidates, f'{r.time_ms:.2f}'])


_COLOURS = {'prediction': 'tab:green', 'last': 'tab:orange', 'cold': 'tab:blue'}


def plots(out: Path, records: Sequence[FrameRecord], summaries: dict,
          speeds: Sequence[float], methods: Sequence[str] = METHODS) -> None:
    """Write locked.png, times.png and errors.png."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    _locked_plot(plt, out, summaries, speeds, methods)
    _times_plot(plt, out, summaries, speeds, methods)
    _errors_plot(plt, out, records, speeds, methods)


def _locked_plot(plt: Any, out: Path, summaries: dict, speeds: Sequence[float],
                 methods: Sequence[str]) -> None:
    colours = _COLOURS
    fig, ax = plt.subplots(figsize=(7, 4))
    for method in methods:
        ys = [100 * summaries[(s, method)]['locked'] for s in speeds if (s, method) in summaries]
        ax.plot(speeds[:len(ys)], ys, 'o-', label=method, color=colours.get(method))
    ax.axhline(98, color='grey', linestyle=':', label='98 % target')
    ax.set_xlabel('head speed [deg/s] (pan and tilt, 30 Hz)')
    ax.set_ylabel('frames locked, error < 1 px [%]')
    ax.set_ylim(0, 102)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / 'locked.png', dpi=110)
    plt.close(fig)


def _times_plot(plt: Any, out: Path, summaries: dict, speeds: Sequence[float],
                methods: Sequence[str]) -> None:
    colours = _COLOURS
    fig, ax = plt.subplots(figsize=(7, 4))
    width = 0.8 / max(len(methods), 1)
    xs = np.arange(len(speeds))
    for k, method in enumerate(methods):
        med = [summaries.get((s, method), {}).get('time_median_ms', np.nan) for s in speeds]
        p95 = [summaries.get((s, method), {}).get('time_p95_ms', np.nan) for s in speeds]
        ax.bar(xs + k * width, med, width, label=f'{method} median',
               color=colours.get(method))
        ax.scatter(xs + k * width, p95, marker='_', s=200, color='black',
                   label='p95' if k == 0 else None)
    ax.set_xticks(xs + width * (len(methods) - 1) / 2)
    ax.set_xticklabels([f'{s:g}' for s in speeds])
    ax.set_xlabel('head speed [deg/s]')
    ax.set_ylabel('time per frame [ms]')
    ax.axhline(1e3 / RATE_HZ, color='grey', linestyle=':', label='33 ms (30 Hz)')
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis='y')
    fig.tight_layout()
    fig.savefig(out / 'times.png', dpi=110)
    plt.close(fig)


def _errors_plot(plt: Any, out: Path, records: Sequence[FrameRecord], speeds: Sequence[float],
                 methods: Sequence[str]) -> None:
    colours = _COLOURS
    fast = sorted(speeds)[-2:]
    fig, axes = plt.subplots(len(fast), 1, figsize=(9, 3 * len(fast)), squeeze=False)
    for ax, speed in zip(axes[:, 0], fast):
        recs = [r for r in records if r.speed == speed and r.floor == FLOORS[0][0]]
        for method in methods:
            mine = sorted((r for r in recs if r.method == method), key=lambda r: r.index)
            err = [min(r.error_px, 300.0) if r.ok else np.nan for r in mine]
            ax.semilogy([r.index for r in mine], np.maximum(err, 1e-3), '.-', ms=2, lw=0.7,
                        label=method, color=colours.get(method))
        ax.axhline(LOCK_ERROR_PX, color='grey', linestyle=':')
        ax.set_title(f'{speed:g} deg/s, {FLOORS[0][0]} floor: transfer error '
                     '(gaps: no plane)')
        ax.set_xlabel('frame')
        ax.set_ylabel('error [px]')
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / 'errors.png', dpi=100)
    plt.close(fig)


def contact_sheet(path: Path, sheet: Sequence[tuple[str, np.ndarray]], cols: int = 4,
                  scale: float = 0.4) -> None:
    """Write a grid of labelled overlays (RGB) as a PNG."""
    if not sheet:
        return
    tiles = []
    for label, rgb in sheet:
        small = cv2.resize(rgb, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        small = np.ascontiguousarray(small)
        cv2.putText(small, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (255, 255, 0), 1,
                    cv2.LINE_AA)
        tiles.append(small)
    h, w = tiles[0].shape[:2]
    rows = -(-len(tiles) // cols)
    grid = np.zeros((rows * h, cols * w, 3), np.uint8)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, cols)
        grid[r * h:(r + 1) * h, c * w:(c + 1) * w] = tile
    cv2.imwrite(str(path), cv2.cvtColor(grid, cv2.COLOR_RGB2BGR))


def _parser() -> argparse.ArgumentParser:
    parser = tool_parser(__doc__)
    parser.add_argument('--frames', type=int, default=300,
                        help='frames per speed (default 300)')
    parser.add_argument('--speeds', default=','.join(f'{s:g}' for s in SPEEDS_DEG_S),
                        help='comma-separated head speeds in deg/s')
    parser.add_argument('--methods', default=','.join(METHODS),
                        help='comma-separated warm starts: prediction, last, cold')
    parser.add_argument('--seed', type=int, default=0, help='seed of the first sequence')
    parser.add_argument('--supersample', type=int, default=1,
                        help='rays per pixel along each axis of the renderer (default 1)')
    parser.add_argument('--dropout-every', type=int, default=0,
                        help='blank both images every N frames (camera drop-outs; 0: none)')
    parser.add_argument('--dropout-lengths', default='1,3',
                        help='comma-separated drop-out lengths in frames, used in turn')
    parser.add_argument('--out', default='eval_output/head', help='output folder')
    return parser


def _parse(argv: list[str] | None) -> tuple[argparse.Namespace, list[float], list[str],
                                            list[int]]:
    """Return the arguments, the speeds, the methods and the drop-out lengths, checked."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        speeds = [float(s) for s in args.speeds.split(',') if s.strip()]
    except ValueError:
        parser.error(f'--speeds must be numbers, got {args.speeds!r}')
    methods = [m.strip() for m in args.methods.split(',') if m.strip()]
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        parser.error(f'unknown method {bad[0] if bad else ""!r}; expected {", ".join(METHODS)}')
    if args.supersample < 1:
        parser.error('--supersample must be >= 1')
    if args.frames < 3 or not speeds or any(not 0 <= s <= 1000 for s in speeds):
        parser.error('need --frames >= 3 and speeds in [0, 1000] deg/s')
    try:
        lengths = [int(v) for v in args.dropout_lengths.split(',') if v.strip()]
    except ValueError:
        parser.error(f'--dropout-lengths must be integers, got {args.dropout_lengths!r}')
    if args.dropout_every < 0 or any(v < 1 for v in lengths):
        parser.error('--dropout-every must be >= 0 and drop-out lengths >= 1')
    return args, speeds, methods, lengths


def _header(args: argparse.Namespace, methods: Sequence[str], lengths: Sequence[int]) -> str:
    """Return the summary's heading: the run, the machine and the command."""
    return (f'# Active head evaluation\n\n{args.frames} frames per speed at {RATE_HZ:g} Hz '
            f'(floors: ' + ', '.join(f'{f} {100 * s:.0f} %' for f, s in FLOORS)
            + f'), seed {args.seed}, 640x480 rendered with {args.supersample}x'
            f'{args.supersample} rays per pixel; one thread; machine: {machine_name()}\n\n'
            f'Command: python -m domplane_ros.tools.evaluate_head --frames {args.frames} '
            f'--speeds {args.speeds} --methods {",".join(methods)} --seed {args.seed} '
            f'--supersample {args.supersample}'
            + (f' --dropout-every {args.dropout_every} --dropout-lengths '
               f'{",".join(map(str, lengths))}' if args.dropout_every else '') + '\n\n'
            + ('Drop-outs: both images blank (uniform grey) for the given lengths in turn; '
               'drop-out frames count as not locked; re-lock frames count the frames after '
               'the input came back.\n\n' if args.dropout_every else ''))


def main(argv: list[str] | None = None) -> int:
    """Run the evaluation; print the table; write the outputs."""
    args, speeds, methods, lengths = _parse(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with one_core():
        records, sheet = run(speeds, args.frames, args.seed, methods,
                             keep_every=max(1, args.frames // 3), supersample=args.supersample,
                             dropout_every=args.dropout_every, dropout_lengths=lengths)
    text, summaries = table(records, speeds, methods)
    header = _header(args, methods, lengths)
    (out / 'summary.md').write_text(header + text, encoding='utf-8')
    write_csv(out / 'frames.csv', records)
    plots(out, records, summaries, speeds, methods)
    contact_sheet(out / 'contact_sheet.png', sheet)
    print(header + text)
    print(f'outputs in {out}/')
    return 0


if __name__ == '__main__':
    sys.exit(main())
