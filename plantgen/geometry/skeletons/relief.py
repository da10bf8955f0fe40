"""Procedural relief height maps per material, and the one sampler every renderer matches.

A height map is an (H, W) uint8 array: row j covers v in [j/H, (j+1)/H), column i covers
u in [i/W, (i+1)/W); texel (j, i) has its centre at (u, v) = ((i + 0.5)/W, (j + 0.5)/H).
Height w = value / 255 in [0, 1]: 0 on the inner cone, 1 at the relief's full depth, the
shell times r(y)/max(r1, r2) (:func:`plantgen.geometry.skeletons.frusta.relief_scale`; §3).

The last row repeats the first (the pattern's period spans rows 0 to H - 1), so with v
clamped a segment's top (v = 1) and its continuing neighbour's bottom (v = 0) read the same
heights: the relief and the bark's colour meet in phase at every joint.

Sampling (:func:`sample_height`) is bilinear, *repeat* in u and *clamp to edge* in v,
exactly GL_LINEAR with GL_REPEAT (s) and GL_CLAMP_TO_EDGE (t) on a texture uploaded with
row j at t = (j + 0.5)/H::

    x = u·W - 0.5;  i0 = floor(x);  fx = x - i0;  columns i0 mod W and (i0 + 1) mod W
    y = v·H - 0.5;  j0 = floor(y);  fy = y - j0;  rows clip(j0, 0, H-1), clip(j0 + 1, 0, H-1)
    w = lerp(lerp(T[j0,i0], T[j0,i1], fx), lerp(T[j1,i0], T[j1,i1], fx), fy) / 255

(GPUs quantise the weights fx, fy to 8 bits: expect differences up to ~1/256 of a
texel step.) Maps are deterministic: the same name always gives the same bytes.

Materials: ``bark`` (furrows running along v), ``cactus`` (saguaro ribs along the axis),
``stone`` (blocks with mortar joints, for the well), ``aloe`` (fine grain), ``leaf`` (flat,
all zero). Any other name gets the bark map and bark's shell thickness (documented
fallback: unknown materials look like bark rather than vanish).

Shell thickness (:data:`DEFAULT_SHELL`) is a fraction of the radius: the relief is that
fraction of r(y) deep at every height (the convention of
:func:`plantgen.geometry.skeletons.skin.skin_skeleton`'s ``shell`` argument), as deep on both sides
of a joint.
"""

from __future__ import annotations

import zlib
from functools import lru_cache

import numpy as np

from ...tolerances import tol

__all__ = ["MATERIALS", "DEFAULT_SHELL", "REPEATS", "height_map", "height_maps",
           "sample_height", "default_shell"]

MATERIALS = ("bark", "cactus", "stone", "aloe", "leaf")

#: Relief depth per material, as a fraction of the radius (at every height of a segment).
DEFAULT_SHELL = {"bark": 0.15, "cactus": 0.12, "stone": 0.10, "aloe": 0.05, "leaf": 0.0}

#: Texture repeats (around u, along v per segment) per material; all 1: (u, v) of the
#: frusta index the map directly (mesh, ray caster and reference agree on this).
REPEATS = dict.fromkeys(MATERIALS, (1.0, 1.0))


def default_shell(name: str) -> float:
    """Shell fraction for ``name``; unknown names fall back to bark's."""
    return DEFAULT_SHELL.get(name, DEFAULT_SHELL["bark"])


def _periodic_noise(rng, shape, cutoff):
    """(H, W) float noise in [0, 1], periodic in both axes, low-passed to ``cutoff``
    (cycles per image, per axis (cv, cu))."""
    h, w = shape
    white = rng.standard_normal(shape)
    fy = np.fft.fftfreq(h)[:, None] * h
    fx = np.fft.fftfreq(w)[None, :] * w
    filt = np.exp(-0.5 * ((fy / cutoff[0]) ** 2 + (fx / cutoff[1]) ** 2))
    out = np.real(np.fft.ifft2(np.fft.fft2(white) * filt))
    out -= out.min()
    return out / max(out.max(), tol.tiny)


def _bark(rng, shape):
    h, w = shape
    u = (np.arange(w) + 0.5) / w
    grooves = _periodic_noise(rng, shape, (3.0, 14.0))           # long along v, narrow in u
    ridges = 0.5 + 0.5 * np.cos(2 * np.pi * 9 * u + 2.5 * grooves)
    fine = _periodic_noise(rng, shape, (24.0, 24.0))
    return 0.15 + 0.6 * ridges ** 0.7 + 0.25 * fine


def _cactus(rng, shape):
    h, w = shape
    u = (np.arange(w) + 0.5) / w
    ribs = np.abs(np.cos(np.pi * 12 * u))[None, :] ** 0.6        # 12 ribs, constant along v
    spines = _periodic_noise(rng, shape, (40.0, 40.0))
    return np.broadcast_to(0.1 + 0.8 * ribs, shape) + 0.1 * spines


def _stone(rng, shape):
    h, w = shape
    rows, cols = 8, 12
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    row = np.floor(v * rows).astype(int)
    shift = (row % 2) * 0.5
    fu = (u[None, :] * cols + shift[:, None]) % 1.0
    fv = (v * rows % 1.0)[:, None]
    mortar = np.minimum(np.minimum(fu, 1 - fu) * 2, np.minimum(fv, 1 - fv)[:, :1] * 2 * np.ones((1, w)))
    block = np.clip(mortar * 6.0, 0.0, 1.0)
    rough = _periodic_noise(rng, shape, (16.0, 16.0))
    return 0.05 + 0.75 * block + 0.2 * rough * block


def _aloe(rng, shape):
    return 0.3 + 0.4 * _periodic_noise(rng, shape, (48.0, 20.0))


def _leaf(rng, shape):
    return np.zeros(shape)


_GENERATORS = {"bark": _bark, "cactus": _cactus, "stone": _stone, "aloe": _aloe, "leaf": _leaf}


@lru_cache(maxsize=64)
def _cached(name: str, size: tuple[int, int]) -> np.ndarray:
    key = name if name in _GENERATORS else "bark"
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    h, w = size
    # One period of the (periodic) pattern over rows 0..H-2, and row H-1 a copy of row 0: v
    # clamps to the edge rows, so a row's v = 1 and its continuing neighbour's v = 0 read
    # the same heights and the relief meets in phase across every joint.
    field = _GENERATORS[key](rng, (h - 1, w)) if h > 1 else _GENERATORS[key](rng, size)
    if h > 1:
        field = np.concatenate([field, field[:1]], axis=0)
    out = np.clip(np.rint(np.clip(field, 0.0, 1.0) * 255.0), 0, 255).astype(np.uint8)
    out.setflags(write=False)
    return out


def height_map(material_name: str, size=(256, 256)) -> np.ndarray:
    """(H, W) uint8 height map of ``material_name`` (rows: v, columns: u); see module doc."""
    h, w = int(size[0]), int(size[1])
    if h <= 0 or w <= 0:
        raise ValueError(f"height map size must be positive, got {size}")
    return _cached(str(material_name), (h, w))


def height_maps(material_names, size=(256, 256)) -> tuple[np.ndarray, np.ndarray]:
    """(n, H, W) uint8 maps, one layer per material slot, and (n, 2) float repeats."""
    names = list(material_names) or ["bark"]
    maps = np.stack([height_map(n, size) for n in names])
    repeats = np.array([REPEATS.get(n, (1.0, 1.0)) for n in names], dtype=np.float64)
    return maps, repeats


def sample_height(hmap: np.ndarray, u, v) -> np.ndarray:
    """Bilinear height in [0, 1] at texture coordinates ``u``, ``v`` (any equal shapes):
    repeat in u, clamp to edge in v, texel centres at (i + 0.5)/W (see module doc)."""
    t = np.asarray(hmap)
    h, w = t.shape
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    x = u * w - 0.5
    y = v * h - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx, fy = x - x0, y - y0
    i0 = np.mod(x0, w).astype(np.int64)
    i1 = np.mod(i0 + 1, w)
    j0 = np.clip(y0, 0, h - 1).astype(np.int64)
    j1 = np.clip(y0 + 1, 0, h - 1).astype(np.int64)
    tf = t.astype(np.float64)
    top = tf[j0, i0] * (1 - fx) + tf[j0, i1] * fx
    bot = tf[j1, i0] * (1 - fx) + tf[j1, i1] * fx
    return (top * (1 - fy) + bot * fy) / 255.0
