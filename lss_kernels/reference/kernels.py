"""Readable numpy specifications of the kernels, one function per kernel: what the tests hold
the Taichi kernels to and what :mod:`lss_kernels.reference.iteration` composes into one whole
iteration.  Plain, vectorised, float64.

Frames and units are those of the kernels: cyclopean ``(H, W)`` arrays indexed ``[y, x]``,
cyclopean disparities ``c = 1 .. c_max`` (volume index ``k = c - 1``); Theta over the
normalised basis (``x_n = (x - (W - 1) / 2) / s``, ``y_n = (y - (H - 1) / 2) / s``,
``s = max(H, W) / 2``).
"""
import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..kernels.filters import gaussian_taps
from ..model import FIXED_POINT_STEPS
from ..model.quadratic import basis, evaluate

__all__ = [
    "census", "matching_cost", "box_sum", "box_mean", "box_extreme", "patches_containing",
    "patch_costs", "patch_messages", "second_best", "distinctness", "consensus",
    "median_filter", "convolve", "gaussian_derivatives", "curvature", "interp_row",
    "interp_volume", "shape_value", "basis", "fit_shape", "delta_theta", "boundary_weight",
    "levelset_step", "squared_distance", "reinitialise", "disparity", "near_pixels", "dilate",
    "grow_region",
]


# ---------------------------------------------------------------------------- costs (Sec. 4)
def census(image, radius=3):
    """Census transform: per pixel, the bits ``grey(neighbour) < grey(centre)`` over the
    ``(2 radius + 1)^2 - 1`` neighbours (clamped at the borders), as a boolean array."""
    grey = image @ np.array([0.299, 0.587, 0.114])
    H, W = grey.shape
    y, x = np.mgrid[0:H, 0:W]
    bits = [grey[np.clip(y + dy, 0, H - 1), np.clip(x + dx, 0, W - 1)] < grey
            for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)
            if dy or dx]
    return np.stack(bits, axis=-1)


def matching_cost(left, right, c_max, kind="ad"):
    """M[y, x, k] for ``c = k + 1``: the left pixel ``(y, x + c)`` against the right pixel
    ``(y, x - c)`` (clamped to the border); ``left``, ``right``: ``(H, W, 3)`` in [0, 1].
    ``"ad"``: mean over RGB of the absolute difference; ``"ad_census"``:
    ``rho(AD, 10/255) + rho(Hamming of the 7x7 census / 48, 30/63)``,
    ``rho(v, l) = 1 - exp(-v / l)``."""
    H, W, _ = left.shape
    x = np.arange(W)
    M = np.empty((H, W, c_max), np.float64)
    if kind == "ad_census":
        cl, cr = census(left), census(right)
    for k in range(c_max):
        c = k + 1
        xl, xr = np.minimum(x + c, W - 1), np.maximum(x - c, 0)
        M[:, :, k] = np.abs(left[:, xl] - right[:, xr]).mean(axis=2)
        if kind == "ad_census":
            hamming = (cl[:, xl] != cr[:, xr]).sum(axis=2) / 48.0
            M[:, :, k] = (1 - np.exp(-M[:, :, k] / (10 / 255))) + (1 - np.exp(-hamming / (30 / 63)))
    return M


def _box(a, size, reduce, fill):
    """``reduce`` of ``a`` (``(H, W)`` or ``(H, W, K)``) over the ``size x size`` patch
    ``[x - size // 2, x - size // 2 + size - 1]`` (both axes) of every pixel, ``fill``
    outside the image (separable)."""
    h = size // 2
    pad = [(h, size - 1 - h)] * 2 + [(0, 0)] * (a.ndim - 2)
    p = np.pad(np.asarray(a, np.float64), pad, constant_values=fill)
    p = reduce(sliding_window_view(p, size, axis=1), axis=-1)
    return reduce(sliding_window_view(p, size, axis=0), axis=-1)


def box_sum(a, size):
    """Sum over each pixel's patch of side ``size``, in-image pixels only (exact zeros where
    the patch holds only zeros)."""
    return _box(a, size, np.sum, 0.0)


def box_mean(a, size):
    """Mean over the in-image pixels of each pixel's patch of side ``size``."""
    n = box_sum(np.ones(a.shape[:2]), size)
    return box_sum(a, size) / (n if a.ndim == 2 else n[..., None])


def box_extreme(a, size, reduce):
    """``np.max`` or ``np.min`` (``reduce``) of ``a`` over each pixel's patch, in-image pixels
    only."""
    return _box(a, size, reduce, -np.inf if reduce is np.max else np.inf)


def patches_containing(a, size):
    """Sum of per-patch values ``a`` over the patches of side ``size`` that contain each pixel:
    a patch centred on ``x`` covers ``[x - size // 2, x - size // 2 + size - 1]``, so pixel
    ``x`` lies in the patches centred on ``[x - (size - 1 - size // 2), x + size // 2]`` (the
    transpose of :func:`box_sum`; the same box only for odd sizes)."""
    return box_sum(a[::-1, ::-1], size)[::-1, ::-1]


def patch_costs(left, right, c_max, sizes, kind="ad"):
    """Per level: the patch-mean matching cost, min-max normalised to [0, 1]."""
    M = matching_cost(left, right, c_max, kind)
    out = []
    for s in sizes:
        v = box_mean(M, s)
        out.append((v - v.min()) / max(v.max() - v.min(), 1e-12))
    return out


# ---------------------------------------------------------------------------- hierarchy
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


def second_best(cost, best, axis):
    """The peak ratio's second candidate: along ``axis`` of ``cost``, the lowest cost at
    least two candidates from the index ``best`` (``cost``'s shape without ``axis``); inf
    where there is none."""
    k = np.arange(cost.shape[axis]).reshape([-1] + [1] * (cost.ndim - 1 - axis % cost.ndim))
    far = np.abs(k - np.expand_dims(best, axis)) >= 2
    return np.where(far, cost, np.inf).min(axis=axis)


def distinctness(cost, ambiguity):
    """The weight of a patch's message by the distinctness of its cost curve ``cost[..., k]``
    (:class:`lss_kernels.model.messages.Messages` with ``ambiguity > 0``):
    ``clip((1 - r) / ambiguity, 0, 1)`` with ``r = (mean - second) / (mean - best)``,
    ``second`` the lowest cost at least two candidates from the (first) argmin; ``r = 1`` on
    a flat curve."""
    cost = np.asarray(cost, np.float64)
    best = cost.min(axis=-1)
    second = second_best(cost, cost.argmin(axis=-1), axis=-1)
    mean = cost.mean(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(mean > best, np.minimum((mean - np.minimum(second, mean)) / (mean - best),
                                             1.0), 1.0)
    return np.clip((1.0 - r) / ambiguity, 0.0, 1.0)


def consensus(d_p, sigma_p, valid, sizes, weights=None):
    """Eq. 7: per pixel, 1/sigma^2 and d-bar from all valid patches (of every level) that
    contain it, each patch's 1/sigma^2 times its weight (``weights``: per level, the
    :func:`distinctness` of its patches; None: 1).  Lists per level of ``(H, W)`` arrays;
    returns ``(precision, mean)``."""
    weights = [1.0] * len(sizes) if weights is None else weights
    a = sum(patches_containing(np.where(v, q / s ** 2, 0.0), size)
            for s, v, q, size in zip(sigma_p, valid, weights, sizes))
    b = sum(patches_containing(np.where(v, q * d / s ** 2, 0.0), size)
            for d, s, v, q, size in zip(d_p, sigma_p, valid, weights, sizes))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(a > 0, b / a, 0.0)
    return a, mean


# ---------------------------------------------------------------------------- filters
def median_filter(a, size):
    """Median over ``size x size`` windows with symmetric (mirror, edge repeated) borders."""
    if size == 1:
        return np.array(a, copy=True)
    h = size // 2
    win = sliding_window_view(np.pad(a, h, mode="symmetric"), (size, size))
    return np.median(win.reshape(np.shape(a) + (size * size,)), axis=-1)


def convolve(a, taps, axis):
    """``out[x] = sum_i taps[i + h] a[reflect(x - i)]`` along ``axis`` (a convolution with
    symmetric borders: -1 -> 0, n -> n - 1)."""
    h = (len(taps) - 1) // 2
    pad = [(0, 0)] * a.ndim
    pad[axis] = (h, h)
    p = np.pad(a, pad, mode="symmetric")
    n = a.shape[axis]
    out = np.zeros_like(a, dtype=np.float64)
    for i in range(-h, h + 1):
        out += taps[i + h] * np.take(p, np.arange(h - i, h - i + n), axis=axis)
    return out


def gaussian_derivatives(a, sigma):
    """``(a_x, a_y, a_xx, a_yy, a_xy)`` by separable Gaussian-derivative convolution
    (half-width ceil(3.5 sigma), symmetric borders)."""
    g, g1, g2 = gaussian_taps(sigma)
    t0, t1, t2 = (convolve(a, t, 1) for t in (g, g1, g2))
    return (convolve(t1, g, 0), convolve(t0, g1, 0), convolve(t2, g, 0), convolve(t0, g2, 0),
            convolve(t1, g1, 0))


def curvature(derivatives, clip):
    """kappa = div(grad phi / |grad phi|) (clipped to +-``clip``) and the unit normal
    ``(N_x, N_y)``, from :func:`gaussian_derivatives` of phi."""
    px, py, pxx, pyy, pxy = derivatives
    norm = np.sqrt(px * px + py * py) + 1e-10
    k = (pxx * py * py - 2.0 * px * py * pxy + pyy * px * px) / norm ** 3
    return np.clip(k, -clip, clip), px / norm, py / norm


# ---------------------------------------------------------------------------- sampling
def interp_row(a, x):
    """Linear interpolation of each row of ``a`` at real positions ``x`` (same shape),
    clamped to the image."""
    H, W = a.shape
    if W == 1:
        return np.array(a, dtype=np.float64, copy=True)
    xf = np.clip(x, 0.0, W - 1.0)
    x0 = np.minimum(np.floor(xf).astype(np.int64), W - 2)
    t = xf - x0
    rows = np.arange(H)[:, None]
    return (1.0 - t) * a[rows, x0] + t * a[rows, x0 + 1]


def interp_volume(vol, x, c):
    """``vol[y, x, c - 1]`` at real x and c per pixel (bilinear, clamped to the volume),
    ``x`` and ``c`` of shape ``(H, W)``."""
    H, W, C = vol.shape
    xf = np.clip(x, 0.0, W - 1.0)
    x0 = np.minimum(np.floor(xf).astype(np.int64), max(W - 2, 0))
    x1 = np.minimum(x0 + 1, W - 1)
    tx = xf - x0
    kf = np.clip(c - 1.0, 0.0, C - 1.0)
    k0 = np.minimum(np.floor(kf).astype(np.int64), max(C - 2, 0))
    k1 = np.minimum(k0 + 1, C - 1)
    tk = kf - k0
    rows = np.arange(H)[:, None]
    a = (1.0 - tk) * vol[rows, x0, k0] + tk * vol[rows, x0, k1]
    b = (1.0 - tk) * vol[rows, x1, k0] + tk * vol[rows, x1, k1]
    return (1.0 - tx) * a + tx * b


# ---------------------------------------------------------------------------- shapes (Eq. 8)
def _normalised(x, y, H, W):
    inv_s = 1.0 / (max(H, W) / 2.0)
    return (x - (W - 1) / 2.0) * inv_s, (y - (H - 1) / 2.0) * inv_s


def shape_value(theta_j, x, y, shape):
    """Theta_j at real cyclopean pixel coordinates of an image of ``shape = (H, W)``."""
    return evaluate(theta_j, *_normalised(x, y, *shape))


def fit_shape(weight, target, previous):
    """Eq. 8: weighted least squares of ``target`` (``(H, W)``) on the basis over the pixels
    with ``weight > 0``.  Returns ``(theta, updated)``: ``previous`` and False with fewer
    than 6 rows or a rank-deficient system."""
    sel = weight > 0
    if sel.sum() < 6:
        return previous, False
    y, x = np.nonzero(sel)
    xn, yn = _normalised(x.astype(np.float64), y.astype(np.float64), *weight.shape)
    sw = np.sqrt(weight[sel])
    sol, _, rank, _ = np.linalg.lstsq(basis(xn, yn) * sw[:, None], target[sel] * sw,
                                      rcond=None)
    if rank < 6 or not np.all(np.isfinite(sol)):
        return previous, False
    return sol, True


# ---------------------------------------------------------------------------- occlusion
def delta_theta(theta1, theta2, phi_x, steps=FIXED_POINT_STEPS, c_cap=None):
    """The ray cast of Sec. 2 for callables ``theta1(x, y)``, ``theta2(x, y)`` (vectorised)
    on the grid of ``phi_x``: ``t = Theta_1(x) - Theta_2(x - s t)`` by ``steps`` fixed-point
    steps from the jump at x, ``s = sign(phi_x)``, each clipped to ``[0, c_cap]``; returns
    ``s t`` (0 where Theta_1 <= Theta_2 or phi_x = 0)."""
    H, W = phi_x.shape
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    s = np.sign(phi_x)
    t1 = theta1(x, y)
    jump = t1 - theta2(x, y)
    t = jump.copy()
    for _ in range(steps):
        t = np.clip(t1 - theta2(x - s * t, y), 0, np.inf if c_cap is None else c_cap)
    return np.where((jump > 0) & (s != 0), s * t, 0.0)


# ---------------------------------------------------------------------------- level set
def boundary_weight(b_occ, edge_left, edge_right, c, alpha):
    """B(x, y, c) = a_occ B_occ + a_mono B_mono + a_const at a real c per pixel (linear between
    integer disparities), B_mono(c) = 1 - e_L(x + c) - e_R(x - c) with zero edge score off the
    image (Eq. 1's B)."""
    H, W, C = b_occ.shape
    x = np.arange(W)[None, :]
    rows = np.arange(H)[:, None]
    kf = np.clip(c - 1.0, 0.0, C - 1.0)
    k0 = (np.minimum(np.floor(kf).astype(np.int64), C - 2) if C > 1
          else np.zeros_like(kf, dtype=np.int64))
    t = kf - k0

    def at(k):
        xl, xr = x + k + 1, x - k - 1
        e = np.where(xl < W, edge_left[rows, np.minimum(xl, W - 1)], 0.0)
        e = e + np.where(xr >= 0, edge_right[rows, np.maximum(xr, 0)], 0.0)
        return alpha[0] * b_occ[rows, x, k] + alpha[1] * (1.0 - e)

    v0 = at(k0)
    v1 = at(k0 + 1) if C > 1 else v0
    return (1.0 - t) * v0 + t * v1 + alpha[2]


def levelset_step(phi, cost1, theta1_map, theta2_map, dtheta, b_map, b_x, b_y, kappa, n_x,
                  n_y, dt, mu, clip, band=0.0):
    """Eq. 2: phi + dt delta(phi) [-M(x, Theta_1) + M(x - delta_theta, Theta_2)
    + mu clip(B kappa + N . grad B)], with delta(phi) = (1/pi) / (1 + phi^2) where
    |phi| <= ``band`` (every pixel for ``band`` 0) and 0 elsewhere."""
    H, W = phi.shape
    x = np.broadcast_to(np.arange(W, dtype=np.float64), (H, W))
    m1 = interp_volume(cost1, x, theta1_map)
    m2 = interp_volume(cost1, x - dtheta, theta2_map)
    bt = np.clip(b_map * kappa + n_x * b_x + n_y * b_y, -clip, clip)
    dirac = (1 / np.pi) / (1 + phi ** 2)
    if band > 0:
        dirac = np.where(np.abs(phi) > band, 0.0, dirac)
    return phi + dt * dirac * (-m1 + m2 + mu * bt)


def squared_distance(features):
    """Squared Euclidean distance of every pixel to the nearest ``True`` of ``features``
    (``inf`` where there is none).  scipy's exact EDT when it is installed (the tests'
    extra), else a separable numpy one (``lss bench`` runs without scipy)."""
    if not features.any():
        return np.full(features.shape, np.inf)
    try:
        from scipy.ndimage import distance_transform_edt
        return distance_transform_edt(~features) ** 2
    except ImportError:
        pass
    H, W = features.shape
    idx = np.arange(H)[:, None] * np.ones((1, W))
    above = np.maximum.accumulate(np.where(features, idx, -np.inf), axis=0)
    below = np.minimum.accumulate(np.where(features, idx, np.inf)[::-1], axis=0)[::-1]
    g = np.minimum(idx - above, below - idx) ** 2            # column distances, inf: none
    xs = np.arange(W, dtype=np.float64)
    d2 = (xs[:, None] - xs[None, :]) ** 2
    out = np.empty((H, W))
    step = max(1, (1 << 22) // (W * W))
    for y0 in range(0, H, step):
        out[y0:y0 + step] = (g[y0:y0 + step, None, :] + d2[None]).min(axis=2)
    return out


def reinitialise(phi, scale):
    """phi <- scale x (distance to the other region - 1/2), signs kept; the distance is capped
    at the image diagonal."""
    H, W = phi.shape
    inside = phi > 0
    cap = math.sqrt(H * H + W * W)
    d_in = np.minimum(np.sqrt(squared_distance(~inside)), cap)   # to the nearest background
    d_out = np.minimum(np.sqrt(squared_distance(inside)), cap)   # to the nearest foreground
    return np.where(inside, scale * (d_in - 0.5), -scale * (d_out - 0.5))


def disparity(phi, theta1_map, theta2_map, c_max):
    """Eq. 3 with the sharp Heaviside: Theta_1 where phi > 0, else Theta_2, clamped to
    [0, c_max]."""
    return np.clip(np.where(phi > 0, theta1_map, theta2_map), 0.0, c_max)


# ------------------------------------------------------------------ initialisation (init.py)
def near_pixels(d, window, contrast):
    """Pixels whose d-bar stands ``contrast`` above the ground of their row: the larger of the
    minima of d-bar's 5x5 maxima over ``[x-window, x-1]`` and ``[x+1, x+window]`` (the one
    that exists at the image's side); ``d < 0`` = no match."""
    H, W = d.shape
    padded = np.pad(d, 2, constant_values=-1.0)
    hi = np.max([padded[2 + dy:2 + dy + H, 2 + dx:2 + dx + W]
                 for dy in range(-2, 3) for dx in range(-2, 3)], axis=0)
    near = np.zeros((H, W), bool)
    for y in range(H):
        for x in range(W):
            left = hi[y, max(x - window, 0):x]
            right = hi[y, x + 1:x + 1 + window]
            lo = [v[v >= 0].min() for v in (left, right) if (v >= 0).any()]
            if d[y, x] >= 0 and lo:
                ground = max(lo) if len(lo) == 2 else lo[0]
                near[y, x] = d[y, x] - ground > contrast
    return near


def dilate(mask, radius):
    """Whether any pixel of ``mask`` lies in each pixel's ``2 radius + 1`` square (the
    image's outside is empty); ``~dilate(~mask, r)`` is the erosion."""
    k = 2 * radius + 1
    padded = np.pad(np.asarray(mask, bool), radius, constant_values=False)
    return sliding_window_view(padded, (k, k)).any(axis=(2, 3))


def grow_region(d, seed, seed_d, tolerance, step):
    """The 4-connected region grown from ``seed = (y, x)`` over pixels with
    ``|d - seed_d| <= tolerance`` and ``|d - d_neighbour| <= step`` (breadth first)."""
    H, W = d.shape
    d = d.copy()
    d[seed] = seed_d
    region = np.zeros((H, W), bool)
    region[seed] = True
    todo = [seed]
    while todo:
        y, x = todo.pop()
        for v, u in ((y, x + 1), (y, x - 1), (y + 1, x), (y - 1, x)):
            if (0 <= v < H and 0 <= u < W and not region[v, u] and d[v, u] >= 0
                    and abs(d[v, u] - seed_d) <= tolerance and abs(d[v, u] - d[y, x]) <= step):
                region[v, u] = True
                todo.append((v, u))
    return region
