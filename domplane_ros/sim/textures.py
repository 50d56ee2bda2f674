"""Textures of the rendered scenes: floor kinds, box faces, the wall, and mip-mapped sampling.

Textures are periodic rasters sampled with trilinear mip-mapping (the mip level follows the
footprint of a sample on the surface). Values are in [0, 1]; the renderer maps them to grey
levels. Every raster is seeded by its kind and variant, so a scene's texture is the same in
every render.
"""

from __future__ import annotations

import functools
import math
from typing import Sequence

import cv2
import numpy as np

FLOOR_KINDS = ('random', 'tiles', 'planks', 'checker')
# Low-texture floors: flat albedo with faint noise between contrasting joints, so that almost
# all structure is in straight lines (the joints). Not drawn by ``random_scene(floor=None)``,
# so existing seeds keep their floors; ask for them by name.
PLAIN_FLOOR_KINDS = ('tiles_plain', 'planks_plain')
# Weakly textured tiled floors unlike ``tiles_plain``: tiles of 32, 64 and 256 texels (16 cm,
# 32 cm and 1.28 m at camera height 1), faint joints and a faint mottled surface (see
# :func:`_faint_tiles_texture`). Also asked for by name only.
FAINT_TILE_SIZES = {'tiles_faint_32': 32, 'tiles_faint_64': 64, 'tiles_faint_256': 256}
FAINT_TILE_KINDS = tuple(FAINT_TILE_SIZES)
# The periodic floors with other periods (texels; the defaults are 64 for checker squares and
# tiles, 32 for plank widths): checker squares and tiles of 16 and 64 cm, planks 8 and 32 cm
# wide. Asked for by name only.
SIZED_FLOOR_SIZES = {'checker_32': ('checker', 32), 'checker_128': ('checker', 128),
                     'tiles_32': ('tiles', 32), 'tiles_128': ('tiles', 128),
                     'planks_16': ('planks', 16), 'planks_64': ('planks', 64)}
SIZED_FLOOR_KINDS = tuple(SIZED_FLOOR_SIZES)
ALL_FLOOR_KINDS = FLOOR_KINDS + PLAIN_FLOOR_KINDS + FAINT_TILE_KINDS + SIZED_FLOOR_KINDS

# Texture rasters: size in texels (a power of two, so the mip pyramid halves exactly) and the
# world size of one texel (camera height = 1).
_FLOOR_TEXELS = 2048
FLOOR_TEXEL = 0.005
_BOX_TEXELS = 1024
BOX_TEXEL = 0.004
_WALL_TEXELS = 1024
WALL_TEXEL = 0.02
# Number of distinct texture rasters per kind; render seeds share them modulo this number.
TEXTURE_VARIANTS = 4


def _periodic_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Return (size, size) float32 smooth periodic noise with about ``cells`` blobs per side."""
    cells = max(2, min(cells, size))
    coarse = rng.standard_normal((cells, cells)).astype(np.float32)
    factor = size // cells
    pad = 2
    padded = np.pad(coarse, pad, mode='wrap')
    up = cv2.resize(padded, None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC)
    start = pad * factor
    return up[start:start + size, start:start + size]


def _normalise(values: np.ndarray) -> np.ndarray:
    return (values - values.mean()) / (values.std() + 1e-6)


def _blur_periodic(values: np.ndarray, sigma: float) -> np.ndarray:
    pad = int(math.ceil(3 * sigma)) + 1
    padded = np.pad(values, pad, mode='wrap')
    return cv2.GaussianBlur(padded, (0, 0), sigma)[pad:-pad, pad:-pad]


def _random_texture(rng: np.random.Generator, size: int, octaves: Sequence[tuple[int, float]],
                    sharpness: float, grain: float) -> np.ndarray:
    """Multi-scale blobby texture: a sharpened sum of periodic noise octaves, in [0, 1]."""
    total = np.zeros((size, size), np.float32)
    for cells, amplitude in octaves:
        total += amplitude * _normalise(_periodic_noise(rng, size, cells))
    blobs = 0.5 + 0.42 * np.tanh(sharpness * _normalise(total))
    fine = _normalise(_periodic_noise(rng, size, size // 2))
    return np.clip(blobs + grain * fine, 0.0, 1.0).astype(np.float32)


def _floor_texture(kind: str, variant: int) -> np.ndarray:
    """Return the (N, N) float32 floor raster in [0, 1] (period N * FLOOR_TEXEL)."""
    if kind not in ALL_FLOOR_KINDS:
        raise ValueError(
            f'unknown floor kind {kind!r}; expected one of {", ".join(ALL_FLOOR_KINDS)}')
    rng = np.random.default_rng(1000 + 17 * variant + ALL_FLOOR_KINDS.index(kind))
    n = _FLOOR_TEXELS
    if kind in PLAIN_FLOOR_KINDS:
        return _plain_floor_texture(kind, rng, n)
    if kind in FAINT_TILE_KINDS:
        return _faint_tiles_texture(FAINT_TILE_SIZES[kind], rng, n)
    size = None
    if kind in SIZED_FLOOR_SIZES:
        kind, size = SIZED_FLOOR_SIZES[kind]
    if kind == 'random':
        return _random_texture(rng, n, ((16, 1.0), (64, 0.8), (256, 0.6), (512, 0.35)),
                               sharpness=1.6, grain=0.04)
    weak = 0.012 * _normalise(_periodic_noise(rng, n, n // 8))
    if kind == 'tiles':
        tile = size or 64
        shades = 0.60 + 0.04 * rng.standard_normal((n // tile, n // tile))
        tex = np.kron(shades, np.ones((tile, tile))).astype(np.float32) + weak
        _draw_tile_joints(tex, tile, 0.30)
        return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)
    if kind == 'planks':
        tex = np.empty((n, n), np.float32)
        grain = _blur_periodic(rng.standard_normal((n, n)).astype(np.float32), 1.0)
        grain = _normalise(cv2.blur(np.pad(grain, ((24, 24), (0, 0)), mode='wrap'),
                                    (1, 49))[24:-24])
        _draw_planks(tex, rng, (200, 520), 0.18, shade=(0.45, 0.07), plank=size or 32)
        tex += 0.035 * grain + weak
        return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)
    if kind == 'checker':
        square = size or 64
        idx = (np.arange(n) // square) % 2
        tex = np.where(idx[:, None] ^ idx[None, :], 0.75, 0.25).astype(np.float32) + weak
        return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)
    raise ValueError(f'unknown floor kind {kind!r}; expected one of {", ".join(FLOOR_KINDS)}')


def _plain_floor_texture(kind: str, rng: np.random.Generator, n: int) -> np.ndarray:
    """Return a low-texture floor raster: flat albedo, faint noise, contrasting joints.

    ``tiles_plain``: 0.64 x 0.64 tiles (camera height 1) of one albedo with 2.5 % noise and
    dark 1.5 cm joints, so corners exist only where joints cross. ``planks_plain``: 16 cm wide
    planks, 1.5 to 3.5 m long, of one albedo with faint grain, dark side joints and end joints,
    so corners exist only at the end joints (T-junctions).
    """
    faint = 0.025 * _normalise(_periodic_noise(rng, n, n // 4))
    if kind == 'tiles_plain':
        tex = np.full((n, n), 0.62, np.float32) + faint
        _draw_tile_joints(tex, 128, 0.28)
        return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)
    tex = np.full((n, n), 0.55, np.float32) + faint
    _draw_planks(tex, rng, (300, 700), 0.22)
    return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)


def _faint_tiles_texture(tile: int, rng: np.random.Generator, n: int) -> np.ndarray:
    """Return a weakly textured tiled floor: faint joints on a faintly mottled surface.

    Tiles of ``tile`` texels, each a shade of 0.62 +- 1.5 %, with a low-frequency mottle of
    1.5 % and fine grain of 1 %; the 2-texel joints are light grout (0.52, against
    ``tiles_plain``'s dark 0.28), so the joints give weak edges and corners where they cross.
    """
    shades = 0.62 + 0.015 * rng.standard_normal((n // tile, n // tile))
    tex = np.kron(shades, np.ones((tile, tile))).astype(np.float32)
    tex += 0.015 * _normalise(_periodic_noise(rng, n, 32))
    tex += 0.01 * _normalise(_periodic_noise(rng, n, n // 2))
    on_joint = np.arange(n) % tile < 2
    tex[on_joint, :] = 0.52
    tex[:, on_joint] = 0.52
    return np.clip(_blur_periodic(tex, 0.7), 0.0, 1.0)


def _draw_tile_joints(tex: np.ndarray, tile: int, joint: float) -> None:
    """Draw 3-texel joints of value ``joint`` every ``tile`` texels, both ways, in place."""
    on_joint = np.arange(tex.shape[0]) % tile < 3
    tex[on_joint, :] = joint
    tex[:, on_joint] = joint


def _draw_planks(tex: np.ndarray, rng: np.random.Generator, lengths: tuple[int, int],
                 joint: float, shade: tuple[float, float] | None = None,
                 plank: int = 32) -> None:
    """Lay ``plank``-texel wide planks along the rows of a square raster, in place.

    Each column of planks starts at a random row; planks have a length drawn from
    ``lengths`` (texels), 3-texel end joints and 2-texel side joints of value ``joint``, and,
    if ``shade = (mean, std)`` is given, their own albedo drawn from it.
    """
    n = tex.shape[0]
    for col in range(n // plank):
        cols = slice(col * plank, (col + 1) * plank)
        start = int(rng.integers(0, n))
        pos = 0
        while pos < n:
            length = int(rng.integers(*lengths))
            rows = (np.arange(pos, min(pos + length, n)) + start) % n
            if shade is not None:
                tex[rows, cols] = shade[0] + shade[1] * rng.standard_normal()
            tex[rows[:3], cols] = joint
            pos += length
        tex[:, col * plank:col * plank + 2] = joint


def _box_texture(variant: int) -> np.ndarray:
    """Return the box-face raster: fine speckle with stripes, unlike any floor kind."""
    rng = np.random.default_rng(5000 + variant)
    n = _BOX_TEXELS
    tex = _random_texture(rng, n, ((32, 0.6), (128, 1.0), (256, 0.5)), sharpness=2.5,
                          grain=0.06)
    stripes = 0.5 + 0.5 * np.sin(2 * np.pi * np.arange(n) / 32.0)
    return np.clip(0.75 * tex + 0.25 * stripes[:, None].astype(np.float32), 0, 1)


def _wall_texture(variant: int) -> np.ndarray:
    rng = np.random.default_rng(7000 + variant)
    tex = _random_texture(rng, _WALL_TEXELS, ((8, 1.0), (32, 0.7), (128, 0.4)),
                          sharpness=1.2, grain=0.03)
    return (0.55 + 0.6 * (tex - 0.5)).astype(np.float32)


def _pyramid(texture: np.ndarray) -> tuple[np.ndarray, ...]:
    """Mip pyramid of a periodic raster, down to 1 x 1, each level periodic."""
    levels = [np.ascontiguousarray(texture, dtype=np.float32)]
    while levels[-1].shape[0] > 1:
        pad = 4
        padded = np.pad(levels[-1], pad, mode='wrap')
        levels.append(cv2.pyrDown(padded)[pad // 2:-pad // 2, pad // 2:-pad // 2].copy())
    return tuple(levels)


@functools.lru_cache(maxsize=8)  # ~22 MB per floor pyramid, ~60 ms to rebuild
def texture_pyramid(name: str, variant: int) -> tuple[np.ndarray, ...]:
    """Return the cached mip pyramid of ``'box'``, ``'wall'`` or a floor kind's raster."""
    if name == 'box':
        return _pyramid(_box_texture(variant))
    if name == 'wall':
        return _pyramid(_wall_texture(variant))
    return _pyramid(_floor_texture(name, variant))


def _wrap(values: np.ndarray, size: int) -> np.ndarray:
    """Return ``np.mod(values, size)`` for a power-of-two ``size``, bit for bit, faster.

    The division by ``size`` and the product with it are exact, so the one rounding is that of
    the exact remainder, as in numpy's ``fmod``-based ``mod``.
    """
    return values - np.floor(values * (1.0 / size)) * size


def _remap(level: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear, wrapping lookup of a raster at 1-D texel coordinates (u = column, v = row)."""
    n = u.size
    size = level.shape[0]
    cols = 4096
    rows = -(-n // cols)
    mx = np.empty(rows * cols, np.float32)
    my = np.empty(rows * cols, np.float32)
    mx[:n] = _wrap(u, size)
    my[:n] = _wrap(v, size)
    mx[n:] = 0.0
    my[n:] = 0.0
    out = cv2.remap(level, mx.reshape(rows, cols), my.reshape(rows, cols), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_WRAP)
    return out.reshape(-1)[:n]


def sample(pyramid: tuple[np.ndarray, ...], u: np.ndarray, v: np.ndarray,
           footprint: np.ndarray) -> np.ndarray:
    """Trilinear mip-mapped lookup.

    Args:
        pyramid: Mip levels of a periodic raster.
        u: (N,) float64 column coordinate in level-0 texels.
        v: (N,) float64 row coordinate in level-0 texels.
        footprint: (N,) float64 size of the sample on the surface, in level-0 texels.

    Returns:
        (N,) float32 texture values.

    """
    top = len(pyramid) - 1
    level = np.clip(np.log2(np.maximum(footprint, 1e-6)), 0.0, top)
    base = np.minimum(np.floor(level).astype(np.int64), top)
    frac = (level - base).astype(np.float32)
    out = np.empty(u.shape, np.float32)
    if not base.size:
        return out
    # The samples grouped by mip level (a stable radix sort of small integers), so that each
    # level gathers its own samples instead of scanning all of them (the same values: each
    # sample's lookup depends on its own coordinates only).
    order = np.argsort(base.astype(np.uint8), kind='stable')
    ends = np.cumsum(np.bincount(base, minlength=top + 1))
    for lev in range(top + 1):
        sel = order[ends[lev - 1] if lev else 0:ends[lev]]
        if not sel.size:
            continue
        u_lev, v_lev = u[sel], v[sel]
        values = []
        for k in (lev, min(lev + 1, top)):
            scale = 0.5 ** k
            values.append(_remap(pyramid[k], (u_lev + 0.5) * scale - 0.5,
                                 (v_lev + 0.5) * scale - 0.5))
        out[sel] = values[0] + (values[1] - values[0]) * frac[sel]
    return out
