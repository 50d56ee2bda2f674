"""The on-disk cache of rendered frames returns what the renderer renders, or renders again."""

from __future__ import annotations

import dataclasses

from domplane_ros.sim import render_cache
from domplane_ros.sim.model import CameraSetup
from domplane_ros.sim.render import render_stereo
import numpy as np
import pytest

SETUP = CameraSetup(150.0, 0.2, 20.0, 0.0, 160, 120)


def _same(a, b):
    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), field.name
        else:
            assert repr(x) == repr(y), field.name


def _files(folder):
    return sorted(p for p in folder.iterdir() if p.suffix == '.z')


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(render_cache.ENVIRONMENT_VARIABLE, str(tmp_path))
    return tmp_path


def test_a_cached_frame_equals_the_rendered_one_and_is_loaded_not_rendered(cache, monkeypatch):
    rendered = render_stereo(SETUP, floor='tiles', seed=3)
    assert len(_files(cache)) == 1
    first = render_stereo(SETUP, floor='tiles', seed=3)
    _same(rendered, first)
    # A second load gives fresh arrays: a caller that writes into its frame changes no other.
    first.left[:] = 0
    _same(rendered, render_stereo(SETUP, floor='tiles', seed=3))
    # Unset, the renderer renders and writes nothing.
    monkeypatch.delenv(render_cache.ENVIRONMENT_VARIABLE)
    _same(rendered, render_stereo(SETUP, floor='tiles', seed=3))
    assert len(_files(cache)) == 1


def test_other_arguments_or_other_code_are_other_frames(cache, monkeypatch):
    one = render_stereo(SETUP, floor='tiles', seed=3)
    other = render_stereo(SETUP, floor='tiles', seed=3, gain=1.2)
    assert len(_files(cache)) == 2
    assert not np.array_equal(one.right, other.right)
    key = render_cache.cache_key('render_stereo', (SETUP,), {'seed': 3})
    monkeypatch.setattr(render_cache, '_code_version', lambda: b'another simulator')
    assert render_cache.cache_key('render_stereo', (SETUP,), {'seed': 3}) != key


def test_a_damaged_file_is_rendered_again_and_replaced(cache):
    rendered = render_stereo(SETUP, floor='checker', seed=1)
    (path,) = _files(cache)
    path.write_bytes(path.read_bytes()[:100])
    _same(rendered, render_stereo(SETUP, floor='checker', seed=1))
    _same(rendered, render_stereo(SETUP, floor='checker', seed=1))
    assert [p.name for p in cache.iterdir()] == [path.name]  # no temporary file left
