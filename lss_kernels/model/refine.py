"""Surface plus parallax inside each layer: the left-view disparity of the two quadratics
(Sec. 2) refined by a residual that each layer estimates from its own pixels.

The paper (Sec. 4) notes that one quadratic per layer cannot describe every object or
background, and points to a surface-plus-parallax model.  Here each layer's disparity is its
rendered surface S (the z-buffered ``2 Theta_j`` of :mod:`lss_kernels.model.occlusion`) plus
a smooth residual r, found after the alternation (the occlusion geometry, delta_theta, keeps
the quadratics):

1. a plane sweep in the left view: for every integer disparity d, the AD-Census matching
   cost of :mod:`lss_kernels.model.matching` (left pixel x against right pixel x - d) is
   averaged over a ``(2 window + 1)^2`` box **restricted to the pixel's own layer** (a
   foreground pixel averages foreground pixels only, so a window never straddles the
   boundary), and stored for the candidates ``round(S) - range .. round(S) + range``;
2. per pixel, the best candidate, refined to the vertex of the parabola through it and its
   two neighbours, is kept as a match when it is distinct (its cost below ``ratio`` times
   that of the best candidate that is not its neighbour: the peak-ratio test, which rejects
   flat and periodic cost curves) and not at the edge of the range; occluded pixels (seen by
   one camera only) and candidates whose right pixel leaves the image are no evidence;
3. the residual of the matches, ``match - S``, is averaged over a box of ``smoothing``
   pixels (plus a twentieth of a box four times wider, which fills larger holes) restricted
   to the layer, and added to S.  Where fewer than a fraction ``support`` of the box's layer
   pixels hold a match, the average is shrunk towards 0 in proportion (as if the missing
   matches said "no residual"): a textureless or dark region passes the peak-ratio test only
   on a few noise matches, whose average would otherwise replace a correct surface.

The result of a pass is the surface of the next: a wide first pass follows a layer far from
its quadratic, a narrow second one settles the detail.  Box sums run as prefix sums along
rows, then columns: a few operations per pixel whatever the window.
"""
import taichi as ti

from ..kernels.curves import curve_minima, parabola_vertex
from ..params import REFINE_RATIO, REFINE_SUPPORT
from .matching import MatchingCost

__all__ = ["LayerRefinement", "NO_COST"]

#: Cost stored for a candidate that has none (right pixel outside the image, or outside the
#: candidate range of the pixel).
NO_COST = 1e9
#: Weight of the wide box in the residual's average (pass smoothing times four).
WIDE_WEIGHT = 0.05


@ti.data_oriented
class LayerRefinement:
    """Owns the plane sweep's cost store and the residual's planes for ``(H, W)`` images.

    Parameters
    ----------
    pool : FieldPool
    height, width : int
    passes : tuple of ``(range, window, smoothing)``
        Candidate half-range around the surface (left-view pixels), the half-side of the
        layer-restricted matching window and of the residual's box, per pass.
    ratio : float
        Peak-ratio threshold of a distinct match (in (0, 1]; :data:`~lss_kernels.params.
        REFINE_RATIO`).
    support : float
        Fraction of a box's layer pixels that must hold a distinct match for the box's
        average residual to count fully (in [0, 1]; 0: any match counts fully;
        :data:`~lss_kernels.params.REFINE_SUPPORT`).

    After :meth:`run`, ``surface`` holds the refined map and ``weight`` 1 on the pixels
    whose last pass kept a distinct match of their own (the others took their layer's
    average from their neighbours); ``match`` their match (left-view disparity; the
    surface elsewhere) and ``peak_ratio`` every pixel's best cost over its second best
    (step 2's test; 1 where no second candidate has a cost or both costs are 0), the
    largest of the passes: the wide first pass sees a period that the narrow last one
    cannot.  :mod:`lss_kernels.confidence` reads them.  The planes have the shape of the
    image's size bucket and the kernels read ``H`` and ``W`` at run time from the pool's
    :class:`~lss_kernels.kernels.backend.Extent`: they compile once per bucket.
    """

    def __init__(self, pool, height, width, passes, ratio=REFINE_RATIO,
                 support=REFINE_SUPPORT):
        self.H, self.W = int(height), int(width)
        self.extent = pool.extent(self.H, self.W)
        self.passes = tuple(tuple(int(v) for v in p) for p in passes)
        self.ratio = float(ratio)
        self.support = float(support)
        self.K = 2 * max(p[0] for p in self.passes) + 1
        shape = self.extent.bucket
        field = lambda dtype, shape: pool.field(dtype, shape, bucket=True)
        vector = lambda: pool.vector(4, ti.f32, shape, bucket=True)
        self.matching = MatchingCost(pool, self.H, self.W, "ad_census")
        self.label = field(ti.i32, shape)          # 0 foreground, 1 background
        self.visible = field(ti.i32, shape)        # seen by both cameras
        self.surface = field(ti.f32, shape)
        self.base = field(ti.i32, shape)
        self.span = field(ti.i32, (2,))             # the lowest and highest base
        self.costs = field(ti.f32, shape + (self.K,))
        self.residual = field(ti.f32, shape)
        self.weight = field(ti.f32, shape)
        self.match = field(ti.f32, shape)          # the last pass's best candidate
        self.peak_ratio = field(ti.f32, shape)     # the best over the second, every pass's
        # box sums of a 4-channel source, a value and its weight per layer (value fg,
        # value bg, weight fg, weight bg): its row prefix sums, the column prefix sums of
        # their row boxes, and the residual's average (the sums of both boxes)
        self.source = vector()
        self.prefix = vector()
        self.columns = vector()
        self.average = vector()
        self.count = vector()        # the same boxes' layer pixels (fg, bg, -, -)

    @ti.func
    def _pixels(self):
        """The ``ti.ndrange`` bounds of the image's pixels (``y, x``)."""
        return (0, self.extent.height()), (0, self.extent.width())

    # ------------------------------------------------------------------ box sums
    @ti.func
    def _row_prefix(self):
        """``prefix``: the prefix sums of ``source`` along each row."""
        width = self.extent.width()
        for y in range(self.extent.height()):
            s = ti.Vector([0.0, 0.0, 0.0, 0.0])
            for x in range(width):
                s += self.source[y, x]
                self.prefix[y, x] = s

    @ti.func
    def _column_prefix(self, r):
        """``columns``: the prefix sums down each column of the row boxes (half-width r,
        clamped to the image) that ``prefix`` gives."""
        height, width = self.extent.height(), self.extent.width()
        for x in range(width):
            s = ti.Vector([0.0, 0.0, 0.0, 0.0])
            for y in range(height):
                v = self.prefix[y, ti.min(x + r, width - 1)]
                if x - r - 1 >= 0:
                    v -= self.prefix[y, x - r - 1]
                s += v
                self.columns[y, x] = s

    @ti.func
    def _box(self, y, x, r):
        """The box of half-width r around (y, x), clamped to the image, from ``columns``."""
        v = self.columns[ti.min(y + r, self.extent.height() - 1), x]
        if y - r - 1 >= 0:
            v -= self.columns[y - r - 1, x]
        return v

    @ti.func
    def _accumulate(self, r, weight):
        """``average = weight x box`` for weight 1, ``average += weight x box`` otherwise,
        with ``box`` the sums of ``source`` over the in-image pixels of the
        ``(2 r + 1)^2`` window around each pixel."""
        self._row_prefix()
        self._column_prefix(r)
        for y, x in ti.ndrange(*self._pixels()):
            self.average[y, x] = weight * self._box(y, x, r) + \
                ti.select(weight < 1.0, self.average[y, x], 0.0)

    @ti.func
    def _boxes(self, r, wide):
        """``average``: the box sums of ``source`` over the ``r`` box plus ``wide`` times
        the ``4 r`` box."""
        self._accumulate(r, 1.0)
        self._accumulate(4 * r, wide)

    # ------------------------------------------------------------------ the passes
    @ti.kernel
    def _begin(self, surface: ti.template(), foreground: ti.template(),
               occlusion: ti.template(), d_max: ti.f32, first: ti.i32,
               R: ti.i32) -> ti.types.vector(2, ti.i32):
        """A pass's candidate centres and their span, no costs yet; on the ``first`` pass
        the layers, and the surface clamped to the searched range ``[0, d_max]`` (a
        quadratic can leave it; its candidates would then lie outside the sweep),
        non-finite values as 0.  Returns the span."""
        self.span[0] = 1 << 30
        self.span[1] = -(1 << 30)
        for y, x in ti.ndrange((0, ti.select(first == 1, self.extent.height(), 0)),
                               (0, self.extent.width())):
            s = surface[y, x]
            if not (s >= 0.0 and s <= 3.0e38):
                s = 0.0
            self.surface[y, x] = ti.min(s, d_max)
            self.label[y, x] = 1 - foreground[y, x]
            self.visible[y, x] = 1 - occlusion[y, x]
            self.peak_ratio[y, x] = 0.0
        for y, x in ti.ndrange(*self._pixels()):
            b = ti.cast(ti.round(self.surface[y, x]), ti.i32)
            self.base[y, x] = b
            ti.atomic_min(self.span[0], b)
            ti.atomic_max(self.span[1], b)
            for k in range(2 * R + 1):
                self.costs[y, x, k] = NO_COST
        return ti.Vector([self.span[0], self.span[1]])

    @ti.func
    def _match(self, left: ti.template(), right: ti.template(), y, x, d):
        """The box's source at disparity d: the matching cost and a weight of 1 in the
        pixel's layer's channels, for pixels whose right pixel x - d is in the image."""
        c = 0.0
        inside = x - d >= 0
        if inside:
            c = self.matching.cost(left, right, y, x, x - d)
        fg = inside & (self.label[y, x] == 0)
        bg = inside & (self.label[y, x] == 1)
        return ti.Vector([ti.select(fg, c, 0.0), ti.select(bg, c, 0.0),
                          ti.select(fg, 1.0, 0.0), ti.select(bg, 1.0, 0.0)])

    @ti.kernel
    def _sweep(self, left: ti.template(), right: ti.template(), d: ti.i32, R: ti.i32,
               r: ti.i32):
        """Step 1 at disparity d: the layer-restricted window mean (the box of half-width
        r) for the pixels whose candidate range holds d and whose right pixel is in the
        image."""
        width = self.extent.width()
        for y in range(self.extent.height()):      # row prefix sums of the source at d
            s = ti.Vector([0.0, 0.0, 0.0, 0.0])
            for x in range(width):
                s += self._match(left, right, y, x, d)
                self.prefix[y, x] = s
        self._column_prefix(r)
        for y, x in ti.ndrange(*self._pixels()):
            k = d - self.base[y, x] + R
            if 0 <= k <= 2 * R and x - d >= 0:
                lab = self.label[y, x]
                box = self._box(y, x, r)
                n = box[2 + lab]
                if n > 0:
                    self.costs[y, x, k] = box[lab] / n

    @ti.func
    def _select(self, R, ratio):
        """Per pixel: the distinct, interior best candidate (peak ratio), refined to the
        parabola's vertex; its residual against the surface and its weight (1 or 0)."""
        for y, x in ti.ndrange(*self._pixels()):
            best, kb, second, _ = curve_minima(self.costs, y, x, 2 * R + 1, NO_COST)
            w = 0.0
            r = 0.0
            if 0 < kb < 2 * R and self.visible[y, x] == 1:
                cm = self.costs[y, x, kb - 1]
                cp = self.costs[y, x, kb + 1]
                if cm < NO_COST and cp < NO_COST and best < ratio * second:
                    sub = parabola_vertex(cm, best, cp, 0.0)
                    r = ti.cast(self.base[y, x] + kb - R, ti.f32) + sub - self.surface[y, x]
                    w = 1.0
            self.residual[y, x] = r
            self.weight[y, x] = w
            self.match[y, x] = r + self.surface[y, x]
            ratio_here = 1.0                       # flat: no second cost, or both 0
            if second < NO_COST and second > 0:
                ratio_here = best / second
            self.peak_ratio[y, x] = ti.max(self.peak_ratio[y, x], ratio_here)

    @ti.kernel
    def _finish(self, R: ti.i32, ratio: ti.f32, r: ti.i32, wide: ti.f32, d_max: ti.f32,
                support: ti.f32):
        """Steps 2 and 3 of a pass: the matches (:meth:`_select`); ``count``, the layer
        pixels of each pixel's boxes of half-side ``r`` (plus ``wide`` times the ``4 r``
        box); ``average``, the same boxes' layer-restricted sums of the weighted residual
        and of the weights; the surface plus the average residual, clamped to [0, d_max]."""
        self._select(R, ratio)
        for y, x in ti.ndrange(*self._pixels()):
            fg = self.label[y, x] == 0
            self.source[y, x] = ti.Vector([ti.select(fg, 1.0, 0.0), ti.select(fg, 0.0, 1.0),
                                           0.0, 0.0])
        self._boxes(r, wide)
        for y, x in ti.ndrange(*self._pixels()):
            self.count[y, x] = self.average[y, x]
            w = self.weight[y, x]
            fg = self.label[y, x] == 0
            v = w * self.residual[y, x]
            self.source[y, x] = ti.Vector([ti.select(fg, v, 0.0), ti.select(fg, 0.0, v),
                                           ti.select(fg, w, 0.0), ti.select(fg, 0.0, w)])
        self._boxes(r, wide)
        for y, x in ti.ndrange(*self._pixels()):
            lab = self.label[y, x]
            den = ti.max(self.average[y, x][2 + lab], support * self.count[y, x][lab])
            s = self.surface[y, x]
            if den > 0:
                s += self.average[y, x][lab] / den
            self.surface[y, x] = ti.min(ti.max(s, 0.0), d_max)

    def run(self, left, right, surface, foreground, occlusion, d_max):
        """Refine the left-view ``surface`` (f32 plane; clamped to ``[0, d_max]`` first) of
        the layers ``foreground`` (i32, 1 on the foreground) with ``occlusion`` (i32, 1
        where the right camera cannot see);
        ``left``, ``right``: RGB vector fields in [0, 1].  The refined map is left in
        ``surface``."""
        self.matching.setup(left, right)
        for i, (R, window, smoothing) in enumerate(self.passes):
            low, high = (int(v) for v in self._begin(surface, foreground, occlusion,
                                                     float(d_max), int(i == 0), R))
            for d in range(max(low - R, 0), min(high + R, int(d_max)) + 1):
                self._sweep(left, right, d, R, window)
            self._finish(R, self.ratio, smoothing, WIDE_WEIGHT, float(d_max), self.support)
