"""The initial region in the cyclopean frame, from a start given in the left view or in the
cyclopean frame (Sec. 4: the paper initialises phi from a region drawn by hand).

The frames differ by half the foreground's left-view disparity, ``x_left = x_c + c``; ``c`` is
estimated as the median first-consensus mean (Eq. 7 with no prior) over the region read as if
the frames coincided.
"""
import numpy as np

from .init import shift_columns

__all__ = ["cyclopean_start", "foreground_shift", "front_contrast"]

#: Width of the ring around a region that :func:`front_contrast` compares it with, pixels.
RING = 8


def foreground_shift(region: np.ndarray, mean: np.ndarray, precision: np.ndarray) -> float:
    """Half the foreground's left-view disparity: the median consensus ``mean`` (cyclopean
    units) over the pixels of ``region`` that have a consensus (``precision > 0``); 0 if
    none has."""
    sel = region & (precision > 0)
    return float(np.median(mean[sel])) if sel.any() else 0.0


def cyclopean_start(init, init_frame: str, mean: np.ndarray, precision: np.ndarray) -> tuple:
    """``(cyclopean, left)``: the boolean initial region in both frames.

    ``init`` is an ellipse ``(cx, cy, rx, ry)`` or a boolean mask in the frame ``init_frame``
    (``"left"`` or ``"cyclopean"``), on the grid of ``mean`` and ``precision`` (the first
    consensus, cyclopean frame)."""
    if isinstance(init, np.ndarray):
        region = lambda shift: shift_columns(init, shift)
    else:
        cx, cy, rx, ry = (float(v) for v in init)
        y, x = np.mgrid[0:mean.shape[0], 0:mean.shape[1]].astype(np.float64)
        region = lambda shift: ((x - cx - shift) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0
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
                   ring: int = RING) -> float:
    """How far ``region`` stands in front of what surrounds it: the median consensus
    ``mean`` (cyclopean units) of its pixels with a consensus (``precision > 0``) less that
    of the ring ``ring`` pixels wide around it; ``-inf`` when either has none.  A foreground
    lies in front of its background (Sec. 2), so a region found on the background (in the
    notch of an L) has a contrast near 0 or below."""
    around = _dilated(region, ring) & ~region
    inside, outside = region & (precision > 0), around & (precision > 0)
    if not inside.any() or not outside.any():
        return -np.inf
    return float(np.median(mean[inside]) - np.median(mean[outside]))
