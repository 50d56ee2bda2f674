"""Legend and captions for the overlays of :func:`~domplane_ros.core.mask.overlay`.

The legend names what each mark is: the tint is the mask (labels of
:func:`~domplane_ros.core.mask.plane_mask`), a cyan circle a left corner that the plane
homography maps onto a right corner (an inlier of the estimate), a magenta cross a left corner
that it maps onto none (unmatched under the plane: on an obstacle, or on the floor but missed
by the right detector or outside the right view). Text is wrapped to the picture's width,
never cut off.
"""

from __future__ import annotations

import cv2
from domplane_ros.core.mask import INLIER_RGB, OBSTACLE_RGB, OUTLIER_RGB, PLANE_RGB
import numpy as np

# (RGB colour, text) of each mark, in the order the legend shows them.
LEGEND = ((PLANE_RGB, 'green tint: plane (floor)'),
          (OBSTACLE_RGB, 'red tint: off the plane (obstacle)'),
          (INLIER_RGB, 'cyan o: corner matched on the plane'),
          (OUTLIER_RGB, 'magenta x: unmatched corner'))
UNKNOWN_NOTE = 'no tint: unknown (no texture, not seen, too far or above the horizon)'

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_WHITE = (255, 255, 255)
_GREY = (40, 40, 40)
_MARGIN = 8


def _thickness(scale: float) -> int:
    return 1 if scale < 0.7 else 2


def _text_size(text: str, scale: float) -> tuple[int, int]:
    (width, height), _ = cv2.getTextSize(text, _FONT, scale, _thickness(scale))
    return width, height


def wrap_text(text: str, width: int, scale: float) -> list[str]:
    """Split ``text`` at spaces into lines that fit ``width`` pixels (a long word alone).

    Args:
        text: The text.
        width: Room in pixels, margins included.
        scale: OpenCV font scale.

    Returns:
        The lines (at least one).

    """
    room = max(1, width - 2 * _MARGIN)
    lines: list[str] = []
    for word in text.split():
        if lines and _text_size(lines[-1] + ' ' + word, scale)[0] <= room:
            lines[-1] += ' ' + word
        else:
            lines.append(word)
    return lines or ['']


def text_strip(width: int, text: str, scale: float = 0.5, min_height: int = 0) -> np.ndarray:
    """Return a dark (h, width, 3) uint8 RGB strip with ``text`` in white, wrapped to fit.

    Args:
        width: Strip width in pixels.
        text: The text; it wraps onto as many lines as it needs.
        scale: OpenCV font scale.
        min_height: Smallest strip height in pixels.

    """
    lines = wrap_text(text, width, scale)
    line_h = _text_size('Ag', scale)[1] + max(6, int(10 * scale))
    height = max(min_height, line_h * len(lines) + 8)
    strip = np.full((height, width, 3), _GREY, np.uint8)
    top = (height - line_h * len(lines)) // 2
    for k, line in enumerate(lines):
        baseline = top + (k + 1) * line_h - max(3, int(5 * scale))
        cv2.putText(strip, line, (_MARGIN, baseline), _FONT, scale, _WHITE, _thickness(scale),
                    cv2.LINE_AA)
    return strip


def legend_strip(width: int, title: str = '', scale: float = 0.5,
                 unknown_note: bool = True) -> np.ndarray:
    """Return a dark strip with an optional title and every mark of :data:`LEGEND`.

    Entries that do not fit on a row start a new row, so none is dropped.

    Args:
        width: Strip width in pixels.
        title: Text before the entries ('' for none).
        scale: OpenCV font scale.
        unknown_note: Also say what an untinted pixel is.

    Returns:
        (h, width, 3) uint8 RGB image.

    """
    swatch = _text_size('Ag', scale)[1]
    entries = [(None, title)] if title else []
    entries += list(LEGEND) + ([(None, UNKNOWN_NOTE)] if unknown_note else [])
    rows: list[list[tuple[tuple[int, int, int] | None, str, int]]] = [[]]
    x = _MARGIN
    for colour, text in entries:
        item_w = _text_size(text, scale)[0] + (swatch + 6 if colour is not None else 0)
        if rows[-1] and x + item_w > width - _MARGIN:
            rows.append([])
            x = _MARGIN
        rows[-1].append((colour, text, x))
        x += item_w + 20
    line_h = swatch + max(8, int(14 * scale))
    strip = np.full((line_h * len(rows) + 8, width, 3), _GREY, np.uint8)
    for k, row in enumerate(rows):
        y0 = 4 + k * line_h + (line_h - swatch) // 2
        for colour, text, x in row:
            if colour is not None:
                cv2.rectangle(strip, (x, y0), (x + swatch, y0 + swatch), colour, -1)
                x += swatch + 6
            cv2.putText(strip, text, (x, y0 + swatch), _FONT, scale, _WHITE, _thickness(scale),
                        cv2.LINE_AA)
    return strip


def with_legend(rgb: np.ndarray, title: str = '', caption: str = '',
                scale: float | None = None) -> np.ndarray:
    """Return an overlay with the legend above it and an optional caption below.

    Args:
        rgb: (H, W, 3) uint8 overlay from :func:`~domplane_ros.core.mask.overlay`.
        title: Text at the start of the legend.
        caption: Text below the picture ('' for none).
        scale: OpenCV font scale (default: from the width).

    Returns:
        (H', W, 3) uint8 RGB image.

    Raises:
        ValueError: If ``rgb`` is not (H, W, 3) uint8.

    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f'rgb must be (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}')
    width = rgb.shape[1]
    if scale is None:
        scale = 0.5 if width >= 600 else 0.4
    parts = [legend_strip(width, title, scale), rgb]
    if caption:
        parts.append(text_strip(width, caption, scale))
    return np.vstack(parts)
