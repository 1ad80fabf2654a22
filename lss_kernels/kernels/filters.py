"""Separable Gaussian-derivative filters on lane planes, with symmetric borders.

The Gaussian ``g`` and its first two derivatives are sampled on ``-half .. half`` (``half =
ceil(3.5 sigma)``).  A 2-D derivative is a row pass (along x) followed by a column pass (along
y).  The row pass reads a block of pixels and its window of ``half`` pixels on either side once
for every order it is asked for, and stores each order into a row-filtered scratch lane plane
that carries ``half`` reflected rows above and below the image, so that the column pass reads
it unclamped.  Borders are symmetric (MATLAB's 'symmetric', numpy's ``pad(mode="symmetric")``):
the Neumann condition of the level set's Eq. 2.

Nothing here knows of the paper: the level set filters phi with it (normal, curvature) and the
boundary weight B (grad B).
"""
import math

import numpy as np
import taichi as ti

from . import lanes

__all__ = ["GaussianFilters", "gaussian_taps", "mirror", "reflect"]


def gaussian_taps(sigma, half_width=None):
    """Sampled Gaussian ``g`` (sums to 1) and its first and second derivatives on
    ``-half_width .. half_width`` (default ``ceil(3.5 sigma)``)."""
    if half_width is None:
        half_width = int(math.ceil(3.5 * sigma))
    i = np.arange(-half_width, half_width + 1, dtype=np.float64)
    g = np.exp(-i ** 2 / (2 * sigma ** 2))
    g /= g.sum()
    g1 = -i / sigma ** 2 * g
    g2 = (i ** 2 / sigma ** 4 - 1 / sigma ** 2) * g
    return g, g1, g2


@ti.func
def mirror(i, n):
    """One symmetric reflection at the borders of ``0 .. n - 1``: -1 -> 0, -2 -> 1,
    n -> n - 1; exact for ``-n <= i < 2 n``, no modulo."""
    return -1 - i if i < 0 else (2 * n - 1 - i if i >= n else i)


@ti.func
def reflect(i, n):
    """:func:`mirror` for any offset: the reflection repeats beyond one image width (only
    then the costly integer modulo).  Indices inside the image skip both."""
    j = i
    if i < 0 or i >= n:
        if i < -n or i >= 2 * n:
            j = i % (2 * n)
            if j < 0:
                # Taichi's algebraic simplification can turn (2 p - 1) % 2 into C's -1
                j += 2 * n
        j = mirror(j, n)
    return j


@ti.data_oriented
class GaussianFilters:
    """Gaussian-derivative filters of ``(H, W)`` planes, a block of ``lanes`` pixels per loop
    index; owns the row-filtered scratch (one lane plane per derivative order 0, 1, 2).

    Use inside a kernel: :meth:`rows` (the row pass of a plane into the scratch, for the
    orders asked), then :meth:`columns` per block (the column pass of one scratch plane).
    """

    def __init__(self, pool, height, width, sigma):
        self.H, self.W = int(height), int(width)
        self.extent = pool.extent(self.H, self.W)
        g, g1, g2 = gaussian_taps(sigma)
        self.half = (len(g) - 1) // 2
        self.tap_values = np.stack([g, g1, g2]).astype(np.float32).tolist()
        self.lanes = lanes.lanes_for_arch()
        # the row pass's output per order, with ``half`` reflected rows above and below, in
        # the bucket's shape (the image's size is read at run time)
        bucket_h, bucket_w = self.extent.bucket
        # the blocks of the bucket's rows: the row pass's loop (over the image's, at run time)
        self.bucket_blocks = (bucket_h, lanes.block_count(bucket_w, self.lanes))
        self.scratch = [lanes.lane_plane(pool, bucket_h, bucket_w, self.lanes, self.half,
                                         bucket=True)
                        for _ in range(3)]

    def _weights(self, orders, i):
        """``(j, w_i, odd)`` for each of ``orders``: the weight of taps +-i of the derivative
        of ``orders[j]``, and whether it weighs the difference of the two samples (the odd
        order) rather than their sum."""
        return tuple((j, float(self.tap_values[order][self.half + i]), int(order == 1))
                     for j, order in enumerate(orders))

    @ti.func
    def _taps(self, out: ti.template(), before: ti.template(), after: ti.template(),
              i: ti.template(), orders: ti.template()):
        """Taps +-i of the derivatives of ``orders``, added to ``out``: w_i (before + after)
        for the even orders, w_i (before - after) for the odd one (``before`` = src at
        pos - i, ``after`` at pos + i).  The taps are compile-time constants, and each pair
        of samples is read once for all orders (one call per tap, not per tap and order:
        the front end visits 40% fewer nodes for a filter pass)."""
        pair = [before + after, before - after]
        for j, w, odd in ti.static(self._weights(orders, i)):
            out[j] += w * pair[odd]

    @ti.func
    def _shifted(self, window: ti.template(), i: ti.template()):
        """The block's pixels moved by ``i``, from its filter window."""
        return lanes.take(window, ti.static(self.half + i), self.lanes)

    @ti.func
    def row_filters(self, src: ti.template(), y, b, orders: ti.template()):
        """Convolutions along x of ``src`` (a plane) with the Gaussian derivatives of
        ``orders`` for the pixels of block ``b`` of row ``y``: one lane vector per order.  The
        block's window (its pixels and ``half`` on either side) is read once, indices
        reflected only for the blocks within the half-width of the border."""
        n = ti.static(self.lanes + 2 * self.half)
        width = self.extent.width()
        x0 = b * self.lanes - self.half
        window = ti.Vector.zero(ti.f32, n)
        if 0 <= x0 and x0 + n <= width:
            for k in ti.static(range(n)):
                window[k] = src[y, x0 + k]
        else:           # a loop, not unrolled: this branch would double the compile time
            for k in range(n):
                window[k] = src[y, reflect(x0 + k, width)]
        centre = self._shifted(window, 0)
        out = [ti.static(float(self.tap_values[o][self.half])) * centre
               for o in ti.static(orders)]
        for i in ti.static(range(1, self.half + 1)):
            before = self._shifted(window, -i)
            after = self._shifted(window, i)
            self._taps(out, before, after, i, orders)
        return out

    @ti.func
    def columns(self, order: ti.template(), y, b, orders: ti.template()):
        """Convolutions along y of block ``b`` of row ``y`` of the scratch that holds the row
        pass of ``order``, with the Gaussian derivatives of ``orders``: one lane vector per
        order.  The scratch's margin rows hold the reflection, so no index is clamped."""
        src = ti.static(self.scratch[order])
        centre = src[y, b]
        out = [ti.static(float(self.tap_values[o][self.half])) * centre
               for o in ti.static(orders)]
        for i in ti.static(range(1, self.half + 1)):
            before = src[y - i, b]
            after = src[y + i, b]
            self._taps(out, before, after, i, orders)
        return out

    @ti.func
    def _put(self, scratch: ti.template(), y, b, value, height):
        """Block ``b`` of row ``y`` of the scratch <- value, and of the margin rows that
        reflect row y (``height``: the image's rows)."""
        scratch[y, b] = value
        if height >= self.half:
            if y < self.half:
                scratch[-1 - y, b] = value
            if y >= height - self.half:
                scratch[2 * height - 1 - y, b] = value
        else:           # images fewer rows high than ``half``: the reflection repeats
            for m in range(-self.half, 0):
                if reflect(m, height) == y:
                    scratch[m, b] = value
            for m in range(height, height + self.half):
                if reflect(m, height) == y:
                    scratch[m, b] = value

    @ti.func
    def rows(self, src: ti.template(), orders: ti.template(), where: ti.template(),
             outside: ti.template()):
        """The row pass of ``src`` (an ``(H, W)`` plane) for each of ``orders`` (ascending,
        from 0) into the scratch of that order, a block of pixels at a time (a parallel loop:
        call it at kernel scope).  ``where``: None, or a ``(rows, blocks)`` plane whose zeros
        mark the blocks that get only the orders in ``outside`` (a sub-tuple of ``orders``,
        possibly empty; the others keep what their scratch held)."""
        height = self.extent.height()
        blocks = (self.extent.width() + self.lanes - 1) // self.lanes
        for y, b in ti.ndrange(*ti.static(self.bucket_blocks)):
            if y < height and b < blocks:
                if ti.static(not isinstance(where, ti.Field)):
                    self._row_block(src, y, b, orders, height)
                elif where[y, b] != 0:
                    self._row_block(src, y, b, orders, height)
                elif ti.static(len(outside) > 0):
                    self._row_block(src, y, b, outside, height)

    @ti.func
    def _row_block(self, src: ti.template(), y, b, orders: ti.template(), height):
        out = self.row_filters(src, y, b, orders)
        for j in ti.static(range(len(orders))):
            self._put(self.scratch[orders[j]], y, b, out[j], height)
