"""Flying pixels: points of a cloud that belong to neither the object nor its background.

A matcher that smooths across a depth jump puts points between the foreground and the
background surfaces: in a point cloud they hang in the air between the object and the wall.
Near a boundary every pixel has two true surfaces, the one it shows and the one on the other
side of the boundary; a point is *flying* when its disparity lies more than ``tolerance``
pixels from both.

The scene folders give the visible surface only (``disp_left``).  The other one is read
along the row, where the stereo geometry places it: the true disparities of the nearest
pixels of the other layer to the left and to the right (``fg_left`` says the layers; pixels of
unknown truth are skipped).  A pixel whose own layer continues smoothly under the boundary
has the other surface within a few pixels of it; a point that is on neither of these
disparities nor on its own lies between the surfaces (or off both).

The points counted are those of the evaluation band (``lss_kernels.metrics``: within
``BAND_RADIUS`` columns of the true boundary, truth known, the boundary pixels and their row
neighbours left out) that the method puts into its cloud: the pixels it does not label
occluded (an occluded pixel has no match and no point).
"""
from __future__ import annotations

import numpy as np

from .metrics import evaluation_masks

__all__ = ["TOLERANCE", "flying_pixels", "flying_share", "other_surface"]

#: Pixels: a point farther than this from both true surfaces is flying.
TOLERANCE = 1.0


def _nearest_along_rows(values, source):
    """For every pixel, ``values`` at the nearest ``source`` pixel of its row to the left
    and to the right (inf where there is none)."""
    H, W = source.shape
    columns = np.broadcast_to(np.arange(W), (H, W))
    rows = np.broadcast_to(np.arange(H)[:, None], (H, W))
    left = np.maximum.accumulate(np.where(source, columns, -1), axis=1)
    right = np.minimum.accumulate(np.where(source, columns, W)[:, ::-1], axis=1)[:, ::-1]
    from_left = np.where(left >= 0, values[rows, np.clip(left, 0, W - 1)], np.inf)
    from_right = np.where(right < W, values[rows, np.clip(right, 0, W - 1)], np.inf)
    return from_left, from_right


def other_surface(disp_true, fg_true):
    """The true disparities of the surface on the other side of the boundary, per pixel.

    Parameters
    ----------
    disp_true : ndarray, float, shape (H, W)
        True left-view disparity; non-finite = unknown.
    fg_true : ndarray, bool, shape (H, W)
        True left-view foreground.

    Returns
    -------
    from_left, from_right : ndarray, float64, shape (H, W)
        For a foreground pixel, the true disparity of the nearest background pixel of known
        truth on its row to the left and to the right; for a background pixel, those of the
        nearest foreground pixels; inf where the row has none on that side.
    """
    disp = np.asarray(disp_true, np.float64)
    fg = np.asarray(fg_true, bool)
    if disp.ndim != 2 or fg.shape != disp.shape:
        raise ValueError(f"fg_true: expected an array of shape {disp.shape} like disp_true, "
                         f"got shape {fg.shape}")
    known = np.isfinite(disp)
    bg_left, bg_right = _nearest_along_rows(disp, ~fg & known)
    fg_left, fg_right = _nearest_along_rows(disp, fg & known)
    return np.where(fg, bg_left, fg_left), np.where(fg, bg_right, fg_right)


def flying_pixels(disparity, points, disp_true, fg_true, tolerance: float = TOLERANCE):
    """Which of ``points`` are flying: farther than ``tolerance`` from the true disparity
    and from both of :func:`other_surface`'s.

    Parameters
    ----------
    disparity : ndarray, float, shape (H, W)
        The method's left-view disparity (non-finite: flying).
    points : ndarray, bool, shape (H, W)
        The pixels counted (of known truth).
    disp_true, fg_true : ndarray, shape (H, W)
        As :func:`other_surface`.

    Returns
    -------
    ndarray, bool, shape (H, W)
        False outside ``points``.
    """
    d = np.asarray(disparity, np.float64)
    if d.shape != np.shape(disp_true):
        raise ValueError(f"disparity: expected an array of shape {np.shape(disp_true)} like "
                         f"the ground truth, got shape {d.shape}")
    from_left, from_right = other_surface(disp_true, fg_true)
    near = lambda surface: np.abs(d - surface) <= tolerance
    with np.errstate(invalid="ignore"):
        on_a_surface = near(np.asarray(disp_true, np.float64)) | near(from_left) | near(from_right)
    return np.asarray(points, bool) & ~on_a_surface


def flying_share(disparity, occlusion, scene, masks=None) -> dict:
    """The share of the band's cloud points that are flying, on a scene with ground truth.

    Parameters
    ----------
    disparity : ndarray, float, shape (H, W)
        The method's left-view disparity.
    occlusion : ndarray, bool, shape (H, W)
        Its occlusion labels: those pixels are not points.
    scene : lss_kernels.io.Scene
        Needs ``disp_left``, ``occ_left`` and ``fg_left``.
    masks : dict, optional
        :func:`lss_kernels.metrics.evaluation_masks` of the scene.

    Returns
    -------
    dict
        ``flying`` (percent of the band's points), ``n_points`` (the band's points) and
        ``n_flying``; ``flying`` is NaN without a ``fg_left`` or without points.
    """
    if scene.fg_left is None:
        return {"flying": float("nan"), "n_points": 0, "n_flying": 0}
    if masks is None:
        masks = evaluation_masks(scene)
    points = masks["band"] & ~np.asarray(occlusion, bool)
    flying = flying_pixels(disparity, points, scene.disp_left, scene.fg_left)
    n_points, n_flying = int(points.sum()), int(flying.sum())
    share = 100.0 * n_flying / n_points if n_points else float("nan")
    return {"flying": share, "n_points": n_points, "n_flying": n_flying}
