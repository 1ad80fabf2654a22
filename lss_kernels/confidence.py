"""Per-pixel confidence of the left-view disparity, from what the solve already knows, and how
a confidence is judged (the sparsification curve).

A pixel's disparity can be wrong for five reasons the model can see:

- it is **occluded** (seen by the left camera only, Sec. 2): its depth is the background's
  surface continued under the foreground, with no match to check it against;
- it lies **near the boundary** (phi's zero level, Eq. 2) that may be off by a pixel or two:
  a pixel on the wrong side keeps the other layer's depth.  How far off the boundary may
  be depends on the evidence around it, its **local stability**: amid distinct matches the
  boundary cost pins it within about a pixel, amid pixels without a distinct match it can
  sit several pixels off;
- its **match is not distinct**: the peak ratio of the refinement's plane sweep
  (:mod:`lss_kernels.model.refine`, the best window cost over the second best away from
  it; 1 for a flat or periodic cost curve);
- the refinement's **residual**: its own distinct match disagrees with the answer (the
  layer's surface plus the smoothed residual of its neighbours);
- the left image is **periodic** around it along the rows
  (:func:`lss_kernels.checks.periodicity.periodicity`): a match there is one of several
  equally good, whatever its peak ratio over a range shorter than the period says.  A
  periodic pair is solved without the refinement first (:mod:`lss_kernels.checks.recovery`),
  and then this is the only evidence about its matches.

The confidence is the product of one factor in ``[0, 1]`` per reason (:func:`confidence`).
It ranks pixels; it is not a probability.

A confidence is judged by sparsification (:func:`sparsification`): the pixels are dropped
from the least confident up, and bad-4.0 of those kept is plotted against the fraction kept.
A useful confidence gives a falling curve; :func:`confidence_ratio` summarises it as the
bad-4.0 of the least confident 10 % over that of the most confident 50 %.
"""
from __future__ import annotations

import numpy as np

__all__ = ["BOUNDARY_REACH", "BOUNDARY_WIDTH", "RESIDUAL_SCALE", "STABILITY_WINDOW",
           "boundary_distance", "confidence", "confidence_ratio", "local_stability",
           "of_solver", "periodic_map", "sparsification"]

#: Pixels (left view): the boundary's distance is measured up to this far; beyond it the
#: boundary factor is within 0.2 % of 1 for the widths :func:`confidence` uses (at most 5).
BOUNDARY_REACH = 32
#: Half-side (pixels) of the window over which the boundary's local stability is measured.
STABILITY_WINDOW = 4
#: Disparity (left-view pixels) at which a residual lowers the residual factor to 1/e.
RESIDUAL_SCALE = 1.0
#: Boundary width (pixels) amid distinct matches, and its growth amid none.
BOUNDARY_WIDTH = (1.0, 4.0)


def _mask(value, name, shape=None):
    a = np.asarray(value)
    if a.ndim != 2 or (shape is not None and a.shape != shape):
        want = "HxW" if shape is None else f"{shape}"
        raise ValueError(f"{name}: expected an array of shape {want}, got shape {a.shape}")
    return a


def boundary_distance(foreground, reach: int = BOUNDARY_REACH) -> np.ndarray:
    """Chamfer distance (pixels; steps of 1 and sqrt 2) from every pixel to the nearest pixel
    of the other layer, minus one: 0 on the pixels that touch the other layer (4- or
    8-neighbours), capped at ``reach``.

    Parameters
    ----------
    foreground : ndarray, bool, shape (H, W)
        Left-view foreground.

    Returns
    -------
    ndarray, float64, shape (H, W)
        ``reach`` everywhere when the image holds one layer only.
    """
    fg = _mask(foreground, "foreground").astype(bool)
    H, W = fg.shape
    dist = np.full((H, W), float(reach))
    padded = np.pad(fg, 1, mode="edge")
    touches = np.zeros((H, W), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            touches |= padded[1 + dy:1 + dy + H, 1 + dx:1 + dx + W] != fg
    dist[touches] = 0.0
    steps = [(dy, dx, float(np.hypot(dy, dx))) for dy in (-1, 0, 1) for dx in (-1, 0, 1)
             if dy or dx]
    for _ in range(reach):
        before = dist
        big = np.pad(dist, 1, constant_values=float(reach))
        dist = np.minimum.reduce([dist] + [big[1 + dy:1 + dy + H, 1 + dx:1 + dx + W] + step
                                           for dy, dx, step in steps])
        dist = np.minimum(dist, float(reach))
        if np.array_equal(dist, before):
            break
    return dist


def _box_mean(values, radius: int) -> np.ndarray:
    """Mean of ``values`` over the in-image pixels of the ``(2 radius + 1)^2`` window."""
    H, W = values.shape
    c = np.zeros((H + 1, W + 1))
    c[1:, 1:] = np.cumsum(np.cumsum(values, axis=0), axis=1)
    y0 = np.clip(np.arange(H) - radius, 0, H)
    y1 = np.clip(np.arange(H) + radius + 1, 0, H)
    x0 = np.clip(np.arange(W) - radius, 0, W)
    x1 = np.clip(np.arange(W) + radius + 1, 0, W)
    total = c[y1][:, x1] - c[y0][:, x1] - c[y1][:, x0] + c[y0][:, x0]
    area = (y1 - y0)[:, None] * (x1 - x0)[None, :]
    return total / area


def local_stability(distinct, radius: int = STABILITY_WINDOW) -> np.ndarray:
    """The share of pixels holding a distinct match within ``radius`` pixels (a square
    window, clamped to the image): 1 where the boundary cost has evidence on every pixel
    around, 0 where it has none."""
    return _box_mean(_mask(distinct, "distinct").astype(float), radius)


def periodic_map(image, score=None) -> np.ndarray:
    """:func:`lss_kernels.checks.periodicity.periodicity` of ``image`` ``(H, W, 3)`` per
    pixel ``(H, W)`` (``score``: that periodicity, when it is known): each pixel takes its
    tile's score (the pixels past the last tile, the nearest tile's); 0 everywhere for an
    image smaller than a tile."""
    from .checks.periodicity import TILE, periodicity
    H, W = np.asarray(image).shape[:2]
    score = periodicity(image) if score is None else score
    if score.size == 0:
        return np.zeros((H, W))
    rows = np.minimum(np.arange(H) // TILE[0], score.shape[0] - 1)
    cols = np.minimum(np.arange(W) // TILE[1], score.shape[1] - 1)
    return score[rows][:, cols]


def confidence(disparity, foreground, occlusion, match, peak_ratio, distinct,
               periodic=None) -> np.ndarray:
    """Per-pixel confidence of a left-view disparity, in ``[0, 1]``.

    ``C = C_occ * C_match * C_residual * C_boundary * C_periodic`` with

    - ``C_occ``: 0 on occluded pixels, 1 elsewhere;
    - ``C_match = 1 - peak_ratio``: the distinctness of the pixel's best match;
    - ``C_residual = exp(-|match - disparity| / RESIDUAL_SCALE)`` on pixels with a distinct
      match, 1 on the others (no evidence against the answer);
    - ``C_boundary = 1 - exp(-(dist + 1) / width)``: ``dist`` the pixel's
      :func:`boundary_distance`, ``width = 1 + 4 (1 - s)`` pixels with ``s`` the
      boundary's :func:`local_stability` around the pixel;
    - ``C_periodic = 1 - periodic``: the image's periodicity around the pixel
      (:func:`periodic_map`).

    Parameters
    ----------
    disparity : ndarray, float, shape (H, W)
        The answer (left view, pixels).
    foreground, occlusion : ndarray, bool, shape (H, W)
        The layers and the occluded pixels (left view).
    match : ndarray, float, shape (H, W)
        The refinement's last match per pixel (left-view disparity).
    peak_ratio : ndarray, float, shape (H, W)
        Its best cost over its second best, in ``(0, 1]``.
    distinct : ndarray, bool, shape (H, W)
        Pixels whose match passed the peak-ratio test.
    periodic : ndarray, float, shape (H, W), optional
        The left image's periodicity in [0, 1] (:func:`periodic_map`); None: 0.

    Returns
    -------
    ndarray, float32, shape (H, W)
    """
    disparity = np.asarray(_mask(disparity, "disparity"), np.float64)
    shape = disparity.shape
    occlusion = _mask(occlusion, "occlusion", shape).astype(bool)
    distinct = _mask(distinct, "distinct", shape).astype(bool)
    ratio = np.clip(np.nan_to_num(_mask(peak_ratio, "peak_ratio", shape), nan=1.0), 0.0, 1.0)
    residual = np.abs(np.asarray(_mask(match, "match", shape), np.float64) - disparity)
    c_match = 1.0 - ratio
    c_residual = np.where(distinct, np.exp(-np.nan_to_num(residual, nan=np.inf)
                                           / RESIDUAL_SCALE), 1.0)
    width = BOUNDARY_WIDTH[0] + BOUNDARY_WIDTH[1] * (1.0 - local_stability(distinct))
    c_boundary = 1.0 - np.exp(-(boundary_distance(_mask(foreground, "foreground", shape)) + 1.0)
                              / width)
    c_periodic = 1.0 if periodic is None else 1.0 - np.clip(
        _mask(periodic, "periodic", shape), 0.0, 1.0)
    return np.where(occlusion, 0.0, c_match * c_residual * c_boundary * c_periodic
                    ).astype(np.float32)


def of_solver(solver, disparity, foreground, occlusion) -> np.ndarray:
    """:func:`confidence` of a :class:`~lss_kernels.Solver`'s left-view output (after its
    ``left_view(refine=True)``), from its refinement's planes
    (:class:`~lss_kernels.model.refine.LayerRefinement`: the last pass's match, the peak
    ratio, the largest of the passes, and the last pass's distinct matches) and its left
    image.  Without the refinement (``Params(refine=False)``) there is no match evidence:
    the match is the disparity, the ratio 0 and no pixel distinct."""
    from .model.offset import to_user_left
    disparity_shape = np.shape(disparity)
    refinement = solver.refinement
    if refinement is None:
        evidence = (disparity, np.zeros(disparity_shape), np.zeros(disparity_shape, bool))
    else:
        user = lambda plane: to_user_left(solver.extent.image(plane), solver.shift)
        evidence = (np.clip(user(refinement.match) - solver.offset, 0.0, solver.d_max),
                    user(refinement.peak_ratio), user(refinement.weight) > 0.5)
    return confidence(disparity, foreground, occlusion, *evidence,
                      periodic_map(solver.left_image, solver.pair.periodicity))


def sparsification(confidence, bad, fractions=None):
    """Bad-pixel rate of the most confident pixels against the fraction kept.

    Parameters
    ----------
    confidence : ndarray, float, shape (N,)
        Of the scored pixels (higher: surer); NaN counts as the least sure.
    bad : ndarray, bool, shape (N,)
        Whether each scored pixel is bad (e.g. ``|d - d_true| > 4``).
    fractions : sequence of float in (0, 1], optional
        Fractions of pixels kept (default 0.05, 0.10, ..., 1.00).

    Returns
    -------
    fractions, rates : ndarray, float64
        ``rates[i]``: percentage of bad pixels among the ``ceil(fractions[i] N)`` most
        confident (ties broken by the pixels' order; NaN when N is 0).
    """
    conf = np.nan_to_num(np.asarray(confidence, np.float64).ravel(), nan=-np.inf)
    bad = np.asarray(bad, bool).ravel()
    if conf.shape != bad.shape:
        raise ValueError(f"bad: expected {conf.size} values like confidence, got {bad.size}")
    fractions = (np.arange(1, 21) / 20.0 if fractions is None
                 else np.asarray(fractions, np.float64))
    if fractions.size == 0 or not ((fractions > 0) & (fractions <= 1)).all():
        raise ValueError(f"fractions: expected values in (0, 1], got {fractions!r}")
    order = np.argsort(-conf, kind="stable")
    cumulative = np.cumsum(bad[order])
    n = conf.size
    rates = np.full(fractions.shape, np.nan)
    if n:
        kept = np.maximum(np.ceil(fractions * n - 1e-9).astype(int), 1)
        rates = 100.0 * cumulative[kept - 1] / kept
    return fractions, rates


def confidence_ratio(confidence, bad):
    """Bad-pixel rate of the least confident 10 % over that of the most confident 50 %
    (``inf`` when the latter is 0 and the former is not, NaN when both are 0).

    Returns
    -------
    ratio, worst, best : float
        The ratio and the two rates (percent).
    """
    conf = np.nan_to_num(np.asarray(confidence, np.float64).ravel(), nan=-np.inf)
    bad = np.asarray(bad, bool).ravel()
    n = conf.size
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    order = np.argsort(-conf, kind="stable")
    ranked = bad[order]
    best = 100.0 * ranked[:max(int(np.ceil(0.5 * n)), 1)].mean()
    worst = 100.0 * ranked[n - max(int(np.ceil(0.1 * n)), 1):].mean()
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = float(np.float64(worst) / np.float64(best))
    return ratio, float(worst), float(best)
