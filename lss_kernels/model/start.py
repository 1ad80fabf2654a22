"""The initial region in the cyclopean frame, from a start given in the left view or in the
cyclopean frame (Sec. 4: the paper initialises phi from a region drawn by hand); an ellipse is
read as the box around it (:func:`region_in_ellipse`), other starts are found by
:mod:`lss_kernels.model.init`.

The frames differ by half the foreground's left-view disparity, ``x_left = x_c + c``; ``c`` is
estimated as the median first-consensus mean (Eq. 7 with no prior) over the region read as if
the frames coincided.
"""
import time

import numpy as np

from ..start_types import Box
from .init import CONTRAST, shift_columns
from .offset import info_to_user, to_model_left, to_model_start, to_user_left

__all__ = ["cyclopean_start", "ellipse_mask", "foreground_shift", "front_contrast",
           "initial_region", "region_in_ellipse"]

#: Width of the ring around a region that :func:`front_contrast` compares it with, pixels.
RING = 8


def foreground_shift(region: np.ndarray, mean: np.ndarray, precision: np.ndarray) -> float:
    """Half the foreground's left-view disparity: the median consensus ``mean`` (cyclopean
    units) over the pixels of ``region`` that have a consensus (``precision > 0``); 0 if
    none has."""
    sel = region & (precision > 0)
    return float(np.median(mean[sel])) if sel.any() else 0.0


def ellipse_mask(ellipse, shape: tuple, shift: float = 0.0) -> np.ndarray:
    """The pixels of ``shape`` inside the ellipse ``(cx, cy, rx, ry)`` moved ``shift``
    columns right."""
    cx, cy, rx, ry = (float(v) for v in ellipse)
    y, x = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    return ((x - cx - shift) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0


def cyclopean_start(init, init_frame: str, mean: np.ndarray, precision: np.ndarray) -> tuple:
    """``(cyclopean, left)``: the boolean initial region in both frames.

    ``init`` is an ellipse ``(cx, cy, rx, ry)`` or a boolean mask in the frame ``init_frame``
    (``"left"`` or ``"cyclopean"``), on the grid of ``mean`` and ``precision`` (the first
    consensus, cyclopean frame)."""
    if isinstance(init, np.ndarray):
        region = lambda shift: shift_columns(init, shift)
    else:
        region = lambda shift: ellipse_mask(init, mean.shape, shift)
    shift = foreground_shift(region(0.0), mean, precision)
    if init_frame == "left":
        return region(-shift), region(0.0)
    return region(0.0), region(shift)


def _dilated(mask: np.ndarray, r: int) -> np.ndarray:
    """``mask`` dilated by a ``(2r+1)`` square (pixels beyond the border count as False)."""
    out = mask.copy()
    for axis in (0, 1):
        grown = out.copy()
        n = out.shape[axis]
        for k in range(1, min(r, n - 1) + 1):
            lo, hi = [slice(None)] * 2, [slice(None)] * 2
            lo[axis], hi[axis] = slice(0, n - k), slice(k, n)
            grown[tuple(lo)] |= out[tuple(hi)]
            grown[tuple(hi)] |= out[tuple(lo)]
        out = grown
    return out


def front_contrast(region: np.ndarray, mean: np.ndarray, precision: np.ndarray,
                   ring: int = RING, exclude: np.ndarray = None) -> float:
    """How far ``region`` stands in front of what surrounds it: the median consensus
    ``mean`` (cyclopean units) of its pixels with a consensus (``precision > 0``) less that
    of the ring ``ring`` pixels wide around it, less the pixels of ``exclude`` (None: none);
    ``-inf`` when either has none.  A foreground lies in front of its background (Sec. 2),
    so a region found on the background (in the notch of an L) has a contrast near 0 or
    below."""
    around = _dilated(region, ring) & ~region
    if exclude is not None:
        around &= ~exclude
    inside, outside = region & (precision > 0), around & (precision > 0)
    if not inside.any() or not outside.any():
        return -np.inf
    return float(np.median(mean[inside]) - np.median(mean[outside]))


def region_in_ellipse(ellipse, frame: str, mean: np.ndarray, precision: np.ndarray,
                      find) -> tuple:
    """``Params.refine_ellipse``: the start that an ellipse ``(cx, cy, rx, ry)`` (in the
    model's left view or the cyclopean frame, ``frame``) stands for, as ``(start,
    start_frame, report)``: the object under its centre cut to the box around it, as a
    :class:`~lss_kernels.start_types.Box` starts (``(mask, "cyclopean", info)``), or
    ``(ellipse, frame, why)`` when the box finds no object, or finds one that is not
    ``CONTRAST`` in front of the ring around it (:func:`front_contrast`, less the object's
    own pixels beyond the box: in the notch of an L the centre lies on the background).

    ``mean``, ``precision``: the first consensus; ``find(box)`` runs
    :meth:`~lss_kernels.model.init.InitialRegion.find` on a box of the model's left view and
    returns ``(start, start_frame, info, grown)``, ``grown`` the region before its cut.  A
    cyclopean ellipse's box lies ``c`` columns right of it (``x_left = x_c + c``): ``c`` is
    first the ellipse's :func:`foreground_shift`, then, if the object found differs from it
    by more than half a pixel, the object's own (half its ``seed_disparity``)."""
    H, W = mean.shape
    cx, cy, rx, ry = (float(v) for v in ellipse)
    shift = 0.0
    if frame == "cyclopean":
        shift = foreground_shift(ellipse_mask(ellipse, mean.shape), mean, precision)
    for _ in range(2):
        box = Box(max(cx + shift - rx, 0.0), max(cy - ry, 0.0), min(cx + shift + rx, W),
                  min(cy + ry, H))
        if box.x1 - box.x0 < 1.0 or box.y1 - box.y0 < 1.0:
            return ellipse, frame, ("none (the ellipse's box covers less than a pixel of "
                                    "the image): the ellipse itself")
        start, start_frame, info, grown = find(box)
        if start_frame != "cyclopean":
            return ellipse, frame, f"none ({info['why']}): the ellipse itself"
        seed = info["centre"]["seed_disparity"] / 2.0
        if frame != "cyclopean" or abs(seed - shift) <= 0.5:
            break
        shift = seed
    info["front_contrast"] = contrast = 2.0 * front_contrast(start, mean, precision,
                                                             exclude=grown)
    if contrast == -np.inf:
        return ellipse, frame, "none (no consensus around the object): the ellipse itself"
    if not contrast > 2.0 * CONTRAST:
        return ellipse, frame, (f"none (the region under the centre is not in front of what "
                                f"surrounds it ({contrast:.1f} px)): the ellipse itself")
    return start, start_frame, info


def initial_region(init, init_frame: str, shift: int, mean: np.ndarray, precision: np.ndarray,
                   find, refine_ellipse: bool) -> tuple:
    """The start of a solve, ``(cyclopean, left, info)``: the boolean initial region in the
    cyclopean frame and in the user's left view, and the report :attr:`Solver.init_info`.

    ``init`` as :class:`~lss_kernels.Solver` takes it, in the user's frame ``init_frame``;
    ``shift``: the model's grid shift (:mod:`lss_kernels.model.offset`); ``mean``,
    ``precision``: the first consensus; ``find`` as for :func:`region_in_ellipse` (``"auto"``,
    a point and a box are found by it; an ellipse is read as its box with
    ``refine_ellipse``)."""
    info = {"kind": "mask" if isinstance(init, np.ndarray) else "ellipse"}
    t0 = time.perf_counter()
    if not isinstance(init, (np.ndarray, tuple)):
        init, init_frame, found, _ = find(to_model_start(init, shift))
        info = dict(info_to_user(found, shift), seconds=time.perf_counter() - t0)
    else:
        if init_frame == "left":        # the user's left view -> the model's
            init = (to_model_left(init, shift) if isinstance(init, np.ndarray)
                    else (init[0] + shift,) + tuple(init[1:]))
        if isinstance(init, tuple) and refine_ellipse:
            init, init_frame, report = region_in_ellipse(init, init_frame, mean, precision,
                                                         find)
            info["seconds"] = time.perf_counter() - t0
            info["region"] = (info_to_user(report, shift) if isinstance(report, dict)
                              else report)
    cyclopean, left = cyclopean_start(init, init_frame, mean, precision)
    return cyclopean, to_user_left(left, shift), info
