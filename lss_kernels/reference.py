"""Readable numpy references of the kernels: the specification the tests and the benchmark
compare the Taichi kernels against.  Slow, simple, one function per kernel.

Frames and units are those of the kernels: cyclopean ``(H, W)`` arrays indexed ``[y, x]``,
cyclopean disparities ``c = 1 .. c_max`` (volume index ``k = c - 1``).
"""
import numpy as np

__all__ = [
    "matching_cost", "box_mean", "box_sum", "patch_costs", "patch_messages", "consensus",
]


def matching_cost(left, right, c_max):
    """M[y, x, k] = mean over RGB of |L(y, x + c) - R(y, x - c)|, ``c = k + 1``, with image
    coordinates clamped to the border.  ``left``, ``right``: ``(H, W, 3)`` in [0, 1]."""
    H, W, _ = left.shape
    x = np.arange(W)
    M = np.empty((H, W, c_max), np.float64)
    for k in range(c_max):
        c = k + 1
        xl = np.minimum(x + c, W - 1)
        xr = np.maximum(x - c, 0)
        M[:, :, k] = np.abs(left[:, xl] - right[:, xr]).mean(axis=2)
    return M


def box_sum(a, size):
    """Sum of ``a`` (``(H, W)`` or ``(H, W, K)``) over the ``size x size`` box centred on each
    pixel (covering ``[x - size // 2, x - size // 2 + size - 1]``), zero outside the image."""
    h = size // 2
    pad = [(h, size - 1 - h), (h, size - 1 - h)] + [(0, 0)] * (a.ndim - 2)
    p = np.pad(np.asarray(a, np.float64), pad)
    c = np.cumsum(np.cumsum(p, axis=0), axis=1)
    c = np.pad(c, [(1, 0), (1, 0)] + [(0, 0)] * (a.ndim - 2))
    H, W = a.shape[:2]
    return (c[size:size + H, size:size + W] - c[:H, size:size + W]
            - c[size:size + H, :W] + c[:H, :W])


def box_mean(a, size):
    """Mean over the in-image pixels of the centred ``size x size`` box."""
    n = box_sum(np.ones(a.shape[:2]), size)
    return box_sum(a, size) / (n if a.ndim == 2 else n[..., None])


def patch_costs(left, right, c_max, sizes):
    """Per level: the patch-mean matching cost, min-max normalised to [0, 1]."""
    M = matching_cost(left, right, c_max)
    out = []
    for s in sizes:
        v = box_mean(M, s)
        out.append((v - v.min()) / max(v.max() - v.min(), 1e-12))
    return out


def patch_messages(cost, d_mean, beta, valid=None):
    """Eq. 5: d_p = argmin_c C_p(c) + beta |c - <D>_p| and sigma_p = c_max / (mean - min).

    ``cost``: ``(H, W, c_max)``; ``d_mean``: ``(H, W)`` patch mean of D; returns
    ``(d_p, sigma_p)`` (ties take the smallest c)."""
    C = cost.shape[2]
    c = np.arange(1, C + 1, dtype=np.float64)
    total = cost + beta * np.abs(c[None, None, :] - np.asarray(d_mean)[..., None])
    k = np.argmin(total, axis=2)
    best = np.take_along_axis(total, k[..., None], axis=2)[..., 0]
    sigma = C / (total.mean(axis=2) - best + 1e-8)
    return (k + 1).astype(np.float64), sigma


def consensus(d_p, sigma_p, valid, sizes):
    """Eq. 7: per pixel, 1/sigma^2 and d-bar from all valid patches (of every level) that
    contain it.  Lists per level of ``(H, W)`` arrays; returns ``(precision, mean)``."""
    a = sum(box_sum(np.where(v, 1.0 / s ** 2, 0.0), size)
            for s, v, size in zip(sigma_p, valid, sizes))
    b = sum(box_sum(np.where(v, d / s ** 2, 0.0), size)
            for d, s, v, size in zip(d_p, sigma_p, valid, sizes))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(a > 0, b / a, 0.0)
    return a, mean
