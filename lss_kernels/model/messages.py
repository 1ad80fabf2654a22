"""Per-patch disparity messages and validity: Eqs. 4 and 5 of the paper.

For every patch p of every level of the hierarchy (:mod:`lss_kernels.model.hierarchy`), from
what the upward pass brought it -- the patch sum of D and the extremes of phi and
phi(x + delta_theta) --

* w_p = [max_p phi > 0] XOR [min_p phi(x + delta_theta) < 0]                    (Eq. 4)
* d_p = argmin_c C_p(c) + beta |c - m|,  sigma_p = c_max / (<C_p + beta |c - m|>_c - min)
                                                                                   (Eq. 5)

with m the patch mean of D and C_p the patch-mean matching cost.  Eq. 5 writes the prior as a
sum of |d - D(x, y)| over the patch; we use |d - <D>_p| of the patch mean (relayed up the
hierarchy), as the authors' release does at the patch centre.  Invalid patches send no message
(relay 0).  A valid patch seeds the downward relays with 1 / sigma_p^2 and d_p / sigma_p^2.

How it is made fast without changing the result: the minimum of C_p(c) + beta |c - m| is the
better of two candidates, the argmins of C_p(c) - beta c over c <= floor m and of
C_p(c) + beta c over c >= ceil m (the lower envelope of the cost under an L1 cone), which depend
on m only through (floor m, ceil m).  They are cached per patch (the level's ``key``,
``below``, ``above``, ``d_below``, ``d_above`` lane planes) and searched again only where that
pair moved (after the first few iterations, < 1 % of the patches).  Where the matching cost
has a local minimum at the argmin, d_p is refined to the vertex of the parabola through it and
its two neighbours (Eq. 5 takes a continuous argmin; ``subpixel`` off gives the release's
integer messages).

Frame: cyclopean; disparities ``c = 1 .. c_max`` (volume index ``k = c - 1``).
"""
import numpy as np
import taichi as ti

from ..kernels.curves import curve_minima, parabola_vertex

__all__ = ["Messages"]


@ti.data_oriented
class Messages:
    """The message pass over a :class:`~lss_kernels.model.hierarchy.PatchHierarchy`'s levels
    (their fields hold the cache and the relays it writes).

    Parameters
    ----------
    hierarchy : PatchHierarchy
    subpixel : bool
        Refine each message's integer argmin to the vertex of a parabola (see
        ``Params.subpixel_messages``).
    pool : FieldPool, optional
        Where the distinctness planes live (needed with ``ambiguity > 0``).
    ambiguity : float
        0: Eq. 5's sigma_p alone.  > 0: a patch's precision is also weighted by the
        distinctness of its matching-cost curve, ``q = clip((1 - r) / ambiguity, 0, 1)``
        with the peak ratio ``r = (mean - second) / (mean - best)`` (``second``: the
        lowest cost at least two candidates from the best): a periodic or flat curve with
        several equally deep minima sends (almost) no message (see
        ``Params.message_ambiguity``).
    """

    def __init__(self, hierarchy, subpixel=True, pool=None, ambiguity=0.0):
        self.hierarchy = hierarchy
        self.levels = hierarchy.levels
        self.H, self.W, self.C = hierarchy.H, hierarchy.W, hierarchy.C
        self.extent = hierarchy.extent
        self.lanes = hierarchy.lanes
        self.subpixel = bool(subpixel)
        self.ambiguity = float(ambiguity)
        # per level, q of every patch centre in lane blocks (as the level's ``key``), in the
        # bucket's shape
        height, width = self.extent.bucket
        self.distinct = ([pool.vector(self.lanes, ti.f32,
                                      (height, -(-width // self.lanes)), bucket=True)
                          for _ in self.levels] if self.ambiguity > 0 else [])
        self._cached = None       # (beta, the hierarchy's cost_version) of the cache
        self._distinct_version = None
        self.extent.pool.host(*(level.key for level in self.levels))   # emptied by prepare

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
                if c0 <= cm and c0 <= cp:
                    r += ti.min(ti.max(parabola_vertex(cm, c0, cp, 1e-12), -0.5), 0.5)
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
    def _level(self, level: ti.template(), beta: ti.f32, use_validity: ti.i32,
               keep: ti.template()):
        """Eq. 4 and Eq. 5 per patch: d_p and sigma_p of the full scan of
        C_p(c) + beta |c - m| (up to float rounding of near-ties), from the two cached
        candidates of :meth:`_side_argmins`; a patch whose (floor m, ceil m) moved since the
        last call searches its curve again (:meth:`_search`).  A block of patch centres at a
        time, in SIMD lanes: the relays are stored as whole blocks, d_p, sigma_p and the
        validity only if ``keep``."""
        L = ti.static(self.lanes)
        cf = ti.cast(self.C, ti.f32)
        size, cost = ti.static(level.size, level.cost)
        d_sum, phi_max, phi_plus_min = ti.static(level.d_sum, level.phi_max, level.phi_plus_min)
        width = self.extent.width()
        for y, blk in ti.ndrange(*ti.static(self.hierarchy.bucket_blocks)):
            if y < self.extent.height() and blk < self.hierarchy.image_blocks_now():
                x = ti.Vector([blk * L + lane for lane in ti.static(range(L))])
                w = ti.cast(x < width, ti.i32)           # in the image and valid
                if use_validity:
                    w &= ti.cast((phi_max[y, blk] > 0) != (phi_plus_min[y, blk] < 0),
                                 ti.i32)                  # Eq. 4
                # the prior mean m
                n = self.hierarchy._in_image_count(size, y, x, self.extent.height(), width)
                m = ti.min(ti.max(d_sum[y, blk] / ti.max(n, 1), 0.0), cf)
                lo = ti.cast(ti.floor(m), ti.i32)            # candidates c <= lo ...
                hi = ti.max(ti.cast(ti.ceil(m), ti.i32), 1)  # ... and c >= hi
                key = 2 * lo + 1 + ti.cast(hi == lo, ti.i32)
                moved = w & ti.cast(level.key[y, blk] != key, ti.i32)
                if moved.sum() > 0:
                    for lane in range(L):
                        if moved[lane]:
                            self._search(level, y, blk, lane, x[lane], lo[lane], hi[lane],
                                         key[lane], beta)
                # Eq. 5 from the two candidates: min over c of C_p(c) + beta |c - m|, less the
                # mean over c of C_p
                below = level.below[y, blk] + beta * m
                above = level.above[y, blk] - beta * m
                take_above = above < below
                best = ti.min(below, above)
                d = ti.select(take_above, level.d_above[y, blk], level.d_below[y, blk])
                # mean over c of beta |c - m|, in closed form
                f = ti.cast(lo, ti.f32)
                l1 = f * m - 0.5 * f * (f + 1.0) + 0.5 * (cf * (cf + 1.0) - f * (f + 1.0)) \
                    - (cf - f) * m
                spread = beta * l1 / cf - best
                sigma = ti.select(w == 1, cf / (spread + 1e-8), 1.0)   # 1: no message
                a = ti.select(w == 1, 1.0 / (sigma * sigma), 0.0)
                if ti.static(self.ambiguity > 0):
                    a *= self.distinct[level.index][y, blk]
                level.relay_a[y, blk] = a
                level.relay_b[y, blk] = a * d
                if ti.static(keep):
                    for lane in ti.static(range(L)):
                        if x[lane] < width:
                            level.valid[y, x[lane]] = w[lane]
                            if w[lane] == 1:
                                level.d_p[y, x[lane]] = d[lane]
                                level.sigma_p[y, x[lane]] = sigma[lane]

    @ti.func
    def _search(self, level: ti.template(), y, blk, lane, x, lo, hi, key, beta):
        """Patch ``(y, x)``'s two candidates of Eq. 5 (:meth:`_side_argmins`), searched again
        and cached in lane ``lane`` of block ``blk`` under ``key``."""
        cost = ti.static(level.cost)
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
        level.below[y, blk][lane] = below
        level.above[y, blk][lane] = above
        level.d_below[y, blk][lane] = d_below
        level.d_above[y, blk][lane] = d_above
        level.key[y, blk][lane] = key

    def run(self, beta, use_prior, use_validity, keep=False):
        """Per-patch (d_p, sigma_p) and w_p at every level; seeds the downward relays.

        A patch scans its cost curve (O(c_max)) only when floor or ceil of its prior mean
        moved, or the prior weight changed; otherwise its message is O(1) from the cached
        candidates.  Validity from Eq. 4 if ``use_validity``.  Without the prior (the first
        iteration) the weight is 0: the two candidates then cover every c, so d_p is the
        plain argmin and every patch is valid.  ``keep``: also store ``d_p``, ``sigma_p``
        and ``valid`` (same inputs give the same messages: a second call after an
        iteration's reproduces them)."""
        self._all_levels(self.prepare(beta, use_prior, use_validity), int(use_validity),
                         bool(keep))

    def prepare(self, beta, use_prior, use_validity):
        """What :meth:`run` does on the host before its kernel (:meth:`levels_func`, which a
        kernel can run with other stages): the patches' distinctness once per cost volume,
        the cache of candidates emptied when the prior weight or the volumes changed.
        Returns the prior weight."""
        beta = float(beta) if use_prior else 0.0
        if not use_prior and use_validity:
            raise ValueError("messages: validity needs the prior (iteration >= 2)")
        cached = (beta, self.hierarchy.cost_version)
        if self.ambiguity > 0 and self._distinct_version != self.hierarchy.cost_version:
            for i in range(len(self.levels)):
                self._distinctness(i, self.levels[i].cost)
            self._distinct_version = self.hierarchy.cost_version
        if self._cached != cached:
            for level in self.levels:
                self.extent.pool.write(level.key, np.zeros(level.key.shape + (level.key.n,)))
            self._cached = cached
        return beta

    @ti.kernel
    def _distinctness(self, i: ti.template(), cost: ti.template()):
        """q of every patch centre of level ``i`` from its matching-cost curve (the cost
        volumes do not change during a solve: computed once per set-up)."""
        width = self.extent.width()
        for y, blk in ti.ndrange(*ti.static(self.hierarchy.bucket_blocks)):
            if y < self.extent.height() and blk < self.hierarchy.image_blocks_now():
                for lane in range(self.lanes):
                    x = blk * self.lanes + lane
                    q = 0.0
                    if x < width:
                        best, _, second, total = curve_minima(cost, y, x, self.C, 1e30)
                        mean = total / self.C
                        r = 1.0
                        if mean > best:
                            r = ti.min((mean - ti.min(second, mean)) / (mean - best), 1.0)
                        q = ti.min(ti.max((1.0 - r) / self.ambiguity, 0.0), 1.0)
                    self.distinct[i][y, blk][lane] = q

    @ti.kernel
    def _all_levels(self, beta: ti.f32, use_validity: ti.i32, keep: ti.template()):
        """:meth:`_level` for every level, in one launch."""
        self.levels_func(beta, use_validity, keep)

    @ti.func
    def levels_func(self, beta, use_validity, keep: ti.template()):
        """:meth:`_level` for every level (for a kernel that runs it with other stages)."""
        for i in ti.static(range(len(self.levels))):
            self._level(self.levels[i], beta, use_validity, keep)
