"""The cooperative patch hierarchy: upward messages and validity, downward consensus.

Sec. 3 of the paper, after Chakrabarti et al. (2015): levels of dense, overlapping square
patches, one patch centred on every pixel at every level, where a patch at level ``l`` is the
union of ``r x r`` non-overlapping patches of level ``l - 1`` (``r = s_l / s_{l-1}``; level 0
is the pixels).  Everything a patch needs is relayed between parents and children:

* **upward**: the patch-mean matching cost C_p(c) (once, at set-up), the patch mean of the
  current disparity D, and the extremes of phi and phi(x + delta_theta) that decide the
  validity w_p (Eq. 4);
* **messages** (Eqs. 4, 5; :mod:`lss_kernels.model.messages`): w_p, d_p and sigma_p of every
  patch from what the upward pass brought it, seeding the downward relays;
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

__all__ = ["Level", "PatchHierarchy", "PatchLevel", "level_geometry"]


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
class PatchLevel:
    """One level of the hierarchy: its geometry (see :class:`Level`) and every field its
    patches own, one entry per patch centre (the in-image centres, and the margins that the
    relays reach).

    ``cost``: the normalised patch-mean matching cost C_p(c), ``(H + 2m, W + 2m, c_max)``.
    Upward relays (lane planes): ``d_sum`` (sum of D over the patch), ``phi_max`` and
    ``phi_plus_min`` (the extremes of phi and phi(x + delta_theta) that decide w_p, Eq. 4).
    Downward relays: ``relay_a`` and ``relay_b`` (sums of w / sigma^2 and w d / sigma^2 over the
    patches of this level and above that contain the centre, Eq. 7).  The message cache of
    :mod:`lss_kernels.model.messages` (``key``, ``below``, ``above``, ``d_below``,
    ``d_above``; lane planes over the in-image centres), and ``d_p``, ``sigma_p``, ``valid``
    (``(H, W)``, written only on request).
    """

    def __init__(self, pool, geometry, span, height, width, c_max, lanes_per_block, index):
        self.size, self.half = geometry.size, geometry.half
        self.offsets, self.margin = geometry.offsets, geometry.margin
        self.span, self.index = span, index
        H, W, C, L, m = height, width, c_max, lanes_per_block, geometry.margin
        # Level 1 is also M of the Eq. 2 step, read at Theta_j per pixel: rows, disparities,
        # columns in memory; the patch levels are scanned along c per patch (messages)
        self.cost = pool.field(ti.f32, (H + 2 * m, W + 2 * m, C), offset=(-m, -m, 0),
                               order=ROWS_DISPARITIES_COLUMNS if index == 0 else None,
                               volume=True)

        def relay():
            left, right = span
            return pool.vector(L, ti.f32, (H + 2 * m, (left + right) // L),
                               offset=(-m, -left // L))

        def cache(dtype=ti.f32):
            return pool.vector(L, dtype, (H, lanes.block_count(W, L)))

        self.d_sum, self.phi_max, self.phi_plus_min = relay(), relay(), relay()
        self.relay_a, self.relay_b = relay(), relay()
        self.key = cache(ti.i32)
        self.below, self.above, self.d_below, self.d_above = (cache() for _ in range(4))
        self.d_p = pool.field(ti.f32, (H, W))
        self.sigma_p = pool.field(ti.f32, (H, W))
        self.valid = pool.field(ti.i32, (H, W))
        self._image_rows = (m, m + H)
        self._image_columns = (span[0], span[0] + W)

    def image(self, plane):
        """The in-image patch centres of one of this level's lane planes (``d_sum``,
        ``phi_max``, ``phi_plus_min``, ``relay_a``, ``relay_b``) as a float32 ``(H, W)``
        array."""
        rows = plane.to_numpy()
        rows = rows.reshape(rows.shape[0], -1)
        (r0, r1), (c0, c1) = self._image_rows, self._image_columns
        return np.ascontiguousarray(rows[r0:r1, c0:c1], dtype=np.float32)

    def __repr__(self):
        return f"PatchLevel(size={self.size}, offsets={self.offsets}, margin={self.margin})"


@ti.data_oriented
class PatchHierarchy:
    """The levels' fields and the kernels of the upward and downward passes; the consensus.

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

    Attributes
    ----------
    levels : list of PatchLevel
        From the smallest patches up.
    precision, consensus_mean : ``(H, W)`` fields
        The consensus (Eq. 7): 1 / sigma^2 and d-bar (cyclopean units; 0 where no valid patch
        contains the pixel).
    """

    def __init__(self, pool, height, width, c_max, sizes):
        self.H, self.W, self.C = int(height), int(width), int(c_max)
        H, W, C = self.H, self.W, self.C
        # the per-iteration relays are lane planes (blocks of ``lanes`` patch centres along
        # x; see :mod:`lss_kernels.kernels.lanes`): the upward and downward stencils run a
        # block per loop index.  Columns -left .. right - 1 of :func:`column_spans`
        self.lanes = lanes.lanes_for_arch()
        self.image_blocks = lanes.block_count(W, self.lanes)
        geometry = level_geometry(sizes)
        spans = column_spans(geometry, W, self.lanes)
        self.levels = [PatchLevel(pool, g, span, H, W, C, self.lanes, i)
                       for i, (g, span) in enumerate(zip(geometry, spans))]
        self.precision = pool.field(ti.f32, (H, W))       # 1 / sigma^2
        self.consensus_mean = pool.field(ti.f32, (H, W))  # d-bar, cyclopean units
        self._lo = pool.field(ti.f32, ())
        self._hi = pool.field(ti.f32, ())
        self.curve = pool.field(ti.f32, (C,), volume=True)
        #: How many times the cost volumes were built (the message cache depends on them).
        self.cost_version = 0

    @property
    def matching_cost(self):
        """Level 1's C_p(c), ``(H, W, c_max)`` (and margins): the size-3 matching cost M that
        the Eq. 2 step reads at Theta_1 and Theta_2."""
        return self.levels[0].cost

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
    def _cost_from_pixels(self, matcher: ti.template(), left: ti.template(),
                          right: ti.template(), dst: ti.template(), offs: ti.template()):
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
                    total += matcher.cost(left, right, py, xl, xr)
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

    def build_costs(self, matcher, left, right):
        """Fill every level's C_p(c) (patch mean of M, min-max normalised per level).

        ``left``, ``right``: ``ti.Vector.field(3, f32)`` of shape ``(H, W)``, values in [0, 1];
        ``matcher``: a :class:`lss_kernels.model.matching.MatchingCost` whose ``setup`` ran.
        Level 1 sums the pixels' matching costs M(x, y, c) of L(x + c) against R(x - c)
        (image coordinates clamped at the borders); each higher level sums its children.
        """
        first = self.levels[0]
        self._cost_from_pixels(matcher, left, right, first.cost, first.offsets)
        for child, level in zip(self.levels, self.levels[1:]):
            self._cost_from_children(child.cost, child.size, level.cost, level.offsets)
        for level in self.levels:
            self._normalise(level.cost)
        self.cost_version += 1

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
                        level: ti.template()):
        """Level 1 from the pixels, a block of patch centres at a time: each row of the
        patches reads its window of the three planes once (out-of-image pixels as the
        neutral 0, -1e30, +1e30, the old starting values: every patch sums and compares in the
        same order)."""
        L = ti.static(self.lanes)
        offs = ti.static(level.offsets)
        lo = ti.static(offs[0])                 # the offsets ascend
        hi = ti.static(offs[len(offs) - 1])
        for y, b in level.d_sum:
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
            level.d_sum[y, b] = s
            level.phi_max[y, b] = most
            level.phi_plus_min[y, b] = least

    @ti.func
    def _up_from_children(self, child: ti.template(), level: ti.template()):
        L = ti.static(self.lanes)
        offs = ti.static(level.offsets)
        for y, b in level.d_sum:
            s = ti.Vector.zero(ti.f32, L)
            most = ti.Vector([-1e30] * L)
            least = ti.Vector([1e30] * L)
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                cy = y + offs[jy]
                s += self._shifted(child.d_sum, cy, b, offs[jx], ())
                most = ti.max(most, self._shifted(child.phi_max, cy, b, offs[jx], ()))
                least = ti.min(least, self._shifted(child.phi_plus_min, cy, b, offs[jx], ()))
            level.d_sum[y, b] = s
            level.phi_max[y, b] = most
            level.phi_plus_min[y, b] = least

    @ti.kernel
    def upward(self, D: ti.template(), phi: ti.template(), phi_plus: ti.template()):
        """Relay the patch sums of D and the patch extremes of phi and phi(x + delta_theta)
        from the pixels up through every level (inputs: ``(H, W)`` f32 fields).  One launch:
        the levels' loops run in order."""
        self._up_from_pixels(D, phi, phi_plus, self.levels[0])
        for i in ti.static(range(1, len(self.levels))):
            self._up_from_children(self.levels[i - 1], self.levels[i])

    # ------------------------------------------------------------------ downward (Eq. 7)
    @ti.func
    def _down(self, level: ti.template(), parent: ti.template()):
        """A level's relays += its parents', a block of patch centres at a time; its own
        messages count only at in-image centres (the rest of the plane holds last
        iteration's relays)."""
        H, W = self.H, self.W
        L = ti.static(self.lanes)
        relay_a, relay_b = ti.static(level.relay_a, level.relay_b)
        parent_offs, parent_margin = ti.static(parent.offsets, parent.margin)
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
                        a += self._shifted(parent.relay_a, py, b, -parent_offs[jx], parent.span)
                        c += self._shifted(parent.relay_b, py, b, -parent_offs[jx], parent.span)
            relay_a[y, b] = a
            relay_b[y, b] = c

    @ti.func
    def _to_pixels(self, level: ti.template()):
        L = ti.static(self.lanes)
        offs = ti.static(level.offsets)
        for y, b in ti.ndrange(self.H, self.image_blocks):
            a = ti.Vector.zero(ti.f32, L)
            c = ti.Vector.zero(ti.f32, L)
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                a += self._shifted(level.relay_a, y - offs[jy], b, -offs[jx], ())
                c += self._shifted(level.relay_b, y - offs[jy], b, -offs[jx], ())
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
            self._down(self.levels[i], self.levels[i + 1])
        self._to_pixels(self.levels[0])

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
        self._read_curve(self.levels[level].cost, int(y), int(x))
        return self.curve.to_numpy()
