"""What every tool shares: one core, the machine's name, progress bars, memory, arguments.

One core
    The tools time the product on one core, so :func:`one_core` pins OpenCV and BLAS to one
    thread for the duration of a run. Environment variables such as ``OPENBLAS_NUM_THREADS``
    cannot do it here: OpenBLAS reads them once, when numpy loads it, and
    ``python -m domplane_ros.tools.<name>`` imports ``domplane_ros`` (and with it numpy and
    cv2) before the tool's first line runs. So the limits are set at run time:
    ``cv2.setNumThreads(1)`` for OpenCV, and for BLAS threadpoolctl if it is installed, else
    the ``*openblas_set_num_threads*`` entry point of the OpenBLAS that numpy loaded (the numpy
    wheels bundle OpenBLAS; Linux only, found through ``/proc/self/maps``). Both are restored
    on exit, so a test that calls a tool's ``main`` leaves the process as it found it. Child
    processes (the load test's node) get :data:`ONE_THREAD_ENV` instead, which works there
    because it is set before they start.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import os
from pathlib import Path
import platform
import sys
from types import SimpleNamespace
from typing import Any, Callable, Iterable, Iterator

import cv2
import numpy as np

ONE_THREAD_ENV = {'OMP_NUM_THREADS': '1', 'OPENBLAS_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1',
                  'OPENCV_FOR_THREADS_NUM': '1'}
_OPENBLAS_PREFIXES = ('openblas', 'scipy_openblas')
_OPENBLAS_SUFFIXES = ('', '64_')


def _openblas_thread_calls() -> list[tuple[Callable[[], int], Callable[[int], None]]]:
    """Return ``(get, set)`` thread-count functions of every OpenBLAS loaded in this process."""
    try:
        with open('/proc/self/maps', encoding='utf-8') as stream:
            paths = {fields[5].strip() for fields in (line.split(None, 5) for line in stream)
                     if len(fields) == 6 and 'openblas' in os.path.basename(fields[5]).lower()}
    except OSError:
        return []
    calls = []
    for path in sorted(paths):
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        names = [(f'{prefix}_get_num_threads{suffix}', f'{prefix}_set_num_threads{suffix}')
                 for prefix in _OPENBLAS_PREFIXES for suffix in _OPENBLAS_SUFFIXES]
        found = [(getattr(library, get, None), getattr(library, put, None))
                 for get, put in names]
        calls += [pair for pair in found if None not in pair][:1]
    return calls


@contextlib.contextmanager
def _blas_limited_to_one_thread() -> Iterator[None]:
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        calls = _openblas_thread_calls()
        before = [get() for get, _ in calls]
        for _, put in calls:
            put(1)
        try:
            yield
        finally:
            for (_, put), count in zip(calls, before):
                put(count)
        return
    with threadpool_limits(limits=1):
        yield


@contextlib.contextmanager
def one_core() -> Iterator[None]:
    """Run the body with OpenCV and BLAS on one thread each (see the module docstring)."""
    before = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with _blas_limited_to_one_thread():
            yield
    finally:
        cv2.setNumThreads(before)


def machine_name() -> str:
    """Return the host name, CPU model and Python/numpy versions, on one line."""
    cpu = platform.processor() or 'unknown CPU'
    try:
        with open('/proc/cpuinfo', encoding='utf-8') as stream:
            for line in stream:
                if line.startswith('model name'):
                    cpu = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    return (f'{platform.node()} | {cpu} | {os.cpu_count()} cores, 1 used | '
            f'Python {platform.python_version()} | numpy {np.__version__} | '
            f'OpenCV {cv2.__version__}')


def progress(items: Iterable, desc: str, **options: Any) -> Iterable:
    """Return ``items`` wrapped in a tqdm progress bar on stderr (as they are without tqdm).

    Args:
        items: What to iterate over (a sized iterable gets a total).
        desc: Label of the bar.
        **options: More tqdm options (``total``, ``disable``, ``unit``, ``mininterval``...);
            by default the bar shows only on a terminal and disappears when done.

    Returns:
        The wrapped iterable; with ``total`` and no items (``items=None``) a bar to
        ``update()`` by hand.

    """
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is in requirements.txt
        return _NoBar() if items is None else items
    settings = {'file': sys.stderr, 'leave': False, 'disable': None}
    settings.update(options)
    return tqdm(items, desc=desc, **settings)


class _NoBar:
    """Stands in for a tqdm bar updated by hand when tqdm is missing."""

    def update(self, count: int = 1) -> None:
        """Do nothing."""

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        """Do nothing."""

    def close(self) -> None:
        """Do nothing."""


def rss_mb(pid: int) -> tuple[float, float]:
    """Return ``(VmRSS, VmHWM)`` of a process in MB (current and peak resident memory)."""
    values = {}
    with open(f'/proc/{pid}/status', encoding='ascii') as stream:
        for line in stream:
            key, _, rest = line.partition(':')
            if key in ('VmRSS', 'VmHWM'):
                values[key] = int(rest.split()[0]) / 1024.0
    return values.get('VmRSS', float('nan')), values.get('VmHWM', float('nan'))


def mono8_message(gray: np.ndarray, stamp_ns: int = 0, encoding: str = 'mono8',
                  frame_id: str = 'cam') -> SimpleNamespace:
    """Return a duck-typed ``sensor_msgs/Image`` of a (H, W) uint8 image, with a header."""
    header = SimpleNamespace(stamp=SimpleNamespace(sec=stamp_ns // 1_000_000_000,
                                                   nanosec=stamp_ns % 1_000_000_000),
                             frame_id=frame_id)
    return SimpleNamespace(header=header, height=gray.shape[0], width=gray.shape[1],
                           encoding=encoding, is_bigendian=0, step=gray.shape[1],
                           data=gray.tobytes())


def tool_parser(doc: str, prog: str | None = None) -> argparse.ArgumentParser:
    """Return an argument parser described by the first line of a tool's docstring."""
    return argparse.ArgumentParser(prog=prog, description=doc.splitlines()[0])


def add_size_arguments(parser: argparse.ArgumentParser, width: int = 640,
                       height: int = 480) -> None:
    """Add ``--width`` and ``--height`` (pixels) with the given defaults."""
    parser.add_argument('--width', type=int, default=width, help=f'image width (default {width})')
    parser.add_argument('--height', type=int, default=height,
                        help=f'image height (default {height})')


def add_output_argument(parser: argparse.ArgumentParser, default: str | Path, what: str,
                        flag: str = '--out') -> None:
    """Add the output folder option (``--out`` or ``--output``) as a :class:`Path`."""
    parser.add_argument(flag, type=Path, default=Path(default),
                        help=f'output folder for {what} (default {default})')


def stop_process(proc: Any) -> None:
    """Stop a child process (a ``subprocess.Popen``): Ctrl-C, then kill after 10 s."""
    import signal
    import subprocess

    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
