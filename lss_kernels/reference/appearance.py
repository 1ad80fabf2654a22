"""Readable numpy specification of the layers' colour term (:mod:`lss_kernels.model.
appearance`).  Plain loops, float64."""
import numpy as np

from ..model.appearance import BINS, CLIP

__all__ = ["appearance_term"]


def _colour(image, y, x):
    """``image`` at row y and real column x, linear between columns, clamped."""
    W = image.shape[1]
    xf = min(max(x, 0.0), W - 1.0)
    x0 = min(int(np.floor(xf)), max(W - 2, 0))
    x1 = min(x0 + 1, W - 1)
    t = xf - x0
    return (1.0 - t) * image[y, x0] + t * image[y, x1]


def _bin(left, right, y, x, theta):
    colour = 0.5 * (_colour(left, y, x + theta) + _colour(right, y, x - theta))
    q = [min(max(int(c * BINS), 0), BINS - 1) for c in colour]
    return (q[0] * BINS + q[1]) * BINS + q[2]


def appearance_term(left, right, phi, theta_1, theta_2, precision, weight, band):
    """The Eq. 2 colour term of every pixel: ``left``, ``right`` ``(H, W, 3)`` in [0, 1];
    ``phi``, ``theta_1``, ``theta_2`` (cyclopean disparity), ``precision`` ``(H, W)``."""
    H, W = phi.shape
    n = BINS ** 3
    counts = np.zeros((2, n))
    precision_sum = 0.0
    in_band = []
    for y in range(H):
        for x in range(W):
            if abs(phi[y, x]) < band:
                j = 0 if phi[y, x] > 0 else 1
                theta = (theta_1, theta_2)[j][y, x]
                counts[j, _bin(left, right, y, x, theta)] += 1
                precision_sum += precision[y, x]
                in_band.append((y, x))
    mean_precision = precision_sum / max(len(in_band), 1)
    log_p = np.log((counts + 1.0) / (counts.sum(axis=1, keepdims=True) + n))
    out = np.zeros((H, W))
    for y, x in in_band:
        ratio = (log_p[0, _bin(left, right, y, x, theta_1[y, x])]
                 - log_p[1, _bin(left, right, y, x, theta_2[y, x])])
        ratio = min(max(ratio, -CLIP), CLIP)
        out[y, x] = weight * ratio / (1.0 + precision[y, x] / max(mean_precision, 1e-12))
    return out
