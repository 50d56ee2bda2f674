"""Rendered pairs whose dominant plane is not the ground: a board or wall in front of the head.

For ``verification.plane: any``. Each seed draws a correctly ordered head (focal length,
baseline, vergence within the default prior's ranges) and, in front of it, a textured
rectangle that fills much of the view (its side 45-95 % of the view's at its distance), tilted
up to :data:`MAX_TURN_DEG` about the horizontal axis (top toward or away from the head) and
about the vertical one. Its texture is one of :data:`BOARD_TEXTURES`: blobby noise, a
checkerboard (periodic, with or without a plain border), tiles. Behind it, the room: a
backdrop of 3 x 4 nearly plain surfaces (texture contrast 0.02-0.1 of the board's: painted
walls) at 0.7-1.3 times a far depth (2-4 times the board's), each turned its own way, so no
plane behind the board spans the view, and 3-6 textured panels at depths in between.

Every surface is a plane, so each is rendered exactly by warping its texture with its own
homography into each camera (twice supersampled, then area-averaged), nearest last.
The truth is the board's homography ``K (R + t n^T / d) K^-1``; ``plane_left`` is the board
in the left image, ``visible_in_right`` the part of it mapped inside the right image (nothing
stands in front of the board). Nothing here is fitted to any recorded pair.
"""

from __future__ import annotations

import math

import cv2
from domplane_ros.sim.model import CameraSetup, StereoFrame
from domplane_ros.sim.textures import _random_texture
import numpy as np

BOARD_TEXTURES = ('noise', 'checker', 'checker_border', 'tiles')
MAX_TURN_DEG = 30.0
_SUPERSAMPLE = 2
_TEXELS = 512
BACKDROP_ROWS, BACKDROP_COLS = 3, 4


def _rotation(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """Return R = R_y(yaw) R_x(pitch), (3, 3)."""
    p, y = math.radians(pitch_deg), math.radians(yaw_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(p), -math.sin(p)], [0, math.sin(p), math.cos(p)]])
    ry = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
    return ry @ rx


def _texture(kind: str, rng: np.random.Generator) -> np.ndarray:
    """Return a (T, T) float32 texture in [0, 1] of ``kind`` (:data:`BOARD_TEXTURES`)."""
    n = _TEXELS
    if kind == 'noise':
        return _random_texture(rng, n, ((8, 1.0), (32, 0.6), (128, 0.3)), 2.0, 0.08)
    grain = 0.05 * rng.standard_normal((n, n)).astype(np.float32)
    squares = int(rng.integers(5, 13))
    index = (np.arange(n) * squares) // n
    if kind == 'tiles':
        tone = 0.55 + 0.2 * rng.random((squares, squares)).astype(np.float32)
        tex = tone[index[:, None], index[None, :]]
        joint = np.zeros(n, bool)
        joint[(np.arange(n) * squares) % n < max(2, n // 100) * squares] = True
        tex[joint, :] = 0.15
        tex[:, joint] = 0.15
        return np.clip(tex + grain, 0.0, 1.0)
    tex = np.where((index[:, None] + index[None, :]) % 2 == 0, 0.1, 0.9).astype(np.float32)
    if kind == 'checker_border':
        border = n // (squares + 2)
        inner = cv2.resize(tex, (n - 2 * border, n - 2 * border),
                           interpolation=cv2.INTER_NEAREST)
        tex = np.full((n, n), 0.9, np.float32)
        tex[border:n - border, border:n - border] = inner
    return np.clip(tex + grain, 0.0, 1.0)


def _plane_to_image(k: np.ndarray, rot: np.ndarray, centre: np.ndarray,
                    corner: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Return the (3, 3) map from texel (u, v, 1) to image pixels of a camera.

    ``rot``, ``centre``: the camera's rotation (world to camera) and centre; ``corner``: the
    rectangle's world corner at texel (0, 0); ``axes``: (2, 3) world step per texel along u, v.
    """
    cols = np.column_stack([rot @ axes[0], rot @ axes[1], rot @ (corner - centre)])
    return k @ cols


def _render(k: np.ndarray, rot: np.ndarray, centre: np.ndarray, surfaces: list,
            size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Return the float image and the coverage of the last (nearest) surface, (H, W) each."""
    width, height = size
    s = _SUPERSAMPLE
    scale = np.diag([s, s, 1.0])
    shift = np.array([[1.0, 0.0, 0.5 * (s - 1)], [0.0, 1.0, 0.5 * (s - 1)], [0.0, 0.0, 1.0]])
    canvas = np.full((height * s, width * s), 0.5, np.float32)
    cover = np.zeros_like(canvas)
    for tex, corner, axes, gain in surfaces:
        h = shift @ scale @ _plane_to_image(k, rot, centre, corner, axes)
        value = cv2.warpPerspective(tex * gain, h, (width * s, height * s),
                                    flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        inside = cv2.warpPerspective(np.ones_like(tex), h, (width * s, height * s),
                                     flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        canvas = np.where(inside > 0, value, canvas)
        cover = inside
    image = cv2.resize(canvas, size, interpolation=cv2.INTER_AREA)
    return image, cv2.resize(cover, size, interpolation=cv2.INTER_AREA)


def _surface(rng: np.random.Generator, kind: str, centre: np.ndarray, normal_rot: np.ndarray,
             side: tuple[float, float], gain: float, contrast: float = 1.0) -> tuple:
    """Return (texture, corner, axes, gain) of a rectangle centred at ``centre``."""
    ex, ey = normal_rot[:, 0], normal_rot[:, 1]
    corner = centre - 0.5 * side[0] * ex - 0.5 * side[1] * ey
    axes = np.stack([ex * side[0] / _TEXELS, ey * side[1] / _TEXELS])
    texture = 0.5 + contrast * (_texture(kind, rng) - 0.5)
    return texture, corner, axes, gain


def board_scene(seed: int, width: int = 640, height: int = 480) -> StereoFrame:
    """Return a rendered pair whose dominant plane is a tilted board (module docstring).

    Args:
        seed: Scene seed; everything is drawn from it.
        width: Image width in pixels.
        height: Image height in pixels.

    Returns:
        The :class:`~domplane_ros.sim.model.StereoFrame`: ``homography`` the board's,
        ``plane_left`` the board's left pixels, ``floor`` the board's texture kind, ``setup``
        the head (``baseline_over_height``: baseline over the board's distance, tilt 0).

    """
    rng = np.random.default_rng(seed)
    focal = float(rng.uniform(400.0, 900.0))
    vergence = float(rng.uniform(-2.0, 4.0))
    distance = 1.0
    baseline = float(rng.uniform(0.05, 0.2))
    k = np.array([[focal, 0.0, 0.5 * (width - 1)], [0.0, focal, 0.5 * (height - 1)],
                  [0.0, 0.0, 1.0]])
    kind = BOARD_TEXTURES[seed % len(BOARD_TEXTURES)]
    pitch, yaw = rng.uniform(-MAX_TURN_DEG, MAX_TURN_DEG, 2)
    board_rot = _rotation(float(pitch), float(yaw))
    view_w, view_h = width * distance / focal, height * distance / focal
    fill = float(rng.uniform(0.45, 0.95))
    side = (fill * view_w * rng.uniform(0.8, 1.2), fill * view_h * rng.uniform(0.8, 1.2))
    offset = rng.uniform(-0.5, 0.5, 2) * (1.0 - fill) * np.array([view_w, view_h])
    board_centre = np.array([offset[0], offset[1], distance])
    far = distance * float(rng.uniform(2.0, 4.0))
    panels = []
    for row in range(BACKDROP_ROWS):
        for col in range(BACKDROP_COLS):
            # The room behind: a grid of surfaces at their own depths and turns, so that no
            # plane behind the board spans the view.
            depth = far * float(rng.uniform(0.7, 1.3))
            cell = (1.6 * depth * width / focal / BACKDROP_COLS,
                    1.6 * depth * height / focal / BACKDROP_ROWS)
            centre = np.array([(col + 0.5 - 0.5 * BACKDROP_COLS) * cell[0],
                               (row + 0.5 - 0.5 * BACKDROP_ROWS) * cell[1], depth])
            panels.append((depth, _surface(rng, 'noise', centre,
                                           _rotation(*rng.uniform(-40, 40, 2)),
                                           (1.5 * cell[0], 1.5 * cell[1]),
                                           float(rng.uniform(0.5, 1.0)),
                                           float(rng.uniform(0.02, 0.1)))))
    for _ in range(int(rng.integers(3, 7))):
        depth = float(rng.uniform(1.4 * distance, 0.95 * far))
        centre = np.array([*(rng.uniform(-0.5, 0.5, 2) * depth * np.array([width, height])
                             / focal), depth])
        size = tuple(rng.uniform(0.1, 0.4, 2) * depth * width / focal)
        panels.append((depth, _surface(rng, str(rng.choice(['noise', 'tiles'])), centre,
                                       _rotation(*rng.uniform(-40, 40, 2)), size,
                                       float(rng.uniform(0.5, 1.0)))))
    surfaces = [s for _, s in sorted(panels, key=lambda item: -item[0])]
    surfaces.append(_surface(rng, kind, board_centre, board_rot, side,
                             float(rng.uniform(0.7, 1.0))))
    right_rot = _rotation(0.0, vergence)
    right_centre = np.array([baseline, 0.0, 0.0])
    left, cover = _render(k, np.eye(3), np.zeros(3), surfaces, (width, height))
    right, _ = _render(k, right_rot, right_centre, surfaces, (width, height))
    gain, offset_grey = rng.uniform(0.85, 1.15), rng.uniform(-10.0, 10.0)
    noise = float(rng.uniform(0.5, 2.0))
    left_img = np.clip(20 + 215 * left + noise * rng.standard_normal(left.shape), 0, 255)
    right_img = np.clip(gain * (20 + 215 * right) + offset_grey
                        + noise * rng.standard_normal(right.shape), 0, 255)
    normal = board_rot[:, 2]
    plane_distance = float(normal @ board_centre)
    t = -right_rot @ right_centre
    truth = k @ (right_rot + np.outer(t, normal) / plane_distance) @ np.linalg.inv(k)
    truth /= truth[2, 2]
    plane_left = cover > 0.999
    ys, xs = np.nonzero(plane_left)
    mapped = truth @ np.stack([xs, ys, np.ones(xs.size)])
    mx, my = mapped[0] / mapped[2], mapped[1] / mapped[2]
    visible = np.zeros_like(plane_left)
    visible[ys, xs] = (mx >= 0) & (mx <= width - 1) & (my >= 0) & (my <= height - 1)
    setup = CameraSetup(focal, baseline / plane_distance, 0.0, vergence, width, height)
    return StereoFrame(left_img.astype(np.uint8), right_img.astype(np.uint8), truth,
                       plane_left, visible, ~plane_left, setup, floor=kind)
