"""Exact Euclidean distance transforms as kernels (Felzenszwalb & Huttenlocher, 2012).

The squared distance to the nearest feature is computed one axis at a time: every line along
an axis is an independent 1-D lower-envelope problem, so each pass is a data-parallel loop over
lines with a serial sweep along the line (a GPU thread per line).  Used for B_occ (3-D), B_mono
and the signed-distance re-initialisation of phi (2-D).
"""

import taichi as ti

from . import backend

INF = 1e20

__all__ = ["DistanceTransform", "INF"]


@ti.data_oriented
class DistanceTransform:
    """Squared EDT of the ``(n0, n1, n2)`` corner of fields of shape ``shape`` (2-D maps use
    ``n2 = 1``).

    ``run(f, (n0, n1))`` expects ``f = 0`` at features and ``INF`` elsewhere in that corner
    and overwrites it with the squared distance (in voxel units, all axes weighted 1) to the
    nearest feature; ``n2`` is ``f``'s third axis, ``n0`` and ``n1`` are read at run time, so
    the passes compile once for every ``n0 x n1`` of a size bucket (``shape``: the bucket's).
    Lines are processed in batches so that each of the three scratch buffers stays within
    ``max_scratch`` elements (a line of length n takes n + 1).
    """

    def __init__(self, shape, max_scratch: int = 1 << 22):
        self.shape = tuple(int(s) for s in shape)
        total = self.shape[0] * self.shape[1] * self.shape[2]
        axes = [n for n in self.shape if n > 1] or [1]
        # a line of length n takes n + 1 elements of each buffer (z has the extra one); a pass
        # takes as many lines as fit, so a short axis runs in few launches, not one launch per
        # ``max_scratch / longest`` lines (B_occ's c axis at 580x340, c_max 25: 13 launches,
        # not 290)
        need = max((total // n) * (n + 1) for n in axes)
        self.size = max(min(int(max_scratch), need), max(axes) + 1)
        self.v = ti.field(ti.i32)
        self.z = ti.field(ti.f32)
        self.g = ti.field(ti.f32)
        builder = ti.FieldsBuilder()
        builder.dense(ti.i, self.size).place(self.v, self.g, self.z)
        self._tree = builder.finalize()
        self._generation = backend.allocated(self)
        self.nbytes = 4 * 3 * self.size

    def destroy(self) -> None:
        """Free the scratch memory (the object cannot be used afterwards); after a
        :func:`~lss_kernels.kernels.backend.restart` Taichi has freed it already."""
        if self._generation == backend.generation():
            self._tree.destroy()
        backend.released(self)

    @ti.func
    def _index(self, axis, line, i, n1, n2: ti.template()):
        a = 0
        b = 0
        c = 0
        if axis == 0:
            a, b, c = i, line // n2, line % n2
        elif axis == 1:
            a, b, c = line // n2, i, line % n2
        else:
            a, b, c = line // n1, line % n1, i
        return a, b, c

    @ti.kernel
    def _pass(self, f: ti.template(), axis: ti.i32, start: ti.i32, count: ti.i32,
              n0: ti.i32, n1: ti.i32):
        """The 1-D transforms of lines ``start .. start + count - 1`` along ``axis`` (read
        at run time: one kernel for the three axes)."""
        n2 = ti.static(f.shape[2])
        n = n2
        if axis == 0:
            n = n0
        elif axis == 1:
            n = n1
        for t in range(count):
            line = start + t
            o = t * (n + 1)                   # this line's stretch of the buffers
            near = 0                          # whether the line holds a finite value
            for i in range(n):
                a, b, c = self._index(axis, line, i, n1, n2)
                value = f[a, b, c]
                self.g[o + i] = value
                if value < INF:
                    near = 1
            if near == 1:
                self._envelope(f, axis, line, o, n, n1, n2)

    @ti.func
    def _envelope(self, f: ti.template(), axis, line, o, n, n1, n2: ti.template()):
        """The 1-D transform of a line loaded into ``g`` from ``o`` on, written back into
        ``f``.  A line of INF alone is left as it is: every value would be
        ``min((q - p)^2 + INF, INF) = INF`` again (the square vanishes in INF's rounding)."""
        # lower envelope of the parabolas rooted at (q, g[q]); z[0] = -INF is a sentinel
        # that no intersection reaches, since |g| <= INF keeps |s| < INF / 2 + n
        k = 0
        self.v[o] = 0
        self.z[o] = -INF
        self.z[o + 1] = INF
        for q in range(1, n):
            fq = self.g[o + q] + ti.cast(q * q, ti.f32)
            p = self.v[o + k]
            s = (fq - (self.g[o + p] + ti.cast(p * p, ti.f32))) / ti.cast(2 * (q - p), ti.f32)
            while s <= self.z[o + k]:
                k -= 1
                p = self.v[o + k]
                s = (fq - (self.g[o + p] + ti.cast(p * p, ti.f32))) / ti.cast(2 * (q - p),
                                                                             ti.f32)
            k += 1
            self.v[o + k] = q
            self.z[o + k] = s
            self.z[o + k + 1] = INF
        k = 0
        for q in range(n):
            while self.z[o + k + 1] < ti.cast(q, ti.f32):
                k += 1
            p = self.v[o + k]
            a, b, c = self._index(axis, line, q, n1, n2)
            f[a, b, c] = ti.min(ti.cast((q - p) * (q - p), ti.f32) + self.g[o + p], INF)

    def run(self, f, size) -> None:
        """The transform of the ``size`` (``(n0, n1)``) corner of ``f``, in place."""
        n0, n1 = (int(v) for v in size)
        n2 = f.shape[2]
        for axis, n in enumerate((n0, n1, n2)):
            if n == 1:
                continue
            lines = n0 * n1 * n2 // n
            batch = max(1, self.size // (n + 1))
            for start in range(0, lines, batch):
                self._pass(f, axis, start, min(batch, lines - start), n0, n1)
