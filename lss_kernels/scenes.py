"""Synthetic stereo scenes with exact ground truth: two layers, or several objects.

A textured foreground surface with an elliptic (or rectangular, L-shaped, blob) outline floats
in front of a textured background surface.  Each surface ``S`` is a disparity function quadratic
in the LEFT-view pixel coordinates, ``d_S(x, y) = Theta_S . U(x, y)`` with the paper's basis
``U = (x^2, xy, y^2, x, y, 1)`` (Sec. 2; 0-based pixels, x to the right, y down), and a scene
point is named by the left-view coordinates ``(x, y)`` of its ray.  Its right-view position is
``x - d_S(x, y)`` (same row), and its colour is a texture sampled at ``(x, y)``, so one scene point
has one colour in both views.

Both views are ray cast per pixel, with a z-buffer: the left pixel ``(x, y)`` sees the nearest
surface (larger disparity) that holds ``(x, y)`` (the foreground inside its ellipse); the right
pixel ``(xr, y)`` finds, on each surface, the point that projects to it (the root of the
quadratic ``x - d_S(x, y) = xr``) and keeps the nearest.  The ground truth is therefore exact
for the rendered images: ``disp_left`` is ``d_S`` at the pixel centres, and a left pixel is
occluded (``occ_left``) when its point is not seen by the right camera: it projects outside
the right image (``xr < -0.5``) or a nearer surface covers its right-view ray.

Textures, one per layer (:mod:`lss_kernels.textures`): value noise (the default), low-contrast
noise, stripes, and palette blobs (camouflage, when both layers share the palette).

``SceneSpec.props`` adds surfaces behind the object (boxes, a floor meeting the wall, a shelf):
each view shows the nearest surface on each ray, and the ground truth counts them as background.

:func:`make_multi_scene` renders several objects at different depths instead (whole photos):
the same ray cast over a list of surfaces, any of them in front of the clicked object, with
outlines that may turn (a thin turned rectangle is a rod or a handle); it also gives the
index of the surface each left pixel sees (``layers_left``), a click on the object
(``init_point``) and the band of that object alone (:func:`object_band`).

Presets (:data:`PRESETS`): ``"easy"`` (128x96, fronto-parallel layers at 24 and 8 px),
``"slanted"`` (128x96, curved slanted foreground over a slanted background) and ``"tiny"``
(64x48, layers at 12 and 4 px, for quick tests).

Examples
--------
>>> scene = make_scene("tiny", seed=1)
>>> scene = make_scene("easy", noise=0.02, d_fg=disparity_coefficients(20.0, slope=(0.05, 0)))
>>> scene = make_multi_scene(width=128, height=96, d_bg=6.0, clicked=0, objects=[
...     {"d": 20.0, "box": (64.0, 48.0, 24.0, 20.0), "outline": "ellipse"},
...     {"d": 28.0, "box": (64.0, 48.0, 70.0, 2.5), "angle": -20.0}])     # a rod before it
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from .io import Scene, save_scene
from .model.quadratic import evaluate
from .metrics import BAND_RADIUS, _dilate_rows, band_from_foreground, boundary_from_foreground
from .textures import TEXTURES, make_texture

__all__ = ["OUTLINES", "PRESETS", "TEXTURES", "MultiSpec", "SceneSpec", "check_scene",
           "disparity_coefficients", "make_multi_scene", "make_scene", "object_band",
           "write_multi_scene", "write_scene"]

#: Foreground outlines, each inside the box ``cx +- rx``, ``cy +- ry`` of ``SceneSpec.ellipse``:
#: the ellipse; the box; the box without its top-right corner ``(x > cx - 0.1 rx,
#: y < cy + 0.1 ry)``, an L; a fixed lobed blob.
OUTLINES = ("ellipse", "rectangle", "L", "blob")


def disparity_coefficients(d_centre: float, slope=(0.0, 0.0), curvature=(0.0, 0.0, 0.0),
                           centre=(0.0, 0.0)) -> tuple:
    """Coefficients on ``U = (x^2, xy, y^2, x, y, 1)`` of a disparity given about a centre.

    ``d(x, y) = d_centre + gx u + gy v + cxx u^2 + cxy u v + cyy v^2`` with
    ``(u, v) = (x - cx, y - cy)``, in left-view pixels.

    Parameters
    ----------
    d_centre : float
        Disparity at ``centre``.
    slope : (float, float)
        ``(gx, gy)``: disparity change per pixel along x and y.
    curvature : (float, float, float)
        ``(cxx, cxy, cyy)``.
    centre : (float, float)
        ``(cx, cy)`` in left-view pixels.

    Returns
    -------
    tuple of 6 float
    """
    (gx, gy), (cxx, cxy, cyy), (cx, cy) = slope, curvature, centre
    return (float(cxx), float(cxy), float(cyy),
            float(gx - 2 * cxx * cx - cxy * cy),
            float(gy - 2 * cyy * cy - cxy * cx),
            float(d_centre - gx * cx - gy * cy + cxx * cx * cx + cxy * cx * cy + cyy * cy * cy))


@dataclass(frozen=True)
class SceneSpec:
    """Parameters of a rendered scene (defaults: the ``"easy"`` preset).

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    d_fg, d_bg : float or tuple of 6 float
        Foreground / background disparity (left-view pixels): a constant (fronto-parallel) or
        the coefficients on ``U = (x^2, xy, y^2, x, y, 1)`` of left-view pixel coordinates (see
        :func:`disparity_coefficients`).
    ellipse : tuple of 4 float or None
        Foreground ellipse ``(cx, cy, rx, ry)`` in left-view pixels, or the box of another
        ``outline``; None: centred, radii a quarter of the width and 0.29 of the height.
    texture_cells : tuple of float
        Cell sizes (pixels) of the value-noise octaves of the textures, averaged.
    noise : float
        Standard deviation of the Gaussian noise added to each image, in [0, 1] units.
    quantize : bool
        Round the images to 8-bit levels (so that they survive a PNG round trip exactly).
    init_scale : float
        Radii of ``init_ellipse`` relative to the true ellipse.
    init_shift : (float, float)
        Shift of the ``init_ellipse`` centre from the true one, in pixels.
    band_radius : int
        Half-width of the evaluation band (``roi_fg`` / ``roi_bg``).
    texture_fg, texture_bg : dict, str or None
        Texture of each layer: ``{"kind": ..., **parameters}`` (:data:`TEXTURES`), or a kind
        name with its default parameters; None: ``"random"``.
    outline : str
        Shape of the foreground (:data:`OUTLINES`) in the box of ``ellipse``.
    d_max_step : int
        ``d_max`` is rounded up to a multiple of this.
    props : tuple of dict
        Further surfaces behind the object, which the ground truth counts as background
        (clutter, a floor, a shelf): each a dict with ``d`` (as ``d_bg``), ``box`` (``(cx, cy,
        rx, ry)`` of its ``outline``, default ``"rectangle"``; None or absent: the whole plane,
        seen where it is nearer than the rest, e.g. a floor that meets the wall),
        ``texture`` (as ``texture_bg``), and ``angle`` and ``name`` as in
        ``MultiSpec.objects``.  Both views show the nearest surface on each ray;
        inside the object's outline every prop must lie behind the object.
    """

    width: int = 128
    height: int = 96
    d_fg: float | tuple = 24.0
    d_bg: float | tuple = 8.0
    ellipse: tuple | None = None
    texture_cells: tuple = (2.0, 5.0)
    noise: float = 0.0
    quantize: bool = True
    init_scale: float = 0.7
    init_shift: tuple = (4.0, -3.0)
    band_radius: int = BAND_RADIUS
    texture_fg: dict | str | None = None
    texture_bg: dict | str | None = None
    outline: str = "ellipse"
    d_max_step: int = 2
    props: tuple = ()


@dataclass(frozen=True)
class MultiSpec:
    """Parameters of a rendered scene of several objects (:func:`make_multi_scene`).

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    d_bg : float or tuple of 6 float
        The background (a wall, slanted or curved), as ``SceneSpec.d_bg``: seen wherever no
        object is nearer.
    texture_bg : dict, str or None
        Its texture, as ``SceneSpec.texture_bg``.
    objects : tuple of dict
        The surfaces before the background, at any depths and in any order: each a dict with
        ``d`` (as ``d_bg``), ``box`` (``(cx, cy, rx, ry)`` of its ``outline``, default
        ``"rectangle"``; None or absent: the whole plane, seen where it is nearer than the
        rest, e.g. a floor), ``angle`` (degrees the outline turns about the box's centre, from
        the x axis toward the y axis; a thin turned rectangle is a rod), ``texture`` (as
        ``texture_bg``) and ``name``.  Layer ``k + 1`` is ``objects[k]``; layer 0 is the
        background.
    clicked : int
        Index in ``objects`` of the object to segment: ``fg_left`` and the evaluation band
        are its own.
    init_point : (float, float) or None
        The click ``(x, y)``, on a visible pixel of the clicked object; None: the pixel
        deepest inside its part seen by both cameras (:func:`_deepest_pixel`).
    d_max : float or None
        The search range; None: the smallest multiple of ``d_max_step`` >= max(disp_left) + 2.
        A given one must be at least max(disp_left) + 2.
    texture_cells, noise, quantize, band_radius, d_max_step
        As in :class:`SceneSpec`.
    """

    width: int = 336
    height: int = 280
    d_bg: float | tuple = 8.0
    texture_bg: dict | str | None = None
    objects: tuple = ()
    clicked: int = 0
    init_point: tuple | None = None
    d_max: float | None = None
    texture_cells: tuple = (2.0, 5.0)
    noise: float = 0.0
    quantize: bool = True
    band_radius: int = BAND_RADIUS
    d_max_step: int = 2


#: Named scenes: keyword overrides of :class:`SceneSpec`.
PRESETS = {
    "easy": {},
    "slanted": {
        "d_fg": disparity_coefficients(22.0, slope=(0.06, 0.04),
                                       curvature=(-0.0015, 0.0, -0.001), centre=(64.0, 48.0)),
        "d_bg": disparity_coefficients(8.0, slope=(-0.03, 0.03), centre=(64.0, 48.0)),
        "noise": 0.01,
    },
    "tiny": {"width": 64, "height": 48, "d_fg": 12.0, "d_bg": 4.0},
}


def _theta(d, name: str) -> np.ndarray:
    """Six float64 coefficients on U from a constant or a 6-sequence."""
    theta = np.zeros(6) if np.ndim(d) == 0 else np.asarray(d, dtype=np.float64).ravel()
    if np.ndim(d) == 0:
        theta[5] = float(d)
    if theta.shape != (6,) or not np.isfinite(theta).all():
        raise ValueError(f"{name}: expected a number or 6 finite coefficients on "
                         f"(x^2, xy, y^2, x, y, 1), got {d!r}")
    return theta


def _source_x(theta: np.ndarray, xr, y):
    """Left-view x of the surface point seen at right-view ``(xr, y)``: ``x - d(x, y) = xr``.

    The root of ``-a x^2 + B x - C = 0`` (``B = 1 - b y - e``, ``C = c y^2 + f y + g + xr``)
    that continues the linear solution ``C / B`` (stable for ``a -> 0``); NaN where the ray
    misses the surface.
    """
    a, b, c, e, f, g = theta
    big_b = 1.0 - b * y - e
    big_c = c * y * y + f * y + g + xr
    with np.errstate(invalid="ignore", divide="ignore"):
        return 2.0 * big_c / (big_b + np.sqrt(big_b * big_b - 4.0 * a * big_c))


def _inside(ellipse, x, y, outline: str = "ellipse", angle: float = 0.0):
    """Whether the left-view points ``(x, y)`` lie inside an outline (NaN: outside): its box
    ``ellipse = (cx, cy, rx, ry)`` turned by ``angle`` degrees about its centre, from the
    x axis toward the y axis (0: axis-aligned, and then ``(u, v)`` are exactly the unturned
    ones)."""
    cx, cy, rx, ry = ellipse
    cos, sin = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    u = (cos * (x - cx) + sin * (y - cy)) / rx
    v = (cos * (y - cy) - sin * (x - cx)) / ry
    if outline == "ellipse":
        return u ** 2 + v ** 2 <= 1.0
    box = (np.abs(u) <= 1.0) & (np.abs(v) <= 1.0)
    if outline == "rectangle":
        return box
    if outline == "L":
        return box & ~((u > -0.1) & (v < 0.1))
    angle = np.arctan2(v, u)
    return np.hypot(u, v) <= (1.0 + 0.2 * np.cos(3 * angle + 0.7)
                              + 0.1 * np.cos(5 * angle + 2.0)) / 1.3


def _check_image(spec) -> None:
    """The checks of a :class:`SceneSpec` or :class:`MultiSpec` that do not depend on its
    surfaces: the size, ``d_max_step`` and ``noise``."""
    if spec.width < 8 or spec.height < 8:
        raise ValueError(f"width, height: expected at least 8 pixels, got {spec.width}x{spec.height}")
    if int(spec.d_max_step) != spec.d_max_step or spec.d_max_step < 1:
        raise ValueError(f"d_max_step: expected a positive integer, got {spec.d_max_step}")
    if not 0.0 <= spec.noise <= 1.0:
        raise ValueError(f"noise: expected a standard deviation in [0, 1], got {spec.noise}")


def _check_surfaces(surfaces: list, names: list, width: int, height: int, pad: int) -> None:
    """Each surface must have a disparity >= 0 in the image (a whole plane other than the
    background only where it is seen, that is nearer than the rest) and must not fold in the
    right view: ``d/dx < 0.9`` over the rendered domain (``pad`` columns either side)."""
    y, x = np.mgrid[0:height, -pad:width + pad].astype(np.float64)
    for i, (surface, name) in enumerate(zip(surfaces, names)):
        d = evaluate(surface.theta, x, y)
        dx = 2 * surface.theta[0] * x + surface.theta[1] * y + surface.theta[3]
        if (i == 0 or surface.box is not None) and d[:, pad:-pad].min() < 0:
            raise ValueError(f"{name}: disparity must be >= 0 in the image, min is "
                             f"{d[:, pad:-pad].min():.3g}")
        if dx.max() >= 0.9:
            raise ValueError(f"{name}: d/dx must stay below 0.9 (the surface must not fold in "
                             f"the right view), max is {dx.max():.3g}")


def _check(spec: SceneSpec, surfaces: list, ellipse, pad: int) -> None:
    """The scene must be a valid two-layer scene on the rendered domain: ``surfaces`` are
    the background, the props and the object (:func:`_geometry`)."""
    _check_image(spec)
    if ellipse[2] <= 0 or ellipse[3] <= 0:
        raise ValueError(f"ellipse: expected radii > 0, got {ellipse}")
    if spec.outline not in OUTLINES:
        raise ValueError(f"outline: unknown {spec.outline!r}; valid: {', '.join(OUTLINES)}")
    names = ["d_bg", *(f"props[{i}]: d" for i in range(len(spec.props))), "d_fg"]
    _check_surfaces(surfaces, names, spec.width, spec.height, pad)
    y, x = np.mgrid[0:spec.height, 0:spec.width].astype(np.float64)
    inside = _inside(ellipse, x, y, spec.outline)
    if not inside.any():
        raise ValueError(f"ellipse: {ellipse} covers no pixel of the {spec.width}x{spec.height} image")
    d_fg = evaluate(surfaces[-1].theta, x, y)
    for surface, name in zip(surfaces[:-1], names):
        behind = ~surface.covers(x, y) | (evaluate(surface.theta, x, y) < d_fg)
        if not behind[inside].all():
            what = "background" if name == "d_bg" else f"prop ({name[:-3]})"
            raise ValueError(f"d_fg, {name}: the foreground must be in front of the {what} "
                             f"(larger disparity) everywhere inside the outline")
    # nor may a prop beside the object hide it from the right camera (a third layer)
    xr = np.where(inside, x - d_fg, np.nan)
    seen, _, _ = _nearest(surfaces, y, lambda surface: _source_x(surface.theta, xr, y))
    hidden = inside & (seen > 0) & (seen < len(surfaces) - 1)
    if hidden.any():
        i = int(seen[hidden][0]) - 1
        raise ValueError(f"props[{i}]: nearer than the object on its right-view rays, it hides "
                         f"{int(hidden.sum())} of its pixels from the right camera; put it "
                         f"behind the object or away from its rows")


@dataclass(frozen=True)
class _Surface:
    """A rendered surface: disparity coefficients on U, and the outline that bounds it in
    surface (left-view) coordinates (``box`` None: the whole plane), turned by ``angle``
    degrees about the box's centre."""

    theta: np.ndarray
    box: tuple | None = None
    outline: str = "rectangle"
    angle: float = 0.0

    def covers(self, x, y):
        """Whether the surface holds the points ``(x, y)`` (NaN: a ray that misses it)."""
        return np.isfinite(x) if self.box is None else _inside(self.box, x, y, self.outline,
                                                               self.angle)


_SURFACE_KEYS = ("d", "box", "outline", "angle", "texture", "name")


def _surfaces(items, what: str) -> list:
    """The :class:`_Surface` of each dict of ``items`` (``SceneSpec.props`` or
    ``MultiSpec.objects``, named ``what`` in errors), checked."""
    surfaces = []
    for i, item in enumerate(items):
        name = f"{what}[{i}]"
        if not isinstance(item, dict) or "d" not in item:
            raise ValueError(f"{name}: expected a dict with 'd' and any of "
                             f"{', '.join(repr(k) for k in _SURFACE_KEYS[1:])}, got {item!r}")
        unknown = sorted(set(item) - set(_SURFACE_KEYS))
        if unknown:
            raise ValueError(f"{name}: unknown key(s) {', '.join(unknown)}; valid: "
                             f"{', '.join(_SURFACE_KEYS)}")
        box = item.get("box")
        if box is not None:
            box = tuple(float(v) for v in box)
            if len(box) != 4 or not box[2] > 0 or not box[3] > 0:
                raise ValueError(f"{name}: box: expected (cx, cy, rx, ry) with radii > 0, "
                                 f"got {item['box']!r}")
        outline = item.get("outline", "rectangle")
        if outline not in OUTLINES:
            raise ValueError(f"{name}: outline: unknown {outline!r}; valid: {', '.join(OUTLINES)}")
        angle = item.get("angle", 0.0)
        if not isinstance(angle, (int, float)) or not math.isfinite(angle):
            raise ValueError(f"{name}: angle: expected a finite number of degrees, got {angle!r}")
        surfaces.append(_Surface(_theta(item["d"], f"{name}: d"), box, outline, float(angle)))
    return surfaces


def _pad(surfaces: list, width: int, height: int) -> int:
    """Columns rendered beyond each side of the image: the largest |disparity| + 4."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    return int(math.ceil(max(np.abs(evaluate(s.theta, x, y)).max() for s in surfaces))) + 4


def _geometry(spec: SceneSpec) -> tuple:
    """``(surfaces, ellipse, pad)`` of a spec, checked (``ValueError`` if it is not a valid
    scene): the background, the props, then the object, as :class:`_Surface`."""
    w, h = int(spec.width), int(spec.height)
    ellipse = tuple(float(v) for v in (spec.ellipse if spec.ellipse is not None
                                       else (w / 2, h / 2, 0.25 * w, 0.29 * h)))
    surfaces = [_Surface(_theta(spec.d_bg, "d_bg")), *_surfaces(spec.props, "props"),
                _Surface(_theta(spec.d_fg, "d_fg"), ellipse, spec.outline)]
    pad = _pad(surfaces, w, h)
    _check(spec, surfaces, ellipse, pad)
    return surfaces, ellipse, pad


def _nearest(surfaces: list, y, source):
    """The z-buffer over rays: per ray, the index of the nearest surface that holds its point
    on the ray, that point's left-view x and its disparity (larger is nearer).
    ``source(surface)`` gives the left-view x of each ray's point on a surface (NaN: none)."""
    xs = source(surfaces[0])
    index, d = np.zeros(y.shape, np.int64), evaluate(surfaces[0].theta, xs, y)
    for k, surface in enumerate(surfaces[1:], 1):
        xk = source(surface)
        dk = evaluate(surface.theta, xk, y)
        take = surface.covers(xk, y) & (dk > d)
        index, xs, d = np.where(take, k, index), np.where(take, xk, xs), np.where(take, dk, d)
    return index, xs, d


def _paint(textures: list, index, xs, y):
    """The colour of each ray's point: the texture of its surface ``index`` at ``(xs, y)``."""
    colour = textures[0](xs, y)
    for k, texture in enumerate(textures[1:], 1):
        colour = np.where((index == k)[..., None], texture(xs, y), colour)
    return colour


def _render(surfaces: list, textures: list, width: int, height: int) -> tuple:
    """Ray cast both views over ``surfaces`` (the background first, which must cover the
    right view) painted with ``textures``.

    Returns ``(left, right, seen, d_left, occ)``: the noise-free images (float64, (H, W, 3)),
    the index of the surface each left pixel sees, its disparity, and the occlusion: the
    left pixel's point projects outside the right image, or another surface is nearer on its
    right-view ray."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    # Left view: the nearest surface on the pixel's own ray.
    seen, _, d_left = _nearest(surfaces, y, lambda surface: x)
    left = _paint(textures, seen, x, y)

    # Right view: on each ray, the point of each surface that projects to it (the root of
    # x - d(x, y) = xr); the nearest one wins.
    if np.isnan(_source_x(surfaces[0].theta, x, y)).any():
        raise ValueError("d_bg: the background does not cover the right view; reduce its "
                         "curvature")
    seen_right, xs, _ = _nearest(surfaces, y, lambda surface: _source_x(surface.theta, x, y))
    right = _paint(textures, seen_right, xs, y)

    xr = x - d_left
    seen_there, _, d_there = _nearest(surfaces, y,
                                      lambda surface: _source_x(surface.theta, xr, y))
    occ = (xr < -0.5) | ((seen_there != seen) & (d_there > d_left))
    return left, right, seen, d_left, occ


def check_scene(**params) -> None:
    """Raise ``ValueError`` if :func:`make_scene` ``(None, **params)`` would, without
    rendering (the geometry of :class:`SceneSpec` keywords)."""
    _geometry(replace(SceneSpec(), **params))


def _spec(cls, params: dict, function: str, extra: str = ""):
    """``cls(**params)`` after checking that every key is one of its fields."""
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(params) - names)
    if unknown:
        raise ValueError(f"{function}: unknown parameter(s) {', '.join(unknown)}; "
                         f"valid: {extra}{', '.join(sorted(names))}")
    return cls(**params)


def make_scene(preset: str | None = "easy", *, seed: int = 0, **params) -> Scene:
    """Render a two-layer scene with exact ground truth.

    Parameters
    ----------
    preset : str or None
        A key of :data:`PRESETS` giving the defaults; None: the :class:`SceneSpec` defaults.
    seed : int
        Seed of the textures and the noise; equal seeds give identical scenes.
    **params
        Overrides of any :class:`SceneSpec` field (``width``, ``d_fg``, ``noise``...).

    Returns
    -------
    Scene
        ``left``, ``right`` float32 (H, W, 3); ``disp_left`` float32 (H, W), finite everywhere;
        ``fg_left``, ``occ_left``, ``boundary`` (:func:`~lss_kernels.metrics.boundary_from_foreground`)
        and ``roi_fg`` / ``roi_bg`` (:func:`~lss_kernels.metrics.band_from_foreground`), bool
        (H, W); ``d_max`` the smallest multiple of ``d_max_step`` (default 2) >=
        max(disp_left) + 2; ``init_ellipse`` the true ellipse (the box's ellipse for other
        outlines) scaled by ``init_scale`` and shifted by ``init_shift``;
        ``init_ellipse_cyclopean`` the same moved by ``-d_fg(centre) / 2`` in x; ``meta`` the
        preset, the seed and the spec.
    """
    if preset is not None and preset not in PRESETS:
        raise ValueError(f"preset: unknown {preset!r}; valid: {', '.join(PRESETS)}")
    spec = _spec(SceneSpec, {**PRESETS.get(preset, {}), **params}, "make_scene", "seed, ")
    w, h = int(spec.width), int(spec.height)
    surfaces, ellipse, pad = _geometry(spec)
    theta_bg, theta_fg = surfaces[0].theta, surfaces[-1].theta

    rng = np.random.default_rng(seed)
    box = (-pad, -1.0, w + pad, h + 1.0)
    tex_fg = make_texture(rng, spec.texture_fg, spec.texture_cells, box, "texture_fg")
    tex_bg = make_texture(rng, spec.texture_bg, spec.texture_cells, box, "texture_bg")
    textures = [tex_bg, *(make_texture(rng, prop.get("texture"), spec.texture_cells, box,
                                       f"props[{i}]: texture")
                          for i, prop in enumerate(spec.props)), tex_fg]
    left, right, seen, d_left, occ = _render(surfaces, textures, w, h)
    fg = seen == len(surfaces) - 1

    left, right = (_finish(img, spec, rng) for img in (left, right))
    roi_fg, roi_bg = band_from_foreground(fg, spec.band_radius)
    cx, cy, rx, ry = ellipse
    init = (cx + spec.init_shift[0], cy + spec.init_shift[1],
            rx * spec.init_scale, ry * spec.init_scale)
    d_centre = float(evaluate(theta_fg, cx, cy))
    name = f"{preset or 'custom'}_seed{seed}"
    step = int(spec.d_max_step)
    return Scene(
        name=name, left=left, right=right,
        d_max=float(step * math.ceil((d_left.max() + 2.0) / step)),
        init_ellipse=init,
        init_ellipse_cyclopean=(init[0] - d_centre / 2.0,) + init[1:],
        disp_left=d_left.astype(np.float32), fg_left=fg, occ_left=occ,
        roi_fg=roi_fg, roi_bg=roi_bg, boundary=boundary_from_foreground(fg),
        meta={"generator": "lss_kernels.scenes", "preset": preset, "seed": int(seed),
              "ellipse": list(ellipse), "theta_fg": theta_fg.tolist(),
              "theta_bg": theta_bg.tolist(), "spec": _jsonable(asdict(spec))})


def _deepest_pixel(mask: np.ndarray) -> tuple:
    """``(x, y)`` of the pixel of ``mask`` (H, W) farthest inside it: of its last non-empty
    erosion (4-neighbour; outside the image is outside the mask), the pixel nearest that
    erosion's centroid."""
    core = mask.copy()
    while True:
        inner = core.copy()
        inner[1:] &= core[:-1]
        inner[:-1] &= core[1:]
        inner[:, 1:] &= core[:, :-1]
        inner[:, :-1] &= core[:, 1:]
        inner[[0, -1]] = False
        inner[:, [0, -1]] = False
        if not inner.any():
            break
        core = inner
    ys, xs = np.nonzero(core)
    i = int(np.argmin((xs - xs.mean()) ** 2 + (ys - ys.mean()) ** 2))
    return float(xs[i]), float(ys[i])


def _on_mask(point, mask: np.ndarray) -> bool:
    """Whether ``point`` is two finite numbers ``(x, y)`` whose nearest pixel is in ``mask``."""
    try:
        x, y = (float(v) for v in point)
    except (TypeError, ValueError):
        return False
    if not (math.isfinite(x) and math.isfinite(y)):
        return False
    ix, iy = int(round(x)), int(round(y))
    return 0 <= iy < mask.shape[0] and 0 <= ix < mask.shape[1] and bool(mask[iy, ix])


def object_band(fg_left, nearer, other_occ, radius: int = BAND_RADIUS) -> tuple:
    """The evaluation band of one object among several (``docs/scene-format.md``).

    The object's own boundary is its visible pixels with a left or right neighbour that lies
    behind it (neither the object nor ``nearer``): an edge against a nearer object belongs to
    that object.  The band is every pixel within ``radius`` columns of it (same row), minus
    ``nearer`` pixels and ``other_occ``, the occlusions another object causes.  With nothing
    nearer and no other occlusion it is :func:`~lss_kernels.metrics.band_from_foreground`.

    Parameters
    ----------
    fg_left : ndarray, bool, shape (H, W)
        The object's visible pixels (left view).
    nearer : ndarray, bool, shape (H, W)
        Pixels of other surfaces nearer than the object's surface there.
    other_occ : ndarray, bool, shape (H, W)
        Pixels hidden from the right camera by a surface other than the object.
    radius : int
        Half-width of the band in pixels.

    Returns
    -------
    boundary, roi_fg, roi_bg : ndarray, bool, shape (H, W)
        The own boundary and the object's and the background's parts of the band.
    """
    behind = ~fg_left & ~nearer
    boundary = np.zeros_like(fg_left)
    boundary[:, :-1] |= fg_left[:, :-1] & behind[:, 1:]
    boundary[:, 1:] |= fg_left[:, 1:] & behind[:, :-1]
    band = _dilate_rows(boundary, int(radius)) & ~other_occ
    return boundary, band & fg_left, band & behind


def make_multi_scene(*, seed: int = 0, **params) -> Scene:
    """Render a scene of several objects at different depths with exact ground truth.

    The views are ray cast as in :func:`make_scene`, over the background and
    ``MultiSpec.objects``; one of them is the clicked object, whose boundary, occlusions and
    depth are to be found among the others, before and behind it.

    Parameters
    ----------
    seed : int
        Seed of the textures and the noise; equal seeds give identical scenes.
    **params
        :class:`MultiSpec` fields (``objects`` at least).

    Returns
    -------
    Scene
        ``left``, ``right``, ``disp_left`` (the visible surface) as in :func:`make_scene`;
        ``occ_left``: every left pixel hidden from the right camera, whatever hides it;
        ``layers_left`` uint8 (H, W): the index of the surface each left pixel sees (0 the
        background, ``k + 1`` for ``objects[k]``); ``fg_left``: the clicked object's visible
        pixels; ``boundary``, ``roi_fg``, ``roi_bg`` its band (:func:`object_band`), where
        ``other_occ`` is the occlusion not caused by the clicked object nor by the left image
        border; ``init_point``; ``init_ellipse`` None; ``d_max``; ``meta`` the seed, the
        spec and, per object, its name, coefficients, box, outline, angle and visible pixels.
    """
    spec = _spec(MultiSpec, params, "make_multi_scene", "seed, ")
    _check_image(spec)
    if not spec.objects:
        raise ValueError("objects: expected at least one object, got none")
    if len(spec.objects) > 255:
        raise ValueError(f"objects: expected at most 255 (8-bit layer indices), got "
                         f"{len(spec.objects)}")
    if not isinstance(spec.clicked, int) or not 0 <= spec.clicked < len(spec.objects):
        raise ValueError(f"clicked: expected an index in objects (0..{len(spec.objects) - 1}), "
                         f"got {spec.clicked!r}")
    w, h = int(spec.width), int(spec.height)
    surfaces = [_Surface(_theta(spec.d_bg, "d_bg")), *_surfaces(spec.objects, "objects")]
    pad = _pad(surfaces, w, h)
    _check_surfaces(surfaces, ["d_bg", *(f"objects[{i}]: d" for i in range(len(spec.objects)))],
                    w, h, pad)

    rng = np.random.default_rng(seed)
    box = (-pad, -1.0, w + pad, h + 1.0)
    textures = [make_texture(rng, spec.texture_bg, spec.texture_cells, box, "texture_bg"),
                *(make_texture(rng, item.get("texture"), spec.texture_cells, box,
                               f"objects[{i}]: texture") for i, item in enumerate(spec.objects))]
    left, right, seen, d_left, occ = _render(surfaces, textures, w, h)
    clicked = surfaces[spec.clicked + 1]
    fg = seen == spec.clicked + 1
    if not fg.any():
        raise ValueError(f"clicked: objects[{spec.clicked}] is hidden by nearer objects in "
                         f"the left view")

    # The clicked object's own occlusions: it holds a nearer point on the right-view ray of a
    # pixel that is not its own (it does not fold, so it never hides itself).
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    xr = x - d_left
    xk = _source_x(clicked.theta, xr, y)
    own_occ = ~fg & clicked.covers(xk, y) & (evaluate(clicked.theta, xk, y) > d_left)
    nearer = ~fg & (d_left > evaluate(clicked.theta, x, y))
    boundary, roi_fg, roi_bg = object_band(fg, nearer, occ & ~own_occ & (xr >= -0.5),
                                           spec.band_radius)

    if spec.init_point is None and not (fg & ~occ).any():
        raise ValueError(f"clicked: objects[{spec.clicked}] is hidden from the right camera "
                         f"wherever the left one sees it; give init_point")
    point = _deepest_pixel(fg & ~occ) if spec.init_point is None else spec.init_point
    if not _on_mask(point, fg):
        raise ValueError(f"init_point: expected (x, y) on a visible pixel of the clicked "
                         f"object, got {spec.init_point!r}")
    need = float(d_left.max()) + 2.0
    step = int(spec.d_max_step)
    d_max = float(step * math.ceil(need / step)) if spec.d_max is None else float(spec.d_max)
    if d_max < need:
        raise ValueError(f"d_max: expected at least max(disp_left) + 2 = {need:.4g}, "
                         f"got {spec.d_max}")
    objects = [{"name": item.get("name", f"object {i}"), "layer": i + 1,
                "theta": surface.theta.tolist(),
                "box": None if surface.box is None else list(surface.box),
                "outline": surface.outline, "angle": surface.angle,
                "visible_px": int((seen == i + 1).sum())}
               for i, (item, surface) in enumerate(zip(spec.objects, surfaces[1:]))]
    left, right = (_finish(img, spec, rng) for img in (left, right))
    return Scene(
        name=f"multi_seed{seed}", left=left, right=right, d_max=d_max, init_ellipse=None,
        init_point=tuple(float(v) for v in point), disp_left=d_left.astype(np.float32),
        fg_left=fg, occ_left=occ, roi_fg=roi_fg, roi_bg=roi_bg, boundary=boundary,
        layers_left=seen.astype(np.uint8),
        meta={"generator": "lss_kernels.scenes", "kind": "multi", "seed": int(seed),
              "clicked": spec.clicked, "theta_bg": surfaces[0].theta.tolist(),
              "objects": objects, "spec": _jsonable(asdict(spec))})


def _finish(img: np.ndarray, spec, rng) -> np.ndarray:
    """Add the photometric noise of ``spec`` (a :class:`SceneSpec` or :class:`MultiSpec`),
    clip to [0, 1], quantise if asked; float32."""
    if spec.noise > 0:
        img = img + rng.normal(0.0, spec.noise, img.shape)
    img = np.clip(img, 0.0, 1.0)
    if spec.quantize:
        img = np.round(img * 255.0) / 255.0
    return img.astype(np.float32)


def _jsonable(value):
    """Tuples to lists and numpy scalars to Python numbers, recursively (for meta.json)."""
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def write_scene(folder, preset: str | None = "easy", *, seed: int = 0, name: str | None = None,
                meta: dict | None = None, **params) -> Scene:
    """:func:`make_scene` then :func:`lss_kernels.io.save_scene` into ``folder``; returns the scene.

    ``name`` replaces the scene's name and ``meta`` is merged into its ``meta`` (both are
    written to ``meta.json``).
    """
    return _save(folder, make_scene(preset, seed=seed, **params), name, meta)


def write_multi_scene(folder, *, seed: int = 0, name: str | None = None,
                      meta: dict | None = None, **params) -> Scene:
    """:func:`make_multi_scene` then :func:`lss_kernels.io.save_scene`, as :func:`write_scene`."""
    return _save(folder, make_multi_scene(seed=seed, **params), name, meta)


def _save(folder, scene: Scene, name: str | None, meta: dict | None) -> Scene:
    """Rename ``scene`` (unless ``name`` is None), merge ``meta`` into its meta, save it."""
    if name is not None:
        scene.name = name
    scene.meta.update(meta or {})
    save_scene(folder, scene)
    return scene
