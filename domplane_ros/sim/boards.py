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

Two variants, for the real boards' conditions (the OpenCV chessboards: an uncorrected lens, a
board covering a fifth of the view in a textured room), each drawn from its own stream of the
seed so that the scene is otherwise the same:

* ``lens=True``: both cameras see through a radial lens, ``x_d = x_u (1 + k1 r_u^2)`` on
  normalised coordinates about the image centre (:func:`distort_px`), ``k1`` of the left
  camera drawn from :data:`LENS_K1` (barrel, three times in four, else pincushion; at most
  :data:`MAX_CORNER_DISTORTION` at the image corner), the right camera's within
  :data:`LENS_K1_SPREAD` of it. Each view is rendered undistorted with a margin
  and resampled through its lens. No homography maps the board exactly then; ``homography`` is
  the least-squares homography of the board's true correspondences (its visible pixels
  through both lenses), the analogue of the chessboards' reference fitted to their corners,
  and :func:`true_right_px` gives the true correspondences themselves.
* ``small=True``: the board's side is 35-60 % of the view's (15-40 % of the image) and the
  room behind is textured (backdrop contrast 0.2-1.0 of the board's, not painted walls) and
  cluttered: a 6 x 8 backdrop grid and panels at most a quarter of the view wide, so that the
  board stays the dominant plane (no surface of the room is as large).
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
# Radial k1 of the left camera's lens (normalised coordinates), magnitude range: a cheap
# webcam's; the right camera's is the left's times 1 +- LENS_K1_SPREAD.
LENS_K1 = (0.05, 0.25)
LENS_K1_SPREAD = 0.2
# Largest |k1| r^2 at the image corner (a corner moved by up to about 12 % of its radius).
MAX_CORNER_DISTORTION = 0.12
# Side of a small board, share of the view's side at its distance, and its room's contrast.
SMALL_FILL = (0.35, 0.6)
SMALL_ROOM_CONTRAST = (0.2, 1.0)
# The small board's room: a finer backdrop grid and smaller panels, so that no surface of the
# textured room is a plane as large as the board (else the room's would be the dominant plane).
SMALL_BACKDROP = (6, 8)


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


def lens_k1(seed: int, corner_radius: float = 0.0) -> tuple[float, float]:
    """Return the radial k1 of the left and the right lens of ``board_scene(seed, lens=True)``.

    ``corner_radius``: the image corner's distance from the centre over the focal length; the
    lenses are scaled down so that ``|k1| corner_radius^2`` stays at most
    :data:`MAX_CORNER_DISTORTION` (a stronger barrel folds the image corners back inward).
    """
    rng = np.random.default_rng([seed, 7])
    magnitude = float(rng.uniform(*LENS_K1))
    sign = -1.0 if rng.random() < 0.75 else 1.0  # barrel three times in four
    right = float(rng.uniform(1.0 - LENS_K1_SPREAD, 1.0 + LENS_K1_SPREAD))
    magnitude = min(magnitude, MAX_CORNER_DISTORTION / max(corner_radius, 1e-9) ** 2
                    / (1.0 + LENS_K1_SPREAD))
    return sign * magnitude, sign * magnitude * right


def distort_px(points: np.ndarray, k1: float, focal: float, centre: np.ndarray) -> np.ndarray:
    """Return (N, 2) pixels seen through the lens: ``x_d = x_u (1 + k1 r_u^2)``, normalised."""
    norm = (np.asarray(points, np.float64) - centre) / focal
    r2 = np.sum(norm * norm, axis=1, keepdims=True)
    return centre + focal * norm * (1.0 + k1 * r2)


def undistort_px(points: np.ndarray, k1: float, focal: float, centre: np.ndarray,
                 iterations: int = 30) -> np.ndarray:
    """Return (N, 2) undistorted pixels of pixels seen through the lens (:func:`distort_px`)."""
    seen = (np.asarray(points, np.float64) - centre) / focal
    norm = seen.copy()
    for _ in range(iterations):  # fixed point of x_u = x_d / (1 + k1 r_u^2)
        norm = seen / (1.0 + k1 * np.sum(norm * norm, axis=1, keepdims=True))
    return centre + focal * norm


def true_right_px(left_px: np.ndarray, homography: np.ndarray, k1: tuple[float, float],
                  focal: float, centre: np.ndarray) -> np.ndarray:
    """Return (N, 2) right pixels of a plane's left pixels seen through both lenses.

    ``homography``: the plane's (3, 3) map between undistorted pixels; ``k1``: the left and
    right lens (:func:`lens_k1`).
    """
    undistorted = undistort_px(left_px, k1[0], focal, centre)
    mapped = homography @ np.column_stack([undistorted, np.ones(len(undistorted))]).T
    return distort_px((mapped[:2] / mapped[2]).T, k1[1], focal, centre)


def _render_lens(k: np.ndarray, rot: np.ndarray, centre: np.ndarray, surfaces: list,
                 size: tuple[int, int], k1: float) -> tuple[np.ndarray, np.ndarray]:
    """Return :func:`_render`'s image and coverage seen through a radial lens ``k1``."""
    width, height = size
    focal, principal = float(k[0, 0]), k[:2, 2]
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    source = undistort_px(np.column_stack([xs.ravel(), ys.ravel()]), k1, focal, principal)
    margin = int(math.ceil(max(0.0, -source.min(), source[:, 0].max() - (width - 1),
                               source[:, 1].max() - (height - 1)))) + 2
    padded = k.copy()
    padded[:2, 2] += margin
    image, cover = _render(padded, rot, centre, surfaces, (width + 2 * margin,
                                                           height + 2 * margin))
    map_x = (source[:, 0] + margin).reshape(height, width).astype(np.float32)
    map_y = (source[:, 1] + margin).reshape(height, width).astype(np.float32)
    return (cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR),
            cv2.remap(cover, map_x, map_y, cv2.INTER_LINEAR))


def _room_contrast(rng: np.random.Generator, small: bool) -> float:
    """Return a backdrop surface's texture contrast: painted walls, or a textured room."""
    draw = float(rng.uniform(0.02, 0.1))
    if not small:
        return draw
    low, high = SMALL_ROOM_CONTRAST
    return low + (draw - 0.02) / 0.08 * (high - low)


def _surface(rng: np.random.Generator, kind: str, centre: np.ndarray, normal_rot: np.ndarray,
             side: tuple[float, float], gain: float, contrast: float = 1.0) -> tuple:
    """Return (texture, corner, axes, gain) of a rectangle centred at ``centre``."""
    ex, ey = normal_rot[:, 0], normal_rot[:, 1]
    corner = centre - 0.5 * side[0] * ex - 0.5 * side[1] * ey
    axes = np.stack([ex * side[0] / _TEXELS, ey * side[1] / _TEXELS])
    texture = 0.5 + contrast * (_texture(kind, rng) - 0.5)
    return texture, corner, axes, gain


def board_scene(seed: int, width: int = 640, height: int = 480, lens: bool = False,
                small: bool = False) -> StereoFrame:
    """Return a rendered pair whose dominant plane is a tilted board (module docstring).

    Args:
        seed: Scene seed; everything is drawn from it.
        width: Image width in pixels.
        height: Image height in pixels.
        lens: Both cameras see through radial lenses (:func:`lens_k1`); ``homography`` is
            then the least-squares fit to the board's true correspondences.
        small: A small board (:data:`SMALL_FILL`) in a textured room.

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
    if small:
        fill = SMALL_FILL[0] + (fill - 0.45) / 0.5 * (SMALL_FILL[1] - SMALL_FILL[0])
    side = (fill * view_w * rng.uniform(0.8, 1.2), fill * view_h * rng.uniform(0.8, 1.2))
    offset = rng.uniform(-0.5, 0.5, 2) * (1.0 - fill) * np.array([view_w, view_h])
    board_centre = np.array([offset[0], offset[1], distance])
    far = distance * float(rng.uniform(2.0, 4.0))
    panels = []
    rows, cols = SMALL_BACKDROP if small else (BACKDROP_ROWS, BACKDROP_COLS)
    for row in range(rows):
        for col in range(cols):
            # The room behind: a grid of surfaces at their own depths and turns, so that no
            # plane behind the board spans the view.
            depth = far * float(rng.uniform(0.7, 1.3))
            cell = (1.6 * depth * width / focal / cols, 1.6 * depth * height / focal / rows)
            centre = np.array([(col + 0.5 - 0.5 * cols) * cell[0],
                               (row + 0.5 - 0.5 * rows) * cell[1], depth])
            panels.append((depth, _surface(rng, 'noise', centre,
                                           _rotation(*rng.uniform(-40, 40, 2)),
                                           (1.5 * cell[0], 1.5 * cell[1]),
                                           float(rng.uniform(0.5, 1.0)),
                                           _room_contrast(rng, small))))
    for _ in range(int(rng.integers(3, 7))):
        depth = float(rng.uniform(1.4 * distance, 0.95 * far))
        centre = np.array([*(rng.uniform(-0.5, 0.5, 2) * depth * np.array([width, height])
                             / focal), depth])
        size = tuple(rng.uniform(0.1, 0.25 if small else 0.4, 2) * depth * width / focal)
        panels.append((depth, _surface(rng, str(rng.choice(['noise', 'tiles'])), centre,
                                       _rotation(*rng.uniform(-40, 40, 2)), size,
                                       float(rng.uniform(0.5, 1.0)))))
    surfaces = [s for _, s in sorted(panels, key=lambda item: -item[0])]
    surfaces.append(_surface(rng, kind, board_centre, board_rot, side,
                             float(rng.uniform(0.7, 1.0))))
    right_rot = _rotation(0.0, vergence)
    right_centre = np.array([baseline, 0.0, 0.0])
    corner = math.hypot(0.5 * width, 0.5 * height) / focal
    k1 = lens_k1(seed, corner) if lens else (0.0, 0.0)
    if lens:
        left, cover = _render_lens(k, np.eye(3), np.zeros(3), surfaces, (width, height), k1[0])
        right, _ = _render_lens(k, right_rot, right_centre, surfaces, (width, height), k1[1])
    else:
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
    mapped = true_right_px(np.column_stack([xs, ys]), truth, k1, focal, k[:2, 2])
    mx, my = mapped[:, 0], mapped[:, 1]
    visible = np.zeros_like(plane_left)
    inside = (mx >= 0) & (mx <= width - 1) & (my >= 0) & (my <= height - 1)
    visible[ys, xs] = inside
    if lens:
        every = max(1, int(np.count_nonzero(inside)) // 4000)
        src = np.column_stack([xs, ys])[inside][::every].astype(np.float64)
        fitted, _ = cv2.findHomography(src, mapped[inside][::every], 0)
        truth = fitted / fitted[2, 2]
    setup = CameraSetup(focal, baseline / plane_distance, 0.0, vergence, width, height)
    return StereoFrame(left_img.astype(np.uint8), right_img.astype(np.uint8), truth,
                       plane_left, visible, ~plane_left, setup, floor=kind)
