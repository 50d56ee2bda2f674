"""The demo: render a stereo sequence, record it as a bag, replay it, and draw what happened.

``python -m domplane_ros.tools.demo --output demo_output`` (``make demo``):

1. renders a short sequence (40 frames, 640x480) of a stereo head moving over a textured floor
   past three boxes, with ground truth (:func:`domplane_ros.sim.generators.scene_sequence`);
2. records it as a rosbag2 bag, ``OUTPUT/input_bag``, with ``sensor_msgs/Image`` mono8 on
   ``/left/image_raw`` and ``/right/image_raw`` at 30 Hz;
3. replays it with plane_replay's code (:func:`domplane_ros.replay.cli.run_replay`) into
   ``OUTPUT/plane_bag`` (``/plane/homography``, ``/plane/mask``, ``/diagnostics``) and
   ``OUTPUT/pairs.csv``;
4. draws ``OUTPUT/contact_sheet.png`` (left images with the mask overlay, each labelled with
   its frame index and transfer error against the true homography), ``OUTPUT/energy_inliers.png``
   (energy per iteration for a few frames; inliers and transfer error per frame) and
   ``OUTPUT/overlay.png`` (one large overlay), and prints a summary.

The output folder is a scratch folder: the demo replaces its own files there and leaves
anything else alone.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import sys
import time
from typing import Any, Sequence

import cv2
from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.legend import legend_strip, text_strip
from domplane_ros.core.mask import overlay
from domplane_ros.errors import BagError, ConfigError
from domplane_ros.params_file import load_params_file
from domplane_ros.replay.cli import run_replay
from domplane_ros.replay.reader import ReplayedFrame
from domplane_ros.replay.report import ReplaySummary
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.model import StereoFrame
from domplane_ros.sim.truth import floor_points, transfer_error_px
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

PROG = 'domplane_ros.tools.demo'
DEMO_OUTPUTS = ('input_bag', 'plane_bag', 'pairs.csv', 'contact_sheet.png',
                'energy_inliers.png', 'overlay.png')
LEFT_TOPIC, RIGHT_TOPIC = '/left/image_raw', '/right/image_raw'
STAMP0_NS = 1_700_000_000_000_000_000
# A seed whose sequence keeps all three boxes in view on a blobby random floor.
DEFAULT_SEED = 28
_SHEET_TILES = 12
_SHEET_COLS = 4
_TRUTH_STRIDE_PX = 4


@dataclass
class DemoFrame:
    """A replayed frame with its ground truth.

    Attributes:
        index: Frame index in the rendered sequence.
        replayed: What the replay made of it.
        truth: The rendered frame (images, true homography, true labels).
        transfer_error_px: Mean distance between the estimated and the true homography's
            images of the truly visible floor pixels (NaN if no plane was found).

    """

    index: int
    replayed: ReplayedFrame
    truth: StereoFrame
    transfer_error_px: float


def transfer_error_vs_truth(homography: np.ndarray | None, truth: StereoFrame,
                            stride: int = _TRUTH_STRIDE_PX) -> float:
    """Return the mean transfer error (px) of a homography over the true floor pixels.

    Args:
        homography: (3, 3) estimated left-to-right homography, or None (gives NaN).
        truth: The rendered frame; its floor pixels that are visible in the right image are
            used, every ``stride``-th row and column.
        stride: Pixel subsampling.

    Returns:
        ``mean ||H x - H_true x||`` in pixels, or NaN.

    """
    points = floor_points(truth, stride)
    if homography is None or points.shape[0] == 0:
        return float('nan')
    return transfer_error_px(homography, truth, points)


def write_stereo_bag(path: Path, frames: Sequence[StereoFrame], storage: str = 'mcap',
                     rate_hz: float = 30.0, stamp0_ns: int = STAMP0_NS) -> list[int]:
    """Record rendered frames as a rosbag2 bag of mono8 ``sensor_msgs/Image``.

    Args:
        path: Bag folder to create (it must not exist).
        frames: The frames.
        storage: ``'mcap'`` or ``'sqlite3'``.
        rate_hz: Frame rate of the stamps.
        stamp0_ns: Stamp of the first frame.

    Returns:
        The stamps (left and right are equal: a triggered stereo head), nanoseconds.

    """
    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    image_type = 'sensor_msgs/msg/Image'
    period_ns = int(round(1e9 / rate_hz))
    stamps = []
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections = [writer.add_connection(topic, image_type, typestore=store)
                       for topic in (LEFT_TOPIC, RIGHT_TOPIC)]
        for i, frame in enumerate(frames):
            stamp = stamp0_ns + i * period_ns
            stamps.append(stamp)
            for connection, gray, frame_id in ((connections[0], frame.left, 'left_camera'),
                                               (connections[1], frame.right, 'right_camera')):
                header = types['std_msgs/msg/Header'](
                    stamp=types['builtin_interfaces/msg/Time'](sec=stamp // 1_000_000_000,
                                                               nanosec=stamp % 1_000_000_000),
                    frame_id=frame_id)
                height, width = gray.shape
                msg = types[image_type](header=header, height=height, width=width,
                                        encoding='mono8', is_bigendian=0, step=width,
                                        data=np.ascontiguousarray(gray).reshape(-1))
                writer.write(connection, stamp, store.serialize_cdr(msg, image_type))
    return stamps


# --------------------------------------------------------------------------------------------
# Pictures.


def _points(frame: DemoFrame) -> tuple[np.ndarray | None, np.ndarray | None]:
    result = frame.replayed.result
    pts = result.left_points
    inliers = getattr(result.estimate, 'inliers', None)
    if not result.ok or inliers is None:
        return None, pts
    return pts[inliers], pts[~inliers]


def overlay_rgb(frame: DemoFrame) -> np.ndarray:
    """Return the (H, W, 3) RGB overlay of a frame: mask tint, matched and unmatched corners."""
    inliers, outliers = _points(frame)
    return overlay(frame.replayed.left, frame.replayed.result.mask, inliers, outliers)


def frame_label(frame: DemoFrame) -> str:
    """Return the one-line label of a frame: index, error vs truth (or why it failed)."""
    result = frame.replayed.result
    if not result.ok:
        return f'frame {frame.index}: no plane ({result.reason})'
    return (f'frame {frame.index}: err {frame.transfer_error_px:.2f} px, '
            f'{result.n_inliers} matched')


def contact_sheet(frames: Sequence[DemoFrame], tiles: int = _SHEET_TILES,
                  cols: int = _SHEET_COLS, tile_width: int = 320) -> np.ndarray:
    """Return a grid of labelled overlays of frames spread over the sequence.

    Args:
        frames: The replayed frames.
        tiles: How many frames to show (evenly spaced, first and last included).
        cols: Columns of the grid.
        tile_width: Width of one tile in pixels (the overlay is resized to it).

    Returns:
        (H, W, 3) uint8 RGB image.

    """
    picks = sorted({int(round(v)) for v in np.linspace(0, len(frames) - 1, min(tiles,
                                                                               len(frames)))})
    cells = []
    for k in picks:
        rgb = overlay_rgb(frames[k])
        height, width = rgb.shape[:2]
        tile_height = int(round(height * tile_width / width))
        small = cv2.resize(rgb, (tile_width, tile_height), interpolation=cv2.INTER_AREA)
        cells.append((text_strip(tile_width, frame_label(frames[k]), 0.45, min_height=24),
                      small))
    # Every label in full: a long one wraps, and every label strip of the sheet grows with it.
    label_h = max(label.shape[0] for label, _ in cells)
    cells = [np.vstack([np.pad(label, ((0, label_h - label.shape[0]), (0, 0), (0, 0)),
                               mode='edge'), small]) for label, small in cells]
    blank = np.full_like(cells[0], 255)
    rows = []
    for start in range(0, len(cells), cols):
        row = cells[start:start + cols]
        row += [blank] * (cols - len(row))
        rows.append(np.hstack([np.pad(c, ((2, 2), (2, 2), (0, 0)), constant_values=255)
                               for c in row]))
    sheet = np.vstack(rows)
    title = legend_strip(sheet.shape[1], 'domplane_ros demo: left images, mask overlay', 0.55)
    return np.vstack([title, sheet])


def big_overlay(frame: DemoFrame) -> np.ndarray:
    """Return one large labelled overlay (the README picture)."""
    rgb = overlay_rgb(frame)
    width = rgb.shape[1]
    scale = 0.6 if width >= 600 else 0.45
    top = legend_strip(width, 'dominant plane', scale * 0.85)
    result = frame.replayed.result
    caption = frame_label(frame)
    if result.ok:
        caption = (f'frame {frame.index}: transfer error {frame.transfer_error_px:.2f} px vs '
                   f'truth; {result.n_inliers} of {result.left_points.shape[0]} corners '
                   'matched on the plane')
    return np.vstack([top, rgb, text_strip(width, caption, scale * 0.8, min_height=30)])


def energy_inliers_figure(frames: Sequence[DemoFrame], path: Path) -> None:
    """Plot energy per iteration for a few frames, and inliers and error per frame.

    Args:
        frames: The replayed frames.
        path: PNG file to write.

    """
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    fig, (ax_e, ax_i) = plt.subplots(1, 2, figsize=(13, 4.8), dpi=100)
    _energy_panel(ax_e, frames)
    _inliers_panel(ax_i, frames)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _energy_panel(ax_e: Any, frames: Sequence[DemoFrame]) -> None:
    """Draw the energy per local step of up to four frames spread over the sequence."""
    from matplotlib.ticker import MaxNLocator

    ok_frames = [f for f in frames if len(f.replayed.result.estimate.energy_trace)]
    picks = []
    if ok_frames:
        picks = [ok_frames[int(round(v))] for v in np.linspace(0, len(ok_frames) - 1, 4)]
        picks = list({f.index: f for f in picks}.values())
    stage_changes = False
    for frame in picks:
        estimate = frame.replayed.result.estimate
        trace = np.asarray(estimate.energy_trace, dtype=np.float64)
        how = 'from the prior' if frame.replayed.result.reinitialised else 'warm start'
        line, = ax_e.plot(np.arange(trace.size), trace, marker='.', markersize=4,
                          label=f'frame {frame.index} ({how}, {estimate.iterations} '
                                'iterations)')
        stages = np.asarray(getattr(estimate, 'stage_trace', np.zeros(0)))
        if stages.size == trace.size and stages.size:
            for k in np.nonzero(np.diff(stages))[0]:
                stage_changes = True
                ax_e.axvline(k + 0.5, color=line.get_color(), alpha=0.3, linewidth=0.8)
    ax_e.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax_e.set_xlabel('local step')
    ax_e.set_ylabel('joint energy')
    ax_e.set_title('Energy per iteration' + (' (faint lines: GNC scale changes)'
                                             if stage_changes else ''))
    ax_e.grid(True, alpha=0.3)
    if picks:
        ax_e.legend(fontsize=8)


def _inliers_panel(ax_i: Any, frames: Sequence[DemoFrame]) -> None:
    """Draw the inliers (bars) and the transfer error against the truth (line) per frame."""
    index = np.array([f.index for f in frames])
    inliers = np.array([f.replayed.result.n_inliers for f in frames])
    errors = np.array([f.transfer_error_px for f in frames])
    failed = np.array([not f.replayed.result.ok for f in frames])
    ax_i.bar(index, inliers, color='tab:blue', alpha=0.6, label='inlier corners')
    ax_i.set_xlabel('frame')
    ax_i.set_ylabel('inlier corners', color='tab:blue')
    ax_i.set_title('Inliers and transfer error vs ground truth per frame')
    ax_t = ax_i.twinx()
    ax_t.plot(index, errors, color='tab:red', marker='o', markersize=3,
              label='transfer error vs truth')
    if failed.any():
        ax_t.plot(index[failed], np.zeros(failed.sum()), 'kx', markersize=8,
                  label='no plane')
    ax_t.set_ylabel('mean transfer error [px]', color='tab:red')
    finite = errors[np.isfinite(errors)]
    ax_t.set_ylim(0, max(1.0, 1.3 * float(finite.max())) if finite.size else 1.0)
    handles = ax_i.get_legend_handles_labels()
    more = ax_t.get_legend_handles_labels()
    ax_i.set_ylim(0, 1.3 * max(1, int(inliers.max())))
    ax_i.legend(handles[0] + more[0], handles[1] + more[1], fontsize=8, loc='upper left',
                ncol=3)


def _save_rgb(path: Path, rgb: np.ndarray) -> None:
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f'could not write {path}')


# --------------------------------------------------------------------------------------------
# The run.


def _clear_outputs(output: Path) -> list[str]:
    """Remove the demo's own outputs from a previous run; return their names."""
    removed = []
    for name in DEMO_OUTPUTS:
        path = output / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
        else:
            continue
        removed.append(name)
    return removed


def summary_paragraph(frames: Sequence[DemoFrame], summary: ReplaySummary, render_s: float,
                      size: tuple[int, int], floor: str) -> str:
    """Return the one-paragraph summary of a demo run."""
    errors = np.array([f.transfer_error_px for f in frames], dtype=np.float64)
    finite = errors[np.isfinite(errors)]
    n = len(frames)
    found = sum(f.replayed.result.ok for f in frames)
    err_text = (f'mean transfer error against the true homography {finite.mean():.2f} px '
                f'(median {np.median(finite):.2f}, max {finite.max():.2f})' if finite.size
                else 'no transfer error (no plane found)')
    return (f'Rendered {n} stereo pairs ({size[0]}x{size[1]}, {floor} floor, '
            f'{len(frames[0].truth.boxes) if frames else 0} boxes) in {render_s:.1f} s. '
            f'plane_replay paired {summary.pairs} of them and processed {summary.processed} '
            f'in {summary.wall_s:.1f} s ({summary.rate_pairs_per_s:.1f} pairs/s): plane found '
            f'in {found}/{n} ({100.0 * found / max(n, 1):.0f} %), estimator converged in '
            f'{summary.percent(summary.converged):.0f} %, {err_text}; latency per pair median '
            f'{summary.latency_percentile(50):.1f} ms, p95 {summary.latency_percentile(95):.1f} '
            'ms.')


def run_demo(output: Path, n_frames: int = 40, seed: int = DEFAULT_SEED, width: int = 640,
             height: int = 480, storage: str = 'mcap', floor: str = 'random',
             config: PlaneNodeConfig | None = None, progress: bool = False) -> dict:
    """Run the demo into ``output``; see the module docstring.

    Args:
        output: Output folder (created; the demo's own files in it are replaced).
        n_frames: Frames to render.
        seed: Scene seed.
        width: Image width in pixels.
        height: Image height in pixels.
        storage: Storage of the input bag, ``'mcap'`` or ``'sqlite3'``.
        floor: Floor texture kind (see :data:`domplane_ros.sim.textures.FLOOR_KINDS`).
        config: Pipeline configuration (default: the node's defaults).
        progress: Show the replay's progress bar.

    Returns:
        A dict with ``frames`` (the :class:`DemoFrame` list), ``summary`` (the replay's
        :class:`~domplane_ros.replay.report.ReplaySummary`), ``paths`` (name to written path),
        ``removed`` (outputs of an earlier run that were replaced), ``render_s`` and
        ``paragraph`` (the printed summary).

    """
    output.mkdir(parents=True, exist_ok=True)
    removed = _clear_outputs(output)
    t0 = time.perf_counter()
    rendered = scene_sequence(n_frames, seed=seed, width=width, height=height, floor=floor,
                              n_boxes=3)
    render_s = time.perf_counter() - t0
    input_bag = output / 'input_bag'
    stamps = write_stereo_bag(input_bag, rendered, storage)
    by_stamp = {stamp: i for i, stamp in enumerate(stamps)}
    frames: list[DemoFrame] = []

    def collect(replayed: ReplayedFrame) -> None:
        i = by_stamp[replayed.pair.left_stamp_ns]
        truth = rendered[i]
        frames.append(DemoFrame(i, replayed, truth,
                                transfer_error_vs_truth(replayed.result.homography, truth)))

    summary = run_replay(input_bag, output / 'plane_bag', config, LEFT_TOPIC, RIGHT_TOPIC,
                         force=True, csv_path=output / 'pairs.csv', progress=progress,
                         on_frame=collect)
    paths = {name: output / name for name in DEMO_OUTPUTS}
    if frames:
        _save_rgb(paths['contact_sheet.png'], contact_sheet(frames))
        energy_inliers_figure(frames, paths['energy_inliers.png'])
        # The README picture: the found plane with the most obstacle pixels in view.
        candidates = [f for f in frames if f.replayed.result.ok] or frames
        best = max(candidates, key=lambda f: int(np.count_nonzero(f.truth.obstacle_left)))
        _save_rgb(paths['overlay.png'], big_overlay(best))
    paragraph = summary_paragraph(frames, summary, render_s, (width, height),
                                  rendered[0].floor)
    return {'frames': frames, 'summary': summary, 'paths': paths, 'removed': removed,
            'render_s': render_s, 'paragraph': paragraph}


_NOTES = {
    'input_bag': f'recorded stereo input ({{storage}}: {LEFT_TOPIC}, {RIGHT_TOPIC})',
    'plane_bag': 'replay output (/plane/homography, /plane/mask, /diagnostics)',
    'pairs.csv': 'one row per pair (plane_replay --csv)',
    'contact_sheet.png': 'left images with the mask overlay, error vs truth',
    'energy_inliers.png': 'energy per iteration; inliers and error per frame',
    'overlay.png': 'one large overlay',
}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=f'python -m {PROG}',
        description='Render a stereo sequence with ground truth, record it as a rosbag2 bag, '
                    'replay it with plane_replay and draw the results.')
    parser.add_argument('--output', default='demo_output',
                        help='output folder; the demo replaces its own files there '
                             '(default: %(default)s)')
    parser.add_argument('--frames', type=int, default=40, help='frames (default: 40)')
    parser.add_argument('--seed', type=int, default=DEFAULT_SEED,
                        help='scene seed (default: %(default)s)')
    parser.add_argument('--width', type=int, default=640, help='image width (default: 640)')
    parser.add_argument('--height', type=int, default=480, help='image height (default: 480)')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap',
                        help='storage of the recorded input bag (default: mcap)')
    parser.add_argument('--params-file', metavar='YAML',
                        help="plane_node parameters file (default: the node's defaults)")
    return parser


def _checked(args: argparse.Namespace) -> tuple[PlaneNodeConfig | None, Path] | str:
    """Return the configuration and the output folder, or what is wrong with the arguments."""
    if args.frames < 2 or args.width < 64 or args.height < 48:
        return 'need --frames >= 2 and an image of at least 64x48'
    try:
        config = load_params_file(args.params_file) if args.params_file else None
    except ConfigError as err:
        return str(err)
    output = Path(args.output)
    if output.exists() and not output.is_dir():
        return f'output {str(output)!r} exists and is not a folder'
    return config, output


def main(argv: list[str] | None = None) -> int:
    """Run the demo from the command line.

    Args:
        argv: Arguments without the program name (default: ``sys.argv[1:]``).

    Returns:
        0 on success, 2 on a bad argument or params file, 1 if the replay failed.

    """
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:
        return int(exc.code) if isinstance(exc.code, int) else 2
    checked = _checked(args)
    if isinstance(checked, str):
        print(f'{PROG}: error: {checked}', file=sys.stderr)
        return 2
    config, output = checked
    existing = [name for name in DEMO_OUTPUTS if (output / name).exists()]
    if existing:
        print(f'Refreshing the previous demo outputs in {output}: {", ".join(existing)} '
              '(the folder is scratch; other files in it are left alone).')
    print(f'Rendering {args.frames} stereo frames ({args.width}x{args.height}, seed '
          f'{args.seed}) ...', flush=True)
    try:
        run = run_demo(output, args.frames, args.seed, args.width, args.height, args.storage,
                       config=config, progress=sys.stderr.isatty())
    except BagError as err:
        print(f'{PROG}: error: {err}', file=sys.stderr)
        return 1
    print('\n'.join(run['summary'].lines()))
    print('\nWrote:')
    for name, path in run['paths'].items():
        if path.exists():
            print(f'  {os.fspath(path):<40} {_NOTES[name].format(storage=args.storage)}')
    print()
    print(run['paragraph'])
    return 0


if __name__ == '__main__':
    sys.exit(main())
