"""The level-set function phi and its evolution: Eq. 2 and Eq. 3 of the paper.

    dphi/dt = delta_eps(phi) [ -M(x, y, Theta_1) + M(x - delta_theta, y, Theta_2)
                               + mu ( B(x, y, Theta_1) kappa + N . grad B ) ]      (Eq. 2)

    D(x, y) = H(phi) Theta_1(x, y) + (1 - H(phi)) Theta_2(x, y)                      (Eq. 3)

with delta_eps(phi) = (1/pi) / (1 + phi^2) inside a narrow band around the boundary (|phi| <=
``narrow_band`` pixels times ``PHI_SCALE``) and 0 outside it, kappa = div(grad phi / |grad phi|)
and N = grad phi / |grad phi|.  phi being ``PHI_SCALE`` (0.01) times a distance, delta_eps alone
falls only to half its peak 100 px from the boundary: every pixel of the image moves, and where
the data term is weak and noisy (a dark, low-contrast layer) its small imbalances add up over
hundreds of iterations until the sign flips far inside a region, opening holes in an object
that no boundary ever reached.  Inside the band the step is the paper's; outside it phi keeps
its value (a narrow-band level set, Adalsteinsson and Sethian 1995), so regions change only by
moving their boundary; kappa, N, B and grad B are computed only in the blocks of pixels whose
step reads them (``_mark_band``), phi_x everywhere (the ray cast reads its sign).
Derivatives are separable Gaussian-derivative filters (``CURVATURE_SIGMA``, symmetric
borders: the Neumann condition of Eq. 2; :mod:`lss_kernels.kernels.filters`); kappa is clipped
to +-``CURVATURE_CLIP`` and the boundary term to +-``BOUNDARY_CLIP``.  M is the size-3 patch cost (level 1 of the hierarchy) read with
linear interpolation in x and c.  After every step phi is median-filtered (``median_size``
squared, symmetric borders; :mod:`lss_kernels.kernels.median`) and every ``reinit_every`` steps
re-initialised to ``PHI_SCALE`` times a signed distance (the re-initialisation comes first, as
in the authors' release).  The median's output goes through :class:`Settle`, which also counts
the pixels whose sign flipped and writes D (Eq. 3, with the sharp Heaviside), so neither needs a
pass of its own.

Frame: cyclopean ``(H, W)`` images indexed ``[y, x]``; phi > 0 is the foreground.  phi's
derivatives (``phi_x``, ``kappa``, ``normal_x``, ``normal_y``) are lane planes
(:mod:`lss_kernels.kernels.lanes`): the column passes and the Eq. 2 step run a block of
horizontally adjacent pixels per loop index.  Every plane has the shape of the image's size
bucket and the kernels read ``H`` and ``W`` at run time from the pool's
:class:`~lss_kernels.kernels.backend.Extent`: they compile once per bucket.
"""
import math

import numpy as np
import taichi as ti

from ..kernels import lanes
from ..kernels.distance import INF, DistanceTransform
from ..kernels.filters import GaussianFilters
from ..kernels.median import MedianFilter
from ..params import BOUNDARY_CLIP, CURVATURE_CLIP, CURVATURE_SIGMA, PHI_SCALE
from .matching import cost_at

__all__ = ["CARRY", "LevelSet", "Settle", "disparity"]

#: Visible pixels on either side of a hidden run whose data terms it takes (_carry_hidden).
CARRY = 3


@ti.func
def disparity(shapes: ti.template(), phi, x, y):
    """Eq. 3 at a pixel: Theta_1(x, y) where phi > 0, else Theta_2(x, y) (the Heaviside is
    sharp in the final map, as in the paper's output), cyclopean units."""
    j = 0 if phi > 0 else 1
    return shapes.value(j, ti.cast(x, ti.f32), ti.cast(y, ti.f32))


@ti.data_oriented
class Settle:
    """The sink of the median filter during the evolution (see
    :class:`lss_kernels.kernels.median.MedianFilter`): phi <- the median, and on the way the
    pixels whose sign differs from phi's previous value (``flipped``), the foreground area
    (``area``) and Eq. 3's D of the new phi, clamped to [0, c_max] (a quadratic can
    extrapolate outside the searched range)."""

    def __init__(self, levelset, shapes):
        self.ls, self.shapes = levelset, shapes

    @ti.func
    def begin(self):
        self.ls.flipped[None] = 0
        self.ls.area[None] = 0

    @ti.func
    def store(self, y, x, value):
        now = value > 0
        if now != (self.ls.phi[y, x] > 0):
            self.ls.flipped[None] += 1
        if now:
            self.ls.area[None] += 1
        self.ls.phi[y, x] = value
        self.ls.D[y, x] = ti.min(ti.max(disparity(self.shapes, value, x, y), 0.0),
                                 self.ls.d_limit[None])

    @ti.func
    def end(self):
        return ti.Vector([self.ls.flipped[None], self.ls.area[None]])


@ti.data_oriented
class LevelSet:
    """Owns phi, its derivatives, the boundary-term maps, the Eq. 2 step and D (Eq. 3)."""

    def __init__(self, pool, height, width, params):
        self.H, self.W = int(height), int(width)
        self.extent = pool.extent(self.H, self.W)
        H, W = self.extent.bucket
        f = lambda: pool.field(ti.f32, (H, W), bucket=True)
        self.phi = f()
        # phi after the Eq. 2 step, before its median: the shared median's source plane
        self.median = MedianFilter.shared(pool, self.H, self.W, params.median_size)
        self.phi_next = self.median.source
        self.b_map = f()
        self.D = f()                                   # Eq. 3, cyclopean units
        self.d_limit = pool.field(ti.f32, (), bucket=True)    # D is clamped to [0, c_max]
        self.lanes = lanes.lanes_for_arch()
        self.blocks = lanes.block_count(self.W, self.lanes)
        # lane planes: the sign of dphi/dx orients the occlusion ray cast; kappa and N enter
        # the Eq. 2 step
        plane = lambda: lanes.lane_plane(pool, H, W, self.lanes, bucket=True)
        self.phi_x, self.kappa, self.normal_x, self.normal_y = (plane() for _ in range(4))
        self.filters = GaussianFilters(pool, self.H, self.W, CURVATURE_SIGMA)
        # the narrow band (0: none) and the blocks of lanes that its step reads (_mark_band)
        self.band = float(params.narrow_band * PHI_SCALE)
        self.reach = lanes.block_count(self.filters.half, self.lanes)
        block = lambda: pool.field(ti.i8, (H, lanes.block_count(W, self.lanes)), bucket=True)
        self.in_band, self.near_rows, self.near = block(), block(), block()
        self.flipped = pool.field(ti.i32, (), bucket=True)
        self.changed = pool.field(ti.i32, (), bucket=True)
        self.boundary = pool.field(ti.i32, (), bucket=True)
        self.reference_sign = pool.field(ti.i8, (H, W), bucket=True)
        self.area = pool.field(ti.i32, (), bucket=True)
        pool.host(self.d_limit, self.phi, self.phi_next, self.D)   # start(), outputs
        self.curvature_clip = float(CURVATURE_CLIP)
        self.boundary_clip = float(BOUNDARY_CLIP)
        self.scale = float(PHI_SCALE)
        # squared distances of the re-initialisation (also B_mono's scratch, see costs)
        self.distance_map = pool.field(ti.f32, (H, W, 1), bucket=True)
        self.distance = None
        self._settle = {}
        # the pixels without evidence (a layer in front, lss_kernels.model.front, which sets
        # ``hidden``): their data term is carried in from beside them (_carry_hidden)
        self.has_hidden = params.front_margin > 0
        self.hidden = None
        if self.has_hidden:
            self.data, self.force = f(), f()
        # the layers' colour term (lss_kernels.model.appearance), refreshed by its stage
        self.has_appearance = bool(params.appearance)
        if self.has_appearance:
            self.appearance = f()

    def setup(self):
        """Allocate the re-initialisation scratch; call once the pool is finalised."""
        self.distance = DistanceTransform(self.extent.bucket + (1,))

    @property
    def scratch_bytes(self):
        return self.distance.nbytes if self.distance is not None else 0

    def destroy(self):
        if self.distance is not None:
            self.distance.destroy()
            self.distance = None

    # ---------------------------------------------------------------- derivatives
    def image(self, plane):
        """One of the lane planes ``phi_x``, ``kappa``, ``normal_x``, ``normal_y`` as an
        ``(H, W)`` float32 array."""
        return lanes.to_image(plane, self.H, self.W)

    @ti.func
    def _columns_curvature(self):
        """Along y, a block of pixels at a time: the five derivatives of phi from the
        row-filtered scratch, and from them phi_x, the clipped curvature
        kappa = div(grad phi / |grad phi|) and the normal N = grad phi / |grad phi| (phi_y and
        the second derivatives are used here only), kappa and N in the band's blocks only
        (:meth:`_mark_band`; elsewhere they keep older values, which the step never reads).
        Lanes past the right edge hold values of the reflected image: block kernels compute
        with them but never store them as pixels."""
        clip = self.curvature_clip
        for y, b in self.kappa:
            if y < self.extent.height() and b < self._blocks():
                if self.in_band[y, b] != 0:
                    py, pyy = self.filters.columns(0, y, b, (1, 2))
                    px, pxy = self.filters.columns(1, y, b, (0, 1))
                    pxx = self.filters.columns(2, y, b, (0,))[0]
                    norm = ti.sqrt(px * px + py * py) + 1e-10
                    k = (pxx * py * py - 2.0 * px * py * pxy + pyy * px * px) / \
                        (norm * norm * norm)
                    self.phi_x[y, b] = px
                    self.kappa[y, b] = ti.min(ti.max(k, -clip), clip)
                    self.normal_x[y, b] = px / norm
                    self.normal_y[y, b] = py / norm
                else:       # the ray cast reads phi_x's sign everywhere
                    self.phi_x[y, b] = self.filters.columns(1, y, b, (0,))[0]

    @ti.func
    def _blocks(self):
        """Blocks of lanes that cover a row of the image (run time)."""
        return (self.extent.width() + self.lanes - 1) // self.lanes

    @ti.kernel
    def _derivatives(self, band: ti.f32):
        self.derive(band)

    @ti.func
    def derive(self, band):
        """:meth:`derivatives`, for a kernel that runs it with other stages."""
        self._mark_band(band)
        self.filters.rows(self.phi, (0, 1, 2), self.near_rows, (1,))
        self._columns_curvature()

    def derivatives(self):
        """The band's blocks (:meth:`_mark_band`), then phi_x everywhere and kappa and N in
        the band's blocks (one launch)."""
        self._derivatives(self.band)

    @ti.func
    def _mark_band(self, band):
        """The blocks of lanes that the Eq. 2 step reads, from the current phi: ``in_band``,
        those with a pixel inside the band (|phi| <= ``band``; all when ``band`` is 0), the
        only ones whose phi the step moves; ``near_rows``, those within the filters'
        half-width of an in-band block in its column (where the column passes of kappa, N
        and grad B read the row-filtered scratch); ``near``, those within the row pass's
        reach of a ``near_rows`` block in its row (where it reads B).  Elsewhere the step
        keeps phi exactly, so kappa, N, B and the row pass of grad B are left out there."""
        L, half, reach = ti.static(self.lanes, self.filters.half, self.reach)
        height, width, blocks = self.extent.height(), self.extent.width(), self._blocks()
        for y, b in self.in_band:
            if y < height and b < blocks:
                inside = 0
                for lane in range(L):
                    x = b * L + lane
                    if x < width and (band <= 0 or ti.abs(self.phi[y, x]) <= band):
                        inside = 1
                self.in_band[y, b] = ti.cast(inside, ti.i8)
        self._widen(self.in_band, self.near_rows, 0, half)
        self._widen(self.near_rows, self.near, 1, reach)

    @ti.func
    def _widen(self, src: ti.template(), dst: ti.template(), axis: ti.template(),
               reach: ti.template()):
        """``dst`` marks the blocks within ``reach`` of a block marked in ``src`` along
        ``axis`` (0: its column of blocks, 1: its row); a parallel loop."""
        height, blocks = self.extent.height(), self._blocks()
        for y, b in dst:
            if y < height and b < blocks:
                i, n = (y, height) if ti.static(axis == 0) else (b, blocks)
                near = 0
                for k in range(ti.max(i - reach, 0), ti.min(i + reach + 1, n)):
                    v, u = (k, b) if ti.static(axis == 0) else (y, k)
                    near = ti.max(near, ti.cast(src[v, u], ti.i32))
                dst[y, b] = ti.cast(near, ti.i8)

    # ---------------------------------------------------------------- boundary weight
    @ti.func
    def _b_map(self, costs: ti.template(), shapes: ti.template()):
        L = ti.static(self.lanes)
        width = self.extent.width()
        for y, b in self.kappa:
            if y < self.extent.height() and b < self._blocks() and self.near[y, b] != 0:
                theta_1 = shapes.value(0, lanes.columns(b, L), ti.cast(y, ti.f32))
                for lane in range(L):
                    x = b * L + lane
                    if x < width:
                        self.b_map[y, x] = costs.b_at(y, x, theta_1[lane])

    @ti.kernel
    def boundary_weight(self, costs: ti.template(), shapes: ti.template()):
        """B(x, y, Theta_1(x, y)) and the row pass of its gradient (the column pass runs in
        the Eq. 2 step, which alone needs grad B), in one launch; where the step reads them
        (:meth:`_mark_band`, after :meth:`derivatives`)."""
        self.boundary_terms(costs, shapes)

    @ti.func
    def boundary_terms(self, costs: ti.template(), shapes: ti.template()):
        """:meth:`boundary_weight`, for a kernel that runs it with other stages."""
        self._b_map(costs, shapes)
        self.filters.rows(self.b_map, (0, 1), self.near_rows, ())

    # ---------------------------------------------------------------- Eq. 2
    @ti.func
    def _cost_at(self, cost: ti.template(), y, x, c, C: ti.template(), width):
        """M(x, y, c) at real x and c (linear in both; clamped to the volume ``width``
        pixels wide)."""
        xf = ti.min(ti.max(x, 0.0), width - 1.0)
        x0 = ti.min(ti.cast(ti.floor(xf), ti.i32), ti.max(width - 2, 0))
        x1 = ti.min(x0 + 1, width - 1)
        tx = xf - x0
        a = cost_at(cost, y, x0, c, C)
        b = cost_at(cost, y, x1, c, C)
        return (1.0 - tx) * a + tx * b

    @ti.kernel
    def _step(self, cost: ti.template(), C: ti.template(), shapes: ti.template(),
              occ: ti.template(), dt: ti.f32, mu: ti.f32, band: ti.f32):
        """phi_next from phi by Eq. 2, a block of pixels at a time: the boundary term for the
        whole block (grad B is the column pass of the separable filters, whose row pass ran
        in :meth:`boundary_weight`), then each pixel's data term; phi where |phi| > ``band``
        (> 0; 0: no band) is kept, and the blocks without such a pixel are copied
        (:meth:`_mark_band` ran with the same ``band``)."""
        clip = self.boundary_clip
        L = ti.static(self.lanes)
        width = self.extent.width()
        for y, b in self.kappa:
            if y < self.extent.height() and b < self._blocks() and self.in_band[y, b] == 0:
                for lane in range(L):
                    x = b * L + lane
                    if x < width:
                        self.phi_next[y, x] = self.phi[y, x]
                        if ti.static(self.has_hidden):
                            self.data[y, x] = 0.0
                            self.force[y, x] = 0.0
            elif y < self.extent.height() and b < self._blocks():
                b_x = self.filters.columns(1, y, b, (0,))[0]
                b_y = self.filters.columns(0, y, b, (1,))[0]
                b_map = lanes.block(self.b_map, y, b, L, width)
                bt = b_map * self.kappa[y, b] + self.normal_x[y, b] * b_x + \
                    self.normal_y[y, b] * b_y
                bt = ti.min(ti.max(bt, -clip), clip)
                xs = lanes.columns(b, L)
                yf = ti.cast(y, ti.f32)
                theta_1 = shapes.value(0, xs, yf)
                theta_2 = shapes.value(1, xs, yf)
                for lane in range(L):     # not unrolled: compiles 3x faster, runs as fast
                    x = b * L + lane
                    if x < width:
                        xf = xs[lane]
                        p = self.phi[y, x]
                        m1 = cost_at(cost, y, x, theta_1[lane], C)
                        m2 = self._cost_at(cost, y, xf - occ.delta_theta[y, x], theta_2[lane], C,
                                           width)
                        dirac = (1.0 / math.pi) / (1.0 + p * p)
                        if band > 0 and ti.abs(p) > band:
                            dirac = 0.0
                        data = -m1 + m2
                        if ti.static(self.has_appearance):
                            data += self.appearance[y, x]
                        if ti.static(self.has_hidden):
                            self.data[y, x] = data
                            self.force[y, x] = dirac * mu * bt[lane]
                        self.phi_next[y, x] = p + dt * dirac * (data + mu * bt[lane])

    @ti.kernel
    def _carry_hidden(self, dt: ti.f32, band: ti.f32):
        """Eq. 2's data term over the pixels hidden by a layer in front of the object
        (:mod:`lss_kernels.model.front`), which hold no evidence of their own: each run of
        them along a row takes the smaller of the mean data terms of the ``CARRY`` visible
        pixels on either side (one side at the image's border).  The object's support goes
        on behind a thin occluder where the object lies on both sides of it, and stops at
        it where the background lies on one."""
        height, width = self.extent.height(), self.extent.width()
        for y in range(height):
            a = 0
            while a < width:
                if self.hidden[y, a] == 1:
                    b = a
                    while b < width and self.hidden[y, b] == 1:
                        b += 1
                    left, n_left = 0.0, 0
                    for k in range(1, CARRY + 1):
                        if a - k >= 0 and self.hidden[y, a - k] == 0:
                            left += self.data[y, a - k]
                            n_left += 1
                    right, n_right = 0.0, 0
                    for k in range(CARRY):
                        if b + k < width and self.hidden[y, b + k] == 0:
                            right += self.data[y, b + k]
                            n_right += 1
                    carried = 0.0
                    if n_left > 0 and n_right > 0:
                        carried = ti.min(left / n_left, right / n_right)
                    elif n_left > 0:
                        carried = left / n_left
                    elif n_right > 0:
                        carried = right / n_right
                    for x in range(a, b):
                        p = self.phi[y, x]
                        dirac = (1.0 / math.pi) / (1.0 + p * p)
                        if band > 0 and ti.abs(p) > band:
                            dirac = 0.0
                        self.phi_next[y, x] = p + dt * (dirac * carried + self.force[y, x])
                    a = b
                else:
                    a += 1

    # ---------------------------------------------------------------- re-initialisation, stopping
    @ti.kernel
    def _distance_step(self, phi: ti.template(), signed: ti.i32, features: ti.i32,
                       scale: ti.f32):
        """Around a distance transform of ``distance_map``: with ``signed`` 0 or 1, phi of
        that region (1: phi > 0) <- ``scale`` x (its distance to the other region - 1/2),
        the boundary lying between pixel centres and the distance capped at the image
        diagonal; then, with ``features`` 0 or 1, the features of the next transform, the
        pixels of that region."""
        height, width = self.extent.height(), self.extent.width()
        cap = ti.sqrt(ti.cast(height * height + width * width, ti.f32))
        for y, x in ti.ndrange(ti.select(signed >= 0, height, 0), width):
            inside = phi[y, x] > 0
            if inside == (signed == 1):
                # d >= 1 (measured to the nearest pixel of the other region): signs are kept
                d = ti.min(ti.sqrt(self.distance_map[y, x, 0]), cap)
                phi[y, x] = (scale if signed == 1 else -scale) * (d - 0.5)
        for y, x in ti.ndrange(ti.select(features >= 0, height, 0), width):
            inside = phi[y, x] > 0
            self.distance_map[y, x, 0] = 0.0 if inside == (features == 1) else INF

    def reinitialise(self, phi):
        """phi <- PHI_SCALE x signed distance of the region phi > 0, in place (the signs, and
        so the region, are kept)."""
        self._distance_step(phi, -1, 0, self.scale)     # distance to the background
        self.distance.run(self.distance_map, (self.H, self.W))
        self._distance_step(phi, 1, 1, self.scale)      # then to the foreground
        self.distance.run(self.distance_map, (self.H, self.W))
        self._distance_step(phi, 0, -1, self.scale)

    @ti.kernel
    def net_change(self) -> ti.types.vector(2, ti.i32):
        """Pixels whose label differs from the reference taken at the last call (``changed``:
        the net change over a window, an oscillating boundary does not count), and the
        boundary's length (``boundary``: foreground pixels with a 4-neighbour of the
        background inside the image); renews the reference.  Returns both."""
        self.changed[None] = 0
        self.boundary[None] = 0
        height, width = self.extent.height(), self.extent.width()
        for y, x in self.phi:
            if y < height and x < width:
                now = ti.cast(self.phi[y, x] > 0, ti.i8)
                if now != self.reference_sign[y, x]:
                    self.changed[None] += 1
                self.reference_sign[y, x] = now
                # a neighbour outside the image is clamped to the pixel itself (no boundary)
                left, right = self.phi[y, ti.max(x - 1, 0)], self.phi[y, ti.min(x + 1, width - 1)]
                up, down = self.phi[ti.max(y - 1, 0), x], self.phi[ti.min(y + 1, height - 1), x]
                if now == 1 and ti.min(ti.min(left, right), ti.min(up, down)) <= 0:
                    self.boundary[None] += 1
        return ti.Vector([self.changed[None], self.boundary[None]])

    def settle(self, shapes):
        """phi <- the median of phi_next, counting the sign flips (``flipped``) and the
        foreground (``area``), and D (Eq. 3) of the new phi from ``shapes``; returns
        ``(flipped, area)``."""
        sink = self._settle.get(id(shapes))
        if sink is None:
            sink = self._settle[id(shapes)] = Settle(self, shapes)
        return self.median.run(self.phi_next, sink)

    def evolve(self, cost, c_max, shapes, occ, params, reinit):
        """One descent step of Eq. 2, then (every ``reinit_every``) the signed-distance
        re-initialisation and the median filter (:meth:`settle`); returns ``(flipped,
        area)``."""
        self._step(cost, c_max, shapes, occ, params.dt, params.mu, self.band)
        if self.has_hidden:
            self._carry_hidden(params.dt, self.band)
        if reinit:
            self.reinitialise(self.phi_next)
        return self.settle(shapes)

    def start(self, mask, c_max):
        """phi = PHI_SCALE x signed distance of a boolean ``(H, W)`` mask; D will be clamped
        to [0, ``c_max``]."""
        pool = self.extent.pool
        pool.write(self.d_limit, np.array(float(c_max)))
        pool.write(self.phi_next, self.extent.padded(np.where(mask, 1.0, -1.0)))
        self.reinitialise(self.phi_next)
        pool.write(self.phi, pool.read(self.phi_next))
