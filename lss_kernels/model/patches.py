"""The geometry of the cooperative patch hierarchy (Sec. 3; the fields and kernels are in
:mod:`lss_kernels.model.hierarchy`): the levels' patch sides, the offsets of their children and
the margins of patch centres outside the image, and the columns that their relays hold.
"""

__all__ = ["Level", "column_spans", "level_geometry"]


class Level:
    """Geometry of one level: patch side ``size``, the offsets of its children's centres
    (one axis; the children are the product of these offsets in y and x), and ``margin``, the
    number of patch centres kept outside the image on each side."""

    def __init__(self, size, half, offsets, margin):
        self.size, self.half, self.offsets, self.margin = size, half, tuple(offsets), margin

    def __repr__(self):
        return (f"Level(size={self.size}, offsets={self.offsets}, margin={self.margin})")


def level_geometry(sizes):
    """Levels for the patch sides ``sizes`` (e.g. ``(3, 9, 18)``).

    A patch of side ``s`` centred on ``x`` covers ``[x - s // 2, x - s // 2 + s - 1]``; its
    children (side ``s'``) are centred on ``x + o`` with ``o = -s // 2 + j s' + s' // 2``,
    ``j = 0 .. s / s' - 1``.
    """
    sizes = (1,) + tuple(sizes)
    levels = []
    for s_child, s in zip(sizes, sizes[1:]):
        offs = [-(s // 2) + j * s_child + s_child // 2 for j in range(s // s_child)]
        levels.append(Level(s, s // 2, offs, 0))
    margin = 0
    for lev_idx in range(len(levels) - 1, -1, -1):
        levels[lev_idx].margin = margin
        margin += max(abs(o) for o in levels[lev_idx].offsets)
    # the pixels read level 1's centres around them (the consensus): a single level needs
    # that margin too
    levels[0].margin = max(levels[0].margin, max(abs(o) for o in levels[0].offsets))
    return levels


def column_spans(levels, width, lanes_per_block):
    """The columns every level's lane planes hold, ``(left, right)``: patch centres
    ``x = -left .. right - 1``, both multiples of ``lanes_per_block``.

    The top level holds the image's blocks.  Going down, each level holds the reach of its
    parent's children beyond the parent's columns, rounded out to whole blocks (with one
    pixel per block: exactly the levels' margins); level 1 also reaches the pixels' blocks
    and one reach of its own beyond them (the consensus reads it there).  Patch centres
    beyond a level's margin only ever hold zero relays, and their sums and extremes are
    never read."""
    L = int(lanes_per_block)
    round_up = lambda v: -(-v // L) * L
    spans = [None] * len(levels)
    left, right = 0, round_up(width)
    spans[-1] = (left, right)
    for i in range(len(levels) - 2, -1, -1):
        reach = max(abs(o) for o in levels[i + 1].offsets)
        left, right = round_up(left + reach), round_up(right + reach)
        spans[i] = (left, right)
    reach = max(abs(o) for o in levels[0].offsets)
    left, right = spans[0]
    spans[0] = (max(left, round_up(reach)), max(right, round_up(round_up(width) + reach)))
    return spans
