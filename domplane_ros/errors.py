"""The package's exception hierarchy.

Every error that domplane_ros raises on purpose derives from :class:`DomplaneError`, so callers
can catch the package's errors in one place. Errors about bad input values also derive from
:class:`ValueError`, so code that expects the usual Python type keeps working.
"""

from __future__ import annotations


class DomplaneError(Exception):
    """Base class of all errors raised on purpose by domplane_ros."""


class ImageDecodeError(DomplaneError, ValueError):
    """An image message could not be decoded (bad encoding, sizes, step or data).

    Args:
        message: What is wrong, in words.
        kind: The kind of problem, one of :data:`DECODE_ERROR_KINDS` (diagnostics count
            decode errors by kind).

    """

    def __init__(self, message: str, kind: str = 'field') -> None:
        """Keep the message and the kind."""
        super().__init__(message)
        self.kind = kind if kind in DECODE_ERROR_KINDS else 'field'


DECODE_ERROR_KINDS: tuple[str, ...] = (
    'encoding', 'zero_size', 'step', 'data_length', 'data', 'field', 'compressed')
"""Kinds of :class:`ImageDecodeError`: an unsupported encoding or compression, a zero width or
height, a ``step`` smaller than a row, a data length other than ``height * step``, data that
is not a byte buffer, a missing or mistyped field, compressed data that does not decode."""


class ConfigError(DomplaneError, ValueError):
    """A configuration or ROS parameter value is invalid."""


class BagError(DomplaneError):
    """A rosbag2 file could not be read, or lacks the requested topics."""
