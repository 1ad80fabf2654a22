"""Occlusion F1 and bad-4.0 near the true boundary: the paper's protocol (Sec. 4).

Following ``docs/scene-format.md`` (the authors' release), with all arrays ``(H, W)`` in the left view:

- ``keep`` = finite ground-truth disparity, minus the true boundary pixels and their left and
  right neighbours;
- evaluation band = ``(roi_fg | roi_bg) & keep``;
- true occlusions = ``occ_left & roi_bg & keep``;
- occlusion F1: precision and recall of the predicted occlusion mask inside the band against the
  true occlusions;
- bad-4.0: percentage of band pixels that are not truly occluded where ``|d_pred - d_true| > 4``;
  a non-finite prediction (NaN, inf) counts as bad.

Conventions for the cases the protocol leaves open:

- no predicted occlusion in the band: precision = 1 (nothing predicted wrongly);
- no true occlusion in the band: recall = 1 (nothing missed);
- F1 = 2PR / (P + R), and 0 when P + R = 0; so F1 = 1 when both sets are empty and 0 when
  exactly one is;
- no scored pixel for bad-4.0: bad-4.0 = 0;
- without a boundary mask (``boundary.png`` absent) no pixel is excluded as boundary: the
  README lists the file as optional and gives no rule to derive it.  Without ``roi_fg.png`` /
  ``roi_bg.png`` the band is computed from ``fg_left`` by :func:`band_from_foreground`.
"""
from __future__ import annotations

import numpy as np

__all__ = ["BAD_THRESHOLD", "BAND_RADIUS", "band_from_foreground", "boundary_from_foreground",
           "evaluation_masks", "score", "score_arrays"]

#: Half-width of the evaluation band, in pixels along the row (the paper's ±20).
BAND_RADIUS = 20
#: Disparity error (pixels) above which a pixel is bad (bad-4.0).
BAD_THRESHOLD = 4.0


def _mask2d(mask, name: str, shape=None) -> np.ndarray:
    """``mask`` as a bool ``(H, W)`` array, of ``shape`` when given."""
    m = np.asarray(mask)
    if m.ndim != 2 or (shape is not None and m.shape != tuple(shape)):
        want = "HxW" if shape is None else f"{tuple(shape)} like the ground truth"
        raise ValueError(f"{name}: expected an array of shape {want}, got shape {m.shape}")
    return m != 0 if m.dtype != bool else m


def _dilate_rows(mask: np.ndarray, radius: int) -> np.ndarray:
    """Pixels within ``radius`` columns (same row) of a True pixel of ``mask`` (H, W)."""
    h, w = mask.shape
    c = np.zeros((h, w + 2 * radius + 1), dtype=np.int64)
    np.cumsum(np.pad(mask, ((0, 0), (radius, radius))), axis=1, out=c[:, 1:])
    return (c[:, 2 * radius + 1:] - c[:, :w]) > 0


def boundary_from_foreground(fg_left) -> np.ndarray:
    """True boundary pixels: foreground pixels with a background left or right neighbour.

    Parameters
    ----------
    fg_left : ndarray, bool, shape (H, W)
        Left-view foreground mask.

    Returns
    -------
    ndarray, bool, shape (H, W)
        The image border is not a neighbour.  On the Middlebury scenes of ``paper15`` this is
        the release's ``boundary.png`` (exactly for scene 2).
    """
    fg = _mask2d(fg_left, "fg_left")
    change = fg[:, 1:] != fg[:, :-1]
    out = np.zeros_like(fg)
    out[:, :-1] |= change
    out[:, 1:] |= change
    return out & fg


def band_from_foreground(fg_left, radius: int = BAND_RADIUS):
    """The evaluation band: pixels within ``radius`` columns of a true boundary pixel.

    The band is epipolar: it extends along the row only, ``radius`` pixels either side of each
    pixel of :func:`boundary_from_foreground` (``2 * radius + 1`` pixels per boundary pixel).  On
    the Middlebury scenes of ``paper15`` this reproduces the release's ``roi_fg | roi_bg``
    (exactly for scene 2).

    Parameters
    ----------
    fg_left : ndarray, bool, shape (H, W)
        Left-view foreground mask.
    radius : int
        Half-width of the band in pixels.

    Returns
    -------
    roi_fg, roi_bg : ndarray, bool, shape (H, W)
        The foreground and background parts of the band.
    """
    if int(radius) != radius or radius < 0:
        raise ValueError(f"radius: expected an integer >= 0, got {radius!r}")
    fg = _mask2d(fg_left, "fg_left")
    band = _dilate_rows(boundary_from_foreground(fg), int(radius))
    return band & fg, band & ~fg


def _masks(disp_true, occ_true, roi_fg, roi_bg, boundary) -> dict:
    """band, true_occ and keep (bool (H, W)) from validated ground-truth arrays."""
    disp_true = np.asarray(disp_true)
    if disp_true.ndim != 2:
        raise ValueError(f"disp_true: expected an array of shape HxW, got shape {disp_true.shape}")
    shape = disp_true.shape
    keep = np.isfinite(disp_true)
    if boundary is not None:
        b = _mask2d(boundary, "boundary", shape)
        excluded = b.copy()
        excluded[:, 1:] |= b[:, :-1]
        excluded[:, :-1] |= b[:, 1:]
        keep &= ~excluded
    roi_bg = _mask2d(roi_bg, "roi_bg", shape)
    band = (_mask2d(roi_fg, "roi_fg", shape) | roi_bg) & keep
    true_occ = _mask2d(occ_true, "occ_true", shape) & roi_bg & keep
    return {"band": band, "true_occ": true_occ, "keep": keep}


def evaluation_masks(scene) -> dict:
    """The masks of the protocol for a scene.

    Parameters
    ----------
    scene : lss_kernels.io.Scene
        Needs ``disp_left`` and ``occ_left``; ``roi_fg`` / ``roi_bg`` (else computed from
        ``fg_left``) and ``boundary`` (else nothing excluded) are optional.

    Returns
    -------
    dict of ndarray, bool, shape (H, W)
        ``band`` (the evaluation band), ``true_occ`` (the true occlusions in it) and ``keep``
        (pixels with a valid ground truth, away from the true boundary).
    """
    for key in ("disp_left", "occ_left"):
        if getattr(scene, key) is None:
            raise ValueError(f"scene {scene.name}: no ground truth '{key}' to score against")
    roi_fg, roi_bg = scene.roi_fg, scene.roi_bg
    if roi_fg is None or roi_bg is None:
        if scene.fg_left is None:
            raise ValueError(f"scene {scene.name}: needs roi_fg and roi_bg, or fg_left to "
                             "compute the evaluation band")
        roi_fg, roi_bg = band_from_foreground(scene.fg_left)
    return _masks(scene.disp_left, scene.occ_left, roi_fg, roi_bg, scene.boundary)


def _scores(disparity, occlusion, disp_true, masks) -> dict:
    """Occlusion precision / recall / F1 and bad-4.0 of predictions against the masks."""
    shape = masks["band"].shape
    disparity = np.asarray(disparity, dtype=np.float64)
    if disparity.shape != shape:
        raise ValueError(f"disparity: expected an array of shape {shape} like the ground truth, "
                         f"got shape {disparity.shape}")
    band, true_occ = masks["band"], masks["true_occ"]
    pred_occ = _mask2d(occlusion, "occlusion", shape) & band
    n_pred, n_true = int(pred_occ.sum()), int(true_occ.sum())
    n_tp = int((pred_occ & true_occ).sum())
    precision = n_tp / n_pred if n_pred else 1.0
    recall = n_tp / n_true if n_true else 1.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0

    scored = band & ~true_occ
    with np.errstate(invalid="ignore"):
        err = np.abs(disparity[scored] - np.asarray(disp_true, dtype=np.float64)[scored])
    bad = ~(err <= BAD_THRESHOLD)          # NaN (non-finite prediction) is bad
    bad4 = 100.0 * float(bad.mean()) if bad.size else 0.0
    return {"occ_f1": float(f1), "occ_precision": float(precision), "occ_recall": float(recall),
            "bad4": bad4, "n_band": int(band.sum()), "n_true_occ": n_true, "n_pred_occ": n_pred}


def score_arrays(disparity, occlusion, disp_true, occ_true, roi_fg, roi_bg,
                 boundary=None) -> dict:
    """Score a left-view prediction against ground-truth arrays (the module's protocol).

    Parameters
    ----------
    disparity : ndarray, float, shape (H, W)
        Predicted left-view disparity; NaN / inf count as bad.
    occlusion : ndarray, bool, shape (H, W)
        Predicted left-view occlusion mask (seen by the left camera only).
    disp_true : ndarray, float, shape (H, W)
        True left-view disparity; non-finite = unknown (not scored).
    occ_true, roi_fg, roi_bg : ndarray, bool, shape (H, W)
        True occlusions, and the foreground / background parts of the band.
    boundary : ndarray, bool, shape (H, W), optional
        True boundary pixels; they and their row neighbours are not scored.

    Returns
    -------
    dict
        ``occ_f1``, ``occ_precision``, ``occ_recall`` (in [0, 1]), ``bad4`` (percentage, in
        [0, 100]), ``n_band`` (band pixels), ``n_true_occ`` (true occlusions in the band) and
        ``n_pred_occ`` (predicted occlusions in the band).
    """
    masks = _masks(disp_true, occ_true, roi_fg, roi_bg, boundary)
    return _scores(disparity, occlusion, disp_true, masks)


def score(disparity, occlusion, scene, masks=None) -> dict:
    """Score a left-view prediction on a scene: :func:`score_arrays` with the scene's truth.

    Parameters
    ----------
    disparity : ndarray, float, shape (H, W)
        Predicted left-view disparity.
    occlusion : ndarray, bool, shape (H, W)
        Predicted left-view occlusion mask.
    scene : lss_kernels.io.Scene
        See :func:`evaluation_masks` for the fields it needs.
    masks : dict, optional
        ``evaluation_masks(scene)``, computed once by a caller that scores many predictions
        of the same scene.

    Returns
    -------
    dict
        As :func:`score_arrays`.
    """
    if masks is None:
        masks = evaluation_masks(scene)
    return _scores(disparity, occlusion, scene.disp_left, masks)
