"""Working arrays reused between calls, one set per thread (the mask's float images).

A fresh (h, w) float32 array of a 320 x 240 working image is 300 kB: when the C allocator
has given such memory back to the operating system, every new one costs page faults, and the
mask made about twenty per call. In a process that runs only the mask (docs/MASK.md, round 4)
the local fit took twice as long with fresh arrays as with reused ones; where other work keeps
the allocator's memory (the pipeline) the difference is small.
:func:`scratch` hands out the same array for the same name, shape and dtype again; what it
holds on return is undefined, and no caller may keep it past its own call or return it.
Nothing computed is kept: results never depend on earlier calls. :func:`constant` keeps
read-only arrays of one value (masked fills with ``cv2.copyTo``).
"""

from __future__ import annotations

import threading

import numpy as np


class _Arrays(threading.local):
    """The calling thread's arrays by name (one array per name: the latest shape)."""

    def __init__(self) -> None:
        self.by_name: dict[str, np.ndarray] = {}


_ARRAYS = _Arrays()
# More constant arrays than this (image sizes change) and the thread's set starts again.
_MAX_CONSTANTS = 16


def scratch(name: str, shape: tuple[int, ...], dtype: type = np.float32) -> np.ndarray:
    """Return this thread's working array ``name`` of ``shape`` and ``dtype`` (contents undefined).

    Args:
        name: What the array is for; two arrays alive at once need two names.
        shape: The array's shape.
        dtype: The array's dtype (default float32).

    Returns:
        A C-contiguous array, the same object as the last call with this name, shape and
        dtype in this thread.

    """
    array = _ARRAYS.by_name.get(name)
    if array is None or array.shape != shape or array.dtype != dtype:
        array = np.empty(shape, dtype)
        _ARRAYS.by_name[name] = array
    return array


class _Constants(threading.local):
    """The calling thread's constant arrays by value, shape and dtype."""

    def __init__(self) -> None:
        self.by_key: dict[tuple, np.ndarray] = {}


_CONSTANTS = _Constants()


def constant(value: float, shape: tuple[int, ...], dtype: type) -> np.ndarray:
    """Return a read-only array of ``shape`` and ``dtype`` filled with ``value`` (reused).

    Args:
        value: The fill value.
        shape: The array's shape.
        dtype: The array's dtype.

    Returns:
        This thread's array for that value, shape and dtype (made once, never written).

    """
    key = (float(value), tuple(shape), np.dtype(dtype).str)
    array = _CONSTANTS.by_key.get(key)
    if array is None:
        if len(_CONSTANTS.by_key) >= _MAX_CONSTANTS:
            _CONSTANTS.by_key.clear()
        array = np.full(shape, value, dtype)
        array.flags.writeable = False
        _CONSTANTS.by_key[key] = array
    return array
