"""Classical peers of Table 1: OpenCV semi-global matching and block matching, each with a
left-right consistency check that labels occlusions.

The paper compares its occlusion labels with those of "SGM with occlusion label" and "block
matching with LR-consistency check (BM-LR)".  Both are run here the same way:

1. the matcher computes the left-view disparity ``d_L`` of the pair;
2. it computes the right-view disparity ``d_R`` of the *mirrored* pair (both images flipped
   horizontally and swapped, so the right image becomes the reference), flipped back;
3. a left pixel ``x`` is occluded when ``d_L(x)`` is invalid (the matcher rejected it), when its
   match ``x - d_L(x)`` falls outside the right image, or when
   ``|d_L(x) - d_R(x - d_L(x))| > 1`` (an invalid ``d_R`` there fails the check too).

OpenCV leaves the leftmost ``numDisparities`` columns without an estimate; the images are padded
on the left by that many replicated columns and the result is cropped back, so every pixel of the
input gets one.  Occluded pixels keep a finite disparity so that bad-4.0 can score them: each
takes the nearest non-occluded disparity along its row on the background side, i.e. the
*smaller* of its nearest non-occluded neighbours to the left and to the right (an occlusion is
background seen by one camera only, and the background is the farther, smaller-disparity
surface).  A row without any non-occluded pixel is filled with 0.

OpenCV is an optional dependency (``pip install "lss-kernels[baselines]"``); importing this
module never needs it, calling a matcher does.

All images are float32 ``H x W x 3`` arrays in [0, 1]; all outputs are in the left view with the
convention ``x_right = x_left - d``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["METHODS", "OPENCV_MISSING", "bm_lr", "lr_check", "require_opencv", "sgm",
           "sgm_lr_difference"]

OPENCV_MISSING = 'baselines need OpenCV: pip install "lss-kernels[baselines]"'

_LR_TOLERANCE = 1.0  # pixels, the consistency tolerance |d_L - d_R|
_INVALID = -1.0       # disparity of a pixel the matcher rejected


def require_opencv():
    """Return the ``cv2`` module, or raise a one-line ``ImportError`` telling how to install it."""
    try:
        import cv2
    except ImportError:
        raise ImportError(OPENCV_MISSING) from None
    return cv2


def _num_disparities(d_max: float) -> int:
    """``d_max`` rounded up to a multiple of 16 (OpenCV's requirement), at least 16."""
    if not np.isfinite(d_max) or d_max <= 0:
        raise ValueError(f"d_max: expected a positive number, got {d_max!r}")
    return 16 * max(1, int(np.ceil(d_max / 16.0)))


def _to_uint8(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"images: expected an H x W x 3 array, got shape {image.shape}")
    return np.clip(image * 255.0 + 0.5, 0, 255).astype(np.uint8)


def _padded_disparity(matcher, left: np.ndarray, right: np.ndarray, pad: int) -> np.ndarray:
    """Left-view disparity of one pair (uint8 images), padded on the left by ``pad`` replicated
    columns and cropped back; rejected pixels are ``_INVALID``."""
    cv2 = require_opencv()
    widen = lambda im: cv2.copyMakeBorder(im, 0, 0, pad, 0, cv2.BORDER_REPLICATE)
    raw = matcher.compute(widen(left), widen(right))[:, pad:]
    disparity = raw.astype(np.float32) / 16.0  # OpenCV returns fixed point with 4 fraction bits
    disparity[raw < 0] = _INVALID
    return disparity


def _both_views(matcher, left: np.ndarray, right: np.ndarray, pad: int):
    """Left-view disparity of the pair and right-view disparity from the mirrored pair."""
    d_left = _padded_disparity(matcher, left, right, pad)
    mirrored = _padded_disparity(matcher, np.ascontiguousarray(right[:, ::-1]),
                                 np.ascontiguousarray(left[:, ::-1]), pad)
    return d_left, mirrored[:, ::-1]


def lr_check(disparity_left: np.ndarray, disparity_right: np.ndarray,
             tolerance: float = _LR_TOLERANCE) -> np.ndarray:
    """Occlusion mask of the left view from a left-right consistency check.

    Parameters
    ----------
    disparity_left : (H, W) float array
        Left-view disparity; negative values mark pixels the matcher rejected.
    disparity_right : (H, W) float array
        Right-view disparity (a right pixel ``x_r`` matches left pixel ``x_r + d_R``); negative
        values mark rejected pixels.
    tolerance : float
        Largest accepted ``|d_L(x) - d_R(x - d_L(x))|`` in pixels.

    Returns
    -------
    occlusion : (H, W) bool array
        True where ``d_L`` is rejected, where the match ``round(x - d_L(x))`` leaves the right
        image, or where the two views disagree by more than ``tolerance`` (a rejected ``d_R``
        at the match disagrees).

    Examples
    --------
    A foreground at disparity 3 over a background at 0: the left camera sees background at
    columns 0-2 that the foreground hides from the right camera.

    >>> dl = np.array([[0., 0., 0., 3., 3., 3.]])
    >>> dr = np.array([[3., 3., 3., 0., 0., 0.]])
    >>> lr_check(dl, dr)
    array([[ True,  True,  True, False, False, False]])
    """
    d_left = np.asarray(disparity_left, dtype=np.float32)
    d_right = np.asarray(disparity_right, dtype=np.float32)
    height, width = d_left.shape
    valid = d_left >= 0
    x_match = np.rint(np.arange(width, dtype=np.float32)[None, :] - np.where(valid, d_left, 0))
    x_match = x_match.astype(np.int64)
    inside = valid & (x_match >= 0) & (x_match < width)
    rows = np.broadcast_to(np.arange(height)[:, None], d_left.shape)
    d_back = d_right[rows, np.clip(x_match, 0, width - 1)]
    consistent = inside & (d_back >= 0) & (np.abs(d_left - d_back) <= tolerance)
    return ~consistent


def _fill_background(disparity: np.ndarray, occlusion: np.ndarray) -> np.ndarray:
    """Give every occluded pixel the smaller of its nearest non-occluded disparities to the left
    and to the right along its row (the background side); 0 where a row has none."""
    height, width = disparity.shape
    columns = np.broadcast_to(np.arange(width), disparity.shape)
    known = ~occlusion
    last_left = np.maximum.accumulate(np.where(known, columns, -1), axis=1)
    next_right = np.minimum.accumulate(np.where(known, columns, width)[:, ::-1], axis=1)[:, ::-1]
    rows = np.broadcast_to(np.arange(height)[:, None], disparity.shape)
    from_left = np.where(last_left >= 0, disparity[rows, np.clip(last_left, 0, width - 1)],
                         np.inf)
    from_right = np.where(next_right < width,
                          disparity[rows, np.clip(next_right, 0, width - 1)], np.inf)
    fill = np.minimum(from_left, from_right)
    fill[~np.isfinite(fill)] = 0.0
    return np.where(occlusion, fill, disparity).astype(np.float32)


def _run(matcher, left8: np.ndarray, right8: np.ndarray, pad: int):
    d_left, d_right = _both_views(matcher, left8, right8, pad)
    occlusion = lr_check(d_left, d_right)
    return _fill_background(d_left, occlusion), occlusion


def sgm(left: np.ndarray, right: np.ndarray, d_max: float, block_size: int = 5):
    """Semi-global matching (OpenCV ``StereoSGBM``, full 8-path ``MODE_HH``) with occlusions
    from a left-right consistency check.

    Parameters
    ----------
    left, right : (H, W, 3) float32 arrays in [0, 1]
        Rectified pair; the left image is the reference.
    d_max : float
        Largest disparity to search; OpenCV searches ``[0, 16 * ceil(d_max / 16))``.
    block_size : int
        Side of the matching block (odd).  The smoothness penalties are OpenCV's usual
        ``P1 = 8 * 3 * block_size**2`` and ``P2 = 32 * 3 * block_size**2``.

    Returns
    -------
    disparity : (H, W) float32 array
        Left-view disparity; occluded pixels hold the background-side fill described in the
        module docstring, so every value is finite.
    occlusion : (H, W) bool array
        Left-view occlusion labels (unmatched or inconsistent pixels).

    Raises
    ------
    ImportError
        One line, when OpenCV is not installed.

    References
    ----------
    H. Hirschmüller, "Stereo processing by semiglobal matching and mutual information",
    TPAMI 2008.
    """
    num = _num_disparities(d_max)
    return _run(_sgbm(num, block_size), _to_uint8(left), _to_uint8(right), num)


def _sgbm(num: int, block_size: int):
    """OpenCV's StereoSGBM as :func:`sgm` sets it up."""
    cv2 = require_opencv()
    area = 3 * block_size * block_size
    return cv2.StereoSGBM.create(
        minDisparity=0, numDisparities=num, blockSize=block_size, P1=8 * area, P2=32 * area,
        disp12MaxDiff=-1, preFilterCap=63, uniquenessRatio=10, speckleWindowSize=0,
        speckleRange=0, mode=cv2.StereoSGBM_MODE_HH)


def sgm_lr_difference(left: np.ndarray, right: np.ndarray, d_max: float,
                      block_size: int = 5) -> np.ndarray:
    """SGBM's left-right difference ``|d_L(x) - d_R(x - d_L(x))|`` per left pixel (the
    views of :func:`sgm`), the usual confidence of a classical matcher (smaller: surer);
    inf where ``d_L`` or ``d_R`` is rejected or the match leaves the right image."""
    num = _num_disparities(d_max)
    d_left, d_right = _both_views(_sgbm(num, block_size), _to_uint8(left), _to_uint8(right),
                                  num)
    height, width = d_left.shape
    valid = d_left >= 0
    x_match = np.rint(np.arange(width)[None, :] - np.where(valid, d_left, 0)).astype(np.int64)
    inside = valid & (x_match >= 0) & (x_match < width)
    d_back = d_right[np.arange(height)[:, None], np.clip(x_match, 0, width - 1)]
    return np.where(inside & (d_back >= 0), np.abs(d_left - d_back), np.inf).astype(np.float32)


def bm_lr(left: np.ndarray, right: np.ndarray, d_max: float, block_size: int = 11):
    """Block matching (OpenCV ``StereoBM`` on 8-bit grayscale) with occlusions from a
    left-right consistency check (BM-LR of the paper's Table 1).

    Parameters
    ----------
    left, right : (H, W, 3) float32 arrays in [0, 1]
        Rectified pair; the left image is the reference.
    d_max : float
        Largest disparity to search; OpenCV searches ``[0, 16 * ceil(d_max / 16))``.
    block_size : int
        Side of the matching block (odd, 5..255).

    Returns
    -------
    disparity : (H, W) float32 array
        Left-view disparity, occluded pixels filled from the background side (finite).
    occlusion : (H, W) bool array
        Left-view occlusion labels.

    Raises
    ------
    ImportError
        One line, when OpenCV is not installed.
    """
    cv2 = require_opencv()
    num = _num_disparities(d_max)
    matcher = cv2.StereoBM.create(numDisparities=num, blockSize=block_size)
    matcher.setUniquenessRatio(10)
    matcher.setTextureThreshold(10)
    gray = lambda im: cv2.cvtColor(_to_uint8(im), cv2.COLOR_RGB2GRAY)
    return _run(matcher, gray(left), gray(right), num)


METHODS = {"sgm": sgm, "bm-lr": bm_lr}
