"""Colour maps, overlays and animation frames (figures of the paper, Figs. 1 and 3).

Everything here draws with matplotlib's object API (:class:`matplotlib.figure.Figure` on a
:class:`~matplotlib.backends.backend_agg.FigureCanvasAgg`), never with ``pyplot``: importing
this module changes no global matplotlib state and never opens a window.

Conventions
-----------
Images are float32 ``(H, W, 3)`` in [0, 1]; masks are bool ``(H, W)``; disparities are in
left-view pixels.  Arrays of the solver's cyclopean frame (``phi``, the consensus) have the same
``(H, W)`` grid and are displayed as they are.  Occlusions are painted dark blue, as in the
paper's figures.
"""
from __future__ import annotations

import os

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = [
    "OCCLUSION_RGB", "BOUNDARY_RGB", "INIT_BOUNDARY_RGB",
    "colorize", "boundary_mask", "thicken", "paint_mask", "draw_boundary",
    "LAYER_RGB", "layers_rgb", "save_layers_png",
    "occlusion_disparity_rgb", "overlay_rgb", "save_disparity_png", "save_overlay_png",
    "save_rgb_png", "new_figure", "render_figure", "save_figure",
]

#: Dark blue used for occluded pixels (the paper's figures).
OCCLUSION_RGB = (0.05, 0.05, 0.45)
#: Red: the current foreground boundary.
BOUNDARY_RGB = (1.0, 0.1, 0.1)
#: Yellow: the initial boundary.
INIT_BOUNDARY_RGB = (1.0, 0.9, 0.1)


# ---------------------------------------------------------------------------------------------
# Pixel-level helpers (numpy only)
# ---------------------------------------------------------------------------------------------

def _as_mask(mask, shape=None, name="mask") -> np.ndarray:
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D (H, W) array, got shape {m.shape}")
    if shape is not None and m.shape != tuple(shape):
        raise ValueError(f"{name}: expected shape {tuple(shape)}, got {m.shape}")
    return m.astype(bool, copy=False)


def _as_rgb(image, name="image") -> np.ndarray:
    a = np.asarray(image)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        raise ValueError(f"{name}: expected an (H, W, 3) image, got shape {a.shape}")
    a = a[..., :3]
    if a.dtype == np.uint8:
        return a.astype(np.float32) / 255.0
    return np.clip(np.nan_to_num(a.astype(np.float32), nan=0.0), 0.0, 1.0)


def _to_uint8(rgb: np.ndarray) -> np.ndarray:
    if rgb.dtype == np.uint8:
        return rgb
    return (np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def colorize(disparity, vmin, vmax, cmap="viridis") -> np.ndarray:
    """Colour-map a disparity map.

    Parameters
    ----------
    disparity : (H, W) array
        Values to map; non-finite values (NaN, inf) become black.
    vmin, vmax : float
        Range mapped to the ends of the colour map; values outside are clipped.
    cmap : str
        A matplotlib colour-map name.

    Returns
    -------
    (H, W, 3) uint8
    """
    d = np.asarray(disparity, dtype=np.float64)
    if d.ndim != 2:
        raise ValueError(f"disparity: expected a 2-D (H, W) array, got shape {d.shape}")
    vmin, vmax = float(vmin), float(vmax)
    if not (np.isfinite(vmin) and np.isfinite(vmax)):
        raise ValueError(f"colorize: vmin and vmax must be finite, got {vmin}, {vmax}")
    span = vmax - vmin if vmax > vmin else 1.0
    finite = np.isfinite(d)
    t = np.clip((np.where(finite, d, vmin) - vmin) / span, 0.0, 1.0)
    rgb = colormaps[cmap](t)[..., :3]
    rgb[~finite] = 0.0
    return _to_uint8(rgb)


def boundary_mask(mask) -> np.ndarray:
    """Pixels of a label map whose 4-neighbourhood holds a different label.

    Both sides of a boundary are marked (the foreground pixel and the background pixel of
    every differing 4-neighbour pair); the image border is not a boundary.

    Parameters
    ----------
    mask : (H, W) bool

    Returns
    -------
    (H, W) bool
    """
    m = _as_mask(mask)
    out = np.zeros_like(m)
    dx = m[:, 1:] != m[:, :-1]
    dy = m[1:, :] != m[:-1, :]
    out[:, 1:] |= dx
    out[:, :-1] |= dx
    out[1:, :] |= dy
    out[:-1, :] |= dy
    return out


def thicken(mask, radius: int = 1) -> np.ndarray:
    """Dilate a bool mask by a (2 radius + 1)^2 square (radius 0: unchanged)."""
    m = _as_mask(mask)
    r = int(radius)
    if r <= 0:
        return m.copy()
    h, w = m.shape
    padded = np.pad(m, r)
    out = np.zeros_like(m)
    for oy in range(2 * r + 1):
        for ox in range(2 * r + 1):
            out |= padded[oy:oy + h, ox:ox + w]
    return out


def paint_mask(rgb, mask, color, alpha: float = 1.0) -> np.ndarray:
    """Return a copy of a float RGB image with ``mask`` pixels blended towards ``color``."""
    out = _as_rgb(rgb).copy()
    m = _as_mask(mask, out.shape[:2])
    c = np.asarray(color, dtype=np.float32)
    out[m] = (1.0 - alpha) * out[m] + alpha * c
    return out


def draw_boundary(rgb, foreground, color=BOUNDARY_RGB, thickness: int = 1) -> np.ndarray:
    """Paint the boundary of ``foreground`` (see :func:`boundary_mask`) onto a copy of ``rgb``.

    ``thickness`` > 1 dilates the one-pixel-per-side boundary by ``thickness // 2``.
    """
    edge = boundary_mask(foreground)
    if thickness > 1:
        edge = thicken(edge, thickness // 2)
    return paint_mask(rgb, edge, color)


def occlusion_disparity_rgb(disparity, occlusion, vmin, vmax, cmap="viridis") -> np.ndarray:
    """Disparity colour map with occluded pixels in dark blue (the paper's Figs. 1b and 3).

    Parameters
    ----------
    disparity : (H, W) float, left-view pixels
    occlusion : (H, W) bool or None
    vmin, vmax : float
        Colour range in disparity pixels.

    Returns
    -------
    (H, W, 3) uint8
    """
    rgb = colorize(disparity, vmin, vmax, cmap)
    if occlusion is not None:
        occ = _as_mask(occlusion, rgb.shape[:2], "occlusion")
        rgb[occ] = _to_uint8(np.asarray(OCCLUSION_RGB, dtype=np.float32))
    return rgb


def overlay_rgb(left, foreground=None, occlusion=None, init_foreground=None,
                thickness: int | None = None) -> np.ndarray:
    """The left image with occlusions tinted dark blue and boundaries drawn.

    Parameters
    ----------
    left : (H, W, 3) float in [0, 1]
    foreground : (H, W) bool or None
        Its boundary is drawn in red.
    occlusion : (H, W) bool or None
        Tinted dark blue (60 % opacity).
    init_foreground : (H, W) bool or None
        Its boundary is drawn in yellow, under the red one.
    thickness : int or None
        Boundary thickness in pixels; ``None`` picks one from the image size.

    Returns
    -------
    (H, W, 3) uint8
    """
    rgb = _as_rgb(left, "left")
    h, w = rgb.shape[:2]
    if thickness is None:
        thickness = 1 if max(h, w) < 400 else 2
    if occlusion is not None:
        rgb = paint_mask(rgb, _as_mask(occlusion, (h, w), "occlusion"), OCCLUSION_RGB, 0.6)
    if init_foreground is not None:
        rgb = draw_boundary(rgb, _as_mask(init_foreground, (h, w), "init_foreground"),
                            INIT_BOUNDARY_RGB, thickness)
    if foreground is not None:
        rgb = draw_boundary(rgb, _as_mask(foreground, (h, w), "foreground"),
                            BOUNDARY_RGB, thickness)
    return _to_uint8(rgb)


#: The tint of each layer of a layer map (lss_kernels.model.layers): behind the object grey,
#: the object red, in front of it blue; any other value (outside a photo's window) black.
LAYER_RGB = {0: (0.55, 0.55, 0.55), 1: (0.9, 0.15, 0.1), 2: (0.1, 0.35, 0.95)}


def layers_rgb(left, layers) -> np.ndarray:
    """The left image tinted by layer (:data:`LAYER_RGB`, 50 % opacity; other values
    black), each layer's boundary drawn in its own colour."""
    rgb = _as_rgb(left, "left")
    layers = np.asarray(layers)
    if layers.shape != rgb.shape[:2]:
        raise ValueError(f"layers: expected shape {rgb.shape[:2]}, got {layers.shape}")
    known = np.isin(layers, list(LAYER_RGB))
    rgb = np.where(known[..., None], rgb, 0.0)
    for value, colour in LAYER_RGB.items():
        rgb = paint_mask(rgb, layers == value, colour, 0.5)
        if value:
            rgb = draw_boundary(rgb, layers == value, colour, 1)
    return _to_uint8(rgb)


def save_layers_png(path, left, layers) -> str:
    """Save :func:`layers_rgb` as a PNG of the input's size."""
    return save_rgb_png(path, layers_rgb(left, layers))


def _makedirs_for(path) -> None:
    folder = os.path.dirname(os.fspath(path))
    if folder:
        os.makedirs(folder, exist_ok=True)


def save_rgb_png(path, rgb) -> str:
    """Write an (H, W, 3) uint8 or float image as a PNG of exactly H x W pixels."""
    import imageio.v3 as iio
    _makedirs_for(path)
    iio.imwrite(path, _to_uint8(np.asarray(rgb)) if np.asarray(rgb).dtype != np.uint8
                else np.asarray(rgb))
    return os.fspath(path)


def save_overlay_png(path, left, foreground, occlusion, init_foreground=None) -> str:
    """Save :func:`overlay_rgb` as a PNG of exactly the input's H x W pixels.

    Red: boundary of the final foreground; yellow: initial boundary (if given); dark blue
    tint: occluded pixels.  All masks are in the left view.
    """
    return save_rgb_png(path, overlay_rgb(left, foreground, occlusion, init_foreground))


# ---------------------------------------------------------------------------------------------
# Matplotlib figures (object API only)
# ---------------------------------------------------------------------------------------------

def new_figure(width_px: int, height_px: int, dpi: int = 100) -> Figure:
    """A pyplot-free figure of ``width_px`` x ``height_px`` pixels at ``dpi``."""
    fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def render_figure(fig: Figure, size=None) -> np.ndarray:
    """Draw a figure with Agg and return its pixels as (H, W, 3) uint8.

    ``size=(H, W)`` crops or pads (white) the result to exactly that size, so that rounding of
    the figure size in inches never changes the pixel size.
    """
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    if size is not None:
        h, w = int(size[0]), int(size[1])
        out = np.full((h, w, 3), 255, np.uint8)
        hh, ww = min(h, rgb.shape[0]), min(w, rgb.shape[1])
        out[:hh, :ww] = rgb[:hh, :ww]
        rgb = out
    return rgb


def save_figure(fig: Figure, path, size=None) -> str:
    """Render a figure (see :func:`render_figure`) and write it as a PNG."""
    return save_rgb_png(path, render_figure(fig, size))


def save_disparity_png(path, disparity, vmin=0.0, vmax=None, title=None, occlusion=None,
                       cmap="viridis") -> str:
    """Save a colour-mapped disparity map as a PNG of exactly the input's H x W pixels.

    A narrow colour bar with its range in disparity pixels is drawn inside the image, in the
    right margin, so the file keeps the input's size.

    Parameters
    ----------
    path : str or path-like
    disparity : (H, W) float, left-view pixels
    vmin, vmax : float
        Colour range; ``vmax=None`` uses the largest finite value.
    title : str or None
        Drawn in the top-left corner.
    occlusion : (H, W) bool or None
        Painted dark blue.
    """
    d = np.asarray(disparity, dtype=np.float32)
    if d.ndim != 2:
        raise ValueError(f"disparity: expected a 2-D (H, W) array, got shape {d.shape}")
    h, w = d.shape
    if vmax is None:
        finite = d[np.isfinite(d)]
        vmax = float(finite.max()) if finite.size else 1.0
        if vmax <= vmin:
            vmax = vmin + 1.0
    rgb = occlusion_disparity_rgb(d, occlusion, vmin, vmax, cmap)

    fig = new_figure(w, h)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(rgb, interpolation="nearest", aspect="auto")
    ax.set_axis_off()
    fontsize = float(np.clip(min(h, w) / 22.0, 4.0, 10.0))
    if w >= 24 and h >= 24:
        bar_w = max(3, w // 40) / w
        bar_h = 0.7
        cax = fig.add_axes((1.0 - bar_w - 2.0 / w, (1 - bar_h) / 2, bar_w, bar_h))
        ramp = np.linspace(1.0, 0.0, 256)[:, None]
        cax.imshow(ramp, cmap=cmap, aspect="auto", extent=(0, 1, vmin, vmax))
        cax.set_xticks([])
        cax.set_yticks([])
        for spine in cax.spines.values():
            spine.set_edgecolor("white")
            spine.set_linewidth(0.5)
        style = dict(color="white", fontsize=fontsize, ha="right",
                     bbox=dict(facecolor="black", alpha=0.5, pad=1, linewidth=0))
        fig.text(1.0 - bar_w - 4.0 / w, (1 + bar_h) / 2, f"{vmax:g} px", va="top", **style)
        fig.text(1.0 - bar_w - 4.0 / w, (1 - bar_h) / 2, f"{vmin:g} px", va="bottom",
                 **style)
    if title:
        fig.text(3.0 / w, 1 - 3.0 / h, title, color="white", fontsize=fontsize, ha="left",
                 va="top", bbox=dict(facecolor="black", alpha=0.5, pad=1, linewidth=0))
    return save_figure(fig, path, size=(h, w))
