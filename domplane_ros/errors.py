"""The package's exception hierarchy.

Every error that domplane_ros raises on purpose derives from :class:`DomplaneError`, so callers
can catch the package's errors in one place. Errors about bad input values also derive from
:class:`ValueError`, so code that expects the usual Python type keeps working.
"""

from __future__ import annotations


class DomplaneError(Exception):
    """Base class of all errors raised on purpose by domplane_ros."""


class ImageDecodeError(DomplaneError, ValueError):
    """An image message could not be decoded (bad encoding, sizes, step or data)."""


class ConfigError(DomplaneError, ValueError):
    """A configuration or ROS parameter value is invalid."""


class BagError(DomplaneError):
    """A rosbag2 file could not be read, or lacks the requested topics."""
