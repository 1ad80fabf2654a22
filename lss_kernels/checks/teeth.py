"""The foreground's tooth on periodic texture: the offset of the object's surface, and the
move of its outline, that make the outline land where the right image shows it.

On stripes a whole period is a valid match for either layer, and the alternation can settle
with Theta_1 some periods off, its outline moved with it (the matches inside the object
cannot tell; ``periodic_same_*`` of ``lss_kernels.stress --periodic``).  The object's
outline is not periodic: where the object's stripes meet the background's (another phase,
period or colour), the right image shows the outline at ``x - d_fg``, and only the true
tooth puts it there.  So, after each solve of a periodic pair
(:func:`~lss_kernels.checks.recovery.with_recovery`), the left image is warped onto the right
one (:func:`warp_cost`: the right image's rows resampled ``UPSAMPLE`` times by FFT, the
occlusion each model implies, a hidden pixel costing ``HIDDEN_COST``).  The candidates are
the foreground's surface as solved and as a plane fitted to it, each moved by the offsets
``s`` where the inside of the object matches best (the dips of :func:`_teeth`, a period
apart: :func:`row_period`), and for each such tooth the plane fitted to the inside's own
matches within half a period of it (:func:`_refit`: a bent solved surface is no tooth
anywhere), with the outline moved by ``t`` columns between 0 and ``s``
(``MARGIN`` beyond); the best is refined to ``FINE_STEP`` px and a column.  It is taken when
``|s|`` is at least half a period and its warp differs from the right image by
``MIN_GAIN`` less than the solved model's.

A wrong tooth ``k`` periods too small leaves about ``2 k P`` pixels a row mismatched (the
object's last stripes land on the background, and background pixels that are hidden are
taken as seen), one too large about ``k P``; the right one none.  The background's tooth is
not in the pair: with a periodic background of constant disparity the two images are the
same, pixel for pixel, for ``d_bg`` and ``d_bg + P`` (every background pixel matches a
period away, and the occluded strip's width cannot be read).  It is left as solved, unless
it lies less than ``MIN_JUMP`` behind the object, moved or not: then it goes to the nearest
of its teeth behind (:func:`_behind`).
"""
import numpy as np

from .direction import box_sums
from .validate import luma

__all__ = ["FINE_STEP", "HIDDEN_COST", "MARGIN", "MIN_GAIN", "MIN_JUMP", "PEAK", "REFIT_RADIUS",
           "STEP", "TOOTH_DEPTH", "TOOTH_PRECISION", "UPSAMPLE", "choose_tooth", "on_tooth",
           "row_period", "upsampled", "warp_cost"]

#: Step of the foreground offsets searched, left-view pixels.
STEP = 0.25
#: What a left pixel the right camera does not see (hidden, or beyond the right image's
#: edge) costs in :func:`warp_cost`, a fraction of the grey range: without it, a model that
#: hides more pixels leaves out more differences, and a tooth too far in front can hide the
#: very stripes that would give it away.
HIDDEN_COST = 0.05
#: Step of the search around the best offset, left-view pixels.
FINE_STEP = 0.05
#: Factor by which the right image's rows are resampled (band-limited, by FFT) before they
#: are sampled at ``x - d`` linearly: linear interpolation alone attenuates stripes of a few
#: pixels, and its error, which depends on the fraction of ``d``, would favour integer
#: disparities.
UPSAMPLE = 4
#: Columns beyond 0 and ``s`` that the outline's move is searched over.
MARGIN = 3
#: Half the rise of the autocorrelation to a peak that marks the foreground's period.
PEAK = 0.3
#: The local minima of the inside's difference taken as teeth: within this fraction of the
#: curve's range above its lowest minimum (the inside of a solved outline that is off holds
#: some background, which raises every tooth's difference).
TOOTH_DEPTH = 0.25
#: Smallest median jump (left-view pixels) of a moved foreground over its background;
#: as :data:`lss_kernels.checks.recovery.MIN_JUMP`.
MIN_JUMP = 1.0
#: Precision (left-view pixels) of a tooth's offset: on stripes of a few pixels a hundredth of
#: a pixel off a tooth costs as much, summed over a layer, as the few pixels a row by which
#: a wrong tooth's outline is off, so the offsets are refined beyond ``FINE_STEP``.
TOOTH_PRECISION = 0.002
#: Half the side of the square over which a pixel's differences are summed when a tooth's
#: plane is fitted to the matches.
REFIT_RADIUS = 2
#: Smallest relative drop of the warp's difference for which another tooth is taken.
MIN_GAIN = 0.2


def _cover(foreground, right_x):
    """Per row, the right-view columns that foreground pixels land on."""
    H, W = foreground.shape
    cover = np.zeros((H, W + 2), bool)
    ys, xs = np.nonzero(foreground)
    r = right_x[ys, xs]
    inside = (r > -1) & (r < W)
    ys, r = ys[inside], r[inside]
    lo = np.clip(np.floor(r).astype(np.int64), -1, W - 1) + 1
    cover[ys, lo] = True
    cover[ys, np.minimum(lo + 1, W + 1)] = True
    return cover[:, 1:W + 1]


def _sample(right, ys, r):
    """``right`` ``(H, W', C)`` at the fractional columns ``r`` of the rows ``ys``, linearly
    (``r`` within ``[0, W' - 1]``); returns ``(N, C)``."""
    i0 = np.minimum(np.floor(r).astype(np.int64), right.shape[1] - 2)
    t = (r - i0)[:, None]
    return (1 - t) * right[ys, i0] + t * right[ys, i0 + 1]


def upsampled(image, factor=UPSAMPLE):
    """``image`` ``(H, W, C)`` with its rows resampled ``factor`` times as finely (zero-padded
    spectrum of the row mirrored onto itself, so that its ends do not wrap); column ``i`` of
    the result is ``x = i / factor``.  Returns ``(H, factor * (W - 1) + 1, C)``."""
    W = image.shape[1]
    mirrored = np.concatenate([image, image[:, ::-1]], axis=1)
    spectrum = np.fft.rfft(mirrored, axis=1)
    fine = np.fft.irfft(spectrum, n=2 * W * factor, axis=1) * factor
    return fine[:, :factor * (W - 1) + 1]


def warp_cost(left, right, foreground, disparity, factor=1):
    """How far the left image is from the right one sampled at ``x - disparity`` (linear in
    x; ``right`` may be :func:`upsampled` by ``factor``): the absolute difference (mean over
    channels) summed over the left pixels the right camera sees, plus ``HIDDEN_COST`` for
    every other pixel (hidden: a background pixel on whose right column a foreground pixel
    lands; or landing outside the right image), over the number of pixels.  ``left``,
    ``right`` ``(H, W, C)``; ``foreground`` bool and ``disparity`` ``(H, W)``, left view.
    Returns ``(cost, seen)``, ``seen`` the number of pixels seen."""
    H, W = foreground.shape
    x = np.arange(W, dtype=np.float64)[None, :]
    right_x = x - disparity
    cover = _cover(foreground, right_x)
    column = np.clip(np.rint(right_x), 0, W - 1).astype(np.int64)
    hidden = ~foreground & np.take_along_axis(cover, column, axis=1)
    seen = ~hidden & (right_x >= 0) & (right_x <= W - 1)
    ys, xs = np.nonzero(seen)
    sampled = _sample(right, ys, right_x[ys, xs] * factor)
    diff = np.abs(left[ys, xs] - sampled).mean(axis=-1)
    return float((diff.sum() + HIDDEN_COST * (H * W - diff.size)) / (H * W)), int(diff.size)


def row_period(image, mask, max_period=48):
    """The period (pixels, along the rows) of ``image`` ``(H, W, C)`` inside ``mask``: the
    first lag at which the normalised autocorrelation of the horizontal gradient of grey,
    over the pairs of pixels both inside ``mask``, peaks ``2 PEAK`` above its lowest value at
    a smaller lag (parabolic to a fraction of a pixel); None when it never does."""
    g = np.diff(luma(image), axis=1)
    m = mask[:, 1:] & mask[:, :-1]
    rho = np.full(max_period + 2, np.nan)
    for lag in range(1, max_period + 2):
        both = m[:, lag:] & m[:, :-lag]
        if both.sum() < 50:
            break
        a, b = g[:, lag:][both], g[:, :-lag][both]
        rho[lag] = (a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum() + 1e-30)
    lowest = np.inf
    for lag in range(2, max_period + 1):
        if np.isnan(rho[lag + 1]):
            return None
        lowest = min(lowest, rho[lag - 1])
        if rho[lag] >= rho[lag - 1] and rho[lag] >= rho[lag + 1] and rho[lag] - lowest > 2 * PEAK:
            den = rho[lag - 1] - 2 * rho[lag] + rho[lag + 1]
            return float(lag + (0.5 * (rho[lag - 1] - rho[lag + 1]) / den if den < 0 else 0.0))
    return None


class _Model:
    """The solved left view and its foreground moved: by ``t`` columns (the outline in the
    left view) and its surface by ``s`` px."""

    def __init__(self, foreground, surface, front=None):
        self.foreground = foreground
        self.surface = surface if front is None else front
        H, W = foreground.shape
        self.background = surface.copy()       # the background's surface under the object too
        x = np.arange(W)
        for y in np.nonzero(foreground.any(axis=1))[0]:
            own = ~foreground[y]
            if own.sum() >= 2:
                self.background[y] = np.interp(x, x[own], surface[y, own])
        self.background = np.where(foreground, self.background, surface)

    def at(self, s, t):
        """``(foreground, disparity)`` of the moved model."""
        t = int(t)
        fg, front = np.zeros_like(self.foreground), np.zeros_like(self.surface)
        W = fg.shape[1]
        if t >= 0:
            fg[:, t:], front[:, t:] = self.foreground[:, :W - t], self.surface[:, :W - t]
        else:
            fg[:, :t], front[:, :t] = self.foreground[:, -t:], self.surface[:, -t:]
        return fg, np.where(fg, front + s, self.background)


def choose_tooth(left, right, foreground, surface, d_max):
    """The move of the foreground that best explains the pair (:func:`warp_cost`), as the
    module text says: its surface (``shape``: as ``surface`` gives it, ``"solved"``, or the
    plane fitted to it, ``"plane"``) by ``s`` px and its outline in the left view by ``t``
    columns, the background as ``surface`` gives it.  ``left``, ``right`` ``(H, W, C)``,
    ``foreground`` and ``surface`` ``(H, W)``, left view.  Returns ``((s, t, shape),
    info)``: ``(0, 0, "solved")`` when no other tooth beats the solved model by
    ``MIN_GAIN`` (or the foreground has no period); ``info`` the period and the costs."""
    left = np.asarray(left, np.float64)
    right = np.asarray(right, np.float64)
    if left.ndim == 2:
        left, right = left[..., None], right[..., None]
    foreground = np.asarray(foreground, bool)
    surface = np.asarray(surface, np.float64)
    info = {"offset": 0.0, "shift": 0, "shape": "solved"}
    if not foreground.any() or foreground.all() or foreground.shape != left.shape[:2]:
        return (0.0, 0, None), info
    period = row_period(left, _eroded(foreground, 2))
    behind = row_period(left, _eroded(~foreground, 2))
    info.update(period=period, background_period=behind)
    if period is None:
        return (0.0, 0, None), info
    info["full_shape"] = foreground.shape
    rows = np.nonzero(foreground.any(axis=1))[0]
    y0, y1 = max(rows[0] - 2, 0), rows[-1] + 3
    left, foreground, surface = left[y0:y1], foreground[y0:y1], surface[y0:y1]
    right = upsampled(right[y0:y1])
    best, best_cost, base = (0.0, 0, "solved", None), np.inf, None
    plane = plane_of(foreground, surface)
    inner = _eroded(foreground, 3)
    shapes = [("solved", None, None), ("plane", plane, None)]
    while shapes:
        shape, front, teeth = shapes.pop(0)
        model = _Model(foreground, surface, front)
        inside = model.surface[foreground]

        def cost_of(s, t):
            fg, disparity = model.at(s, t)
            back = _behind(fg, disparity, model.background, behind)
            if back:
                disparity = np.where(fg, disparity, disparity + back)
            return warp_cost(left, right, fg, disparity, UPSAMPLE)[0]

        if base is None:
            base = cost_of(0.0, 0)
            info["cost"] = base
            best_cost = base
        if teeth is None:
            teeth = _teeth(left, right, inner, model.surface, -inside.min(),
                           float(d_max) - inside.max())
        if shape == "plane":
            # each tooth's own plane, fitted to the inside's matches within half a period
            for s in teeth:
                coef = _refit(left, right, inner, model.surface + s, period)
                if coef is not None:
                    shapes.append(("refit", _plane(coef, foreground.shape), [0.0]))
        found, found_cost = None, np.inf
        for s in teeth:
            lo, hi = sorted((0, int(round(s + np.median(inside) - np.median(surface[foreground])))))
            for t in range(lo - MARGIN, hi + MARGIN + 1):
                cost = cost_of(s, t)
                if cost < found_cost:
                    found, found_cost = (float(s), t), cost
        if found is None:
            continue
        s0, t0 = found
        for t in (t0 - 1, t0, t0 + 1):
            for s in s0 + np.arange(-STEP, STEP + 1e-9, FINE_STEP):
                cost = cost_of(s, t)
                if cost < found_cost:
                    found, found_cost = (float(s), t), cost
        info[f"{shape}_cost"] = min(found_cost, info.get(f"{shape}_cost", np.inf))
        if found_cost < best_cost:
            best, best_cost = (*found, shape, front), found_cost
    s, t, shape, front = best
    # the offset of the foreground's surface from the solved one, over the object
    offset = s if front is None else float(np.median(front[foreground] + s
                                                     - surface[foreground]))
    info.update(best_offset=offset, best_shift=t, best_shape=shape, best_cost=best_cost)
    # the solved tooth, its surface made a plane or its outline moved, is no other tooth
    if abs(offset) >= period / 2 and best_cost < (1.0 - MIN_GAIN) * base:
        info.update(offset=offset, shift=t, shape=shape)
        full = None
        if front is not None:       # the plane in the whole image's rows
            full = _plane(_coefficients(front, foreground), info["full_shape"], y0)
        return (s, t, full), info
    return (0.0, 0, None), info


def _rows(xs, ys):
    """The rows ``(x, y, 1)`` of a plane's least squares."""
    return np.stack([xs, ys, np.ones_like(xs)], axis=1).astype(np.float64)


def _coefficients(plane, mask):
    """``(a, b, c)`` of the plane ``a x + b y + c`` that ``plane`` holds (least squares
    over ``mask``)."""
    ys, xs = np.nonzero(mask)
    return np.linalg.lstsq(_rows(xs, ys), plane[ys, xs], rcond=None)[0]


def _plane(coef, shape, y0=0):
    """The plane ``a x + b (y - y0) + c`` on a grid of ``shape``."""
    H, W = shape
    yy, xx = np.mgrid[0:H, 0:W]
    return coef[0] * xx + coef[1] * (yy - y0) + coef[2]


def _refit(left, right, inner, front, period):
    """``(a, b, c)`` of the plane fitted to the disparities, within half a ``period`` of
    ``front``, at which each pixel of ``inner`` matches best (differences summed over a
    ``2 REFIT_RADIUS + 1`` square), the pixels more than a pixel off the first fit left out
    of the second; None for an empty ``inner``."""
    ys, xs = np.nonzero(inner)
    if xs.size < 10:
        return None
    H, W = inner.shape
    width = right.shape[1]
    deltas = np.arange(-period / 2, period / 2, STEP)
    best = np.full(xs.size, np.inf)
    chosen = np.zeros(xs.size)
    for delta in deltas:
        r = np.clip((xs - front[ys, xs] - delta) * UPSAMPLE, 0, width - 1)
        sampled = _sample(right, ys, r)
        diff = np.zeros((H, W))
        diff[ys, xs] = np.abs(left[ys, xs] - sampled).mean(axis=-1)
        summed = box_sums(np.pad(diff, REFIT_RADIUS), 2 * REFIT_RADIUS + 1)[ys, xs]
        better = summed < best
        best[better], chosen[better] = summed[better], delta
    d = front[ys, xs] + chosen
    A = _rows(xs, ys)
    coef = np.linalg.lstsq(A, d, rcond=None)[0]
    keep = np.abs(A @ coef - d) <= 1.0
    if keep.sum() >= 10:
        coef = np.linalg.lstsq(A[keep], d[keep], rcond=None)[0]
    return coef


def plane_of(foreground, surface):
    """The plane ``a x + b y + c`` fitted (least squares) to ``surface`` over
    ``foreground``, evaluated on the whole grid."""
    return _plane(_coefficients(surface, foreground), foreground.shape)


def _teeth(left, right, inner, surface, lo, hi):
    """The offsets in ``[lo, hi]`` (not 0) at which the foreground's inside ``inner`` matches
    the right image best: the local minima over steps of ``STEP`` of the mean difference
    between the left image there and the (upsampled) right one at ``x - surface - s``,
    refined to ``FINE_STEP`` and then to ``TOOTH_PRECISION`` (:func:`_golden`), those
    within ``TOOTH_DEPTH`` of the curve's range above the lowest."""
    ys, xs = np.nonzero(inner)
    if xs.size == 0:
        return []
    pixels = left[ys, xs]
    width = right.shape[1]

    def cost(s):
        r = (xs - surface[ys, xs] - s) * UPSAMPLE
        ok = (r >= 0) & (r <= width - 1)
        if ok.sum() < 0.5 * xs.size:
            return np.inf
        sampled = _sample(right, ys[ok], r[ok])
        return float(np.abs(pixels[ok] - sampled).mean())

    grid = np.arange(lo, hi + 1e-9, STEP)
    costs = np.array([cost(s) for s in grid])
    if not np.isfinite(costs).any():
        return []
    minima = []
    for i in range(len(grid)):
        left_ok = i == 0 or costs[i] <= costs[i - 1]
        right_ok = i == len(grid) - 1 or costs[i] <= costs[i + 1]
        if np.isfinite(costs[i]) and left_ok and right_ok:
            fine = grid[i] + np.arange(-STEP, STEP + 1e-9, FINE_STEP)
            values = [cost(s) for s in fine]
            k = int(np.argmin(values))
            minima.append(_golden(cost, float(fine[k]), values[k]))
    floor, top = min(c for c, _ in minima), float(np.max(costs[np.isfinite(costs)]))
    return [s for c, s in minima
            if c <= floor + TOOTH_DEPTH * (top - floor)]


def _golden(cost, s, at_s):
    """``(value, offset)``: the minimum of ``cost`` within ``FINE_STEP`` of ``s`` (where it is
    ``at_s``), to ``TOOTH_PRECISION`` (golden section; ``s`` itself when no point found is
    lower)."""
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = s - FINE_STEP, s + FINE_STEP
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = cost(c), cost(d)
    while b - a > TOOTH_PRECISION:
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = cost(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = cost(d)
    best, value = (c, fc) if fc < fd else (d, fd)
    return (value, float(best)) if value < at_s else (at_s, float(s))


def _eroded(mask, n):
    """``mask`` eroded ``n`` times (4-neighbour)."""
    core = mask.copy()
    for _ in range(n):
        inner = core.copy()
        inner[1:] &= core[:-1]
        inner[:-1] &= core[1:]
        inner[:, 1:] &= core[:, :-1]
        inner[:, :-1] &= core[:, 1:]
        core = inner
    return core


def on_tooth(result, left, right, d_max):
    """``result`` (a :class:`~lss_kernels.result.Result` of the pair ``left``, ``right``)
    with its foreground moved as :func:`choose_tooth` finds: the outline by ``t`` columns,
    the foreground's surface by ``s`` (the disparity the same, clipped to ``[0, d_max]``;
    the background's under the pixels the object left is interpolated along the rows), the
    occlusion of the moved surfaces (:func:`~lss_kernels.model.layers.occlusion_by_layers`;
    confidence 0 there), Theta_1's constant term by ``s`` and phi by ``t - s / 2`` columns
    (the cyclopean frame).  Returns ``(result, info)``; ``result`` is changed in place."""
    foreground = np.asarray(result.foreground, bool)
    (s, t, plane), info = choose_tooth(left, right, foreground, result.surface, d_max)
    moved = not (s == 0.0 and t == 0 and plane is None)
    if not moved:
        # the object stays, but a periodic background solved on a tooth in front of it
        # still goes behind it
        solved = np.asarray(result.surface, np.float64)
        moved = bool(_behind(foreground, solved, _Model(foreground, solved).background,
                             info.get("background_period")))
    if moved:
        _moved(result, foreground, s, t, plane, info, d_max)
    return result, info


def _moved(result, foreground, s, t, plane, info, d_max):
    """``result`` moved in place as :func:`on_tooth` says, by ``s`` px and ``t`` columns
    onto the surface ``plane`` (None: the solved one)."""
    from ..model.layers import occlusion_by_layers
    solved = np.asarray(result.surface, np.float64)
    model = _Model(foreground, solved, plane)
    moved_fg, surface = model.at(s, t)
    refined = _Model(foreground, np.asarray(result.disparity, np.float64),
                     plane).at(s, t)[1]
    back = _behind(moved_fg, surface, model.background, info.get("background_period"))
    info["background_offset"] = back
    if back:
        surface = np.where(moved_fg, surface, surface + back)
        refined = np.where(moved_fg, refined, refined + back)
        theta_bg = np.array(result.theta_bg, dtype=np.float64)
        theta_bg[5] += back
        result.theta_bg = theta_bg.astype(np.asarray(result.theta_bg).dtype)
    clean = lambda d: np.clip(d, 0.0, d_max).astype(np.float32)
    result.foreground, result.surface, result.disparity = moved_fg, clean(surface), clean(refined)
    result.occlusion = occlusion_by_layers(result.surface, moved_fg.astype(np.int32))
    result.confidence = np.where(result.occlusion, 0.0, result.confidence).astype(np.float32)
    if result.layers is not None:
        result.layers = moved_fg.astype(np.uint8)
    theta = np.array(result.theta_fg, dtype=np.float64)
    if plane is not None:
        # d = a x_left + b y + c with x_left = x_cyclopean + d / 2
        a, b, c = _coefficients(surface, moved_fg)
        theta[:] = np.array([0.0, 0.0, 0.0, a, b, c]) / (1.0 - a / 2.0)
    else:
        theta[5] += s
    result.theta_fg = theta.astype(np.asarray(result.theta_fg).dtype)
    result.phi = _shifted_rows(np.asarray(result.phi, np.float32), t - info["offset"] / 2.0)


def _behind(foreground, surface, background, period):
    """The whole number of background periods (``period``, None: the background is not
    periodic), as a negative offset in pixels, that puts the background (``background``
    under the object) at least ``MIN_JUMP`` behind the foreground's ``surface`` over the
    median of the object; 0 when it already lies so, or when the background is not
    periodic.  A periodic background's tooth is not in the pair (module text): of the teeth
    behind the object, the nearest to the one solved."""
    if not foreground.any() or foreground.all():
        return 0.0
    jump = float(np.median(surface[foreground] - background[foreground]))
    if jump >= MIN_JUMP or period is None:
        return 0.0
    periods = np.ceil((MIN_JUMP - jump) / period)
    offset = -periods * period
    if np.median(background[~foreground]) + offset < 0.0:
        return 0.0
    return float(offset)


def _shifted_rows(plane, shift):
    """``plane`` moved by ``shift`` pixels along x (linear; the edge columns repeat)."""
    W = plane.shape[1]
    x = np.clip(np.arange(W) - shift, 0, W - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), W - 2)
    t = (x - i0)[None, :]
    return ((1 - t) * plane[:, i0] + t * plane[:, i0 + 1]).astype(plane.dtype)
