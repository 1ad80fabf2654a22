"""Readable numpy specifications of the third layer (:mod:`lss_kernels.model.front`) and of
the occlusion rule for ordered layers (:mod:`lss_kernels.model.layers`).  Plain loops,
float64."""
import numpy as np

from ..model.front import COST_GAP, MAJORITY, SUPPORT

__all__ = ["front_layer", "occlusion_by_layers"]


def occlusion_by_layers(disparity, layers, occluders=None):
    """The left-view pixels that a nearer pixel of another layer hides from the right camera:
    pixel ``x`` (disparity ``d``) is seen there at ``r = x - d``; a pixel ``u > x`` of
    another layer with a larger disparity covers ``[u - d(u) - 1/2, u - d(u) + 1/2]``,
    stretched to ``u + 1 - d(u + 1)`` when ``u + 1`` is of its layer (and may occlude)."""
    d = np.asarray(disparity, np.float64)
    layers = np.asarray(layers)
    occluders = np.ones(d.shape, bool) if occluders is None else np.asarray(occluders, bool)
    H, W = d.shape
    out = np.zeros((H, W), bool)
    for y in range(H):
        for x in range(W):
            r = x - d[y, x]
            for u in range(x + 1, W):
                if not occluders[y, u] or layers[y, u] == layers[y, x] or d[y, u] <= d[y, x]:
                    continue
                a = b = u - d[y, u]
                if u + 1 < W and occluders[y, u + 1] and layers[y, u + 1] == layers[y, u]:
                    b = u + 1 - d[y, u + 1]
                if min(a, b) - 0.5 <= r <= max(a, b) + 0.5:
                    out[y, x] = True
                    break
    return out


def _cost_at(cost, y, x, c):
    """M at a real candidate c (linear between candidates, clamped to [1, C])."""
    C = cost.shape[2]
    k = min(max(c - 1.0, 0.0), C - 1.0)
    k0 = min(int(np.floor(k)), max(C - 2, 0))
    t = k - k0
    return (1 - t) * cost[y, x, k0] + t * cost[y, x, min(k0 + 1, C - 1)]


def front_layer(cost, theta_1, theta_2, margin, phi=None, near=-np.inf):
    """``(front, hidden)`` of :class:`lss_kernels.model.front.FrontLayer` (``capture`` then
    ``update``): ``cost`` is M, ``(H, W, C)`` over candidates c = 1 .. C, ``theta_1`` and
    ``theta_2`` cyclopean planes, ``margin`` in cyclopean pixels; only pixels with ``phi >
    near`` can be in front (default: all)."""
    cost = np.asarray(cost, np.float64)
    H, W, C = cost.shape
    best = cost.argmin(axis=2)
    first = best + 1.0
    least = np.take_along_axis(cost, best[..., None], axis=2)[..., 0]
    at_theta = np.empty((H, W))
    for y in range(H):
        for x in range(W):
            at_theta[y, x] = min(_cost_at(cost, y, x, theta_1[y, x]),
                                 _cost_at(cost, y, x, theta_2[y, x]))
    raw = (first - theta_1 > margin) & (at_theta - least > COST_GAP)
    if phi is not None:
        raw &= np.asarray(phi) > near
    front = np.zeros((H, W), bool)
    for y in range(H):
        for x in range(W):
            near = raw[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2].sum()
            votes = raw[max(y - 2, 0):y + 3, max(x - 2, 0):x + 3].sum()
            front[y, x] = raw[y, x] and near >= MAJORITY and votes >= SUPPORT
    hidden = front.copy()
    for y in range(H):
        for x in range(W):
            if front[y, x]:
                reach = first[y, x] - theta_1[y, x]
                for u in range(W):
                    if abs(u - x) <= reach:
                        hidden[y, u] = True
    return front, hidden
