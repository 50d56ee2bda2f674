"""The one guarded reader of ROS 2 parameters files, for plane_node and plane_replay.

Both tools read every ``--params-file`` through :func:`read_node_params` before anything
else does: plane_node before rcl parses the file (rcl took minutes and gigabytes on a 55 MB
file), plane_replay instead of a plain ``yaml.safe_load`` (which expanded an 850-byte file of
nested aliases for over a minute). The file is refused with one line naming the problem when

* it is not a regular file or is larger than :data:`MAX_PARAMS_FILE_BYTES` (1 MB, checked
  before it is read, and again while reading);
* it is not UTF-8 or not YAML, uses a YAML alias (``*name``, also ``<<: *name``; rcl does
  not support them either), nests deeper than :data:`MAX_YAML_DEPTH` or holds more than
  :data:`MAX_YAML_NODES` values (a scan of the parser's events, which stops at the limit,
  so no hostile file is ever built into objects);
* its structure is not that of a ROS 2 parameters file: a mapping from node names (``/**``,
  ``plane_node``, ``/ns/plane_node``; or namespaces nesting node names, as rcl allows) to a
  mapping whose only key is ``ros__parameters``, itself a mapping of names to a value or a
  list of values of one type;
* no block applies to the node, or a parameter of a block that applies (``/**``, ``/*``,
  or a name ending in the node's name) is unknown or invalid (the table's validator, as for
  every other way a parameter can be set).

Blocks of other nodes are checked for structure only. Blocks that apply are merged in file
order, wildcards before named blocks, as rclpy applies its overrides.
"""

from __future__ import annotations

import os
import stat
from typing import Any, Iterable, Mapping

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.errors import clip_text, ConfigError
from domplane_ros.parameters import flatten_params
import yaml

MAX_PARAMS_FILE_BYTES = 1_000_000
"""Largest parameters file read, bytes (the full default file is about 12 KB)."""
MAX_YAML_DEPTH = 32
"""Deepest nesting of YAML collections accepted."""
MAX_YAML_NODES = 20_000
"""Most YAML nodes (scalars and collections) accepted in one file."""

_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
_WILDCARDS = ('**', '*')
# rclpy's own parameters, accepted in the node's blocks besides the table's.
_ROS_PARAMETERS = {'use_sim_time': bool}


class NoNodeBlockError(ConfigError):
    """The parameters file has no block that applies to the node."""


def node_name_hint(err: BaseException) -> str:
    """Return what plane_replay and plane_pair add to a file without the node's block.

    Their ``--node-name`` reads the blocks of a renamed node (``-r __node:=front_plane``).
    """
    if isinstance(err, NoNodeBlockError):
        return "; for a renamed node's block give --node-name NAME"
    return ''


def read_yaml(path: str | os.PathLike[str]) -> Any:
    """Read a YAML file within the limits of this module and return its document.

    Args:
        path: The file.

    Returns:
        The document (plain dicts, lists and scalars).

    Raises:
        ConfigError: If the file cannot be read, is not a regular file, is too large, is not
            UTF-8 YAML, uses an alias, nests too deep or holds too many values; one line.

    """
    name = repr(str(path))
    try:
        # Non-blocking, so that a FIFO does not wait for a writer before it is refused.
        fd = os.open(path, os.O_RDONLY | getattr(os, 'O_NONBLOCK', 0))
        with open(fd, 'rb') as stream:
            info = os.fstat(stream.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise ConfigError(f'params file {name} is not a regular file')
            if info.st_size > MAX_PARAMS_FILE_BYTES:
                raise ConfigError(f'params file {name} is {_size(info.st_size)}, larger than '
                                  f'the limit of {_size(MAX_PARAMS_FILE_BYTES)}')
            data = stream.read(MAX_PARAMS_FILE_BYTES + 1)
    except OSError as err:
        raise ConfigError(f'cannot read params file {name}: {err.strerror or err}') from err
    if len(data) > MAX_PARAMS_FILE_BYTES:  # it grew while being read
        raise ConfigError(f'params file {name} is larger than the limit of '
                          f'{_size(MAX_PARAMS_FILE_BYTES)}')
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise ConfigError(f'params file {name} is not UTF-8 text (byte {err.start})') from err
    try:
        _scan_events(text, name)
        return yaml.load(text, Loader=_LOADER)  # noqa: S506 - a safe loader
    except yaml.YAMLError as err:
        raise ConfigError(f'params file {name} is not valid YAML: {_one_line(err)}') from err
    except RecursionError as err:   # cannot happen within MAX_YAML_DEPTH; kept as a guard
        raise ConfigError(f'params file {name} nests too deep') from err


def _scan_events(text: str, name: str) -> None:
    """Refuse aliases, deep nesting and too many nodes, stopping at the first problem."""
    depth = nodes = 0
    for event in yaml.parse(text, Loader=_LOADER):
        if isinstance(event, yaml.AliasEvent):
            raise ConfigError(f'params file {name} uses the YAML alias *{_short(event.anchor)}'
                              f'{_where(event)}: aliases are not supported (write the value '
                              'out)')
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                raise ConfigError(f'params file {name} nests deeper than {MAX_YAML_DEPTH} '
                                  f'levels{_where(event)}')
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
        if isinstance(event, yaml.NodeEvent):
            nodes += 1
            if nodes > MAX_YAML_NODES:
                raise ConfigError(f'params file {name} holds more than {MAX_YAML_NODES} '
                                  f'values{_where(event)}')


def parameter_blocks(document: Any, name: str) -> list[tuple[str, dict[str, Any]]]:
    """Check a parameters file's structure and return its blocks in file order.

    Args:
        document: The file's YAML document.
        name: The file's name, for messages.

    Returns:
        ``(node name, ros__parameters mapping)`` per block; nested namespaces are joined
        with ``/`` (``{'ns': {'node': ...}}`` gives ``'ns/node'``).

    Raises:
        ConfigError: If the structure is not a ROS 2 parameters file's; one line.

    """
    if document is None:
        raise ConfigError(f'params file {name} is empty')
    if not isinstance(document, Mapping):
        raise ConfigError(f'params file {name} must be a mapping of node names to '
                          f'"ros__parameters:" blocks, not a {_kind(document)}')
    blocks: list[tuple[str, dict[str, Any]]] = []
    _collect_blocks(document, '', name, blocks)
    return blocks


def _collect_blocks(mapping: Mapping[Any, Any], prefix: str, name: str,
                    blocks: list[tuple[str, dict[str, Any]]]) -> None:
    for key, value in mapping.items():
        if not isinstance(key, str) or not key.strip('/'):
            raise ConfigError(f'params file {name}: {_short(repr(key))} is not a node name')
        node = f'{prefix}/{key.strip("/")}' if prefix else key.strip('/')
        where = f'params file {name}, node {_short(repr(node))}'
        if not isinstance(value, Mapping) or not value:
            raise ConfigError(f'{where}: expected a "ros__parameters:" mapping, got '
                              f'{_kind(value)}')
        if 'ros__parameters' not in value:
            if any(not isinstance(v, Mapping) for v in value.values()):
                raise ConfigError(f'{where}: expected a "ros__parameters:" mapping')
            _collect_blocks(value, node, name, blocks)   # a namespace
            continue
        if len(value) > 1:
            other = next(k for k in value if k != 'ros__parameters')
            raise ConfigError(f'{where}: {_short(repr(other))} beside ros__parameters')
        params = value['ros__parameters']
        if not isinstance(params, Mapping):
            raise ConfigError(f'{where}: ros__parameters must be a mapping of parameter '
                              f'names to values, not a {_kind(params)}')
        _check_values(params, '', where)
        blocks.append((node, dict(params)))


def _check_values(params: Mapping[Any, Any], prefix: str, where: str) -> None:
    """Check that a block holds names mapping to scalars or lists of one scalar type."""
    for key, value in params.items():
        if not isinstance(key, str) or not key:
            raise ConfigError(f'{where}: {_short(repr(key))} is not a parameter name')
        full = prefix + key
        if isinstance(value, Mapping) and value:
            _check_values(value, full + '.', where)
        elif isinstance(value, list):
            types = {_scalar_type(v) for v in value}
            if None in types or len(types - {float, int}) > 0 and len(types) > 1:
                raise ConfigError(f'{where}: parameter {_short(repr(full))} must be a list of '
                                  'numbers, booleans or strings of one type')
        elif value is None or isinstance(value, Mapping) or _scalar_type(value) is None:
            raise ConfigError(f'{where}: parameter {_short(repr(full))} has no value or a '
                              f'value of type {_kind(value)}')


def _scalar_type(value: Any) -> type | None:
    for kind in (bool, int, float, str):
        if isinstance(value, kind):
            return kind
    return None


def applies_to(block_name: str, node_name: str) -> bool:
    """Return whether a block's parameters apply to a node (its namespace is not known).

    ``/**``, ``/*``, ``node`` and any name whose last part is the node's name or a wildcard
    (``/ns/node``, ``/**/node``) apply.
    """
    last = block_name.strip('/').rsplit('/', 1)[-1]
    return last in _WILDCARDS or last == node_name


def read_node_params(path: str | os.PathLike[str], node_name: str = 'plane_node'
                     ) -> dict[str, Any]:
    """Read a parameters file through every check above; return the node's parameters.

    Args:
        path: The file.
        node_name: The node whose blocks are validated and merged.

    Returns:
        The node's parameters, flat (dotted names), validated one by one, without rclpy's
        own (``use_sim_time``).

    Raises:
        ConfigError: On any problem named in the module docstring; one line.

    """
    name = repr(str(path))
    blocks = parameter_blocks(read_yaml(path), name)
    mine = [(block, params) for block, params in blocks if applies_to(block, node_name)]
    if not mine:
        found = ', '.join(_short(block) for block, _ in blocks[:3]) or 'none'
        raise NoNodeBlockError(
            f'params file {name} has no block for {node_name} (a "{node_name}:" or "/**:" key '
            f'holding "ros__parameters:"; blocks found: {found})')
    mine.sort(key=lambda item: not applies_wildcard(item[0]))   # stable: file order kept
    merged: dict[str, Any] = {}
    for block, params in mine:
        flat = flatten_params(params)
        for key, kind in _ROS_PARAMETERS.items():
            if key in flat and not isinstance(flat.pop(key), kind):
                raise ConfigError(f'params file {name}: parameter {key!r} must be a '
                                  f'{kind.__name__}')
        try:
            PlaneNodeConfig.from_ros_params(flat)
        except ConfigError as err:
            raise ConfigError(f'params file {name}, node {_short(repr(block))}: {err}') from err
        merged.update(flat)
    try:
        PlaneNodeConfig.from_ros_params(merged)
    except ConfigError as err:
        raise ConfigError(f'params file {name}: {err}') from err
    return merged


def applies_wildcard(block_name: str) -> bool:
    """Return whether a block's name ends in a wildcard (``/**``, ``/*``)."""
    return block_name.strip('/').rsplit('/', 1)[-1] in _WILDCARDS


def ros_params_files(args: Iterable[str]) -> tuple[list[str], str | None]:
    """Return the ``--params-file`` paths and the ``__node`` remapping of ROS arguments.

    Only arguments inside ``--ros-args`` sections count (up to ``--`` or the next
    ``--ros-args``), as rcl reads them.

    Args:
        args: The command line (``sys.argv``, program name included or not).

    Returns:
        ``(paths, node name or None)``.

    Raises:
        ConfigError: If ``--params-file`` has no path after it.

    """
    paths: list[str] = []
    node: str | None = None
    items = list(args)
    inside = False
    i = 0
    while i < len(items):
        arg = items[i]
        if arg == '--ros-args':
            inside = True
        elif arg == '--':
            inside = False
        elif inside and arg == '--params-file':
            if i + 1 >= len(items) or items[i + 1] in ('--', '--ros-args'):
                raise ConfigError('--params-file needs a file name after it')
            paths.append(items[i + 1])
            i += 1
        elif inside and arg in ('-r', '--remap') and i + 1 < len(items):
            rule = items[i + 1]
            if rule.split(':=', 1)[0].rsplit(':', 1)[-1] == '__node' and ':=' in rule:
                node = rule.split(':=', 1)[1]
            i += 1
        i += 1
    return paths, node


def _where(event: Any) -> str:
    mark = getattr(event, 'start_mark', None)
    return f' (line {mark.line + 1})' if mark is not None else ''


def _one_line(err: BaseException) -> str:
    return _short(' '.join(str(err).split()), 300)


def _short(text: str, limit: int = 80) -> str:
    return clip_text(str(text), limit)


def _kind(value: Any) -> str:
    if value is None:
        return 'null'
    names = {dict: 'mapping', list: 'list', str: 'string'}
    return names.get(type(value), type(value).__name__)


def _size(n_bytes: int) -> str:
    return f'{n_bytes / 1e6:.1f} MB' if n_bytes >= 100_000 else f'{n_bytes} bytes'


__all__ = ['MAX_PARAMS_FILE_BYTES', 'MAX_YAML_DEPTH', 'MAX_YAML_NODES', 'applies_to',
           'load_params_file', 'parameter_blocks', 'read_node_params', 'read_yaml',
           'ros_params_files']


def load_params_file(path: str, node_name: str = 'plane_node') -> PlaneNodeConfig:
    """Read a ROS 2 parameters YAML file through the guarded reader and validate it.

    Accepts ``plane_node: ros__parameters:``, ``/plane_node: ...`` and ``/**: ...`` blocks
    (merged, wildcards first); see the module docstring for every check (size,
    aliases, structure) made before the file is used.

    Args:
        path: Path to the YAML file.
        node_name: The node whose blocks are read.

    Returns:
        The validated configuration.

    Raises:
        ConfigError: If the file cannot be read or parsed, is too large, uses an alias, is
            not shaped as a parameters file, has no block for the node, or holds an invalid
            parameter; the message is one line and names the problem.

    """
    return PlaneNodeConfig.from_ros_params(read_node_params(path, node_name))
