"""plane_node's start-up checks: parameters files before rcl reads them, rcl's own refusals.

:func:`check_params_files` reads every ``--params-file`` of the command line through the
guarded reader (:mod:`domplane_ros.params_file`: size limit, no YAML aliases, the structure
of a parameters file, every parameter of the node's blocks valid) before ``rclpy.init`` hands
the file to rcl. :func:`init_rclpy` turns rcl's refusal of the arguments (a malformed
``-p`` or ``-r``, a parameters file rcl cannot parse) into one :class:`ConfigError` line: rcl
logs its own ``[ERROR] [rcl]: ...`` line to stderr first and raises with file and line
numbers of its C sources, so stderr is held back while rcl parses and shown only on success.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
from typing import Iterator, Sequence

from domplane_ros.errors import clip_text, ConfigError
from domplane_ros.params_file import read_node_params, ros_params_files
import rclpy

NODE_NAME = 'plane_node'
_C_SOURCE = re.compile(r',? at [^,]*\.c:\d+')


def check_params_files(args: Sequence[str], node_name: str = NODE_NAME) -> int:
    """Check every ``--params-file`` of ``args`` before rcl sees it.

    Args:
        args: The command line (program name first, as ``sys.argv``).
        node_name: The node's name (a ``-r __node:=NAME`` in ``args`` replaces it).

    Returns:
        The number of parameters files checked.

    Raises:
        ConfigError: The first problem, one line naming the file.

    """
    paths, renamed = ros_params_files(args)
    for path in paths:
        read_node_params(path, renamed or node_name)
    return len(paths)


@contextlib.contextmanager
def _stderr_held() -> Iterator[list[str]]:
    """Send file descriptor 2 to a temporary file; yield a list that receives its text."""
    sys.stderr.flush()
    saved = os.dup(2)
    captured: list[str] = []
    with tempfile.TemporaryFile(mode='w+b') as held:
        os.dup2(held.fileno(), 2)
        try:
            yield captured
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            captured.append(held.read(1_000_000).decode('utf-8', 'replace'))


def init_rclpy(args: Sequence[str] | None) -> None:
    """Initialise rclpy with ``args``; refuse what rcl refuses with one line.

    Args:
        args: The command line (None: ``sys.argv``).

    Raises:
        ConfigError: If rcl refuses the arguments; the message is rcl's reason on one line,
            without its C source locations.

    """
    try:
        with _stderr_held() as captured:
            rclpy.init(args=args)
    except Exception as err:  # noqa: B902 - rclpy raises RCLError, which is not exported
        text = ' '.join(_C_SOURCE.sub('', str(err)).split())
        text = text.removeprefix('failed to initialize rcl: ')
        raise ConfigError(f'the ROS arguments were refused: {clip_text(text, 300)}') from err
    if captured and captured[0]:
        sys.stderr.write(captured[0])
