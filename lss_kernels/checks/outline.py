"""The object's outline read row by row from the pair, for each pair of teeth of the two
layers: the check after :func:`~lss_kernels.checks.teeth.on_tooth` for when the solve's
outline itself is wrong, not only a tooth off.

On stripes on both layers the alternation can end with the two surfaces on wrong teeth, or
the background in front of the object, and its outline is then the boundary of whatever
region those surfaces explain, not the object's (``periodic_diff``, ``periodic_same_mid``
of ``lss_kernels.stress --periodic``).  Moving that outline (:mod:`.teeth`) cannot repair
it.  But with Theta_1 and Theta_2 fixed, Eq. (1) along one row, with an object that spans
one run ``[a, b)`` of it, is a function of ``a`` and ``b`` alone (the scanline problem of
Belhumeur, cited in Sec. 1): the foreground's matching cost over ``[a, b)``, the
background's over the rest, and the strip ``[a - Delta theta, a)`` hidden from the right
camera.  Its exact minimum over ``a <= b`` takes two prefix sums and a running minimum
(:func:`row_outline`), so the outline of every candidate pair of surfaces costs one pass
over the image.  The candidates are each layer's plane (fitted to the solved surface over
its region), and the planes of the pair's combs read without the solve (:mod:`.comb`:
when the alternation is lost, as on slanted layers, no plane of its surfaces is on any
tooth), each moved to the teeth where its region matches best
(:func:`~lss_kernels.checks.teeth._teeth`); every pair with the object at least
``MIN_JUMP`` in front, the object within ``REACH`` pixels of the solved object's box, or,
on a comb's plane, of the box of the pixels that support it (a whole photo's other
objects can be explained by the same planes; a lost solve's object may lie anywhere).
The best pair's outline gives the regions of a second round (``ROUNDS``), whose teeth are
read from the right pixels.  :func:`on_layers` takes the
best when its warp explains the right image better than the solved model
(:func:`~lss_kernels.checks.recovery.with_recovery` calls it after each solve of a periodic
pair, after :func:`~lss_kernels.checks.teeth.on_tooth`).

In a whole photo the same planes can explain another object better than the one asked
for.  In the window around a click (:mod:`lss_kernels.photo`: the ``anchor``), only
the pairs whose outline holds the clicked pixel, with the object's surface there within
``ANCHOR_DEPTH`` of the depth the solve found (already on its tooth), and lies within
``REACH`` of the solved object's box, are candidates: what the check may change is the
outline and the background, not which object was clicked.
Elsewhere layers read on a comb's plane must explain the pair to ``COMB_FIT``: over a whole
photo's many surfaces an outline that holds the click can still spread over the rows of
others (``multi_handle`` of ``lss_kernels.stress --multi``, seed 0, solved over the whole
image from its click: F1 0.81 with the limit, 0.24 with the anchor instead).
"""
import numpy as np

from ..params import PHI_SCALE
from .comb import combs
from .teeth import (HIDDEN_COST, MIN_GAIN, MIN_JUMP, UPSAMPLE, _coefficients, _eroded, _plane,
                    _sample, _teeth, plane_of, upsampled, warp_cost)

__all__ = ["ANCHOR_DEPTH", "COMB_FIT", "INNER", "OUTER", "REACH", "ROUNDS", "choose_layers",
           "on_layers", "pixel_costs", "row_outline"]

#: Rounds of the search: each reads the teeth from the regions of the last round's outline.
ROUNDS = 2
#: The outline is searched within this many pixels of the solved object's bounding box: the
#: solve puts the object near where it is, and a row's run of object pixels must not spread
#: over other objects of a whole photo that the two planes happen to explain.
REACH = 32
#: Largest warp cost (:func:`~lss_kernels.checks.teeth.warp_cost`) of layers read on a
#: comb's plane that :func:`on_layers` takes, a quarter of a hidden pixel's cost a pixel:
#: two planes found without the solve are the pair's only where it holds two surfaces (a
#: lost solve of stripes on both layers, 0.005-0.009), not where a whole photo's other
#: surfaces leave more unexplained than the model they replace (``multi_handle`` of
#: ``lss_kernels.stress --multi``, seed 0: 0.055 against 0.141, the object's outline
#: spread over the background's rows, F1 0.79 -> 0.23).
COMB_FIT = HIDDEN_COST / 4
#: Largest change (left-view pixels) of the object's surface at the click that
#: :func:`on_layers` takes.  Below the periods of the rendered sets' stripes (4.1 px and
#: more), so a layer a tooth or more away is never taken for the clicked one; on the
#: multi-object family the outlines that kept the clicked object changed its depth there by
#: 0.1-2.1 px, those that took another surface by 7.3 px or more.
ANCHOR_DEPTH = 3.0
#: Erosions (4-neighbour) of the object's region, and of the rest, over which a layer's
#: teeth are read: a solved outline that is off puts the other layer's texture near it.
INNER, OUTER = 3, 6


def pixel_costs(left, right, disparity):
    """Per left pixel, the absolute difference (mean over channels) from the right image at
    ``x - disparity`` (the Eq. 1 matching cost ``M`` of the AD kind), ``HIDDEN_COST`` where
    that lies outside the right image.  ``left`` ``(H, W, C)``, ``right`` :func:`upsampled
    <lss_kernels.checks.teeth.upsampled>` by ``UPSAMPLE``, ``disparity`` ``(H, W)``, left
    view.  Returns ``(H, W)``."""
    H, W = disparity.shape
    ys, xs = np.mgrid[0:H, 0:W]
    r = xs - disparity
    ok = (r >= 0) & (r <= W - 1)
    cost = np.full((H, W), HIDDEN_COST)
    cost[ok] = np.abs(left[ok] - _sample(right, ys[ok], r[ok] * UPSAMPLE)).mean(axis=-1)
    return cost


def row_outline(left, right, front, back, allowed=None):
    """The object's outline that minimises Eq. (1) for the surfaces ``front`` (Theta_1) and
    ``back`` (Theta_2), ``(H, W)`` left view, with no length term: in each row the run
    ``[a, b)`` of object pixels that minimises the foreground's :func:`pixel_costs` over it,
    plus the background's over the rest, the pixels ``[a - Delta, a)`` (``Delta`` the jump
    at ``a``, rounded) that the object hides from the right camera counted at
    ``HIDDEN_COST`` each; the rows that hold the object are the one run of rows whose
    summed gain over the background alone is largest.  ``left``, ``right`` as in
    :func:`pixel_costs`; ``allowed`` (bool ``(H, W)``, optional): where the object may lie
    (elsewhere its cost exceeds the background's by more than any pixel can gain).
    Returns ``(mask, cost)``: the object (bool ``(H, W)``) and the whole image's cost
    summed, over ``H W``."""
    return _outline(pixel_costs(left, right, front), pixel_costs(left, right, back),
                    front - back, allowed)


def _outline(fore, behind, jump, allowed=None):
    """:func:`row_outline` from the two layers' :func:`pixel_costs` ``fore`` and ``behind``
    and the jump ``front - back``."""
    H, W = fore.shape
    if allowed is not None:
        fore = np.where(allowed, fore, behind + 2.0)
    zero = np.zeros((H, 1))
    P_back = np.concatenate([zero, np.cumsum(behind, axis=1)], axis=1)
    P_diff = np.concatenate([zero, np.cumsum(fore - behind, axis=1)], axis=1)
    cols = np.arange(W + 1)
    jump = np.concatenate([jump, jump[:, -1:]], axis=1)
    start = np.clip(cols[None, :] - np.clip(np.rint(jump), 0, None).astype(np.int64), 0, None)
    # a row's cost less the background's alone: enter(a) + leave(b), a <= b
    enter = (-P_diff - P_back + np.take_along_axis(P_back, start, axis=1)
             + HIDDEN_COST * (cols[None, :] - start))
    total = np.minimum.accumulate(enter, axis=1) + P_diff
    b = total.argmin(axis=1)
    a = np.where(cols[None, :] <= b[:, None], enter, np.inf).argmin(axis=1)
    rows = np.arange(H)
    gain = np.where(b > a, -total[rows, b], 0.0)
    # the run of rows with the largest summed gain (Kadane)
    best, run, first, span = 0.0, 0.0, 0, None
    for y in range(H):
        if run <= 0.0:
            run, first = 0.0, y
        run += gain[y]
        if run > best:
            best, span = run, (first, y + 1)
    mask = np.zeros((H, W), bool)
    if span is not None:
        x = np.arange(W)[None, :]
        y0, y1 = span
        mask[y0:y1] = (x >= a[y0:y1, None]) & (x < b[y0:y1, None])
    return mask, float((P_back[:, -1].sum() - best) / (H * W))


def _near(mask, reach):
    """The bounding box of ``mask`` widened by ``reach`` pixels on every side (bool, the
    mask's shape); everything when ``mask`` is empty."""
    near = np.zeros(mask.shape, bool)
    if not mask.any():
        near[:] = True
        return near
    ys, xs = np.nonzero(mask)
    near[max(ys.min() - reach, 0):ys.max() + reach + 1,
         max(xs.min() - reach, 0):xs.max() + reach + 1] = True
    return near


def _layer(left, right, mask, region, surface, d_max):
    """The plane fitted to ``surface`` over ``mask`` and the offsets of its teeth over
    ``region`` (0 among them)."""
    return _toothed(left, right, plane_of(mask, surface), region, d_max)


def _toothed(left, right, plane, region, d_max):
    """``plane`` and the offsets of its teeth over ``region`` (0 among them)."""
    offsets = _teeth(left, right, region, plane, -plane.min(), float(d_max) - plane.max())
    return plane, sorted({0.0, *offsets})


def _combed(left, right, shape, d_max):
    """The planes of the pair's combs (:func:`~lss_kernels.checks.comb.combs`) on a grid of
    ``shape``, each with the offsets of its teeth over the pixels that support it, and
    those pixels."""
    layers = []
    for coef, ys, xs in combs(left, right, d_max):
        region = np.zeros(shape, bool)
        region[ys, xs] = True
        layers.append((*_toothed(left, right, _plane(coef, shape), region, d_max), region))
    return layers


def choose_layers(left, right, foreground, surface, d_max, anchor=None):
    """The pair of layer teeth, and the outline (:func:`row_outline`), that explain the pair
    best, as the module text says.  ``left`` ``(H, W, C)``, ``right`` upsampled as in
    :func:`pixel_costs`; ``foreground`` bool and ``surface`` ``(H, W)``, the solved model
    (left view); ``anchor``: a click (left-view point) that the outline must hold, with the
    object's surface there within ``ANCHOR_DEPTH`` of ``surface``'s, and within ``REACH``
    of the solved object's box also on a comb's plane.  Returns ``(mask,
    front, back, cost, combed)``, ``front`` and ``back`` planes on the whole grid,
    ``combed`` whether either is a comb's plane or fitted to a comb's outline; None when no
    pair has the object in front (and holds the anchor)."""
    best = None
    pixel = None if anchor is None else _pixel(anchor, foreground.shape)
    if anchor is not None and pixel is None:
        return None
    solved_there = None if pixel is None else float(surface[pixel])
    allowed = _near(foreground, REACH)
    combed = _combed(left, right, foreground.shape, d_max)
    for _ in range(ROUNDS):
        if not foreground.any() or foreground.all():
            break
        fronts = [(*_layer(left, right, foreground, _eroded(foreground, INNER), surface,
                           d_max), None), *combed]
        backs = [(*_layer(left, right, ~foreground, _eroded(~foreground, OUTER), surface,
                          d_max), None), *combed]
        fitted, combed = combed, []     # the next round's planes are fitted to this one's
        costs = {}

        def cost_of(plane, offset):
            key = (id(plane), offset)
            if key not in costs:
                costs[key] = pixel_costs(left, right, plane + offset)
            return costs[key]

        found = None
        for front, front_teeth, support in fronts:
            # a lost solve's object may lie anywhere a comb's plane holds; a clicked one
            # lies where the solve put it
            near = allowed if support is None or anchor is not None else (
                allowed | _near(support, REACH))
            if pixel is not None:        # the object's depth at the click kept
                front_teeth = [s for s in front_teeth
                               if abs(front[pixel] + s - solved_there) <= ANCHOR_DEPTH]
            for back, back_teeth, _ in backs:
                jump = np.median((front - back)[foreground])
                for r in back_teeth:
                    for s in front_teeth:
                        if jump + s - r < MIN_JUMP:
                            continue
                        mask, cost = _outline(cost_of(front, s), cost_of(back, r),
                                              front + s - back - r, near)
                        if pixel is not None and not mask[pixel]:
                            continue
                        if found is None or cost < found[3]:
                            combed_pair = support is not None or any(
                                back is plane for plane, _, _ in fitted)
                            found = (mask, front + s, back + r, cost, combed_pair)
        if found is None or (best is not None and found[3] >= best[3]):
            break
        if best is not None:            # planes fitted to a comb's outline are a comb's
            found = (*found[:4], found[4] or best[4])
        best = found
        foreground, surface = found[0], np.where(found[0], found[1], found[2])
    return best


def on_layers(result, left, right, d_max, anchor=None):
    """``result`` (a :class:`~lss_kernels.result.Result` of the pair ``left``, ``right``,
    after :func:`~lss_kernels.checks.teeth.on_tooth`) replaced in place by the layers and
    outline that :func:`choose_layers` reads from the pair when their warp
    (:func:`~lss_kernels.checks.teeth.warp_cost`) differs from the right image by
    ``MIN_GAIN`` less than ``result``'s does (given an ``anchor``, a left-view
    :class:`~lss_kernels.start_types.Point` such as a whole photo's click, only layers that
    keep the clicked object are read; without one, layers read on a comb's plane must
    explain the pair to ``COMB_FIT``: module text): the two planes as the surfaces (the refined
    disparity kept where a pixel's layer and surface are unchanged, to half a pixel),
    Theta_1 and Theta_2 the planes in the cyclopean frame, phi ``PHI_SCALE`` times the
    signed distance along each row to the outline moved to the cyclopean frame, the
    occlusion of the new surfaces (confidence 0 there).  Returns what was found (None: no
    pair of teeth with the object in front); ``result`` is changed in place."""
    from ..model.layers import occlusion_by_layers
    left = np.asarray(left, np.float64)
    right = np.asarray(right, np.float64)
    if left.ndim == 2:
        left, right = left[..., None], right[..., None]
    right = upsampled(right)
    foreground = np.asarray(result.foreground, bool)
    solved = np.asarray(result.surface, np.float64)
    found = choose_layers(left, right, foreground, solved, d_max, anchor)
    if found is None:
        return None
    mask, front, back, _, combed = found
    surface = np.where(mask, front, back)
    before = warp_cost(left, right, foreground, solved, UPSAMPLE)[0]
    after = warp_cost(left, right, mask, surface, UPSAMPLE)[0]
    kept = anchor is not None or (mask.any() and (not combed or after <= COMB_FIT))
    taken = bool(after < (1.0 - MIN_GAIN) * before and kept)
    info = {"cost_before": before, "cost": after, "taken": taken, "anchored": anchor is not None,
            "front": float(np.median(front[mask])) if mask.any() else None,
            "back": float(np.median(back[~mask]))}
    if not taken:
        return info
    same = (mask == foreground) & (np.abs(surface - solved) <= 0.5)
    clean = lambda d: np.clip(d, 0.0, d_max).astype(np.float32)
    result.disparity = clean(np.where(same, result.disparity, surface))
    result.foreground, result.surface = mask, clean(surface)
    result.occlusion = occlusion_by_layers(result.surface, mask.astype(np.int32))
    result.confidence = np.where(result.occlusion, 0.0, result.confidence).astype(np.float32)
    if result.layers is not None:
        result.layers = mask.astype(np.uint8)
    for name, plane, region in (("theta_fg", front, mask), ("theta_bg", back, ~mask)):
        # d = a x_left + b y + c with x_left = x_cyclopean + d / 2
        a, b, c = _coefficients(plane, region)
        theta = np.array([0.0, 0.0, 0.0, a, b, c]) / (1.0 - a / 2.0)
        setattr(result, name, theta.astype(np.asarray(getattr(result, name)).dtype))
    result.phi = _row_distance(mask, front).astype(np.float32)
    return info


def _pixel(anchor, shape):
    """The pixel ``(y, x)`` nearest ``anchor`` (a left-view point), or None outside
    ``shape``."""
    y, x = int(round(anchor.y)), int(round(anchor.x))
    return (y, x) if 0 <= y < shape[0] and 0 <= x < shape[1] else None


def _row_distance(mask, front):
    """``PHI_SCALE`` times the signed distance along each row (> 0 inside) to the run of
    ``mask`` (one a row, left view) moved to the cyclopean frame (``x - front / 2`` at its
    ends); rows without it at minus the width."""
    H, W = mask.shape
    x = np.arange(W, dtype=np.float64)
    phi = np.full((H, W), -float(W))
    for y in np.nonzero(mask.any(axis=1))[0]:
        cols = np.nonzero(mask[y])[0]
        a = cols[0] - 0.5 - front[y, cols[0]] / 2.0
        b = cols[-1] + 0.5 - front[y, cols[-1]] / 2.0
        phi[y] = np.minimum(x - a, b - x)
    return PHI_SCALE * phi
