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

Planes and volumes have the shape of the image's size bucket (and margins), and most kernels
read ``H`` and ``W`` at run time from the pool's :class:`~lss_kernels.kernels.backend.Extent`,
so they compile once per bucket.  Two compile once per image size, with the size's constants
and its own shapes: the upward pass (:meth:`PatchHierarchy.upward`) and the set-up's sums of
children (:meth:`PatchHierarchy._cost_from_children`).  Taichi compiles with LLVM's fast-math
reassociation, which orders a sum of many terms by how their addresses are computed: the
same code with run-time sizes, or over planes of the bucket's strides, sums their patches in
other orders at some sizes (a few ulp), and the results must stay those of kernels compiled
for one size.
"""
import numpy as np
import taichi as ti

from ..kernels import lanes
from ..kernels.backend import ROWS_DISPARITIES_COLUMNS
from .patches import Level, column_spans, level_geometry

__all__ = ["Level", "PatchHierarchy", "PatchLevel", "level_geometry"]


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

    Every field has the shape of the image's size bucket (``extent.bucket``) with its
    margins; the relays' columns are ``span`` (:func:`column_spans` of the image's width)
    within ``bucket_span`` (of the bucket's).  ``columns``: ``span`` in blocks, as the blocks
    left of the image and those past its last block: both are the bucket's too, so kernels
    find the span at run time from the image's blocks.  ``domain``: the relays' patch
    centres of the image's size in a plane of that shape, what the upward pass loops over.
    """

    def __init__(self, pool, geometry, span, bucket_span, extent, c_max, lanes_per_block,
                 index):
        self.size, self.half = geometry.size, geometry.half
        self.offsets, self.margin = geometry.offsets, geometry.margin
        self.span, self.index = span, index
        (H, W), C, L, m = extent.bucket, c_max, lanes_per_block, geometry.margin
        past = lambda sp, width: (sp[1] - lanes.block_count(width, L) * L) // L
        self.columns = (span[0] // L, past(span, extent.W))
        assert self.columns == (bucket_span[0] // L, past(bucket_span, W))
        span = bucket_span
        # Level 1 is also M of the Eq. 2 step, read at Theta_j per pixel: rows, disparities,
        # columns in memory; the patch levels are scanned along c per patch (messages)
        self.cost = pool.field(ti.f32, (H + 2 * m, W + 2 * m, C), offset=(-m, -m, 0),
                               order=ROWS_DISPARITIES_COLUMNS if index == 0 else None,
                               volume=True)

        def relay():
            left, right = span
            return pool.vector(L, ti.f32, (H + 2 * m, (left + right) // L),
                               offset=(-m, -left // L), bucket=True)

        def cache(dtype=ti.f32):
            return pool.vector(L, dtype, (H, lanes.block_count(W, L)), bucket=True)

        self.d_sum, self.phi_max, self.phi_plus_min = relay(), relay(), relay()
        self.relay_a, self.relay_b = relay(), relay()
        self.key = cache(ti.i32)
        self.below, self.above, self.d_below, self.d_above = (cache() for _ in range(4))
        self.d_p = pool.field(ti.f32, (H, W), bucket=True)
        self.sigma_p = pool.field(ti.f32, (H, W), bucket=True)
        self.valid = pool.field(ti.i32, (H, W), bucket=True)
        self._image_rows = (m, m + extent.H)
        self._image_columns = (span[0], span[0] + extent.W)
        left, right = self.span
        self.domain = pool.field(ti.u8, (extent.H + 2 * m, (left + right) // L),
                                 offset=(-m, -left // L))

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
        self.extent = pool.extent(self.H, self.W)
        (H, W), C = self.extent.bucket, self.C
        # the per-iteration relays are lane planes (blocks of ``lanes`` patch centres along
        # x; see :mod:`lss_kernels.kernels.lanes`): the upward and downward stencils run a
        # block per loop index.  Columns -left .. right - 1 of :func:`column_spans`
        self.lanes = lanes.lanes_for_arch()
        self.image_blocks = lanes.block_count(self.W, self.lanes)
        # the pixels' blocks of the bucket: loops over the image's blocks run over these and
        # skip the rest (compile-time bounds: no run-time division per index)
        self.bucket_blocks = (H, lanes.block_count(W, self.lanes))
        geometry = level_geometry(sizes)
        spans = zip(column_spans(geometry, self.W, self.lanes),
                    column_spans(geometry, W, self.lanes))
        self.levels = [PatchLevel(pool, g, span, bucket_span, self.extent, C, self.lanes, i)
                       for i, (g, (span, bucket_span)) in enumerate(zip(geometry, spans))]
        # the upward pass's copies of D, phi and phi(x + delta_theta), in the size's own shape
        self._upward_planes = [pool.field(ti.f32, (self.H, self.W)) for _ in range(3)]
        self.precision = pool.field(ti.f32, (H, W), bucket=True)       # 1 / sigma^2
        self.consensus_mean = pool.field(ti.f32, (H, W), bucket=True)  # d-bar, cyclopean
        self._lo = pool.field(ti.f32, (), bucket=True)
        self._hi = pool.field(ti.f32, (), bucket=True)
        self.curve = pool.field(ti.f32, (C,), volume=True)
        # the pixels' M while level 1 is built from it: the top level's volume (built last,
        # from its children), a volume of its own when level 1 is the only level
        self._pixel_cost = (self.levels[-1].cost if len(self.levels) > 1 else
                            pool.field(ti.f32, (H, W, C), volume=True))
        #: How many times the cost volumes were built (the message cache depends on them).
        self.cost_version = 0

    @property
    def matching_cost(self):
        """Level 1's C_p(c), ``(H, W, c_max)`` (and margins): the size-3 matching cost M that
        the Eq. 2 step reads at Theta_1 and Theta_2."""
        return self.levels[0].cost

    # ------------------------------------------------------------------ set-up (upward costs)
    @ti.func
    def _in_image_count(self, size: ti.template(), y, x, height, width):
        """In-image pixels of the patch of side ``size`` centred on (y, x) (``x`` may be a
        vector of centres): its square ``[c - size // 2, c - size // 2 + size - 1]`` per axis,
        clipped to the image; 0 for a patch wholly outside.  A parent's count is the sum of
        its children's, since the children tile it."""
        h = ti.static(size // 2)
        rows = ti.max(ti.min(y - h + size - 1, height - 1) - ti.max(y - h, 0) + 1, 0)
        cols = ti.max(ti.min(x - h + size - 1, width - 1) - ti.max(x - h, 0) + 1, 0)
        return rows * cols

    @ti.func
    def image_blocks_now(self):
        """Blocks of lanes that cover a row of the image (run time)."""
        return (self.extent.width() + self.lanes - 1) // self.lanes

    @ti.func
    def _volume(self, level: ti.template()):
        """The ``ti.ndrange`` bounds of a level's volume, its margins included (``y, x,
        k``)."""
        m = ti.static(level.margin)
        H, W = self.extent.height(), self.extent.width()
        return (-m, H + m), (-m, W + m), (0, self.C)

    @ti.func
    def _size(self, fixed: ti.template()):
        """The image's ``(H, W, blocks)``: read at run time, or with ``fixed`` the
        compile-time constants of this size (the kernel then compiles once per size)."""
        if ti.static(fixed):
            return ti.static(self.H, self.W, self.image_blocks)
        else:
            return self.extent.height(), self.extent.width(), self.image_blocks_now()

    @ti.func
    def _pixel_costs(self, matcher: ti.template(), left: ti.template(),
                     right: ti.template(), scratch: ti.template()):
        """M(x, y, c) of every in-image pixel and candidate into ``scratch`` (a volume that
        holds ``[0, H) x [0, W) x c_max``), once: each is read by the 9 patches of level 1
        that contain the pixel."""
        H, W = self.extent.height(), self.extent.width()
        for y, x, k in ti.ndrange(H, W, self.C):
            c = k + 1
            scratch[y, x, k] = matcher.cost(left, right, y, ti.min(x + c, W - 1),
                                            ti.max(x - c, 0))

    @ti.func
    def _cost_from_pixels(self, pixels: ti.template(), level: ti.template()):
        """Level 1's volume (in its memory order: rows, disparities, columns) from the
        pixels' M in ``pixels`` (:meth:`_pixel_costs`)."""
        H, W = self.extent.height(), self.extent.width()
        dst, offs, m = ti.static(level.cost, level.offsets, level.margin)
        for y, k, x in ti.ndrange((-m, H + m), self.C, (-m, W + m)):
            total = 0.0
            n = 0
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                py = y + offs[jy]
                px = x + offs[jx]
                if 0 <= py < H and 0 <= px < W:
                    total += pixels[py, px, k]
                    n += 1
            dst[y, x, k] = total / ti.max(n, 1)

    @ti.func
    def _cost_from_children(self, child: ti.template(), level: ti.template()):
        """A level's volume from its children's (per image size: the counts are the size's
        constants; see the module).  Its bucket's patches past the image's margins get
        values that nothing reads."""
        src, child_size = ti.static(child.cost, child.size)
        dst, offs = ti.static(level.cost, level.offsets)
        for y, x, k in dst:
            total = 0.0
            n = 0
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                cy = y + offs[jy]
                cx = x + offs[jx]
                m = self._in_image_count(child_size, cy, cx, self.H, self.W)
                total += src[cy, cx, k] * m
                n += m
            dst[y, x, k] = total / ti.max(n, 1)

    @ti.func
    def _normalise(self, level: ti.template()):
        """Min-max normalise a level's volume to [0, 1] over its in-image patches."""
        vol = ti.static(level.cost)
        self._lo[None] = 1e30
        self._hi[None] = -1e30
        for y, x in ti.ndrange(self.extent.height(), self.extent.width()):
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
        for y, x, k in ti.ndrange(*self._volume(level)):
            vol[y, x, k] = (vol[y, x, k] - lo) * scale

    def build_costs(self, matcher, left, right):
        """Fill every level's C_p(c) (patch mean of M, min-max normalised per level).

        ``left``, ``right``: ``ti.Vector.field(3, f32)`` of shape ``(H, W)``, values in [0, 1];
        ``matcher``: a :class:`lss_kernels.model.matching.MatchingCost` whose ``setup`` ran.
        Level 1 sums the pixels' matching costs M(x, y, c) of L(x + c) against R(x - c)
        (image coordinates clamped at the borders); each higher level sums its children.
        """
        self._build_costs(matcher, left, right)
        self.cost_version += 1

    @ti.kernel
    def _build_costs(self, matcher: ti.template(), left: ti.template(), right: ti.template()):
        """Every level's volume in one launch: the pixels' M, level 1 from them, each higher
        level from its children, then each normalised."""
        self._pixel_costs(matcher, left, right, self._pixel_cost)
        self._cost_from_pixels(self._pixel_cost, self.levels[0])
        for i in ti.static(range(1, len(self.levels))):
            self._cost_from_children(self.levels[i - 1], self.levels[i])
        for i in ti.static(range(len(self.levels))):
            self._normalise(self.levels[i])

    # ------------------------------------------------------------------ upward, per iteration
    @ti.func
    def _shifted(self, plane: ti.template(), y: ti.template(), b: ti.template(),
                 o: ti.template(), span: ti.template(), blocks: ti.template()):
        """Centres ``b L + o .. b L + o + L - 1`` of row ``y`` of a level's lane plane (``o``
        a compile-time offset): one or two whole blocks, their lanes moved by ``o mod L``.
        With a ``span`` (a parent's ``columns``, which end before its child's; ``()``:
        none), blocks outside it read as zeros: no patch there relays anything.  The
        indices are templates, not copied at each of its hundreds of inlined calls."""
        q, r = ti.static(divmod(o, self.lanes))
        value = self._block(plane, y, b + q, span, blocks)
        if ti.static(r != 0):
            value = self._merge_lanes(value, self._block(plane, y, b + q + 1, span, blocks), r)
        return value

    @ti.func
    def _block(self, plane: ti.template(), y, b, span: ti.template(), blocks):
        """Block ``b`` of row ``y``; with a ``span`` (not ``()``), zeros outside its
        columns (``blocks``: the image's blocks of a row)."""
        if ti.static(len(span) == 0):
            value = plane[y, b]
            return value
        else:
            value = ti.Vector.zero(ti.f32, self.lanes)
            if -ti.static(span[0]) <= b < blocks + ti.static(span[1]):
                value = plane[y, b]
            return value

    @ti.func
    def _merge_lanes(self, first: ti.template(), second: ti.template(), r: ti.template()):
        """Lanes ``r .. L - 1`` of ``first`` followed by lanes ``0 .. r - 1`` of
        ``second`` (templates, not copies, read lane by lane without a list of the two to
        index: the front end visits a third of the nodes)."""
        L = ti.static(self.lanes)
        return ti.Vector([first[l] for l in ti.static(range(r, L))]
                         + [second[l] for l in ti.static(range(r))])

    @ti.func
    def _window(self, src: ti.template(), y, x0, lo: ti.template(), hi: ti.template(),
                fill, width):
        """Pixels ``x0 + lo .. x0 + L - 1 + hi`` of row ``y`` of a plain ``(H, W)`` plane as a
        vector, ``fill`` for those outside the image (unclamped reads away from the
        borders; a run-time loop near them)."""
        n = ti.static(self.lanes + hi - lo)
        window = ti.Vector.zero(ti.f32, n)
        if 0 <= x0 + lo and x0 + n + lo <= width:
            for k in ti.static(range(n)):
                window[k] = src[y, x0 + lo + k]
        else:
            for k in range(n):
                window[k] = fill
                x = x0 + lo + k
                if 0 <= x < width:
                    window[k] = src[y, x]
        return window

    @ti.func
    def _up_from_pixels(self, D: ti.template(), phi: ti.template(), phi_plus: ti.template(),
                        level: ti.template(), fixed: ti.template()):
        """Level 1 from the pixels, a block of patch centres at a time: each row of the
        patches reads its window of the three planes once (out-of-image pixels as the
        neutral 0, -1e30, +1e30, the old starting values: every patch sums and compares in the
        same order)."""
        L = ti.static(self.lanes)
        offs = ti.static(level.offsets)
        lo = ti.static(offs[0])                 # the offsets ascend
        hi = ti.static(offs[len(offs) - 1])
        height, width, _ = self._size(fixed)
        for y, b in level.domain:
            x0 = b * L
            s = ti.Vector.zero(ti.f32, L)
            most = ti.Vector([-1e30] * L)
            least = ti.Vector([1e30] * L)
            for jy in ti.static(range(len(offs))):
                py = y + offs[jy]
                if 0 <= py < height:
                    wd = self._window(D, py, x0, lo, hi, 0.0, width)
                    wp = self._window(phi, py, x0, lo, hi, -1e30, width)
                    wq = self._window(phi_plus, py, x0, lo, hi, 1e30, width)
                    for jx in ti.static(range(len(offs))):
                        k = ti.static(offs[jx] - lo)
                        s += lanes.take(wd, k, L)
                        most = ti.max(most, lanes.take(wp, k, L))
                        least = ti.min(least, lanes.take(wq, k, L))
            level.d_sum[y, b] = s
            level.phi_max[y, b] = most
            level.phi_plus_min[y, b] = least

    @ti.func
    def _up_from_children(self, child: ti.template(), level: ti.template(),
                          fixed: ti.template()):
        L = ti.static(self.lanes)
        offs = ti.static(level.offsets)
        _, _, blocks = self._size(fixed)
        for y, b in level.domain:
            s = ti.Vector.zero(ti.f32, L)
            most = ti.Vector([-1e30] * L)
            least = ti.Vector([1e30] * L)
            for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                cy = y + offs[jy]
                s += self._shifted(child.d_sum, cy, b, offs[jx], (), blocks)
                most = ti.max(most, self._shifted(child.phi_max, cy, b, offs[jx], (), blocks))
                least = ti.min(least, self._shifted(child.phi_plus_min, cy, b, offs[jx], (),
                                                       blocks))
            level.d_sum[y, b] = s
            level.phi_max[y, b] = most
            level.phi_plus_min[y, b] = least

    @ti.kernel
    def upward(self, D: ti.template(), phi: ti.template(), phi_plus: ti.template()):
        """Relay the patch sums of D and the patch extremes of phi and phi(x + delta_theta)
        from the pixels up through every level (inputs: ``(H, W)`` f32 fields).  One launch:
        the levels' loops run in order.  Per image size (see the module): the three planes
        are first copied into planes of the size's own shape, and the levels' loops run over
        their ``domain``."""
        planes = ti.static(self._upward_planes)
        for y, x in planes[0]:
            planes[0][y, x] = D[y, x]
            planes[1][y, x] = phi[y, x]
            planes[2][y, x] = phi_plus[y, x]
        self._up_from_pixels(planes[0], planes[1], planes[2], self.levels[0], True)
        for i in ti.static(range(1, len(self.levels))):
            self._up_from_children(self.levels[i - 1], self.levels[i], True)

    # ------------------------------------------------------------------ downward (Eq. 7)
    @ti.func
    def _down(self, level: ti.template(), parent: ti.template(), fixed: ti.template()):
        """A level's relays += its parents', a block of patch centres at a time; its own
        messages count only at in-image centres (the rest of the plane holds last
        iteration's relays)."""
        H, W, blocks = self._size(fixed)
        L = ti.static(self.lanes)
        relay_a, relay_b = ti.static(level.relay_a, level.relay_b)
        parent_offs, parent_margin = ti.static(parent.offsets, parent.margin)
        for y, b in relay_a:
            if y < H + ti.static(level.margin) and b < blocks + ti.static(level.columns[1]):
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
                            a += self._shifted(parent.relay_a, py, b, -parent_offs[jx],
                                               parent.columns, blocks)
                            c += self._shifted(parent.relay_b, py, b, -parent_offs[jx],
                                               parent.columns, blocks)
                relay_a[y, b] = a
                relay_b[y, b] = c

    @ti.func
    def _to_pixels(self, level: ti.template(), fixed: ti.template()):
        L = ti.static(self.lanes)
        offs = ti.static(level.offsets)
        height, width, blocks = self._size(fixed)
        for y, b in ti.ndrange(*ti.static(self.bucket_blocks)):
            if y < height and b < blocks:
                a = ti.Vector.zero(ti.f32, L)
                c = ti.Vector.zero(ti.f32, L)
                for jy, jx in ti.static(ti.ndrange(len(offs), len(offs))):
                    a += self._shifted(level.relay_a, y - offs[jy], b, -offs[jx], (), blocks)
                    c += self._shifted(level.relay_b, y - offs[jy], b, -offs[jx], (), blocks)
                for l in ti.static(range(L)):
                    x = b * L + l
                    if x < width:
                        self.precision[y, x] = a[l]
                        self.consensus_mean[y, x] = c[l] / a[l] if a[l] > 0 else 0.0

    @ti.kernel
    def downward(self):
        """Relay the messages down to the pixels: fills ``precision`` (1/sigma^2) and
        ``consensus_mean`` (d-bar; 0 where no valid patch contains the pixel).  One launch:
        the levels' loops run in order, from the top."""
        self.down()

    @ti.func
    def down(self):
        """:meth:`downward`, for a kernel that runs it with other stages."""
        # the top level has no parent: its relay is just its own messages
        for i in ti.static(range(len(self.levels) - 2, -1, -1)):
            self._down(self.levels[i], self.levels[i + 1], False)
        self._to_pixels(self.levels[0], False)

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
