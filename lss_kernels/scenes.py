"""Two-layer synthetic stereo scenes with exact ground truth.

A textured foreground surface with an elliptic outline floats in front of a textured background
surface.  Each surface ``S`` is a disparity function quadratic in the LEFT-view pixel
coordinates, ``d_S(x, y) = Theta_S . U(x, y)`` with the paper's basis
``U = (x^2, xy, y^2, x, y, 1)`` (Sec. 3; 0-based pixels, x to the right, y down), and a scene
point is named by the left-view coordinates ``(x, y)`` of its ray.  Its right-view position is
``x - d_S(x, y)`` (same row), and its colour is a texture sampled at ``(x, y)``, so one scene point
has one colour in both views.

Both views are ray cast per pixel: the left pixel ``(x, y)`` sees the foreground where
``(x, y)`` is inside the ellipse, else the background; the right pixel ``(xr, y)`` finds, on each
surface, the point that projects to it (the root of the quadratic ``x - d_S(x, y) = xr``) and keeps
the nearer one (larger disparity).  The ground truth is therefore exact for the rendered images:
``disp_left`` is ``d_S`` at the pixel centres, and a left pixel is occluded (``occ_left``) when
its point is not seen by the right camera: it projects outside the right image
(``xr < -0.5``) or the foreground covers its right-view ray.

Presets (:data:`PRESETS`): ``"easy"`` (128x96, fronto-parallel layers at 24 and 8 px),
``"slanted"`` (128x96, curved slanted foreground over a slanted background) and ``"tiny"``
(64x48, layers at 12 and 4 px, for quick tests).

Examples
--------
>>> scene = make_scene("tiny", seed=1)
>>> scene = make_scene("easy", noise=0.02, d_fg=disparity_coefficients(20.0, slope=(0.05, 0)))
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from .io import Scene, save_scene
from .metrics import BAND_RADIUS, band_from_foreground, boundary_from_foreground

__all__ = ["PRESETS", "SceneSpec", "disparity_coefficients", "make_scene", "write_scene"]


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
        Foreground outline ``(cx, cy, rx, ry)`` in left-view pixels; None: centred, radii a
        quarter of the width and 0.29 of the height.
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


def _disparity(theta: np.ndarray, x, y):
    """``Theta . U(x, y)``, U = (x^2, xy, y^2, x, y, 1), left-view pixels."""
    return theta[0] * x * x + theta[1] * x * y + theta[2] * y * y + theta[3] * x \
        + theta[4] * y + theta[5]


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


def _inside(ellipse, x, y):
    cx, cy, rx, ry = ellipse
    return ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0


def _texture(rng, cells, x0: float, y0: float, x1: float, y1: float):
    """A random RGB texture on the rectangle ``[x0, x1] x [y0, y1]`` of surface coordinates.

    Value noise: for each cell size, uniform random values on a grid of that spacing,
    interpolated bilinearly; the octaves are averaged, stretched to [0.1, 0.9] and tinted by a
    random colour.  Returns ``lookup(x, y) -> (..., 3)`` float64.
    """
    grids = []
    for cell in cells:
        nx, ny = int(math.ceil((x1 - x0) / cell)) + 2, int(math.ceil((y1 - y0) / cell)) + 2
        grids.append((cell, rng.random((ny, nx, 3))))
    tint = 0.15 * (rng.random(3) - 0.5)

    def lookup(x, y):
        total = 0.0
        for cell, grid in grids:
            gx = np.clip((x - x0) / cell, 0.0, grid.shape[1] - 1.000001)
            gy = np.clip((y - y0) / cell, 0.0, grid.shape[0] - 1.000001)
            ix, iy = gx.astype(np.int64), gy.astype(np.int64)
            fx, fy = (gx - ix)[..., None], (gy - iy)[..., None]
            total = total + ((1 - fy) * ((1 - fx) * grid[iy, ix] + fx * grid[iy, ix + 1])
                             + fy * ((1 - fx) * grid[iy + 1, ix] + fx * grid[iy + 1, ix + 1]))
        return np.clip(0.1 + 0.8 * total / len(grids) + tint, 0.0, 1.0)

    return lookup


def _check(spec: SceneSpec, theta_fg, theta_bg, ellipse, pad: int) -> None:
    """The scene must be a valid two-layer scene on the rendered domain."""
    if spec.width < 8 or spec.height < 8:
        raise ValueError(f"width, height: expected at least 8 pixels, got {spec.width}x{spec.height}")
    if ellipse[2] <= 0 or ellipse[3] <= 0:
        raise ValueError(f"ellipse: expected radii > 0, got {ellipse}")
    if not 0.0 <= spec.noise <= 1.0:
        raise ValueError(f"noise: expected a standard deviation in [0, 1], got {spec.noise}")
    y, x = np.mgrid[0:spec.height, -pad:spec.width + pad].astype(np.float64)
    for theta, name in ((theta_fg, "d_fg"), (theta_bg, "d_bg")):
        d = _disparity(theta, x, y)
        dx = 2 * theta[0] * x + theta[1] * y + theta[3]
        if d[:, pad:-pad].min() < 0:
            raise ValueError(f"{name}: disparity must be >= 0 in the image, min is "
                             f"{d[:, pad:-pad].min():.3g}")
        if dx.max() >= 0.9:
            raise ValueError(f"{name}: d/dx must stay below 0.9 (the surface must not fold in "
                             f"the right view), max is {dx.max():.3g}")
    y, x = y[:, pad:-pad], x[:, pad:-pad]
    inside = _inside(ellipse, x, y)
    if not inside.any():
        raise ValueError(f"ellipse: {ellipse} covers no pixel of the {spec.width}x{spec.height} image")
    if (_disparity(theta_fg, x, y) <= _disparity(theta_bg, x, y))[inside].any():
        raise ValueError("d_fg, d_bg: the foreground must be in front of the background "
                         "(larger disparity) everywhere inside the ellipse")


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
        (H, W); ``d_max`` the smallest even integer >= max(disp_left) + 2; ``init_ellipse`` the
        true ellipse scaled by ``init_scale`` and shifted by ``init_shift``;
        ``init_ellipse_cyclopean`` the same moved by ``-d_fg(centre) / 2`` in x; ``meta`` the
        preset, the seed and the spec.
    """
    if preset is not None and preset not in PRESETS:
        raise ValueError(f"preset: unknown {preset!r}; valid: {', '.join(PRESETS)}")
    names = {f.name for f in fields(SceneSpec)}
    unknown = sorted(set(params) - names)
    if unknown:
        raise ValueError(f"make_scene: unknown parameter(s) {', '.join(unknown)}; "
                         f"valid: seed, {', '.join(sorted(names))}")
    spec = replace(SceneSpec(**PRESETS.get(preset, {})), **params)
    w, h = int(spec.width), int(spec.height)
    theta_fg, theta_bg = _theta(spec.d_fg, "d_fg"), _theta(spec.d_bg, "d_bg")
    ellipse = tuple(float(v) for v in (spec.ellipse if spec.ellipse is not None
                                       else (w / 2, h / 2, 0.25 * w, 0.29 * h)))
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    pad = int(math.ceil(max(np.abs(_disparity(t, x, y)).max() for t in (theta_fg, theta_bg)))) + 4
    _check(spec, theta_fg, theta_bg, ellipse, pad)

    rng = np.random.default_rng(seed)
    tex_fg = _texture(rng, spec.texture_cells, -pad, -1.0, w + pad, h + 1.0)
    tex_bg = _texture(rng, spec.texture_cells, -pad, -1.0, w + pad, h + 1.0)

    # Left view: the pixel's own ray.
    fg = _inside(ellipse, x, y)
    d_left = np.where(fg, _disparity(theta_fg, x, y), _disparity(theta_bg, x, y))
    left = np.where(fg[..., None], tex_fg(x, y), tex_bg(x, y))

    # Right view: the point of each surface on the ray, the nearer one wins (z-buffer).
    xs_bg, xs_fg = _source_x(theta_bg, x, y), _source_x(theta_fg, x, y)
    if np.isnan(xs_bg).any():
        raise ValueError("d_bg: the background does not cover the right view; reduce its "
                         "curvature")
    fg_right = _inside(ellipse, xs_fg, y) & (
        _disparity(theta_fg, xs_fg, y) > _disparity(theta_bg, xs_bg, y))
    xs = np.where(fg_right, xs_fg, xs_bg)
    right = np.where(fg_right[..., None], tex_fg(xs, y), tex_bg(xs, y))

    # Occlusion: the left pixel's point projects outside the right image, or the right view's
    # z-buffer picks the other surface on its right-view ray.
    xr = x - d_left
    xs_fg, xs_bg = _source_x(theta_fg, xr, y), _source_x(theta_bg, xr, y)
    covered_bg = ~fg & _inside(ellipse, xs_fg, y) & (_disparity(theta_fg, xs_fg, y) > d_left)
    covered_fg = fg & (_disparity(theta_bg, xs_bg, y) >= d_left)
    occ = (xr < -0.5) | covered_bg | covered_fg

    left, right = (_finish(img, spec, rng) for img in (left, right))
    roi_fg, roi_bg = band_from_foreground(fg, spec.band_radius)
    cx, cy, rx, ry = ellipse
    init = (cx + spec.init_shift[0], cy + spec.init_shift[1],
            rx * spec.init_scale, ry * spec.init_scale)
    d_centre = float(_disparity(theta_fg, cx, cy))
    name = f"{preset or 'custom'}_seed{seed}"
    return Scene(
        name=name, left=left, right=right,
        d_max=float(2 * math.ceil((d_left.max() + 2.0) / 2.0)),
        init_ellipse=init,
        init_ellipse_cyclopean=(init[0] - d_centre / 2.0,) + init[1:],
        disp_left=d_left.astype(np.float32), fg_left=fg, occ_left=occ,
        roi_fg=roi_fg, roi_bg=roi_bg, boundary=boundary_from_foreground(fg),
        meta={"generator": "lss_kernels.scenes", "preset": preset, "seed": int(seed),
              "ellipse": list(ellipse), "theta_fg": theta_fg.tolist(),
              "theta_bg": theta_bg.tolist(), "spec": _jsonable(asdict(spec))})


def _finish(img: np.ndarray, spec: SceneSpec, rng) -> np.ndarray:
    """Add the photometric noise, clip to [0, 1], quantise if asked; float32."""
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


def write_scene(folder, preset: str | None = "easy", *, seed: int = 0, **params) -> Scene:
    """:func:`make_scene` then :func:`lss_kernels.io.save_scene` into ``folder``; returns the scene."""
    scene = make_scene(preset, seed=seed, **params)
    save_scene(folder, scene)
    return scene
