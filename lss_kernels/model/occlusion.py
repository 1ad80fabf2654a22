"""Occlusion geometry: delta_theta (the ray cast of Sec. 2), the visible background, and the
rendering of the two-layer model into the left view.

delta_theta(x, y): cast a ray in x-d space from (x, Theta_1(x, y)) towards decreasing
disparity with slope s = sign(d phi / dx), i.e. through the points (x - s t, Theta_1 - t); it
meets the background surface where ``t = Theta_1(x, y) - Theta_2(x - s t, y)`` and
``delta_theta = x - x' = s t``: the occluded extent equals the disparity jump (cyclopean
units), to the left of a left boundary (s = +1) and to the right of a right boundary.  The
root is found by fixed-point iteration started at the jump at x (``FIXED_POINT_STEPS`` steps,
left early once a step returns its input, which the remaining steps would repeat; a block of
pixels in SIMD lanes steps until every lane has), which
converges whenever |dTheta_2/dx| < 1 (any physical surface); with a fronto-parallel
background it is exact after one step, and the authors' release uses that first step,
``Theta_1 - Theta_2``.  No jump (Theta_1 <= Theta_2) or no slope: delta_theta = 0.

A background pixel is visible (Eq. 1, second term) when phi(x) < 0 and phi(x + delta_theta) < 0.

Left view (Middlebury convention, x_left = x_c + c): a left pixel is foreground when the
foreground surface point that projects there, x_c with x_c + Theta_1(x_c) = x, has
phi(x_c) > 0; otherwise it sees the background at x_c with x_c + Theta_2(x_c) = x.  Its
disparity is 2 Theta of that layer, and a background pixel is occluded (seen by the left
camera, hidden from the right) when the right camera, at x - d, sees the foreground (a z-buffer
with two layers: the foreground is always in front).  The foreground point it would see lies
at x_l in the left view, and the left pixel nearest x_l is asked whether it is foreground: so
the occluded strip is as wide as the rendered jump in whole pixels, and a whole-pixel jump
does not lose or gain a pixel to float rounding.

The strips measured against the refined background (:meth:`OcclusionGeometry.measure_strips`,
after :mod:`lss_kernels.model.refine`): a strip is as wide as the jump from the foreground at
its edge to the background where the right camera sees it again, at the strip's far end.  The
quadratic Theta_2 is one surface for the whole background, and near the object a box, a shelf
or a floor can lie pixels away from it; the refined disparity of the visible background just
beyond the strip says where.  Each run of foreground pixels of a row that starts at ``a``
takes ``t = S(a) - (S(x0) + r)``, with ``S`` the model's left-view disparity, ``x0 =
floor(a - t - 1/2)`` the first background pixel seen again, and ``r`` the median of the
refined minus the model's disparity over the background pixels from ``far`` to ``near``
pixels left of ``x0`` that hold a distinct match of their own (near enough to follow a local
surface, far enough from the strip's end, where the refinement's windows mix the layers;
``r = 0`` with fewer than ``STRIP_EVIDENCE`` of them: a background without matches, dark or
weakly textured, keeps its quadratic, which the refinement only fills from afar); a fixed
point from the model's jump, as the ray cast.  The run's
footprint in the right view bounds the strip on the right (a short run hides no more than
its own length), as the z-buffer does.
"""
import taichi as ti

from ..kernels import lanes
from . import FIXED_POINT_STEPS

__all__ = ["OcclusionGeometry", "STRIP_EVIDENCE"]

#: The fewest matched background pixels in a strip's window that re-measure its jump.
STRIP_EVIDENCE = 3



@ti.data_oriented
class OcclusionGeometry:
    """Owns delta_theta, phi(x + delta_theta) and the left-view outputs: planes of the
    image's size bucket, whose ``H x W`` region the kernels fill (``H`` and ``W`` read at run
    time from the pool's :class:`~lss_kernels.kernels.backend.Extent`, save in the ray
    cast)."""

    def __init__(self, pool, height, width, c_max):
        self.H, self.W, self.C = int(height), int(width), int(c_max)
        self.extent = pool.extent(self.H, self.W)
        self.lanes = lanes.lanes_for_arch()
        plane = lambda dtype: pool.field(dtype, self.extent.bucket, bucket=True)
        self.delta_theta = plane(ti.f32)
        self.phi_plus = plane(ti.f32)
        self.disparity_left = plane(ti.f32)
        self.occlusion_left = plane(ti.i32)
        self.foreground_left = plane(ti.i32)

    @ti.func
    def sample_row(self, f: ti.template(), y, x):
        """Linear interpolation of ``f[y, .]`` at real x, clamped to the image."""
        width = self.extent.width()
        xf = ti.min(ti.max(x, 0.0), width - 1.0)
        x0 = 0
        if width > 1:
            x0 = ti.min(ti.cast(ti.floor(xf), ti.i32), width - 2)
        t = xf - x0
        v = f[y, x0]
        if width > 1:
            v = (1.0 - t) * f[y, x0] + t * f[y, x0 + 1]
        return v

    def compute(self, shapes, phi_x, ray_cast):
        """delta_theta for every pixel (``phi_x``: dphi/dx, a plane or a lane plane).  The
        ray cast runs a block of pixels in SIMD lanes: the block steps until every lane has
        reached its fixed point (a lane there repeats it), so each pixel gets the value of
        its own fixed-point iteration.  phi(x + delta_theta): :meth:`refresh_phi_plus`."""
        self._ray_cast(shapes, phi_x, int(ray_cast), 2.0 * self.C)

    @ti.kernel
    def _ray_cast(self, shapes: ti.template(), phi_x: ti.template(), ray_cast: ti.i32,
                  t_max: ti.f32):
        self.cast(shapes, phi_x, ray_cast, t_max)

    @ti.func
    def cast(self, shapes: ti.template(), phi_x: ti.template(), ray_cast, t_max):
        """:meth:`compute` (for a kernel that runs it with other stages); ``t_max`` (the largest jump, 2 c_max) is an argument, not a
        constant, so that the kernel does not depend on the disparity range.  Once per image
        size: the size and the shapes' normalisation are compile-time constants
        (:meth:`~lss_kernels.model.shapes.GlobalShapes.value_of_size`), which keeps the
        fixed-point steps' float code that of one size."""
        L, width = ti.static(self.lanes, self.W)
        for y, b in ti.ndrange(self.H, ti.static(lanes.block_count(width, L))):
            xf = lanes.columns(b, L)
            yf = ti.cast(y, ti.f32)
            th1 = shapes.value_of_size(0, xf, yf)
            jump = th1 - shapes.value_of_size(1, xf, yf)
            slope = lanes.block(phi_x, y, b, L, width)
            s = ti.select(slope > 0, 1.0, ti.select(slope < 0, -1.0, 0.0))
            # lanes past the right edge (no pixel) must not keep the block stepping
            cast = (jump > 0) & (s != 0) & (xf < width)
            t = jump
            if ray_cast:
                for _ in range(FIXED_POINT_STEPS):
                    t_next = ti.min(ti.max(th1 - shapes.value_of_size(1, xf - s * t, yf),
                                           0.0), t_max)
                    t_next = ti.select(cast, t_next, t)
                    if all(t_next == t):
                        break  # every fixed point reached: the remaining steps repeat it
                    t = t_next
            dt = ti.select(cast, s * t, 0.0)
            for lane in range(L):
                x = b * L + lane
                if x < width:
                    self.delta_theta[y, x] = dt[lane]

    @ti.kernel
    def refresh_phi_plus(self, phi: ti.template()):
        """phi_plus = phi(x + delta_theta), the level set where the ray from (x, y) meets the
        foreground's layer (Eq. 4's validity and the visible background read its sign)."""
        self.refresh(phi)

    @ti.func
    def refresh(self, phi: ti.template()):
        """:meth:`refresh_phi_plus`, for a kernel that runs it with other stages."""
        height, width = self.extent.height(), self.extent.width()
        for y, x in self.phi_plus:
            if y < height and x < width:
                self.phi_plus[y, x] = self.sample_row(phi, y, ti.cast(x, ti.f32) +
                                                      self.delta_theta[y, x])

    @ti.func
    def _source(self, shapes: ti.template(), j, x, y, sign):
        """Cyclopean x_c with x_c + sign * Theta_j(x_c, y) = x (sign +1: left view, -1: right)."""
        xc = x - sign * shapes.value(j, x, y)
        for _ in range(FIXED_POINT_STEPS):
            xc = x - sign * shapes.value(j, xc, y)
        return xc

    @ti.func
    def _foreground_at(self, phi: ti.template(), y, xc):
        """1 where the cyclopean point xc lies on the foreground (phi > 0) inside the frame."""
        fg = 0
        if -0.5 <= xc <= ti.cast(self.extent.width(), ti.f32) - 0.5:
            if self.sample_row(phi, y, xc) > 0:
                fg = 1
        return fg

    @ti.kernel
    def render_left(self, shapes: ti.template(), phi: ti.template()):
        """Left-view disparity (2 Theta, left-view pixels), foreground and occlusion masks."""
        width = ti.cast(self.extent.width(), ti.f32)
        for y, x in self.disparity_left:
            if y < self.extent.height() and x < self.extent.width():
                xf = ti.cast(x, ti.f32)
                yf = ti.cast(y, ti.f32)
                xc = self._source(shapes, 0, xf, yf, 1.0)
                fg = self._foreground_at(phi, y, xc)
                occ = 0
                d = 0.0
                if fg == 1:
                    d = 2.0 * shapes.value(0, xc, yf)
                else:
                    xb = self._source(shapes, 1, xf, yf, 1.0)
                    d = 2.0 * shapes.value(1, xb, yf)
                    # the right camera sees x - d: is the foreground there?  Its point lies
                    # at xl in the left view; ask the left pixel nearest to it, so that the
                    # occluded strip is exactly as wide as the rendered jump (x - d and the
                    # foreground's first pixel coincide for whole-pixel jumps, where asking
                    # phi at that point would leave the strip to float rounding).
                    xcr = self._source(shapes, 0, xf - d, yf, -1.0)
                    xl = ti.round(xcr + shapes.value(0, xcr, yf))
                    if 0.0 <= xl <= width - 1.0:
                        occ = self._foreground_at(phi, y, self._source(shapes, 0, xl, yf, 1.0))
                self.disparity_left[y, x] = ti.max(d, 0.0)
                self.foreground_left[y, x] = fg
                self.occlusion_left[y, x] = occ

    @ti.kernel
    def measure_strips(self, refined: ti.template(), matched: ti.template(), near: ti.i32,
                       far: ti.i32):
        """Re-measure every occluded strip of :meth:`render_left`'s output against the
        ``refined`` left-view disparity (a plane; module text) where ``matched`` (a plane,
        > 0 on the pixels with a distinct match of their own) says it was measured:
        ``occlusion_left`` is rewritten, ``disparity_left`` (the model's) and
        ``foreground_left`` are read.  A thread per row walks its runs of foreground pixels;
        the median over the window is the order statistic found by counting (no local
        arrays)."""
        height, width = self.extent.height(), self.extent.width()
        for y in range(height):
            for x in range(width):
                self.occlusion_left[y, x] = 0
            a = 1
            while a < width:
                if self.foreground_left[y, a] == 1 and self.foreground_left[y, a - 1] == 0:
                    b = a
                    while b < width and self.foreground_left[y, b] == 1:
                        b += 1
                    d_edge = self.disparity_left[y, a]
                    t = d_edge - self.disparity_left[y, a - 1]
                    for _ in range(FIXED_POINT_STEPS):
                        x0 = ti.cast(ti.floor(a - t - 0.5), ti.i32)
                        if t <= 0 or x0 < 0:
                            break
                        if self.foreground_left[y, x0] == 1:
                            break
                        r, count = self._median_residual(refined, matched, y,
                                                         ti.max(x0 - far, 0), x0 - near)
                        if count < STRIP_EVIDENCE:
                            r = 0.0     # no evidence: the quadratic's own jump
                        t_new = d_edge - self.disparity_left[y, x0] - r
                        done = ti.abs(t_new - t) < 1e-3
                        t = t_new
                        if done:
                            break
                    if t > 0:
                        first = ti.max(ti.cast(ti.ceil(a - t - 0.5), ti.i32), 0)
                        t_end = t + self.disparity_left[y, b - 1] - d_edge
                        last = ti.min(a - 1, ti.cast(ti.floor(b - 0.5 - t_end), ti.i32))
                        for x in range(first, last + 1):
                            if self.foreground_left[y, x] == 0:
                                self.occlusion_left[y, x] = 1
                    a = b
                else:
                    a += 1

    @ti.func
    def _evidence(self, matched: ti.template(), y, x):
        """Whether the background pixel ``(y, x)`` holds a match of its own."""
        return (self.foreground_left[y, x] == 0) & (matched[y, x] > 0)

    @ti.func
    def _median_residual(self, refined: ti.template(), matched: ti.template(), y, lo, hi):
        """The median of ``refined - disparity_left`` over the matched background pixels of
        row ``y`` in ``[lo, hi]`` (the mean of the two middle values for an even count), and
        their count."""
        count = 0
        for x in range(lo, hi + 1):
            if self._evidence(matched, y, x):
                count += 1
        low_rank, high_rank = (count - 1) // 2, count // 2
        low, high = 0.0, 0.0
        for i in range(lo, hi + 1):
            if self._evidence(matched, y, i):
                v = refined[y, i] - self.disparity_left[y, i]
                below, not_above = 0, 0
                for j in range(lo, hi + 1):
                    if self._evidence(matched, y, j):
                        w = refined[y, j] - self.disparity_left[y, j]
                        below += ti.cast(w < v, ti.i32)
                        not_above += ti.cast(w <= v, ti.i32)
                # v is every order statistic of rank below .. not_above - 1
                if below <= low_rank < not_above:
                    low = v
                if below <= high_rank < not_above:
                    high = v
        return 0.5 * (low + high), count
