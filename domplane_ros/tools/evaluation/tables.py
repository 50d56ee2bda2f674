"""The evaluation's tables, CSV files, speed lines and verdicts against the targets."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Iterator, Sequence

from domplane_ros.config import PriorConfig
from domplane_ros.sim.textures import FLOOR_KINDS
from domplane_ros.tools.evaluation.datasets import (Case, CHESSBOARD_TARGET_PX, KITTI_TARGET_PX,
                                                    RENDERED_TARGET_SOLVED, SOLVED_PX,
                                                    SPEED_TARGET)
from domplane_ros.tools.evaluation.references import OFF_ROAD_PX, ROAD_PX
import numpy as np


def fmt(value: Any, digits: int = 2) -> str:
    """Return a table cell: ``digits`` decimals, 'fail' for inf, '-' for NaN or None."""
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '-'
    if isinstance(value, float) and math.isinf(value):
        return 'fail'
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return f'{value:.{digits}f}'


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """Return a markdown table; floats get 2 decimals, inf is 'fail', NaN is '-'."""
    cells = [[fmt(v) for v in row] for row in rows]
    widths = [max([len(h)] + [len(r[i]) for r in cells]) for i, h in enumerate(header)]
    lines = ['| ' + ' | '.join(h.ljust(w) for h, w in zip(header, widths)) + ' |',
             '|' + '|'.join('-' * (w + 2) for w in widths) + '|']
    lines += ['| ' + ' | '.join(c.rjust(w) for c, w in zip(row, widths)) + ' |'
              for row in cells]
    return '\n'.join(lines)


def write_csv(path: Path, cases: Sequence[Case]) -> None:
    """Write one row per case and method: pair, method, figures, then the case's info."""
    rows = []
    for case in cases:
        for method, figures in case.figures.items():
            row: dict[str, Any] = {'dataset': case.dataset, 'pair': case.pair, 'method': method}
            row.update(figures)
            row.update(case.info)
            row['reason'] = case.runs[method].reason
            rows.append(row)
    columns: list[str] = []
    for row in rows:
        columns += [key for key in row if key not in columns]
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.DictWriter(stream, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f'{v:.6g}' if isinstance(v, float) else v)
                             for k, v in row.items()})


METHOD_LABEL = {'ours': 'ours (cold / warm)', 'orb_magsac': 'ORB + MAGSAC'}


def _time_cell(figures: dict[str, float]) -> str:
    if math.isnan(figures['warm_ms']):
        return fmt(figures['time_ms'], 1)
    return f'{figures["time_ms"]:.1f} / {figures["warm_ms"]:.1f}'


def prior_text(prior: PriorConfig, roi: Sequence[float] = (0.0, 0.0, 1.0, 1.0)) -> str:
    """Return the one-line description of a data set's prior and ROI."""
    def rng(values: Sequence[float]) -> str:
        return f'{values[0]:g}..{values[1]:g}'
    return (f'prior: focal {rng(prior.focal_px)} px, b/h {rng(prior.baseline_over_height)}, '
            f'tilt {rng(prior.tilt_deg)} deg, vergence {rng(prior.vergence_deg)} deg, '
            f'{prior.samples}^4 grid, best {prior.refine_best} refined; ROI '
            f'[{", ".join(f"{v:g}" for v in roi)}] (both methods)')


def _by_method(cases: Sequence[Case]) -> Iterator[tuple[Case, str, dict[str, float], str]]:
    """Yield ``(case, method label, figures, 'inliers/points')`` per case and method."""
    for case in cases:
        for method, f in case.figures.items():
            yield case, METHOD_LABEL[method], f, f'{int(f["inliers"])}/{int(f["points"])}'


def kitti_table(cases: Sequence[Case]) -> str:
    """Return the KITTI table."""
    header = ['features', 'method', 'road err px', 'err vs GT disp px', 'road IoU',
              'off-road recall', 'inliers/points', 'ms']
    rows = [['ROI' if case.dataset == 'kitti' else 'full image', label, f['error_px'],
             f['error_vs_gt_disparity_px'], f['road_iou'], f['off_road_recall'], counts,
             _time_cell(f)] for case, label, f, counts in _by_method(cases)]
    info = cases[0].info
    text = (f'reference: d = {info["a"]:.5f} x + {info["b"]:.5f} y {info["c"]:+.2f} '
            f'({100 * info["within_1px"]:.1f} % of GT pixels within 1 px); road = GT pixels '
            f'within {ROAD_PX:g} px ({info["road_px"]}), off-road = beyond {OFF_ROAD_PX:g} px '
            f'({info["off_road_px"]}); the full-image rows use the same prior without ROI')
    return text + '\n' + markdown_table(header, rows)


def chessboard_table(cases: Sequence[Case]) -> str:
    """Return the chessboard table (one row per pair and method, then a summary)."""
    header = ['pair', 'method', 'board err px', 'ref floor px', 'prior gap px',
              'inliers/points', 'ms']
    rows = [[case.pair, label, f['error_px'], case.info['reference_floor_px'],
             case.info['prior_gap_px'], counts, _time_cell(f)]
            for case, label, f, counts in _by_method(cases)]
    summary = []
    for method in ('ours', 'orb_magsac'):
        errors = _errors(cases, method)
        under = int(np.count_nonzero(errors < CHESSBOARD_TARGET_PX))
        summary.append([METHOD_LABEL[method], f'{under}/{len(cases)}',
                        float(np.median(errors)), float(np.max(errors)),
                        _median_time(cases, method)])
    return (markdown_table(header, rows) + '\n\n'
            + markdown_table(['method', f'pairs < {CHESSBOARD_TARGET_PX:g} px',
                              'median err px', 'max err px', 'median ms'], summary))


def _median_time(cases: Sequence[Case], method: str) -> str:
    times = [_median_ms(cases, method, column) for column in ('time_ms', 'warm_ms')]
    if method != 'ours':
        return fmt(times[0], 1)
    return ' / '.join(fmt(t, 1) for t in times)


def qualitative_table(cases: Sequence[Case]) -> str:
    """Return the table of the pairs without reference."""
    header = ['pair', 'method', 'inliers/points', 'plane share', 'obstacle share',
              'methods apart px', 'ms']
    rows = [[case.pair, label, counts + ('' if f['ok'] else ' (failed)'), f['plane_fraction'],
             f['obstacle_fraction'], f['methods_apart_px'], _time_cell(f)]
            for case, label, f, counts in _by_method(cases)]
    return markdown_table(header, rows)


def _rendered_summary(cases: Sequence[Case], method: str) -> list[Any]:
    errors = _errors(cases, method)
    solved = float(np.mean(errors < SOLVED_PX))
    iou = np.array([c.figures[method]['plane_iou'] for c in cases])
    recall = np.array([c.figures[method]['obstacle_recall'] for c in cases])
    return [f'{100 * solved:.0f} %', float(np.median(errors)),
            float(np.nanmedian(iou)) if np.any(np.isfinite(iou)) else math.nan,
            float(np.nanmedian(recall)) if np.any(np.isfinite(recall)) else math.nan,
            _median_time(cases, method)]


def rendered_table(cases: Sequence[Case]) -> str:
    """Return the rendered-scene table: all scenes, then per floor kind."""
    header = ['scenes', 'n', 'method', f'solved (< {SOLVED_PX:g} px)', 'median err px',
              'median plane IoU', 'median obstacle recall', 'median ms']
    rows = []
    groups = [('all', list(cases))] + [
        (kind, [c for c in cases if c.info['floor'] == kind]) for kind in FLOOR_KINDS]
    for label, group in groups:
        if not group:
            continue
        for method in ('ours', 'orb_magsac'):
            rows.append([label, len(group), METHOD_LABEL[method]]
                        + _rendered_summary(group, method))
    return markdown_table(header, rows)


def _median_ms(cases: Sequence[Case], method: str, column: str) -> float:
    values = np.array([c.figures[method][column] for c in cases], np.float64)
    return float(np.nanmedian(values)) if np.any(np.isfinite(values)) else math.nan


def _speed(cases: Sequence[Case]) -> tuple[float, list[tuple[str, float]]]:
    """Return the baseline's median ms and ours as ``[(label, median ms)]`` (cold, warm)."""
    ours = [(label, _median_ms(cases, 'ours', column))
            for label, column in (('cold', 'time_ms'), ('warm', 'warm_ms'))]
    return (_median_ms(cases, 'orb_magsac', 'time_ms'),
            [(label, ms) for label, ms in ours if not math.isnan(ms)])


def speed_line(name: str, cases: Sequence[Case]) -> str:
    """Return the speed comparison of a data set: median times and baseline time / ours."""
    orb, ours = _speed(cases)
    return (f'{name}: median ms ORB + MAGSAC {orb:.1f}, '
            + ', '.join(f'ours {label} {ms:.1f} (ORB / ours = {orb / ms:.2f})'
                        for label, ms in ours))


def _errors(cases: Sequence[Case], method: str = 'ours') -> np.ndarray:
    """Return a method's ``error_px`` per case, (N,) float64."""
    return np.array([c.figures[method]['error_px'] for c in cases])


def targets(groups: dict[str, list[Case]]) -> list[str]:
    """Return one verdict line per target: rendered, KITTI, chessboards, speed per data set."""
    lines = []
    rendered = groups.get('rendered', [])
    if rendered:
        solved = float(np.mean(_errors(rendered) < SOLVED_PX))
        lines.append(f'rendered: {100 * solved:.0f} % solved from a cold start (target '
                     f'{100 * RENDERED_TARGET_SOLVED:.0f} %): '
                     + ('met' if solved >= RENDERED_TARGET_SOLVED else 'MISSED'))
    for case in groups.get('kitti', []):
        err = case.figures['ours']['error_px']
        lines.append(f'kitti: road error {fmt(err)} px (target < {KITTI_TARGET_PX:g} px): '
                     + ('met' if err < KITTI_TARGET_PX else 'MISSED'))
    boards = groups.get('chessboards', [])
    if boards:
        under = int(np.count_nonzero(_errors(boards) < CHESSBOARD_TARGET_PX))
        lines.append(f'chessboards: {under}/{len(boards)} pairs under '
                     f'{CHESSBOARD_TARGET_PX:g} px (target: all): '
                     + ('met' if under == len(boards) else 'MISSED'))
    lines += [_speed_verdict(name, cases) for name, cases in groups.items() if cases]
    return lines


def _speed_verdict(name: str, cases: Sequence[Case]) -> str:
    """Return the speed target's verdict on a data set: time ratios at equal accuracy."""
    orb, ours = _speed(cases)
    verdict = []
    if 'error_px' in cases[0].figures['ours']:
        ours_err = np.median(_errors(cases))
        orb_err = np.median(_errors(cases, 'orb_magsac'))
        accurate = bool(ours_err <= orb_err)
        verdict.append(f'median error ours {fmt(float(ours_err))} vs ORB '
                       f'{fmt(float(orb_err))} px '
                       + ('(equal or better)' if accurate else '(WORSE)'))
    else:
        accurate = None
        verdict.append('no reference')
    for label, value in ours:
        ratio = orb / value
        ok = ratio >= SPEED_TARGET and accurate is not False
        verdict.append(f'{label}: ORB / ours time = {ratio:.2f}'
                       + ('' if accurate is None else (' met' if ok else ' MISSED')))
    return (f'speed {name} (target >= {SPEED_TARGET:g}x at equal or better '
            f'accuracy): ' + '; '.join(verdict))
