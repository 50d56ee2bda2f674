"""The evaluation's pictures: the contact sheet and the error and time box plots."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

from domplane_ros.core.mask import overlay
from domplane_ros.sim.textures import FLOOR_KINDS
from domplane_ros.tools.evaluation.datasets import Case
from domplane_ros.tools.evaluation.tables import fmt
import numpy as np


def contact_sheet(path: Path, cases: Sequence[Case], title: str = '') -> None:
    """Write a labelled grid of left images with the product's mask and inliers.

    Args:
        path: Output PNG.
        cases: Pairs to show, in order; a KITTI case gets a whole row.
        title: Figure title.

    """
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    cols = 3
    wide = [c for c in cases if c.dataset == 'kitti']
    rest = [c for c in cases if c.dataset != 'kitti']
    rows = len(wide) + math.ceil(len(rest) / cols)
    heights = [1.5] * len(wide) + [2.2] * math.ceil(len(rest) / cols)
    fig = plt.figure(figsize=(15, sum(heights) * 1.55 + 0.6))
    grid = fig.add_gridspec(rows, cols, height_ratios=heights)
    slots = [grid[i, :] for i in range(len(wide))]
    slots += [grid[len(wide) + i // cols, i % cols] for i in range(len(rest))]
    for slot, case in zip(slots, wide + rest):
        ax = fig.add_subplot(slot)
        ours = case.runs['ours']
        mask = ours.mask if ours.mask is not None else np.zeros_like(case.left)
        ax.imshow(overlay(case.left, mask, ours.inlier_points, ours.outlier_points))
        ax.set_axis_off()
        ax.set_title(_case_label(case), fontsize=8)
    fig.suptitle(title or 'ours: green = plane, red = obstacle, cyan o = corner matched on '
                 'the plane, magenta x = unmatched corner', fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _case_label(case: Case) -> str:
    ours, orb = case.figures['ours'], case.figures['orb_magsac']
    if 'error_px' in ours:
        parts = [f'ours {fmt(ours["error_px"])} px', f'ORB {fmt(orb["error_px"])} px']
    else:
        parts = [f'ours {int(ours["inliers"])} inl', f'ORB {int(orb["inliers"])} inl',
                 f'apart {fmt(ours["methods_apart_px"], 1)} px']
    extra = f' ({case.info["floor"]})' if 'floor' in case.info else ''
    return (f'{case.dataset} {case.pair}{extra}: ' + ', '.join(parts)
            + f', ours {ours["time_ms"]:.0f}/{ours["warm_ms"]:.0f} ms, '
            f'ORB {orb["time_ms"]:.0f} ms')


ERROR_CAP_PX = 300.0


def error_plot(path: Path, groups: dict[str, Sequence[Case]]) -> None:
    """Write box plots of the errors and times per data set, ours vs ORB + MAGSAC.

    Failures are drawn at :data:`ERROR_CAP_PX`. Data sets without a reference (no
    ``error_px``) only appear in the time panel.
    """
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    fig, (ax_err, ax_time) = plt.subplots(1, 2, figsize=(16, 5.5),
                                          gridspec_kw={'width_ratios': [2, 3]})
    colours = {'ours': 'tab:green', 'orb_magsac': 'tab:orange', 'ours_warm': 'tab:olive'}
    with_error = {k: v for k, v in groups.items() if v and 'error_px' in v[0].figures['ours']}
    _boxes(ax_err, with_error, [('ours', 'error_px'), ('orb_magsac', 'error_px')], colours,
           cap=ERROR_CAP_PX)
    ax_err.set_yscale('log')
    ax_err.set_ylabel(f'mean transfer error, px (failures at {ERROR_CAP_PX:g})')
    ax_err.axhline(1.0, color='grey', lw=0.8, ls='--')
    ax_err.set_title('error: ours (cold start; stream: warm from the previous frame) vs '
                     'ORB + MAGSAC', fontsize=10)
    present = {k: v for k, v in groups.items() if v}
    _boxes(ax_time, present, [('ours', 'time_ms'), ('ours_warm', 'warm_ms'),
                              ('orb_magsac', 'time_ms')], colours)
    ax_time.set_yscale('log')
    ax_time.set_ylabel('time per pair, ms (1 thread)')
    ax_time.set_title('time: ours cold, ours warm, ORB + MAGSAC')
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _boxes(ax: Any, groups: dict[str, Sequence[Case]], series: Sequence[tuple[str, str]],
           colours: dict[str, str], cap: float | None = None) -> None:
    width = 0.8 / len(series)
    for index, (name, cases) in enumerate(groups.items()):
        for k, (method, column) in enumerate(series):
            source = 'ours' if method == 'ours_warm' else method
            values = np.array([c.figures[source][column] for c in cases], np.float64)
            if cap is not None:
                values = np.minimum(np.where(np.isfinite(values), values, cap), cap)
            values = values[np.isfinite(values)]
            if values.size == 0:
                continue
            pos = index + (k - (len(series) - 1) / 2) * width
            box = ax.boxplot(values, positions=[pos], widths=0.9 * width, patch_artist=True,
                             showfliers=False)
            for patch in box['boxes']:
                patch.set_facecolor(colours[method])
                patch.set_alpha(0.5)
            jitter = np.random.default_rng(index).uniform(-0.25, 0.25, values.size) * width
            ax.scatter(pos + jitter, values, s=8, color=colours[method], zorder=3)
    ax.set_xticks(range(len(groups)))
    ax.set_xticklabels([f'{k.replace("_", " ")}\n(n={len(v)})' for k, v in groups.items()],
                       fontsize=8)
    names = {'ours': 'ours', 'ours_warm': 'ours warm', 'orb_magsac': 'ORB + MAGSAC'}
    handles = [_legend_patch(colours[m], names[m]) for m, _ in series]
    ax.legend(handles=handles, fontsize=8)


def _legend_patch(colour: str, label: str) -> Any:
    from matplotlib.patches import Patch
    return Patch(facecolor=colour, alpha=0.5, label=label)


def pick_rendered(cases: Sequence[Case], count: int = 4) -> list[Case]:
    """Return one scene per floor kind (first seen), then fill up in seed order."""
    picked: list[Case] = []
    for kind in FLOOR_KINDS:
        picked += [c for c in cases if c.info['floor'] == kind][:1]
    picked += [c for c in cases if c not in picked]
    return picked[:count]
