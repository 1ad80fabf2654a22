"""The photometric difference between the views at their matches, and its correction.

The paper's matching cost M is the absolute colour difference, which assumes that a scene
point looks the same in both views.  Real rigs break that: the cameras' exposures and
offsets differ, their gamma differs, and lenses darken towards the corners (vignetting).
A difference of a few grey levels raises M at every true match by as much, and a layer
whose texture is weaker than the difference loses its matches.

Before the solve the difference is measured and, where a simple model explains it, the
right view is corrected to the left one's photometry.  On grey copies of the pair at the
scale of :mod:`lss_kernels.direction` (at most 320 columns), each textured pixel is matched
along its row over ``0 .. d_max`` by the sum of absolute differences of the *detail* (each
view less its 5x5 mean), which a gain or an offset between the views does not move.  At
each match, the right view's 5x5 mean ``b`` is modelled from the left one's ``a`` as

    b = (g_0 + g_2 r^2) a + o,

``r^2`` the squared distance of the right pixel from the image centre (1 at the corners):
a gain, a radial vignetting and an offset, fitted by least squares with ``ROUNDS`` rounds
that keep the matches within 3 robust deviations (wrong matches and occlusions drop out).
The right image becomes ``(R - o) / (g_0 + g_2 r^2)``, per channel, clipped to [0, 1],
when the views differ by at least ``MIN_DIFFERENCE`` (median absolute difference of the
means at the matches) and the model leaves at most ``EXPLAINED`` of that difference
(a gamma between the views, not in the model, is explained to 0.01-0.04 of it on the
rendered probes); else the pair is left as it is.  Measured on paper15 and the stress
scenes: ``docs/design.md``.
"""
import math

import numpy as np

from .direction import (MIN_TEXTURED, WINDOW, box_sums, grey_copies, textured_windows,
                        window_detail)

__all__ = ["EXPLAINED", "MIN_DIFFERENCE", "corrected", "equalise", "fit"]

MIN_DIFFERENCE = 0.02   # views differing less than this at their matches are left alone
EXPLAINED = 0.3         # ... and those whose model leaves more than this share of it
ROUNDS = 4              # rounds of the robust fit
GAIN_RANGE = (0.3, 3.0)  # a fitted gain outside this (centre or corners) is not trusted
MAX_OFFSET = 0.5        # ... nor an offset beyond this (images in [0, 1])


def _radius2(x, y, W, H):
    """Squared distance of pixel centres from the image centre, 1 at the corners."""
    xn, yn = (np.asarray(x) + 0.5) / W - 0.5, (np.asarray(y) + 0.5) / H - 0.5
    return (xn * xn + yn * yn) / 0.5


def fit(left, right, d_max) -> dict:
    """The photometric model of the right view on the left one at their matches.

    ``left``, ``right``: float images in [0, 1] of one shape (colour or grey, compared as
    grey, :func:`~lss_kernels.checks.validate.luma`); ``d_max``: the searched
    range, left-view pixels.  Returns ``gain``, ``vignetting`` (``g_2``), ``offset``,
    ``difference`` and ``residual`` (median absolute difference of the 5x5 means at the
    matches, before and after the model), ``matches`` and ``correct`` (bool), with ``why``
    when the pair is left as it is."""
    f, gl, gr = grey_copies(left, right)
    H, W = gl.shape
    D = max(1, math.ceil(float(d_max) / f))
    facts = {"matches": 0, "correct": False}
    if W - D < 2 * WINDOW or H < WINDOW:
        return {**facts, "why": "the image is too narrow for the search range"}
    detail_left, detail_right = window_detail(gl), window_detail(gr)
    cost = np.full((H - WINDOW + 1, W - D - WINDOW + 1), np.inf)
    shift = np.zeros(cost.shape, np.int64)
    for s in range(D + 1):
        c = box_sums(np.abs(detail_left[:, D:] - detail_right[:, D - s:W - s]), WINDOW)
        better = c < cost
        cost[better], shift[better] = c[better], s
    ys, xs = np.nonzero(textured_windows(gl[:, D:]))
    facts["matches"] = int(ys.size)
    if ys.size < MIN_TEXTURED:
        return {**facts, "why": f"fewer than {MIN_TEXTURED} textured pixels"}
    area = WINDOW * WINDOW
    xr = xs + D - shift[ys, xs]                    # the right window's first column
    a = box_sums(gl, WINDOW)[:, D:][ys, xs] / area
    b = box_sums(gr, WINDOW)[ys, xr] / area
    r2 = _radius2(xr + WINDOW // 2, ys + WINDOW // 2, W, H)
    A = np.stack([a, a * r2, np.ones_like(a)], axis=1)
    keep = np.ones(a.size, bool)
    for _ in range(ROUNDS):
        g0, g2, o = np.linalg.lstsq(A[keep], b[keep], rcond=None)[0]
        residual = np.abs(b - A @ (g0, g2, o))
        keep = residual <= max(3.0 * 1.4826 * float(np.median(residual[keep])), 0.01)
    difference = float(np.median(np.abs(b - a)))
    left_over = float(np.median(residual))
    facts.update(gain=float(g0), vignetting=float(g2), offset=float(o),
                 difference=difference, residual=left_over)
    lo, hi = GAIN_RANGE
    if not (lo <= g0 <= hi and lo <= g0 + g2 <= hi and abs(o) <= MAX_OFFSET):
        facts["why"] = "the fitted model is out of range (too few or wrong matches)"
    elif difference < MIN_DIFFERENCE:
        facts["why"] = f"the views differ by less than {MIN_DIFFERENCE} at their matches"
    elif left_over > EXPLAINED * difference:
        facts["why"] = (f"the model leaves more than {EXPLAINED:.0%} of the difference "
                        f"unexplained")
    else:
        facts["correct"] = True
    return facts


def equalise(left, right, d_max):
    """``(right, facts)``: the right image corrected to the left one's photometry where
    :func:`fit` says so (else ``right`` itself), and :func:`fit`'s facts."""
    facts = fit(left, right, d_max)
    return corrected(right, facts), facts


def corrected(right, facts):
    """``right`` corrected by :func:`fit`'s model where ``facts["correct"]``, else itself."""
    if not facts["correct"]:
        return right
    H, W = right.shape[:2]
    y, x = np.mgrid[0:H, 0:W]
    gain = facts["gain"] + facts["vignetting"] * _radius2(x, y, W, H)
    gain = gain[..., None] if np.ndim(right) == 3 else gain
    out = (np.asarray(right, np.float64) - facts["offset"]) / gain
    return np.clip(out, 0.0, 1.0).astype(np.float32)
