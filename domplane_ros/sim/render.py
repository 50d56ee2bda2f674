"""The ray caster: renders a stereo pair of a textured floor with boxes, and its ground truth.

Every pixel averages ``supersample x supersample`` rays, so both cameras see the same,
anti-aliased texture (:mod:`~domplane_ros.sim.textures`). Box faces are Lambert-shaded by a
fixed light, which is view independent, so a floor or box point has the same radiance in both
cameras; only the right camera's gain/offset and the pixel noise differ. The geometry and the
frames are those of :mod:`~domplane_ros.sim.model`.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import cv2
from domplane_ros.sim.model import (BACKGROUNDS, Box, camera_poses, CameraSetup, HeadPose,
                                    level_from_left, StereoFrame)
from domplane_ros.sim.render_cache import cached
from domplane_ros.sim.textures import (ALL_FLOOR_KINDS, BOX_TEXEL, FLOOR_TEXEL, sample,
                                       texture_pyramid, TEXTURE_VARIANTS, WALL_TEXEL)
import numpy as np

# Grey levels: texture value v in [0, 1] becomes _BLACK + _RANGE * v.
_BLACK = 20.0
_RANGE = 215.0
_SKY = 0.78
# Direction *toward* the light in the level frame (y points down, so -y is up).
_LIGHT = np.array([-0.35, -1.0, -0.45]) / np.linalg.norm([-0.35, -1.0, -0.45])
_EPS = 1e-9
_ANISOTROPY = 0.75
# Surface labels of the rendered sub-samples.
SKY, FLOOR, BOX, WALL = 0, 1, 2, 3


@dataclass(frozen=True)
class _PlacedBox:
    """A box with its level-to-local rigid transform and per-face texture offsets."""

    box: Box
    rot: np.ndarray      # (2, 2): local (x, z) = rot @ (level (x, z) - centre)
    centre: np.ndarray   # (2,)
    offsets: np.ndarray  # (3, 2) texture offsets (world units) for x-faces, z-faces, top
    shade: np.ndarray    # (3, 2) Lambert shade per axis and sign (-, +)
    brightness: float

    def corners_level(self) -> np.ndarray:
        """(8, 3) corners in the level frame."""
        b = self.box
        out = []
        for sx in (-0.5, 0.5):
            for sz in (-0.5, 0.5):
                local = np.array([sx * b.width, sz * b.depth])
                xz = self.rot.T @ local + self.centre
                for y in (1.0 - b.height, 1.0):
                    out.append((xz[0], y, xz[1]))
        return np.array(out)


def place_boxes(boxes: Sequence[Box], variant_seed: int) -> list[_PlacedBox]:
    """Return the boxes with their transforms, seeded face textures and Lambert shades."""
    placed = []
    for index, box in enumerate(boxes):
        rng = np.random.default_rng((variant_seed, index, 99))
        yaw = math.radians(box.yaw_deg)
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s], [s, c]])
        shade = np.empty((3, 2))
        for axis in range(3):
            for side, sign in enumerate((-1.0, 1.0)):
                normal_local = np.zeros(3)
                normal_local[axis] = sign
                normal_xz = rot.T @ normal_local[[0, 2]]
                normal = np.array([normal_xz[0], normal_local[1], normal_xz[1]])
                shade[axis, side] = 0.45 + 0.55 * max(0.0, float(normal @ _LIGHT))
        placed.append(_PlacedBox(box=box, rot=rot, centre=np.array([box.x, box.z]),
                                 offsets=rng.uniform(0, 50, (3, 2)), shade=shade,
                                 brightness=float(rng.uniform(0.85, 1.15))))
    return placed


def _slab(box: _PlacedBox, origin: np.ndarray, dx: np.ndarray, dy: np.ndarray,
          dz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ray/box slab test in the box's local frame.

    Args:
        box: The placed box.
        origin: (3,) ray origin in the level frame.
        dx: (N,) ray direction x in the level frame.
        dy: (N,) ray direction y.
        dz: (N,) ray direction z.

    Returns:
        ``(t_near, t_far, axis, local)``: (N,) entry and exit ray parameters, (N,) int axis of
        the entry face (0 = x, 1 = y, 2 = z) and the (3,) local ray origin.

    """
    b = box.box
    o_xz = box.rot @ (origin[[0, 2]] - box.centre)
    lx = box.rot[0, 0] * dx + box.rot[0, 1] * dz
    lz = box.rot[1, 0] * dx + box.rot[1, 1] * dz
    lows = (-0.5 * b.width, 1.0 - b.height, -0.5 * b.depth)
    highs = (0.5 * b.width, 1.0, 0.5 * b.depth)
    local_origin = (o_xz[0], origin[1], o_xz[1])
    t_in = []
    t_out = []
    for o, d, lo, hi in zip(local_origin, (lx, dy, lz), lows, highs):
        safe = np.where(np.abs(d) < _EPS, _EPS, d)
        t1 = (lo - o) / safe
        t2 = (hi - o) / safe
        t_in.append(np.minimum(t1, t2))
        t_out.append(np.maximum(t1, t2))
    t_in_all = np.stack(t_in)
    axis = np.argmax(t_in_all, axis=0)
    t_near = np.max(t_in_all, axis=0)
    t_far = np.minimum(np.minimum(t_out[0], t_out[1]), t_out[2])
    return t_near, t_far, axis, np.array(local_origin)


def _project_rect(corners: np.ndarray, origin: np.ndarray, rot_cl: np.ndarray,
                  k: np.ndarray, width: int, height: int) -> tuple[int, int, int, int] | None:
    """Return the pixel bounding rectangle ``(x0, y0, x1, y1)`` of (N, 3) level-frame points.

    The rectangle is the whole image if a point is behind the camera, and None if all are.
    """
    cam = (corners - origin) @ rot_cl  # rows: rot_cl.T @ (p - o)
    if np.all(cam[:, 2] <= 1e-6):
        return None
    if np.any(cam[:, 2] <= 1e-6):
        return 0, 0, width, height
    pix = cam @ k.T
    xs = pix[:, 0] / pix[:, 2]
    ys = pix[:, 1] / pix[:, 2]
    x0 = max(0, int(math.floor(xs.min())) - 2)
    y0 = max(0, int(math.floor(ys.min())) - 2)
    x1 = min(width, int(math.ceil(xs.max())) + 3)
    y1 = min(height, int(math.ceil(ys.max())) + 3)
    if x0 >= x1 or y0 >= y1:
        return None
    return x0, y0, x1, y1


@dataclass(frozen=True)
class _Rays:
    """The sub-sample rays of one camera, unit length, in the level frame.

    Attributes:
        dx: (H * s, W * s) float64 direction x.
        dy: (H * s, W * s) float64 direction y (down).
        dz: (H * s, W * s) float64 direction z (forward).
        pixel_angle: Angle between neighbouring sub-samples, radians.
        k_sub: (3, 3) float64 calibration matrix of the sub-sample grid.
    """

    dx: np.ndarray
    dy: np.ndarray
    dz: np.ndarray
    pixel_angle: float
    k_sub: np.ndarray


@dataclass(frozen=True)
class _Canvas:
    """What the rays of one camera hit so far: range, radiance and surface label."""

    t_best: np.ndarray
    value: np.ndarray
    label: np.ndarray


def _camera_rays(setup: CameraSetup, rot_cl: np.ndarray, s: int) -> _Rays:
    """Return the normalised level-frame rays of every sub-sample (``s`` per pixel side)."""
    width, height = setup.width * s, setup.height * s
    f = setup.focal_px
    cx, cy = (setup.width - 1) / 2.0, (setup.height - 1) / 2.0
    sub_x = (np.arange(width) + 0.5) / s - 0.5
    sub_y = (np.arange(height) + 0.5) / s - 0.5
    xn = ((sub_x - cx) / f)[None, :]
    yn = ((sub_y - cy) / f)[:, None]
    # Level-frame ray directions, normalised (so t is the range).
    dx = rot_cl[0, 0] * xn + rot_cl[0, 1] * yn + rot_cl[0, 2]
    dy = rot_cl[1, 0] * xn + rot_cl[1, 1] * yn + rot_cl[1, 2]
    dz = rot_cl[2, 0] * xn + rot_cl[2, 1] * yn + rot_cl[2, 2]
    norm = np.sqrt(dx * dx + dy * dy + dz * dz)
    k_sub = np.array([[f * s, 0.0, (cx + 0.5) * s - 0.5], [0.0, f * s, (cy + 0.5) * s - 0.5],
                      [0.0, 0.0, 1.0]])
    return _Rays(dx / norm, dy / norm, dz / norm, 1.0 / (f * s), k_sub)


def _draw_floor(canvas: _Canvas, rays: _Rays, origin: np.ndarray, t_wall: np.ndarray | None,
                floor: str, variant: int, head_pose: HeadPose) -> None:
    """Paint the floor ``y = 1`` (in front of the wall, if any) into an empty canvas."""
    down = rays.dy > 1e-9
    t_floor = np.where(down, (1.0 - origin[1]) / np.where(down, rays.dy, 1.0), np.inf)
    hit = np.isfinite(t_floor)
    if t_wall is not None:
        hit &= t_floor < t_wall
    if not np.any(hit):
        return
    t = t_floor[hit]
    xl = origin[0] + t * rays.dx[hit]
    zl = origin[2] + t * rays.dz[hit]
    yaw = math.radians(head_pose.yaw_deg)
    wx = head_pose.x + xl * math.cos(yaw) + zl * math.sin(yaw)
    wz = head_pose.z - xl * math.sin(yaw) + zl * math.cos(yaw)
    footprint = t * rays.pixel_angle / rays.dy[hit] ** _ANISOTROPY / FLOOR_TEXEL
    canvas.value[hit] = sample(texture_pyramid(floor, variant), wx / FLOOR_TEXEL,
                               wz / FLOOR_TEXEL, footprint)
    canvas.t_best[hit] = t
    canvas.label[hit] = FLOOR


def _draw_wall(canvas: _Canvas, rays: _Rays, origin: np.ndarray, t_wall: np.ndarray,
               variant: int) -> None:
    """Paint the wall where it is nearer than what the canvas holds."""
    hit = np.isfinite(t_wall) & (t_wall < canvas.t_best)
    if not np.any(hit):
        return
    t = t_wall[hit]
    xl = origin[0] + t * rays.dx[hit]
    yl = origin[1] + t * rays.dy[hit]
    footprint = t * rays.pixel_angle / rays.dz[hit] ** _ANISOTROPY / WALL_TEXEL
    canvas.value[hit] = sample(texture_pyramid('wall', variant), xl / WALL_TEXEL,
                               yl / WALL_TEXEL, footprint)
    canvas.t_best[hit] = t
    canvas.label[hit] = WALL


def _draw_box(canvas: _Canvas, rays: _Rays, origin: np.ndarray, rot_cl: np.ndarray,
              box: _PlacedBox, box_pyramid: tuple[np.ndarray, ...],
              box_contrast: float = 1.0) -> None:
    """Paint a box's faces where they are nearer than what the canvas holds.

    ``box_contrast`` scales the face texture about mid grey (1 as drawn, 0 a plain face that
    only its Lambert shade and brightness set).
    """
    height, width = canvas.label.shape
    rect = _project_rect(box.corners_level(), origin, rot_cl, rays.k_sub, width, height)
    if rect is None:
        return
    x0, y0, x1, y1 = rect
    window = (slice(y0, y1), slice(x0, x1))
    rdx, rdy, rdz = rays.dx[window], rays.dy[window], rays.dz[window]
    t_near, t_far, axis, local_origin = _slab(box, origin, rdx, rdy, rdz)
    win_best = canvas.t_best[window]
    hit = (t_near <= t_far) & (t_near > 1e-6) & (t_near < win_best)
    if not np.any(hit):
        return
    t = t_near[hit]
    ax = axis[hit]
    ldx = box.rot[0, 0] * rdx[hit] + box.rot[0, 1] * rdz[hit]
    ldz = box.rot[1, 0] * rdx[hit] + box.rot[1, 1] * rdz[hit]
    ldy = rdy[hit]
    px = local_origin[0] + t * ldx
    py = local_origin[1] + t * ldy
    pz = local_origin[2] + t * ldz
    # Face coordinates (along, across) and the ray's direction component along the normal.
    face_u = np.where(ax == 0, pz, px)
    face_v = np.where(ax == 1, pz, py)
    d_normal = np.abs(np.choose(ax, (ldx, ldy, ldz)))
    offsets = box.offsets[ax]
    footprint = t * rays.pixel_angle / np.maximum(d_normal, 1e-3) ** _ANISOTROPY / BOX_TEXEL
    tex = sample(box_pyramid, (face_u + offsets[:, 0]) / BOX_TEXEL,
                 (face_v + offsets[:, 1]) / BOX_TEXEL, footprint)
    if box_contrast != 1.0:
        tex = 0.5 + box_contrast * (tex - 0.5)
    direction = np.choose(ax, (ldx, ldy, ldz))
    side = (direction < 0).astype(np.int64)  # entering the + face moving in -direction
    shade = box.shade[ax, side]
    canvas.value[window][hit] = np.clip(tex * box.brightness * shade, 0.0, 1.0)
    win_best[hit] = t
    canvas.label[window][hit] = BOX


def render_view(setup: CameraSetup, origin: np.ndarray, rot_cl: np.ndarray,
                boxes: list[_PlacedBox], floor: str, variant: int, head_pose: HeadPose,
                wall_distance: float | None, supersample: int, box_contrast: float = 1.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast one camera.

    Args:
        setup: The stereo head.
        origin: (3,) camera centre in the level frame.
        rot_cl: (3, 3) camera-to-level rotation.
        boxes: The placed boxes (:func:`place_boxes`).
        floor: Floor texture kind.
        variant: Texture variant.
        head_pose: Where the head stands on the floor texture.
        wall_distance: Distance of the wall ahead, or None for the horizon.
        supersample: Rays per pixel along each axis.
        box_contrast: Contrast of the box face texture (1 as drawn, 0 plain faces).

    Returns:
        ``(radiance, label)``: (H * s, W * s) float32 values in [0, 1] and int8 surface labels
        (0 sky, 1 floor, 2 box, 3 wall) at the sub-samples, ``s = supersample``.

    """
    rays = _camera_rays(setup, rot_cl, supersample)
    shape = rays.dx.shape
    canvas = _Canvas(np.full(shape, np.inf), np.full(shape, _SKY, np.float32),
                     np.zeros(shape, np.int8))
    t_wall = None
    if wall_distance is not None:
        ahead = rays.dz > 1e-9
        t_wall = np.where(ahead, (wall_distance - origin[2]) / np.where(ahead, rays.dz, 1.0),
                          np.inf)
    _draw_floor(canvas, rays, origin, t_wall, floor, variant, head_pose)
    if t_wall is not None:
        _draw_wall(canvas, rays, origin, t_wall, variant)
    box_pyramid = texture_pyramid('box', variant)
    for box in boxes:
        _draw_box(canvas, rays, origin, rot_cl, box, box_pyramid, box_contrast)
    return canvas.value, canvas.label


def left_labels(setup: CameraSetup, boxes: Sequence[Box]) -> np.ndarray:
    """Return the (H, W) int8 surface labels of the left camera, one ray per pixel, no wall."""
    origin, rot_cl = camera_poses(setup)[0]
    _, label = render_view(setup, origin, rot_cl, place_boxes(boxes, 0), 'checker', 0,
                           HeadPose(), None, 1)
    return label


def _occluded(boxes: list[_PlacedBox], origin: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(N,) bool: the segment from ``origin`` (3,) to each of ``target`` (N, 3) crosses a box."""
    out = np.zeros(target.shape[0], bool)
    if target.shape[0] == 0:
        return out
    seg = target - origin
    for box in boxes:
        t_near, t_far, _, _ = _slab(box, origin, seg[:, 0], seg[:, 1], seg[:, 2])
        out |= (t_near <= t_far) & (t_far > 1e-6) & (t_near < 1.0 - 1e-6)
    return out


def _ground_truth(setup: CameraSetup, labels: tuple[np.ndarray, np.ndarray],
                  boxes: list[_PlacedBox], supersample: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return the left floor, floor seen by the right camera, obstacle and occluded floor."""
    s = supersample
    h, w = setup.height, setup.width
    left_labels = labels[0].reshape(h, s, w, s)
    plane_left = np.all(left_labels == 1, axis=(1, 3))
    obstacle_left = np.any(left_labels == 2, axis=(1, 3))
    visible = np.zeros((h, w), bool)
    occluded = np.zeros((h, w), bool)
    ys, xs = np.nonzero(plane_left)
    if ys.size:
        hom = setup.homography()
        pts = np.stack([xs, ys, np.ones_like(xs)]).astype(np.float64)
        mapped = hom @ pts
        in_front = mapped[2] > 1e-9
        rx = mapped[0] / np.where(in_front, mapped[2], 1.0)
        ry = mapped[1] / np.where(in_front, mapped[2], 1.0)
        inside = in_front & (rx >= 0) & (rx <= w - 1) & (ry >= 0) & (ry <= h - 1)
        # Floor point of each left pixel centre, in the level frame.
        r_lc = level_from_left(setup.tilt_deg)
        k_inv = np.linalg.inv(setup.intrinsics())
        rays = r_lc @ (k_inv @ pts[:, inside])
        floor_pts = (rays / rays[1]).T
        right_origin = camera_poses(setup)[1][0]
        clear = ~_occluded(boxes, right_origin, floor_pts)
        idx = np.flatnonzero(inside)
        visible[ys[idx[clear]], xs[idx[clear]]] = True
        occluded[ys[idx[~clear]], xs[idx[~clear]]] = True
    return plane_left, visible, obstacle_left, occluded


def _obstacle_hidden(setup: CameraSetup, obstacle_left: np.ndarray,
                     boxes: list[_PlacedBox]) -> np.ndarray:
    """Return the (H, W) bool box pixels whose point the right camera does not see.

    The point is where the left pixel centre's ray first meets a box; it is not seen when it
    is outside the right image or a box (its own included: a face turned away) lies between
    it and the right camera. Box pixels whose centre ray misses every box (edges) are not
    counted as hidden.
    """
    hidden = np.zeros(obstacle_left.shape, bool)
    ys, xs = np.nonzero(obstacle_left)
    if ys.size == 0:
        return hidden
    (left_origin, r_lc), (right_origin, r_rc) = camera_poses(setup)
    pts = np.stack([xs, ys, np.ones_like(xs)]).astype(np.float64)
    rays = r_lc @ (np.linalg.inv(setup.intrinsics()) @ pts)
    t_hit = np.full(xs.size, np.inf)
    for box in boxes:
        t_near, t_far, _, _ = _slab(box, left_origin, rays[0], rays[1], rays[2])
        hit = (t_near <= t_far) & (t_near > 1e-6)
        t_hit = np.where(hit & (t_near < t_hit), t_near, t_hit)
    on_box = np.isfinite(t_hit)
    # Step back toward the left camera by a millimetre so the point's own face does not count.
    points = left_origin + (rays[:, on_box] * (t_hit[on_box] * (1.0 - 1e-3))).T
    cam = (points - right_origin) @ r_rc
    pix = cam @ setup.intrinsics().T
    depth = np.where(pix[:, 2] > 1e-9, pix[:, 2], 1.0)
    rx, ry = pix[:, 0] / depth, pix[:, 1] / depth
    inside = (pix[:, 2] > 1e-9) & (rx >= 0) & (rx <= setup.width - 1) & (ry >= 0) \
        & (ry <= setup.height - 1)
    unseen = ~inside | _occluded(boxes, right_origin, points)
    idx = np.flatnonzero(on_box)[unseen]
    hidden[ys[idx], xs[idx]] = True
    return hidden


def _check_render_arguments(floor: str, background: str, gain: float, offset: float,
                            noise_std: float, blur_sigma: float, wall_distance: float,
                            supersample: int) -> None:
    """Raise ValueError on an argument :func:`render_stereo` cannot render."""
    if floor not in ALL_FLOOR_KINDS:
        raise ValueError(f'unknown floor kind {floor!r}; expected one of '
                         f'{", ".join(ALL_FLOOR_KINDS)}')
    if background not in BACKGROUNDS:
        raise ValueError(f'unknown background {background!r}; expected one of '
                         f'{", ".join(BACKGROUNDS)}')
    values = (gain, offset, noise_std, blur_sigma, wall_distance)
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f'photometric values must be finite, got {values!r}')
    if noise_std < 0 or blur_sigma < 0 or wall_distance <= 0:
        raise ValueError('noise_std and blur_sigma must be >= 0 and wall_distance > 0, got '
                         f'{noise_std}, {blur_sigma}, {wall_distance}')
    if int(supersample) != supersample or supersample < 1:
        raise ValueError(f'supersample must be a positive integer, got {supersample!r}')


def _expose(value: np.ndarray, setup: CameraSetup, s: int, blur_sigma: float,
            gain_offset: tuple[float, float] | None, noise_std: float,
            rng: np.random.Generator) -> np.ndarray:
    """Return the (H, W) uint8 image of sub-sample radiance: average, blur, gain, noise."""
    grey = _BLACK + _RANGE * value.reshape(setup.height, s, setup.width, s).mean(axis=(1, 3))
    if blur_sigma > 0:
        grey = cv2.GaussianBlur(grey, (0, 0), blur_sigma)
    if gain_offset is not None:
        grey = gain_offset[0] * grey + gain_offset[1]
    if noise_std > 0:
        grey = grey + rng.normal(0.0, noise_std, grey.shape)
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)


@cached
def render_stereo(setup: CameraSetup, boxes: Sequence[Box] = (), floor: str = 'random',
                  seed: int = 0, gain: float = 1.0, offset: float = 0.0,
                  noise_std: float = 1.0, head_pose: HeadPose | None = None,
                  background: str = 'horizon', wall_distance: float = 15.0,
                  blur_sigma: float = 0.5, noise_seed: int | None = None,
                  supersample: int = 2, box_contrast: float = 1.0) -> StereoFrame:
    """Render a stereo pair of a textured floor with boxes, and its ground truth.

    Args:
        setup: The stereo head.
        boxes: Boxes standing on the floor, in the level frame.
        floor: Floor texture kind, one of :data:`ALL_FLOOR_KINDS` (:data:`FLOOR_KINDS` or
            the low-texture :data:`PLAIN_FLOOR_KINDS`).
        seed: Picks the texture variant (``seed % TEXTURE_VARIANTS``) and the box face
            textures, and seeds the pixel noise unless ``noise_seed`` is given.
        gain: Gain of the right camera relative to the left one.
        offset: Offset of the right camera in grey levels (after the gain).
        noise_std: Standard deviation of the Gaussian pixel noise in grey levels (both images).
        head_pose: Where the head stands on the floor texture (default: the origin).
        background: ``'horizon'`` (floor to the horizon, flat grey sky above it) or ``'wall'``
            (a textured wall facing the head at ``wall_distance``).
        wall_distance: Distance of the wall ahead of the head (camera height = 1).
        blur_sigma: Gaussian blur of both images in pixels, the lens's point spread (0
            disables; the default 0.5 keeps pixel-scale texture from aliasing).
        noise_seed: Seed of the pixel noise (default: ``seed``).
        supersample: Rays per pixel along each axis (anti-aliasing).
        box_contrast: Contrast of the box face texture about mid grey, in [0, 1]: 1 (the
            default) as drawn, 0 plain faces that only their shade sets (weakly textured
            in between).

    Returns:
        The rendered :class:`StereoFrame`.

    Raises:
        ValueError: On an unknown floor kind or background, a non-finite or negative
            photometric parameter, ``supersample < 1`` or ``box_contrast`` outside [0, 1].

    """
    if not 0.0 <= box_contrast <= 1.0:
        raise ValueError(f'box_contrast must be in [0, 1], got {box_contrast}')
    _check_render_arguments(floor, background, gain, offset, noise_std, blur_sigma,
                            wall_distance, supersample)
    head_pose = head_pose or HeadPose()
    variant = int(seed) % TEXTURE_VARIANTS
    placed = place_boxes(boxes, int(seed))
    wall = wall_distance if background == 'wall' else None
    s = int(supersample)
    rng = np.random.default_rng(seed if noise_seed is None else noise_seed)
    images = []
    labels = []
    for index, (origin, rot_cl) in enumerate(camera_poses(setup)):
        value, label = render_view(setup, origin, rot_cl, placed, floor, variant, head_pose,
                                   wall, s, float(box_contrast))
        labels.append(label)
        images.append(_expose(value, setup, s, blur_sigma, (gain, offset) if index == 1 else None,
                              noise_std, rng))
    plane_left, visible, obstacle_left, occluded = _ground_truth(
        setup, (labels[0], labels[1]), placed, s)
    return StereoFrame(left=images[0], right=images[1], homography=setup.homography(),
                       plane_left=plane_left, visible_in_right=visible,
                       obstacle_left=obstacle_left, setup=setup, boxes=tuple(boxes),
                       floor=floor, head_pose=head_pose, occluded_in_right=occluded,
                       obstacle_hidden=_obstacle_hidden(setup, obstacle_left, placed))
