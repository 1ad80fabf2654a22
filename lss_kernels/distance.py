"""Exact Euclidean distance transforms as kernels (Felzenszwalb & Huttenlocher, 2012).

The squared distance to the nearest feature is computed one axis at a time: every line along
an axis is an independent 1-D lower-envelope problem, so each pass is a data-parallel loop over
lines with a serial sweep along the line (a GPU thread per line).  Used for B_occ (3-D), B_mono
and the signed-distance re-initialisation of phi (2-D).
"""

import taichi as ti

INF = 1e20

__all__ = ["DistanceTransform", "INF"]


@ti.data_oriented
class DistanceTransform:
    """Squared EDT of a field of shape ``(n0, n1, n2)`` (2-D maps use ``n2 = 1``).

    ``run(f)`` expects ``f = 0`` at features and ``INF`` elsewhere and overwrites it with the
    squared distance (in voxel units, all axes weighted 1) to the nearest feature.  Lines are
    processed in batches so that the scratch memory stays at ``batch`` lines.
    """

    def __init__(self, shape, max_scratch: int = 1 << 22):
        self.shape = tuple(int(s) for s in shape)
        longest = max(self.shape)
        total = self.shape[0] * self.shape[1] * self.shape[2]
        # the most lines of any processed axis (an axis of length 1 is skipped)
        lines = max([total // n for n in self.shape if n > 1] or [1])
        self.batch = max(1, min(lines, max_scratch // longest))
        self.v = ti.field(ti.i32)
        self.z = ti.field(ti.f32)
        self.g = ti.field(ti.f32)
        builder = ti.FieldsBuilder()
        builder.dense(ti.ij, (self.batch, longest)).place(self.v, self.g)
        builder.dense(ti.ij, (self.batch, longest + 1)).place(self.z)
        self._tree = builder.finalize()
        self.nbytes = 4 * self.batch * (2 * longest + longest + 1)

    def destroy(self) -> None:
        """Free the scratch memory (the object cannot be used afterwards)."""
        self._tree.destroy()

    @ti.func
    def _index(self, axis: ti.template(), line: ti.i32, i: ti.i32):
        n0, n1, n2 = ti.static(self.shape)
        a = 0
        b = 0
        c = 0
        if ti.static(axis == 0):
            a, b, c = i, line // n2, line % n2
        elif ti.static(axis == 1):
            a, b, c = line // n2, i, line % n2
        else:
            a, b, c = line // n1, line % n1, i
        return a, b, c

    @ti.kernel
    def _pass(self, f: ti.template(), axis: ti.template(), start: ti.i32, count: ti.i32):
        n = ti.static(self.shape[axis])
        for t in range(count):
            line = start + t
            for i in range(n):
                a, b, c = self._index(axis, line, i)
                self.g[t, i] = f[a, b, c]
            # lower envelope of the parabolas rooted at (q, g[q]); z[0] = -INF is a sentinel
            # that no intersection reaches, since |g| <= INF keeps |s| < INF / 2 + n
            k = 0
            self.v[t, 0] = 0
            self.z[t, 0] = -INF
            self.z[t, 1] = INF
            for q in range(1, n):
                fq = self.g[t, q] + ti.cast(q * q, ti.f32)
                p = self.v[t, k]
                s = (fq - (self.g[t, p] + ti.cast(p * p, ti.f32))) / ti.cast(2 * (q - p), ti.f32)
                while s <= self.z[t, k]:
                    k -= 1
                    p = self.v[t, k]
                    s = (fq - (self.g[t, p] + ti.cast(p * p, ti.f32))) / ti.cast(2 * (q - p), ti.f32)
                k += 1
                self.v[t, k] = q
                self.z[t, k] = s
                self.z[t, k + 1] = INF
            k = 0
            for q in range(n):
                while self.z[t, k + 1] < ti.cast(q, ti.f32):
                    k += 1
                p = self.v[t, k]
                a, b, c = self._index(axis, line, q)
                f[a, b, c] = ti.min(ti.cast((q - p) * (q - p), ti.f32) + self.g[t, p], INF)

    def run(self, f) -> None:
        n0, n1, n2 = self.shape
        for axis in range(3):
            if self.shape[axis] == 1:
                continue
            lines = n0 * n1 * n2 // self.shape[axis]
            for start in range(0, lines, self.batch):
                self._pass(f, axis, start, min(self.batch, lines - start))
