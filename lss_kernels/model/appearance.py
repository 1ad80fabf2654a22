"""The layers' appearance: a colour term in Eq. 2 where the matches say little.

Eq. 2 moves phi by the matching costs alone: ``-M(Theta_1) + M(Theta_2)``.  On a uniform or
weakly textured surface every shift matches about as well, so that difference is noise and
the curvature term shrinks the object away; a neighbour at almost the same depth costs
the same under either surface and is swallowed.  What still tells the layers apart there is
what they look like.

Each layer gets a colour histogram (``BINS`` levels per channel) of the pixels on its side
of the boundary within ``BAND`` pixels of it: a cyclopean pixel's colour under layer j is
the mean of the two views at its match, ``(left(x + Theta_j) + right(x - Theta_j)) / 2``
(a pixel that is not on layer j mixes two unrelated colours, a colour the layer seldom
has).  The term adds to Eq. 2's data term, in the band,

    weight * clip(log p_1(colour_1) - log p_2(colour_2), +-CLIP) / (1 + P / P_band)

with the histograms smoothed by one count a bin.  ``P`` is the pixel's consensus precision
(Eq. 7) and ``P_band`` the band's mean: the term speaks where the matches are uncertain
and fades where they are distinct, which keeps the paper's data term in charge of textured
surfaces.  The histograms and the term are refreshed every ``reinit_every`` iterations, with
the re-initialisation's cadence, and the term is held in between (``LevelSet.appearance``).
"""
import taichi as ti

__all__ = ["BAND", "BINS", "CLIP", "Appearance"]

#: Levels per colour channel of the histograms (``BINS ** 3`` bins).
BINS = 12
#: Pixels of phi on either side of the boundary whose colours make the histograms and get
#: the term.
BAND = 16.0
#: Bound of the log-likelihood ratio.
CLIP = 4.0


@ti.data_oriented
class Appearance:
    """Owns the two layers' colour histograms; writes the Eq. 2 colour term into the level
    set's ``appearance`` field (:meth:`update`)."""

    def __init__(self, pool, height, width):
        self.extent = pool.extent(int(height), int(width))
        self.bins = BINS ** 3
        self.histogram = pool.field(ti.f32, (2, self.bins), bucket=True)
        self.sums = pool.field(ti.f32, (4,), bucket=True)  # the layers' counts, P, the band
        self.row_precision = pool.field(ti.f32, (self.extent.bucket[0],), bucket=True)

    @ti.func
    def _colour(self, image: ti.template(), y, x):
        """``image`` at row y and real column x, linear between columns, clamped."""
        width = self.extent.width()
        xf = ti.min(ti.max(x, 0.0), width - 1.0)
        x0 = ti.min(ti.cast(ti.floor(xf), ti.i32), ti.max(width - 2, 0))
        x1 = ti.min(x0 + 1, width - 1)
        t = xf - x0
        return (1.0 - t) * image[y, x0] + t * image[y, x1]

    @ti.func
    def _bin(self, left: ti.template(), right: ti.template(), y, x, theta):
        """The histogram bin of the pixel's colour under a layer of disparity ``theta``
        (cyclopean units)."""
        xf = ti.cast(x, ti.f32)
        colour = 0.5 * (self._colour(left, y, xf + theta) + self._colour(right, y, xf - theta))
        q = ti.min(ti.max(ti.cast(colour * BINS, ti.i32), 0), BINS - 1)
        return (q[0] * BINS + q[1]) * BINS + q[2]

    @ti.kernel
    def update(self, left: ti.template(), right: ti.template(), phi: ti.template(),
               shapes: ti.template(), precision: ti.template(), out: ti.template(),
               weight: ti.f32, band: ti.f32):
        """The histograms of the band (phi within ``band``) from ``phi`` and ``shapes``,
        then ``out`` = the colour term (module docstring) in the band, 0 outside it."""
        for j, k in self.histogram:
            self.histogram[j, k] = 0.0
        for i in self.sums:
            self.sums[i] = 0.0
        for y, x in ti.ndrange(self.extent.height(), self.extent.width()):
            p = phi[y, x]
            if ti.abs(p) < band:
                j = 0 if p > 0 else 1
                theta = shapes.value(j, ti.cast(x, ti.f32), ti.cast(y, ti.f32))
                self.histogram[j, self._bin(left, right, y, x, theta)] += 1.0
                self.sums[j] += 1.0
                self.sums[3] += 1.0
        # the band's precision summed in a fixed order (a row a thread, then the rows in
        # turn): a float sum in the threads' order would differ from run to run
        for y in range(self.extent.height()):
            row = 0.0
            for x in range(self.extent.width()):
                if ti.abs(phi[y, x]) < band:
                    row += precision[y, x]
            self.row_precision[y] = row
        ti.loop_config(serialize=True)
        for y in range(self.extent.height()):
            self.sums[2] += self.row_precision[y]
        for y, x in ti.ndrange(self.extent.height(), self.extent.width()):
            p = phi[y, x]
            term = 0.0
            if ti.abs(p) < band:
                xf, yf = ti.cast(x, ti.f32), ti.cast(y, ti.f32)
                b_1 = self._bin(left, right, y, x, shapes.value(0, xf, yf))
                b_2 = self._bin(left, right, y, x, shapes.value(1, xf, yf))
                n = ti.cast(self.bins, ti.f32)
                p_1 = (self.histogram[0, b_1] + 1.0) / (self.sums[0] + n)
                p_2 = (self.histogram[1, b_2] + 1.0) / (self.sums[1] + n)
                ratio = ti.min(ti.max(ti.log(p_1) - ti.log(p_2), -CLIP), CLIP)
                mean_precision = self.sums[2] / ti.max(self.sums[3], 1.0)
                term = weight * ratio / (1.0 + precision[y, x] / ti.max(mean_precision, 1e-12))
            out[y, x] = term
