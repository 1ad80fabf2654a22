"""Textures of the rendered scenes (:mod:`lss_kernels.scenes`): value noise, low-contrast
noise, stripes and palette blobs, each a function of surface (left-view) coordinates, so that
one scene point has one colour in both views.

``make_texture`` builds one from a kind of :data:`TEXTURES` and its parameters.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["TEXTURES", "make_texture"]

#: Texture kinds and their parameters with defaults (``SceneSpec.texture_fg`` / ``texture_bg``:
#: a dict with ``"kind"`` and any of these keys).  Lengths are pixels of surface coordinates,
#: levels are in [0, 1]; ``cells`` None means ``SceneSpec.texture_cells``.
#:
#: - ``random``: value noise stretched to ``[low, low + contrast]``, plus a random colour tint of
#:   amplitude ``tint``.
#: - ``low_contrast``: the same noise spanning ``amplitude`` around ``brightness``.
#: - ``stripes``: ``brightness +- contrast / 2`` (two random colours) modulated by a sinusoid of
#:   ``period`` along the direction ``angle`` (degrees; 0: vertical stripes, varying along x),
#:   random phase; ``mix`` blends in random value noise.
#: - ``palette``: each point takes the colour of ``colours`` whose value-noise channel is the
#:   largest there (blobs of about ``cells``, each colour equally likely).
TEXTURES = {
    "random": {"cells": None, "low": 0.1, "contrast": 0.8, "tint": 0.15},
    "low_contrast": {"cells": None, "brightness": 0.12, "amplitude": 8 / 255, "tint": 0.01},
    "stripes": {"cells": None, "period": 6.0, "angle": 0.0, "brightness": 0.5, "contrast": 0.6,
                "mix": 0.0},
    "palette": {"cells": (6.0,), "colours": ((0.35, 0.38, 0.22), (0.55, 0.5, 0.33),
                                             (0.2, 0.24, 0.16), (0.62, 0.6, 0.52))},
}


def _texture_params(texture, name: str) -> tuple:
    """``(kind, parameters)`` of a layer's texture: the defaults of :data:`TEXTURES` updated
    with ``texture`` (a dict with ``kind``, a kind name, or None: ``"random"``)."""
    if isinstance(texture, str):
        texture = {"kind": texture}
    if texture is not None and not isinstance(texture, dict):
        raise ValueError(f"{name}: expected a dict such as {{'kind': 'stripes', 'period': 5}}, "
                         f"a kind name or None, got {texture!r}")
    given = dict(texture or {})
    kind = given.pop("kind", "random")
    if kind not in TEXTURES:
        raise ValueError(f"{name}: unknown texture kind {kind!r}; valid: {', '.join(TEXTURES)}")
    unknown = sorted(set(given) - set(TEXTURES[kind]))
    if unknown:
        raise ValueError(f"{name}: unknown parameter(s) {', '.join(unknown)} of a {kind!r} "
                         f"texture; valid: kind, {', '.join(TEXTURES[kind])}")
    params = {**TEXTURES[kind], **given}
    if kind == "stripes" and not params["period"] > 0:
        raise ValueError(f"{name}: stripes need a period > 0, got {params['period']}")
    return kind, params


def _octave_sum(rng, cells, x0: float, y0: float, x1: float, y1: float, channels: int = 3):
    """Value noise on the rectangle ``[x0, x1] x [y0, y1]``: for each cell size, uniform random
    values on a grid of that spacing, interpolated bilinearly.  Returns ``lookup(x, y) ->
    (..., channels)``, the sum over the cell sizes (each term in [0, 1])."""
    grids = []
    for cell in cells:
        nx, ny = int(math.ceil((x1 - x0) / cell)) + 2, int(math.ceil((y1 - y0) / cell)) + 2
        grids.append((cell, rng.random((ny, nx, channels))))

    def lookup(x, y):
        total = 0.0
        for cell, grid in grids:
            gx = np.clip((x - x0) / cell, 0.0, grid.shape[1] - 1.000001)
            gy = np.clip((y - y0) / cell, 0.0, grid.shape[0] - 1.000001)
            ix, iy = gx.astype(np.int64), gy.astype(np.int64)
            fx, fy = (gx - ix)[..., None], (gy - iy)[..., None]
            total = total + ((1 - fy) * ((1 - fx) * grid[iy, ix] + fx * grid[iy, ix + 1])
                             + fy * ((1 - fx) * grid[iy + 1, ix] + fx * grid[iy + 1, ix + 1]))
        return total

    return lookup


def make_texture(rng, texture, cells, box: tuple, name: str):
    """A texture of :data:`TEXTURES` on the rectangle ``box = (x0, y0, x1, y1)`` of surface
    coordinates; ``cells``: the default cell sizes.  Returns ``lookup(x, y) -> (..., 3)``
    float64 in [0, 1]."""
    kind, p = _texture_params(texture, name)
    cells = tuple(p["cells"] if p["cells"] is not None else cells)
    if kind == "palette":
        colours = np.asarray(p["colours"], dtype=np.float64)
        noise = _octave_sum(rng, cells, *box, channels=len(colours))
        return lambda x, y: colours[np.argmax(noise(x, y), axis=-1)]
    if kind == "stripes":
        return _stripes(rng, p, cells, box)
    if kind == "low_contrast":
        p = {"low": p["brightness"] - p["amplitude"] / 2, "contrast": p["amplitude"],
             "tint": p["tint"]}
    noise = _octave_sum(rng, cells, *box)
    tint = p["tint"] * (rng.random(3) - 0.5)
    return lambda x, y: np.clip(p["low"] + p["contrast"] * noise(x, y) / len(cells) + tint,
                                0.0, 1.0)


def _stripes(rng, p: dict, cells, box: tuple):
    """The ``"stripes"`` texture of :data:`TEXTURES` (see :func:`make_texture`)."""
    phase = 2 * math.pi * rng.random()
    dark, light = (p["brightness"] + sign * p["contrast"] / 2 + 0.1 * (rng.random(3) - 0.5)
                   for sign in (-1, 1))
    noise = _octave_sum(rng, cells, *box) if p["mix"] > 0 else None
    angle = math.radians(p["angle"])

    def lookup(x, y):
        t = 2 * math.pi * (x * math.cos(angle) + y * math.sin(angle)) / p["period"] + phase
        value = dark + (light - dark) * (0.5 + 0.5 * np.sin(t))[..., None]
        if noise is not None:
            value = (1 - p["mix"]) * value + p["mix"] * (0.1 + 0.8 * noise(x, y) / len(cells))
        return np.clip(value, 0.0, 1.0)

    return lookup
