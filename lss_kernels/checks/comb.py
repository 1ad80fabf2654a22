"""The layers' planes read from the whole pair, each up to a tooth: the combs of a periodic
pair, found without the solve.

On stripes a pixel's matching cost has a comb of equally deep minima a period apart, and a
plane ``d = a x + b y + c`` of a layer explains the layer's pixels for every ``c`` a tooth
apart, and for no other slope: a plane of another slope crosses the teeth and matches only
where it does.  So the planes of the layers are found by RANSAC over the combs of
sampled pixels (:func:`combs`), as the best-supported plane, then the best-supported one of
the pixels left: each hypothesis is the plane through three pixels, within ``SPREAD`` of
one another, each on one of its own minima, drawn at random; its support is the number of
pixels whose cost at the plane lies within ``NEAR`` of their cost curve's range above its
lowest value; the best is fitted again to its support's nearest minima.  When the solve
itself is lost (``periodic_slanted_same`` of ``lss_kernels.stress --periodic``: slanted
layers, the alternation chaotic), its surfaces give no plane on any tooth, and these give
:mod:`.outline` its candidates.  The tooth of each comb is left open: the outline's search
reads it.
"""
import numpy as np

from .direction import box_sums
from .teeth import STEP, UPSAMPLE, _rows, _sample

__all__ = ["COMBS", "GRID", "HYPOTHESES", "NEAR", "RADIUS", "SPREAD", "combs", "cost_curves"]

#: Spacing (pixels) of the grid of pixels whose cost curves are sampled.
GRID = 4
#: Half the side of the square over which a pixel's differences are summed.
RADIUS = 2
#: A disparity matches a pixel when its cost lies within this fraction of the curve's range
#: above the curve's lowest value.
NEAR = 0.15
#: Planes drawn per comb.
HYPOTHESES = 600
#: Largest distance (pixels, along each axis) between the three pixels of a hypothesis: the
#: three lie on one layer more often when near.
SPREAD = 40
#: Combs read, one a layer.
COMBS = 2


def cost_curves(left, right, d_max):
    """The grid's pixels (every ``GRID``-th row and column, ``RADIUS`` from the edges) and
    their cost curves over the disparities ``0, STEP, .. d_max``: the absolute difference
    (mean over channels) of the left image from the right one (:func:`upsampled
    <lss_kernels.checks.teeth.upsampled>` by ``UPSAMPLE``) at ``x - d``, summed over the
    ``2 RADIUS + 1`` square, scaled to ``[0, 1]`` per pixel (0 its lowest value, 1 its
    highest); a pixel beyond the right image's edge differs by 1, the whole grey range.
    Returns ``(ys, xs, disparities, curves)``, ``curves`` ``(N, D)``."""
    H, W = left.shape[:2]
    width = right.shape[1]
    disparities = np.arange(0.0, float(d_max) + 1e-9, STEP)
    gy = np.arange(RADIUS, H - RADIUS, GRID)
    gx = np.arange(RADIUS, W - RADIUS, GRID)
    ys, xs = (a.ravel() for a in np.meshgrid(gy, gx, indexing="ij"))
    yy, xx = np.mgrid[0:H, 0:W]
    curves = np.empty((ys.size, disparities.size))
    for i, d in enumerate(disparities):
        r = (xx - d) * UPSAMPLE
        ok = r >= 0
        diff = np.ones((H, W))
        diff[ok] = np.abs(left[ok] - _sample(right, yy[ok], np.minimum(r[ok], width - 1))
                          ).mean(axis=-1)
        curves[:, i] = box_sums(diff, 2 * RADIUS + 1)[ys - RADIUS, xs - RADIUS]
    lo = curves.min(axis=1, keepdims=True)
    span = curves.max(axis=1, keepdims=True) - lo
    return ys, xs, disparities, (curves - lo) / np.maximum(span, 1e-12)


def _minima(curve):
    """Indices of the local minima of ``curve`` within ``NEAR`` of its lowest value (0)."""
    inner = (curve[1:-1] <= curve[:-2]) & (curve[1:-1] <= curve[2:]) & (curve[1:-1] < NEAR)
    return np.nonzero(inner)[0] + 1


def _at(curves, disparities, d):
    """Each curve at its own disparity ``d`` (linear; 1 outside the range)."""
    f = (d - disparities[0]) / STEP
    i0 = np.floor(f).astype(np.int64)
    ok = (i0 >= 0) & (i0 < disparities.size - 1)
    i0c = np.clip(i0, 0, disparities.size - 2)
    t = f - i0c
    rows = np.arange(curves.shape[0])
    value = (1 - t) * curves[rows, i0c] + t * curves[rows, i0c + 1]
    return np.where(ok, value, 1.0)


def _refined(coef, ys, xs, curves, disparities, support):
    """``coef`` fitted again (least squares) to the disparities of the minima of the
    ``support``'s curves nearest the plane (within a ``STEP`` either side)."""
    A = _rows(xs[support], ys[support])
    d = A @ coef
    steps = np.arange(-4, 5) * STEP / 4
    values = np.stack([_at(curves[support], disparities, d + s) for s in steps], axis=1)
    best = d + steps[values.argmin(axis=1)]
    return np.linalg.lstsq(A, best, rcond=None)[0]


def combs(left, right, d_max, count=COMBS, seed=0):
    """Up to ``count`` planes ``(a, b, c)`` (``d = a x + b y + c``, left view) of the pair's
    layers, each up to a tooth, as the module text says, best supported first, and the
    grid's pixels that support each: ``[(coef, ys, xs)]``.  ``left`` ``(H, W, C)``,
    ``right`` upsampled by ``UPSAMPLE``; ``d_max`` the searched range."""
    ys, xs, disparities, curves = cost_curves(left, right, d_max)
    minima = [_minima(c) for c in curves]
    rng = np.random.default_rng(seed)
    free = np.array([m.size > 0 for m in minima])
    found = []
    for _ in range(count):
        pool = np.nonzero(free)[0]
        if pool.size < 10:
            break
        best, best_support = None, None
        for _ in range(HYPOTHESES):
            first = pool[rng.integers(pool.size)]
            near = pool[(np.abs(ys[pool] - ys[first]) <= SPREAD)
                        & (np.abs(xs[pool] - xs[first]) <= SPREAD)]
            if near.size < 3:
                continue
            three = np.concatenate([[first], rng.choice(near, 2, replace=False)])
            A = _rows(xs[three], ys[three])
            if abs(np.linalg.det(A)) < 1e-6:
                continue
            d = np.array([disparities[rng.choice(minima[i])] for i in three])
            coef = np.linalg.solve(A, d)
            support = free & (_at(curves, disparities, _rows(xs, ys) @ coef) < NEAR)
            if best_support is None or support.sum() > best_support.sum():
                best, best_support = coef, support
        if best is None:
            break
        for _ in range(2):
            best = _refined(best, ys, xs, curves, disparities, best_support)
            best_support = free & (_at(curves, disparities, _rows(xs, ys) @ best) < NEAR)
        found.append((best, ys[best_support], xs[best_support]))
        free &= ~best_support
    return found
