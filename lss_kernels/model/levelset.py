"""The level-set function phi and its evolution: Eq. 2 of the paper.

    dphi/dt = delta_eps(phi) [ -M(x, y, Theta_1) + M(x - delta_theta, y, Theta_2)
                               + mu ( B(x, y, Theta_1) kappa + N . grad B ) ]

with delta_eps(phi) = (1/pi) / (1 + phi^2), kappa = div(grad phi / |grad phi|) and
N = grad phi / |grad phi|.  Derivatives are separable Gaussian-derivative filters
(``curvature_sigma``, half-width 3.5 sigma, symmetric borders: the Neumann condition of Eq. 2);
kappa is clipped to +-``curvature_clip`` and the boundary term to +-``boundary_clip``.  M is the
size-3 patch cost (level 1 of the hierarchy) read with linear interpolation in x and c.  After
every step phi is median-filtered (``median_size`` squared, symmetric borders) and every
``reinit_every`` steps re-initialised to ``phi_scale`` times a signed distance (the
re-initialisation comes first, as in the authors' release).

Frame: cyclopean ``(H, W)`` fields indexed ``[y, x]``; phi > 0 is the foreground.  The
separable filters' row-filtered scratch and phi's derivatives (``phi_x``, ``kappa``,
``normal_x``, ``normal_y``) are lane planes (:mod:`.lanes`): the column passes and the Eq. 2 step
run a block of horizontally adjacent pixels per loop index.
"""
import math

import numpy as np
import taichi as ti

from ..kernels import lanes
from .costs import gaussian_taps
from ..kernels.distance import INF, DistanceTransform

__all__ = ["LevelSet", "median_network"]


def _batcher(size, block=1):
    """Comparator pairs of Batcher's odd-even merge sort of ``size`` (a power of two) values,
    omitting the sorts of the first ``block``-long runs (taken as already sorted)."""
    pairs = []

    def merge(lo, length, step):
        double = step * 2
        if double < length:
            merge(lo, length, double)
            merge(lo + step, length, double)
            for i in range(lo + step, lo + length - step, double):
                pairs.append((i, i + step))
        else:
            pairs.append((lo, lo + step))

    def sort(lo, length):
        if length > block:
            half = length // 2
            sort(lo, half)
            sort(lo + half, half)
            merge(lo, length, 1)

    sort(0, size)
    return pairs


def _next_pow2(n):
    size = 1
    while size < n:
        size *= 2
    return size


def _resolve_padding(slots, pairs):
    """Run ``pairs`` symbolically over ``slots`` (``"lo"`` = -inf, ``"hi"`` = +inf, anything
    else a value): comparators with a padding input become no-ops or fixed swaps.  Returns
    the ops ``("cmp", a, b)`` / ``("swap", a, b)`` and the final slot contents."""
    cur = list(slots)
    ops = []
    for a, b in pairs:
        ka, kb = cur[a], cur[b]
        if ka == "lo" or kb == "hi":
            continue                                   # already in order
        if ka == "hi" or kb == "lo":
            cur[a], cur[b] = kb, ka                    # known outcome: a swap
            ops.append(("swap", a, b))
            continue
        ops.append(("cmp", a, b))
    return ops, cur


def _prune(ops, needed):
    """Keep only what the positions ``needed`` depend on; ``("cmp", a, b, keep_min,
    keep_max)``."""
    needed = set(needed)
    kept = []
    for op, a, b in reversed(ops):
        if op == "swap":
            if a in needed or b in needed:
                kept.append((op, a, b, True, True))
                na, nb = b in needed, a in needed
                needed -= {a, b}
                needed |= ({a} if na else set()) | ({b} if nb else set())
            continue
        keep_min, keep_max = a in needed, b in needed
        if keep_min or keep_max:
            kept.append((op, a, b, keep_min, keep_max))
            needed |= {a, b}
    return kept[::-1]


def _merge_network(lengths, ranks):
    """A pruned network that merges sorted runs of ``lengths`` far enough to place the given
    ``ranks`` of their union (0-based, ascending order).

    Each run is padded to ``block`` (the next power of two) slots, the runs to a power of
    two, and the padding is split between -inf and +inf so that rank ``r`` ends at position
    ``n_low + r``; the merge stages of Batcher's odd-even merge sort then run with every
    comparator that touches padding resolved, pruned to what the ranks depend on.  The
    positions no op touches are then dropped and the rest renumbered.  Returns ``(slots,
    ops, positions)``: the initial content of each (renumbered) position (``"lo"``/``"hi"``
    padding or ``(run, rank)``), the ops (see :func:`median_network`) and where each of
    ``ranks`` ends."""
    block = _next_pow2(max(lengths))
    size = _next_pow2(len(lengths) * block)
    n_low = (size - sum(lengths)) // 2
    slots, lows = [], n_low
    for run in range(size // block):
        length = lengths[run] if run < len(lengths) else 0
        n_lo = min(lows, block - length)
        lows -= n_lo
        slots += ["lo"] * n_lo + [(run, r) for r in range(length)] + \
            ["hi"] * (block - length - n_lo)
    positions = tuple(n_low + r for r in ranks)
    ops, _ = _resolve_padding(slots, _batcher(size, block))
    ops = _prune(ops, positions)
    # drop the positions no op touches (padding, values that cannot reach a rank) and
    # renumber: the networks run on short vectors
    used = sorted({p for op in ops for p in op[1:3]} | set(positions))
    new = {p: i for i, p in enumerate(used)}
    ops = tuple((op, new[a], new[b], lo, hi) for op, a, b, lo, hi in ops)
    return tuple(slots[p] for p in used), ops, tuple(new[p] for p in positions)


def median_network(k):
    """Selection networks for the medians of a tile of ``tile`` horizontally adjacent
    ``k x k`` windows (``k`` odd; ``tile`` 4, or 2 for ``k = 3``), sharing work between the
    windows (after Adams, "Fast median filters using separable sorting networks", 2021).

    1. ``column_ops``: sort each window column of ``k`` values (Batcher over the next power
       of two, the padding +inf, pruned) -- shared by every window that contains the column.
    2. A binary tree over the tile's windows.  A node holds the columns that all its windows
       contain; it merges those its parent did not hold (first into one run, when there are
       several) with its parent's survivors, only as far as the ranks that can still be the
       median of one of its windows: with ``low`` values known to lie below, and each window
       still to add ``rest`` values, held rank ``r`` can only be the median
       ``m = (k*k - 1) // 2`` if ``low + r <= m <= low + r + rest``; the others are dropped.
       At a leaf (one window, ``rest = 0``) one rank is left: the median.

    A node is ``(columns, pre, slots, ops, keep, children, output)``: the offsets of its new
    columns from the centre column of the tile's first window, ``pre = (slots, ops,
    positions)`` merging them into one run (``()`` when there is one column, or at the root,
    whose ``slots`` take the columns as runs directly), the merge with the parent's
    survivors (run 0) and that run (run 1), the positions of the survivors in the merged
    vector, the child nodes and, at a leaf, the window's index in the tile (-1 elsewhere).
    For ``k = 7`` this takes 75.25 comparators per window after the column sort (78.75 ops
    with the fixed swaps), against 112.5 for pairs of windows (Adams' two-window tile) and
    210 for one window alone.

    Ops are ``(op, a, b, keep_min, keep_max)`` with ``op`` ``"cmp"`` (position ``a`` gets
    the minimum, ``b`` the maximum, each only if still needed) or ``"swap"`` (a comparator
    whose outcome padding decides).  Returns ``(column_ops, tile, root)``.
    """
    if k < 3 or k % 2 == 0:
        raise ValueError(f"median_network: k must be odd and >= 3, got {k}")
    block = _next_pow2(k)
    column_ops, _ = _resolve_padding(list(range(k)) + ["hi"] * (block - k), _batcher(block))
    column_ops = tuple((op, a, b, True, True) for op, a, b in column_ops)
    half, m = k // 2, (k * k - 1) // 2
    tile = 4 if k >= 5 else 2

    def common(a, b):
        """Columns shared by windows a .. b - 1 of the tile."""
        return set(range(b - 1 - half, a + half + 1))

    def node(a, b, held, low, parent_columns):
        shared = common(a, b)
        columns = sorted(shared - parent_columns)
        rest = k * (k - len(shared))
        n = k * len(columns)
        pre = ()
        if held == 0:
            runs = [k] * len(columns)
        elif len(columns) == 1:
            runs = [held, k]
        else:
            pre = _merge_network([k] * len(columns), range(n))
            runs = [held, n]
        first, last = max(m - low - rest, 0), min(m - low, held + n - 1)
        slots, ops, keep = _merge_network(runs, range(first, last + 1))
        if b - a == 1:
            children, output = (), a
        else:
            mid = (a + b) // 2
            children = tuple(node(lo, hi, len(keep), low + first, shared)
                             for lo, hi in ((a, mid), (mid, b)))
            output = -1
        return (tuple(columns), pre, slots, ops, keep, children, output)

    return column_ops, tile, node(0, tile, 0, 0, set())


@ti.data_oriented
class LevelSet:
    """Owns phi, its derivatives, the boundary-term maps and the Eq. 2 step."""

    def __init__(self, pool, height, width, params):
        self.H, self.W = int(height), int(width)
        H, W = self.H, self.W
        f = lambda: pool.field(ti.f32, (H, W))
        self.phi = f()
        self.phi_next = f()
        self.b_map = f()
        g, g1, g2 = gaussian_taps(params.curvature_sigma)
        self.half = (len(g) - 1) // 2
        self.lanes = lanes.lanes_for_arch()
        self.blocks = lanes.block_count(W, self.lanes)
        plane = lambda margin_rows=0: lanes.lane_plane(pool, H, W, self.lanes, margin_rows)
        # lane planes: the sign of dphi/dx orients the occlusion ray cast; kappa and N enter
        # the Eq. 2 step
        self.phi_x, self.kappa, self.normal_x, self.normal_y = (plane() for _ in range(4))
        # row-filtered scratch of the separable filters (phi: three orders; B: two), with
        # ``half`` reflected rows above and below: the column passes read it unclamped
        self._t0, self._t1, self._t2 = (plane(self.half) for _ in range(3))
        self.flipped = pool.field(ti.i32, ())
        self.changed = pool.field(ti.i32, ())
        self.reference_sign = pool.field(ti.i8, (H, W))
        self.area = pool.field(ti.i32, ())
        self.tap_values = np.stack([g, g1, g2]).astype(np.float32).tolist()
        self.curvature_clip = float(params.curvature_clip)
        self.boundary_clip = float(params.boundary_clip)
        self.median_size = int(params.median_size)
        if self.median_size > 1:
            self._network = median_network(self.median_size)
            # the sorted window columns in blocks of ``lanes`` rows (rank r of row
            # ``yb lanes + l`` at r * lanes + l), every column of the tiles and ``k // 2``
            # reflected columns on either side: the merge runs in SIMD lanes over the rows
            # of a block and reads a tile's columns at compile-time offsets, unreflected
            tile, k = self._network[1], self.median_size
            self._row_blocks = lanes.block_count(H, self.lanes)
            self._tiles = lanes.block_count(W, tile)
            self._sorted = pool.vector(k * self.lanes, ti.f32,
                                       (self._row_blocks, self._tiles * tile + 2 * (k // 2)),
                                       offset=(0, -(k // 2)))
            # the medians of a block's rows, stored whole: LLVM packs the tree's comparators
            # into SIMD lanes only from stores of whole vectors (scalar stores into phi's
            # rows left them scalar, 9.4 ms against 8.3 for the tile of one row)
            self._medians = pool.vector(self.lanes, ti.f32,
                                        (self._row_blocks, self._tiles * tile))
        self.scale = float(params.phi_scale)
        # squared distances of the re-initialisation (also B_mono's scratch, see costs)
        self.distance_map = pool.field(ti.f32, (H, W, 1))
        self.distance = None

    def setup(self):
        """Allocate the re-initialisation scratch; call once the pool is finalised."""
        self.distance = DistanceTransform((self.H, self.W, 1))

    @property
    def scratch_bytes(self):
        return self.distance.nbytes if self.distance is not None else 0

    def destroy(self):
        if self.distance is not None:
            self.distance.destroy()
            self.distance = None

    # ---------------------------------------------------------------- helpers
    @ti.func
    def _mirror(self, i, n):
        """One symmetric reflection at the borders of ``0 .. n - 1``: -1 -> 0, -2 -> 1,
        n -> n - 1 (MATLAB's 'symmetric', numpy's ``pad(mode="symmetric")``); exact for
        ``-n <= i < 2 n``, no modulo."""
        return -1 - i if i < 0 else (2 * n - 1 - i if i >= n else i)

    @ti.func
    def _reflect(self, i, n):
        """:meth:`_mirror` for any offset: the reflection repeats beyond one image width
        (only then the costly integer modulo).  Indices inside the image skip both."""
        j = i
        if i < 0 or i >= n:
            if i < -n or i >= 2 * n:
                j = i % (2 * n)
                if j < 0:
                    # Taichi's algebraic simplification can turn (2 p - 1) % 2 into C's -1
                    j += 2 * n
            j = self._mirror(j, n)
        return j

    @ti.func
    def _taps(self, before, after, i: ti.template(), order: ti.template()):
        """Taps +-i of the derivative of ``order``: w_i (before + after) for the even orders,
        w_i (before - after) for the odd one (``before`` = src at pos - i, ``after`` at
        pos + i).  The taps are compile-time constants, and each pair of samples is read
        once for all orders."""
        w = ti.static(float(self.tap_values[order][self.half + i]))
        value = w * (before + after)
        if ti.static(order == 1):
            value = w * (before - after)
        return value

    @ti.func
    def _row_filters(self, src: ti.template(), y, b, orders: ti.template()):
        """Convolutions along x of ``src`` (a plane) with the Gaussian derivatives of
        ``orders`` for the pixels of block ``b`` of row ``y``: one lane vector per order.  The
        block's window (its pixels and ``half`` on either side) is read once, indices
        reflected only for the blocks within the half-width of the border."""
        n = ti.static(self.lanes + 2 * self.half)
        x0 = b * self.lanes - self.half
        window = ti.Vector.zero(ti.f32, n)
        if 0 <= x0 and x0 + n <= self.W:
            for k in ti.static(range(n)):
                window[k] = src[y, x0 + k]
        else:           # a loop, not unrolled: this branch would double the compile time
            for k in range(n):
                window[k] = src[y, self._reflect(x0 + k, self.W)]
        centre = self._shifted(window, 0)
        out = [ti.static(float(self.tap_values[o][self.half])) * centre
               for o in ti.static(orders)]
        for i in ti.static(range(1, self.half + 1)):
            before = self._shifted(window, -i)
            after = self._shifted(window, i)
            for j in ti.static(range(len(orders))):
                out[j] += self._taps(before, after, i, orders[j])
        return out

    @ti.func
    def _shifted(self, window, i: ti.template()):
        """The block's pixels moved by ``i``, from its filter window."""
        return lanes.take(window, ti.static(self.half + i), self.lanes)

    @ti.func
    def _column_filters(self, src: ti.template(), y, b, orders: ti.template()):
        """Convolutions along y of block ``b`` of row ``y`` of the row-filtered scratch
        ``src`` (a lane plane) with the Gaussian derivatives of ``orders``: one lane vector
        per order.  The scratch's margin rows hold the reflection, so no index is clamped."""
        centre = src[y, b]
        out = [ti.static(float(self.tap_values[o][self.half])) * centre
               for o in ti.static(orders)]
        for i in ti.static(range(1, self.half + 1)):
            before = src[y - i, b]
            after = src[y + i, b]
            for j in ti.static(range(len(orders))):
                out[j] += self._taps(before, after, i, orders[j])
        return out

    @ti.func
    def _put(self, scratch: ti.template(), y, b, value):
        """Block ``b`` of row ``y`` of the scratch <- value, and of the margin rows that
        reflect row y."""
        scratch[y, b] = value
        if ti.static(self.H >= self.half):
            if y < self.half:
                scratch[-1 - y, b] = value
            if y >= self.H - self.half:
                scratch[2 * self.H - 1 - y, b] = value
        else:           # images fewer rows high than ``half``: the reflection repeats
            for m in range(-self.half, 0):
                if self._reflect(m, self.H) == y:
                    scratch[m, b] = value
            for m in range(self.H, self.H + self.half):
                if self._reflect(m, self.H) == y:
                    scratch[m, b] = value

    def image(self, plane):
        """One of the lane planes ``phi_x``, ``kappa``, ``normal_x``, ``normal_y`` as an
        ``(H, W)`` float32 array."""
        return lanes.to_image(plane, self.W)

    @ti.func
    def _rows3(self, src: ti.template()):
        """Along x, a block of pixels at a time: orders 0, 1, 2 of src into the three scratch
        lane planes (their margin rows: those of the reflected rows)."""
        for y, b in self.kappa:
            v0, v1, v2 = self._row_filters(src, y, b, (0, 1, 2))
            self._put(self._t0, y, b, v0)
            self._put(self._t1, y, b, v1)
            self._put(self._t2, y, b, v2)

    @ti.func
    def _columns_curvature(self):
        """Along y, a block of pixels at a time: the five derivatives of phi from the
        row-filtered scratch, and from them phi_x, the clipped curvature
        kappa = div(grad phi / |grad phi|) and the normal N = grad phi / |grad phi| (phi_y and
        the second derivatives are used here only).  Lanes past the right edge hold values
        of the reflected image: block kernels compute with them but never store them as
        pixels."""
        clip = self.curvature_clip
        for y, b in self.kappa:
            py, pyy = self._column_filters(self._t0, y, b, (1, 2))
            px, pxy = self._column_filters(self._t1, y, b, (0, 1))
            pxx = self._column_filters(self._t2, y, b, (0,))[0]
            norm = ti.sqrt(px * px + py * py) + 1e-10
            k = (pxx * py * py - 2.0 * px * py * pxy + pyy * px * px) / (norm * norm * norm)
            self.phi_x[y, b] = px
            self.kappa[y, b] = ti.min(ti.max(k, -clip), clip)
            self.normal_x[y, b] = px / norm
            self.normal_y[y, b] = py / norm

    @ti.func
    def _rows2(self, src: ti.template()):
        """:meth:`_rows3` with orders 0 and 1 (for grad B)."""
        for y, b in self.kappa:
            v0, v1 = self._row_filters(src, y, b, (0, 1))
            self._put(self._t0, y, b, v0)
            self._put(self._t1, y, b, v1)

    @ti.kernel
    def derivatives(self):
        """phi_x, kappa and N from the current phi (both passes in one launch)."""
        self._rows3(self.phi)
        self._columns_curvature()

    # ---------------------------------------------------------------- boundary weight
    @ti.func
    def _b_map(self, costs: ti.template(), shapes: ti.template()):
        L = ti.static(self.lanes)
        for y, b in self.kappa:
            theta_1 = shapes.value(0, lanes.columns(b, L), ti.cast(y, ti.f32))
            for lane in range(L):
                x = b * L + lane
                if x < self.W:
                    self.b_map[y, x] = costs.b_at(y, x, theta_1[lane])

    @ti.kernel
    def boundary_weight(self, costs: ti.template(), shapes: ti.template()):
        """B(x, y, Theta_1(x, y)) and the row pass of its gradient (the column pass runs in
        the Eq. 2 step, which alone needs grad B), in one launch."""
        self._b_map(costs, shapes)
        self._rows2(self.b_map)

    # ---------------------------------------------------------------- Eq. 2
    @ti.func
    def _cost_at(self, cost: ti.template(), y, x, c, C: ti.template()):
        """M(x, y, c) at real x and c (linear in both; clamped to the volume)."""
        xf = ti.min(ti.max(x, 0.0), self.W - 1.0)
        x0 = ti.min(ti.cast(ti.floor(xf), ti.i32), ti.max(self.W - 2, 0))
        x1 = ti.min(x0 + 1, self.W - 1)
        tx = xf - x0
        a = self._cost_at_pixel(cost, y, x0, c, C)
        b = self._cost_at_pixel(cost, y, x1, c, C)
        return (1.0 - tx) * a + tx * b

    @ti.func
    def _cost_at_pixel(self, cost: ti.template(), y, x, c, C: ti.template()):
        """M(x, y, c) at an integer x (a pixel): linear in c only (clamped to the volume)."""
        kf = ti.min(ti.max(c - 1.0, 0.0), C - 1.0)
        k0 = ti.min(ti.cast(ti.floor(kf), ti.i32), ti.max(C - 2, 0))
        k1 = ti.min(k0 + 1, C - 1)
        tk = kf - k0
        return (1.0 - tk) * cost[y, x, k0] + tk * cost[y, x, k1]

    @ti.kernel
    def _step(self, cost: ti.template(), C: ti.template(), shapes: ti.template(),
              occ: ti.template(), dt: ti.f32, mu: ti.f32):
        """phi_next from phi by Eq. 2, a block of pixels at a time: the boundary term for the
        whole block (grad B is the column pass of the separable filters, whose row pass ran
        in ``_rows2``), then each pixel's data term."""
        clip = self.boundary_clip
        L = ti.static(self.lanes)
        for y, b in self.kappa:
            b_x = self._column_filters(self._t1, y, b, (0,))[0]
            b_y = self._column_filters(self._t0, y, b, (1,))[0]
            b_map = lanes.block(self.b_map, y, b, L)
            bt = b_map * self.kappa[y, b] + self.normal_x[y, b] * b_x + \
                self.normal_y[y, b] * b_y
            bt = ti.min(ti.max(bt, -clip), clip)
            xs = lanes.columns(b, L)
            yf = ti.cast(y, ti.f32)
            theta_1 = shapes.value(0, xs, yf)
            theta_2 = shapes.value(1, xs, yf)
            for lane in range(L):     # not unrolled: compiles 3x faster, runs as fast
                x = b * L + lane
                if x < self.W:
                    xf = xs[lane]
                    p = self.phi[y, x]
                    m1 = self._cost_at_pixel(cost, y, x, theta_1[lane], C)
                    m2 = self._cost_at(cost, y, xf - occ.delta_theta[y, x], theta_2[lane], C)
                    dirac = (1.0 / math.pi) / (1.0 + p * p)
                    self.phi_next[y, x] = p + dt * dirac * (-m1 + m2 + mu * bt[lane])

    # ---------------------------------------------------------------- median, re-init
    @ti.func
    def _apply(self, v: ti.template(), ops: ti.template()):
        """Run a network's ``ops`` on the local vector ``v``, in place."""
        for op, a, b, keep_min, keep_max in ti.static(ops):
            if ti.static(op == "swap"):
                v[a], v[b] = v[b], v[a]
            else:
                lo = ti.min(v[a], v[b])
                hi = ti.max(v[a], v[b])
                if ti.static(keep_min):
                    v[a] = lo
                if ti.static(keep_max):
                    v[b] = hi

    @ti.func
    def _sort_columns(self, src: ti.template()):
        """Stage 1 of the median: every window column (symmetric borders), sorted, for a
        block of ``lanes`` rows at a time in SIMD lanes, the margin columns included.
        The networks are attributes read with ``ti.static``, not kernel arguments: Taichi
        hashes every template argument at each launch, which for these tuples of a few
        hundred comparators cost more than the kernel itself."""
        k, L = ti.static(self.median_size, self.lanes)
        column_ops = ti.static(self._network[0])
        for yb, x in self._sorted:
            xs = self._reflect(x, self.W)
            # the rows of the block's windows: k - 1 more than the block
            window = [src[self._reflect(yb * L + i - k // 2, self.H), xs]
                      for i in ti.static(range(L + k - 1))]
            v = [lanes.take(window, r, L) for r in ti.static(range(k))]
            self._apply(v, column_ops)
            self._sorted[yb, x] = ti.Vector([v[r][lane] for r in ti.static(range(k))
                                             for lane in ti.static(range(L))])

    @ti.func
    def _column(self, yb, t, c: ti.template()):
        """The sorted column ``c`` (a compile-time offset, possibly negative) of the tile
        ``t``'s first window for the rows of block ``yb``: ``k`` ranks, each a vector over
        the rows."""
        k, L = ti.static(self.median_size, self.lanes)
        ranks = self._sorted[yb, t * ti.static(self._network[1]) + c]
        return [lanes.take(ranks, r * L, L) for r in ti.static(range(k))]

    @ti.func
    def _load(self, slots: ti.template(), runs: ti.template()):
        """The initial values of a merge network, each a vector over a block's rows: padding
        as -+1e30, ``(run, rank)`` from the sorted ``runs``."""
        L = ti.static(self.lanes)
        v = [ti.Vector.zero(ti.f32, L) for _ in ti.static(range(len(slots)))]
        for i in ti.static(range(len(slots))):
            if ti.static(slots[i] == "lo"):
                v[i] = ti.Vector([-1e30 for _ in ti.static(range(L))])
            elif ti.static(slots[i] == "hi"):
                v[i] = ti.Vector([1e30 for _ in ti.static(range(L))])
            else:
                v[i] = runs[ti.static(slots[i][0])][ti.static(slots[i][1])]
        return v

    @ti.func
    def _start_count(self, count: ti.template()):
        """Zero ``flipped`` and ``area`` before a counting pass (kernel scope, serial)."""
        if ti.static(count):
            self.flipped[None] = 0
            self.area[None] = 0

    @ti.func
    def _store(self, dst: ti.template(), y, x, value, count: ti.template(),
               disparity: ti.template(), c_max):
        """dst[y, x] = value; with ``count``, first tally the sign flip against dst's previous
        value and the new foreground.  With ``disparity`` = ``(D, shapes)`` (not ``()``),
        also Eq. 3's D = Theta_1 where value > 0, else Theta_2, clamped to [0, c_max] (a
        quadratic can extrapolate outside the searched range).  ``c_max`` is a kernel
        argument, not a constant, so that the kernels do not depend on the disparity range
        (see :class:`lss_kernels.kernels.backend.FieldPool`)."""
        if ti.static(count):
            now = value > 0
            if now != (dst[y, x] > 0):
                self.flipped[None] += 1
            if now:
                self.area[None] += 1
        dst[y, x] = value
        if ti.static(len(disparity) > 0):
            D, shapes = ti.static(disparity)
            j = 0 if value > 0 else 1
            v = shapes.value(j, ti.cast(x, ti.f32), ti.cast(y, ti.f32))
            D[y, x] = ti.min(ti.max(v, 0.0), c_max)

    @ti.func
    def _descend(self, yb, t, held, node: ti.template()):
        """A node of the tile's tree below the root (see :func:`median_network`): merge its
        new columns with the parent's survivors ``held``; store the medians of a block's
        rows at a leaf, else pass the survivors on to the children."""
        columns_at, pre, slots, ops, keep, children, output = ti.static(node)
        columns = [self._column(yb, t, c) for c in ti.static(columns_at)]
        v = self._load(slots, [held, self._one_run(columns, pre)])
        self._apply(v, ops)
        if ti.static(output >= 0):
            self._medians[yb, t * ti.static(self._network[1]) + output] = v[ti.static(keep[0])]
        else:
            kept = self._gather(v, keep)
            for child in ti.static(children):
                self._descend(yb, t, kept, child)

    @ti.func
    def _one_run(self, columns: ti.template(), pre: ti.template()):
        """A node's new sorted columns as one sorted run (merged by ``pre``, if several)."""
        if ti.static(len(pre) == 0):
            return columns[0]
        else:
            v = self._load(pre[0], columns)
            self._apply(v, pre[1])
            return self._gather(v, pre[2])

    @ti.func
    def _gather(self, v, positions: ti.template()):
        """The entries of ``v`` at ``positions``, as a new list."""
        return [v[i] for i in ti.static(positions)]

    @ti.func
    def _median_of_columns(self):
        """Stage 2: the medians of a tile of horizontally adjacent windows from the sorted
        columns, through the tree of :func:`median_network`, for a block of rows at a time."""
        tile, root = ti.static(self._network[1:])
        columns_at, slots, ops, keep, children = ti.static(
            (root[0], root[2], root[3], root[4], root[5]))
        for yb, t in ti.ndrange(self._row_blocks, self._tiles):
            columns = [self._column(yb, t, c) for c in ti.static(columns_at)]
            v = self._load(slots, columns)
            self._apply(v, ops)
            kept = self._gather(v, keep)
            for child in ti.static(children):
                self._descend(yb, t, kept, child)

    @ti.func
    def _store_medians(self, dst: ti.template(), count: ti.template(),
                       disparity: ti.template(), c_max):
        """Stage 3: the medians into dst (and D, see :meth:`_store`).  With ``count``,
        ``flipped`` and ``area`` count the sign changes against dst's previous content and
        the pixels > 0."""
        self._start_count(count)
        for yb, x in self._medians:
            if x < self.W:
                medians = self._medians[yb, x]
                for lane in ti.static(range(self.lanes)):
                    y = yb * ti.static(self.lanes) + lane
                    if y < self.H:
                        self._store(dst, y, x, medians[lane], count, disparity, c_max)

    @ti.kernel
    def _copy(self, src: ti.template(), dst: ti.template(), count: ti.template(),
              disparity: ti.template(), c_max: ti.f32):
        """dst = src; with ``count`` and ``disparity``, as in :meth:`_store`."""
        self._start_count(count)
        for y, x in dst:
            self._store(dst, y, x, src[y, x], count, disparity, c_max)

    @ti.kernel
    def _features(self, src: ti.template(), foreground: ti.i32):
        for y, x in src:
            inside = src[y, x] > 0
            self.distance_map[y, x, 0] = 0.0 if inside == (foreground == 1) else INF

    @ti.kernel
    def _signed(self, phi: ti.template(), foreground: ti.i32, scale: ti.f32):
        # phi = scale * (distance to the other region - 1/2), the boundary lying between
        # pixel centres; the distance is capped at the image diagonal
        cap = ti.sqrt(ti.cast(self.H * self.H + self.W * self.W, ti.f32))
        for y, x in phi:
            inside = phi[y, x] > 0
            if inside == (foreground == 1):
                # d >= 1 (measured to the nearest pixel of the other region): signs are kept
                d = ti.min(ti.sqrt(self.distance_map[y, x, 0]), cap)
                phi[y, x] = (scale if foreground == 1 else -scale) * (d - 0.5)

    def reinitialise(self, phi):
        """phi <- phi_scale x signed distance of the region phi > 0, in place (the signs, and
        so the region, are kept)."""
        for region in (1, 0):
            self._features(phi, 1 - region)  # distance to the pixels of the other region
            self.distance.run(self.distance_map)
            self._signed(phi, region, self.scale)

    def median(self, src, dst, count=False, disparity=(), c_max=0.0):
        """dst = the ``median_size``-square median of src (symmetric borders); with
        ``count``, also the sign flips against dst's previous content (``flipped``) and the
        pixels > 0 (``area``); with ``disparity`` = ``(D, shapes)``, also Eq. 3's D of the
        new dst, clamped to [0, ``c_max``] (see :meth:`_store`)."""
        c_max = float(c_max)
        if self.median_size == 1:
            self._copy(src, dst, count, disparity, c_max)
        else:
            self._median(src, dst, count, disparity, c_max)

    @ti.kernel
    def _median(self, src: ti.template(), dst: ti.template(), count: ti.template(),
                disparity: ti.template(), c_max: ti.f32):
        """The stages of :meth:`median`, in one launch."""
        self._sort_columns(src)
        self._median_of_columns()
        self._store_medians(dst, count, disparity, c_max)

    @ti.kernel
    def net_change(self):
        """Pixels whose label differs from the reference taken at the last call (the net
        change over a window: an oscillating boundary does not count); renews the reference."""
        self.changed[None] = 0
        for y, x in self.phi:
            now = ti.cast(self.phi[y, x] > 0, ti.i8)
            if now != self.reference_sign[y, x]:
                self.changed[None] += 1
            self.reference_sign[y, x] = now

    def evolve(self, cost, c_max, shapes, occ, params, reinit, D=None):
        """One descent step of Eq. 2, then (every ``reinit_every``) the signed-distance
        re-initialisation and the median filter; counts the pixels whose sign flipped and the
        foreground area.  With ``D`` (an ``(H, W)`` field), also Eq. 3's disparity of the new
        phi, written as phi is (no pass of its own)."""
        self._step(cost, c_max, shapes, occ, params.dt, params.mu)
        if reinit:
            self.reinitialise(self.phi_next)
        self.median(self.phi_next, self.phi, count=True,
                    disparity=() if D is None else (D, shapes), c_max=c_max)

    @ti.kernel
    def _from_mask(self, mask: ti.types.ndarray()):
        for y, x in self.phi_next:
            self.phi_next[y, x] = 1.0 if mask[y, x] != 0 else -1.0

    def set_from_mask(self, mask):
        """phi = phi_scale x signed distance of a boolean ``(H, W)`` mask."""
        self._from_mask(np.ascontiguousarray(mask, dtype=np.int32))
        self.reinitialise(self.phi_next)
        self._copy(self.phi_next, self.phi, False, (), 0.0)
