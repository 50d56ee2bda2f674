"""Evaluation of line features: points only, lines only, both, and ORB + MAGSAC, side by side.

Run ``python -m domplane_ros.tools.evaluate_lines [--scenes N] [--data DIR] [--out DIR]``.

Every pair is solved in the same process by four methods: the product's pipeline
(:class:`~domplane_ros.stream.pipeline.PlanePipeline`, cold start from the prior) with
``features.kind`` = ``points``, ``lines`` and ``both``, and the correspondence baseline of
:mod:`domplane_ros.tools.evaluation.methods` (ORB 2000, cross-checked Hamming matches,
USAC_MAGSAC at 1 px). All single-threaded. Scene classes:

* rendered low-texture floors (:data:`~domplane_ros.sim.textures.PLAIN_FLOOR_KINDS`:
  ``tiles_plain`` and ``planks_plain``, flat albedo with faint noise between contrasting
  joints), and the textured ``random`` floor as the control; ``--scenes`` seeds each
  (``random_scene(seed, floor=kind)``: random set-up within the default prior, 1-5 boxes,
  horizon or wall). The error is the mean transfer error over the floor pixels seen by both
  cameras (every 4th pixel); a scene is solved when it is below 1 px;
* KITTI 2015 000046 (road error against the ground-truth disparity plane, road ROI, as in
  :mod:`domplane_ros.tools.evaluate`) and the OpenCV chessboard pairs (error on the board
  corners; solved below 2 px), from ``--data`` (default ``../shared/data`` or ``test/data``).

Outputs in ``--out`` (default ``eval_output/lines/``): ``summary.md`` (the table, also on
stdout), ``results.csv`` (one row per pair and method), ``success.png`` (success rate per
method and class, and the error distributions) and ``contact_sheet.png`` (low-texture scenes:
points only against both, with inlier corners and segments drawn).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field, replace
import math
from pathlib import Path
import sys
import time
from typing import Any, Sequence

from domplane_ros.config import FeatureConfig, one_shot_search, PlaneNodeConfig
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.mask import overlay
from domplane_ros.sim.generators import random_scene, RENDERED_PRIOR
from domplane_ros.sim.textures import PLAIN_FLOOR_KINDS
from domplane_ros.sim.truth import floor_points
from domplane_ros.stream.pipeline import debug_overlay, FrameResult, PlanePipeline
from domplane_ros.tools.common import machine_name, one_core, progress, tool_parser
from domplane_ros.tools.evaluation.datasets import (CHESSBOARD_PRIOR, CHESSBOARD_TARGET_PX,
                                                    KITTI_PRIOR, KITTI_ROI, SOLVED_PX)
from domplane_ros.tools.evaluation.methods import run_orb_magsac
from domplane_ros.tools.evaluation.references import (chessboard_pairs, chessboards,
                                                      default_data_dir, KITTI_DIR, kitti_reference,
                                                      mean_transfer_px, OPENCV_DIR, read_gray)
import numpy as np

METHODS = ('points', 'lines', 'both', 'orb_magsac')
METHOD_NAMES = {'points': 'points only', 'lines': 'lines only', 'both': 'points + lines',
                'orb_magsac': 'ORB + MAGSAC'}
RENDERED_CLASSES = PLAIN_FLOOR_KINDS + ('random',)
COLOURS = {'points': 'tab:blue', 'lines': 'tab:purple', 'both': 'tab:green',
           'orb_magsac': 'tab:orange'}
ERROR_CAP_PX = 300.0


@dataclass
class LineCase:
    """One pair solved by every method.

    Attributes:
        scene_class: ``tiles_plain``, ``planks_plain``, ``random``, ``kitti`` or
            ``chessboards``.
        pair: Seed or pair name.
        left: (H, W) uint8 left image, for the pictures.
        errors: Mean transfer error per method, pixels (inf on failure).
        times_ms: Time per method (cold start for ours), milliseconds.
        warm_ms: Ours only: time on the same pair again, warm-started from the cold result.
        inliers: Inlier features (ours: corners + segments) or matches (baseline) per method.
        features: Left corners + segments (ours) or matches (baseline) per method.
        results: The pipeline's results per method (ours only), for the pictures.
        solved_px: Error below which the pair counts as solved.
    """

    scene_class: str
    pair: str
    left: np.ndarray
    errors: dict[str, float] = field(default_factory=dict)
    times_ms: dict[str, float] = field(default_factory=dict)
    warm_ms: dict[str, float] = field(default_factory=dict)
    inliers: dict[str, int] = field(default_factory=dict)
    features: dict[str, str] = field(default_factory=dict)
    results: dict[str, FrameResult] = field(default_factory=dict)
    solved_px: float = SOLVED_PX

    def solved(self, method: str) -> bool:
        """Return whether ``method``'s error is below the class's success threshold."""
        return self.errors[method] < self.solved_px


def run_methods(case: LineCase, left: np.ndarray, right: np.ndarray,
                config: PlaneNodeConfig, points: np.ndarray, target: np.ndarray,
                keep_results: bool = False) -> LineCase:
    """Solve one pair with every method and score it on ``points`` -> ``target``.

    Args:
        case: The case to fill.
        left: (H, W) uint8 left image.
        right: (H, W) uint8 right image.
        config: Pipeline configuration (prior, ROI); ``features.kind`` is set per method.
        points: (N, 2) float64 reference left pixels.
        target: (N, 2) float64 their true right positions.
        keep_results: Keep the pipeline results (for the contact sheet).

    Returns:
        ``case``, filled.

    """
    for kind in METHODS[:3]:
        # A single pair gets the whole prior search at once (not spread over frames).
        cfg = one_shot_search(replace(config, features=replace(config.features, kind=kind)))
        pipeline = PlanePipeline(cfg)
        start = time.perf_counter()
        result = pipeline.process(left, right, 0)
        middle = time.perf_counter()
        pipeline.process(left, right, 1)
        case.times_ms[kind] = 1e3 * (middle - start)
        case.warm_ms[kind] = 1e3 * (time.perf_counter() - middle)
        case.errors[kind] = mean_transfer_px(result.homography, points, target)
        case.inliers[kind] = result.n_inliers if result.ok else 0
        case.features[kind] = f'{result.left_points.shape[0]}+{result.left_lines.shape[0]}'
        if keep_results:
            case.results[kind] = result
    orb = run_orb_magsac(left, right, config.features.roi, repeats=1)
    case.times_ms['orb_magsac'] = orb.time_ms
    case.warm_ms['orb_magsac'] = math.nan
    case.errors['orb_magsac'] = mean_transfer_px(orb.homography, points, target)
    case.inliers['orb_magsac'] = orb.n_inliers
    case.features['orb_magsac'] = str(orb.n_points)
    return case


def evaluate_rendered(n_scenes: int, classes: Sequence[str] = RENDERED_CLASSES,
                      first_seed: int = 0) -> list[LineCase]:
    """Solve ``n_scenes`` rendered scenes per floor class with every method."""
    config = PlaneNodeConfig(prior=RENDERED_PRIOR)
    jobs = [(kind, seed) for kind in classes
            for seed in range(first_seed, first_seed + n_scenes)]
    cases = []
    for kind, seed in progress(jobs, 'rendered scenes'):
        frame = random_scene(seed, floor=kind)
        points = floor_points(frame, step=4)
        target = apply_homography(frame.homography, points)
        case = LineCase(kind, str(seed), frame.left)
        cases.append(run_methods(case, frame.left, frame.right, config, points, target,
                                 keep_results=kind in PLAIN_FLOOR_KINDS and seed < 12))
    return cases


def evaluate_real(data: Path) -> list[LineCase]:
    """Solve KITTI 000046 and the chessboard pairs found under ``data``."""
    cases = []
    kitti = data / KITTI_DIR
    if kitti.is_dir():
        left = read_gray(kitti / 'left.png')
        right = read_gray(kitti / 'right.png')
        ref = kitti_reference(kitti)
        ys, xs = np.nonzero(ref.road)
        points = np.stack([xs, ys], axis=1).astype(np.float64)
        target = apply_homography(ref.plane.homography(), points)
        config = PlaneNodeConfig(features=FeatureConfig(roi=KITTI_ROI), prior=KITTI_PRIOR)
        cases.append(run_methods(LineCase('kitti', '000046', left), left, right, config,
                                 points, target, keep_results=True))
    boards = data / OPENCV_DIR
    if boards.is_dir():
        config = PlaneNodeConfig(prior=CHESSBOARD_PRIOR)
        numbers = progress(chessboard_pairs(boards), 'chessboards')
        for number, left, right, src, dst in chessboards(boards, numbers):
            case = LineCase('chessboards', number, left, solved_px=CHESSBOARD_TARGET_PX)
            cases.append(run_methods(case, left, right, config, src, dst))
    return cases


# --------------------------------------------------------------------------------------------
# Tables and pictures.


def summary_rows(cases: Sequence[LineCase]) -> list[list[str]]:
    """Return one row per scene class and method: solved, errors, time."""
    rows = []
    classes = list(dict.fromkeys(c.scene_class for c in cases))
    for scene_class in classes:
        group = [c for c in cases if c.scene_class == scene_class]
        for method in METHODS:
            errors = np.array([c.errors[method] for c in group])
            solved = np.array([c.solved(method) for c in group])
            good = errors[solved]
            times = np.array([c.times_ms[method] for c in group])
            warm = np.array([c.warm_ms[method] for c in group])
            rows.append([
                scene_class.replace('_', ' '), METHOD_NAMES[method],
                f'{int(solved.sum())} / {len(group)} ({100.0 * solved.mean():.0f} %)',
                f'{np.median(good):.2f}' if good.size else '-',
                _fmt_px(float(np.median(errors))),
                f'{np.median(times):.0f} (p95 {np.percentile(times, 95):.0f})',
                '-' if np.all(np.isnan(warm)) else
                f'{np.nanmedian(warm):.1f} (p95 {np.nanpercentile(warm, 95):.1f})'])
    return rows


def _fmt_px(value: float) -> str:
    return 'failed' if not math.isfinite(value) else f'{value:.2f}'


def markdown_table(rows: Sequence[Sequence[str]]) -> str:
    """Return the summary rows as a markdown table."""
    header = ['scene class', 'method', 'solved', 'error of solved, median px',
              'error, median px', 'cold time, median ms', 'warm time, median ms']
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(row) + ' |' for row in rows]
    return '\n'.join(lines) + '\n'


def aim_text(cases: Sequence[LineCase]) -> str:
    """Say whether points + lines solved strictly more low-texture scenes than points alone.

    And whether it lost none on the textured control (``random``).
    """
    low = [c for c in cases if c.scene_class in PLAIN_FLOOR_KINDS]
    control = [c for c in cases if c.scene_class == 'random']
    both_low = sum(c.solved('both') for c in low)
    pts_low = sum(c.solved('points') for c in low)
    both_ctl = sum(c.solved('both') for c in control)
    pts_ctl = sum(c.solved('points') for c in control)
    lost = sum(c.solved('points') and not c.solved('both') for c in low)
    met = both_low > pts_low and both_ctl >= pts_ctl
    return (f'Aim {"met" if met else "MISSED"}: low-texture scenes solved by points + lines '
            f'{both_low} / {len(low)} vs points only {pts_low} / {len(low)} (points + lines '
            f'loses {lost} that points solve); textured control {both_ctl} / {len(control)} vs '
            f'{pts_ctl} / {len(control)}.')


def write_csv(path: Path, cases: Sequence[LineCase]) -> None:
    """Write one row per pair and method."""
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(['scene_class', 'pair', 'method', 'error_px', 'solved', 'time_ms',
                         'warm_ms', 'inliers', 'features'])
        for c in cases:
            for m in METHODS:
                writer.writerow([c.scene_class, c.pair, m, f'{c.errors[m]:.4f}',
                                 int(c.solved(m)), f'{c.times_ms[m]:.2f}',
                                 f'{c.warm_ms[m]:.2f}', c.inliers[m], c.features[m]])


def success_plot(path: Path, cases: Sequence[LineCase]) -> None:
    """Write the success-rate bars and the error box plots per class and method."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    classes = list(dict.fromkeys(c.scene_class for c in cases))
    fig, (ax_ok, ax_err) = plt.subplots(1, 2, figsize=(15, 5))
    width = 0.8 / len(METHODS)
    for k, method in enumerate(METHODS):
        offset = (k - (len(METHODS) - 1) / 2) * width
        rates, errors = [], []
        for scene_class in classes:
            group = [c for c in cases if c.scene_class == scene_class]
            rates.append(100.0 * np.mean([c.solved(method) for c in group]))
            values = np.array([c.errors[method] for c in group])
            errors.append(np.minimum(np.where(np.isfinite(values), values, ERROR_CAP_PX),
                                     ERROR_CAP_PX))
        pos = np.arange(len(classes)) + offset
        ax_ok.bar(pos, rates, width * 0.9, color=COLOURS[method], label=METHOD_NAMES[method])
        box = ax_err.boxplot(errors, positions=pos, widths=0.85 * width, patch_artist=True,
                             showfliers=False)
        for patch in box['boxes']:
            patch.set_facecolor(COLOURS[method])
            patch.set_alpha(0.5)
        for i, values in enumerate(errors):
            jitter = np.random.default_rng(i).uniform(-0.3, 0.3, values.size) * width
            ax_err.scatter(pos[i] + jitter, values, s=6, color=COLOURS[method], zorder=3)
    labels = [f'{c.replace("_", " ")}\n(n={sum(x.scene_class == c for x in cases)})'
              for c in classes]
    for ax in (ax_ok, ax_err):
        ax.set_xticks(range(len(classes)))
        ax.set_xticklabels(labels, fontsize=8)
    ax_ok.set_ylabel('solved, % (rendered < 1 px, KITTI < 1 px, chessboards < 2 px)')
    ax_ok.set_ylim(0, 105)
    ax_ok.legend(fontsize=8)
    ax_ok.set_title('success rate per scene class')
    ax_err.set_yscale('log')
    ax_err.axhline(1.0, color='grey', lw=0.8, ls='--')
    ax_err.set_ylabel(f'mean transfer error, px (failures at {ERROR_CAP_PX:g})')
    ax_err.set_title('errors (cold start from the prior)')
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def pick_cases(cases: Sequence[LineCase], per_class: int = 4) -> list[LineCase]:
    """Pick low-texture cases for the contact sheet: where points + lines and points differ.

    Per class: scenes solved by points + lines but not by points first, then scenes that
    points + lines fails (so the sheet shows failures too), then the rest; and KITTI.
    """
    picked = []
    for scene_class in PLAIN_FLOOR_KINDS + ('kitti',):
        group = [c for c in cases if c.scene_class == scene_class and c.results]
        wins = [c for c in group if c.solved('both') and not c.solved('points')]
        fails = [c for c in group if not c.solved('both')]
        rest = [c for c in group if c not in wins and c not in fails]
        count = 1 if scene_class == 'kitti' else per_class
        picked += (wins[:count - 1] + fails[:1] + wins[count - 1:] + rest)[:count]
    return picked


def contact_sheet(path: Path, cases: Sequence[LineCase]) -> None:
    """Write points-only vs points + lines overlays for low-texture scenes and KITTI."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    shown = pick_cases(cases)
    if not shown:
        return
    fig, axes = plt.subplots(len(shown), 2, figsize=(10, 3.3 * len(shown) + 0.5),
                             squeeze=False)
    for row, case in zip(axes, shown):
        for ax, method in zip(row, ('points', 'both')):
            result = case.results[method]
            if result.ok:
                image = debug_overlay(case.left, result)
            else:
                image = overlay(case.left, np.zeros_like(case.left), None,
                                result.left_points, None, result.left_lines)
            ax.imshow(image)
            ax.set_axis_off()
            ax.set_title(f'{case.scene_class} {case.pair}, {METHOD_NAMES[method]}: '
                         f'{_fmt_px(case.errors[method])} px, {case.inliers[method]} inliers',
                         fontsize=9)
    fig.suptitle('green = plane, red = obstacle; cyan = corners (o) and segments matched on '
                 'the plane, magenta = unmatched', fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.4 / (3.3 * len(shown) + 0.5)))
    fig.savefig(path, dpi=80)
    plt.close(fig)


# --------------------------------------------------------------------------------------------
# Main.


def main(argv: list[str] | None = None) -> int:
    """Run the evaluation and write the outputs."""
    parser = tool_parser(__doc__, prog='python -m domplane_ros.tools.evaluate_lines')
    parser.add_argument('--scenes', type=int, default=40,
                        help='rendered scenes per floor class (default 40)')
    parser.add_argument('--first-seed', type=int, default=0)
    parser.add_argument('--data', type=Path, default=None,
                        help='folder with kitti2015_000046/ and opencv_samples/ '
                             '(default ../shared/data, else test/data)')
    parser.add_argument('--out', type=Path, default=Path('eval_output') / 'lines')
    args = parser.parse_args(argv)
    if args.scenes < 0:
        parser.error('--scenes must be >= 0')
    args.out.mkdir(parents=True, exist_ok=True)
    data = args.data or default_data_dir()
    with one_core():
        cases: list[Any] = evaluate_rendered(args.scenes, first_seed=args.first_seed)
        cases += evaluate_real(data)
    table = markdown_table(summary_rows(cases))
    aim = aim_text(cases)
    text = (f'Line features, {machine_name()}, one thread; cold start from the prior; '
            f'rendered scenes solved below {SOLVED_PX:g} px, chessboards below '
            f'{CHESSBOARD_TARGET_PX:g} px; data {data}.\n\n{table}\n{aim}\n')
    print(text)
    (args.out / 'summary.md').write_text(text, encoding='utf-8')
    write_csv(args.out / 'results.csv', cases)
    success_plot(args.out / 'success.png', cases)
    contact_sheet(args.out / 'contact_sheet.png', cases)
    print(f'wrote {args.out}/summary.md, results.csv, success.png, contact_sheet.png')
    return 0


if __name__ == '__main__':
    sys.exit(main())
