"""Scoring against a rendered frame's truth: floor pixels seen by both cameras, transfer error.

The tools score a homography by the mean distance between its image and the true homography's
image of floor pixels that the right camera sees; they differ only in which of those pixels
they use (a grid, or every k-th pixel), so both samplings are here. Over a sequence,
:func:`relock_runs` counts the frames each loss of the lock lasted.
"""

from __future__ import annotations

import math
from typing import Sequence

from domplane_ros.core.homography import apply_homography
from domplane_ros.sim.model import StereoFrame
import numpy as np


def floor_points(frame: StereoFrame, step: int = 4, offset: int = 0) -> np.ndarray:
    """Return the visible floor pixels on a grid, (N, 2) float64 ``(x, y)`` in raster order.

    Args:
        frame: The rendered frame.
        step: Grid spacing in pixels, both ways.
        offset: Row and column of the first grid line.

    Returns:
        The left pixels on the floor and seen by the right camera, at ``offset + k * step``.

    """
    truth = frame.plane_left & frame.visible_in_right
    grid = np.zeros_like(truth)
    grid[offset::step, offset::step] = True
    ys, xs = np.nonzero(truth & grid)
    return np.stack([xs, ys], axis=1).astype(np.float64)


def every_floor_pixel(frame: StereoFrame, every: int = 1) -> np.ndarray:
    """Return every ``every``-th visible floor pixel in raster order, (N, 2) float64 ``(x, y)``."""
    pixels = np.argwhere(frame.plane_left & frame.visible_in_right)
    return pixels[::every, ::-1].astype(np.float64)


def transfer_error_px(homography: np.ndarray | None, frame: StereoFrame,
                      points: np.ndarray) -> float:
    """Return the mean ``||H x - H_true x||`` over (N, 2) points; inf without H or points."""
    if homography is None or points.shape[0] == 0:
        return math.inf
    diff = apply_homography(homography, points) - apply_homography(frame.homography, points)
    return float(np.mean(np.linalg.norm(diff, axis=1)))


def relock_runs(locked: Sequence[bool], dropout: Sequence[bool] | None = None) -> list[int]:
    """Return, for each loss, the frames it took to re-lock.

    A loss starts at an unlocked frame after a locked one and ends at the next locked frame;
    frames before the first locked one are not a loss. Drop-out frames (blank input) in a loss
    are not counted, so a loss caused by a drop-out counts the frames after the input came
    back (0 if the first of them is locked). A loss still open at the end of the sequence
    counts with its length so far.

    Args:
        locked: Per-frame lock flags of one sequence, in order.
        dropout: Per-frame drop-out flags (default: none).

    Returns:
        One count per loss.

    """
    runs = []
    seen_lock = in_loss = False
    run = 0
    for k, flag in enumerate(locked):
        if flag:
            if in_loss:
                runs.append(run)
            seen_lock, in_loss, run = True, False, 0
        elif seen_lock:
            in_loss = True
            if not (dropout is not None and dropout[k]):
                run += 1
    if in_loss:
        runs.append(run)
    return runs
