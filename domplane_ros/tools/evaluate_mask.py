"""Measure the ground/obstacle mask: residual parallax (now) against local NCC (before), one run.

Run ``python -m domplane_ros.tools.evaluate_mask [--scenes N] [--held-out] [--indoor N]
[--plain N]
[--data DIR] [--out DIR] [--repeats R] [--baseline FILE]``. The masks run in the same process
on the same images:

* ``parallax``: :func:`~domplane_ros.core.mask.parallax_mask` with the documented defaults
  (``MaskConfig()``) and the prior's focal range (the default prior's on rendered scenes, the
  KITTI prior's on KITTI);
* ``ncc``: the mask before issue 12 (:mod:`domplane_ros.tools.evaluation.ncc_mask`);
* ``parallax, min height 0.05``: the parallax mask with ``mask.min_obstacle_height`` 0.05
  instead of 0.1 (more pixels unknown, thinner bottoms of walls and furniture marked plane);
* with ``--baseline FILE``, ``baseline``: the ``parallax_mask`` of another version of
  ``core/mask.py`` (``git show COMMIT:domplane_ros/core/mask.py > FILE``), with the defaults,
  to compare a change before and after in one run; ``FILE`` may be a folder holding that
  ``mask.py`` and the same version's ``residual.py``, ``occlusion.py``, ``parallax.py``
  (:func:`load_baseline`).

Data, each scored with the plane homography named in the table:

* **rendered**: :func:`~domplane_ros.sim.random_scene` seeds ``0 .. N-1`` (the tuning set) or,
  with ``--held-out``, ``1000 .. 1000+N-1`` (not looked at while tuning), true homography.
  Plane truth = floor seen by both cameras, obstacle truth = box pixels. Figures per scene,
  medians over scenes: plane IoU, obstacle recall (also over the box pixels the right camera
  sees, the renderer's ``obstacle_hidden``) and precision, true ground marked obstacle,
  and floor hidden from the right camera by a box (the renderer's ``occluded_in_right``)
  marked unknown and marked obstacle (over the scenes that have such floor), and box pixels
  marked plane.
* **plain boxes**: the same seeds rendered again with plain box faces (``box_contrast`` 0 on
  even seeds, 0.1, weakly textured, on odd ones; every other choice the same), ``--plain N``
  of them (default: as many as ``--scenes``): the rendered figures, and the box pixels marked
  plane (median and worst scene): a plain face cannot be measured, and must not be filled
  as plane.
* **KITTI 2015 000046**: road = ground-truth disparity pixels within 1 px of the robust road
  plane, off-road = pixels more than 1 px off it (the issue's labels); scored with the
  reference homography (from that plane) and with the homography our pipeline estimates (the
  documented KITTI prior and ROI).
* **indoor**: :func:`~domplane_ros.sim.generators.indoor_scene`, a small-baseline head: 7.5 cm
  baseline at 1 m height (baseline / height 0.075), focal 525 px, tilt 10-25 deg, a wall
  3-6 m ahead, 2-4 boxes (furniture) before it; seeds ``0 .. M-1`` (``2000 ..`` with
  ``--held-out``). Wall and
  furniture pixels marked plane, true homography.
* **time**: both masks at 640x480 on one core, median over ``R`` interleaved repetitions on
  the first rendered scenes.

With ``--readme-overlay FILE`` it also writes the README picture (right image, left image
with the pipeline's debug overlay on a rendered scene). Writes ``mask_contact_sheet.png``
(left image; NCC mask, or the baseline's with ``--baseline``; parallax mask; residual
parallax, 0-8 px, black where not measured)
and ``mask_summary.txt`` (the tables) to ``--out``. CPU time is given beside wall-clock time
because the machine may be shared: it counts only this process's work.
"""

from __future__ import annotations

from dataclasses import dataclass
import importlib.util
import math
from pathlib import Path
import sys
import time
from typing import Callable, Sequence

import cv2
from domplane_ros.config import FeatureConfig, MaskConfig, PlaneNodeConfig
from domplane_ros.core.mask import (DEFAULT_FOCAL_PX, mask_scores, OBSTACLE, overlay,
                                    parallax_mask, ParallaxMask, PLANE, UNKNOWN)
from domplane_ros.sim.generators import indoor_scene, random_scene
from domplane_ros.sim.model import StereoFrame
from domplane_ros.stream.frame import debug_overlay
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.common import (add_output_argument, machine_name, one_core, progress,
                                       tool_parser)
from domplane_ros.tools.evaluation.datasets import KITTI_PRIOR, KITTI_ROI
from domplane_ros.tools.evaluation.methods import run_ours
from domplane_ros.tools.evaluation.ncc_mask import ncc_mask
from domplane_ros.tools.evaluation.references import (default_data_dir, KITTI_DIR,
                                                      kitti_reference, read_gray)
from domplane_ros.tools.evaluation.tables import fmt, markdown_table
import numpy as np

HELD_OUT_FIRST_SEED = 1000
# The README picture's rendered scene.
README_SEED = 6
# Box face texture contrast of the plain-box scenes, by seed parity (untextured, weak).
PLAIN_BOX_CONTRAST = (0.0, 0.1)
INDOOR_FIRST_SEED = 0
INDOOR_HELD_OUT_FIRST_SEED = 2000
KITTI_LABEL_PX = 1.0
# The third column: the parallax mask with a lower minimum obstacle height.
LOW_MIN_HEIGHT = 0.05
# Targets of issue 12.
TARGETS = {'plane_iou': 0.92, 'obstacle_recall': 0.92, 'ground_as_obstacle': 0.01,
           'road_plane': 0.95, 'off_road_not_plane': 0.95, 'off_road_plane': 0.02,
           'indoor_plane': 0.02, 'time_ms': 3.0}
MaskFunction = Callable[[np.ndarray, np.ndarray, np.ndarray], ParallaxMask]
# Column titles of the mask functions.
TITLES = {'ncc': 'ncc (before)', 'baseline': 'baseline (--baseline)',
          'parallax': 'parallax (now)', 'parallax_low': f'parallax, min height {LOW_MIN_HEIGHT}'}


# Core modules of the mask that a baseline folder may hold beside its mask.py, in the order
# they are loaded (pixel_decision imports residual and parallax: it is loaded after them).
BASELINE_MODULES = ('residual', 'occlusion', 'parallax', 'pixel_decision')


def load_baseline(path: Path) -> Callable[..., ParallaxMask]:
    """Return ``parallax_mask`` of a ``core/mask.py`` file (another version of the module).

    ``path`` is that file, or a folder holding it and, optionally, the same version's
    :data:`BASELINE_MODULES` (``residual.py`` ...): those stand in for today's while the
    baseline's ``mask.py`` is loaded, so a change of the measurement has its own before.

    Raises:
        ValueError: If the file cannot be loaded or has no ``parallax_mask``.

    """
    folder = path if path.is_dir() else None
    mask_file = path / 'mask.py' if folder else path
    saved = {}
    try:
        for name in BASELINE_MODULES if folder else ():
            if (folder / f'{name}.py').is_file():
                key = f'domplane_ros.core.{name}'
                saved[key] = sys.modules.get(key)
                sys.modules[key] = _load_module(folder / f'{name}.py', f'baseline_{name}')
        module = _load_module(mask_file, 'baseline_mask')
    finally:
        for key, previous in saved.items():
            if previous is None:
                sys.modules.pop(key, None)
            else:
                sys.modules[key] = previous
    if not callable(getattr(module, 'parallax_mask', None)):
        raise ValueError(f'{mask_file} has no parallax_mask function')
    return module.parallax_mask


def _load_module(path: Path, name: str) -> object:
    """Return the module executed from ``path`` under ``name``; ValueError if it fails."""
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ValueError(f'cannot load {path} as a Python module')
    module = importlib.util.module_from_spec(spec)
    # Registered, as importlib's recipe does: a dataclass with a plain annotation
    # (``noise: float``) looks its module up while it is executed.
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except (OSError, SyntaxError, ImportError) as err:
        raise ValueError(f'cannot load {path}: {err}') from err
    return module


def masks(focal_px: tuple[float, float] = DEFAULT_FOCAL_PX,
          baseline: Callable[..., ParallaxMask] | None = None) -> dict[str, MaskFunction]:
    """Return the mask functions as ``(left, right, H) -> ParallaxMask`` (see :data:`TITLES`)."""
    config = MaskConfig()
    low = MaskConfig(min_obstacle_height=LOW_MIN_HEIGHT)

    def old(left: np.ndarray, right: np.ndarray, hom: np.ndarray) -> ParallaxMask:
        return ParallaxMask(ncc_mask(left, right, hom), np.zeros((1, 1), np.float32))

    def before(left: np.ndarray, right: np.ndarray, hom: np.ndarray) -> ParallaxMask:
        assert baseline is not None
        return baseline(left, right, hom, config, focal_px)

    def new(left: np.ndarray, right: np.ndarray, hom: np.ndarray) -> ParallaxMask:
        return parallax_mask(left, right, hom, config, focal_px)

    def new_low(left: np.ndarray, right: np.ndarray, hom: np.ndarray) -> ParallaxMask:
        return parallax_mask(left, right, hom, low, focal_px)

    functions = {'ncc': old, 'baseline': before, 'parallax': new, 'parallax_low': new_low}
    if baseline is None:
        del functions['baseline']
    return functions


def rendered_scores(frame: StereoFrame, labels: np.ndarray) -> dict[str, float]:
    """Return the mask figures of a rendered frame against its truth."""
    ground = frame.plane_left & frame.visible_in_right
    scores = mask_scores(labels, ground, frame.obstacle_left)
    scores['ground_as_obstacle'] = float(np.mean(labels[ground] == OBSTACLE)) \
        if ground.any() else math.nan
    scores['box_as_plane'] = float(np.mean(labels[frame.obstacle_left] == PLANE)) \
        if frame.obstacle_left.any() else math.nan
    seen = frame.obstacle_left & ~frame.obstacle_hidden if frame.obstacle_hidden is not None \
        else frame.obstacle_left
    scores['seen_obstacle_recall'] = float(np.mean(labels[seen] == OBSTACLE)) \
        if seen.any() else math.nan
    hidden = frame.occluded_in_right
    for key, value in (('occluded_unknown', UNKNOWN), ('occluded_obstacle', OBSTACLE)):
        scores[key] = float(np.mean(labels[hidden] == value)) \
            if hidden is not None and hidden.any() else math.nan
    return scores


def indoor_scores(frame: StereoFrame, labels: np.ndarray) -> dict[str, float]:
    """Return the share of wall and furniture pixels marked plane, and of the ground."""
    off_ground = ~frame.plane_left
    ground = frame.plane_left & frame.visible_in_right
    return {'indoor_plane': float(np.mean(labels[off_ground] == PLANE)),
            'indoor_obstacle': float(np.mean(labels[off_ground] == OBSTACLE)),
            'ground_plane': float(np.mean(labels[ground] == PLANE)) if ground.any()
            else math.nan}


@dataclass
class KittiLabels:
    """KITTI's issue-12 labels: road and off-road pixels of the ground-truth disparity."""

    road: np.ndarray
    off_road: np.ndarray
    reference_h: np.ndarray


def kitti_labels(folder: Path) -> KittiLabels:
    """Return road (within 1 px of the road plane) and off-road (beyond 1 px) pixels."""
    ref = kitti_reference(folder)
    ys, xs = np.mgrid[0:ref.disparity.shape[0], 0:ref.disparity.shape[1]]
    known = np.isfinite(ref.disparity)
    residual = np.full(ref.disparity.shape, np.inf)
    residual[known] = ref.plane.residuals(xs[known], ys[known], ref.disparity[known])
    return KittiLabels(road=known & (residual <= KITTI_LABEL_PX),
                       off_road=known & (residual > KITTI_LABEL_PX),
                       reference_h=ref.plane.homography())


def kitti_scores(labels: np.ndarray, truth: KittiLabels) -> dict[str, float]:
    """Return road marked plane, off-road marked obstacle or unknown, off-road marked plane."""
    return {'road_plane': float(np.mean(labels[truth.road] == PLANE)),
            'off_road_not_plane': float(np.mean(labels[truth.off_road] != PLANE)),
            'off_road_plane': float(np.mean(labels[truth.off_road] == PLANE)),
            'off_road_obstacle': float(np.mean(labels[truth.off_road] == OBSTACLE))}


def time_masks(frames: Sequence[StereoFrame], repeats: int,
               baseline: Callable[..., ParallaxMask] | None = None
               ) -> dict[str, dict[str, float]]:
    """Return each mask's median wall-clock and CPU time in ms (interleaved, one core)."""
    functions = masks(baseline=baseline)
    times: dict[str, dict[str, list[float]]] = {
        name: {'wall': [], 'cpu': []} for name in functions}
    with one_core():
        for name, function in functions.items():  # warm-up (first-use allocations)
            function(frames[0].left, frames[0].right, frames[0].homography)
        for index in range(repeats):
            frame = frames[index % len(frames)]
            for name, function in functions.items():
                wall, cpu = time.perf_counter(), time.process_time()
                function(frame.left, frame.right, frame.homography)
                times[name]['cpu'].append(1e3 * (time.process_time() - cpu))
                times[name]['wall'].append(1e3 * (time.perf_counter() - wall))
    return {name: {key: float(np.median(values)) for key, values in entry.items()}
            for name, entry in times.items()}


def _median(rows: list[dict[str, float]], key: str) -> float:
    values = [row[key] for row in rows if not math.isnan(row.get(key, math.nan))]
    return float(np.median(values)) if values else math.nan


def _tile(left: np.ndarray, result: ParallaxMask | None, labels: np.ndarray | None
          ) -> list[np.ndarray]:
    """Return the contact sheet's tiles of one pair (RGB, the left image's size)."""
    tiles = [cv2.cvtColor(left, cv2.COLOR_GRAY2RGB)]
    tiles.append(overlay(left, labels) if labels is not None else tiles[0])
    if result is not None:
        tiles.append(overlay(left, result.labels))
        parallax = result.parallax_image()
        scaled = np.clip(parallax / 8.0 * 255.0, 0, 255).astype(np.uint8)
        heat = cv2.cvtColor(cv2.applyColorMap(scaled, cv2.COLORMAP_JET), cv2.COLOR_BGR2RGB)
        heat[parallax < 0] = 0
        tiles.append(heat)
    return tiles


def contact_sheet(rows: list[tuple[str, list[np.ndarray]]], tile_width: int = 320
                  ) -> np.ndarray:
    """Return the RGB contact sheet: one row of tiles per pair, its name written on it."""
    lines = []
    for name, tiles in rows:
        scaled = []
        for tile in tiles:
            height = int(round(tile.shape[0] * tile_width / tile.shape[1]))
            scaled.append(cv2.resize(tile, (tile_width, height), interpolation=cv2.INTER_AREA))
        height = max(t.shape[0] for t in scaled)
        padded = [np.pad(t, ((0, height - t.shape[0]), (0, 0), (0, 0))) for t in scaled]
        line = np.hstack(padded)
        cv2.putText(line, name, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 0), 1,
                    cv2.LINE_AA)
        lines.append(line)
    width = max(line.shape[1] for line in lines)
    return np.vstack([np.pad(line, ((0, 0), (0, width - line.shape[1]), (0, 0)))
                      for line in lines])


def evaluate_rendered(seeds: Sequence[int], sheet: list, shown: int = 4,
                      baseline: Callable[..., ParallaxMask] | None = None
                      ) -> dict[str, list[dict[str, float]]]:
    """Score the masks on rendered scenes; the first ``shown`` go on the contact sheet."""
    return _evaluate_frames(seeds, sheet, shown, 'rendered', random_scene, rendered_scores,
                            lambda seed, frame: f'rendered seed {seed} ({frame.floor})',
                            baseline)


def plain_box_scene(seed: int) -> StereoFrame:
    """Return :func:`random_scene` ``seed`` with plain faces (:data:`PLAIN_BOX_CONTRAST`)."""
    return random_scene(seed, box_contrast=PLAIN_BOX_CONTRAST[seed % 2])


def evaluate_plain(seeds: Sequence[int], sheet: list, shown: int = 0,
                   baseline: Callable[..., ParallaxMask] | None = None
                   ) -> dict[str, list[dict[str, float]]]:
    """Score the masks on the rendered scenes with plain box faces (:func:`plain_box_scene`)."""
    return _evaluate_frames(seeds, sheet, shown, 'plain boxes', plain_box_scene,
                            rendered_scores,
                            lambda seed, frame: f'plain boxes seed {seed} ({frame.floor})',
                            baseline)


def evaluate_indoor(seeds: Sequence[int], sheet: list, shown: int = 2,
                    baseline: Callable[..., ParallaxMask] | None = None
                    ) -> dict[str, list[dict[str, float]]]:
    """Score the masks on the small-baseline indoor head."""
    return _evaluate_frames(seeds, sheet, shown, 'indoor', indoor_scene, indoor_scores,
                            lambda seed, frame: f'indoor seed {seed} (b/h 0.075)', baseline)


def _evaluate_frames(seeds: Sequence[int], sheet: list, shown: int, name: str,
                     render: Callable[[int], StereoFrame],
                     score: Callable[[StereoFrame, np.ndarray], dict],
                     label: Callable[[int, StereoFrame], str],
                     baseline: Callable[..., ParallaxMask] | None = None
                     ) -> dict[str, list[dict[str, float]]]:
    """Score the masks on ``render(seed)`` frames; the first ``shown`` go on the sheet."""
    functions = masks(baseline=baseline)
    rows: dict[str, list[dict[str, float]]] = {mask: [] for mask in functions}
    for index, seed in enumerate(progress(seeds, name)):
        frame = render(seed)
        results = {mask: f(frame.left, frame.right, frame.homography)
                   for mask, f in functions.items()}
        for mask, result in results.items():
            rows[mask].append(score(frame, result.labels))
        if index < shown:
            sheet.append((label(seed, frame), _tile(frame.left, results['parallax'],
                                                    _before(results).labels)))
    return rows


def _before(results: dict[str, ParallaxMask]) -> ParallaxMask:
    """Return the mask the contact sheet shows as *before*: the baseline's, else the NCC's."""
    return results.get('baseline', results['ncc'])


def evaluate_kitti(folder: Path, sheet: list,
                   baseline: Callable[..., ParallaxMask] | None = None
                   ) -> dict[str, dict[str, dict[str, float]]]:
    """Score the masks on KITTI with the reference and with our estimated homography."""
    left = read_gray(folder / 'left.png')
    right = read_gray(folder / 'right.png')
    truth = kitti_labels(folder)
    config = PlaneNodeConfig(features=FeatureConfig(roi=KITTI_ROI), prior=KITTI_PRIOR)
    estimated = run_ours(left, right, config, repeats=1).homography
    functions = masks(KITTI_PRIOR.focal_px, baseline)
    out: dict[str, dict[str, dict[str, float]]] = {}
    for h_name, hom in (('reference H', truth.reference_h), ('our H', estimated)):
        if hom is None:
            print(f'KITTI: no plane estimated ({h_name}), skipped', file=sys.stderr)
            continue
        results = {name: f(left, right, hom) for name, f in functions.items()}
        out[h_name] = {name: kitti_scores(r.labels, truth) for name, r in results.items()}
        sheet.append((f'KITTI 000046, {h_name}',
                      _tile(left, results['parallax'], _before(results).labels)))
    return out


def _rendered_rows(rendered: dict, data: str) -> list[list]:
    """Return the table rows of the rendered figures (medians over scenes) of one data set."""
    rows = []
    for key, label in (('plane_iou', 'plane IoU (median)'),
                       ('obstacle_recall', 'obstacle recall (median)'),
                       ('seen_obstacle_recall', 'obstacle recall, box seen by both (median)'),
                       ('obstacle_precision', 'obstacle precision (median)'),
                       ('ground_as_obstacle', 'true ground marked obstacle (median)'),
                       ('plane_precision', 'plane precision (median)'),
                       ('occluded_unknown', 'occluded floor marked unknown (median)'),
                       ('occluded_obstacle', 'occluded floor marked obstacle (median)'),
                       ('box_as_plane', 'box pixels marked plane (median)')):
        target = TARGETS.get(key)
        rows.append([f'{data}, {len(rendered["ncc"])} scenes', label,
                     '-' if target is None else fmt(target)]
                    + [_median(rendered[name], key) for name in rendered])
    return rows


def summary(rendered: dict, indoor: dict, kitti: dict, times: dict[str, float],
            held_out: bool, plain: dict | None = None) -> str:
    """Return the tables of the run as text."""
    seeds = 'held-out' if held_out else 'tuning'
    header = ['data', 'figure', 'target'] + [TITLES[name] for name in rendered]
    rows = _rendered_rows(rendered, f'rendered, {seeds}')
    if plain and plain['ncc']:
        rows += _rendered_rows(plain, f'plain boxes, {seeds}')
        rows.append([f'plain boxes, {seeds}, {len(plain["ncc"])} scenes',
                     'box pixels marked plane (worst scene)', '-']
                    + [max(r['box_as_plane'] for r in plain[name]) for name in plain])
    for h_name, scores in kitti.items():
        for key, label in (('road_plane', 'road marked plane'),
                           ('off_road_not_plane', 'off-road obstacle or unknown'),
                           ('off_road_plane', 'off-road marked plane'),
                           ('off_road_obstacle', 'off-road marked obstacle')):
            rows.append([f'KITTI 000046, {h_name}', label, fmt(TARGETS.get(key))]
                        + [scores[name][key] for name in scores])
    for key, label in (('indoor_plane', 'walls + furniture marked plane (median)'),
                       ('indoor_obstacle', 'walls + furniture marked obstacle (median)'),
                       ('ground_plane', 'visible ground marked plane (median)')):
        rows.append([f'indoor b/h 0.075, {seeds}, {len(indoor["ncc"])} scenes', label,
                     fmt(TARGETS.get(key))] + [_median(indoor[name], key) for name in indoor])
    for key, label in (('wall', 'mask time, median ms (wall clock)'),
                       ('cpu', 'mask time, median ms (CPU time)')):
        rows.append(['640x480, one core', label, fmt(TARGETS['time_ms'])]
                    + [times[name][key] for name in times])
    rows.append(['rendered', 'worst scene plane IoU', '-']
                + [min(r['plane_iou'] for r in rendered[name]) for name in rendered])
    cells = [[f'{v:.3f}' if isinstance(v, float) else v for v in row] for row in rows]
    return machine_name() + '\n\n' + markdown_table(header, cells) + '\n'


def readme_overlay(path: Path, seed: int = README_SEED) -> None:
    """Write the README picture: right image | left image with the pipeline's debug overlay.

    The rendered scene :func:`~domplane_ros.sim.random_scene` ``seed`` goes through a
    :class:`~domplane_ros.stream.pipeline.PlanePipeline` with the default configuration
    (prior search, verification, mask), so the picture shows what the node publishes.
    """
    frame = random_scene(seed)
    result = PlanePipeline(PlaneNodeConfig()).process(frame.left, frame.right, 1)
    if not result.ok:
        raise RuntimeError(f'seed {seed}: no plane ({result.reason})')
    rgb = debug_overlay(frame.left, result)
    right = cv2.cvtColor(frame.right, cv2.COLOR_GRAY2RGB)
    picture = cv2.resize(np.hstack([right, rgb]), None, fx=0.75, fy=0.75,
                         interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(path), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the evaluation (see the module docstring)."""
    parser = tool_parser(__doc__, 'python -m domplane_ros.tools.evaluate_mask')
    parser.add_argument('--scenes', type=int, default=30, help='rendered scenes (default 30)')
    parser.add_argument('--indoor', type=int, default=10, help='indoor scenes (default 10)')
    parser.add_argument('--plain', type=int, default=None,
                        help='rendered scenes with plain box faces (default: --scenes)')
    parser.add_argument('--held-out', action='store_true',
                        help=f'held-out seeds ({HELD_OUT_FIRST_SEED}.., '
                             f'{INDOOR_HELD_OUT_FIRST_SEED}.. indoor)')
    parser.add_argument('--repeats', type=int, default=60, help='timing repetitions')
    parser.add_argument('--data', type=Path, default=default_data_dir(),
                        help='folder holding kitti2015_000046/')
    add_output_argument(parser, 'mask_output', 'the contact sheet and the summary')
    parser.add_argument('--readme-overlay', type=Path, default=None,
                        help='also write the README picture (docs/overlay.png) to this file')
    parser.add_argument('--baseline', type=Path, default=None, metavar='FILE',
                        help='another version of core/mask.py (git show '
                             'COMMIT:domplane_ros/core/mask.py > FILE), or a folder with it '
                             'and its residual.py, occlusion.py, parallax.py, as an extra '
                             'column')
    args = parser.parse_args(argv)
    baseline = None
    if args.baseline is not None:
        try:
            baseline = load_baseline(args.baseline)
        except ValueError as err:
            parser.error(str(err))
    if args.readme_overlay is not None:
        readme_overlay(args.readme_overlay)
    first = HELD_OUT_FIRST_SEED if args.held_out else 0
    indoor_first = INDOOR_HELD_OUT_FIRST_SEED if args.held_out else INDOOR_FIRST_SEED
    sheet: list = []
    rendered = evaluate_rendered(range(first, first + args.scenes), sheet, baseline=baseline)
    plain_count = args.scenes if args.plain is None else args.plain
    plain = evaluate_plain(range(first, first + plain_count), sheet, baseline=baseline)
    indoor = evaluate_indoor(range(indoor_first, indoor_first + args.indoor), sheet,
                             baseline=baseline)
    kitti = evaluate_kitti(args.data / KITTI_DIR, sheet, baseline)
    frames = [random_scene(seed) for seed in range(first, first + 4)]
    times = time_masks(frames, args.repeats, baseline)
    text = summary(rendered, indoor, kitti, times, args.held_out, plain)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / 'mask_summary.txt').write_text(text, encoding='utf-8')
    picture = contact_sheet(sheet)
    cv2.imwrite(str(args.out / 'mask_contact_sheet.png'),
                cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
    print(text)
    print(f'wrote {args.out / "mask_contact_sheet.png"} and {args.out / "mask_summary.txt"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
