"""A stress set of hard rendered two-layer scenes with exact ground truth.

Nine families (:data:`STRESS_FAMILIES`) of four scenes each, rendered by
:mod:`lss_kernels.scenes` into scene folders (``docs/scene-format.md``): periodic stripes,
camouflage, weak and dark textures, curved backgrounds, wide occlusions, poor starts,
non-elliptic outlines and small jumps.  Geometry is given for the ``"medium"`` size
(320x240) and scaled with the image (disparities, positions, radii); texture scales (stripe
periods, cells) and grey levels are kept in pixels and levels.  ``d_max`` is the true
maximum + 2 rounded up to a multiple of 16; ``init_ellipse`` is a hand-placed ellipse: about
the object's box (radii 0.9-1.05 of it, a few pixels off centre), except in the ``init``
family.  ``meta.json`` also
holds ``family`` and ``description``.

Examples
--------
>>> folders = write_stress_set("DIR", seed=0, size="small")

:func:`random_specs` draws scenes at random over the generator's dimensions instead (no
family: what no one thought to test).

:func:`multi_specs` is a separate family, not in the stress set: whole photos, eight scenes of
4-6 objects at different depths (:func:`lss_kernels.scenes.make_multi_scene`), each with one
clicked object and its click (``init_point``), scored on the band around that object only
(``docs/scene-format.md``).  Its geometry is written for the "photo" size (672x560, d_max
128) and scaled to "medium" (336x280, d_max 64) and "small" (168x140, d_max 32).

:func:`periodic_specs` is another separate set: twelve two-layer scenes where a whole period
is a valid match for either layer (stripes of 3-32 px on both layers, of one period or two,
vertical or at an angle, or on the object over a weak background), periods and angles drawn
per seed.

Command line::

    python -m lss_kernels.stress OUT [--seed S] [--size small|medium|photo]
        [--random N | --multi | --periodic]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .scenes import OUTLINES, check_scene, disparity_coefficients, write_multi_scene, write_scene

__all__ = ["MULTI_FAMILY", "MULTI_SIZES", "SIZES", "STRESS_FAMILIES", "multi_specs",
           "periodic_specs", "random_specs", "stress_specs", "write_stress_set"]

#: What each family tests.
STRESS_FAMILIES = {
    "periodic": "vertical stripes of period 3-8 px on the foreground, the background or both",
    "camouflage": "foreground and background drawn from the same texture statistics or palette",
    "weak": "low-contrast textures of a few grey levels, mid-grey or dark, on fg, bg or both",
    "curved": "sphere-like (quadratic bowl) and cylinder-like backgrounds behind the object",
    "jump": "foreground 40-60 px nearer than the background: wide occlusion strips",
    "init": "hand ellipses covering about half of the object or spilling 30 % beyond it",
    "shape": "non-elliptic outlines: a rectangle, an L and a blob",
    "fine": "small disparity jumps (3-7 px): occlusion strips a few pixels wide",
    "clutter": "surfaces behind the object that one quadratic cannot follow: a floor meeting "
               "a wall, an object standing on the floor, boxes, a shelf's step",
}

#: Image sizes (width, height); the families' geometry is written for "medium".
SIZES = {"small": (160, 120), "medium": (320, 240)}

_OBJECT = (165.0, 120.0, 70.0, 75.0)        # default (cx, cy, rx, ry), medium pixels
_D_MAX_STEP = 16


def _stripes(period, **extra) -> dict:
    """A vertical ``"stripes"`` texture of ``period`` pixels."""
    return {"kind": "stripes", "period": float(period), **extra}


def _weak(amplitude_levels, brightness) -> dict:
    """A ``"low_contrast"`` texture spanning ``amplitude_levels`` 8-bit grey levels."""
    return {"kind": "low_contrast", "amplitude": amplitude_levels / 255, "brightness": brightness}


def _palette(rng, n_colours: int, cell: float) -> dict:
    """A palette texture of ``n_colours`` random colours near one random base colour."""
    base = rng.uniform(0.25, 0.6, 3)
    colours = np.clip(base + rng.uniform(-0.18, 0.18, (n_colours, 3)), 0.05, 0.95)
    return {"kind": "palette", "cells": (cell,), "colours": [list(map(float, c)) for c in colours]}


def _periodic(rng) -> list:
    """The family's scenes as ``(variant, description, parameters in medium pixels)``."""
    return [
        ("fg_p3", "stripes of period 3 on the foreground",
         {"d_fg": 30, "d_bg": 12, "texture_fg": _stripes(3)}),
        ("bg_p6", "stripes of period 6 on the background, slanted foreground",
         {"d_fg": {"d": 28, "slope": (0.04, 0.02)}, "d_bg": 10, "texture_bg": _stripes(6)}),
        ("both_p5_p8", "stripes of period 5 (fg) and 8 (bg)",
         {"d_fg": 34, "d_bg": 14, "texture_fg": _stripes(5), "texture_bg": _stripes(8)}),
        ("both_p7", "stripes of period 7 on both layers, a little noise on the fg",
         {"d_fg": {"d": 32, "slope": (-0.04, 0.0)}, "d_bg": 12,
          "texture_fg": _stripes(7, mix=0.15), "texture_bg": _stripes(7)}),
    ]


def _periodic_hard(rng) -> list:
    """The periodic set (:func:`periodic_specs`): stripes on both layers or on the object
    over a weak background, periods and angles drawn per seed."""
    period = lambda lo, hi: float(rng.uniform(lo, hi))
    angle = float(rng.uniform(20.0, 40.0))
    same = [period(3, 5), period(6, 10), period(12, 20), period(24, 32)]
    weak = _weak(6, 0.45)
    scenes = [(f"same_{name}", f"stripes of one period ({p:.1f} px) on both layers",
               {"texture_fg": _stripes(p), "texture_bg": _stripes(p)})
              for name, p in zip(("fine", "mid", "coarse", "wide"), same)]
    p_fg, p_bg, p_fg2, p_bg2, p_angle = (period(4, 8), period(9, 16), period(16, 24),
                                         period(25, 32), period(6, 12))
    scenes += [
        ("diff", f"stripes of {p_fg:.1f} px (fg) and {p_bg:.1f} px (bg)",
         {"texture_fg": _stripes(p_fg), "texture_bg": _stripes(p_bg)}),
        ("diff_wide", f"stripes of {p_fg2:.1f} px (fg) and {p_bg2:.1f} px (bg)",
         {"texture_fg": _stripes(p_fg2), "texture_bg": _stripes(p_bg2)}),
        ("angle_same", f"stripes of {p_angle:.1f} px at {angle:.0f} degrees on both layers",
         {"texture_fg": _stripes(p_angle, angle=angle),
          "texture_bg": _stripes(p_angle, angle=angle)}),
        ("angle_cross", f"stripes of {p_angle:.1f} px at +-{angle:.0f} degrees (fg, bg)",
         {"texture_fg": _stripes(p_angle, angle=angle),
          "texture_bg": _stripes(p_angle, angle=-angle)}),
        ("slanted_same", f"stripes of {same[1]:.1f} px on both layers, slanted fg and bg",
         {"texture_fg": _stripes(same[1]), "texture_bg": _stripes(same[1]),
          "d_fg": {"d": 30, "slope": (0.05, -0.02)}, "d_bg": {"d": 12, "slope": (-0.03, 0.02)}}),
    ]
    for name, p, a in (("fine", period(3, 6), 0.0), ("coarse", period(10, 20), 0.0),
                       ("angle", p_angle, 45.0)):
        scenes.append((f"fg_{name}_weak_bg", f"stripes of {p:.1f} px at {a:.0f} degrees on "
                       f"the object over a weak background",
                       {"texture_fg": _stripes(p, angle=a), "texture_bg": weak}))
    for _, _, params in scenes:
        params.setdefault("d_fg", float(rng.uniform(26, 36)))
        params.setdefault("d_bg", float(rng.uniform(8, 14)))
    return scenes


def _camouflage(rng) -> list:
    """As :func:`_periodic`; ``rng`` draws the palettes."""
    fine, coarse = _palette(rng, 4, 5.0), _palette(rng, 3, 12.0)
    same = {"kind": "random", "tint": 0.0}
    noisy = {"kind": "random", "tint": 0.0, "cells": (3.0, 8.0)}
    return [
        ("palette_fine", "one 4-colour palette of 5 px blobs on both layers",
         {"d_fg": 30, "d_bg": 12, "texture_fg": fine, "texture_bg": fine}),
        ("palette_coarse", "one 3-colour palette of 12 px blobs on both layers, slanted bg",
         {"d_fg": 36, "d_bg": {"d": 14, "slope": (-0.03, 0.02)}, "texture_fg": coarse,
          "texture_bg": coarse}),
        ("noise_same", "untinted value noise of the same cells on both layers",
         {"d_fg": 26, "d_bg": 12, "texture_fg": same, "texture_bg": same}),
        ("noise_noisy", "untinted value noise of 3 and 8 px cells on both layers, noise 0.02",
         {"d_fg": 30, "d_bg": 10, "texture_fg": noisy, "texture_bg": noisy, "noise": 0.02}),
    ]


def _weak_family(rng) -> list:
    """As :func:`_periodic`."""
    return [
        ("fg_grey", "12 grey levels on a mid-grey foreground",
         {"d_fg": 30, "d_bg": 12, "texture_fg": _weak(12, 0.45)}),
        ("bg_dark", "8 grey levels on a dark background",
         {"d_fg": 30, "d_bg": 10, "texture_bg": _weak(8, 0.10)}),
        ("both_grey", "10 grey levels on both layers, mid-grey",
         {"d_fg": 28, "d_bg": 12, "texture_fg": _weak(10, 0.45), "texture_bg": _weak(10, 0.52)}),
        ("both_dark", "16 grey levels on both layers, dark, 1 level of noise",
         {"d_fg": 32, "d_bg": 12, "texture_fg": _weak(16, 0.08), "texture_bg": _weak(16, 0.11),
          "noise": 1 / 255}),
    ]


def _curved(rng) -> list:
    """As :func:`_periodic`; the curvatures are about the object's centre."""
    return [
        ("bowl", "sphere-like bowl background (26 px at the centre, 5-7 at the corners), flat fg",
         {"d_fg": 44, "d_bg": {"d": 26, "curvature": (-0.0005, 0.0, -0.0005)}}),
        ("cylinder_x", "cylinder background curved along x, slanted fg",
         {"d_fg": {"d": 42, "slope": (0.08, 0.03)},
          "d_bg": {"d": 26, "curvature": (-0.0007, 0.0, 0.0)}}),
        ("ball_dark", "dark weakly textured ball behind the object",
         {"d_fg": 40, "d_bg": {"d": 28, "curvature": (-0.0006, 0.0, -0.0006)},
          "texture_bg": _weak(10, 0.12)}),
        ("cylinder_y", "cylinder background curved along y, flat fg",
         {"d_fg": 38, "d_bg": {"d": 24, "curvature": (0.0, 0.0, -0.0009)}}),
    ]


def _jump(rng) -> list:
    """As :func:`_periodic`; objects right of centre leave room for the occluded strip."""
    return [
        ("40", "foreground 40 px in front of the background",
         {"d_fg": 50, "d_bg": 10, "ellipse": (195.0, 120.0, 60.0, 70.0)}),
        ("50_slanted", "about 50 px in front, both layers slanted",
         {"d_fg": {"d": 62, "slope": (0.05, 0.02)}, "d_bg": {"d": 12, "slope": (-0.03, 0.0)},
          "ellipse": (200.0, 120.0, 60.0, 70.0)}),
        ("60_narrow", "60 px in front, object 90 px wide",
         {"d_fg": 68, "d_bg": 8, "ellipse": (200.0, 120.0, 45.0, 70.0)}),
        ("60_far", "60 px in front of a background at 30 px (d_max 96)",
         {"d_fg": 90, "d_bg": 30, "ellipse": (205.0, 120.0, 60.0, 70.0)}),
    ]


def _init(rng) -> list:
    """As :func:`_periodic`; ``init_shift`` in radii of the object."""
    base = {"d_fg": 32, "d_bg": 12}
    return [
        ("half_inside", "a centred ellipse covering about half of the object",
         {**base, "init_scale": 0.71, "init_shift": (0.0, 0.0)}),
        ("half_side", "an ellipse over the right half of the object",
         {**base, "init_scale": 0.75, "init_shift": (0.5, 0.0)}),
        ("spill30", "an ellipse 30 % larger than the object",
         {**base, "init_scale": 1.3, "init_shift": (0.0, 0.0)}),
        ("spill30_left", "an ellipse spilling 30 % beyond the object's left edge",
         {**base, "init_scale": 1.15, "init_shift": (-0.15, 0.0)}),
    ]


def _shape(rng) -> list:
    """As :func:`_periodic`; ``ellipse`` is the box of the outline."""
    return [
        ("rectangle", "a fronto-parallel rectangle",
         {"d_fg": 30, "d_bg": 10, "outline": "rectangle", "ellipse": (165.0, 120.0, 65.0, 60.0)}),
        ("L", "an L-shaped object",
         {"d_fg": 32, "d_bg": 12, "outline": "L", "ellipse": (165.0, 120.0, 70.0, 75.0)}),
        ("blob", "a lobed blob, slanted",
         {"d_fg": {"d": 32, "slope": (0.05, -0.03)}, "d_bg": 12, "outline": "blob",
          "ellipse": (165.0, 120.0, 85.0, 85.0)}),
        ("L_curved", "an L, slanted, over a cylinder background",
         {"d_fg": {"d": 40, "slope": (-0.04, 0.04)},
          "d_bg": {"d": 24, "curvature": (-0.0006, 0.0, 0.0)}, "outline": "L",
          "ellipse": (170.0, 115.0, 75.0, 70.0)}),
    ]


def _fine(rng) -> list:
    """As :func:`_periodic`."""
    return [
        ("jump3", "foreground 3 px in front of the background",
         {"d_fg": 15, "d_bg": 12}),
        ("jump5_far", "foreground at 8 px over a background at 3 px",
         {"d_fg": 8, "d_bg": 3}),
        ("jump7_slanted", "about 7 px in front, both layers slanted",
         {"d_fg": {"d": 20, "slope": (0.03, 0.01)}, "d_bg": {"d": 13, "slope": (-0.02, 0.01)}}),
        ("thin", "a thin object (28 px wide) 6 px in front",
         {"d_fg": 18, "d_bg": 12, "ellipse": (165.0, 120.0, 14.0, 90.0)}),
    ]


def _floor(d_wall: float, y_meet: float, slope: float, cy: float) -> dict:
    """A floor as a whole-plane prop: its disparity rises by ``slope`` per row below the row
    ``y_meet``, where it meets a wall at ``d_wall``; given about the object's centre row
    ``cy`` (medium pixels)."""
    return {"d": {"d": d_wall + slope * (cy - y_meet), "slope": (0.0, slope)}, "box": None}


def _clutter(rng) -> list:
    """As :func:`_periodic`; ``props`` in medium pixels (:func:`_placed` scales them)."""
    return [
        ("floor_wall", "a floor rising from 10 to 22 px meets a wall at 10 px across the "
                       "object's lower half; the object floats at 34 px",
         {"d_fg": 34, "d_bg": 10, "props": [_floor(10.0, 140.0, 0.12, 120.0)]}),
        ("standing", "a box standing on a floor that meets the wall at 10 px: 2 px in front "
                     "of the floor where it stands, 18 px in front of the wall at its top",
         {"d_fg": 28.5, "d_bg": 10, "outline": "rectangle", "ellipse": (165.0, 130.0, 45.0, 80.0),
          "props": [_floor(10.0, 100.0, 0.15, 130.0)]}),
        ("boxes", "three boxes at 14-22 px in front of a wall at 8 px, one under the "
                  "object's occlusion strip",
         {"d_fg": 36, "d_bg": 8,
          "props": [{"d": 18, "box": (60.0, 150.0, 30.0, 40.0)},
                    {"d": 22, "box": (265.0, 70.0, 35.0, 30.0)},
                    {"d": 14, "box": (150.0, 218.0, 60.0, 18.0), "outline": "ellipse"}]}),
        ("shelf", "a shelf at 20 px over the left 130 px of a wall at 8 px; the object at "
                  "38 px stands across the shelf's edge",
         {"d_fg": 38, "d_bg": 8, "ellipse": (180.0, 120.0, 70.0, 75.0),
          "props": [{"d": 20, "box": (65.0, 120.0, 65.0, 125.0)}]}),
    ]


_FAMILY_SCENES = {"periodic": _periodic, "camouflage": _camouflage, "weak": _weak_family,
                  "curved": _curved, "jump": _jump, "init": _init, "shape": _shape,
                  "fine": _fine, "clutter": _clutter}


def _layer(value, scale: float, centre) -> tuple:
    """Disparity coefficients of a layer given in medium pixels (a number or a dict of
    ``d``, ``slope``, ``curvature`` about ``centre``), for an image ``scale`` times medium."""
    layer = value if isinstance(value, dict) else {"d": value}
    curvature = tuple(c / scale for c in layer.get("curvature", (0.0, 0.0, 0.0)))
    return disparity_coefficients(layer["d"] * scale, layer.get("slope", (0.0, 0.0)), curvature,
                                  (centre[0] * scale, centre[1] * scale))


def _placed(params: dict, rng, scale: float) -> dict:
    """make_scene keywords from a family's medium-size parameters: the object jittered by a
    few pixels, the layers and the hand ellipse scaled to the image (``init_shift`` is given in
    radii of the object)."""
    params = dict(params)
    cx, cy, rx, ry = params.pop("ellipse", _OBJECT)
    centre = (cx, cy)
    cx, cy = cx + rng.uniform(-6, 6), cy + rng.uniform(-6, 6)
    rx, ry = rx * rng.uniform(0.95, 1.05), ry * rng.uniform(0.95, 1.05)
    hand_scale = rng.uniform(0.9, 1.05)
    hand_shift = (rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05))
    shift = params.pop("init_shift", hand_shift)
    props = [{**prop, "d": _layer(prop["d"], scale, centre),
              "box": None if prop.get("box") is None else tuple(v * scale for v in prop["box"])}
             for prop in params.pop("props", ())]
    if props:
        params["props"] = tuple(props)
    return {**params,
            "d_fg": _layer(params["d_fg"], scale, centre),
            "d_bg": _layer(params["d_bg"], scale, centre),
            "ellipse": (cx * scale, cy * scale, rx * scale, ry * scale),
            "init_scale": float(params.get("init_scale", hand_scale)),
            "init_shift": (shift[0] * rx * scale, shift[1] * ry * scale)}


def stress_specs(seed: int = 0, size: str = "medium") -> list:
    """The stress scenes as ``(name, keywords)``: ``write_scene(folder, None, name=name,
    **keywords)`` renders one.

    Parameters
    ----------
    seed : int
        Seed of the textures, the palettes and the jitter of the objects; equal seeds give
        identical scenes.
    size : str
        A key of :data:`SIZES`.

    Returns
    -------
    list of (str, dict)
        Names ``FAMILY_VARIANT``, family by family in the order of :data:`STRESS_FAMILIES`.
    """
    if size not in SIZES:
        raise ValueError(f"size: unknown {size!r}; valid: {', '.join(SIZES)}")
    width, height = SIZES[size]
    scale = width / SIZES["medium"][0]
    rng = np.random.default_rng(seed)
    specs = []
    for family in STRESS_FAMILIES:
        for variant, description, params in _FAMILY_SCENES[family](rng):
            name = f"{family}_{variant}"
            keywords = _placed(params, rng, scale)
            keywords.update(width=width, height=height, d_max_step=_D_MAX_STEP,
                            seed=int(seed) * 1000 + len(specs),
                            meta={"family": family, "description": description,
                                  "stress_seed": int(seed), "size": size})
            specs.append((name, keywords))
    return specs


def _random_scene(rng, width: int, height: int) -> dict:
    """One draw of :func:`random_specs` (make_scene keywords, maybe not a valid scene)."""
    cx, cy = rng.uniform(0.25, 0.75) * width, rng.uniform(0.3, 0.7) * height
    rx, ry = rng.uniform(0.08, 0.25) * width, rng.uniform(0.12, 0.3) * height
    d_bg = rng.uniform(0.0, 30.0) * width / SIZES["medium"][0]
    d_fg = d_bg + rng.uniform(3.0, 40.0) * width / SIZES["medium"][0]

    def layer(d, steepest):
        if rng.random() < 0.5:
            return d
        return disparity_coefficients(d, tuple(rng.uniform(-steepest, steepest, 2)),
                                      centre=(cx, cy))
    texture = lambda: str(rng.choice(["random", "random", "palette", "low_contrast"]))
    return dict(width=width, height=height, d_fg=layer(d_fg, 0.06), d_bg=layer(d_bg, 0.04),
                ellipse=(cx, cy, rx, ry), outline=str(rng.choice(OUTLINES)),
                texture_fg=texture(), texture_bg=texture(), noise=rng.uniform(0.0, 0.02),
                init_scale=rng.uniform(0.75, 1.1),
                init_shift=(rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0)),
                d_max_step=_D_MAX_STEP)


def random_specs(seed: int = 0, count: int = 24, size: str = "medium") -> list:
    """``count`` scenes drawn at random over the generator's dimensions, as
    ``(name, keywords)`` like :func:`stress_specs`: the object's place, size and outline
    (:data:`~lss_kernels.scenes.OUTLINES`), the background at 0-30 px and the object 3-40 px
    in front (medium pixels), each layer fronto-parallel or slanted, each layer's texture
    (random, palette or dark and low-contrast), noise of sigma 0-0.02 and a hand ellipse of
    radii 0.75-1.1 up to 5 px off centre.  Draws that are not a valid scene are drawn again.
    Names ``random_K``; equal seeds give identical scenes."""
    if size not in SIZES:
        raise ValueError(f"size: unknown {size!r}; valid: {', '.join(SIZES)}")
    rng = np.random.default_rng([int(seed), 1])
    specs = []
    while len(specs) < count:
        keywords = _random_scene(rng, *SIZES[size])
        try:
            check_scene(**keywords)
        except ValueError:
            continue
        keywords.update(seed=int(seed) * 1000 + len(specs),
                        meta={"family": "random", "stress_seed": int(seed), "size": size,
                              "description": "drawn at random (lss_kernels.stress.random_specs)"})
        specs.append((f"random_{len(specs):02d}", keywords))
    return specs


# ------------------------------------------------------------------------------ multi
#: Image sizes (width, height) of the multi-object family (:func:`multi_specs`); its geometry
#: is written for "photo" and scaled with the image.
MULTI_SIZES = {"small": (168, 140), "medium": (336, 280), "photo": (672, 560)}

#: What the multi-object family tests.
MULTI_FAMILY = ("3-6 objects at different depths over slanted or curved walls, shelves and "
                "floors; objects partly in front of the clicked one, thin rods and handles "
                "across it, a neighbour a few pixels behind it, a weakly textured object; "
                "each surface with one of the package's textures")

_MULTI_D_MAX = 128.0                        # photo pixels, scaled with the image
_PHOTO_CENTRE = (336.0, 280.0)
_ROD = 4.0                                  # half-width of rods and handles, photo pixels


def _obj(name: str, d, box, outline: str = "rectangle", angle: float = 0.0, **extra) -> dict:
    """An object of a multi scene in photo pixels: ``d`` as :func:`_layer` (about the box's
    centre), ``box`` ``(cx, cy, rx, ry)`` or None (a whole plane, about the image centre)."""
    return {"name": name, "d": d, "box": box, "outline": outline, "angle": angle, **extra}


def _rod(name: str, d, cx: float, cy: float, half_length: float, angle: float) -> dict:
    """A rod or a handle: a rectangle ``2 * _ROD`` pixels wide turned by ``angle`` degrees."""
    return _obj(name, d, (cx, cy, half_length, _ROD), angle=angle, thin=True)


def _multi_scenes(rng) -> list:
    """The family's scenes as ``(variant, description, parameters in photo pixels)``; the
    parameters hold ``d_bg``, ``objects`` and ``clicked`` (an index in ``objects``)."""
    return [
        ("front_box", "an ellipse at 64 px, its lower left covered by a box at 96 px; a shelf "
                      "at 36 px and a blob at 44 px behind; a slanted wall",
         {"d_bg": {"d": 24, "slope": (-0.02, 0.01)}, "clicked": 1, "objects": [
             _obj("shelf", 36, (150.0, 300.0, 150.0, 200.0)),
             _obj("ellipse", {"d": 64, "slope": (0.03, -0.02)}, (340.0, 260.0, 110.0, 95.0),
                  "ellipse"),
             _obj("front box", 96, (250.0, 385.0, 80.0, 70.0)),
             _obj("blob", 44, (560.0, 170.0, 60.0, 60.0), "blob")]}),
        ("rod", "a blob at 70 px crossed by a rod 8 px wide at 104 px; boxes at 46 and 52 px "
                "behind; a cylinder wall",
         {"d_bg": {"d": 30, "curvature": (-0.00015, 0.0, 0.0)}, "clicked": 0, "objects": [
             _obj("blob", 70, (330.0, 290.0, 120.0, 120.0), "blob"),
             _rod("rod", 104, 340.0, 270.0, 330.0, 25.0),
             _obj("box", 46, (110.0, 430.0, 80.0, 100.0)),
             _obj("ellipse", 52, (570.0, 150.0, 70.0, 60.0), "ellipse")]}),
        ("neighbour", "an ellipse at 72 px; a box 6 px behind it touches it on the left (its "
                      "occlusion strip falls on the box); a floor; an ellipse at 100 px covers "
                      "its lower right",
         {"d_bg": {"d": 20, "slope": (0.02, 0.0)}, "clicked": 2, "objects": [
             _obj("neighbour", 66, (240.0, 300.0, 70.0, 110.0)),
             _obj("floor", {"d": 20 - 0.15 * (420 - 280), "slope": (0.0, 0.15)}, None),
             _obj("ellipse", 72, (380.0, 280.0, 95.0, 120.0), "ellipse"),
             _obj("front ellipse", 100, (460.0, 380.0, 55.0, 70.0), "ellipse")]}),
        ("weak", "an L of 12 grey levels at 60 px, slanted; a bar at 92 px across its top, a "
                 "box at 84 px over its right, a box at 40 px behind",
         {"d_bg": {"d": 26, "slope": (-0.015, 0.02)}, "clicked": 0, "objects": [
             _obj("weak L", {"d": 60, "slope": (0.02, 0.01)}, (320.0, 280.0, 120.0, 110.0), "L",
                  texture={"kind": "low_contrast", "amplitude": 12 / 255,
                           "brightness": 0.45}),
             _obj("box behind", 40, (140.0, 130.0, 90.0, 70.0)),
             _rod("bar", 92, 330.0, 200.0, 90.0, -10.0),
             _obj("front box", 84, (480.0, 370.0, 70.0, 90.0))]}),
        ("curved", "a ball at 76 px on a bowl-shaped wall; a blob at 58 px behind its left, a "
                   "box at 108 px over its lower right, a rod at 96 px across its left, an "
                   "ellipse at 54 px",
         {"d_bg": {"d": 40, "curvature": (-0.0001, 0.0, -0.0001)}, "clicked": 1, "objects": [
             _obj("blob behind", 58, (200.0, 330.0, 90.0, 90.0), "blob"),
             _obj("ball", {"d": 76, "curvature": (-0.0002, 0.0, -0.0002)},
                  (330.0, 260.0, 100.0, 100.0), "ellipse"),
             _obj("front box", 108, (445.0, 345.0, 60.0, 60.0)),
             _rod("rod", 96, 250.0, 280.0, 280.0, 82.0),
             _obj("ellipse", 54, (580.0, 140.0, 55.0, 80.0), "ellipse")]}),
        ("shelves", "a box at 62 px standing on a plank at 48 px, a handle at 80 px across "
                    "it; a floor meets the wall; a box at 44 px and an ellipse at 88 px",
         {"d_bg": 18, "clicked": 2, "objects": [
             _obj("floor", {"d": 18 - 0.16 * (430 - 280), "slope": (0.0, 0.16)}, None),
             _obj("plank", 48, (336.0, 252.0, 336.0, 8.0)),
             _obj("box", 62, (300.0, 170.0, 80.0, 72.0)),
             _rod("handle", 80, 330.0, 170.0, 100.0, 60.0),
             _obj("low box", 44, (470.0, 360.0, 90.0, 60.0)),
             _obj("front ellipse", 88, (120.0, 340.0, 60.0, 50.0), "ellipse")]}),
        ("handle", "an L at 68 px with a bent handle (two rods at 100 px) before it and an "
                   "ellipse 8 px behind it on its right; a box at 38 px",
         {"d_bg": {"d": 22, "slope": (0.0, -0.02)}, "clicked": 0, "objects": [
             _obj("L", 68, (300.0, 290.0, 115.0, 120.0), "L"),
             _obj("neighbour", 60, (470.0, 300.0, 60.0, 110.0), "ellipse"),
             _rod("handle, left", 100, 230.0, 240.0, 70.0, 60.0),
             _rod("handle, top", 100, 330.0, 180.0, 90.0, -15.0),
             _obj("box", 38, (120.0, 450.0, 90.0, 70.0))]}),
        ("stack", "a blob at 74 px covered on the left by a box at 98 px and on the right by "
                  "an ellipse at 90 px, crossed by a rod at 112 px; an ellipse at 54 px "
                  "behind it and a shelf at 40 px; a slanted, curved wall",
         {"d_bg": {"d": 28, "slope": (0.015, 0.01), "curvature": (0.0, 0.0, -0.00008)},
          "clicked": 2, "objects": [
             _obj("shelf", 40, (520.0, 200.0, 150.0, 140.0)),
             _obj("ellipse behind", 54, (330.0, 180.0, 90.0, 70.0), "ellipse"),
             _obj("blob", 74, (340.0, 320.0, 110.0, 110.0), "blob"),
             _obj("front box", 98, (200.0, 365.0, 70.0, 80.0)),
             _obj("front ellipse", 90, (475.0, 400.0, 55.0, 65.0), "ellipse"),
             _rod("rod", 112, 336.0, 280.0, 340.0, -35.0)]}),
    ]


def _multi_texture(rng) -> dict:
    """A texture for a surface without its own, of the package's four kinds equally likely:
    tinted value noise of contrast 0.4-0.8, a palette of 3-5 colours in blobs of 4-12 px,
    10-30 grey levels (weak), or stripes of period 4-10 px turned by up to 30 degrees with
    10-30 % of noise mixed in."""
    kind = int(rng.integers(4))
    if kind == 0:
        contrast = float(rng.uniform(0.4, 0.8))
        return {"kind": "random", "tint": float(rng.uniform(0.1, 0.3)), "contrast": contrast,
                "low": (1.0 - contrast) / 2}
    if kind == 1:
        return _palette(rng, int(rng.integers(3, 6)), float(rng.uniform(4.0, 12.0)))
    if kind == 2:
        return _weak(float(rng.uniform(10.0, 30.0)), float(rng.uniform(0.15, 0.6)))
    return _stripes(rng.uniform(4.0, 10.0), angle=float(rng.uniform(-30.0, 30.0)),
                    mix=float(rng.uniform(0.1, 0.3)))


def _multi_placed(params: dict, rng, scale: float) -> dict:
    """make_multi_scene keywords from a scene's photo-size parameters: every object moved by
    up to 10 px and resized by up to 6 % (rods keep their width), rods turned by up to 5
    degrees, all objects moved by one common 0-3 px in depth, then scaled to the image."""
    shift = rng.uniform(-3.0, 3.0)
    objects = []
    for item in params["objects"]:
        item = dict(item)
        thin = item.pop("thin", False)
        layer = item["d"] if isinstance(item["d"], dict) else {"d": item["d"]}
        layer = {**layer, "d": layer["d"] + shift}
        centre = _PHOTO_CENTRE
        if item["box"] is not None:
            cx, cy, rx, ry = item["box"]
            centre = (cx, cy)
            cx, cy = cx + rng.uniform(-10, 10), cy + rng.uniform(-10, 10)
            rx, ry = rx * rng.uniform(0.94, 1.06), ry * (1.0 if thin else rng.uniform(0.94, 1.06))
            item["box"] = (cx * scale, cy * scale, rx * scale, ry * scale)
        if thin:
            item["angle"] += rng.uniform(-5.0, 5.0)
        item["d"] = _layer(layer, scale, centre)
        if "texture" not in item:
            item["texture"] = _multi_texture(rng)
        objects.append(item)
    return {"d_bg": _layer(params["d_bg"], scale, _PHOTO_CENTRE), "objects": tuple(objects),
            "clicked": params["clicked"], "texture_bg": _multi_texture(rng),
            "noise": float(rng.uniform(2.0, 5.0)) / 255, "d_max": _MULTI_D_MAX * scale}


def multi_specs(seed: int = 0, size: str = "medium") -> list:
    """The multi-object scenes as ``(name, keywords)``: ``write_multi_scene(folder,
    name=name, **keywords)`` renders one (:func:`lss_kernels.scenes.make_multi_scene`).

    Eight scenes of 4-6 objects (:data:`MULTI_FAMILY`), each with a clicked object and its
    click (``init_point``: the pixel deepest inside its part seen by both cameras); noise of
    2-5 grey levels; ``d_max`` 128 at the "photo" size, scaled with the image.

    Parameters
    ----------
    seed : int
        Seed of the placements, the textures and the noise; equal seeds give identical scenes.
    size : str
        A key of :data:`MULTI_SIZES`.

    Returns
    -------
    list of (str, dict)
        Names ``multi_VARIANT``.
    """
    if size not in MULTI_SIZES:
        raise ValueError(f"size: unknown {size!r} for the multi family; valid: "
                         f"{', '.join(MULTI_SIZES)}")
    width, height = MULTI_SIZES[size]
    scale = width / MULTI_SIZES["photo"][0]
    rng = np.random.default_rng([int(seed), 2])
    return _named_specs("multi", _multi_scenes(rng), _multi_placed, rng, seed, size,
                        width=width, height=height, scale=scale)


def _named_specs(family, scenes, place, rng, seed, size, width, height, scale, **extra):
    """``(FAMILY_VARIANT, keywords)`` of a set's scenes, each placed by ``place(params, rng,
    scale)`` and given the image's size, its seed and its meta (``extra``: more keywords)."""
    specs = []
    for variant, description, params in scenes:
        keywords = place(params, rng, scale)
        keywords.update(width=width, height=height, **extra,
                        seed=int(seed) * 1000 + len(specs),
                        meta={"family": family, "description": description,
                              "stress_seed": int(seed), "size": size})
        specs.append((f"{family}_{variant}", keywords))
    return specs


def periodic_specs(seed: int = 0, size: str = "medium") -> list:
    """The periodic set as ``(name, keywords)``, as :func:`stress_specs`: twelve two-layer
    scenes where a whole period is a valid match for either layer, stripes of 3-32 px on both
    layers (one period or two, vertical or at an angle) or on the object over a weak
    background; names ``periodic_VARIANT``."""
    if size not in SIZES:
        raise ValueError(f"size: unknown {size!r}; valid: {', '.join(SIZES)}")
    width, height = SIZES[size]
    scale = width / SIZES["medium"][0]
    rng = np.random.default_rng([int(seed), 3])
    return _named_specs("periodic", _periodic_hard(rng), _placed, rng, seed, size,
                        width=width, height=height, scale=scale, d_max_step=_D_MAX_STEP)


def write_stress_set(out_dir, seed: int = 0, size: str = "medium", random: int = 0,
                     multi: bool = False, periodic: bool = False) -> list:
    """Write every scene of :func:`stress_specs` (or, with ``random`` > 0, of
    :func:`random_specs` with that count; with ``multi``, of :func:`multi_specs`; with
    ``periodic``, of :func:`periodic_specs`) into ``out_dir/NAME``; returns the folders."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"out_dir: {out} exists and is not a folder")
    if sum((bool(random > 0), bool(multi), bool(periodic))) > 1:
        raise ValueError(f"expected one of random, multi and periodic, got random={random}, "
                         f"multi={multi}, periodic={periodic}")
    folders = []
    if multi:
        for name, keywords in multi_specs(seed, size):
            write_multi_scene(out / name, name=name, **keywords)
            folders.append(out / name)
        return folders
    specs = (random_specs(seed, random, size) if random > 0 else
             periodic_specs(seed, size) if periodic else stress_specs(seed, size))
    for name, keywords in specs:
        write_scene(out / name, None, name=name, **keywords)
        folders.append(out / name)
    return folders


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def main(argv=None) -> int:
    """``python -m lss_kernels.stress OUT [--seed S] [--size SIZE] [--random N | --multi |
    --periodic]``."""
    parser = _Parser(prog="python -m lss_kernels.stress",
                     description="Write the stress set of hard rendered two-layer scenes "
                                 "(docs/stress.md) as scene folders under OUT.")
    parser.add_argument("out", metavar="OUT", help="output folder (created if needed)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the set (default 0)")
    parser.add_argument("--size", choices=sorted({*SIZES, *MULTI_SIZES}), default="medium",
                        help="image size: small 160x120, medium 320x240 (default); with "
                             "--multi small 168x140, medium 336x280, photo 672x560")
    parser.add_argument("--random", type=int, default=0, metavar="N",
                        help="N scenes drawn at random instead of the families")
    parser.add_argument("--multi", action="store_true",
                        help="the multi-object family instead (whole photos: one clicked "
                             "object among others, docs/scene-format.md)")
    parser.add_argument("--periodic", action="store_true",
                        help="the periodic set instead: twelve scenes of stripes on both "
                             "layers or on the object over a weak background")
    args = parser.parse_args(argv)
    if args.random < 0:
        parser.error(f"--random: expected a number of scenes >= 0, got {args.random}")
    if sum((bool(args.random), args.multi, args.periodic)) > 1:
        parser.error("--random, --multi and --periodic: one at a time")
    if args.periodic and args.size not in SIZES:
        parser.error(f"--size: the periodic set has {', '.join(SIZES)}, got {args.size}")
    try:
        folders = write_stress_set(args.out, args.seed, args.size, args.random, args.multi,
                                   args.periodic)
    except (ValueError, OSError) as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 1
    kind = ("random" if args.random else "multi-object" if args.multi
            else "periodic" if args.periodic else f"{len(STRESS_FAMILIES)} families")
    print(f"wrote {len(folders)} scenes ({kind}, {args.size}, seed {args.seed}) to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
