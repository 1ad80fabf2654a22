"""A third layer: whatever stands in front of the object (a handle, a rod, a nearer object).

The paper's model has two layers, the object (Theta_1, phi > 0) over one background
(Theta_2).  In a whole photo, things also stand in front of the object: a handle crosses
it, a nearer object covers its corner.  Their pixels match neither surface, and the
pixels they hide from one camera (a strip beside each of them, as wide as their disparity
jump: Sec. 2's occlusion geometry, applied to the nearer layer) match nothing at all.  Read
as background they bend Theta_2 and push the boundary back; a thin occluder cuts the
object in two.

This module adds the nearer layer as a support of its own, found per pixel from the
matching cost M (the size-3 patch cost that Eq. 2 reads): the candidate of least cost,
``c*``, is the pixel's own match (the consensus would blur a thin occluder over the
object's pixels beside it: its largest patches straddle both).  A pixel is in front where

* ``c*`` stands more than ``margin`` in front of Theta_1, and
* its cost is clearly below the costs at both surfaces: ``min(M(Theta_1), M(Theta_2)) -
  M(c*) > COST_GAP`` (neither the object nor the background explains it; a periodic
  background, whose matches repeat, is explained by Theta_2 as well as by any tooth);
* it lies on the object or within ``REACH`` pixels of it (phi > -REACH PHI_SCALE): what
  stands in front of the object matters where it covers the object or its band; far from
  it, a layer read from single matches would only feed on the background's ambiguities
  (a striped wall whose pixels left Theta_2's fit would move Theta_2 and leave more);
* and at least ``MAJORITY`` of its 3x3 window and ``SUPPORT`` of its 5x5 window are such
  pixels (stray matches, and the streaks of them in a half-occluded strip, are no layer).

From these,
* ``hidden``: the front pixels and the strips they hide from one of the cameras: a front
  pixel at x with match c* in front of the object's surface hides the cyclopean columns
  within ``c* - Theta_1`` of it on both sides (the left camera's half-occlusion on one
  side, the right camera's on the other: x -+ (c* - Theta_1) in the cyclopean frame).  A
  front pixel beside the object, over the background, hides a wider strip of background
  than this; that strip keeps its data term.

Hidden pixels carry no evidence of their own: they leave both Eq. 8 fits, and Eq. 2's data
term over them is carried in from the visible pixels beside them
(:meth:`lss_kernels.model.levelset.LevelSet._carry_hidden`), so the object's support
continues under a thin occluder where the object lies on both sides of it.  The left-view layer map and the occlusion that the front layer
casts are :mod:`lss_kernels.model.layers`.

Frame: cyclopean; planes of the image's size bucket (``H`` and ``W`` read at run time).
"""
import taichi as ti

from .matching import cost_at

__all__ = ["COST_GAP", "FrontLayer", "MAJORITY", "REACH", "SUPPORT"]

#: A front pixel stays one when at least this many of its 3x3 window are front pixels...
MAJORITY = 5
#: ... and this many of its 5x5 window.
SUPPORT = 12
#: How far from the object (phi's zero level) a pixel can be in front, pixels.
REACH = 24.0
#: How much lower than at both surfaces a front pixel's least cost must be (M is a mean
#: absolute difference of colours in [0, 1]).
COST_GAP = 0.05


@ti.data_oriented
class FrontLayer:
    """Owns each pixel's least-cost match (``first``, cyclopean; ``least``, its cost), the
    ``front`` support and the ``hidden`` mask (i32 planes, 1 = true)."""

    def __init__(self, pool, height, width):
        self.H, self.W = int(height), int(width)
        self.extent = pool.extent(self.H, self.W)
        plane = lambda dtype: pool.field(dtype, self.extent.bucket, bucket=True)
        self.first = plane(ti.f32)      # c*, cyclopean
        self.least = plane(ti.f32)      # M(c*)
        self.excess = plane(ti.f32)     # c* - Theta_1
        self.raw = plane(ti.i32)        # in front of Theta_1, before the majority vote
        self.front = plane(ti.i32)
        self.hidden = plane(ti.i32)

    @ti.kernel
    def capture(self, cost: ti.template(), C: ti.template()):
        """Each pixel's least-cost candidate of M (``cost``, ``C`` candidates) and its
        cost; the layer cleared."""
        height, width = self.extent.height(), self.extent.width()
        for y, x in self.first:
            best, at = 1e30, 1
            if y < height and x < width:
                for k in range(C):
                    m = cost[y, x, k]
                    if m < best:
                        best, at = m, k + 1
            self.first[y, x] = ti.cast(at, ti.f32)
            self.least[y, x] = best
            self.raw[y, x] = 0
            self.front[y, x] = 0
            self.hidden[y, x] = 0

    @ti.kernel
    def update(self, cost: ti.template(), C: ti.template(), shapes: ti.template(),
               phi: ti.template(), near: ti.f32, margin: ti.f32):
        """``front`` and ``hidden`` for the current Theta_1 (module text); ``cost`` is M
        (``C`` candidates), ``phi`` the level set, ``near`` the least phi of a front pixel
        (``-REACH`` pixels in phi's units), ``margin`` in cyclopean pixels."""
        height, width = self.extent.height(), self.extent.width()
        for y, x in self.raw:
            if y < height and x < width:
                c = self.first[y, x]
                th1 = shapes.value(0, ti.cast(x, ti.f32), ti.cast(y, ti.f32))
                th2 = shapes.value(1, ti.cast(x, ti.f32), ti.cast(y, ti.f32))
                gap = ti.min(cost_at(cost, y, x, th1, C),
                             cost_at(cost, y, x, th2, C)) - self.least[y, x]
                self.raw[y, x] = ti.cast((c - th1 > margin) & (gap > COST_GAP)
                                         & (phi[y, x] > near), ti.i32)
                self.excess[y, x] = c - th1
        for y, x in self.front:
            if y < height and x < width:
                close, votes = 0, 0
                for v, u in ti.ndrange((y - 2, y + 3), (x - 2, x + 3)):
                    if 0 <= v < height and 0 <= u < width:
                        votes += self.raw[v, u]
                        if ti.abs(v - y) <= 1 and ti.abs(u - x) <= 1:
                            close += self.raw[v, u]
                self.front[y, x] = ti.cast(self.raw[y, x] == 1 and close >= MAJORITY
                                           and votes >= SUPPORT, ti.i32)
        for y in range(height):
            reach = -1.0                      # right of a front run: x + (c* - Theta_1)
            for x in range(width):
                if self.front[y, x] == 1:
                    reach = ti.max(reach, x + self.excess[y, x])
                self.hidden[y, x] = ti.cast(self.front[y, x] == 1 or x <= reach, ti.i32)
            reach = width + 1.0               # left of a front run: x - (c* - Theta_1)
            for k in range(width):
                x = width - 1 - k
                if self.front[y, x] == 1:
                    reach = ti.min(reach, x - self.excess[y, x])
                if x >= reach:
                    self.hidden[y, x] = 1
