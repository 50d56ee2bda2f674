"""An optional on-disk cache of rendered frames, for runs that render the same scenes again.

The renderer is deterministic: a frame is a function of :func:`render_stereo`'s arguments,
the simulator's source (with the prior's camera model) and the numpy and OpenCV versions.
When the environment variable ``DOMPLANE_RENDER_CACHE`` names a folder, each rendered frame
is stored there under a key made of exactly these (the arguments' pickled bytes, so two
calls share a frame only when their arguments are equal value for value), and a later call
with the same key loads it instead of rendering (~1 s a 640x480 pair). The test suite
(``make test``) sets it, so a scene that several tests render is rendered once a run, also
across the parallel workers; evaluations may set it too. Unset (the default), nothing is
read or written.

Every load returns fresh arrays (no frame is shared between callers). A file that cannot be
read (truncated, another version) is rendered again and replaced; files are written to a
temporary name and renamed, so a parallel reader never sees half a frame. ``make clean``
removes the folder.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path
import pickle
from typing import Callable, TypeVar
import zlib

import cv2
import numpy as np

ENVIRONMENT_VARIABLE = 'DOMPLANE_RENDER_CACHE'
# What a frame depends on: the simulator and the camera model it takes from the prior.
_SOURCES = Path(__file__).resolve().parent
_MORE_SOURCES = (_SOURCES.parent / 'core' / 'prior.py',)
_Frame = TypeVar('_Frame')


@functools.lru_cache(maxsize=1)
def _code_version() -> bytes:
    """Return a digest of the simulator's source and the numeric libraries' versions."""
    digest = hashlib.sha256()
    for path in sorted(_SOURCES.glob('*.py')) + list(_MORE_SOURCES):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    digest.update(f'numpy {np.__version__} opencv {cv2.__version__}'.encode())
    return digest.digest()


def cache_key(name: str, args: tuple, kwargs: dict) -> str:
    """Return the hex key of a call: its function, arguments and the code version."""
    digest = hashlib.sha256(_code_version())
    digest.update(name.encode())
    digest.update(pickle.dumps((args, sorted(kwargs.items())), protocol=4))
    return digest.hexdigest()


def _load(path: Path):
    try:
        return pickle.loads(zlib.decompress(path.read_bytes()))
    except FileNotFoundError:
        return None
    except Exception:  # noqa: B902 - a damaged or foreign file is rendered again
        return None


def _store(path: Path, frame) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f'{path.name}.{os.getpid()}.tmp')
    temporary.write_bytes(zlib.compress(pickle.dumps(frame, protocol=4), 1))
    os.replace(temporary, path)


def cached(render: Callable[..., _Frame]) -> Callable[..., _Frame]:
    """Wrap a deterministic renderer with the cache named by ``DOMPLANE_RENDER_CACHE``."""

    @functools.wraps(render)
    def wrapper(*args, **kwargs):
        folder = os.environ.get(ENVIRONMENT_VARIABLE, '')
        if not folder:
            return render(*args, **kwargs)
        path = Path(folder) / f'{cache_key(render.__qualname__, args, kwargs)}.pkl.z'
        frame = _load(path)
        if frame is None:
            frame = render(*args, **kwargs)
            _store(path, frame)
        return frame

    return wrapper
