"""Ray-cast stereo scenes of a textured floor with box obstacles, with ground truth.

The renderer is used by the tests, the demo, the benchmark and the evaluation. It uses exactly
the camera model of :mod:`domplane_ros.core.prior`:

* Left camera frame: x right, y down, z forward; ``K`` has the principal point at
  ``((w - 1) / 2, (h - 1) / 2)``.
* The floor is ``n . X = h`` with ``h = 1`` and ``n = (0, cos(tilt), sin(tilt))``.
* The right camera centre is ``C = (b, 0, 0)`` (``b = baseline_over_height``) and
  ``X_right = R_v (X_left - C)``.

Geometry lives in the *level frame* of the head: the origin is the left camera centre, x is the
camera's x axis, y points straight down (the floor is ``y = 1``) and z is the horizontal forward
direction. Boxes are placed in this frame. Floor texture is a function of *world* floor
coordinates; a :class:`HeadPose` says where the head stands on the floor and where it faces, so
moving the head moves the floor texture under a fixed camera set-up.

Textures are periodic rasters sampled with trilinear mip-mapping (the mip level follows the
footprint of a sample on the surface), and every pixel averages ``supersample x supersample``
rays, so both cameras see the same, anti-aliased texture. Box faces are Lambert-shaded by a
fixed light, which is view independent, so a floor or box point has the same radiance in both
cameras; only the right camera's gain/offset and the pixel noise differ.
"""

from __future__ import annotations

from dataclasses import dataclass
import functools
import math
from typing import Iterator, Sequence

import cv2
from domplane_ros.core import prior
import numpy as np

FLOOR_KINDS = ('random', 'tiles', 'planks', 'checker')
# Low-texture floors: flat albedo with faint noise between contrasting joints, so that almost
# all structure is in straight lines (the joints). Not drawn by ``random_scene(floor=None)``,
# so existing seeds keep their floors; ask for them by name.
PLAIN_FLOOR_KINDS = ('tiles_plain', 'planks_plain')
ALL_FLOOR_KINDS = FLOOR_KINDS + PLAIN_FLOOR_KINDS
BACKGROUNDS = ('horizon', 'wall')

# Texture rasters: size in texels (a power of two, so the mip pyramid halves exactly) and the
# world size of one texel (camera height = 1).
_FLOOR_TEXELS = 2048
_FLOOR_TEXEL = 0.005
_BOX_TEXELS = 1024
_BOX_TEXEL = 0.004
_WALL_TEXELS = 1024
_WALL_TEXEL = 0.02
# Number of distinct texture rasters per kind; render seeds share them modulo this number.
TEXTURE_VARIANTS = 4
# Grey levels: texture value v in [0, 1] becomes _BLACK + _RANGE * v.
_BLACK = 20.0
_RANGE = 215.0
_SKY = 0.78
# Direction *toward* the light in the level frame (y points down, so -y is up).
_LIGHT = np.array([-0.35, -1.0, -0.45]) / np.linalg.norm([-0.35, -1.0, -0.45])
_EPS = 1e-9
_ANISOTROPY = 0.75


@dataclass(frozen=True)
class CameraSetup:
    """A stereo head: intrinsics, baseline, tilt and vergence, as in :mod:`~.core.prior`.

    Attributes:
        focal_px: Focal length in pixels (both cameras).
        baseline_over_height: Stereo baseline divided by the camera height above the floor.
        tilt_deg: Tilt toward the floor in degrees (positive looks down).
        vergence_deg: Yaw of the right camera toward the left one, degrees.
        width: Image width in pixels.
        height: Image height in pixels.
    """

    focal_px: float
    baseline_over_height: float
    tilt_deg: float
    vergence_deg: float
    width: int = 640
    height: int = 480

    def __post_init__(self) -> None:
        """Check that the set-up is finite and renderable.

        Raises:
            ValueError: If a value is non-finite, the focal length is not positive, the image
                is smaller than 8 x 8 or the tilt is not in (-89, 89) degrees.

        """
        values = (self.focal_px, self.baseline_over_height, self.tilt_deg, self.vergence_deg)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'camera set-up values must be finite, got {values!r}')
        if self.focal_px <= 0:
            raise ValueError(f'focal_px must be positive, got {self.focal_px}')
        if int(self.width) != self.width or int(self.height) != self.height:
            raise ValueError(f'image size must be integer, got {self.width} x {self.height}')
        if self.width < 8 or self.height < 8:
            raise ValueError(f'image must be at least 8 x 8, got {self.width} x {self.height}')
        if not -89.0 < self.tilt_deg < 89.0:
            raise ValueError(f'tilt_deg must be in (-89, 89), got {self.tilt_deg}')

    def homography(self) -> np.ndarray:
        """Return the true left-to-right floor homography, (3, 3) float64, ``H[2, 2] == 1``."""
        return prior.plane_homography(self.focal_px, self.baseline_over_height, self.tilt_deg,
                                      self.vergence_deg, self.width, self.height)

    def intrinsics(self) -> np.ndarray:
        """Return the (3, 3) float64 calibration matrix shared by both cameras."""
        return prior.intrinsics(self.focal_px, self.width, self.height)


@dataclass(frozen=True)
class Box:
    """A box standing on the floor, in the level frame of the head (camera height = 1).

    Attributes:
        x: Centre of the footprint, metres to the right of the left camera.
        z: Centre of the footprint, horizontal distance ahead of the left camera.
        width: Side along the box's own x axis.
        depth: Side along the box's own z axis.
        height: Height above the floor.
        yaw_deg: Rotation of the box about the vertical axis, degrees.
    """

    x: float
    z: float
    width: float
    depth: float
    height: float
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        """Check that the box is finite with positive sides.

        Raises:
            ValueError: If a value is non-finite or a side is not positive.

        """
        values = (self.x, self.z, self.width, self.depth, self.height, self.yaw_deg)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'box values must be finite, got {values!r}')
        if min(self.width, self.depth, self.height) <= 0:
            raise ValueError(
                f'box sides must be positive, got {self.width}, {self.depth}, {self.height}')


@dataclass(frozen=True)
class HeadPose:
    """Where the head stands on the textured floor (the floor texture origin).

    A level-frame floor point ``(x_l, z_l)`` has world floor coordinates
    ``(x, z) + x_l * (cos yaw, -sin yaw) + z_l * (sin yaw, cos yaw)``.

    Attributes:
        x: World x of the point under the left camera.
        z: World z of the point under the left camera.
        yaw_deg: Heading of the head in the world, degrees.
    """

    x: float = 0.0
    z: float = 0.0
    yaw_deg: float = 0.0


@dataclass(frozen=True, eq=False)
class StereoFrame:
    """A rendered stereo pair with its ground truth.

    Attributes:
        left: (H, W) uint8 left image.
        right: (H, W) uint8 right image.
        homography: (3, 3) float64 true left-to-right floor homography.
        plane_left: (H, W) bool, the left pixel sees the floor (not a box, wall or sky).
        visible_in_right: (H, W) bool, the floor point seen at the left pixel's centre is inside
            the right image and not occluded by a box from the right camera.
        obstacle_left: (H, W) bool, the left pixel sees (at least partly) a box.
        setup: The camera set-up.
        boxes: The boxes, in the level frame.
        floor: The floor texture kind.
        head_pose: The head's pose on the floor.
    """

    left: np.ndarray
    right: np.ndarray
    homography: np.ndarray
    plane_left: np.ndarray
    visible_in_right: np.ndarray
    obstacle_left: np.ndarray
    setup: CameraSetup
    boxes: tuple[Box, ...] = ()
    floor: str = 'random'
    head_pose: HeadPose = HeadPose()


# --------------------------------------------------------------------------------------------
# Textures.


def _periodic_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Return (size, size) float32 smooth periodic noise with about ``cells`` blobs per side."""
    cells = max(2, min(cells, size))
    coarse = rng.standard_normal((cells, cells)).astype(np.float32)
    factor = size // cells
    pad = 2
    padded = np.pad(coarse, pad, mode='wrap')
    up = cv2.resize(padded, None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC)
    start = pad * factor
    return up[start:start + size, start:start + size]


def _normalise(values: np.ndarray) -> np.ndarray:
    return (values - values.mean()) / (values.std() + 1e-6)


def _blur_periodic(values: np.ndarray, sigma: float) -> np.ndarray:
    pad = int(math.ceil(3 * sigma)) + 1
    padded = np.pad(values, pad, mode='wrap')
    return cv2.GaussianBlur(padded, (0, 0), sigma)[pad:-pad, pad:-pad]


def _random_texture(rng: np.random.Generator, size: int, octaves: Sequence[tuple[int, float]],
                    sharpness: float, grain: float) -> np.ndarray:
    """Multi-scale blobby texture: a sharpened sum of periodic noise octaves, in [0, 1]."""
    total = np.zeros((size, size), np.float32)
    for cells, amplitude in octaves:
        total += amplitude * _normalise(_periodic_noise(rng, size, cells))
    blobs = 0.5 + 0.42 * np.tanh(sharpness * _normalise(total))
    fine = _normalise(_periodic_noise(rng, size, size // 2))
    return np.clip(blobs + grain * fine, 0.0, 1.0).astype(np.float32)


def _floor_texture(kind: str, variant: int) -> np.ndarray:
    """Return the (N, N) float32 floor raster in [0, 1] (period N * _FLOOR_TEXEL)."""
    if kind not in ALL_FLOOR_KINDS:
        raise ValueError(
            f'unknown floor kind {kind!r}; expected one of {", ".join(ALL_FLOOR_KINDS)}')
    rng = np.random.default_rng(1000 + 17 * variant + ALL_FLOOR_KINDS.index(kind))
    n = _FLOOR_TEXELS
    if kind in PLAIN_FLOOR_KINDS:
        return _plain_floor_texture(kind, rng, n)
    if kind == 'random':
        return _random_texture(rng, n, ((16, 1.0), (64, 0.8), (256, 0.6), (512, 0.35)),
                               sharpness=1.6, grain=0.04)
    weak = 0.012 * _normalise(_periodic_noise(rng, n, n // 8))
    if kind == 'tiles':
        tile = 64
        shades = 0.60 + 0.04 * rng.standard_normal((n // tile, n // tile))
        tex = np.kron(shades, np.ones((tile, tile))).astype(np.float32) + weak
        idx = np.arange(n) % tile
        joint = (idx < 3)
        tex[joint, :] = 0.30
        tex[:, joint] = 0.30
        return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)
    if kind == 'planks':
        plank = 32
        tex = np.empty((n, n), np.float32)
        grain = _blur_periodic(rng.standard_normal((n, n)).astype(np.float32), 1.0)
        grain = _normalise(cv2.blur(np.pad(grain, ((24, 24), (0, 0)), mode='wrap'),
                                    (1, 49))[24:-24])
        for col in range(n // plank):
            cols = slice(col * plank, (col + 1) * plank)
            start = int(rng.integers(0, n))
            pos = 0
            while pos < n:
                length = int(rng.integers(200, 520))
                rows = (np.arange(pos, min(pos + length, n)) + start) % n
                tex[rows, cols] = 0.45 + 0.07 * rng.standard_normal()
                tex[rows[:3], cols] = 0.18
                pos += length
            tex[:, col * plank:col * plank + 2] = 0.18
        tex += 0.035 * grain + weak
        return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)
    if kind == 'checker':
        square = 64
        idx = (np.arange(n) // square) % 2
        tex = np.where(idx[:, None] ^ idx[None, :], 0.75, 0.25).astype(np.float32) + weak
        return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)
    raise ValueError(f'unknown floor kind {kind!r}; expected one of {", ".join(FLOOR_KINDS)}')


def _plain_floor_texture(kind: str, rng: np.random.Generator, n: int) -> np.ndarray:
    """Return a low-texture floor raster: flat albedo, faint noise, contrasting joints.

    ``tiles_plain``: 0.64 x 0.64 tiles (camera height 1) of one albedo with 2.5 % noise and
    dark 1.5 cm joints, so corners exist only where joints cross. ``planks_plain``: 16 cm wide
    planks, 1.5 to 3.5 m long, of one albedo with faint grain, dark side joints and end joints,
    so corners exist only at the end joints (T-junctions).
    """
    faint = 0.025 * _normalise(_periodic_noise(rng, n, n // 4))
    if kind == 'tiles_plain':
        tile = 128
        tex = np.full((n, n), 0.62, np.float32) + faint
        idx = np.arange(n) % tile
        joint = idx < 3
        tex[joint, :] = 0.28
        tex[:, joint] = 0.28
        return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)
    plank = 32
    tex = np.full((n, n), 0.55, np.float32) + faint
    for col in range(n // plank):
        cols = slice(col * plank, (col + 1) * plank)
        start = int(rng.integers(0, n))
        pos = 0
        while pos < n:
            length = int(rng.integers(300, 700))
            rows = (np.arange(pos, min(pos + length, n)) + start) % n
            tex[rows[:3], cols] = 0.22
            pos += length
        tex[:, col * plank:col * plank + 2] = 0.22
    return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)


def _box_texture(variant: int) -> np.ndarray:
    """Return the box-face raster: fine speckle with stripes, unlike any floor kind."""
    rng = np.random.default_rng(5000 + variant)
    n = _BOX_TEXELS
    tex = _random_texture(rng, n, ((32, 0.6), (128, 1.0), (256, 0.5)), sharpness=2.5,
                          grain=0.06)
    stripes = 0.5 + 0.5 * np.sin(2 * np.pi * np.arange(n) / 32.0)
    return np.clip(0.75 * tex + 0.25 * stripes[:, None].astype(np.float32), 0, 1)


def _wall_texture(variant: int) -> np.ndarray:
    rng = np.random.default_rng(7000 + variant)
    tex = _random_texture(rng, _WALL_TEXELS, ((8, 1.0), (32, 0.7), (128, 0.4)),
                          sharpness=1.2, grain=0.03)
    return (0.55 + 0.6 * (tex - 0.5)).astype(np.float32)


def _pyramid(texture: np.ndarray) -> tuple[np.ndarray, ...]:
    """Mip pyramid of a periodic raster, down to 1 x 1, each level periodic."""
    levels = [np.ascontiguousarray(texture, dtype=np.float32)]
    while levels[-1].shape[0] > 1:
        pad = 4
        padded = np.pad(levels[-1], pad, mode='wrap')
        levels.append(cv2.pyrDown(padded)[pad // 2:-pad // 2, pad // 2:-pad // 2].copy())
    return tuple(levels)


@functools.lru_cache(maxsize=8)  # ~22 MB per floor pyramid, ~60 ms to rebuild
def _texture_pyramid(name: str, variant: int) -> tuple[np.ndarray, ...]:
    if name == 'box':
        return _pyramid(_box_texture(variant))
    if name == 'wall':
        return _pyramid(_wall_texture(variant))
    return _pyramid(_floor_texture(name, variant))


def _remap(level: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear, wrapping lookup of a raster at 1-D texel coordinates (u = column, v = row)."""
    n = u.size
    size = level.shape[0]
    cols = 4096
    rows = -(-n // cols)
    mx = np.zeros(rows * cols, np.float32)
    my = np.zeros(rows * cols, np.float32)
    mx[:n] = np.mod(u, size)
    my[:n] = np.mod(v, size)
    out = cv2.remap(level, mx.reshape(rows, cols), my.reshape(rows, cols), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_WRAP)
    return out.reshape(-1)[:n]


def _sample(pyramid: tuple[np.ndarray, ...], u: np.ndarray, v: np.ndarray,
            footprint: np.ndarray) -> np.ndarray:
    """Trilinear mip-mapped lookup.

    Args:
        pyramid: Mip levels of a periodic raster.
        u: (N,) float64 column coordinate in level-0 texels.
        v: (N,) float64 row coordinate in level-0 texels.
        footprint: (N,) float64 size of the sample on the surface, in level-0 texels.

    Returns:
        (N,) float32 texture values.

    """
    top = len(pyramid) - 1
    level = np.clip(np.log2(np.maximum(footprint, 1e-6)), 0.0, top)
    base = np.minimum(np.floor(level).astype(np.int64), top)
    frac = (level - base).astype(np.float32)
    out = np.empty(u.shape, np.float32)
    for lev in range(int(base.min()), int(base.max()) + 1) if base.size else ():
        sel = base == lev
        if not np.any(sel):
            continue
        values = []
        for k in (lev, min(lev + 1, top)):
            scale = 0.5 ** k
            values.append(_remap(pyramid[k], (u[sel] + 0.5) * scale - 0.5,
                                 (v[sel] + 0.5) * scale - 0.5))
        out[sel] = values[0] + (values[1] - values[0]) * frac[sel]
    return out


# --------------------------------------------------------------------------------------------
# Geometry.


def _rot_y(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _level_from_left(tilt_deg: float) -> np.ndarray:
    """(3, 3) rotation taking left-camera coordinates to level-frame coordinates."""
    t = math.radians(tilt_deg)
    return np.array([[1.0, 0.0, 0.0],
                     [0.0, math.cos(t), math.sin(t)],
                     [0.0, -math.sin(t), math.cos(t)]])


def _cameras(setup: CameraSetup) -> list[tuple[np.ndarray, np.ndarray]]:
    """(origin (3,), camera-to-level rotation (3, 3)) of the left and right cameras."""
    r_lc = _level_from_left(setup.tilt_deg)
    r_v = _rot_y(math.radians(setup.vergence_deg))
    centre = np.array([setup.baseline_over_height, 0.0, 0.0])
    return [(np.zeros(3), r_lc), (r_lc @ centre, r_lc @ r_v.T)]


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


def _place_boxes(boxes: Sequence[Box], variant_seed: int) -> list[_PlacedBox]:
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


def _render_view(setup: CameraSetup, origin: np.ndarray, rot_cl: np.ndarray,
                 boxes: list[_PlacedBox], floor: str, variant: int, head_pose: HeadPose,
                 wall_distance: float | None, supersample: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast one camera.

    Returns:
        ``(radiance, label)``: (H * s, W * s) float32 values in [0, 1] and int8 surface labels
        (0 sky, 1 floor, 2 box, 3 wall) at the sub-samples, ``s = supersample``.

    """
    s = supersample
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
    dx, dy, dz = dx / norm, dy / norm, dz / norm
    pixel_angle = 1.0 / (f * s)

    t_best = np.full((height, width), np.inf)
    value = np.full((height, width), _SKY, np.float32)
    label = np.zeros((height, width), np.int8)

    # Floor: y = 1.
    down = dy > 1e-9
    t_floor = np.where(down, (1.0 - origin[1]) / np.where(down, dy, 1.0), np.inf)
    hit = np.isfinite(t_floor)
    if wall_distance is not None:
        ahead = dz > 1e-9
        t_wall = np.where(ahead, (wall_distance - origin[2]) / np.where(ahead, dz, 1.0), np.inf)
        hit &= t_floor < t_wall
    if np.any(hit):
        t = t_floor[hit]
        xl = origin[0] + t * dx[hit]
        zl = origin[2] + t * dz[hit]
        yaw = math.radians(head_pose.yaw_deg)
        wx = head_pose.x + xl * math.cos(yaw) + zl * math.sin(yaw)
        wz = head_pose.z - xl * math.sin(yaw) + zl * math.cos(yaw)
        footprint = t * pixel_angle / dy[hit] ** _ANISOTROPY / _FLOOR_TEXEL
        value[hit] = _sample(_texture_pyramid(floor, variant), wx / _FLOOR_TEXEL,
                             wz / _FLOOR_TEXEL, footprint)
        t_best[hit] = t
        label[hit] = 1
    if wall_distance is not None:
        hit = np.isfinite(t_wall) & (t_wall < t_best)
        if np.any(hit):
            t = t_wall[hit]
            xl = origin[0] + t * dx[hit]
            yl = origin[1] + t * dy[hit]
            footprint = t * pixel_angle / dz[hit] ** _ANISOTROPY / _WALL_TEXEL
            value[hit] = _sample(_texture_pyramid('wall', variant), xl / _WALL_TEXEL,
                                 yl / _WALL_TEXEL, footprint)
            t_best[hit] = t
            label[hit] = 3

    k_sub = np.array([[f * s, 0.0, (cx + 0.5) * s - 0.5], [0.0, f * s, (cy + 0.5) * s - 0.5],
                      [0.0, 0.0, 1.0]])
    box_pyramid = _texture_pyramid('box', variant)
    for box in boxes:
        rect = _project_rect(box.corners_level(), origin, rot_cl, k_sub, width, height)
        if rect is None:
            continue
        x0, y0, x1, y1 = rect
        window = (slice(y0, y1), slice(x0, x1))
        rdx, rdy, rdz = dx[window], dy[window], dz[window]
        t_near, t_far, axis, local_origin = _slab(box, origin, rdx, rdy, rdz)
        win_best = t_best[window]
        hit = (t_near <= t_far) & (t_near > 1e-6) & (t_near < win_best)
        if not np.any(hit):
            continue
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
        footprint = t * pixel_angle / np.maximum(d_normal, 1e-3) ** _ANISOTROPY / _BOX_TEXEL
        tex = _sample(box_pyramid, (face_u + offsets[:, 0]) / _BOX_TEXEL,
                      (face_v + offsets[:, 1]) / _BOX_TEXEL, footprint)
        direction = np.choose(ax, (ldx, ldy, ldz))
        side = (direction < 0).astype(np.int64)  # entering the + face moving in -direction
        shade = box.shade[ax, side]
        win_value = value[window]
        win_label = label[window]
        win_value[hit] = np.clip(tex * box.brightness * shade, 0.0, 1.0)
        win_best[hit] = t
        win_label[hit] = 2
    return value, label


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
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    s = supersample
    h, w = setup.height, setup.width
    left_labels = labels[0].reshape(h, s, w, s)
    plane_left = np.all(left_labels == 1, axis=(1, 3))
    obstacle_left = np.any(left_labels == 2, axis=(1, 3))
    visible = np.zeros((h, w), bool)
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
        r_lc = _level_from_left(setup.tilt_deg)
        k_inv = np.linalg.inv(setup.intrinsics())
        rays = r_lc @ (k_inv @ pts[:, inside])
        floor_pts = (rays / rays[1]).T
        right_origin = _cameras(setup)[1][0]
        clear = ~_occluded(boxes, right_origin, floor_pts)
        idx = np.flatnonzero(inside)[clear]
        visible[ys[idx], xs[idx]] = True
    return plane_left, visible, obstacle_left


def render_stereo(setup: CameraSetup, boxes: Sequence[Box] = (), floor: str = 'random',
                  seed: int = 0, gain: float = 1.0, offset: float = 0.0,
                  noise_std: float = 1.0, head_pose: HeadPose | None = None,
                  background: str = 'horizon', wall_distance: float = 15.0,
                  blur_sigma: float = 0.5, noise_seed: int | None = None,
                  supersample: int = 2) -> StereoFrame:
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

    Returns:
        The rendered :class:`StereoFrame`.

    Raises:
        ValueError: On an unknown floor kind or background, a non-finite or negative
            photometric parameter, or ``supersample < 1``.

    """
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
    head_pose = head_pose or HeadPose()
    variant = int(seed) % TEXTURE_VARIANTS
    placed = _place_boxes(boxes, int(seed))
    wall = wall_distance if background == 'wall' else None
    s = int(supersample)
    rng = np.random.default_rng(seed if noise_seed is None else noise_seed)
    images = []
    labels = []
    for index, (origin, rot_cl) in enumerate(_cameras(setup)):
        value, label = _render_view(setup, origin, rot_cl, placed, floor, variant, head_pose,
                                    wall, s)
        labels.append(label)
        grey = _BLACK + _RANGE * value.reshape(setup.height, s, setup.width, s).mean(
            axis=(1, 3))
        if blur_sigma > 0:
            grey = cv2.GaussianBlur(grey, (0, 0), blur_sigma)
        if index == 1:
            grey = gain * grey + offset
        if noise_std > 0:
            grey = grey + rng.normal(0.0, noise_std, grey.shape)
        images.append(np.clip(np.rint(grey), 0, 255).astype(np.uint8))
    plane_left, visible, obstacle_left = _ground_truth(setup, (labels[0], labels[1]), placed, s)
    return StereoFrame(left=images[0], right=images[1], homography=setup.homography(),
                       plane_left=plane_left, visible_in_right=visible,
                       obstacle_left=obstacle_left, setup=setup, boxes=tuple(boxes),
                       floor=floor, head_pose=head_pose)


# --------------------------------------------------------------------------------------------
# Random scenes and sequences.

SETUP_RANGES = {
    'focal_px': (400.0, 900.0),
    'baseline_over_height': (0.05, 0.4),
    'tilt_deg': (10.0, 50.0),
    'vergence_deg': (-2.0, 4.0),
}


def random_setup(rng: np.random.Generator, width: int = 640, height: int = 480) -> CameraSetup:
    """Draw a camera set-up uniformly within :data:`SETUP_RANGES` (the default prior)."""
    return CameraSetup(**{name: float(rng.uniform(lo, hi))
                          for name, (lo, hi) in SETUP_RANGES.items()},
                       width=width, height=height)


def _obstacle_fraction(setup: CameraSetup, boxes: Sequence[Box]) -> tuple[float, float]:
    """(obstacle pixels / (floor + obstacle) pixels, floor fraction) from a coarse render."""
    factor = max(1, setup.width // 80)
    small = CameraSetup(setup.focal_px / factor, setup.baseline_over_height, setup.tilt_deg,
                        setup.vergence_deg, max(8, setup.width // factor),
                        max(8, setup.height // factor))
    origin, rot_cl = _cameras(small)[0]
    _, label = _render_view(small, origin, rot_cl, _place_boxes(boxes, 0), 'checker', 0,
                            HeadPose(), None, 1)
    floor = np.count_nonzero(label == 1)
    obstacle = np.count_nonzero(label == 2)
    return obstacle / max(1, floor + obstacle), floor / label.size


def random_boxes(rng: np.random.Generator, setup: CameraSetup, count: int,
                 max_obstacle_fraction: float = 0.25, max_distance: float = 9.0
                 ) -> list[Box]:
    """Place up to ``count`` non-overlapping boxes on floor points seen by the left camera.

    Boxes whose addition makes the obstacles cover more than ``max_obstacle_fraction`` of the
    floor-or-obstacle pixels are dropped, so the floor stays the dominant plane.

    Args:
        rng: Random generator.
        setup: The stereo head.
        count: Number of boxes wanted.
        max_obstacle_fraction: Largest obstacle share of floor-or-obstacle pixels.
        max_distance: Farthest box centre from the head.

    Returns:
        The boxes in the level frame (at least one if the floor is visible at all).

    """
    r_lc = _level_from_left(setup.tilt_deg)
    k_inv = np.linalg.inv(setup.intrinsics())
    boxes: list[Box] = []
    for _ in range(40 * max(1, count)):
        if len(boxes) >= count:
            break
        px = rng.uniform(0.08, 0.92) * (setup.width - 1)
        py = rng.uniform(0.3, 0.97) * (setup.height - 1)
        ray = r_lc @ (k_inv @ np.array([px, py, 1.0]))
        if ray[1] <= 1e-3:
            continue
        point = ray / ray[1]
        if not 1.2 < point[2] < max_distance:
            continue
        size = float(np.clip(0.15 * point[2], 0.3, 1.0))
        box = Box(x=float(point[0]), z=float(point[2]),
                  width=float(rng.uniform(0.6, 1.3) * size),
                  depth=float(rng.uniform(0.6, 1.3) * size),
                  height=float(rng.uniform(0.25, 0.9)), yaw_deg=float(rng.uniform(-40, 40)))
        radius = 0.5 * math.hypot(box.width, box.depth)
        if box.z - radius < 0.8:
            continue
        if any(math.hypot(box.x - o.x, box.z - o.z)
               < radius + 0.5 * math.hypot(o.width, o.depth) + 0.1 for o in boxes):
            continue
        fraction, _ = _obstacle_fraction(setup, boxes + [box])
        if fraction > max_obstacle_fraction:
            continue
        boxes.append(box)
    return boxes


def random_scene(seed: int, width: int = 640, height: int = 480, floor: str | None = None,
                 n_boxes: int | tuple[int, int] = (1, 5), gain: float | None = 1.0,
                 offset: float | None = 0.0, noise_std: float = 1.0,
                 background: str | None = None, setup: CameraSetup | None = None,
                 blur_sigma: float = 0.5) -> StereoFrame:
    """Render a random scene: set-up within :data:`SETUP_RANGES`, 1-5 boxes in view.

    Args:
        seed: Seed of every random choice; the same seed gives the same frame.
        width: Image width in pixels.
        height: Image height in pixels.
        floor: Floor kind (one of :data:`ALL_FLOOR_KINDS`), or None for a random one of
            :data:`FLOOR_KINDS`.
        n_boxes: Number of boxes, or an inclusive ``(min, max)`` range to draw from.
        gain: Right camera gain, or None to draw one in [0.8, 1.25].
        offset: Right camera offset in grey levels, or None to draw one in [-20, 20].
        noise_std: Pixel noise standard deviation in grey levels.
        background: ``'horizon'``, ``'wall'`` or None for a random one.
        setup: A fixed camera set-up instead of a random one.
        blur_sigma: Gaussian blur of both images in pixels.

    Returns:
        The rendered :class:`StereoFrame`.

    """
    rng = np.random.default_rng((int(seed), 4242))
    setup = setup or random_setup(rng, width, height)
    floor = floor or FLOOR_KINDS[int(rng.integers(len(FLOOR_KINDS)))]
    background = background or BACKGROUNDS[int(rng.integers(len(BACKGROUNDS)))]
    if isinstance(n_boxes, tuple):
        n_boxes = int(rng.integers(n_boxes[0], n_boxes[1] + 1))
    boxes = random_boxes(rng, setup, n_boxes)
    pose = HeadPose(float(rng.uniform(0, 100)), float(rng.uniform(0, 100)),
                    float(rng.uniform(0, 360)))
    gain = float(rng.uniform(0.8, 1.25)) if gain is None else gain
    offset = float(rng.uniform(-20, 20)) if offset is None else offset
    return render_stereo(setup, boxes, floor=floor, seed=int(seed), gain=gain, offset=offset,
                         noise_std=noise_std, head_pose=pose, background=background,
                         wall_distance=float(rng.uniform(8, 20)), blur_sigma=blur_sigma)


def scene_sequence(n_frames: int, seed: int, width: int = 640, height: int = 480,
                   floor: str | None = None, n_boxes: int = 3, step: float = 0.04,
                   yaw_rate_deg: float = 0.6, tilt_jitter_deg: float = 1.0,
                   vergence_jitter_deg: float = 0.3, gain: float = 1.0, offset: float = 0.0,
                   noise_std: float = 1.0, background: str = 'horizon',
                   setup: CameraSetup | None = None, blur_sigma: float = 0.5
                   ) -> list[StereoFrame]:
    """Render a short sequence of a head walking over the floor past fixed boxes.

    The head moves ``step`` per frame along its heading, which turns slowly (a sine of
    amplitude ``yaw_rate_deg * n_frames / 4`` degrees); tilt and vergence wobble smoothly by up
    to the given jitter, so the true homography changes from frame to frame only through them.
    Boxes are fixed in the world and move through the level frame.

    Args:
        n_frames: Number of frames (>= 1).
        seed: Seed of every random choice.
        width: Image width in pixels.
        height: Image height in pixels.
        floor: Floor kind, or None for a random one.
        n_boxes: Number of boxes placed ahead of the start pose.
        step: Forward motion per frame (camera height = 1).
        yaw_rate_deg: Scale of the heading change per frame, degrees.
        tilt_jitter_deg: Amplitude of the tilt wobble, degrees.
        vergence_jitter_deg: Amplitude of the vergence wobble, degrees.
        gain: Right camera gain.
        offset: Right camera offset in grey levels.
        noise_std: Pixel noise standard deviation in grey levels.
        background: ``'horizon'`` or ``'wall'``.
        setup: The nominal set-up (default: a random one).
        blur_sigma: Gaussian blur of both images in pixels.

    Returns:
        ``n_frames`` :class:`StereoFrame` values.

    Raises:
        ValueError: If ``n_frames < 1``.

    """
    if n_frames < 1:
        raise ValueError(f'n_frames must be >= 1, got {n_frames}')
    rng = np.random.default_rng((int(seed), 777))
    nominal = setup or random_setup(rng, width, height)
    # Keep the wobble inside the prior ranges.
    lo_t, hi_t = SETUP_RANGES['tilt_deg']
    lo_v, hi_v = SETUP_RANGES['vergence_deg']
    nominal = CameraSetup(nominal.focal_px, nominal.baseline_over_height,
                          float(np.clip(nominal.tilt_deg, lo_t + tilt_jitter_deg,
                                        hi_t - tilt_jitter_deg)),
                          float(np.clip(nominal.vergence_deg, lo_v + vergence_jitter_deg,
                                        hi_v - vergence_jitter_deg)),
                          nominal.width, nominal.height)
    floor = floor or FLOOR_KINDS[int(rng.integers(len(FLOOR_KINDS)))]
    travel = step * n_frames
    # Boxes are placed for the head's position half-way through, then expressed in the world.
    mid = CameraSetup(nominal.focal_px, nominal.baseline_over_height, nominal.tilt_deg,
                      nominal.vergence_deg, nominal.width, nominal.height)
    world_boxes = [Box(b.x, b.z + 0.5 * travel, b.width, b.depth, b.height, b.yaw_deg)
                   for b in random_boxes(rng, mid, n_boxes)]
    world_boxes = [b for b in world_boxes if b.z - 0.5 * math.hypot(b.width, b.depth)
                   > travel + 0.8]
    origin = np.array([rng.uniform(0, 100), rng.uniform(0, 100)])
    heading0 = float(rng.uniform(0, 360))
    phases = rng.uniform(0, 2 * np.pi, 3)
    frames = []
    x, z, yaw = 0.0, 0.0, 0.0  # head pose relative to the start, in the start's level frame
    for i in range(n_frames):
        phase = 2 * np.pi * i / max(n_frames, 8)
        setup_i = CameraSetup(
            nominal.focal_px, nominal.baseline_over_height,
            nominal.tilt_deg + tilt_jitter_deg * math.sin(phase + phases[0]),
            nominal.vergence_deg + vergence_jitter_deg * math.sin(phase + phases[1]),
            nominal.width, nominal.height)
        c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
        level_boxes = []
        for b in world_boxes:
            dx_, dz_ = b.x - x, b.z - z
            level_boxes.append(Box(c * dx_ - s * dz_, s * dx_ + c * dz_, b.width, b.depth,
                                   b.height, b.yaw_deg - yaw))
        # Start-frame coordinates -> texture world coordinates.
        h0 = math.radians(heading0)
        pose = HeadPose(
            float(origin[0] + x * math.cos(h0) + z * math.sin(h0)),
            float(origin[1] - x * math.sin(h0) + z * math.cos(h0)),
            heading0 + yaw)
        frames.append(render_stereo(setup_i, level_boxes, floor=floor, seed=int(seed),
                                    gain=gain, offset=offset, noise_std=noise_std,
                                    head_pose=pose, background=background,
                                    blur_sigma=blur_sigma, noise_seed=int(seed) * 100003 + i))
        yaw_step = yaw_rate_deg * math.cos(phase + phases[2])
        x += step * math.sin(math.radians(yaw))
        z += step * math.cos(math.radians(yaw))
        yaw += yaw_step
    return frames


# --------------------------------------------------------------------------------------------
# Active head sequences.


@dataclass(frozen=True)
class HeadMotion:
    """How an active head moves in :func:`head_sequence` (angles in degrees, rates per second).

    The head stands still on the floor. It pans about the vertical axis through the left
    camera at a constant ``pan_rate_deg_s``, tilts sinusoidally about the baseline between
    ``tilt_range_deg`` with peak rate ``tilt_rate_deg_s``, and verges sinusoidally within
    ``vergence_range_deg`` with peak rate ``vergence_rate_deg_s``.

    Attributes:
        pan_rate_deg_s: Pan speed, degrees per second (sign: direction).
        tilt_rate_deg_s: Peak tilt speed, degrees per second.
        vergence_rate_deg_s: Peak vergence speed, degrees per second.
        tilt_range_deg: ``(min, max)`` tilt, degrees.
        vergence_range_deg: ``(min, max)`` vergence, degrees.
        rate_hz: Frame rate.
    """

    pan_rate_deg_s: float = 30.0
    tilt_rate_deg_s: float = 30.0
    vergence_rate_deg_s: float = 6.0
    tilt_range_deg: tuple[float, float] = (15.0, 45.0)
    vergence_range_deg: tuple[float, float] = (-1.5, 3.5)
    rate_hz: float = 30.0

    def __post_init__(self) -> None:
        """Check the values.

        Raises:
            ValueError: If a value is non-finite, a range is inverted, the tilt leaves
                (-89, 89) degrees or the rate is not positive.

        """
        values = (self.pan_rate_deg_s, self.tilt_rate_deg_s, self.vergence_rate_deg_s,
                  *self.tilt_range_deg, *self.vergence_range_deg, self.rate_hz)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'head motion values must be finite, got {values!r}')
        if self.rate_hz <= 0:
            raise ValueError(f'rate_hz must be positive, got {self.rate_hz}')
        for name in ('tilt_range_deg', 'vergence_range_deg'):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f'{name} is inverted: {low} > {high}')
        if not (-89.0 < self.tilt_range_deg[0] and self.tilt_range_deg[1] < 89.0):
            raise ValueError(f'tilt_range_deg must be inside (-89, 89), got '
                             f'{self.tilt_range_deg}')

    @classmethod
    def at_speed(cls, speed_deg_s: float, rate_hz: float = 30.0) -> HeadMotion:
        """Return pan and tilt at ``speed_deg_s`` each, vergence at a fifth of it."""
        return cls(pan_rate_deg_s=speed_deg_s, tilt_rate_deg_s=speed_deg_s,
                   vergence_rate_deg_s=0.2 * speed_deg_s, rate_hz=rate_hz)

    def angles(self, frame: int, phase: float = 0.0) -> tuple[float, float, float]:
        """Return ``(pan, tilt, vergence)`` in degrees at a frame index.

        Args:
            frame: Frame index (time ``frame / rate_hz``).
            phase: Phase offset of the tilt and vergence sines, radians.

        Returns:
            The three angles, degrees.

        """
        t = frame / self.rate_hz
        pan = self.pan_rate_deg_s * t
        out = [pan]
        for (low, high), rate, shift in ((self.tilt_range_deg, self.tilt_rate_deg_s, 0.0),
                                         (self.vergence_range_deg, self.vergence_rate_deg_s,
                                          1.3)):
            centre, amplitude = 0.5 * (low + high), 0.5 * (high - low)
            if amplitude <= 0 or rate == 0:
                out.append(centre)
                continue
            omega = math.radians(abs(rate)) / math.radians(amplitude)
            out.append(centre + amplitude * math.sin(omega * t + phase + shift))
        return out[0], out[1], out[2]


def ring_of_boxes(rng: np.random.Generator, count: int = 10, distance: tuple[float, float] = (
        2.5, 7.0)) -> list[Box]:
    """Place ``count`` boxes around a head at the origin (level frame, all directions).

    Args:
        rng: Random generator.
        count: Number of boxes.
        distance: ``(min, max)`` horizontal distance of a box centre from the head.

    Returns:
        Non-overlapping boxes spread evenly in bearing, with random distance and size.

    """
    boxes: list[Box] = []
    for i in range(count):
        bearing = 2 * math.pi * (i + rng.uniform(0.15, 0.85)) / max(count, 1)
        dist = float(rng.uniform(*distance))
        size = float(np.clip(0.12 * dist, 0.3, 0.8))
        box = Box(x=dist * math.sin(bearing), z=dist * math.cos(bearing),
                  width=float(rng.uniform(0.6, 1.3) * size),
                  depth=float(rng.uniform(0.6, 1.3) * size),
                  height=float(rng.uniform(0.25, 0.8)), yaw_deg=float(rng.uniform(0, 90)))
        radius = 0.5 * math.hypot(box.width, box.depth)
        if any(math.hypot(box.x - o.x, box.z - o.z)
               < radius + 0.5 * math.hypot(o.width, o.depth) + 0.1 for o in boxes):
            continue
        boxes.append(box)
    return boxes


def head_sequence(n_frames: int, seed: int, motion: HeadMotion, floor: str = 'random',
                  focal_px: float = 600.0, baseline_over_height: float = 0.2,
                  n_boxes: int = 10, width: int = 640, height: int = 480,
                  noise_std: float = 1.0, first_frame: int = 0,
                  supersample: int = 2) -> Iterator[StereoFrame]:
    """Render an active head panning, tilting and verging over a floor with boxes.

    The head stands at a random place on the floor texture; boxes stand around it in all
    directions (:func:`ring_of_boxes`), fixed in the world, so they pass through the view as
    the head pans. Each frame's :attr:`StereoFrame.homography` is its true floor homography
    (it changes with tilt and vergence; pan about the vertical leaves it unchanged, but moves
    the texture and the boxes through the images).

    Args:
        n_frames: Number of frames (>= 1).
        seed: Seed of the head's place, the boxes, the phase and the pixel noise.
        motion: The head's motion.
        floor: Floor texture kind.
        focal_px: Focal length, pixels.
        baseline_over_height: Baseline over camera height.
        n_boxes: Boxes around the head.
        width: Image width in pixels.
        height: Image height in pixels.
        noise_std: Pixel noise, grey levels.
        first_frame: Index of the first frame rendered (to render a sequence in parts).
        supersample: Rays per pixel along each axis.

    Yields:
        ``n_frames`` :class:`StereoFrame` values, rendered lazily.

    Raises:
        ValueError: If ``n_frames < 1``.

    """
    if n_frames < 1:
        raise ValueError(f'n_frames must be >= 1, got {n_frames}')
    rng = np.random.default_rng((int(seed), 9090))
    world_boxes = ring_of_boxes(rng, n_boxes)
    origin = rng.uniform(0, 100, 2)
    heading0 = float(rng.uniform(0, 360))
    phase = float(rng.uniform(0, 2 * math.pi))
    for i in range(first_frame, first_frame + n_frames):
        pan, tilt, vergence = motion.angles(i, phase)
        setup = CameraSetup(focal_px, baseline_over_height, tilt, vergence, width, height)
        c, s = math.cos(math.radians(pan)), math.sin(math.radians(pan))
        level_boxes = [Box(c * b.x - s * b.z, s * b.x + c * b.z, b.width, b.depth, b.height,
                           b.yaw_deg - pan) for b in world_boxes]
        pose = HeadPose(float(origin[0]), float(origin[1]), heading0 + pan)
        yield render_stereo(setup, level_boxes, floor=floor, seed=int(seed),
                            noise_std=noise_std, head_pose=pose,
                            noise_seed=int(seed) * 100003 + i, supersample=supersample)
