"""One full solver iteration in vectorised numpy: the readable specification of
:meth:`lss_kernels.solver.Solver.step`, stage by stage, in float64.

The stages and their order are those of the solver (``solver.STAGES``):

``upward``
    Gaussian-derivative filters of phi (phi_x, phi_y, phi_xx, phi_yy, phi_xy; separable,
    half-width ``ceil(3.5 sigma)``, symmetric borders), the curvature kappa and normal N;
    phi(x + delta_theta) with the previous delta_theta; from the second iteration on, the
    patch sums of D and the patch extremes max phi, min phi(x + delta_theta) at every level
    (what the hierarchy relays upward, computed here directly over each patch's in-image
    pixels).
``messages``
    Eq. 4 (w_p = max phi > 0 XOR min phi_+ < 0) and Eq. 5 (d_p = argmin_c C_p(c) +
    beta |c - <D>_p|, sigma_p = c_max / (mean - min)); at the first iteration every patch is
    valid and there is no prior term.
``downward``
    Eq. 7: 1/sigma^2 and d-bar from every valid patch (of every level) containing the pixel.
``shapes``
    Eq. 8/9: Theta_1 over phi >= 0 and Theta_2 over the visible background (phi < 0 and
    phi_+ < 0), weighted least squares (:func:`numpy.linalg.lstsq`) of the consensus mean with
    weights (1/sigma^2) ** ``shape_weight_power``; a region with fewer than 6 weighted rows, or
    a rank-deficient system, keeps its previous shape.
``occlusion``
    delta_theta by the ray cast of Sec. 2 (fixed-point iteration on
    ``t = Theta_1(x) - Theta_2(x - s t)``, ``s = sign(dphi/dx)``), and phi(x + delta_theta).
``boundary``
    B(x, y, Theta_1(x, y)) = alpha_occ B_occ + alpha_mono B_mono + alpha_const (linear in c)
    and its Gaussian-derivative gradient.
``levelset``
    The Eq. 2 step, then (every ``reinit_every`` iterations) the signed-distance
    re-initialisation, then the ``median_size``-squared median filter with symmetric
    borders, and D = Theta_1 where the new phi > 0, else Theta_2 (Eq. 3; the kernels write
    it in the median's last pass).

Frames and units are the solver's: cyclopean ``(H, W)`` arrays indexed ``[y, x]``, cyclopean
disparities ``c = 1 .. c_max`` (volume index ``k = c - 1``); Theta over the normalised basis
(``x_n = (x - (W - 1) / 2) / s``, ``y_n = (y - (H - 1) / 2) / s``, ``s = max(H, W) / 2``) in
cyclopean units.

Examples
--------
>>> solver = Solver(left, right, 32, (40, 30, 15, 12), params=params)   # doctest: +SKIP
>>> state = state_from_solver(solver)                                   # doctest: +SKIP
>>> new_state, seconds = iteration(state, params)                       # doctest: +SKIP
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..kernels.filters import gaussian_taps
from .kernels import patch_messages

__all__ = ["IterationState", "STAGES", "iteration", "run", "state_from_solver"]

STAGES = ("upward", "messages", "downward", "shapes", "occlusion", "boundary", "levelset")

FIXED_POINT_STEPS = 6  # as occlusion.FIXED_POINT_STEPS


@dataclass
class IterationState:
    """Everything one iteration reads (and, for the evolving part, writes).

    Constant over a solve: ``costs`` (per level, the in-image ``(H, W, c_max)`` min-max
    normalised patch-mean matching cost C_p(c); level 0 is the size-3 cost M of Eq. 2),
    ``b_occ`` ``(H, W, c_max)``, ``edge_left`` and ``edge_right`` ``(H, W)`` (edge scores of
    B_mono).  Evolving: ``phi``, ``D``, ``delta_theta`` ``(H, W)``, ``theta`` ``(2, 6)`` and
    ``iteration`` (iterations done).  ``extra`` holds the diagnostics of the last iteration
    (``consensus_mean``, ``precision``, ``phi_plus``, ``flipped``, ``area``, ...).
    """

    costs: list
    b_occ: np.ndarray
    edge_left: np.ndarray
    edge_right: np.ndarray
    phi: np.ndarray
    D: np.ndarray
    delta_theta: np.ndarray
    theta: np.ndarray
    iteration: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def shape(self):
        return self.phi.shape

    @property
    def c_max(self):
        return self.costs[0].shape[2]

    @property
    def nbytes_levels(self):
        """Bytes of the level cost volumes in float32 (what the kernels stream)."""
        return sum(4 * c.size for c in self.costs)


def state_from_solver(solver) -> IterationState:
    """The state of a :class:`~lss_kernels.solver.Solver` (after set-up or any step), as
    float64 numpy arrays; level volumes are cut to their in-image part."""
    H, W = solver.H, solver.W
    h = solver.hierarchy
    costs = []
    for lev in h.levels:
        m = lev.margin
        costs.append(lev.cost.to_numpy()[m:m + H, m:m + W].astype(np.float64))
    f64 = lambda f: f.to_numpy().astype(np.float64)
    prec = f64(h.precision)
    return IterationState(
        costs=costs, b_occ=f64(solver.costs.b_occ), edge_left=f64(solver.costs.edge_left),
        edge_right=f64(solver.costs.edge_right), phi=f64(solver.levelset.phi),
        D=f64(solver.levelset.D), delta_theta=f64(solver.occ.delta_theta),
        theta=f64(solver.shapes.theta), iteration=int(solver.iteration),
        extra=dict(consensus_mean=f64(h.consensus_mean), precision=prec,
                   phi_plus=f64(solver.occ.phi_plus)))


# ---------------------------------------------------------------------------- small helpers
def _convolve(a, taps, axis):
    """``dst[x] = sum_i taps[i + h] a[reflect(x - i)]`` along ``axis`` (a convolution, with
    MATLAB's symmetric border: -1 -> 0, n -> n - 1)."""
    h = (len(taps) - 1) // 2
    pad = [(0, 0)] * a.ndim
    pad[axis] = (h, h)
    p = np.pad(a, pad, mode="symmetric")
    n = a.shape[axis]
    out = np.zeros_like(a, dtype=np.float64)
    for i in range(-h, h + 1):
        out += taps[i + h] * np.take(p, np.arange(h - i, h - i + n), axis=axis)
    return out


def _gaussian_derivatives(phi, taps):
    """(phi_x, phi_y, phi_xx, phi_yy, phi_xy) with separable Gaussian-derivative filters."""
    g, g1, g2 = taps
    t0, t1, t2 = (_convolve(phi, t, 1) for t in (g, g1, g2))
    return (_convolve(t1, g, 0), _convolve(t0, g1, 0), _convolve(t2, g, 0),
            _convolve(t0, g2, 0), _convolve(t1, g1, 0))


def _curvature(px, py, pxx, pyy, pxy, clip):
    """kappa = div(grad phi / |grad phi|) (clipped) and the unit normal N."""
    norm = np.sqrt(px * px + py * py) + 1e-10
    k = (pxx * py * py - 2.0 * px * py * pxy + pyy * px * px) / norm ** 3
    return np.clip(k, -clip, clip), px / norm, py / norm


def _sample_row(f, x):
    """Linear interpolation of every row of ``f`` at real ``x`` (``(H, W)``), clamped."""
    H, W = f.shape
    xf = np.clip(x, 0.0, W - 1.0)
    if W == 1:
        return f.copy()
    x0 = np.minimum(np.floor(xf).astype(np.int64), W - 2)
    t = xf - x0
    rows = np.arange(H)[:, None]
    return (1.0 - t) * f[rows, x0] + t * f[rows, x0 + 1]


def _box_extreme(a, size, reduce, fill):
    """max / min of ``a`` over the ``size x size`` box ``[x - size//2, x - size//2 + size - 1]``
    (both axes), over in-image pixels only (``fill`` outside)."""
    h = size // 2
    p = np.pad(a, [(h, size - 1 - h)] * 2, constant_values=fill)
    p = reduce(sliding_window_view(p, size, axis=1), axis=-1)
    return reduce(sliding_window_view(p, size, axis=0), axis=-1)


def _box_sum(a, size):
    """Sum of ``a`` over the patch ``[x - size//2, x - size//2 + size - 1]`` (both axes) of
    every pixel, in-image pixels only: separable window sums (exact zeros where the patch holds
    only zeros, unlike a summed-area table)."""
    h = size // 2
    p = np.pad(a, [(h, size - 1 - h)] * 2)
    p = sliding_window_view(p, size, axis=1).sum(axis=-1)
    return sliding_window_view(p, size, axis=0).sum(axis=-1)


def _patches_containing(a, size):
    """Sum of the per-patch values ``a`` over the patches (of side ``size``) that contain each
    pixel: a patch centred on ``x`` covers ``[x - size//2, x - size//2 + size - 1]``, so pixel
    ``x`` is in the patches centred on ``[x - (size - 1 - size//2), x + size//2]`` (the
    transpose of :func:`_box_sum`; the same box only for odd sizes)."""
    return _box_sum(a[::-1, ::-1], size)[::-1, ::-1]


def _consensus(d_p, sigma_p, valid, sizes):
    """Eq. 7: per pixel, 1/sigma^2 and d-bar from the valid patches of every level that
    contain it."""
    a = sum(_patches_containing(np.where(v, 1.0 / s ** 2, 0.0), size)
            for s, v, size in zip(sigma_p, valid, sizes))
    b = sum(_patches_containing(np.where(v, d / s ** 2, 0.0), size)
            for d, s, v, size in zip(d_p, sigma_p, valid, sizes))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(a > 0, b / a, 0.0)
    return a, mean


def _grid(H, W):
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    return x, y


def _normalised(x, y, H, W):
    inv_s = 1.0 / (max(H, W) / 2.0)
    return (x - (W - 1) / 2.0) * inv_s, (y - (H - 1) / 2.0) * inv_s


def _basis(xn, yn):
    return np.stack([xn * xn, xn * yn, yn * yn, xn, yn, np.ones_like(xn)], axis=-1)


def _shape_value(theta_j, x, y, H, W):
    """Theta_j at real cyclopean pixel coordinates."""
    xn, yn = _normalised(x, y, H, W)
    t = theta_j
    return t[0] * xn * xn + t[1] * xn * yn + t[2] * yn * yn + t[3] * xn + t[4] * yn + t[5]


def _fit_shape(weight, target, previous, H, W):
    """Weighted least squares of ``target`` on the basis over the rows with ``weight > 0``;
    ``previous`` if fewer than 6 rows or a rank-deficient system."""
    sel = weight > 0
    if sel.sum() < 6:
        return previous, False
    x, y = _grid(H, W)
    xn, yn = _normalised(x[sel], y[sel], H, W)
    sw = np.sqrt(weight[sel])
    A = _basis(xn, yn) * sw[:, None]
    sol, _, rank, _ = np.linalg.lstsq(A, target[sel] * sw, rcond=None)
    if rank < 6 or not np.all(np.isfinite(sol)):
        return previous, False
    return sol, True


def _cost_at(cost, x, c):
    """M(x, y, c) at real x and c per pixel (bilinear in x and c, clamped to the volume)."""
    H, W, C = cost.shape
    xf = np.clip(x, 0.0, W - 1.0)
    x0 = np.minimum(np.floor(xf).astype(np.int64), max(W - 2, 0))
    x1 = np.minimum(x0 + 1, W - 1)
    tx = xf - x0
    kf = np.clip(c - 1.0, 0.0, C - 1.0)
    k0 = np.minimum(np.floor(kf).astype(np.int64), max(C - 2, 0))
    k1 = np.minimum(k0 + 1, C - 1)
    tk = kf - k0
    rows = np.arange(H)[:, None]
    a = (1.0 - tk) * cost[rows, x0, k0] + tk * cost[rows, x0, k1]
    b = (1.0 - tk) * cost[rows, x1, k0] + tk * cost[rows, x1, k1]
    return (1.0 - tx) * a + tx * b


def _boundary_weight(state, c, alpha):
    """B(x, y, c) = a_occ B_occ + a_mono B_mono + a_const at real c (linear between integer
    disparities); B_mono(c) = 1 - e_L(x + c) - e_R(x - c), zero edge score off the image."""
    H, W, C = state.b_occ.shape
    x = np.arange(W)[None, :]
    rows = np.arange(H)[:, None]
    kf = np.clip(c - 1.0, 0.0, C - 1.0)
    k0 = np.minimum(np.floor(kf).astype(np.int64), C - 2) if C > 1 else np.zeros_like(
        kf, dtype=np.int64)
    t = kf - k0

    def at(k):
        ci = k + 1
        xl, xr = x + ci, x - ci
        e = np.where(xl < W, state.edge_left[rows, np.minimum(xl, W - 1)], 0.0)
        e = e + np.where(xr >= 0, state.edge_right[rows, np.maximum(xr, 0)], 0.0)
        return alpha[0] * state.b_occ[rows, x, k] + alpha[1] * (1.0 - e)

    v0 = at(k0)
    v1 = at(k0 + 1) if C > 1 else v0
    return (1.0 - t) * v0 + t * v1 + alpha[2]


def _squared_distance(features):
    """Squared Euclidean distance of every pixel to the nearest ``True`` of ``features``
    (``inf`` where there is none).  scipy's exact EDT when available, else a separable numpy
    one (column pass by scans, row pass by brute-force minimum, in chunks of rows)."""
    if not features.any():
        return np.full(features.shape, np.inf)
    try:
        from scipy.ndimage import distance_transform_edt
        return distance_transform_edt(~features) ** 2
    except ImportError:  # pragma: no cover - scipy is a test dependency
        pass
    H, W = features.shape
    idx = np.arange(H)[:, None] * np.ones((1, W))
    above = np.maximum.accumulate(np.where(features, idx, -np.inf), axis=0)
    below = np.minimum.accumulate(np.where(features, idx, np.inf)[::-1], axis=0)[::-1]
    g = np.minimum(idx - above, below - idx) ** 2            # (H, W), inf: no feature
    out = np.empty((H, W))
    xs = np.arange(W, dtype=np.float64)
    d2 = (xs[:, None] - xs[None, :]) ** 2                   # (x, x')
    step = max(1, (1 << 22) // (W * W))
    for y0 in range(0, H, step):
        out[y0:y0 + step] = (g[y0:y0 + step, None, :] + d2[None]).min(axis=2)
    return out


def _reinitialise(phi, scale):
    """phi <- scale x (distance to the other region - 1/2), signs kept; the distance is capped
    at the image diagonal (as ``LevelSet.reinitialise``)."""
    H, W = phi.shape
    inside = phi > 0
    cap = math.sqrt(H * H + W * W)
    d_in = np.minimum(np.sqrt(_squared_distance(~inside)), cap)   # to the nearest background
    d_out = np.minimum(np.sqrt(_squared_distance(inside)), cap)   # to the nearest foreground
    return np.where(inside, scale * (d_in - 0.5), -scale * (d_out - 0.5))


def _median(phi, k):
    """``k x k`` median with symmetric borders."""
    if k == 1:
        return phi.copy()
    h = k // 2
    p = np.pad(phi, h, mode="symmetric")
    win = sliding_window_view(p, (k, k)).reshape(phi.shape + (k * k,))
    return np.median(win, axis=-1)


# ---------------------------------------------------------------------------- the iteration
def iteration(state: IterationState, params, taps=None):
    """One iteration of the solver (the alternation of Sec. 3), in numpy.

    Parameters
    ----------
    state : IterationState
        The state before the iteration (see :func:`state_from_solver`); not modified.
    params : lss_kernels.Params
    taps : tuple of 3 arrays, optional
        ``gaussian_taps(params.curvature_sigma)`` (pass them to skip recomputing).

    Returns
    -------
    new_state : IterationState
        ``phi``, ``D``, ``delta_theta``, ``theta`` and ``iteration`` updated; ``extra`` holds
        ``consensus_mean`` and ``precision`` ``(H, W)`` (cyclopean units, 1/sigma^2), ``d_p``,
        ``sigma_p``, ``valid`` (lists per level), ``phi_plus``, ``updated`` (which shapes were
        refitted), ``flipped`` and ``area``.
    seconds : dict
        Wall-clock seconds per stage (keys :data:`STAGES`).
    """
    p = params
    H, W = state.shape
    C = state.c_max
    sizes = tuple(p.patch_sizes)
    if taps is None:
        taps = gaussian_taps(p.curvature_sigma)
    it = state.iteration + 1
    first = it == 1
    seconds = {}
    x, y = _grid(H, W)

    # upward: derivatives of phi, phi(x + delta_theta), patch sums / extremes
    t = time.perf_counter()
    phi = state.phi
    px, py, pxx, pyy, pxy = _gaussian_derivatives(phi, taps)
    kappa, nx, ny = _curvature(px, py, pxx, pyy, pxy, p.curvature_clip)
    phi_plus = _sample_row(phi, x + state.delta_theta)
    if not first:
        ones = np.ones((H, W))
        d_mean = [_box_sum(state.D, s) / np.maximum(_box_sum(ones, s), 1) for s in sizes]
        phi_max = [_box_extreme(phi, s, np.max, -np.inf) for s in sizes]
        phi_plus_min = [_box_extreme(phi_plus, s, np.min, np.inf) for s in sizes]
    now = time.perf_counter()
    seconds["upward"], t = now - t, now

    # messages: Eq. 4 and Eq. 5
    if first:
        valid = [np.ones((H, W), bool) for _ in sizes]
        msgs = [patch_messages(cost, np.zeros((H, W)), 0.0, p.subpixel_messages)
                for cost in state.costs]
    else:
        valid = [(mx > 0) != (mn < 0) for mx, mn in zip(phi_max, phi_plus_min)]
        msgs = [patch_messages(cost, dm, p.beta / C, p.subpixel_messages)
                for cost, dm in zip(state.costs, d_mean)]
    d_p = [m[0] for m in msgs]
    sigma_p = [m[1] for m in msgs]
    now = time.perf_counter()
    seconds["messages"], t = now - t, now

    # downward: Eq. 7
    precision, mean = _consensus(d_p, sigma_p, valid, sizes)
    now = time.perf_counter()
    seconds["downward"], t = now - t, now

    # shapes: Eq. 8/9 over the foreground and the visible background
    w = precision if p.shape_weight_power == 1 else precision * precision
    # a consensus whose correspondence falls outside the other image is no evidence
    w = np.where((x - mean < 0) | (x + mean > W - 1), 0.0, w)
    w_fg = np.where(phi >= 0, w, 0.0)
    w_bg = np.where((phi < 0) & (phi_plus < 0), w, 0.0)
    theta = np.array(state.theta, np.float64, copy=True)
    updated = []
    for j, wj in enumerate((w_fg, w_bg)):
        theta[j], ok = _fit_shape(wj, mean, theta[j], H, W)
        updated.append(ok)
    now = time.perf_counter()
    seconds["shapes"], t = now - t, now

    # occlusion: delta_theta (ray cast) and phi(x + delta_theta)
    th1 = _shape_value(theta[0], x, y, H, W)
    jump = th1 - _shape_value(theta[1], x, y, H, W)
    s = np.sign(px)
    tt = jump.copy()
    for _ in range(FIXED_POINT_STEPS):
        tt = np.clip(th1 - _shape_value(theta[1], x - s * tt, y, H, W), 0.0, 2.0 * C)
    delta_theta = np.where((jump > 0) & (s != 0), s * tt, 0.0)
    phi_plus = _sample_row(phi, x + delta_theta)
    now = time.perf_counter()
    seconds["occlusion"], t = now - t, now

    # boundary: B(x, y, Theta_1) and its gradient
    alpha = (p.alpha_occ, p.alpha_mono, p.alpha_const)
    b = _boundary_weight(state, th1, alpha)
    g, g1, _ = taps
    b_x = _convolve(_convolve(b, g1, 1), g, 0)
    b_y = _convolve(_convolve(b, g, 1), g1, 0)
    now = time.perf_counter()
    seconds["boundary"], t = now - t, now

    # levelset: Eq. 2, re-initialisation, median
    m1 = _cost_at(state.costs[0], x, th1)
    m2 = _cost_at(state.costs[0], x - delta_theta, _shape_value(theta[1], x, y, H, W))
    bt = np.clip(b * kappa + nx * b_x + ny * b_y, -p.boundary_clip, p.boundary_clip)
    dirac = (1.0 / math.pi) / (1.0 + phi * phi)
    phi_next = phi + p.dt * dirac * (-m1 + m2 + p.mu * bt)
    if it % p.reinit_every == 0:
        phi_next = _reinitialise(phi_next, p.phi_scale)
    phi_new = _median(phi_next, p.median_size)
    flipped = int(((phi_new > 0) != (phi > 0)).sum())
    area = int((phi_new > 0).sum())
    # Eq. 3
    D = np.where(phi_new > 0, th1, _shape_value(theta[1], x, y, H, W))
    seconds["levelset"] = time.perf_counter() - t

    extra = dict(consensus_mean=mean, precision=precision, d_p=d_p, sigma_p=sigma_p,
                 valid=valid, phi_plus=phi_plus, updated=updated, flipped=flipped, area=area)
    return replace(state, phi=phi_new, D=D, delta_theta=delta_theta, theta=theta,
                   iteration=it, extra=extra), seconds


def run(state: IterationState, params, n: int):
    """``n`` iterations; returns the final state and the summed seconds per stage."""
    taps = gaussian_taps(params.curvature_sigma)
    total = {s: 0.0 for s in STAGES}
    for _ in range(n):
        state, sec = iteration(state, params, taps)
        for k, v in sec.items():
            total[k] += v
    return state, total
