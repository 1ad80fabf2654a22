"""Periodic texture along the rows: how much of an image repeats itself with a period of a
few pixels, read from the image alone, before a solve.

Stripes leave every match ambiguous by whole periods, and a model of the pair can look sound
at the wrong disparity.  In tiles of ``TILE`` pixels, the autocorrelation of the horizontal
grey-level gradient along the rows, at lags 1 to ``MAX_PERIOD`` pixels, is computed; a tile
is periodic when the correlation, after falling, rises back to a peak ``2 PERIODIC_SCORE``
above its lowest value at a smaller lag (stripes: from -1 at half the period to +1 at the
period, a rise of 2; real texture decorrelates and stays near 0).  An image with at least
``PERIODIC_AREA`` of its tiles periodic counts as periodic: :mod:`lss_kernels.checks.recovery`
solves it with distinctness-weighted messages first, and a start found from the first
consensus (a box, ``auto``) does not trust that consensus
(:meth:`~lss_kernels.model.init.InitialRegion.find`).
"""
import numpy as np

from .validate import luma

__all__ = ["MAX_PERIOD", "PERIODIC_AREA", "PERIODIC_SCORE", "TILE", "periodic_fraction",
           "periodic_share", "periodic_tiles", "periodicity"]

#: Rows and columns of the tiles in which periodicity is measured.
TILE = (16, 64)
#: Largest lag (period) searched, pixels.
MAX_PERIOD = 32
#: Half the rise of the autocorrelation back to a peak that makes a tile periodic.
PERIODIC_SCORE = 0.6
#: Fraction of periodic tiles from which an image counts as periodic.
PERIODIC_AREA = 0.05


def periodicity(image) -> np.ndarray:
    """Per tile of ``TILE`` pixels, how periodic the image is along its rows, in [0, 1]:
    half the largest rise of the normalised autocorrelation of the horizontal gradient of
    grey, from its lowest value at smaller lags to a local peak at a lag in
    ``2 .. MAX_PERIOD - 1``; 0 for flat tiles and where no peak follows a dip.  ``image``:
    ``(H, W)`` grey or ``(H, W, 3)`` RGB.  Tiles cover the image from the top left; the
    last ``MAX_PERIOD`` columns only serve as shifted copies.  Returns ``(rows, cols)``."""
    gx = np.diff(luma(image), axis=1)
    th, tw = TILE
    rows, cols = gx.shape[0] // th, (gx.shape[1] - MAX_PERIOD) // tw
    if rows <= 0 or cols <= 0:
        return np.zeros((max(rows, 0), max(cols, 0)))
    gx = gx[:rows * th]

    def tile_sums(a):
        return a.reshape(rows, th, cols, tw).sum(axis=(1, 3))

    base = gx[:, :cols * tw]
    energy = tile_sums(base * base)
    rho = np.empty((MAX_PERIOD, rows, cols))
    for lag in range(1, MAX_PERIOD + 1):
        shifted = gx[:, lag:lag + cols * tw]
        rho[lag - 1] = tile_sums(base * shifted) / np.sqrt(
            energy * tile_sums(shifted * shifted) + 1e-30)
    lowest = np.minimum.accumulate(rho, axis=0)
    peak = (rho[1:-1] >= rho[:-2]) & (rho[1:-1] >= rho[2:])
    rise = np.where(peak, (rho[1:-1] - lowest[:-2]) / 2.0, 0.0)
    score = np.clip(rise.max(axis=0), 0.0, 1.0)
    return np.where(energy > 1e-6 * th * tw, score, 0.0)


def periodic_tiles(score) -> float:
    """The fraction of the tiles of a :func:`periodicity` ``score`` above ``PERIODIC_SCORE``
    (0 for an image too small for one tile)."""
    return float((score > PERIODIC_SCORE).mean()) if score.size else 0.0


def periodic_fraction(image) -> float:
    """:func:`periodic_tiles` of ``image``'s :func:`periodicity`."""
    return periodic_tiles(periodicity(image))


def periodic_share(image) -> float:
    """:func:`periodic_fraction` of ``image`` when it reaches ``PERIODIC_AREA`` (the image
    counts as periodic), else 0."""
    fraction = periodic_fraction(image)
    return fraction if fraction >= PERIODIC_AREA else 0.0
