"""Stereo pairs from image files: two files, or two folders paired by sorted name.

No ROS: images are read with OpenCV as 8-bit grey (colour is converted; 16-bit grey or colour
files are scaled by ``image.mono16_bits`` as mono16 messages are).
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path

import cv2
from domplane_ros.core.image import mono16_range_warning, mono16_to_gray
from domplane_ros.errors import DomplaneError
import numpy as np

# File name endings read from a folder (OpenCV decodes them all).
IMAGE_SUFFIXES = ('.bmp', '.jpeg', '.jpg', '.pgm', '.png', '.ppm', '.tif', '.tiff', '.webp')


class PairInputError(DomplaneError):
    """A stereo pair cannot be formed or read from the given files."""


@dataclass(frozen=True)
class ImagePair:
    """One stereo pair of image files.

    Attributes:
        name: Name of the pair: the left file's stem (its whole name if stems repeat).
        left: Left image file.
        right: Right image file.

    """

    name: str
    left: Path
    right: Path


def image_pairs(left: str | os.PathLike[str], right: str | os.PathLike[str]) -> list[ImagePair]:
    """Return the stereo pairs of two image files, or of two folders paired by sorted name.

    Args:
        left: Left image file, or a folder of left images.
        right: Right image file, or a folder of right images.

    Returns:
        One pair for two files; for two folders, the i-th left image (sorted by file name)
        with the i-th right image.

    Raises:
        PairInputError: If a path does not exist, one is a file and the other a folder, a
            folder holds no image, or the folders hold different numbers of images.

    """
    left_path, right_path = Path(left), Path(right)
    for side, path in (('left', left_path), ('right', right_path)):
        if not path.exists():
            raise PairInputError(f'{side} {str(path)!r} does not exist')
    if left_path.is_dir() != right_path.is_dir():
        raise PairInputError(f'give two image files or two folders, not a '
                             f'{_kind(left_path)} ({str(left_path)!r}) and a '
                             f'{_kind(right_path)} ({str(right_path)!r})')
    if not left_path.is_dir():
        return [ImagePair(left_path.stem, left_path, right_path)]
    lefts, rights = _images_in(left_path, 'left'), _images_in(right_path, 'right')
    if len(lefts) != len(rights):
        raise PairInputError(f'left folder {str(left_path)!r} holds {len(lefts)} images but '
                             f'right folder {str(right_path)!r} holds {len(rights)}; pairs are '
                             'made by sorted name, so the counts must match')
    stems = [path.stem for path in lefts]
    unique = len(set(stems)) == len(stems)
    return [ImagePair(path.stem if unique else path.name, path, other)
            for path, other in zip(lefts, rights)]


def _kind(path: Path) -> str:
    return 'folder' if path.is_dir() else 'file'


def _images_in(folder: Path, side: str) -> list[Path]:
    files = sorted(p for p in folder.iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise PairInputError(f'{side} folder {str(folder)!r} holds no image files '
                             f'({", ".join(IMAGE_SUFFIXES)})')
    return files


def read_gray(path: Path, side: str, mono16_bits: int = 16) -> tuple[np.ndarray, bool]:
    """Return an image file as (H, W) uint8 grey, and whether it held 16 bits.

    A 16-bit file (a 12-bit sensor's PNG) is scaled by ``mono16_bits`` as the node scales
    mono16 (:func:`~domplane_ros.core.image.mono16_to_gray`).

    Raises:
        PairInputError: If the file cannot be read or decoded as an image.

    """
    try:
        data = np.fromfile(path, np.uint8)
    except OSError as err:
        raise PairInputError(f'cannot read {side} image {str(path)!r}: '
                             f'{err.strerror or err}') from err
    flags = cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH
    image = cv2.imdecode(data, flags) if data.size else None
    if image is None or image.size == 0:
        raise PairInputError(f'{side} image {str(path)!r} is not an image OpenCV can decode')
    if image.dtype == np.uint16:
        return mono16_to_gray(image, mono16_bits), True
    if image.dtype != np.uint8:   # 32-bit float files (EXR, TIFF): OpenCV's 8-bit reading
        image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    return image, False


def read_pair(pair: ImagePair, mono16_bits: int = 16) -> tuple[np.ndarray, np.ndarray, str]:
    """Return the pair's (H, W) uint8 grey left and right images, and an image warning.

    Args:
        pair: The files.
        mono16_bits: Significant bits of 16-bit files (``image.mono16_bits``).

    Returns:
        ``(left, right, warning)``; the warning says when 16-bit files use far fewer bits
        than ``mono16_bits`` ('' if not, and for 8-bit files).

    Raises:
        PairInputError: If an image cannot be read, or the two differ in size.

    """
    (left, left16), (right, right16) = (read_gray(pair.left, 'left', mono16_bits),
                                        read_gray(pair.right, 'right', mono16_bits))
    if left.shape != right.shape:
        raise PairInputError(
            f'left {str(pair.left)!r} is {left.shape[1]}x{left.shape[0]} but right '
            f'{str(pair.right)!r} is {right.shape[1]}x{right.shape[0]}; the two cameras must '
            'give images of one size')
    wide = [gray for gray, sixteen in ((left, left16), (right, right16)) if sixteen]
    return left, right, mono16_range_warning(wide, mono16_bits) if wide else ''
