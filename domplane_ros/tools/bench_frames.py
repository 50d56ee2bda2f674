"""The benchmarks' rendered frames: image messages with their truth, decoded as the node does.

Shared by :mod:`~domplane_ros.tools.bench_pipeline` (the per-pair rows) and
:mod:`~domplane_ros.tools.bench_live` (the live node and the breakdown). Sizes above 1280x720
are the 1280x720 renders upscaled (bicubic), the truth scaled with them: the renderer is slow.
"""

from __future__ import annotations

from dataclasses import dataclass
import functools
from typing import Any

import cv2
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.image import message_to_gray
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.truth import every_floor_pixel
from domplane_ros.tools.common import mono8_message
import numpy as np

_RENDER_LIMIT = (1280, 720)  # larger sizes are upscaled renders (the renderer is slow)


@dataclass
class BenchFrame:
    """One stereo pair as messages, with its truth in the pair's own pixels."""

    left: Any
    right: Any
    homography: np.ndarray
    floor: np.ndarray

    def error(self, h: np.ndarray | None) -> float:
        """Return the mean transfer error over the floor pixels (inf without H)."""
        if h is None:
            return float('inf')
        diff = apply_homography(h, self.floor) - apply_homography(self.homography, self.floor)
        return float(np.mean(np.linalg.norm(diff, axis=1)))


def bench_frames(frames: list, scale: int) -> list[BenchFrame]:
    """Return rendered frames as :class:`BenchFrame` messages, upscaled ``scale`` times."""
    out = []
    for f in frames:
        left, right, h = f.left, f.right, f.homography
        if scale != 1:
            size = (left.shape[1] * scale, left.shape[0] * scale)
            left = cv2.resize(left, size, interpolation=cv2.INTER_CUBIC)
            right = cv2.resize(right, size, interpolation=cv2.INTER_CUBIC)
            s = np.diag([scale, scale, 1.0])
            # Upscaling maps pixel centre x to scale x + (scale - 1) / 2.
            shift = np.array([[1.0, 0, (scale - 1) / 2], [0, 1.0, (scale - 1) / 2], [0, 0, 1]])
            to_big = shift @ s
            h = to_big @ h @ np.linalg.inv(to_big)
            floor = apply_homography(to_big, every_floor_pixel(f, 37))
        else:
            floor = every_floor_pixel(f, 37)
        out.append(BenchFrame(mono8_message(left), mono8_message(right), h, floor))
    return out


@functools.lru_cache(maxsize=4)
def _rendered(n_frames: int, seed: int, width: int, height: int) -> list:
    return scene_sequence(n_frames, seed, width=width, height=height, floor='random')


def sequence(width: int, height: int, n_frames: int, seed: int) -> tuple[list[BenchFrame], Any]:
    """Return a rendered moving sequence at ``width`` x ``height`` and its camera set-up."""
    scale = max(1, int(round(width / _RENDER_LIMIT[0])))
    frames = _rendered(n_frames, seed, width // scale, height // scale)
    return bench_frames(frames, scale), frames[0].setup


def decode(msg: Any) -> np.ndarray:
    """Decode an image message as the node's session does (read-only, uncopied if it can)."""
    gray = message_to_gray(msg, copy=False)
    gray.flags.writeable = False
    return gray
