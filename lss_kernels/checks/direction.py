"""Which way and how far a pair's matches run: checks for swapped views and for a search range
that is too short, before the solve.

The model reads the pair in the Middlebury convention: the left image is the reference and a
left pixel ``x`` matches the right pixel ``x - d`` with ``d >= 0``.  Passed the other way
round (the right image first), every match runs the other way, the searched range holds no
true match, and the model explains nothing (on the tiny scene the foreground vanishes after
18 iterations, and the retry of :mod:`lss_kernels.checks.recovery` collapses too).  Nothing
in the output says why, so the pair is examined first.

On a grey copy of the pair, block-averaged to at most ``MAX_WIDTH`` columns, each pixel's
best sum of absolute differences over a ``WINDOW`` square is found along the row for the
stated direction (``x - s``, ``s = 1 .. d``) and for the reversed one (``x + s``), over the
columns where both can be read.  A direction *wins* a pixel whose gradient is textured
(mean absolute horizontal difference over the window above ``TEXTURE``) where its best cost
is below ``MARGIN`` times the other's.  The pair looks swapped when the reversed direction
wins at least ``SWAPPED_SHARE`` of the textured pixels and ``SWAPPED_RATIO`` times as many
as the stated one.  A pair with no parallax (identical views, a distant scene) or with
periodic texture matches both ways alike and is not flagged; nor is a pair with too little
texture to tell (fewer than ``MIN_TEXTURED`` pixels).

A search range shorter than the scene's disparities is the other silent failure: the
nearer surface has no match inside ``[0, d_max]``, and the foreground vanishes or lies.
:func:`match_range` compares, in the stated direction, each textured pixel's best cost within
the range (``s = 0 .. d``) with its best just beyond it (``d < s <= 2 d``), on the grey
copies and on their detail (less the window's mean); the range looks too short when the
beyond wins on both at least ``SHORT_SHARE`` of the textured pixels (about the share of them
whose disparity the range misses).  The detail keeps a gain between the views (exposure)
from passing for matches beyond the range; the grey levels keep stripes from doing so.

With no range given, :func:`estimate_range` proposes one from the same grey copies: each
textured pixel's best shift over half the image's width (grey and detail costs summed) is
kept where it is distinct (below ``MARGIN`` times the best beyond one shift of it) and the
right view's best match of its match points back to it.  A shift holds signal where its
kept matches (averaged with its neighbours') exceed ``RANGE_FLOOR`` times the median shift's
(false matches spread evenly over the shifts); such shifts at most ``RANGE_GAP`` px apart
form runs, runs with less than ``RANGE_SHARE`` of the kept matches are dropped (repeated
texture matched far off), and the range is 15 % and 8 px above the farthest shift with
signal, rounded up to 8 px.  A layer without texture gives no matches, so its disparity can
lie beyond the proposal; repeated texture and noise can put it far beyond the scene's.

Measured on paper15 and the stress scenes (``python -m lss_kernels.stress``, seeds 0 and 2):
see ``docs/design.md``.
"""
import math

import numpy as np

from .validate import luma

__all__ = ["MARGIN", "RANGE_FLOOR", "RANGE_GAP", "RANGE_SHARE", "SHORT_SHARE", "SWAPPED_RATIO",
           "SWAPPED_SHARE", "box_sums", "estimate_range", "grey_copies", "match_direction",
           "match_range", "textured_windows", "window_detail"]

MAX_WIDTH = 320        # the check's image width at most, pixels (block averages)
WINDOW = 5             # side of the square that sums absolute differences, pixels
TEXTURE = 0.01         # mean |horizontal difference| of a textured window (grey in [0, 1])
MARGIN = 0.8           # a direction wins a pixel where its cost is below MARGIN x the other's
SWAPPED_SHARE = 0.5    # swapped: the reversed direction wins this share of textured pixels
SWAPPED_RATIO = 3.0    # ... and this many times as many as the stated one
MIN_TEXTURED = 200     # fewer textured pixels: no verdict
SHORT_SHARE = 0.1      # range too short: matches beyond it win this share of textured pixels
RANGE_FLOOR = 4.0      # estimate_range: a shift's matches must exceed this x the median shift's
RANGE_GAP = 8          # ... such shifts farther apart than this (px) split into runs
RANGE_SHARE = 0.003    # ... and runs with less than this share of the kept matches are dropped


def box_sums(a, k):
    """Sums of ``a`` over ``k x k`` windows (valid part: ``(H - k + 1, W - k + 1)``; the
    running sums in float64, which keep a window's sum exact to well below its pixels')."""
    c = np.pad(np.cumsum(np.cumsum(a, axis=0, dtype=np.float64), axis=1), ((1, 0), (1, 0)))
    return c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]


def _grey(image, f):
    g = luma(image)
    H, W = (g.shape[0] // f) * f, (g.shape[1] // f) * f
    return g[:H, :W].reshape(H // f, f, W // f, f).mean(axis=(1, 3))


def grey_copies(left, right):
    """The check's scale (block size) and the pair's grey copies (:func:`~lss_kernels.checks.
    validate.luma`; ``(H, W)`` images as they are) at it."""
    f = max(1, math.ceil(np.shape(left)[1] / MAX_WIDTH))
    return f, _grey(left, f), _grey(right, f)


def textured_windows(g):
    """The windows of ``g`` whose mean absolute horizontal difference is above ``TEXTURE``
    (the valid part of :func:`box_sums`)."""
    gradient = np.abs(np.diff(g, axis=1, append=g[:, -1:]))
    return box_sums(gradient, WINDOW) > TEXTURE * WINDOW * WINDOW


def window_detail(g):
    """``g`` less its mean over the ``WINDOW`` square around each pixel (edges repeated): a
    gain or offset between the views then scales the costs of true matches, not raises them."""
    h = WINDOW // 2
    return g - box_sums(np.pad(g, h, mode="edge"), WINDOW) / (WINDOW * WINDOW)


def match_direction(left, right, d_max) -> dict:
    """Whether the pair's matches run the stated way (``x_right = x_left - d``).

    ``left``, ``right``: float images in [0, 1] of one shape (``(H, W)`` or ``(H, W, C)``);
    ``d_max``: the searched range, left-view pixels.  Returns ``stated`` and ``reversed``
    (the share of textured pixels each direction wins), ``textured`` (their count at the
    check's scale), ``scale`` (the block size) and ``swapped`` (bool)."""
    f, gl, gr = grey_copies(left, right)
    H, W = gl.shape
    D = min(max(1, math.ceil(float(d_max) / f)), (W - WINDOW) // 2)
    facts = {"scale": f, "textured": 0, "stated": 0.0, "reversed": 0.0, "swapped": False}
    if D < 1 or H < WINDOW:
        return facts
    cols = slice(D, W - D)                     # the columns both directions can read
    best = []
    for sign in (-1, 1):                       # -1: x - s (stated), +1: x + s (reversed)
        cost = np.full((H - WINDOW + 1, W - 2 * D - WINDOW + 1), np.inf)
        for s in range(1, D + 1):
            shifted = gr[:, D + sign * s:W - D + sign * s]
            cost = np.minimum(cost, box_sums(np.abs(gl[:, cols] - shifted), WINDOW))
        best.append(cost)
    textured = textured_windows(gl[:, cols])
    n = int(textured.sum())
    facts["textured"] = n
    if n < MIN_TEXTURED:
        return facts
    stated = float((textured & (best[0] < MARGIN * best[1])).sum()) / n
    reverse = float((textured & (best[1] < MARGIN * best[0])).sum()) / n
    facts.update(stated=stated, reversed=reverse,
                 swapped=reverse >= SWAPPED_SHARE and reverse >= SWAPPED_RATIO * stated)
    return facts


def match_range(left, right, d_max) -> dict:
    """Whether the pair's matches lie inside the searched range ``[0, d_max]``.

    Arguments as for :func:`match_direction`.  Returns ``beyond`` (the share of textured
    pixels whose best cost at shifts ``d_max < s <= 2 d_max`` is below ``MARGIN`` times their
    best within the range), ``textured``, ``scale`` and ``short`` (bool); ``short`` is False
    without a verdict (an image too narrow for the shifts, or too little texture)."""
    f, gl, gr = grey_copies(left, right)
    H, W = gl.shape
    D = max(1, math.ceil(float(d_max) / f))
    E = min(2 * D, W - 2 * WINDOW)             # the farthest shift read; columns E .. W - 1
    facts = {"scale": f, "textured": 0, "beyond": 0.0, "short": False}
    if E <= D or H < WINDOW:
        return facts

    def best(a, b, shifts):
        cost = np.full((H - WINDOW + 1, W - E - WINDOW + 1), np.inf)
        for s in shifts:
            cost = np.minimum(cost, box_sums(np.abs(a[:, E:] - b[:, E - s:W - s]), WINDOW))
        return cost
    textured = textured_windows(gl[:, E:])
    n = int(textured.sum())
    facts["textured"] = n
    if n < MIN_TEXTURED:
        return facts
    beyond_wins = textured
    for a, b in ((gl, gr), (window_detail(gl), window_detail(gr))):
        beyond_wins = beyond_wins & (best(a, b, range(D + 1, E + 1))
                                     < MARGIN * best(a, b, range(0, D + 1)))
    share = float(beyond_wins.sum()) / n
    facts.update(beyond=share, short=share >= SHORT_SHARE)
    return facts


def estimate_range(left, right) -> dict:
    """A search range for a pair given none: the largest disparity of its distinct,
    left-right consistent matches (module text), with a margin.

    ``left``, ``right``: float images in [0, 1] of one shape.  Returns ``d_max`` (left-view
    px, a multiple of 8, at least 16 and below the width), ``farthest`` (the farthest shift with signal, px),
    ``matches`` (the pixels kept, at the check's scale) and ``scale``.  Raises ValueError
    when fewer than ``MIN_TEXTURED`` matches are kept (too little texture)."""
    f, gl, gr = grey_copies(left, right)
    H, W = gl.shape
    S = W // 2
    if H < WINDOW or S < 1:
        raise ValueError(f"left: {W * f}x{H * f} pixels are too few to estimate d_max; give it")
    dl, dr = window_detail(gl), window_detail(gr)
    Hc, Wc = H - WINDOW + 1, W - WINDOW + 1
    cost = np.full((S + 1, Hc, Wc), np.inf, np.float32)
    for s in range(S + 1):                     # left x against right x - s, x >= s
        cost[s, :, s:] = (box_sums(np.abs(gl[:, s:] - gr[:, :W - s]), WINDOW)
                          + box_sums(np.abs(dl[:, s:] - dr[:, :W - s]), WINDOW))
    best = np.argmin(cost, axis=0)
    lowest = np.take_along_axis(cost, best[None], 0)[0]
    shifts = np.arange(S + 1)[:, None, None]
    beyond = np.where(np.abs(shifts - best[None]) > 1, cost, np.inf).min(axis=0)
    # the right view's best match of right column u = x - s, read off the same costs
    back = np.full((Hc, Wc), np.inf, np.float32)
    back_best = np.zeros((Hc, Wc), np.int64)
    for s in range(S + 1):
        c = cost[s, :, s:]
        better = c < back[:, :Wc - s]
        back[:, :Wc - s] = np.where(better, c, back[:, :Wc - s])
        back_best[:, :Wc - s] = np.where(better, s, back_best[:, :Wc - s])
    u = np.arange(Wc)[None, :] - best
    mutual = np.abs(np.take_along_axis(back_best, np.clip(u, 0, Wc - 1), 1) - best) <= 1
    kept = (textured_windows(gl) & np.isfinite(lowest) & (lowest < MARGIN * beyond)
            & (u >= 0) & mutual)
    found = best[kept]
    if found.size < MIN_TEXTURED:
        raise ValueError(f"left, right: {found.size} distinct matches, too few to estimate "
                         f"d_max (at least {MIN_TEXTURED}); give it")
    hist = np.bincount(found, minlength=S + 1)
    counts = np.convolve(hist, np.ones(3) / 3, mode="same")
    floor = RANGE_FLOOR * np.median(counts)
    signal = np.nonzero(counts > floor)[0]
    runs = np.split(signal, np.nonzero(np.diff(signal) * f > RANGE_GAP)[0] + 1)
    runs = [r for r in runs if r.size and hist[r[0]:r[-1] + 1].sum() >= RANGE_SHARE * found.size]
    if runs:                                   # the last run's farthest shift above the floor
        last = max(runs, key=lambda r: r[-1])
        above = np.nonzero(hist[last[0]:last[-1] + 1] > floor)[0]
        farthest = float((last[0] + above[-1] if above.size else last[-1]) * f)
    else:
        farthest = float(np.argmax(hist) * f)
    # a multiple of 8 from 16, below the image's width (what lss_kernels.checks.validate accepts)
    d_max = min(max(16, 8 * math.ceil((1.15 * farthest + 8) / 8)),
                max(1, 8 * ((W * f - 1) // 8)))
    return {"d_max": d_max, "farthest": farthest, "matches": int(found.size), "scale": f}
