"""Real pairs perturbed by transformations whose effect on the true plane is known exactly.

A :class:`Perturbed` pair carries its images, the true left-to-right homography of the
reference plane in the perturbed images and the reference plane's pixels in the perturbed left
image, so any estimate is scored by the same transfer error as the unperturbed pair:

* rig errors of the right camera, applied to the right image by a homography ``A`` (truth
  ``A H``): roll about the image centre, vertical offset, focal mismatch (scale about the
  centre), principal point offset, and the rough rig of issue 11 (all four at their limits);
  the warped right image is black where it has no data;
* photometric differences on one camera (truth ``H``): gain, gamma, noise, JPEG, blur,
  vignetting;
* crops of both images to the same window (truth ``T H T^-1``, ``T`` the window's shift),
  including windows in the upper half where there is little or no road;
* downscaling both by ``cv2.pyrDown`` (``x -> x / 2`` exactly; truth ``S H S^-1``);
* swapped cameras (truth ``H^-1``, the reference points mapped into the new left image).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable

import cv2
from domplane_ros.core.homography import apply_homography
import numpy as np

ROLL_DEG = 4.0
VERTICAL_PX = 30.0
FOCAL = (0.97, 1.03)
PRINCIPAL_PX = 10.0
# The rough rig's relative pitch of 2 degrees at KITTI's focal length (721 px) moves the
# image by about 721 tan(2 deg) = 25 px vertically.
ROUGH_PITCH_PX = 25.0
GAIN = (0.6, 1.4)
GAMMA = (0.7, 1.4)
NOISE_SIGMA = (2.0, 6.0)
JPEG_QUALITY = (30, 70)
BLUR_SIGMA = (1.0, 2.0)
VIGNETTE = (0.2, 0.5)  # darkening at the image corners
PHOTOMETRIC_KINDS = ('gain', 'gamma', 'noise', 'jpeg', 'blur', 'vignette')
# A window with fewer reference pixels than this has no road to score: the right answer
# there is a refusal, and every plane published in it counts as wrong.
MIN_ROAD_PX = 500


@dataclass
class Perturbed:
    """One perturbed pair and its truth.

    Attributes:
        family: Perturbation family (``rig_roll``, ``photometric``, ``crop``, ...).
        detail: The drawn parameters, for the tables and the sheet.
        left: (H, W) uint8 left image.
        right: (H', W') uint8 right image.
        truth: (3, 3) float64 true left-to-right homography of the reference plane.
        points: (N, 2) float64 reference-plane pixels in ``left`` (inside the image).
    """

    family: str
    detail: str
    left: np.ndarray
    right: np.ndarray
    truth: np.ndarray
    points: np.ndarray

    @property
    def has_road(self) -> bool:
        """Return whether the pair shows enough of the reference plane to score a plane."""
        return self.points.shape[0] >= MIN_ROAD_PX

    def errors_px(self, homography: np.ndarray) -> np.ndarray:
        """Return (N,) ``||homography(p) - truth(p)||`` over :attr:`points`."""
        return np.linalg.norm(apply_homography(homography, self.points)
                              - apply_homography(self.truth, self.points), axis=1)


def _about_centre(shape: tuple[int, int], linear: np.ndarray) -> np.ndarray:
    cx, cy = (shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0
    to_centre = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]])
    return np.linalg.inv(to_centre) @ linear @ to_centre


def rig_homography(shape: tuple[int, int], roll_deg: float = 0.0, vertical_px: float = 0.0,
                   focal: float = 1.0, principal_px: tuple[float, float] = (0.0, 0.0)
                   ) -> np.ndarray:
    """Return the (3, 3) homography ``A`` that a right camera's rig errors apply to its image.

    A model in image terms (a relative pitch taken as a pure vertical shift), so that each
    error is drawn in the pixels a user sees. It is not the renderer's rough rig:
    :func:`domplane_ros.sim.rigs.rig_warp` is the exact ``K' R K^-1``, whose pitch also
    moves the image corners by a perspective term (at 2 degrees and KITTI's 721 px focal
    length the two differ by up to 6 px at the corners of the 1242 x 375 image).

    Args:
        shape: ``(H, W)`` of the image; roll and focal act about its centre.
        roll_deg: Rotation about the optical axis (image centre).
        vertical_px: Vertical shift (a small relative pitch).
        focal: Focal-length ratio right / left (scale about the centre).
        principal_px: ``(dx, dy)`` principal point offset (a shift).

    Returns:
        (3, 3) float64 ``A``: a right-image point ``x`` moves to ``A x``.

    """
    angle = math.radians(roll_deg)
    cos, sin = math.cos(angle), math.sin(angle)
    linear = np.array([[focal * cos, -focal * sin, 0.0], [focal * sin, focal * cos, 0.0],
                       [0.0, 0.0, 1.0]])
    shift = np.array([[1.0, 0.0, principal_px[0]], [0.0, 1.0, principal_px[1] + vertical_px],
                      [0.0, 0.0, 1.0]])
    return shift @ _about_centre(shape, linear)


def warp_right(base: Perturbed, family: str, detail: str, rig: np.ndarray) -> Perturbed:
    """Return ``base`` with its right image warped by ``rig`` (truth ``rig @ truth``)."""
    height, width = base.right.shape
    right = cv2.warpPerspective(base.right, rig, (width, height), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return Perturbed(family, detail, base.left, right, rig @ base.truth, base.points)


def _uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(rng.uniform(bounds[0], bounds[1]))


def _disc(rng: np.random.Generator, radius: float) -> tuple[float, float]:
    angle, length = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(0.0, radius)
    return float(length * math.cos(angle)), float(length * math.sin(angle))


def draw_rig(base: Perturbed, family: str, rng: np.random.Generator) -> Perturbed:
    """Draw one rig error of ``family`` and apply it to the right image.

    ``family`` is ``rig_roll``, ``rig_vertical``, ``rig_focal``, ``rig_principal`` (each
    uniform within its limit) or ``rig_rough`` (all four at their limits, random signs).
    """
    shape = base.right.shape
    if family == 'rig_rough':  # issue 11's rough rig, every error at its limit
        sign = rng.choice([-1.0, 1.0], 3)
        angle = rng.uniform(0.0, 2.0 * math.pi)
        principal = (PRINCIPAL_PX * math.cos(angle), PRINCIPAL_PX * math.sin(angle))
        values = {'roll_deg': sign[0] * ROLL_DEG, 'vertical_px': sign[1] * ROUGH_PITCH_PX,
                  'focal': 1.0 + sign[2] * (FOCAL[1] - 1.0), 'principal_px': principal}
    elif family == 'rig_roll':
        values = {'roll_deg': _uniform(rng, (-ROLL_DEG, ROLL_DEG))}
    elif family == 'rig_vertical':
        values = {'vertical_px': _uniform(rng, (-VERTICAL_PX, VERTICAL_PX))}
    elif family == 'rig_focal':
        values = {'focal': _uniform(rng, FOCAL)}
    elif family == 'rig_principal':
        values = {'principal_px': _disc(rng, PRINCIPAL_PX)}
    else:
        raise ValueError(f'unknown rig family {family!r}')
    detail = ' '.join(f'{k}={_short(v)}' for k, v in values.items())
    return warp_right(base, family, detail, rig_homography(shape, **values))


def _short(value: object) -> str:
    if isinstance(value, tuple):
        return '(' + ','.join(f'{v:.1f}' for v in value) + ')'
    return f'{value:.3f}' if isinstance(value, float) else str(value)


def photometric(image: np.ndarray, kind: str, value: float, rng: np.random.Generator
                ) -> np.ndarray:
    """Return ``image`` (uint8) with one photometric change of ``kind`` and strength ``value``.

    ``gain`` multiplies, ``gamma`` applies ``255 (I / 255) ** value``, ``noise`` adds Gaussian
    noise of sigma ``value`` (drawn from ``rng``), ``jpeg`` re-encodes at quality ``value``,
    ``blur`` is a Gaussian of sigma ``value``, ``vignette`` darkens by ``value`` at the corners
    (``1 - value r^2``, ``r`` 1 at a corner).
    """
    grey = image.astype(np.float64)
    if kind == 'gain':
        out = grey * value
    elif kind == 'gamma':
        out = 255.0 * (grey / 255.0) ** value
    elif kind == 'noise':
        out = grey + rng.normal(0.0, value, image.shape)
    elif kind == 'jpeg':
        ok, data = cv2.imencode('.jpg', image, [cv2.IMWRITE_JPEG_QUALITY, int(value)])
        assert ok
        return cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    elif kind == 'blur':
        return cv2.GaussianBlur(image, (0, 0), value)
    elif kind == 'vignette':
        ys, xs = np.mgrid[0:image.shape[0], 0:image.shape[1]].astype(np.float64)
        cx, cy = (image.shape[1] - 1) / 2.0, (image.shape[0] - 1) / 2.0
        radius2 = ((xs - cx) ** 2 + (ys - cy) ** 2) / (cx ** 2 + cy ** 2)
        out = grey * (1.0 - value * radius2)
    else:
        raise ValueError(f'unknown photometric kind {kind!r}')
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def draw_value(kind: str, rng: np.random.Generator) -> float:
    """Return a strength of photometric ``kind`` drawn uniformly within its limits."""
    bounds = {'gain': GAIN, 'gamma': GAMMA, 'noise': NOISE_SIGMA, 'jpeg': JPEG_QUALITY,
              'blur': BLUR_SIGMA, 'vignette': VIGNETTE}[kind]
    if kind == 'jpeg':
        return float(rng.integers(bounds[0], bounds[1] + 1))
    return _uniform(rng, bounds)


def draw_photometric(base: Perturbed, rng: np.random.Generator, kind: str, camera: str
                     ) -> Perturbed:
    """Apply one drawn photometric change of ``kind`` to ``camera`` (``left`` or ``right``)."""
    value = draw_value(kind, rng)
    left, right = base.left, base.right
    if camera == 'left':
        left = photometric(left, kind, value, rng)
    else:
        right = photometric(right, kind, value, rng)
    return Perturbed('photometric', f'{kind}={value:.2f} on {camera}', left, right, base.truth,
                     base.points)


def crop(base: Perturbed, family: str, x0: int, y0: int, width: int, height: int
         ) -> Perturbed:
    """Return both images cut to the same window (truth ``T H T^-1``, ``T`` the shift)."""
    shift = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
    inside = ((base.points[:, 0] >= x0) & (base.points[:, 0] <= x0 + width - 1)
              & (base.points[:, 1] >= y0) & (base.points[:, 1] <= y0 + height - 1))
    points = apply_homography(shift, base.points[inside]) if inside.any() else np.zeros((0, 2))
    window = (slice(y0, y0 + height), slice(x0, x0 + width))
    return Perturbed(family, f'window x{x0} y{y0} {width}x{height}',
                     np.ascontiguousarray(base.left[window]),
                     np.ascontiguousarray(base.right[window]),
                     shift @ base.truth @ np.linalg.inv(shift), points)


def draw_crop(base: Perturbed, family: str, rng: np.random.Generator) -> Perturbed:
    """Draw a window of ``family`` and cut both images to it.

    ``crop``: anywhere, 35-90 % wide, 45-100 % high; ``crop_upper``: the top half of the
    image, 40-100 % wide, where there is little or no road.
    """
    rows, cols = base.left.shape
    if family == 'crop_upper':
        width, height = int(cols * rng.uniform(0.4, 1.0)), rows // 2
        y0 = 0
    else:
        width = int(cols * rng.uniform(0.35, 0.9))
        height = int(rows * rng.uniform(0.45, 1.0))
        y0 = int(rng.integers(0, rows - height + 1))
    x0 = int(rng.integers(0, cols - width + 1))
    return crop(base, family, x0, y0, width, height)


def downscale(base: Perturbed, levels: int) -> Perturbed:
    """Return both images ``cv2.pyrDown``-ed ``levels`` times (truth ``S H S^-1``)."""
    left, right = base.left, base.right
    for _ in range(levels):
        left, right = cv2.pyrDown(left), cv2.pyrDown(right)
    factor = 0.5 ** levels
    scale = np.diag([factor, factor, 1.0])
    points = base.points * factor
    keep = ((points[:, 0] <= left.shape[1] - 1) & (points[:, 1] <= left.shape[0] - 1))
    return Perturbed('downscale', f'pyrDown x{levels}', left, right,
                     scale @ base.truth @ np.linalg.inv(scale), points[keep])


def swap(base: Perturbed, family: str = 'swapped') -> Perturbed:
    """Return the pair with left and right exchanged (truth ``H^-1``, points ``H p``)."""
    points = apply_homography(base.truth, base.points)
    height, width = base.right.shape
    keep = ((points[:, 0] >= 0) & (points[:, 0] <= width - 1) & (points[:, 1] >= 0)
            & (points[:, 1] <= height - 1))
    return Perturbed(family, (base.detail + ' swapped').strip(), base.right, base.left,
                     np.linalg.inv(base.truth), points[keep])


DRAW_FAMILIES = ('rig_roll', 'rig_vertical', 'rig_focal', 'rig_principal', 'rig_rough',
                 'photometric', 'crop', 'crop_upper', 'swapped_rig')


def draw(base: Perturbed, family: str, seed: int) -> Perturbed:
    """Return draw ``seed`` of ``family`` (one of :data:`DRAW_FAMILIES`) from ``base``.

    The generator is ``numpy.random.default_rng((seed, index of the family))``; the
    photometric kind goes through :data:`PHOTOMETRIC_KINDS` in turn with the seed, on the
    right camera for even ``seed // 6``, the left for odd; ``swapped_rig`` swaps a
    ``rig_rough``-like pair whose errors are drawn within the limits (not at them).
    """
    rng = np.random.default_rng((seed, DRAW_FAMILIES.index(family)))
    makers: dict[str, Callable[[], Perturbed]] = {
        'photometric': lambda: draw_photometric(
            base, rng, PHOTOMETRIC_KINDS[seed % len(PHOTOMETRIC_KINDS)],
            'right' if (seed // len(PHOTOMETRIC_KINDS)) % 2 == 0 else 'left'),
        'crop': lambda: draw_crop(base, 'crop', rng),
        'crop_upper': lambda: draw_crop(base, 'crop_upper', rng),
        'swapped_rig': lambda: swap(_within_limits(base, rng), 'swapped_rig'),
    }
    if family in makers:
        return makers[family]()
    return draw_rig(base, family, rng)


def _within_limits(base: Perturbed, rng: np.random.Generator) -> Perturbed:
    values = {'roll_deg': _uniform(rng, (-ROLL_DEG, ROLL_DEG)),
              'vertical_px': _uniform(rng, (-ROUGH_PITCH_PX, ROUGH_PITCH_PX)),
              'focal': _uniform(rng, FOCAL), 'principal_px': _disc(rng, PRINCIPAL_PX)}
    detail = ' '.join(f'{k}={_short(v)}' for k, v in values.items())
    return warp_right(base, 'rig', detail, rig_homography(base.right.shape, **values))
