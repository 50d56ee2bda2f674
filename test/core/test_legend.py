"""The overlay legend names every mark and never cuts text off."""

from __future__ import annotations

import cv2
from domplane_ros.core.legend import LEGEND, legend_strip, text_strip, with_legend, wrap_text
from domplane_ros.core.mask import INLIER_RGB, OUTLIER_RGB, overlay
import numpy as np
import pytest


def _has_colour(image: np.ndarray, colour) -> bool:
    return bool(np.any(np.all(image == np.array(colour, np.uint8), axis=-1)))


def test_legend_names_the_overlay_colours_as_what_they_are():
    texts = dict(LEGEND)
    assert 'unmatched' in texts[OUTLIER_RGB] and 'off-plane' not in texts[OUTLIER_RGB]
    assert 'matched on the plane' in texts[INLIER_RGB]
    # The overlay draws exactly these colours for the two kinds of corner.
    gray = np.full((60, 80), 128, np.uint8)
    rgb = overlay(gray, np.zeros_like(gray), np.array([[20.0, 30.0]]), np.array([[60.0, 30.0]]))
    assert _has_colour(rgb[:, :40], INLIER_RGB) and not _has_colour(rgb[:, :40], OUTLIER_RGB)
    assert _has_colour(rgb[:, 40:], OUTLIER_RGB) and not _has_colour(rgb[:, 40:], INLIER_RGB)


@pytest.mark.parametrize('width', [1200, 320, 160])
def test_legend_strip_shows_every_entry_at_any_width(width):
    strip = legend_strip(width, 'title')
    assert strip.shape[1] == width
    for colour, _ in LEGEND:
        assert _has_colour(strip, colour), (width, colour)
    # Narrow strips wrap onto more rows instead of dropping entries.
    assert legend_strip(160, 'title').shape[0] > legend_strip(1200, 'title').shape[0]


def test_long_text_wraps_within_the_width():
    text = 'frame 0: no plane (search found no verified plane: plane explains too little)'
    lines = wrap_text(text, 320, 0.45)
    assert len(lines) > 1 and ' '.join(lines) == text
    for line in lines:
        (line_w, _), _ = cv2.getTextSize(line, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)
        assert line_w <= 320 - 16
    assert text_strip(320, text, 0.45).shape[0] > text_strip(320, 'short', 0.45).shape[0]


def test_with_legend_keeps_the_picture_and_checks_its_input():
    rgb = np.full((50, 400, 3), 7, np.uint8)
    out = with_legend(rgb, 'title', 'caption')
    assert out.shape[1] == 400 and out.shape[0] > 50
    assert any(np.array_equal(out[k:k + 50], rgb) for k in range(out.shape[0] - 49))
    with pytest.raises(ValueError, match='rgb must be'):
        with_legend(np.zeros((5, 5), np.uint8))
