"""The figures of ``lss demo`` and the walk-through, after the paper's Fig. 1: an evolution
frame (left image with the current and initial boundary, the consensus mean and confidence,
D with its occlusions, the truth) and one patch's message over the iterations (Eq. 6).
Drawn with matplotlib's object API, never ``pyplot``."""
from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from .. import viz

__all__ = ["evolution_frame", "patch_gaussian", "patch_message_figure"]


def patch_gaussian(d, cost, d_p, sigma_p) -> np.ndarray:
    """Gaussian depiction of a patch's disparity message (Eq. 6 of the paper).

    ``f_p(d) = max C_p - (max C_p - min C_p) exp(-(d - d_p)^2 / (2 sigma_p^2))``.

    Parameters
    ----------
    d : (K,) float
        Disparities at which to draw.
    cost : (K,) float
        C_p(d) (only its min and max are used).
    d_p, sigma_p : float
        The message (same units as ``d``).

    Returns
    -------
    (K,) float
    """
    d = np.asarray(d, dtype=np.float64)
    c = np.asarray(cost, dtype=np.float64)
    c = c[np.isfinite(c)]
    hi, lo = (float(c.max()), float(c.min())) if c.size else (1.0, 0.0)
    s = max(float(sigma_p), 1e-6) if np.isfinite(sigma_p) else 1e6
    return hi - (hi - lo) * np.exp(-((d - float(d_p)) ** 2) / (2.0 * s * s))


def _image_panel(ax, rgb, title, fontsize):
    ax.imshow(rgb, interpolation="nearest")
    ax.set_title(title, fontsize=fontsize, pad=2)
    ax.set_xticks([])
    ax.set_yticks([])


def _contour(ax, mask, color, linewidth=1.0):
    m = np.asarray(mask, dtype=np.float32)
    if m.min() != m.max():
        ax.contour(m, levels=[0.5], colors=[color], linewidths=linewidth)


def _robust_max(a, q=99.0):
    a = np.asarray(a, dtype=np.float64)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return 1.0
    v = float(np.percentile(a, q))
    return v if v > 0 else (float(a.max()) if a.max() > 0 else 1.0)


def evolution_frame(left, snapshot, d_max, iteration, true_disparity=None, scores=None,
                    panel_px: int = 240, dpi: int = 100) -> np.ndarray:
    """One animation frame laid out like the paper's Fig. 1(b), as (H, W, 3) uint8.

    Panels, left to right: the left image with the current (red) and initial (yellow)
    boundary; the consensus mean d-bar (Eq. 7; cyclopean frame, left-view disparity units);
    its confidence 1/sigma (cyclopean frame); the current two-surface disparity D (Eq. 3,
    left view) with occlusions in dark blue; and, when ground truth is given, the true
    disparity with the current and initial boundaries.

    Parameters
    ----------
    left : (H, W, 3) float
    snapshot : dict
        ``Solver.snapshot()``: ``consensus_mean``, ``consensus_sigma``, ``disparity``,
        ``occlusion``, ``foreground``, ``initial_foreground``.
    d_max : float
        Upper end of the disparity colour range (left-view pixels).
    iteration : int
    true_disparity : (H, W) float or None
    scores : dict or None
        ``occ_f1`` (in [0, 1]) and ``bad4`` (a percentage, :func:`lss_kernels.metrics.score`)
        shown in the caption.
    panel_px : int
        Width of one panel in pixels.

    Returns
    -------
    (H', W', 3) uint8 — the same size for every call with the same inputs' shapes.
    """
    left = viz._as_rgb(left, "left")
    h, w = left.shape[:2]
    n = 5 if true_disparity is not None else 4
    panel_h = int(round(panel_px * h / w))
    title_px, caption_px = 18, 22
    fig_w, fig_h = n * panel_px, panel_h + title_px + caption_px
    fig = viz.new_figure(fig_w, fig_h, dpi)
    fs = 8
    fg = np.asarray(snapshot["foreground"], bool)
    init_fg = snapshot.get("initial_foreground")

    def axes(i):
        return fig.add_axes((i / n, caption_px / fig_h, 1.0 / n, panel_h / fig_h))

    ax = axes(0)
    _image_panel(ax, left, "left image, boundary", fs)
    if init_fg is not None:
        _contour(ax, init_fg, viz.INIT_BOUNDARY_RGB, 1.0)
    _contour(ax, fg, viz.BOUNDARY_RGB, 1.0)

    mean = np.asarray(snapshot["consensus_mean"], np.float32)
    _image_panel(axes(1), viz.colorize(mean, 0, d_max), "consensus mean $\\bar d$ (cyc.)", fs)

    sigma = np.asarray(snapshot["consensus_sigma"], np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(sigma > 0, 1.0 / sigma, np.nan)
    top = _robust_max(inv)
    _image_panel(axes(2), viz.colorize(inv, 0, top, "magma"),
                 f"$1/\\sigma$ (cyc., 0–{top:.3g})", fs)

    disp = np.asarray(snapshot["disparity"], np.float32)
    _image_panel(axes(3), viz.occlusion_disparity_rgb(disp, snapshot.get("occlusion"), 0, d_max),
                 "D, occlusion dark blue", fs)

    if true_disparity is not None:
        ax = axes(4)
        _image_panel(ax, viz.colorize(np.asarray(true_disparity, np.float32), 0, d_max),
                     "true disparity, boundary", fs)
        if init_fg is not None:
            _contour(ax, init_fg, viz.INIT_BOUNDARY_RGB, 1.0)
        _contour(ax, fg, viz.BOUNDARY_RGB, 1.0)

    caption = f"iteration {iteration}"
    if scores:
        if "occ_f1" in scores:
            caption += f"   occlusion F1 {float(scores['occ_f1']):.2f}"
        if "bad4" in scores:
            caption += f"   bad-4.0 {float(scores['bad4']):.1f}%"
    caption += f"   (colour range 0–{d_max:g} px)"
    fig.text(0.5, 4.0 / fig_h, caption, ha="center", va="bottom", fontsize=9)
    return viz.render_figure(fig, size=(fig_h, fig_w))


def patch_message_figure(records, left=None, patch_box=None, title=None,
                         width_px: int = 760, height_px: int = 440, dpi: int = 100) -> Figure:
    """A figure like the paper's Fig. 1(a): the evolution of one patch's disparity message.

    Parameters
    ----------
    records : list of (iteration, curve)
        ``curve`` is a ``Solver.patch_curve`` dict: ``d`` (K,), ``cost`` (K,) C_p(d),
        ``matching_cost`` (K,) patch-mean M, ``d_p``, ``sigma_p``, ``valid``, ``mean_D``
        (left-view disparity units).  Each record draws the Gaussian f_p(d) of Eq. 6 in a
        colour of its iteration and a dashed line at the patch mean of D.  The patch-mean
        matching cost of the last record is drawn in black.  A second, smaller plot below
        gives d_p +- sigma_p and the patch mean of D against the iteration (Eq. 6 is nearly
        flat when sigma_p is much wider than the disparity range).
    left : (H, W, 3) float or None
        If given, a side panel shows it with the patch outlined in red.
    patch_box : (x0, y0, size) or None
        The patch's outline on ``left`` (pixels).
    title : str or None

    Returns
    -------
    matplotlib.figure.Figure (not yet rendered; see :func:`lss_kernels.viz.save_figure`)
    """
    from matplotlib.patches import Rectangle

    fig = viz.new_figure(width_px, height_px, dpi)
    if left is not None:
        ax = fig.add_axes((0.70, 0.30, 0.28, 0.56))
        ax.imshow(viz._as_rgb(left, "left"), interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title("patch (red)", fontsize=8)
        if patch_box is not None:
            x0, y0, size = patch_box
            ax.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), size, size, fill=False,
                                   edgecolor="red", linewidth=1.5))
        axc = fig.add_axes((0.08, 0.44, 0.52, 0.48))
        axi = fig.add_axes((0.08, 0.09, 0.52, 0.23))
        cbar_box = (0.615, 0.44, 0.015, 0.48)
    else:
        axc = fig.add_axes((0.08, 0.44, 0.78, 0.48))
        axi = fig.add_axes((0.08, 0.09, 0.78, 0.23))
        cbar_box = (0.88, 0.44, 0.02, 0.48)
    if not records:
        axc.text(0.5, 0.5, "no records", ha="center", va="center", transform=axc.transAxes)
        return fig

    its = [int(r[0]) for r in records]
    lo, hi = min(its), max(its)
    from matplotlib.colors import ListedColormap
    # plasma without its pale-yellow end, which is hard to see on white
    cmap = ListedColormap(colormaps["plasma"](np.linspace(0.0, 0.88, 256)), "plasma_dark")
    norm = lambda it: 0.0 if hi == lo else (it - lo) / (hi - lo)
    d_ref = None
    for it, c in records:
        d = np.asarray(c["d"], dtype=np.float64)
        d_ref = d
        dd = np.linspace(d.min(), d.max(), max(200, 4 * d.size))
        f = patch_gaussian(dd, c["cost"], c["d_p"], c["sigma_p"])
        color = cmap(norm(it))
        style = "-" if bool(c.get("valid", True)) else ":"
        axc.plot(dd, f, style, color=color, linewidth=1.3)
        mean_d = c.get("mean_D")
        if mean_d is not None and np.isfinite(mean_d):
            axc.axvline(float(mean_d), color=color, linestyle="--", linewidth=0.8, alpha=0.8)
    last = records[-1][1]
    axc.plot(np.asarray(last["d"]), np.asarray(last["matching_cost"]), color="black",
             linewidth=1.0, label=r"patch-mean matching cost $\langle M\rangle_p$")
    axc.plot([], [], "-", color=cmap(0.45), label=r"message $f_p(d)$ (Eq. 6)")
    axc.plot([], [], ":", color=cmap(0.45), label="message of an invalid patch ($w_p=0$)")
    axc.plot([], [], "--", color=cmap(0.45), label=r"patch mean of $D$")
    axc.set_xlim(float(d_ref.min()), float(d_ref.max()))
    axc.set_xlabel("disparity d (left-view pixels)", fontsize=8, labelpad=1)
    axc.set_ylabel("cost", fontsize=8)

    # d_p +- sigma_p and <D>_p against the iteration
    dlo, dhi = float(d_ref.min()), float(d_ref.max())
    for it, c in records:
        dp, sp = float(c["d_p"]), float(c["sigma_p"])
        color = cmap(norm(it))
        axi.plot([it, it], [max(dp - sp, dlo - 1e3), min(dp + sp, dhi + 1e3)], color=color,
                 linewidth=1.0, alpha=0.5)
        face = color if bool(c.get("valid", True)) else "white"
        axi.plot([it], [dp], "o", markersize=3.5, markerfacecolor=face, markeredgecolor=color)
    mean_ds = [(int(it), float(c["mean_D"])) for it, c in records
               if c.get("mean_D") is not None and np.isfinite(c["mean_D"])]
    if mean_ds:
        axi.plot(*zip(*mean_ds), "--", color="black", linewidth=0.8,
                 label=r"$\langle D\rangle_p$")
    axi.plot([], [], "o-", color="0.4", markersize=3.5, linewidth=1.0,
             label=r"$d_p \pm \sigma_p$ (hollow: invalid)")
    axi.set_ylim(dlo, dhi)
    axi.set_xlim(lo - 0.5 - 0.02 * (hi - lo), hi + 0.5 + 0.02 * (hi - lo))
    axi.set_xlabel("iteration", fontsize=8, labelpad=1)
    axi.set_ylabel("d (px)", fontsize=8)
    axi.tick_params(labelsize=7)
    axi.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)
    axc.tick_params(labelsize=7)
    axc.legend(fontsize=6.5, loc="lower right", framealpha=0.8)
    if title:
        axc.set_title(title, fontsize=8)

    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    sm = ScalarMappable(norm=Normalize(lo, hi if hi > lo else lo + 1), cmap=cmap)
    sm.set_array([])
    cax = fig.add_axes(cbar_box)
    cb = fig.colorbar(sm, cax=cax)
    cb.set_label("iteration", fontsize=7)
    cb.ax.tick_params(labelsize=6)
    return fig
