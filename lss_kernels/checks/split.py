"""The object's layer split in two: a neighbour a few pixels behind the clicked object that
the solve took with it.

In a whole photo a neighbour can stand just behind the object and touch it (a second book
on a shelf, the base of a cone).  The two-layer model has one quadratic background, which
cannot explain a neighbour a few pixels in front of the wall; the neighbour's pixels cost
about as much under Theta_1 (a few pixels off) as under Theta_2 (far off), the foreground
spreads over it, and Theta_1 bends to hold both.  The refinement
(:mod:`lss_kernels.model.refine`) then follows each surface, but it averages within a
layer, so the step between them becomes a ramp and the strip that the object hides from the
right camera on the neighbour, the object's own occlusion there, is lost.

After a whole photo's solve, the object's pixels are split between two quadratics
(:func:`two_surfaces`) of d-bar, the consensus mean read at each pixel's cyclopean column
(:func:`consensus_in_left_view`): the refined disparity follows the bent Theta_1 wherever
the object's own matches are not distinct, and shows no step there.  The first quadratic is
grown from the pixels around the click, the second from the pixels that lie more than
``STEP`` behind it; for ``ROUNDS`` rounds each is fitted to its side clear of the ramp
(``GAP`` pixels from the other side) and each pixel goes to the nearer fit (by the majority
of the object's pixels in its ``MAJORITY`` square).  The second surface is a neighbour
(:func:`split_neighbour`) when

* it covers at least ``MIN_SHARE`` of the object's pixels (and ``MIN_PIXELS``), in one
  4-connected piece that does not hold the click, and meets it along ``MIN_BORDER`` pixels;
* its pixels lie on it (median distance at most ``FIT`` times their median distance to the
  object's surface, which is at least ``STEP``), and the output (the refined matches) lies
  within ``STEP`` of each side's surface (median over the side: on a periodic object d-bar
  can take a wrong tooth over part of it);
* it lies behind the object where they meet: on ``BORDER_SHARE`` of the pixels of their
  common border the object's surface is ``STEP`` or more in front of the neighbour's (a
  surface that folds smoothly away meets its fit with no gap).

The neighbour then leaves the object (layer 0, behind it).  d-bar and the refined matches
both spread over the strip that the object hides, so each row's edge is moved to the column
that explains the pair best (:func:`snap_edges`); each side of the border takes its own
surface where the output strays more than ``RAMP`` from it (within ``RAMP_REACH`` pixels of
the border), and the neighbour's pixels that the object hides from the right camera are
occluded (:func:`~lss_kernels.model.layers.occlusion_by_layers`).
"""
import numpy as np

from ..model.init import background_fit
from ..model.quadratic import basis
from .teeth import _eroded

__all__ = ["BORDER_SHARE", "FIT", "MIN_BORDER", "MIN_PIXELS", "MIN_SHARE", "RAMP", "RAMP_REACH",
           "ROUNDS", "SNAP", "STEP", "consensus_in_left_view", "snap_edges", "split_neighbour",
           "two_surfaces"]

#: The smallest jump between the object and a neighbour, left-view pixels.
STEP = 1.5
#: The smallest neighbour, as a share of the object's pixels and in pixels.
MIN_SHARE = 0.08
MIN_PIXELS = 150
#: A neighbour's pixels lie on its surface: median distance at most this times their median
#: distance to the object's surface.
FIT = 0.4
#: Share of the common border where the object's surface stands ``STEP`` in front.
BORDER_SHARE = 0.75
#: The fewest pixels of the common border (both sides).
MIN_BORDER = 20
#: Rounds of the two fits.
ROUNDS = 4
#: Near the border, a pixel further than this from its layer's surface takes it (pixels).
RAMP = 0.25
#: ... within this many pixels of the border.
RAMP_REACH = 12
#: The object's first fit: the pixels within this share of its equivalent radius of the click.
CORE = 0.5
#: The fits leave out the pixels this close to the other side (the refinement's ramp), pixels.
GAP = 6
#: An edge against the neighbour moves at most this many pixels more than the jump to its
#: left, and this many to its right (:func:`snap_edges`).
SNAP = 2
#: The majority window of the assignment, pixels.
MAJORITY = 7


def _fit(D, mask):
    """The robust quadratic of ``D`` over ``mask`` (:func:`~lss_kernels.model.init.
    background_fit`: least squares, then again over the values within 1 px, or 2.5 robust
    deviations, of the last fit), evaluated at every pixel; None with fewer than 6 values."""
    H, W = D.shape
    coefficients, _ = background_fit(np.where(mask, D, -1.0), band=1.0)
    if coefficients is None:
        return None
    yy, xx = np.mgrid[0:H, 0:W]
    return basis(xx / W - 0.5, yy / H - 0.5) @ coefficients


def _majority(mask, within, size=MAJORITY):
    """Pixels of ``within`` where more than half of the pixels of ``within`` in the ``size``
    x ``size`` window are set in ``mask``."""
    r = size // 2

    def box(a):
        c = np.pad(np.pad(a.astype(np.float64), r).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
        return c[size:, size:] - c[:-size, size:] - c[size:, :-size] + c[:-size, :-size]
    return within & (box(mask & within) > 0.5 * box(within))


def _components(mask):
    """4-connected labels of ``mask`` (-1 outside it): the runs of each row, joined by
    union-find where they overlap a run of the row above."""
    H, W = mask.shape
    edges = np.diff(np.pad(mask, ((0, 0), (1, 1))).astype(np.int8), axis=1)
    rows, starts = np.nonzero(edges == 1)
    ends = np.nonzero(edges == -1)[1]
    parent = np.arange(rows.size)

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i
    first = np.searchsorted(rows, np.arange(H + 1))
    for y in range(1, H):
        i, i_end, j, j_end = first[y - 1], first[y], first[y], first[y + 1]
        while i < i_end and j < j_end:
            if starts[i] < ends[j] and starts[j] < ends[i]:
                parent[root(i)] = root(j)
            if ends[i] < ends[j]:
                i += 1
            else:
                j += 1
    runs = np.array([root(i) for i in range(rows.size)], np.int64)
    lengths = ends - starts
    offsets = np.repeat(np.cumsum(lengths) - lengths - starts, lengths)
    labels = np.full((H, W), -1, np.int64)
    labels[np.repeat(rows, lengths), np.arange(lengths.sum()) - offsets] = np.repeat(runs, lengths)
    return labels


def _largest(mask, exclude=None):
    """The largest 4-connected piece of ``mask`` that holds no pixel of ``exclude``."""
    labels = _components(mask)
    ids, counts = np.unique(labels[labels >= 0], return_counts=True)
    if exclude is not None:
        bad = np.unique(labels[exclude & (labels >= 0)])
        counts = np.where(np.isin(ids, bad), 0, counts)
    if ids.size == 0 or counts.max() == 0:
        return np.zeros_like(mask)
    return labels == ids[int(np.argmax(counts))]


def _piece(mask, seed):
    """The 4-connected piece of ``mask`` that holds ``seed`` (a boolean mask)."""
    labels = _components(mask)
    ids = np.unique(labels[seed & (labels >= 0)])
    return np.isin(labels, ids) & mask


def _border(a, b):
    """Pixels of ``a`` with a 4-neighbour in ``b``."""
    return a & _within(b, 1)


def _within(mask, reach):
    """Pixels within ``reach`` 4-neighbour steps of ``mask``."""
    return ~_eroded(~mask, reach)


def two_surfaces(disparity, foreground, point):
    """The object's pixels ``foreground`` split between two quadratics of ``disparity``
    (left view, ``(H, W)``: d-bar in :func:`split_neighbour`), the first grown from the
    pixels around ``point`` (``(x, y)``, integer pixel of the object).  Returns ``(object,
    other, object_surface, other_surface)`` (masks and maps ``(H, W)``), or None when no
    second surface lies ``STEP`` behind the first."""
    D = np.asarray(disparity, np.float64)
    F = np.asarray(foreground, bool)
    H, W = F.shape
    x0, y0 = point
    seed = np.zeros_like(F)
    seed[y0, x0] = True
    yy, xx = np.mgrid[0:H, 0:W]
    radius = CORE * np.sqrt(F.sum() / np.pi)
    core = F & (np.hypot(xx - x0, yy - y0) <= radius)
    obj = _fit(D, core)
    if obj is None:
        return None
    other = _largest(_majority(D < obj - STEP, F), exclude=seed)
    for _ in range(ROUNDS):
        # each surface from its own side, clear of the ramp between them
        rest = F & ~other
        back = _fit(D, other & ~_within(rest, GAP))
        obj = _fit(D, rest & ~_within(other, GAP))
        if back is None or obj is None:
            return None
        nearer = _majority(np.abs(D - back) < np.abs(D - obj), F)
        other = _largest(nearer & (back < obj), exclude=seed)
        if other.sum() < 6:
            return None
    first = _piece(F & ~other, seed)
    return first, other, obj, back


def snap_edges(first, other, obj, back, left, right):
    """The object's left edges against the neighbour, each row's moved to the column that
    explains the row best (in place): d-bar and the refined matches both spread the object
    over the strip it hides, so the fits meet there, not where the object ends.  Within
    ``SNAP`` plus the jump ``J`` of a row's edge ``c``, the column minimising the neighbour's
    :func:`~lss_kernels.checks.outline.pixel_costs` left of ``c - J``, ``HIDDEN_COST`` over
    ``[c - J, c)`` (hidden from the right camera) and the object's costs from ``c`` on (the
    scanline of Eq. 1, as :func:`~lss_kernels.checks.outline.row_outline`), then the moves
    of the edges of 5 neighbouring rows' median.  ``left``, ``right``: the pair,
    ``(H, W, C)``.  Returns how many edges moved."""
    from .outline import pixel_costs
    from .teeth import HIDDEN_COST, upsampled
    left = np.asarray(left, np.float64)
    right = np.asarray(right, np.float64)
    if left.ndim == 2:
        left, right = left[..., None], right[..., None]
    right = upsampled(right)
    fore = pixel_costs(left, right, obj)
    behind = pixel_costs(left, right, back)
    H, W = first.shape
    ys, xs = np.nonzero(first[:, 1:] & other[:, :-1])
    xs = xs + 1
    moves = np.zeros(ys.size, np.int64)
    for k, (y, c) in enumerate(zip(ys, xs)):
        jump = int(max(round(obj[y, c] - back[y, c]), 0))
        reach = SNAP + jump
        lo, hi = max(c - 2 * reach, 0), min(c + reach + 1, W)
        best, moves[k] = np.inf, 0
        for e in range(max(c - reach, lo + jump), min(c + SNAP, hi - 1) + 1):
            cost = (behind[y, lo:e - jump].sum() + HIDDEN_COST * jump
                    + fore[y, e:hi].sum())
            if cost < best - 1e-12:
                best, moves[k] = cost, e - c
    order = np.argsort(ys, kind="stable")
    smooth = moves.copy()
    for i, k in enumerate(order):
        near = order[max(i - 2, 0):i + 3]
        smooth[k] = int(np.median(moves[near]))
    for y, c, m in zip(ys, xs, smooth):
        if m < 0:
            span = slice(c + m, c)
            take = other[y, span]
            first[y, span] |= take
            other[y, span] &= ~take
        elif m > 0:
            span = slice(c, c + m)
            take = first[y, span]
            other[y, span] |= take
            first[y, span] &= ~take
    return int((smooth != 0).sum())


def consensus_in_left_view(consensus, disparity):
    """The consensus mean (cyclopean frame, ``(H, W)``) read at each left-view pixel's
    cyclopean column ``x - disparity / 2`` (nearest, clamped to the image): d-bar in the left
    view."""
    consensus = np.asarray(consensus, np.float64)
    H, W = consensus.shape
    columns = np.rint(np.arange(W)[None, :] - np.asarray(disparity, np.float64) / 2.0)
    columns = np.clip(np.nan_to_num(columns), 0, W - 1).astype(np.int64)
    return np.take_along_axis(consensus, columns, axis=1)


def split_neighbour(result, point, left=None, right=None):
    """``result`` (a window's :class:`~lss_kernels.result.Result`, left view) with a
    neighbour behind the object moved out of it (module text); ``point``: the click,
    ``(x, y)`` in the result's pixels; ``left``, ``right``: the window's pair, which places
    the object's edges against the neighbour (:func:`snap_edges`; None: where the fits
    meet).  Returns what was found as a dict (``split`` True when the result was changed in
    place)."""
    from ..model.layers import BACKGROUND, OBJECT, occlusion_by_layers
    F = np.asarray(result.foreground, bool)
    H, W = F.shape
    x, y = int(round(point[0])), int(round(point[1]))
    facts = {"split": False}
    if not (0 <= x < W and 0 <= y < H) or not F[y, x]:
        facts["why"] = "the click is not on the object"
        return facts
    if F.sum() < MIN_PIXELS:
        facts["why"] = "the object is too small"
        return facts
    D = np.asarray(result.disparity, np.float64)
    evidence = consensus_in_left_view(result.consensus_mean, D)
    found = two_surfaces(evidence, F, (x, y))
    if found is None:
        facts["why"] = "no second surface behind the object"
        return facts
    first, other, obj, back = found
    n_other = int(other.sum())
    near = np.median(np.abs(evidence - back)[other])
    far = np.median(np.abs(evidence - obj)[other])
    border = _border(first, other) | _border(other, first)
    gap = (obj - back)[border]
    in_front = float((gap >= STEP).mean()) if gap.size else 0.0
    facts.update(pixels=n_other, share=round(float(n_other / F.sum()), 3),
                 fit=round(float(near), 3), off=round(float(far), 3),
                 border=int(border.sum()), in_front=round(in_front, 3))
    if n_other < max(MIN_PIXELS, MIN_SHARE * F.sum()):
        facts["why"] = "the second surface is too small"
        return facts
    if far < STEP or near > FIT * far:
        facts["why"] = "the second surface does not explain its pixels"
        return facts
    if max(np.median(np.abs(D - obj)[first]), np.median(np.abs(D - back)[other])) > STEP:
        facts["why"] = "the output does not follow the two surfaces"
        return facts
    if border.sum() < MIN_BORDER:
        facts["why"] = "the second surface hardly touches the object"
        return facts
    if in_front < BORDER_SHARE:
        facts["why"] = "the object does not stand in front of it where they meet"
        return facts
    if left is not None:
        facts["edges_moved"] = snap_edges(first, other, obj, back, left, right)
        border = _border(first, other) | _border(other, first)
    # the ramp the refinement leaves across the step, replaced by each side's surface
    reach = _within(border, RAMP_REACH)
    disparity = D.copy()
    for mask, surface in ((first, obj), (other, back)):
        stray = mask & reach & (np.abs(D - surface) > RAMP)
        disparity[stray] = surface[stray]
    disparity = disparity.astype(np.float32)
    layers = np.asarray(result.layers if result.layers is not None else F, np.uint8).copy()
    layers[other] = BACKGROUND
    labels = np.where(first, OBJECT, BACKGROUND).astype(np.int32)
    hidden = occlusion_by_layers(np.nan_to_num(disparity), labels, occluders=first) & other
    result.disparity = disparity
    result.foreground = F & ~other
    result.layers = layers
    result.occlusion = np.asarray(result.occlusion, bool) | hidden
    if result.confidence is not None:
        result.confidence = np.where(hidden, 0.0, result.confidence).astype(np.float32)
    facts.update(split=True, hidden=int(hidden.sum()))
    return facts
