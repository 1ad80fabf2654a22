"""Readable numpy references of the kernels: the specification the tests and the benchmark
compare the Taichi kernels against.  Slow, simple, one function per kernel.

Frames and units are those of the kernels: cyclopean ``(H, W)`` arrays indexed ``[y, x]``,
cyclopean disparities ``c = 1 .. c_max`` (volume index ``k = c - 1``).
"""
import numpy as np

__all__ = [
    "matching_cost", "box_mean", "box_sum", "patch_costs", "patch_messages", "consensus",
    "upward_extremes", "median_filter", "gaussian_derivatives", "curvature", "delta_theta",
    "interp_row", "interp_volume", "levelset_step",
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


def patch_messages(cost, d_mean, beta, subpixel=True):
    """Eq. 5: d_p = argmin_c C_p(c) + beta |c - <D>_p| and sigma_p = c_max / (mean - min).

    ``cost``: ``(H, W, c_max)``; ``d_mean``: ``(H, W)`` patch mean of D; returns
    ``(d_p, sigma_p)`` (ties take the smallest c).  ``subpixel``: where the matching cost
    has a local minimum at the argmin, d_p moves to the vertex of the parabola through it and
    its two neighbours (not at the ends of the range, nor where the prior made the argmin)."""
    C = cost.shape[2]
    c = np.arange(1, C + 1, dtype=np.float64)
    total = cost + beta * np.abs(c[None, None, :] - np.asarray(d_mean)[..., None])
    k = np.argmin(total, axis=2)
    best = np.take_along_axis(total, k[..., None], axis=2)[..., 0]
    sigma = C / (total.mean(axis=2) - best + 1e-8)
    d_p = (k + 1).astype(np.float64)
    if subpixel:
        inner = (k > 0) & (k < C - 1)
        at = lambda j: np.take_along_axis(cost, np.clip(j, 0, C - 1)[..., None], axis=2)[..., 0]
        cm, c0, cp = at(k - 1), at(k), at(k + 1)
        den = cm - 2.0 * c0 + cp
        ok = inner & (c0 <= cm) & (c0 <= cp) & (den > 1e-12)
        d_p += np.where(ok, np.clip(0.5 * (cm - cp) / np.where(ok, den, 1.0), -0.5, 0.5), 0.0)
    return d_p, sigma


def consensus(d_p, sigma_p, valid, sizes):
    """Eq. 7: per pixel, 1/sigma^2 and d-bar from all valid patches (of every level) that
    contain it.  Lists per level of ``(H, W)`` arrays; returns ``(precision, mean)``."""
    # the patches containing a pixel are centred on the mirrored box (it matters for even
    # sizes): flip, box-sum, flip back
    gather = lambda a, size: box_sum(a[::-1, ::-1], size)[::-1, ::-1]
    a = sum(gather(np.where(v, 1.0 / s ** 2, 0.0), size)
            for s, v, size in zip(sigma_p, valid, sizes))
    b = sum(gather(np.where(v, d / s ** 2, 0.0), size)
            for d, s, v, size in zip(d_p, sigma_p, valid, sizes))
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(a > 1e-12 * max(a.max(), 1e-300), a, 0.0)  # summed-area round-off
        mean = np.where(a > 0, b / a, 0.0)
    return a, mean


def upward_extremes(a, size, reduce):
    """Max (``reduce=np.max``) or min of ``a`` over each centred patch (in-image pixels)."""
    H, W = a.shape
    h = size // 2
    out = np.empty((H, W), np.float64)
    for y in range(H):
        for x in range(W):
            out[y, x] = reduce(a[max(0, y - h):max(0, y - h + size),
                                 max(0, x - h):max(0, x - h + size)])
    return out


def median_filter(a, size):
    """Median over ``size x size`` windows with symmetric (mirror, edge repeated) borders."""
    h = size // 2
    p = np.pad(a, h, mode="symmetric")
    win = np.lib.stride_tricks.sliding_window_view(p, (size, size))
    return np.median(win, axis=(2, 3))


def gaussian_derivatives(phi, sigma):
    """phi_x, phi_y, phi_xx, phi_yy, phi_xy by separable Gaussian-derivative convolution
    (half-width ceil(3.5 sigma), symmetric borders)."""
    from ..kernels.filters import gaussian_taps
    g = gaussian_taps(sigma)
    h = (len(g[0]) - 1) // 2

    def conv(a, taps, axis):
        p = np.pad(a, [(h, h) if ax == axis else (0, 0) for ax in range(2)], mode="symmetric")
        out = np.zeros_like(a, dtype=np.float64)
        n = a.shape[axis]
        for i in range(-h, h + 1):
            sl = [slice(None)] * 2
            sl[axis] = slice(h - i, h - i + n)
            out += taps[i + h] * p[tuple(sl)]
        return out

    cx = [conv(phi, t, 1) for t in g]
    return (conv(cx[1], g[0], 0), conv(cx[0], g[1], 0), conv(cx[2], g[0], 0),
            conv(cx[0], g[2], 0), conv(cx[1], g[1], 0))


def curvature(phi, sigma, clip):
    """kappa = div(grad phi / |grad phi|) (clipped) and the unit normal (N_x, N_y)."""
    px, py, pxx, pyy, pxy = gaussian_derivatives(phi, sigma)
    norm = np.sqrt(px ** 2 + py ** 2) + 1e-10
    k = (pxx * py ** 2 - 2 * px * py * pxy + pyy * px ** 2) / norm ** 3
    return np.clip(k, -clip, clip), px / norm, py / norm


def delta_theta(theta1, theta2, phi_x, steps=6, c_cap=None):
    """The ray cast of Sec. 2 for callables ``theta1(x, y)``, ``theta2(x, y)`` (vectorised over
    arrays) on the grid of ``phi_x``: solves t = Theta_1(x) - Theta_2(x - s t) by fixed-point
    iteration; returns s t (0 where Theta_1 <= Theta_2 or phi_x = 0)."""
    H, W = phi_x.shape
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    s = np.sign(phi_x)
    t1 = theta1(x, y)
    jump = t1 - theta2(x, y)
    t = jump.copy()
    for _ in range(steps):
        t = np.clip(t1 - theta2(x - s * t, y), 0, np.inf if c_cap is None else c_cap)
    return np.where((jump > 0) & (s != 0), s * t, 0.0)


def interp_row(a, x):
    """Linear interpolation of each row of ``a`` at real positions ``x`` (same shape), clamped."""
    H, W = a.shape
    xf = np.clip(x, 0, W - 1)
    x0 = np.minimum(np.floor(xf).astype(int), W - 2)
    t = xf - x0
    rows = np.arange(H)[:, None]
    return (1 - t) * a[rows, x0] + t * a[rows, x0 + 1]


def interp_volume(vol, x, c):
    """vol[y, x, c - 1] at real x and c (bilinear, clamped), ``x`` and ``c`` of shape (H, W)."""
    H, W, C = vol.shape
    xf = np.clip(x, 0, W - 1)
    x0 = np.minimum(np.floor(xf).astype(int), W - 2)
    tx = xf - x0
    kf = np.clip(c - 1.0, 0, C - 1)
    k0 = np.minimum(np.floor(kf).astype(int), C - 2)
    tk = kf - k0
    y = np.arange(H)[:, None]
    at = lambda xx, kk: vol[y, xx, kk]
    a = (1 - tk) * at(x0, k0) + tk * at(x0, k0 + 1)
    b = (1 - tk) * at(x0 + 1, k0) + tk * at(x0 + 1, k0 + 1)
    return (1 - tx) * a + tx * b


def levelset_step(phi, cost1, theta1_map, theta2_map, dtheta, b_map, b_x, b_y, kappa, n_x,
                  n_y, dt, mu, clip):
    """Eq. 2: phi + dt delta(phi) [-M(x, Theta_1) + M(x - delta_theta, Theta_2)
    + mu clip(B kappa + N . grad B)], with delta(phi) = (1/pi) / (1 + phi^2)."""
    H, W = phi.shape
    x = np.broadcast_to(np.arange(W, dtype=np.float64), (H, W))
    m1 = interp_volume(cost1, x, theta1_map)
    m2 = interp_volume(cost1, x - dtheta, theta2_map)
    bt = np.clip(b_map * kappa + n_x * b_x + n_y * b_y, -clip, clip)
    return phi + dt * (1 / np.pi) / (1 + phi ** 2) * (-m1 + m2 + mu * bt)
