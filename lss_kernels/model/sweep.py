"""The background's plane sweep: Theta_2 chosen by the energy's background term itself where
the consensus cannot place it.

Eq. 8 fits Theta_2 to the consensus d-bar weighted by its precision.  On a dark or
low-contrast background whose texture is lost in noise, every patch's cost curve is shallow
under the hierarchy's one min-max scale per level, so the background pixels carry almost no
weight (and, from the second iteration on, their messages echo the ``beta |c - D|`` prior):
the fit is then decided by the few confident pixels outside the boundary -- the part of the
object that the start does not cover, and the halo where large patches straddle it -- and
Theta_2 lands on the object.  The two layers coincide, nothing drives phi, and the
foreground vanishes.

The signal is there when summed over the whole background: the mean matching cost of the
visible background, as a function of one disparity, dips by about 6 % at the true one.  So
the sweep evaluates Eq. 1's background term over the visible background, Theta_2 held
fronto-parallel at each candidate c = 1 .. c_max, with each pixel's cost curve standardised
(``z(c) = (M(c) - mean_c M) / std_c M``): every pixel has one vote of the same weight, and
the few textured pixels of the object that lie outside the boundary cannot outvote tens of
thousands of dark ones.  Pixels whose consensus lies within ``NEAR`` of Theta_1 are left out
(they look like the foreground: the object's uncovered part).  When the best plane's mean
standardised cost is below that of the fitted Theta_2 by more than ``Params.background_sweep``,
Theta_2 becomes that plane (its disparity refined to the vertex of the parabola through the
best candidate and its neighbours), provided that it is a distinct dip of the swept curve
(``WIDTH``): a slanted or curved background, whose pixels dip at many disparities, sweeps to a
broad bowl whose lowest plane explains none of it (a wall spanning 60 px of disparity would
get the plane at the range's end), and is left to the fit.  On a textured fronto-parallel
background the plane can win too, where it explains the background better than the fitted
quadratic.  A dark background that is curved becomes a plane.

The sweep runs after the fit in each of the first ``reinit_every`` iterations (while the
first consensus' pull on Theta_2 is undone) and then at every re-initialisation.

Frames and units are the solver's: cyclopean planes, ``c = 1 .. c_max`` (volume index
``k = c - 1``), Theta in cyclopean units.
"""
import math

import numpy as np
import taichi as ti

from ..kernels.curves import vertex_offset
from .matching import cost_at

__all__ = ["BackgroundSweep", "FLAT", "MIN_SHARE", "NEAR", "WIDTH", "choose_plane",
           "distinct_dip", "due", "plane_vertex"]

#: A background pixel whose consensus lies within this of Theta_1 (cyclopean pixels) is left
#: out of the sweep.
NEAR = 1.5
#: The best plane must be a distinct dip of the swept curve: the candidates below half its
#: depth (from the curve's mean) span at most this fraction of the range (or 2 candidates).
WIDTH = 0.25
#: A curve whose standard deviation over c is at most this is flat (no vote).
FLAT = 1e-6
#: The fewest swept pixels, as a fraction of the image, for a plane to be set.
MIN_SHARE = 0.01


@ti.data_oriented
class BackgroundSweep:
    """Owns each pixel's cost-curve standardisation (``centre``, ``inv_spread``: the mean and
    the inverse standard deviation of M over c), the swept pixels (``swept``, with their
    standardised cost at the fitted Theta_2, ``at_theta2``) and the sweep's per-row sums;
    :meth:`run` sweeps and, when a plane wins, sets Theta_2 to it.

    Parameters
    ----------
    pool : FieldPool
    height, width, c_max : int
    """

    def __init__(self, pool, height, width, c_max):
        self.H, self.W, self.C = int(height), int(width), int(c_max)
        self.extent = pool.extent(self.H, self.W)
        Hb, Wb = self.extent.bucket
        self.centre = pool.field(ti.f32, (Hb, Wb), bucket=True)
        self.inv_spread = pool.field(ti.f32, (Hb, Wb), bucket=True)
        self.swept = pool.field(ti.f32, (Hb, Wb), bucket=True)
        self.at_theta2 = pool.field(ti.f32, (Hb, Wb), bucket=True)
        # per row: the standardised cost summed over the row's swept pixels at each c (k < C),
        # at the fitted Theta_2 (k = C) and the pixels' count (k = C + 1)
        self.rows = pool.field(ti.f32, (Hb, self.C + 2), volume=True)
        self.totals = pool.field(ti.f32, (self.C + 2,), volume=True)
        pool.host(self.totals)

    @ti.kernel
    def standardise(self, cost: ti.template()):
        """``centre`` and ``inv_spread`` of every pixel's curve ``cost[y, x, :]`` (M, the
        hierarchy's level-1 volume); a flat curve (spread at most ``FLAT``: float32
        rounding of a constant curve leaves about 1e-8) gets ``inv_spread = 0`` (no vote)."""
        C = ti.static(self.C)
        height, width = self.extent.height(), self.extent.width()
        for y, x in ti.ndrange(*ti.static(self.extent.bucket)):
            if y < height and x < width:
                s = 0.0
                for k in range(C):
                    s += cost[y, x, k]
                m = s / C
                v = 0.0
                for k in range(C):
                    v += (cost[y, x, k] - m) ** 2
                sd = ti.sqrt(v / C)
                self.centre[y, x] = m
                self.inv_spread[y, x] = 1.0 / sd if sd > FLAT else 0.0

    @ti.func
    def _z(self, cost: ti.template(), y, x, c):
        """The standardised cost at real cyclopean c (:func:`~.matching.cost_at`)."""
        return (cost_at(cost, y, x, c, self.C) - self.centre[y, x]) * self.inv_spread[y, x]

    @ti.kernel
    def _sweep(self, cost: ti.template(), shapes: ti.template(), phi: ti.template(),
               phi_plus: ti.template(), consensus: ti.template(), near: ti.f32):
        """The sweep's sums in one launch (:meth:`_select`, :meth:`_accumulate`,
        :meth:`_reduce`)."""
        self._select(cost, shapes, phi, phi_plus, consensus, near)
        self._accumulate(cost)
        self._reduce()

    @ti.func
    def _select(self, cost: ti.template(), shapes: ti.template(), phi: ti.template(),
                phi_plus: ti.template(), consensus: ti.template(), near):
        """``swept``: 1 on the visible background away from Theta_1's consensus, else 0;
        ``at_theta2``: there, the standardised cost at the fitted Theta_2."""
        height, width = self.extent.height(), self.extent.width()
        for y, x in ti.ndrange(*ti.static(self.extent.bucket)):
            if y < height and x < width:
                w = 0.0
                z = 0.0
                if phi[y, x] < 0 and phi_plus[y, x] < 0:
                    xf, yf = ti.cast(x, ti.f32), ti.cast(y, ti.f32)
                    if ti.abs(consensus[y, x] - shapes.value(0, xf, yf)) >= near:
                        w = 1.0
                        z = self._z(cost, y, x, shapes.value(1, xf, yf))
                self.swept[y, x] = w
                self.at_theta2[y, x] = z

    @ti.func
    def _accumulate(self, cost: ti.template()):
        """``rows``: per row, the swept pixels' standardised cost summed at every candidate,
        their ``at_theta2`` summed, and their count (a thread per row and column of sums)."""
        C = ti.static(self.C)
        height, width = self.extent.height(), self.extent.width()
        for y, k in ti.ndrange(self.extent.bucket[0], C + 2):
            if y < height:
                s = 0.0
                for x in range(width):
                    if k < C:
                        s += self.swept[y, x] * ((cost[y, x, k] - self.centre[y, x])
                                                 * self.inv_spread[y, x])
                    elif k == C:
                        s += self.at_theta2[y, x]
                    else:
                        s += self.swept[y, x]
                self.rows[y, k] = s

    @ti.func
    def _reduce(self):
        """``totals``: ``rows`` summed over the image's rows, in row order."""
        height = self.extent.height()
        for k in range(self.C + 2):
            t = 0.0
            for y in range(height):
                t += self.rows[y, k]
            self.totals[k] = t

    def _set_plane(self, shapes, c):
        """Theta_2 := the fronto-parallel plane at cyclopean disparity ``c``."""
        theta = self.extent.pool.read(shapes.theta)
        theta[1] = 0.0
        theta[1, 5] = c
        self.extent.pool.write(shapes.theta, theta)

    def run(self, iteration, params, cost, shapes, phi, phi_plus, consensus):
        """After the fit of iteration ``iteration`` (1-based), when a sweep is :func:`due`:
        sweep the visible background (``phi < 0`` and ``phi_plus < 0``) and set Theta_2 to
        the plane :func:`choose_plane` picks.  Returns the plane's disparity (cyclopean), or
        None when Theta_2 is kept.  Reads ``c_max + 2`` numbers back to the host."""
        if not due(iteration, params):
            return None
        self._sweep(cost, shapes, phi, phi_plus, consensus, NEAR)
        c = choose_plane(self.extent.pool.read(self.totals).astype(np.float64), params.background_sweep,
                         self.H * self.W)
        if c is not None:
            self._set_plane(shapes, c)
        return c


def due(iteration, params):
    """Whether the sweep runs after the fit of iteration ``iteration`` (1-based): in each of
    the first ``params.reinit_every`` iterations and then every ``reinit_every``; never with
    ``params.background_sweep`` = 0."""
    every = params.reinit_every
    return params.background_sweep > 0 and (iteration <= every or iteration % every == 0)


def choose_plane(totals, margin, pixels):
    """The plane (cyclopean disparity, :func:`plane_vertex`) from a sweep's ``totals``: the
    standardised cost summed at each of the ``c_max`` candidates, at the fitted Theta_2, and
    the swept pixels' count.  None unless its mean lies more than ``margin`` below the fitted
    Theta_2's, it is a distinct dip (:func:`distinct_dip`) and at least ``MIN_SHARE`` of the
    image's ``pixels`` were swept."""
    C = len(totals) - 2
    n = totals[C + 1]
    if n < max(1.0, MIN_SHARE * pixels):
        return None
    mean = totals[:C] / n
    k = int(np.argmin(mean))
    if not (mean[k] < totals[C] / n - margin and distinct_dip(mean, k)):
        return None
    return plane_vertex(mean, k)


def distinct_dip(mean, k):
    """Whether candidate ``k`` of the swept curve ``mean`` is a distinct dip (``WIDTH``)."""
    half = mean[k] + 0.5 * (float(np.mean(mean)) - mean[k])
    return int(np.count_nonzero(mean < half)) <= max(2, WIDTH * len(mean))


def plane_vertex(mean, k):
    """Cyclopean disparity of the vertex of the parabola through ``mean[k - 1 .. k + 1]``
    (within half a candidate of ``k + 1``; ``k + 1`` at the range's ends or on a flat
    curve)."""
    c = k + 1.0
    if 0 < k < len(mean) - 1:
        t = vertex_offset(mean[k - 1], mean[k], mean[k + 1], 0.0)
        if math.isfinite(t):
            c += min(max(t, -0.5), 0.5)
    return c
