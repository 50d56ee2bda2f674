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


def clip_text(text: str, limit: int = 80) -> str:
    """Return ``text`` cut to ``limit`` characters, saying how long it was if it was cut.

    For strings from the wire (an image's encoding, a joint's name) and from files, before
    they reach a log line, an error message or ``/diagnostics``: a 10 KB encoding name
    becomes ``'xxxx...' (10240 characters)`` instead of filling the log.

    Args:
        text: The string.
        limit: Most characters kept.

    Returns:
        ``text`` itself, or its first ``limit`` characters followed by
        ``... (N characters)``.

    """
    if len(text) <= limit:
        return text
    return f'{text[:limit]}... ({len(text)} characters)'


def wire_repr(value: object, limit: int = 40) -> str:
    """Return ``repr(value)`` of a value from the wire, clipped by :func:`clip_text`."""
    text = value if isinstance(value, str) else str(value)
    if len(text) <= limit:
        return repr(text) if isinstance(value, str) else text
    clipped = repr(text[:limit]) if isinstance(value, str) else text[:limit]
    return f'{clipped}... ({len(text)} characters)'
