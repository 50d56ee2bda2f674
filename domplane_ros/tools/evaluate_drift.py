"""Lock drift: how far a held plane drifts over sequences of several kinds.

Run ``python -m domplane_ros.tools.evaluate_drift [--seeds 20] [--first-seed 0] [--frames 16]
[--families plain,long,...] [--out DIR]``. Every sequence goes through a fresh
:class:`~domplane_ros.stream.pipeline.PlanePipeline` with the documented default configuration
(default prior: no range is set from a scene's truth), one pair per 33.3 ms; the first pair
(the cold start) is not counted, every pair after it is. The families:

* ``plain``: :func:`~domplane_ros.sim.generators.scene_sequence` as it is;
* ``long``: the same, ``--long-frames`` (48) frames;
* ``fast``: twice the forward ``step`` (0.08 camera heights a frame) and three times the
  ``yaw_rate_deg`` (1.8 deg);
* ``wobble``: tilt wobble 3 deg and vergence wobble 1 deg (defaults 1 and 0.3);
* ``floors``: every :data:`~domplane_ros.sim.textures.FLOOR_KINDS` floor and the faint tiles of
  :data:`~domplane_ros.sim.textures.FAINT_TILE_KINDS`, one per seed in turn (default
  ``features.kind`` here too: points only);
* ``lighting``: the right camera's gain 0.8-1.25 and offset -20 to 20 grey levels, and each
  camera its own response curve and vignetting (:func:`~domplane_ros.sim.rigs.camera_response`),
  one draw per sequence;
* ``rough``: every frame through :func:`~domplane_ros.sim.rigs.rough_rig` with one
  :func:`~domplane_ros.sim.rigs.random_rig_error` per sequence;
* ``head``: the rendered active head (:func:`~domplane_ros.sim.head.head_sequence`, 30 deg/s
  pan and tilt, 6 deg/s vergence, 30 Hz; random and tiled floors in turn).

A published plane is *correct* below 1 px mean transfer error over the visible floor, *wrong*
above 5 px. Precision = correct / published; recall = correct / pairs. Per family the table
counts the sequences whose worst published plane ever exceeds 1, 3 and 5 px and names the
worst. For every sequence that exceeds 1 px the worst pair is also given alone to a fresh
pipeline that searches the whole prior in it (:func:`~domplane_ros.config.one_shot_search`):
if that cold search is correct, the drift is the lock's, not the search's or the gate's.
Writes ``summary.md``, ``sequences.csv`` and, per family that drifts, ``sheet_<family>.png``
(left image with the mask of its first, middle and worst pair). Tuning seeds start at 0.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
import math
from pathlib import Path
import sys
from typing import Callable, Sequence

import cv2
from domplane_ros.config import one_shot_search, PlaneNodeConfig
from domplane_ros.core.mask import overlay
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.head import head_sequence, HeadMotion
from domplane_ros.sim.model import StereoFrame
from domplane_ros.sim.rigs import camera_response, plane_error_px, random_rig_error, rough_rig
from domplane_ros.sim.textures import FAINT_TILE_KINDS, FLOOR_KINDS
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.common import (add_output_argument, machine_name, one_core, progress,
                                       tool_parser)
import numpy as np

CORRECT_PX = 1.0
WRONG_PX = 5.0
DRIFT_LEVELS_PX = (1.0, 3.0, 5.0)
PERIOD_NS = 33_333_333
DRIFT_FLOORS = FLOOR_KINDS + FAINT_TILE_KINDS
HEAD_FLOORS = ('random', 'tiles')
HEAD_SPEED_DEG_S = 30.0

# family -> (frames, seed) -> (frames, what the sequence is)
Maker = Callable[[int, int], tuple[list[StereoFrame], str]]


def _plain(n: int, seed: int) -> tuple[list[StereoFrame], str]:
    return scene_sequence(n, seed), ''


def _fast(n: int, seed: int) -> tuple[list[StereoFrame], str]:
    return scene_sequence(n, seed, step=0.08, yaw_rate_deg=1.8), 'step 0.08, yaw 1.8'


def _wobble(n: int, seed: int) -> tuple[list[StereoFrame], str]:
    return (scene_sequence(n, seed, tilt_jitter_deg=3.0, vergence_jitter_deg=1.0),
            'tilt 3, vergence 1')


def _floors(n: int, seed: int) -> tuple[list[StereoFrame], str]:
    floor = DRIFT_FLOORS[seed % len(DRIFT_FLOORS)]
    return scene_sequence(n, seed, floor=floor), floor


def _lighting(n: int, seed: int) -> tuple[list[StereoFrame], str]:
    rng = np.random.default_rng((seed, 555))
    gain = float(np.exp(rng.uniform(math.log(0.8), math.log(1.25))))
    offset = float(rng.uniform(-20.0, 20.0))
    frames = [camera_response(f, np.random.default_rng((seed, 556)))
              for f in scene_sequence(n, seed, gain=gain, offset=offset)]
    return frames, f'gain {gain:.2f}, offset {offset:+.0f}'


def _rough(n: int, seed: int) -> tuple[list[StereoFrame], str]:
    error = random_rig_error(np.random.default_rng((seed, 77)))
    detail = (f'roll {error.roll_deg:+.1f}, pitch {error.pitch_deg:+.1f}, '
              f'focal x{error.focal_ratio:.3f}')
    return [rough_rig(f, error) for f in scene_sequence(n, seed)], detail


def _head(n: int, seed: int) -> tuple[list[StereoFrame], str]:
    floor = HEAD_FLOORS[seed % len(HEAD_FLOORS)]
    motion = HeadMotion.at_speed(HEAD_SPEED_DEG_S)
    return list(head_sequence(n, seed, motion, floor=floor, supersample=1)), floor


FAMILIES: dict[str, Maker] = {'plain': _plain, 'long': _plain, 'fast': _fast, 'wobble': _wobble,
                              'floors': _floors, 'lighting': _lighting, 'rough': _rough,
                              'head': _head}


@dataclass
class Run:
    """One sequence: the error of every counted pair (None: nothing published)."""

    family: str
    seed: int
    detail: str
    errors: list[float | None]
    cold_px: float | None = math.nan
    worst_pair: int = -1

    @property
    def worst_px(self) -> float:
        """Return the largest published error (0 when nothing was published)."""
        return max([e for e in self.errors if e is not None], default=0.0)


@dataclass
class Tally:
    """Counts of one family."""

    runs: list[Run] = field(default_factory=list)

    def row(self, family: str) -> str:
        """Return the markdown table row."""
        errors = [e for r in self.runs for e in r.errors]
        published = [e for e in errors if e is not None]
        correct = sum(e < CORRECT_PX for e in published)
        wrong = sum(e > WRONG_PX for e in published)
        middle = len(published) - correct - wrong
        over = [sum(r.worst_px > level for r in self.runs) for level in DRIFT_LEVELS_PX]
        worst = sorted((r for r in self.runs if r.worst_px > CORRECT_PX),
                       key=lambda r: -r.worst_px)[:3]
        names = ', '.join(f'{r.seed} ({r.worst_px:.1f})' for r in worst) or '-'
        return (f'| {family} | {len(self.runs)} | {len(errors)} | {len(published)} | '
                f'{correct} | {wrong} | {_pct(correct, len(published))} | '
                f'{_pct(correct, len(errors))} | {middle} | '
                f'{max(published, default=0.0):.2f} | {over[0]} / {over[1]} / {over[2]} | '
                f'{names} |')


def _pct(part: int, whole: int) -> str:
    return '-' if not whole else f'{100 * part / whole:.1f} %'


HEADER = ['| family | sequences | pairs | published | correct | wrong | precision | recall | '
          'pairs 1-5 px | worst px | sequences > 1 / 3 / 5 px | worst seeds (px) |',
          '|' + '---|' * 12]


def run_sequence(family: str, frames: list[StereoFrame], seed: int, detail: str,
                 config: PlaneNodeConfig) -> tuple[Run, list[tuple[str, np.ndarray]]]:
    """Run one sequence through a fresh pipeline; return its run and, if it drifts, a sheet.

    The sheet holds the left image with the mask of the first, the middle and the worst pair.
    """
    pipeline = PlanePipeline(config)
    every: list[float | None] = []
    masks = []
    for index, frame in enumerate(frames):
        result = pipeline.process(frame.left, frame.right, index * PERIOD_NS)
        every.append(plane_error_px(frame, result.homography) if result.ok else None)
        masks.append(result.mask)
    errors = every[1:]
    run = Run(family, seed, detail, errors)
    if run.worst_px <= CORRECT_PX:
        return run, []
    run.worst_pair = 1 + max((i for i, e in enumerate(errors) if e is not None),
                             key=lambda i: errors[i])
    worst = frames[run.worst_pair]
    cold = PlanePipeline(one_shot_search(config)).process(worst.left, worst.right, 0)
    run.cold_px = plane_error_px(worst, cold.homography) if cold.ok else None
    sheet = []
    for label, index in (('first', 0), ('middle', len(frames) // 2),
                         ('worst', run.worst_pair)):
        text = '-' if every[index] is None else f'{every[index]:.2f} px'
        sheet.append((f'{family} {seed} {label} #{index}: {text}',
                      overlay(frames[index].left, masks[index])))
    return run, sheet


def write_sheet(path: Path, sheet: Sequence[tuple[str, np.ndarray]], scale: float = 0.5
                ) -> None:
    """Write labelled RGB overlays side by side as a PNG."""
    tiles = []
    for label, rgb in sheet:
        small = np.ascontiguousarray(cv2.resize(rgb, None, fx=scale, fy=scale,
                                                interpolation=cv2.INTER_AREA))
        cv2.putText(small, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 0), 1,
                    cv2.LINE_AA)
        tiles.append(small)
    cv2.imwrite(str(path), cv2.cvtColor(np.hstack(tiles), cv2.COLOR_RGB2BGR))


def evaluate(families: Sequence[str], seeds: Sequence[int], frames: int, long_frames: int,
             out: Path) -> dict[str, Tally]:
    """Run every family on every seed; write the sheets of the worst drifting sequences."""
    config = PlaneNodeConfig()
    tallies: dict[str, Tally] = {}
    for family in families:
        tally = tallies.setdefault(family, Tally())
        worst: tuple[float, list] = (CORRECT_PX, [])
        for seed in progress(seeds, family):
            n = long_frames if family == 'long' else frames
            sequence, detail = FAMILIES[family](n, seed)
            run, sheet = run_sequence(family, sequence, seed, detail, config)
            tally.runs.append(run)
            if sheet and run.worst_px > worst[0]:
                worst = (run.worst_px, sheet)
        if worst[1]:
            write_sheet(out / f'sheet_{family}.png', worst[1])
    return tallies


def write_csv(path: Path, tallies: dict[str, Tally]) -> None:
    """Write one row per sequence: counts, first / worst / last error, the cold search."""
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(['family', 'seed', 'detail', 'pairs', 'published', 'correct', 'wrong',
                         'first_px', 'worst_px', 'worst_pair', 'last_px', 'cold_worst_px',
                         'errors_px'])
        for tally in tallies.values():
            for r in tally.runs:
                published = [e for e in r.errors if e is not None]
                writer.writerow([
                    r.family, r.seed, r.detail, len(r.errors), len(published),
                    sum(e < CORRECT_PX for e in published), sum(e > WRONG_PX for e in published),
                    _px(r.errors[0] if r.errors else None), f'{r.worst_px:.3f}', r.worst_pair,
                    _px(r.errors[-1] if r.errors else None), _px(r.cold_px),
                    ' '.join(_px(e) for e in r.errors)])


def _px(value: float | None) -> str:
    if value is None:
        return '-'
    return '' if math.isnan(value) else f'{value:.3f}'


def drift_lines(tallies: dict[str, Tally]) -> list[str]:
    """Return one line per sequence above 1 px: its worst pair and the cold search there."""
    lines = []
    for tally in tallies.values():
        for r in sorted(tally.runs, key=lambda r: -r.worst_px):
            if r.worst_px <= CORRECT_PX:
                continue
            cold = 'nothing published' if r.cold_px is None else f'{r.cold_px:.2f} px'
            verdict = ('lock' if r.cold_px is not None and r.cold_px < CORRECT_PX
                       else 'search/gate')
            lines.append(f'- {r.family} seed {r.seed} ({r.detail or "default"}): worst '
                         f'{r.worst_px:.2f} px at pair {r.worst_pair}; cold search on that '
                         f'pair: {cold} ({verdict})')
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    """Run the drift evaluation, print its table and write the outputs; return the exit code."""
    parser = tool_parser(__doc__)
    parser.add_argument('--seeds', type=int, default=20, help='sequences per family')
    parser.add_argument('--first-seed', type=int, default=0, help='first seed (tuning: 0 on)')
    parser.add_argument('--frames', type=int, default=16, help='frames per sequence')
    parser.add_argument('--long-frames', type=int, default=48,
                        help='frames per sequence of the long family')
    parser.add_argument('--families', default=','.join(FAMILIES),
                        help='comma-separated families: ' + ', '.join(FAMILIES))
    add_output_argument(parser, 'eval_output/drift', 'summary.md, sequences.csv, sheets')
    args = parser.parse_args(argv)
    families = [f.strip() for f in args.families.split(',') if f.strip()]
    unknown = [f for f in families if f not in FAMILIES]
    if unknown or args.frames < 2 or args.long_frames < 2 or args.seeds < 1:
        parser.error(f'unknown families {unknown}' if unknown
                     else '--frames and --long-frames need 2 or more, --seeds 1 or more')
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    args.out.mkdir(parents=True, exist_ok=True)
    with one_core():
        tallies = evaluate(families, seeds, args.frames, args.long_frames, args.out)
    lines = [f'machine: {machine_name()}',
             f'seeds {seeds[0]}..{seeds[-1]}, {args.frames} frames ({args.long_frames} long); '
             'config and prior: the documented defaults; every pair after the first counted; '
             'correct < 1 px, wrong > 5 px', '', *HEADER]
    lines += [tally.row(family) for family, tally in tallies.items()]
    drifting = drift_lines(tallies)
    if drifting:
        lines += ['', 'Sequences above 1 px (cold search: a fresh pipeline, the whole prior '
                  'search on the worst pair alone):', '', *drifting]
    text = '\n'.join(lines)
    print(text)
    (args.out / 'summary.md').write_text(text + '\n')
    write_csv(args.out / 'sequences.csv', tallies)
    return 0


if __name__ == '__main__':
    sys.exit(main())
