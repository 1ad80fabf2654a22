"""The median filter of a plane with symmetric borders, by selection networks.

A ``k x k`` median (``k`` odd) in two stages, after Adams, "Fast median filters using separable
sorting networks" (2021):

1. every window column of ``k`` values is sorted once (a Batcher network), for a block of rows
   at a time in SIMD lanes;
2. the medians of a tile of horizontally adjacent windows come from a binary tree that merges
   the sorted columns the windows share only as far as the ranks that can still be a median
   (:func:`median_network`).

The tree of stage 2 compiles once for every image of up to :data:`SCRATCH` (it touches only
scratch of that one shape and reads the size at run time), and once for all the filters of a
pool with the same window; the two other stages once per *size bucket*
(:func:`lss_kernels.kernels.backend.bucket_shape`): see :class:`MedianFilter`.

The filter writes through a *sink*: any ``ti.data_oriented`` object with a ``ti.func``
``begin()`` (run once, serially, before the pixels) and a ``ti.func`` ``store(y, x, value)``
(once per pixel); :class:`Assign` is the plain one.  Nothing here knows of the paper: the level
set hands it a sink that also counts sign flips and writes the disparity of Eq. 3.
"""
import taichi as ti

from . import lanes
from .backend import bucket_shape
from .filters import reflect

__all__ = ["Assign", "MedianFilter", "SCRATCH", "median_network", "scratch_bytes",
           "scratch_shape"]

#: Rows and columns of the merge tree's scratch for every image that fits in them: its
#: kernel, seconds to compile for a 7x7 window, then compiles once for all their size
#: buckets (a larger image takes its bucket's side).  32 bytes a pixel for a 7x7 window:
#: 25 MB, whatever the image.
SCRATCH = (768, 1024)


def scratch_shape(bucket) -> tuple:
    """The shape of the merge tree's scratch for images of size bucket ``bucket``:
    :data:`SCRATCH`, or the bucket's side where it is larger."""
    return tuple(max(int(b), s) for b, s in zip(bucket, SCRATCH))


def scratch_bytes(bucket, size: int = 7) -> int:
    """Bytes of the merge tree's scratch of a ``size x size`` filter for images of size
    bucket ``bucket``: ``size`` sorted ranks and a median a pixel, and ``size // 2``
    reflected columns on either side (every side of a scratch is a whole number of blocks
    of lanes and tiles of windows)."""
    rows, columns = scratch_shape(bucket)
    return 4 * rows * (size * (columns + 2 * (size // 2)) + columns)


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


def _runs(ops):
    """``ops`` (see :func:`median_network`) as runs of consecutive ops of one kind,
    ``(kind, ((a, b), ...))`` in order: ``"swap"``, ``"both"`` (a comparator whose minimum
    and maximum are both kept), ``"min"`` or ``"max"`` (only one kept)."""
    runs = []
    for op, a, b, keep_min, keep_max in ops:
        kind = op if op == "swap" else ("both" if keep_min and keep_max else
                                        ("min" if keep_min else "max"))
        if runs and runs[-1][0] == kind:
            runs[-1][1].append((a, b))
        else:
            runs.append((kind, [(a, b)]))
    return tuple((kind, tuple(pairs)) for kind, pairs in runs)


def _sources(slots, n_runs):
    """Where each of a merge network's ``slots`` starts: ``(run, rank)``, the padding as
    rank 0 (-inf) or 1 (+inf) of a run ``n_runs`` past the sorted ones."""
    return tuple((n_runs, 0) if slot == "lo" else (n_runs, 1) if slot == "hi" else slot
                 for slot in slots)


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
class Assign:
    """The plain sink of :meth:`MedianFilter.run`: ``dst[y, x] = value``."""

    def __init__(self, dst):
        self.dst = dst

    @ti.func
    def begin(self):
        pass

    @ti.func
    def store(self, y, x, value):
        self.dst[y, x] = value

    @ti.func
    def end(self):
        return ti.Vector([0, 0])


@ti.data_oriented
class _MergeTree:
    """Stage 2 of :class:`MedianFilter`: the medians of a tile of horizontally adjacent
    windows from the sorted window columns, through the tree of :func:`median_network`, in
    :meth:`_merge`.

    Its fields are in the pool's fixed tree (see
    :class:`lss_kernels.kernels.backend.FieldPool`): the sorted window columns and the
    medians of a block of rows, as lane vectors, of the scratch's shape
    (:func:`scratch_shape`).  The kernel touches only them and takes ``H`` and ``W`` as
    arguments, so its code and its offline-cache key are those of every image that fits in
    :data:`SCRATCH`.  The filters of a pool with the same window and lanes share one
    (``pool.shared``); a solver's start and level set share one 7x7 filter
    (:meth:`MedianFilter.shared`).
    """

    def __init__(self, pool, shape, size, lane_count):
        self.median_size, self.lanes = int(size), int(lane_count)
        self.network = median_network(self.median_size)
        tile, k, L = self.network[1], self.median_size, self.lanes
        blocks = lanes.block_count(shape[0], L)
        columns = lanes.block_count(shape[1], tile) * tile
        # the sorted window columns in blocks of ``lanes`` rows (rank r of row
        # ``yb lanes + l`` at r * lanes + l), every column of the tiles and ``k // 2``
        # reflected columns on either side: the merge runs in SIMD lanes over the rows of a
        # block and reads a tile's columns at compile-time offsets, unreflected
        self.sorted = pool.vector(k * L, ti.f32, (blocks, columns + 2 * (k // 2)),
                                  offset=(0, -(k // 2)), fixed=True)
        # the medians of a block's rows, stored whole: LLVM packs the tree's comparators
        # into SIMD lanes only from stores of whole vectors (scalar stores into the output's
        # rows left them scalar, 9.4 ms against 8.3 for the tile of one row)
        self.medians = pool.vector(L, ti.f32, (blocks, columns), fixed=True)

    @ti.func
    def apply(self, v: ti.template(), ops: ti.template()):
        """Run a network's ``ops`` on the local vector ``v``, in place, by runs of one kind
        (:func:`_runs`): the front end tells the kinds apart once per run, not for every
        comparator (a third fewer nodes)."""
        for kind, pairs in ti.static(_runs(ops)):
            if ti.static(kind == "swap"):
                for a, b in ti.static(pairs):
                    v[a], v[b] = v[b], v[a]
            elif ti.static(kind == "both"):
                for a, b in ti.static(pairs):
                    v[a], v[b] = ti.min(v[a], v[b]), ti.max(v[a], v[b])
            elif ti.static(kind == "min"):
                for a, b in ti.static(pairs):
                    v[a] = ti.min(v[a], v[b])
            else:
                for a, b in ti.static(pairs):
                    v[b] = ti.max(v[a], v[b])

    @ti.func
    def _column(self, yb, t, c: ti.template()):
        """The sorted column ``c`` (a compile-time offset, possibly negative) of the tile
        ``t``'s first window for the rows of block ``yb``: ``k`` ranks, each a vector over
        the rows."""
        k, L = ti.static(self.median_size, self.lanes)
        ranks = self.sorted[yb, t * ti.static(self.network[1]) + c]
        return [lanes.take(ranks, r * L, L) for r in ti.static(range(k))]

    @ti.func
    def _load(self, slots: ti.template(), runs: ti.template()):
        """The initial values of a merge network, each a vector over a block's rows: padding
        as -+1e30, ``(run, rank)`` from the sorted ``runs`` (:func:`_sources`)."""
        L = ti.static(self.lanes)
        padding = [ti.Vector([-1e30] * L), ti.Vector([1e30] * L)]
        sources = ti.static(runs + [padding])
        return [sources[run][rank] for run, rank in ti.static(_sources(slots, len(runs)))]

    @ti.func
    def _descend(self, yb, t, held: ti.template(), node: ti.template()):
        """A node of the tile's tree below the root (see :func:`median_network`): merge its
        new columns with the parent's survivors ``held``; store the medians of a block's
        rows at a leaf, else pass the survivors on to the children."""
        columns_at, pre, slots, ops, keep, children, output = ti.static(node)
        columns = [self._column(yb, t, c) for c in ti.static(columns_at)]
        v = self._load(slots, [held, self._one_run(columns, pre)])
        self.apply(v, ops)
        if ti.static(output >= 0):
            self.medians[yb, t * ti.static(self.network[1]) + output] = v[ti.static(keep[0])]
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
            self.apply(v, pre[1])
            return self._gather(v, pre[2])

    @ti.func
    def _gather(self, v: ti.template(), positions: ti.template()):
        """The entries of ``v`` at ``positions``, as a new list (``v`` a template: not
        copied whole for each node of the tree)."""
        return [v[i] for i in ti.static(positions)]

    @ti.kernel
    def _merge(self, height: ti.i32, width: ti.i32):
        """Stage 2 for the ``height x width`` region only, a tile of windows of a block of
        rows at a time.  Touches only the scratch and reads nothing of the size at compile
        time."""
        L, tile, root = ti.static(self.lanes, self.network[1], self.network[2])
        columns_at, slots, ops, keep, children = ti.static(
            (root[0], root[2], root[3], root[4], root[5]))
        for yb, t in ti.ndrange((height + L - 1) // L, (width + tile - 1) // tile):
            columns = [self._column(yb, t, c) for c in ti.static(columns_at)]
            v = self._load(slots, columns)
            self.apply(v, ops)
            kept = self._gather(v, keep)
            for child in ti.static(children):
                self._descend(yb, t, kept, child)


@ti.data_oriented
class MedianFilter:
    """The ``size x size`` median of ``(H, W)`` planes (``size`` odd; 1 is a copy).

    Three kernels: :meth:`_sort` (stage 1: the sorted window columns into the scratch of a
    :class:`_MergeTree`), the tree's ``_merge`` (stage 2, the merge networks: seconds to
    compile for ``size`` 7) and :meth:`_store` (stage 3: the medians into the sink).  All
    three read the image's size at run time (the first and the last from the pool's
    :class:`~lss_kernels.kernels.backend.Extent`, the tree as arguments): the first and the
    last compile once per size bucket when the planes they read and the sink's fields are
    in the bucket tree, the tree once for every image of up to :data:`SCRATCH`.
    """

    def __init__(self, pool, height, width, size, source=False):
        self.H, self.W = int(height), int(width)
        self.median_size = int(size)
        self.lanes = lanes.lanes_for_arch()
        self.extent = pool.extent(self.H, self.W)
        #: with ``source``, a plane of the bucket tree for the users of a shared filter to
        #: write what they filter into (:meth:`shared`); else None
        self.source = pool.field(ti.f32, self.extent.bucket, bucket=True) if source else None
        if self.median_size > 1:
            self.bucket = bucket_shape(self.H, self.W)
            shape = scratch_shape(self.bucket)
            key = ("median", self.median_size, self.lanes, shape)
            self._tree = pool.shared(key, lambda: _MergeTree(pool, shape, self.median_size,
                                                             self.lanes))
            # the loops of the sort and the store run over the bucket's blocks of rows and
            # columns, skipping those past the image's (compile-time bounds: no run-time
            # division per index)
            tile = self._tree.network[1]
            self._bucket_rows = lanes.block_count(self.bucket[0], self.lanes)
            self._bucket_columns = lanes.block_count(self.bucket[1], tile) * tile

    @ti.func
    def _sort_columns(self, src: ti.template()):
        """Stage 1 of the median: every window column (symmetric borders), sorted, for a
        block of ``lanes`` rows at a time in SIMD lanes, the margin columns included.
        The networks are attributes read with ``ti.static``, not kernel arguments: Taichi
        hashes every template argument at each launch, which for these tuples of a few
        hundred comparators cost more than the kernel itself."""
        k, L, tile = ti.static(self.median_size, self.lanes, self._tree.network[1])
        column_ops = ti.static(self._tree.network[0])
        height, width = self.extent.height(), self.extent.width()
        row_blocks = (height + L - 1) // L
        tiles = (width + tile - 1) // tile
        for yb, x in ti.ndrange(self._bucket_rows, (-(k // 2), self._bucket_columns + k // 2)):
            if yb >= row_blocks or x >= tiles * tile + k // 2:
                continue
            xs = reflect(x, width)
            # the rows of the block's windows: k - 1 more than the block
            window = [src[reflect(yb * L + i - k // 2, height), xs]
                      for i in ti.static(range(L + k - 1))]
            v = [lanes.take(window, r, L) for r in ti.static(range(k))]
            self._tree.apply(v, column_ops)
            self._tree.sorted[yb, x] = ti.Vector([v[r][lane] for r in ti.static(range(k))
                                                  for lane in ti.static(range(L))])

    @ti.kernel
    def _sort(self, src: ti.template()):
        """Stage 1: the sorted window columns of ``src`` (an ``(H, W)`` plane) into the
        tree's scratch.  Sorting here rather than in the tree's kernel saves a copy of the
        plane into the scratch: 0.3 ms of a 15 ms iteration at 400x300 on the 2-core CPU."""
        self._sort_columns(src)

    @ti.kernel
    def _store(self, sink: ti.template()) -> ti.types.vector(2, ti.i32):
        """Stage 3: the medians of every block of rows, pixel by pixel, into the sink;
        returns the sink's ``end()``."""
        sink.begin()
        L = ti.static(self.lanes)
        height, width = self.extent.height(), self.extent.width()
        for yb, x in ti.ndrange(self._bucket_rows, self.bucket[1]):
            if yb >= (height + L - 1) // L or x >= width:
                continue
            medians = self._tree.medians[yb, x]
            for lane in ti.static(range(L)):
                y = yb * L + lane
                if y < height:
                    sink.store(y, x, medians[lane])
        return sink.end()

    @ti.kernel
    def _copy(self, src: ti.template(), sink: ti.template()) -> ti.types.vector(2, ti.i32):
        """The 1x1 median: ``src`` itself."""
        sink.begin()
        for y, x in ti.ndrange(self.extent.height(), self.extent.width()):
            sink.store(y, x, src[y, x])
        return sink.end()

    @classmethod
    def shared(cls, pool, height, width, size) -> "MedianFilter":
        """The ``size x size`` filter of ``pool`` that every user with that window shares:
        each writes what it filters into :attr:`source` and calls ``run(filter.source,
        sink)``, so that the sort compiles once for all of them (a kernel instance is one
        per filter object and source plane).  Ask before the pool is finalised."""
        return pool.shared(("median filter", int(size), int(height), int(width)),
                           lambda: cls(pool, height, width, size, source=True))

    def run(self, src, sink):
        """``sink.store(y, x, m)`` for every pixel, ``m`` the median of ``src`` (an ``(H, W)``
        plane) over the window centred there, symmetric borders.  Three launches (one for
        ``size`` 1): :meth:`_sort`, the tree's :meth:`_MergeTree._merge`, :meth:`_store`.
        Returns the sink's ``end()``, two integers."""
        if self.median_size == 1:
            return self._copy(src, sink)
        self._sort(src)
        self._tree._merge(self.H, self.W)
        return self._store(sink)
