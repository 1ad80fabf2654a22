"""Boundary costs B_occ and B_mono (Sec. 4) and their combination B (Eq. 1).

The matching cost M and its patch levels live in :mod:`lss_kernels.model.hierarchy` (they are the
upward pass's first product).  Here:

* ``B_occ(x, y, c)``: small where the matching cost changes abruptly along the epipolar line:
  |x-derivative of a Gaussian (sigma = ``OCC_SIGMA``)| of the size-3 cost volume, thresholded,
  then the 3-D Euclidean distance to the nearest above-threshold voxel, normalised to [0, 1].
* ``B_mono(x, y, c)``: small where both images have an intensity edge at the projections of
  the scene point (x, y, c): with e(.) = 0.5 (1 - dist_to_edge / max dist) per image
  (0.5 on an edge, 0 far from edges), ``B_mono = 1 - e_L(x + c) - e_R(x - c)``; edges are
  Sobel magnitudes (grey, Sobel / 8) above ``mono_threshold``.
* ``B = alpha_1 B_occ + alpha_2 B_mono + alpha_3`` (``Params.alpha``), read at Theta_1(x, y) with linear
  interpolation between integer disparities.

Frame: cyclopean; volumes ``(H, W, c_max)`` indexed ``[y, x, c - 1]``.  Planes and volumes
have the shape of the image's size bucket (the volumes by ``c_max``), and the kernels read
``H`` and ``W`` at run time from the pool's :class:`~lss_kernels.kernels.backend.Extent`.
"""
import math

import numpy as np
import taichi as ti

from ..kernels.backend import ROWS_DISPARITIES_COLUMNS
from ..kernels.distance import INF, DistanceTransform
from ..kernels.filters import gaussian_taps
from ..params import OCC_SIGMA, OCC_THRESHOLD

__all__ = ["BoundaryCosts"]


#: B_occ is filtered in blocks of rows holding as many values as this many planes (its
#: scratch).
CHUNK = 4


@ti.data_oriented
class BoundaryCosts:
    """Owns B_occ (a volume) and the two monocular edge maps; evaluates B at any (x, y, c)."""

    def __init__(self, pool, height, width, c_max):
        self.H, self.W, self.C = int(height), int(width), int(c_max)
        self.extent = pool.extent(self.H, self.W)
        (H, W), C = self.extent.bucket, self.C
        self.b_occ = pool.field(ti.f32, (H, W, C), order=ROWS_DISPARITIES_COLUMNS,
                                volume=True)
        self.edge_left = pool.field(ti.f32, (H, W), bucket=True)
        self.edge_right = pool.field(ti.f32, (H, W), bucket=True)
        self._max = pool.field(ti.f32, (), bucket=True)
        self.alpha = pool.vector(3, ti.f32, (), bucket=True)
        pool.host(self.alpha)
        # scratch, kept for the solver's life: destroying an SNode tree makes Taichi drop
        # every compiled kernel, which a reset solver would then compile again
        rows = max(1, -(-H * min(C, CHUNK) // C))               # B_occ, a block of rows at a time
        self._chunk = pool.field(ti.f32, (rows, W, C), order=ROWS_DISPARITIES_COLUMNS,
                                 volume=True)
        self._edt3 = None
        self._edt2 = self._dist2 = None

    def setup(self, distance, distance_map):
        """Allocate B_occ's distance-transform scratch; call once the pool is finalised.
        B_mono borrows the level set's 2-D transform ``distance`` and its ``(H, W, 1)``
        ``distance_map`` (set-up runs before any re-initialisation)."""
        H, W = self.extent.bucket
        budget = 2 * H * W                        # elements per line buffer: two planes
        self._edt3 = DistanceTransform((H, W, self.C), max_scratch=budget)
        self._edt2, self._dist2 = distance, distance_map

    def destroy(self):
        if self._edt3 is not None:
            self._edt3.destroy()
        self._edt3 = None

    @property
    def scratch_bytes(self):
        return self._edt3.nbytes if self._edt3 is not None else 0

    # -------------------------------------------------------------------- B_occ
    @ti.func
    def _correlate(self, src: ti.template(), taps: ti.template(), y, x, k,
                   axis: ti.template()):
        """sum_i taps[half + i] src at (y, x, k) + i along ``axis`` (0: y, 1: x), clamped.
        ``taps`` is a tuple (compile-time constants): away from the border the sum runs
        unrolled and unclamped; near it, as a loop with clamped indices."""
        half = ti.static((len(taps) - 1) // 2)
        height, width = self.extent.height(), self.extent.width()
        n = height if ti.static(axis == 0) else width
        pos = y if ti.static(axis == 0) else x
        s = 0.0
        if half <= pos < n - half:
            for i in ti.static(range(-half, half + 1)):
                if ti.static(axis == 0):
                    s += ti.static(taps[i + half]) * src[y + i, x, k]
                else:
                    s += ti.static(taps[i + half]) * src[y, x + i, k]
        else:
            weights = ti.Vector(taps)
            for i in range(-half, half + 1):
                if ti.static(axis == 0):
                    s += weights[i + half] * src[ti.min(ti.max(y + i, 0), height - 1), x, k]
                else:
                    s += weights[i + half] * src[y, ti.min(ti.max(x + i, 0), width - 1), k]
        return s

    @ti.kernel
    def _occ_chunk(self, src: ti.template(), taps: ti.template(), dtaps: ti.template(),
                   threshold: ti.f32, y0: ti.i32):
        """B_occ's features of rows y0 .. of ``src`` (as many as the chunk holds): the rows
        smoothed along y into the chunk (the block and its filter reach are read in their
        memory order), then |d/dx of the chunk| above ``threshold``."""
        for r, k, x in ti.ndrange(self._chunk.shape[0], self.C, self.extent.width()):
            if y0 + r < self.extent.height():
                self._chunk[r, x, k] = self._correlate(src, taps, y0 + r, x, k, 0)
        for r, k, x in ti.ndrange(self._chunk.shape[0], self.C, self.extent.width()):
            if y0 + r < self.extent.height():
                s = self._correlate(self._chunk, dtaps, r, x, k, 1)
                self.b_occ[y0 + r, x, k] = 0.0 if ti.abs(s) > threshold else INF

    @ti.func
    def _sqrt_normalise(self, vol: ti.template(), rows):
        """The ``H x W`` region of ``vol`` (squared distances, in memory order) <- the
        distances over their largest finite one, 1 where there is none (``rows``: the
        image's height, or 0 for nothing)."""
        self._max[None] = 0.0
        width = self.extent.width()
        for y, k in ti.ndrange(rows, self.C):
            # a row's largest first: one atomic per row, not one per voxel (a maximum is
            # exact in any order)
            largest = 0.0
            for x in range(width):
                if vol[y, x, k] < INF * 0.5:
                    largest = ti.max(largest, ti.sqrt(vol[y, x, k]))
            ti.atomic_max(self._max[None], largest)
        m = self._max[None]
        for y, k, x in ti.ndrange(rows, self.C, width):
            v = vol[y, x, k]
            vol[y, x, k] = ti.min(ti.sqrt(v) / m, 1.0) if (m > 0 and v < INF * 0.5) else 1.0

    def _occ_distances(self, cost_level1, sigma, threshold):
        """B_occ's squared distances to its features, from the size-3 normalised cost volume
        (``cost_level1`` may carry a margin; only its in-image part is read); the first of
        :meth:`_around_transforms` makes them B_occ."""
        g, _, _ = gaussian_taps(sigma, int(math.ceil(4 * sigma)))
        # derivative taps as central differences of the sampled Gaussian (what a discrete
        # gradient of the smoothing kernel gives)
        dg = np.zeros_like(g)
        dg[1:-1] = (g[2:] - g[:-2]) / 2.0
        g = tuple(g.astype(np.float32).tolist())
        # correlation with dg[::-1] is convolution with dg
        dg = tuple(dg[::-1].astype(np.float32).tolist())
        for y0 in range(0, self.H, self._chunk.shape[0]):
            self._occ_chunk(cost_level1, g, dg, float(threshold), y0)
        self._edt3.run(self.b_occ, (self.H, self.W))

    # -------------------------------------------------------------------- B_mono
    @ti.kernel
    def _around_transforms(self, left: ti.template(), right: ti.template(),
                           dist2: ti.template(), normalise: ti.i32, score: ti.i32,
                           features: ti.i32, threshold: ti.f32):
        """What runs between B's distance transforms, in order: with ``normalise``, B_occ
        from its transform (:meth:`_sqrt_normalise`); with ``score`` 0 or 1, that side's
        edge scores from the transform ``dist2`` (:meth:`_edge_score`); with ``features`` 0
        or 1, that side's edges as the features of the next transform
        (:meth:`_edge_features`)."""
        height = self.extent.height()
        self._sqrt_normalise(self.b_occ, ti.select(normalise == 1, height, 0))
        self._edge_score(dist2, score, ti.select(score >= 0, height, 0))
        self._edge_features(left, right, features, threshold, dist2,
                            ti.select(features >= 0, height, 0))

    @ti.func
    def _edge_features(self, left: ti.template(), right: ti.template(), side, threshold,
                       dist2: ti.template(), rows):
        """The Sobel edges of the left (``side`` 0) or right image as features of the
        distance map ``dist2`` (0 on an edge, INF elsewhere)."""
        height, width = self.extent.height(), self.extent.width()
        for y, x in ti.ndrange(rows, width):
            gx = 0.0
            gy = 0.0
            for dy, dx in ti.static(ti.ndrange((-1, 2), (-1, 2))):
                yy = ti.min(ti.max(y + dy, 0), height - 1)
                xx = ti.min(ti.max(x + dx, 0), width - 1)
                p = left[yy, xx]
                if side == 1:
                    p = right[yy, xx]
                grey = 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]
                wx = ti.static(dx * (2 - abs(dy)))
                wy = ti.static(dy * (2 - abs(dx)))
                gx += wx * grey
                gy += wy * grey
            mag = ti.sqrt(gx * gx + gy * gy) / 8.0
            dist2[y, x, 0] = 0.0 if mag > threshold else INF

    @ti.func
    def _edge_score(self, dist2: ti.template(), side, rows):
        """e_L (``side`` 0) or e_R from the squared distances to the edges."""
        self._max[None] = 0.0
        width = self.extent.width()
        for y, x in ti.ndrange(rows, width):
            if dist2[y, x, 0] < INF * 0.5:
                ti.atomic_max(self._max[None], ti.sqrt(dist2[y, x, 0]))
        m = self._max[None]
        for y, x in ti.ndrange(rows, width):
            d2 = dist2[y, x, 0]
            e = 0.0
            if d2 < INF * 0.5:
                e = 0.5 * (1.0 - ti.sqrt(d2) / m) if m > 0 else 0.5
            if side == 0:
                self.edge_left[y, x] = e
            else:
                self.edge_right[y, x] = e

    def build(self, cost_level1, left, right, params):
        """Everything B needs, once per solve: B_occ, then the edge scores e_L, e_R of the
        two images (``(H, W)`` vector fields in [0, 1]) for B_mono."""
        self.extent.pool.write(self.alpha, np.array(params.alpha))
        self._occ_distances(cost_level1, OCC_SIGMA, OCC_THRESHOLD)
        t, run = float(params.mono_threshold), self._around_transforms
        run(left, right, self._dist2, 1, -1, 0, t)    # B_occ; the left image's edges
        self._edt2.run(self._dist2, (self.H, self.W))
        run(left, right, self._dist2, 0, 0, 1, t)     # e_L; the right image's edges
        self._edt2.run(self._dist2, (self.H, self.W))
        run(left, right, self._dist2, 0, 1, -1, t)    # e_R

    # -------------------------------------------------------------------- evaluation
    @ti.func
    def b_mono_at(self, y, x, k):
        """B_mono at integer disparity index k (c = k + 1); zero edge score off the image."""
        c = k + 1
        e = 0.0
        if x + c < self.extent.width():
            e += self.edge_left[y, x + c]
        if x - c >= 0:
            e += self.edge_right[y, x - c]
        return 1.0 - e

    @ti.func
    def b_at(self, y, x, c):
        """B(x, y, c) for a real cyclopean disparity c (linear interpolation, clamped)."""
        kf = ti.min(ti.max(c - 1.0, 0.0), self.C - 1.0)
        k0 = ti.min(ti.cast(ti.floor(kf), ti.i32), self.C - 2) if self.C > 1 else 0
        t = kf - k0
        a = self.alpha[None]
        v0 = a[0] * self.b_occ[y, x, k0] + a[1] * self.b_mono_at(y, x, k0)
        v1 = v0
        if self.C > 1:
            v1 = a[0] * self.b_occ[y, x, k0 + 1] + a[1] * self.b_mono_at(y, x, k0 + 1)
        return (1.0 - t) * v0 + t * v1 + a[2]
