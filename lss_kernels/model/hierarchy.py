"""The cooperative patch hierarchy: upward messages and validity, downward consensus.

Sec. 3 of the paper, after Chakrabarti et al. (2015): levels of dense, overlapping square
patches, one patch centred on every pixel at every level, where a patch at level ``l`` is the
union of ``r x r`` non-overlapping patches of level ``l - 1`` (``r = s_l / s_{l-1}``; level 0
is the pixels).  Everything a patch needs is relayed between parents and children:

* **upward**: the patch-mean matching cost C_p(c) (once, at set-up), the patch mean of the
  current disparity D, and the extremes of phi and phi(x + delta_theta) that decide the
  validity w_p (Eq. 4);
* **messages**: d_p = argmin_c C_p(c) + beta |c - <D>_p| and sigma_p (Eq. 5), from two
  candidates per patch (the lower envelope of the cost under the L1 cone) that are searched
  again only where the integer part of <D>_p moved, refined below the integer grid where the
  matching cost has a local minimum;
* **downward**: every pixel receives the sums of w_p / sigma_p^2 and w_p d_p / sigma_p^2 over
  all patches that contain it (Eq. 7), relayed from parents to children.

Frame: cyclopean, arrays ``(H, W)`` indexed ``[y, x]``; disparities are cyclopean (left-view
disparity = 2 c); the cost volumes sample integer ``c = 1 .. c_max`` (volume index
``k = c - 1``).
Patches are centred on in-image pixels only; pixels outside the image contribute nothing
(sums are over in-image pixels and means divide by the in-image count).  Lower levels
carry a margin of patch centres outside the image because a parent near the border has
children centred there, and level 1 at least one patch reach (the pixels' consensus reads
it around them); the per-iteration relays are lane planes whose columns extend the margins
to whole blocks (:func:`column_spans`).
"""
import numpy as np
import taichi as ti

from ..kernels import lanes
from ..kernels.backend import ROWS_DISPARITIES_COLUMNS

__all__ = ["Level", "PatchHierarchy", "level_geometry"]


class Level:
    """Geometry of one level: patch side ``size``, the offsets of its children's centres
    (one axis; the children are the product of these offsets in y and x), and ``margin``, the
    number of patch centres kept outside the image on each side."""

    def __init__(self, size, half, offsets, margin):
        self.size, self.half, self.offsets, self.margin = size, half, tuple(offsets), margin

    def __repr__(self):
        return (f"Level(size={self.size}, offsets={self.offsets}, margin={self.margin})")


def level_geometry(sizes):
    """Levels for the patch sides ``sizes`` (e.g. ``(3, 9, 18)``).

    A patch of side ``s`` centred on ``x`` covers ``[x - s // 2, x - s // 2 + s - 1]``; its
    children (side ``s'``) are centred on ``x + o`` with ``o = -s // 2 + j s' + s' // 2``,
    ``j = 0 .. s / s' - 1``.
    """
    sizes = (1,) + tuple(sizes)
    levels = []
    for s_child, s in zip(sizes, sizes[1:]):
        offs = [-(s // 2) + j * s_child + s_child // 2 for j in range(s // s_child)]
        levels.append(Level(s, s // 2, offs, 0))
    margin = 0
    for lev_idx in range(len(levels) - 1, -1, -1):
        levels[lev_idx].margin = margin
        margin += max(abs(o) for o in levels[lev_idx].offsets)
    # the pixels read level 1's centres around them (the consensus): a single level needs
    # that margin too
    levels[0].margin = max(levels[0].margin, max(abs(o) for o in levels[0].offsets))
    return levels


def column_spans(levels, width, lanes_per_block):
    """The columns every level's lane planes hold, ``(left, right)``: patch centres
    ``x = -left .. right - 1``, both multiples of ``lanes_per_block``.

    The top level holds the image's blocks.  Going down, each level holds the reach of its
    parent's children beyond the parent's columns, rounded out to whole blocks (with one
    pixel per block: exactly the levels' margins); level 1 also reaches the pixels' blocks
    and one reach of its own beyond them (the consensus reads it there).  Patch centres
    beyond a level's margin only ever hold zero relays, and their sums and extremes are
    never read."""
    L = int(lanes_per_block)
    round_up = lambda v: -(-v // L) * L
    spans = [None] * len(levels)
    left, right = 0, round_up(width)
    spans[-1] = (left, right)
    for i in range(len(levels) - 2, -1, -1):
        reach = max(abs(o) for o in levels[i + 1].offsets)
        left, right = round_up(left + reach), round_up(right + reach)
        spans[i] = (left, right)
    reach = max(abs(o) for o in levels[0].offsets)
    left, right = spans[0]
    spans[0] = (max(left, round_up(reach)), max(right, round_up(round_up(width) + reach)))
    return spans


@ti.data_oriented
class PatchHierarchy:
    """Fields of every level and the kernels of the upward and downward passes.

    Parameters
    ----------
    pool : lss_kernels.kernels.backend.FieldPool
        Where the fields are allocated.
    height, width : int
        Image size (cyclopean grid).
    c_max : int
        Number of cyclopean disparities searched (``c = 1 .. c_max``).
    sizes : tuple of int
        Patch sides per level.
    subpixel : bool
        Refine each message's integer argmin to the vertex of a parabola (see
        ``Params.subpixel_messages``).
    """

    def __init__(self, pool, height, width, c_max, sizes, subpixel=True):
        self.H, self.W, self.C = int(height), int(width), int(c_max)
        self.subpixel = bool(subpixel)
        self.levels = level_geometry(sizes)
        H, W, C = self.H, self.W, self.C

        def padded(lev, *extra, dtype=ti.f32, order=None):
            m = lev.margin
            return pool.field(dtype, (H + 2 * m, W + 2 * m) + extra,
                              offset=(-m, -m) + (0,) * len(extra), order=order,
                              volume=len(extra) > 0)

        # upward: normalised patch-mean cost volumes, D sums, extremes (a patch's in-image
        # pixel count is its clipped square: :meth:`_in_image_count`).
        # Level 1 is also M of the Eq. 2 step, read at Theta_j per pixel: rows, disparities,
        # columns in memory; the patch levels are scanned along c per patch (messages)
        self.cost = [padded(lev, C, order=ROWS_DISPARITIES_COLUMNS if i == 0 else None)
                     for i, lev in enumerate(self.levels)]
        # the per-iteration relays are lane planes (blocks of ``lanes`` patch centres along
        # x; see :mod:`lss_kernels.kernels.lanes`): the upward and downward stencils run a block per
        # loop index.  Columns -left .. right - 1 of :func:`column_spans`, rows as ``padded``
        self.lanes = lanes.lanes_for_arch()
        self.spans = column_spans(self.levels, W, self.lanes)
        self.image_blocks = lanes.block_count(W, self.lanes)

        def lane_level(i):
            m, (left, right) = self.levels[i].margin, self.spans[i]
            return pool.vector(self.lanes, ti.f32, (H + 2 * m, (left + right) // self.lanes),
                               offset=(-m, -left // self.lanes))

        self.d_sum = [lane_level(i) for i in range(len(self.levels))]
        self.phi_max = [lane_level(i) for i in range(len(self.levels))]
        self.phi_plus_min = [lane_level(i) for i in range(len(self.levels))]
        # messages of the in-image patches, stored only on request (``messages(keep=True)``:
        # the tests and ``Solver.patch_curve``); an iteration passes them on as relays
        self.d_p = [pool.field(ti.f32, (H, W)) for _ in self.levels]
        self.sigma_p = [pool.field(ti.f32, (H, W)) for _ in self.levels]
        self.valid = [pool.field(ti.i32, (H, W)) for _ in self.levels]
        # per in-image patch, lane planes of the two candidates of Eq. 5 (the argmins below
        # and above the prior mean m, see :meth:`_side_argmins`) for the current
        # (floor(m), ceil(m)), ``env_key`` (0 = none): they depend on m only through that
        # pair, so a patch scans its cost curve again only where the pair moved (after the
        # first few iterations, < 1 % of the patches).  Stored with beta and the mean over c
        # folded in: ``env_below`` = C_p(c-) - beta c- - mean_c C_p, ``env_above`` =
        # C_p(c+) + beta c+ - mean_c C_p (1e30 for an empty side), and their positions
        # refined below the integer grid, ``env_d_below`` and ``env_d_above``
        def lane_cache(dtype=ti.f32):
            return [pool.vector(self.lanes, dtype, (H, self.image_blocks))
                    for _ in self.levels]

        self.env_key = lane_cache(ti.i32)
        self.env_below = lane_cache()
        self.env_above = lane_cache()
        self.env_d_below = lane_cache()
        self.env_d_above = lane_cache()
        self._cached_beta = None
        # downward relays of w / sigma^2 and w d / sigma^2
        self.relay_a = [lane_level(i) for i in range(len(self.levels))]
        self.relay_b = [lane_level(i) for i in range(len(self.levels))]
        # the consensus (Eq. 7)
        self.precision = pool.field(ti.f32, (H, W))       # 1 / sigma^2
        self.consensus_mean = pool.field(ti.f32, (H, W))  # d-bar, cyclopean units
        self._lo = pool.field(ti.f32, ())
        self._hi = pool.field(ti.f32, ())
        self.curve = pool.field(ti.f32, (C,), volume=True)

    # ------------------------------------------------------------------ set-up (upward costs)
    @ti.func
    def _in_image_count(self, size: ti.template(), y, x):
        """In-image pixels of the patch of side ``size`` centred on (y, x) (``x`` may be a
        vector of centres): its square ``[c - size // 2, c - size // 2 + size - 1]`` per axis,
        clipped to the image; 0 for a patch wholly outside.  A parent's count is the sum of
        its children's, since the children tile it."""
        h = ti.static(size // 2)
        rows = ti.max(ti.min(y - h + size - 1, self.H - 1) - ti.max(y - h, 0) + 1, 0)
        cols = ti.max(ti.min(x - h + size - 1, self.W - 1) - ti.max(x - h, 0) + 1, 0)
        return rows * cols

    @ti.kernel
    def _cost_from_pixels(self, left: ti.template(), right: ti.template(), dst: ti.template(),
                          offs: ti.template()):
        H, W = self.H, self.W
        for y, x, k in dst:
            c = k + 1
            total = 0.0
            n = 0
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                py = y + offs[jy]
                px = x + offs[jx]
                if 0 <= py < H and 0 <= px < W:
                    xl = ti.min(px + c, W - 1)
                    xr = ti.max(px - c, 0)
                    diff = 0.0
                    for ch in ti.static(range(3)):
                        diff += ti.abs(left[py, xl][ch] - right[py, xr][ch])
                    total += diff / 3.0
                    n += 1
            dst[y, x, k] = total / ti.max(n, 1)

    @ti.kernel
    def _cost_from_children(self, src: ti.template(), child_size: ti.template(),
                            dst: ti.template(), offs: ti.template()):
        for y, x, k in dst:
            total = 0.0
            n = 0
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                cy = y + offs[jy]
                cx = x + offs[jx]
                m = self._in_image_count(child_size, cy, cx)
                total += src[cy, cx, k] * m
                n += m
            dst[y, x, k] = total / ti.max(n, 1)

    @ti.kernel
    def _normalise(self, vol: ti.template()):
        """Min-max normalise a level's volume to [0, 1] over its in-image patches."""
        self._lo[None] = 1e30
        self._hi[None] = -1e30
        for y, x in ti.ndrange(self.H, self.W):
            # a patch's extremes first: one atomic per patch, not one per candidate
            lo = vol[y, x, 0]
            hi = lo
            for k in range(1, self.C):
                lo = ti.min(lo, vol[y, x, k])
                hi = ti.max(hi, vol[y, x, k])
            ti.atomic_min(self._lo[None], lo)
            ti.atomic_max(self._hi[None], hi)
        lo = self._lo[None]
        scale = 1.0 / ti.max(self._hi[None] - lo, 1e-12)
        for y, x, k in vol:
            vol[y, x, k] = (vol[y, x, k] - lo) * scale

    def build_costs(self, left, right):
        """Fill every level's C_p(c) (patch mean of M, min-max normalised per level).

        ``left``, ``right``: ``ti.Vector.field(3, f32)`` of shape ``(H, W)``, values in [0, 1].
        Level 1 sums the pixels' matching costs M(x, y, c) = mean_RGB |L(x + c) - R(x - c)|
        (image coordinates clamped at the borders); each higher level sums its children.
        """
        lev0 = self.levels[0]
        self._cost_from_pixels(left, right, self.cost[0], lev0.offsets)
        for i in range(1, len(self.levels)):
            self._cost_from_children(self.cost[i - 1], self.levels[i - 1].size, self.cost[i],
                                     self.levels[i].offsets)
        for vol in self.cost:
            self._normalise(vol)
        self._cached_beta = None

    # ------------------------------------------------------------------ upward, per iteration
    @ti.func
    def _shifted(self, plane: ti.template(), y, b, o: ti.template(), span: ti.template()):
        """Centres ``b L + o .. b L + o + L - 1`` of row ``y`` of a level's lane plane (``o``
        a compile-time offset): one or two whole blocks, their lanes moved by ``o mod L``.
        With a ``span`` (a parent's columns, which end before its child's; ``()``: none),
        blocks outside it read as zeros: no patch there relays anything."""
        L = ti.static(self.lanes)
        q = ti.static(o // L)
        r = ti.static(o % L)
        value = self._block(plane, y, b + q, span)
        if ti.static(r != 0):
            value = self._merge_lanes(value, self._block(plane, y, b + q + 1, span), r)
        return value

    @ti.func
    def _block(self, plane: ti.template(), y, b, span: ti.template()):
        """Block ``b`` of row ``y``; with a ``span`` (not ``()``), zeros outside its
        columns."""
        L = ti.static(self.lanes)
        value = ti.Vector.zero(ti.f32, L)
        if ti.static(len(span) == 0):
            value = plane[y, b]
        elif -ti.static(span[0] // L) <= b < ti.static(span[1] // L):
            value = plane[y, b]
        return value

    @ti.func
    def _merge_lanes(self, first, second, r: ti.template()):
        """Lanes ``r .. L - 1`` of ``first`` followed by lanes ``0 .. r - 1`` of
        ``second``."""
        L = ti.static(self.lanes)
        pair = [first, second]
        return ti.Vector([pair[ti.static((r + l) // L)][ti.static((r + l) % L)]
                          for l in ti.static(range(L))])

    @ti.func
    def _window(self, src: ti.template(), y, x0, lo: ti.template(), hi: ti.template(),
                fill):
        """Pixels ``x0 + lo .. x0 + L - 1 + hi`` of row ``y`` of a plain ``(H, W)`` plane as a
        vector, ``fill`` for those outside the image (unclamped reads away from the
        borders; a run-time loop near them)."""
        n = ti.static(self.lanes + hi - lo)
        window = ti.Vector.zero(ti.f32, n)
        if 0 <= x0 + lo and x0 + n + lo <= self.W:
            for k in ti.static(range(n)):
                window[k] = src[y, x0 + lo + k]
        else:
            for k in range(n):
                window[k] = fill
                x = x0 + lo + k
                if 0 <= x < self.W:
                    window[k] = src[y, x]
        return window

    @ti.func
    def _up_from_pixels(self, D: ti.template(), phi: ti.template(), phi_plus: ti.template(),
                        d_sum: ti.template(), phi_max: ti.template(),
                        phi_plus_min: ti.template(), offs: ti.template()):
        """Level 1 from the pixels, a block of patch centres at a time: each row of the
        patches reads its window of the three planes once (out-of-image pixels as the
        neutral 0, -1e30, +1e30, the old starting values: every patch sums and compares in the
        same order)."""
        L = ti.static(self.lanes)
        lo = ti.static(offs[0])                 # the offsets ascend
        hi = ti.static(offs[len(offs) - 1])
        for y, b in d_sum:
            x0 = b * L
            s = ti.Vector.zero(ti.f32, L)
            most = ti.Vector([-1e30] * L)
            least = ti.Vector([1e30] * L)
            for jy in ti.static(range(len(offs))):
                py = y + offs[jy]
                if 0 <= py < self.H:
                    wd = self._window(D, py, x0, lo, hi, 0.0)
                    wp = self._window(phi, py, x0, lo, hi, -1e30)
                    wq = self._window(phi_plus, py, x0, lo, hi, 1e30)
                    for jx in ti.static(range(len(offs))):
                        k = ti.static(offs[jx] - lo)
                        s += lanes.take(wd, k, L)
                        most = ti.max(most, lanes.take(wp, k, L))
                        least = ti.min(least, lanes.take(wq, k, L))
            d_sum[y, b] = s
            phi_max[y, b] = most
            phi_plus_min[y, b] = least

    @ti.func
    def _up_from_children(self, src_sum: ti.template(), src_max: ti.template(),
                          src_min: ti.template(), d_sum: ti.template(), phi_max: ti.template(),
                          phi_plus_min: ti.template(), offs: ti.template()):
        L = ti.static(self.lanes)
        for y, b in d_sum:
            s = ti.Vector.zero(ti.f32, L)
            most = ti.Vector([-1e30] * L)
            least = ti.Vector([1e30] * L)
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                cy = y + offs[jy]
                s += self._shifted(src_sum, cy, b, offs[jx], ())
                most = ti.max(most, self._shifted(src_max, cy, b, offs[jx], ()))
                least = ti.min(least, self._shifted(src_min, cy, b, offs[jx], ()))
            d_sum[y, b] = s
            phi_max[y, b] = most
            phi_plus_min[y, b] = least

    @ti.kernel
    def upward(self, D: ti.template(), phi: ti.template(), phi_plus: ti.template()):
        """Relay the patch sums of D and the patch extremes of phi and phi(x + delta_theta)
        from the pixels up through every level (inputs: ``(H, W)`` f32 fields).  One launch:
        the levels' loops run in order."""
        self._up_from_pixels(D, phi, phi_plus, self.d_sum[0], self.phi_max[0],
                             self.phi_plus_min[0], ti.static(self.levels[0].offsets))
        for i in ti.static(range(1, len(self.levels))):
            self._up_from_children(self.d_sum[i - 1], self.phi_max[i - 1],
                                   self.phi_plus_min[i - 1], self.d_sum[i], self.phi_max[i],
                                   self.phi_plus_min[i], ti.static(self.levels[i].offsets))

    def level_image(self, planes, level):
        """The in-image patch centres of one level of ``d_sum``, ``phi_max``,
        ``phi_plus_min``, ``relay_a`` or ``relay_b`` as a float32 ``(H, W)`` array."""
        blocks = planes[level].to_numpy()
        rows = blocks.reshape(blocks.shape[0], -1)
        m, left = self.levels[level].margin, self.spans[level][0]
        return np.ascontiguousarray(rows[m:m + self.H, left:left + self.W], dtype=np.float32)

    # ------------------------------------------------------------------ messages (Eq. 4, 5)
    @ti.func
    def _refine(self, cost: ti.template(), y, x, arg):
        """d_p below the integer grid (Eq. 5 takes the argmin over a continuous d): where the
        matching cost C_p has a local minimum at ``arg``, the vertex of the parabola through
        C_p at ``arg - 1``, ``arg``, ``arg + 1`` (it lies within half a step).  ``arg`` itself
        at the ends of the range, on flat costs, where the prior beta |c - m| rather than the
        matching cost put the minimum at ``arg``, or with ``subpixel`` off."""
        r = ti.cast(arg, ti.f32)
        if ti.static(self.subpixel):
            if 1 < arg < self.C:
                cm = cost[y, x, arg - 2]
                c0 = cost[y, x, arg - 1]
                cp = cost[y, x, arg]
                den = cm - 2.0 * c0 + cp
                if c0 <= cm and c0 <= cp and den > 1e-12:
                    r += ti.min(ti.max(0.5 * (cm - cp) / den, -0.5), 0.5)
        return r

    @ti.func
    def _side_argmins(self, cost: ti.template(), y, x, lo, hi, beta):
        """The two candidates of Eq. 5 for a prior mean m with floor m = ``lo``, ceil m =
        ``hi``:

        min_c C_p(c) + beta |c - m| = min( min_{c <= lo} [C_p(c) - beta c] + beta m,
                                           min_{c >= hi} [C_p(c) + beta c] - beta m ),

        and neither inner argmin depends on m itself (the lower envelope of the cost under an
        L1 cone).  Returns (argmin over c <= lo, argmin over c >= hi), 0 where the side is
        empty; ties go to the smallest c."""
        c_lo = 0
        best = 1e30
        for k in range(lo):
            g = cost[y, x, k] - beta * (k + 1)
            if g < best:
                best = g
                c_lo = k + 1
        c_hi = 0
        best = 1e30
        for j in range(self.C - hi + 1):
            k = self.C - 1 - j
            g = cost[y, x, k] + beta * (k + 1)
            if g <= best:
                best = g
                c_hi = k + 1
        return c_lo, c_hi

    @ti.func
    def _messages(self, size: ti.template(), cost: ti.template(), env_key: ti.template(),
                  env_below: ti.template(), env_above: ti.template(),
                  env_d_below: ti.template(), env_d_above: ti.template(),
                  d_sum: ti.template(), phi_max: ti.template(), phi_plus_min: ti.template(),
                  relay_a: ti.template(), relay_b: ti.template(), d_p: ti.template(),
                  sigma_p: ti.template(), valid: ti.template(), beta: ti.f32,
                  use_validity: ti.i32, keep: ti.template()):
        """Eq. 4 and Eq. 5 per patch: d_p and sigma_p of the full scan of
        C_p(c) + beta |c - m| (up to float rounding of near-ties), from the two cached
        candidates of :meth:`_side_argmins`; a patch whose (floor m, ceil m) moved since the
        last call searches its curve again (:meth:`_search`).  A block of patch centres at a
        time, in SIMD lanes: the relays are stored as whole blocks, d_p, sigma_p and the
        validity only if ``keep``."""
        L = ti.static(self.lanes)
        cf = ti.cast(self.C, ti.f32)
        for y, blk in ti.ndrange(self.H, self.image_blocks):
            x = ti.Vector([blk * L + lane for lane in ti.static(range(L))])
            w = ti.cast(x < self.W, ti.i32)          # in the image and valid
            if use_validity:
                w &= ti.cast((phi_max[y, blk] > 0) != (phi_plus_min[y, blk] < 0),
                             ti.i32)                  # Eq. 4
            # the prior mean m
            n = self._in_image_count(size, y, x)
            m = ti.min(ti.max(d_sum[y, blk] / ti.max(n, 1), 0.0), cf)
            lo = ti.cast(ti.floor(m), ti.i32)            # candidates c <= lo ...
            hi = ti.max(ti.cast(ti.ceil(m), ti.i32), 1)  # ... and c >= hi
            key = 2 * lo + 1 + ti.cast(hi == lo, ti.i32)
            moved = w & ti.cast(env_key[y, blk] != key, ti.i32)
            if moved.sum() > 0:
                for lane in range(L):
                    if moved[lane]:
                        self._search(cost, env_key, env_below, env_above, env_d_below,
                                     env_d_above, y, blk, lane, x[lane], lo[lane], hi[lane],
                                     key[lane], beta)
            # Eq. 5 from the two candidates: min over c of C_p(c) + beta |c - m|, less the
            # mean over c of C_p
            below = env_below[y, blk] + beta * m
            above = env_above[y, blk] - beta * m
            take_above = above < below
            best = ti.min(below, above)
            d = ti.select(take_above, env_d_above[y, blk], env_d_below[y, blk])
            # mean over c of beta |c - m|, in closed form
            f = ti.cast(lo, ti.f32)
            l1 = f * m - 0.5 * f * (f + 1.0) + 0.5 * (cf * (cf + 1.0) - f * (f + 1.0)) \
                - (cf - f) * m
            spread = beta * l1 / cf - best
            sigma = ti.select(w == 1, cf / (spread + 1e-8), 1.0)   # 1: no message
            a = ti.select(w == 1, 1.0 / (sigma * sigma), 0.0)
            relay_a[y, blk] = a
            relay_b[y, blk] = a * d
            if ti.static(keep):
                for lane in ti.static(range(L)):
                    if x[lane] < self.W:
                        valid[y, x[lane]] = w[lane]
                        if w[lane] == 1:
                            d_p[y, x[lane]] = d[lane]
                            sigma_p[y, x[lane]] = sigma[lane]

    @ti.func
    def _search(self, cost: ti.template(), env_key: ti.template(), env_below: ti.template(),
                env_above: ti.template(), env_d_below: ti.template(),
                env_d_above: ti.template(), y, blk, lane, x, lo, hi, key, beta):
        """Patch ``(y, x)``'s two candidates of Eq. 5 (:meth:`_side_argmins`), searched again
        and cached in lane ``lane`` of block ``blk`` under ``key``."""
        c_lo, c_hi = self._side_argmins(cost, y, x, lo, hi, beta)
        total = 0.0
        for k in range(self.C):
            total += cost[y, x, k]
        mean = total / self.C
        below, d_below = 1e30, 1.0
        if c_lo >= 1:
            below = cost[y, x, c_lo - 1] - beta * c_lo - mean
            d_below = self._refine(cost, y, x, c_lo)
        above, d_above = 1e30, 1.0
        if c_hi >= 1:
            above = cost[y, x, c_hi - 1] + beta * c_hi - mean
            d_above = self._refine(cost, y, x, c_hi)
        env_below[y, blk][lane] = below
        env_above[y, blk][lane] = above
        env_d_below[y, blk][lane] = d_below
        env_d_above[y, blk][lane] = d_above
        env_key[y, blk][lane] = key

    def messages(self, beta, use_prior, use_validity, keep=False):
        """Per-patch (d_p, sigma_p) and w_p at every level; seeds the downward relays.

        A patch scans its cost curve (O(c_max)) only when floor or ceil of its prior mean
        moved, or the prior weight changed; otherwise its message is O(1) from the cached
        candidates.  Validity from Eq. 4 if ``use_validity``.  Without the prior (the first
        iteration) the weight is 0: the two candidates then cover every c, so d_p is the
        plain argmin and every patch is valid.  ``keep``: also store ``d_p``, ``sigma_p``
        and ``valid`` (same inputs give the same messages: a second call after an
        iteration's reproduces them)."""
        beta = float(beta) if use_prior else 0.0
        if not use_prior and use_validity:
            raise ValueError("messages: validity needs the prior (iteration >= 2)")
        if self._cached_beta != beta:
            for key in self.env_key:
                key.fill(0)
            self._cached_beta = beta
        self._all_messages(beta, int(use_validity), bool(keep))

    @ti.kernel
    def _all_messages(self, beta: ti.f32, use_validity: ti.i32, keep: ti.template()):
        """:meth:`_messages` of every level, in one launch."""
        for i in ti.static(range(len(self.levels))):
            self._messages(ti.static(self.levels[i].size), self.cost[i], self.env_key[i],
                           self.env_below[i], self.env_above[i], self.env_d_below[i],
                           self.env_d_above[i], self.d_sum[i], self.phi_max[i],
                           self.phi_plus_min[i], self.relay_a[i], self.relay_b[i],
                           self.d_p[i], self.sigma_p[i], self.valid[i], beta, use_validity,
                           keep)

    # ------------------------------------------------------------------ downward (Eq. 7)
    @ti.func
    def _down(self, relay_a: ti.template(), relay_b: ti.template(), parent_a: ti.template(),
              parent_b: ti.template(), parent_offs: ti.template(),
              parent_margin: ti.template(), parent_span: ti.template()):
        """A level's relays += its parents', a block of patch centres at a time; its own
        messages count only at in-image centres (the rest of the plane holds last
        iteration's relays)."""
        H, W = self.H, self.W
        L = ti.static(self.lanes)
        for y, b in relay_a:
            a = ti.Vector.zero(ti.f32, L)
            c = ti.Vector.zero(ti.f32, L)
            if 0 <= y < H:
                own_a = relay_a[y, b]
                own_b = relay_b[y, b]
                for l in ti.static(range(L)):
                    if 0 <= b * L + l < W:
                        a[l] = own_a[l]
                        c[l] = own_b[l]
            for jy in ti.static(range(len(parent_offs))):
                py = y - parent_offs[jy]
                if -parent_margin <= py < H + parent_margin:
                    for jx in ti.static(range(len(parent_offs))):
                        a += self._shifted(parent_a, py, b, -parent_offs[jx], parent_span)
                        c += self._shifted(parent_b, py, b, -parent_offs[jx], parent_span)
            relay_a[y, b] = a
            relay_b[y, b] = c

    @ti.func
    def _to_pixels(self, relay_a: ti.template(), relay_b: ti.template(),
                   offs: ti.template()):
        L = ti.static(self.lanes)
        for y, b in ti.ndrange(self.H, self.image_blocks):
            a = ti.Vector.zero(ti.f32, L)
            c = ti.Vector.zero(ti.f32, L)
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                a += self._shifted(relay_a, y - offs[jy], b, -offs[jx], ())
                c += self._shifted(relay_b, y - offs[jy], b, -offs[jx], ())
            for l in ti.static(range(L)):
                x = b * L + l
                if x < self.W:
                    self.precision[y, x] = a[l]
                    self.consensus_mean[y, x] = c[l] / a[l] if a[l] > 0 else 0.0

    @ti.kernel
    def downward(self):
        """Relay the messages down to the pixels: fills ``precision`` (1/sigma^2) and
        ``consensus_mean`` (d-bar; 0 where no valid patch contains the pixel).  One launch:
        the levels' loops run in order, from the top."""
        # the top level has no parent: its relay is just its own messages
        for i in ti.static(range(len(self.levels) - 2, -1, -1)):
            self._down(self.relay_a[i], self.relay_b[i], self.relay_a[i + 1],
                       self.relay_b[i + 1], ti.static(self.levels[i + 1].offsets),
                       ti.static(self.levels[i + 1].margin), ti.static(self.spans[i + 1]))
        self._to_pixels(self.relay_a[0], self.relay_b[0], ti.static(self.levels[0].offsets))

    # ------------------------------------------------------------------ inspection
    @ti.kernel
    def _read_curve(self, cost: ti.template(), y: ti.i32, x: ti.i32):
        for k in range(self.C):
            self.curve[k] = cost[y, x, k]

    def in_image_count(self, level, y, x):
        """:meth:`_in_image_count` of one patch of ``level``, on the host."""
        size = self.levels[level].size
        lo_y, lo_x = y - size // 2, x - size // 2
        rows = min(lo_y + size - 1, self.H - 1) - max(lo_y, 0) + 1
        cols = min(lo_x + size - 1, self.W - 1) - max(lo_x, 0) + 1
        return max(rows, 0) * max(cols, 0)

    def patch_cost(self, level, y, x):
        """The normalised patch-mean matching cost C_p(c), ``c = 1 .. c_max``, of one patch."""
        self._read_curve(self.cost[level], int(y), int(x))
        return self.curve.to_numpy()
