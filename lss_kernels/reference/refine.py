"""Readable numpy specifications of the steps after the alternation
(:mod:`lss_kernels.model.refine`, :meth:`lss_kernels.model.occlusion.OcclusionGeometry.
measure_strips`): the left-view AD-Census cost, surface plus parallax, and the occluded
strips measured against the refined background.  Plain, float64; left-view ``(H, W)``
arrays and left-view disparities, as those kernels take them.
"""
import numpy as np

from ..model import FIXED_POINT_STEPS
from ..model.occlusion import STRIP_EVIDENCE
from .kernels import box_sum, census, second_best

__all__ = ["left_cost", "refine_layers", "refine_with_evidence", "occluded_strips"]


def left_cost(left, right, d, censuses):
    """The AD-Census cost (as :func:`.kernels.matching_cost`) of every left pixel (y, x) against the
    right pixel (y, x - d); NaN where x - d leaves the image.  ``censuses``: the
    :func:`census` of both images."""
    H, W, _ = left.shape
    cost = np.full((H, W), np.nan)
    if d >= W:
        return cost
    ad = np.abs(left[:, d:] - right[:, :W - d]).mean(axis=2)
    cl, cr = censuses
    hamming = (cl[:, d:] != cr[:, :W - d]).sum(axis=2) / 48.0
    cost[:, d:] = (1 - np.exp(-ad / (10 / 255))) + (1 - np.exp(-hamming / (30 / 63)))
    return cost


def refine_layers(left, right, surface, foreground, occlusion, d_max, passes, ratio,
                  support=0.0, wide_weight=0.05):
    """Surface plus parallax (:mod:`lss_kernels.model.refine`): per pass ``(R, window,
    smoothing)``, the layer-restricted window mean of the AD-Census cost for the candidates
    ``round(S) - R .. round(S) + R``, the distinct interior best (peak ratio) refined by a
    parabola, the layer-restricted average of its residual (its denominator at least
    ``support`` times the boxes' layer pixels), added to S and clamped.  S starts clamped
    to ``[0, d_max]`` (non-finite: 0)."""
    return refine_with_evidence(left, right, surface, foreground, occlusion, d_max, passes,
                                ratio, support, wide_weight)[0]


def refine_with_evidence(left, right, surface, foreground, occlusion, d_max, passes, ratio,
                         support=0.0, wide_weight=0.05):
    """:func:`refine_layers` with the refinement's evidence: ``(S, match, peak_ratio)``, the
    match the distinct pixels of the last pass kept (the pass's surface elsewhere) and
    every pixel's best cost over its second best (1 where no second candidate has a cost or
    both costs are 0), the largest of the passes."""
    H, W = surface.shape
    S = np.asarray(surface, np.float64)
    S = np.clip(np.where(np.isfinite(S), S, 0.0), 0.0, d_max)
    layers = [np.asarray(foreground, bool), ~np.asarray(foreground, bool)]
    visible = ~np.asarray(occlusion, bool)
    censuses = census(left), census(right)
    peak_ratio = np.zeros((H, W))
    costs_by_d = {d: left_cost(left, right, d, censuses) for d in range(int(d_max) + 1)}
    for R, window, smoothing in passes:
        base = np.round(S).astype(int)
        costs = np.full((2 * R + 1, H, W), np.inf)
        for d in range(int(d_max) + 1):
            c = costs_by_d[d]
            inside = np.isfinite(c)
            for lab in layers:
                num = box_sum(np.where(inside & lab, c, 0.0), 2 * window + 1)
                den = box_sum((inside & lab).astype(float), 2 * window + 1)
                k = d - base + R
                ok = lab & inside & (k >= 0) & (k <= 2 * R) & (den > 0)
                costs[np.where(ok, k, 0), np.arange(H)[:, None], np.arange(W)] = np.where(
                    ok, num / np.maximum(den, 1e-30),
                    costs[np.where(ok, k, 0), np.arange(H)[:, None], np.arange(W)])
        kb = costs.argmin(axis=0)
        best = costs.min(axis=0)
        second = second_best(costs, kb, axis=0)
        cm = np.take_along_axis(costs, np.clip(kb - 1, 0, 2 * R)[None], 0)[0]
        cp = np.take_along_axis(costs, np.clip(kb + 1, 0, 2 * R)[None], 0)[0]
        ok = ((kb > 0) & (kb < 2 * R) & visible & np.isfinite(best) & np.isfinite(cm)
              & np.isfinite(cp) & (best < ratio * second))
        with np.errstate(invalid="ignore", divide="ignore"):
            den = cm - 2 * best + cp
            sub = np.where(ok & (den > 0), 0.5 * (cm - cp) / den, 0.0)
        residual = np.where(ok, base + kb - R + sub - S, 0.0)
        match = S + residual
        with np.errstate(invalid="ignore"):
            peak_ratio = np.maximum(peak_ratio, np.where(
                np.isfinite(second) & (second > 0), best / np.where(second > 0, second, 1.0),
                1.0))
        weight = ok.astype(float)
        boxes = lambda a: (box_sum(a, 2 * smoothing + 1)
                           + wide_weight * box_sum(a, 8 * smoothing + 1))
        for lab in layers:
            num = boxes(weight * residual * lab)
            den = np.maximum(boxes(weight * lab), support * boxes(lab.astype(float)))
            S = np.where(lab & (den > 0), S + num / np.where(den > 0, den, 1.0), S)
        S = np.clip(S, 0.0, d_max)
    return S, match, peak_ratio


def occluded_strips(foreground, surface, refined, matched, near, far, steps=FIXED_POINT_STEPS,
                    least=STRIP_EVIDENCE):
    """The left-view occlusion with each strip measured against the refined background
    (``OcclusionGeometry.measure_strips``).  ``foreground`` bool, ``surface`` the model's
    left-view disparity (each layer's quadratic), ``refined`` the refined disparity,
    ``matched`` the pixels with a distinct match of their own in the refinement's last pass,
    all ``(H, W)`` left-view arrays.

    A run ``[a, b)`` of foreground pixels of a row, ``a > 0``, hides from the right camera
    the background pixels ``x`` with ``ceil(a - t - 1/2) <= x < a`` and ``x <= b - 1/2 -
    t_b``, ``t_b = t + S(b - 1) - S(a)``, where ``t`` is the jump from the foreground at
    its edge to the background where it is seen again, at ``x0 = floor(a - t - 1/2)``:
    the fixed point of ``t = S(a) - (S(x0) + r)``, ``r`` the median of ``refined - S`` over
    the matched background pixels of ``[x0 - far, x0 - near]`` (0 when it holds fewer than
    ``least``: the quadratic's own jump), started at the jump ``S(a) - S(a - 1)``; at most
    ``steps`` steps, ending early (with the last ``t``) once a step changes ``t`` by less
    than 1e-3, or before it when ``x0`` leaves the image or falls on the foreground."""
    fg = np.asarray(foreground, bool)
    evidence = ~fg & np.asarray(matched, bool)
    S, R = np.asarray(surface, np.float64), np.asarray(refined, np.float64)
    occ = np.zeros_like(fg)
    for y in range(fg.shape[0]):
        starts = np.flatnonzero(fg[y, 1:] & ~fg[y, :-1]) + 1
        ends = np.flatnonzero(fg[y, :-1] & ~fg[y, 1:]) + 1
        for a in starts:
            b = ends[ends > a][0] if (ends > a).any() else fg.shape[1]
            t = S[y, a] - S[y, a - 1]
            for _ in range(steps):
                x0 = int(np.floor(a - t - 0.5))
                if t <= 0 or x0 < 0 or fg[y, x0]:
                    break
                lo = max(x0 - far, 0)
                hi = max(x0 - near + 1, lo)     # an empty window near the border
                window = evidence[y, lo:hi]
                r = np.median((R - S)[y, lo:hi][window]) if window.sum() >= least else 0.0
                t_new = S[y, a] - S[y, x0] - r
                done = abs(t_new - t) < 1e-3
                t = t_new
                if done:
                    break
            if t > 0:
                first = max(int(np.ceil(a - t - 0.5)), 0)
                last = min(a - 1, int(np.floor(b - 0.5 - (t + S[y, b - 1] - S[y, a]))))
                if last >= first:
                    occ[y, first:last + 1] |= ~fg[y, first:last + 1]
    return occ
