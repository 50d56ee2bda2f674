"""Hypothesis strategies of hostile ROS 2 parameters files, invalid by construction.

Shared by the fuzz tests of plane_replay (test/replay) and plane_node (test/ros). Every file
drawn here is invalid for a reason the generator knows, without asking the reader under test:
random structures whose keys cannot be ``ros__parameters`` or a parameter name (they start
with ``z``, no parameter does), wrong-typed or out-of-range values of real parameters, YAML
aliases, deep nesting, files over the size limit and random bytes.
"""

from __future__ import annotations

from pathlib import Path

from domplane_ros.parameters import PARAMETERS
from domplane_ros.params_file import MAX_PARAMS_FILE_BYTES, MAX_YAML_DEPTH
from hypothesis import strategies as st
import yaml

_NAMES = st.text(alphabet='abcdefghijklmnopqrstuvwxyz', min_size=1, max_size=6).map(
    lambda s: 'z' + s)
_SCALARS = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(),
                     st.text(max_size=12))
_VALUES = st.recursive(
    _SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                      st.dictionaries(_NAMES, inner, max_size=4)),
    max_leaves=16)
_NODE_KEYS = st.sampled_from(['plane_node', '/plane_node', '/**', '/robot/plane_node'])
KINDS = ('random document', 'random parameters', 'not a mapping', 'wrong type',
         'out of range', 'aliases', 'deep nesting', 'oversize', 'random bytes')


def _dump(document: object) -> bytes:
    return yaml.safe_dump(document, allow_unicode=True).encode('utf-8')


def _block(key: str, params: object) -> bytes:
    return _dump({key: {'ros__parameters': params}})


@st.composite
def hostile_params_files(draw: st.DrawFn) -> tuple[str, bytes, int]:
    """Draw ``(kind, file contents, size to pad the file to with zero bytes, or 0)``."""
    kind = draw(st.sampled_from(KINDS))
    key = draw(_NODE_KEYS)
    specs = st.sampled_from(PARAMETERS)
    if kind == 'random document':   # no key can be ros__parameters: no block anywhere
        return kind, _dump(draw(st.dictionaries(_NAMES, _VALUES, max_size=5))), 0
    if kind == 'random parameters':   # every name is unknown
        return kind, _block(key, draw(st.dictionaries(_NAMES, _VALUES, min_size=1,
                                                      max_size=5))), 0
    if kind == 'not a mapping':
        params = draw(st.one_of(_SCALARS, st.lists(_VALUES, max_size=4)))
        return kind, draw(st.sampled_from([_dump(params), _block(key, params)])), 0
    if kind == 'wrong type':
        spec = draw(specs)
        wrong = {'bool': st.integers(), 'int': st.text(min_size=1).map(lambda s: 'z' + s),
                 'float': st.sampled_from(['z', 'nan?', 'true']), 'str': st.floats(),
                 'range': st.text(max_size=5), 'floats': st.booleans()}[spec.kind]
        return kind, _block(key, {spec.name: draw(wrong)}), 0
    if kind == 'out of range':
        spec = draw(specs.filter(lambda s: s.kind in ('int', 'float') and s.high is not None))
        excess = draw(st.integers(1, 10**6))
        value = spec.high + excess if spec.kind == 'int' else float(spec.high) * 2 + excess
        return kind, _block(key, {spec.name: value}), 0
    if kind == 'aliases':
        levels, width = draw(st.integers(1, 40)), draw(st.integers(2, 6))
        lines = [f'{key}:', '  ros__parameters:', '    a0: &a0 [1.0, 2.0]']
        lines += [f'    a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * width) + ']'
                  for i in range(1, levels + 1)]
        return kind, ('\n'.join(lines) + '\n').encode(), 0
    if kind == 'deep nesting':
        depth = draw(st.integers(MAX_YAML_DEPTH + 1, 5000))
        opener, closer = draw(st.sampled_from([('[', ']'), ('{a: ', '}')]))
        text = f'{key}:\n  ros__parameters:\n    a: {opener * depth}1{closer * depth}\n'
        return kind, text.encode(), 0
    if kind == 'oversize':
        size = draw(st.integers(MAX_PARAMS_FILE_BYTES + 1, 60_000_000))
        return kind, _block(key, {'estimator.threshold_px': 3.0}), size
    return kind, draw(st.binary(min_size=1, max_size=300)), 0


def write_case(path: Path, case: tuple[str, bytes, int]) -> Path:
    """Write a drawn file (padded, sparse, to its size) and return its path."""
    _, data, size = case
    with open(path, 'wb') as stream:
        stream.write(data)
        if size:
            stream.truncate(size)
    return path


def snapshot(folder: Path) -> dict[str, int]:
    """Return every path under ``folder`` with its size (to show that nothing was written)."""
    return {str(p.relative_to(folder)): p.stat().st_size if p.is_file() else -1
            for p in folder.rglob('*')}
