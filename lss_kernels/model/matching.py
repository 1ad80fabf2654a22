"""The pixel matching cost M of Sec. 4: the data the patch hierarchy averages into C_p(c).

M(x, y, c) compares the left image at x + c with the right image at x - c (the cyclopean
frame; image coordinates clamped at the borders).  Two costs:

``"ad"``
    the paper's: absolute difference of colour, mean over RGB (images in [0, 1]);
``"ad_census"``
    AD-Census (Mei et al., "On building an accurate stereo matching system on graphics
    hardware", 2011): rho(AD, lambda_ad) + rho(census, lambda_census) with
    rho(v, lambda) = 1 - exp(-v / lambda), where census is the Hamming distance between the
    7x7 census transforms (each neighbour's grey value below the centre's, 48 bits) of the
    two pixels, as a fraction of the 48 bits.  The census term depends only on the order of
    grey values around a pixel, so a dark or low-contrast texture, or a gain and offset
    between the cameras, matches as sharply as a bright one; the AD term keeps colour
    where the census is ambiguous (flat regions).

Either way the hierarchy min-max normalises each level's patch means, so only the shape of
M matters.
"""
import taichi as ti

from ..kernels.backend import FieldPool

__all__ = ["COSTS", "MatchingCost", "cost_at"]

#: The matching costs the solver knows (``Params.matching_cost``).
COSTS = ("ad", "ad_census")


@ti.func
def cost_at(cost: ti.template(), y, x, c, C: ti.template()):
    """``cost[y, x, :]`` (a volume of candidates c = 1 .. ``C``) at a real cyclopean c:
    linear between candidates, clamped to ``[1, C]``."""
    kf = ti.min(ti.max(c - 1.0, 0.0), C - 1.0)
    k0 = ti.min(ti.cast(ti.floor(kf), ti.i32), ti.max(C - 2, 0))
    k1 = ti.min(k0 + 1, C - 1)
    tk = kf - k0
    return (1.0 - tk) * cost[y, x, k0] + tk * cost[y, x, k1]


#: Census window radius (7x7 window: 48 neighbours, two 32-bit words).
_RADIUS = 3
#: rho's scales (Mei et al.'s 10 / 255 for AD; 30 of 63 bits, as a fraction, for census).
_LAMBDA_AD = 10.0 / 255.0
_LAMBDA_CENSUS = 30.0 / 63.0


@ti.data_oriented
class MatchingCost:
    """Owns what the pixel cost needs besides the images (the census transforms of both
    views, for ``"ad_census"``) and evaluates M at one pixel pair (:meth:`cost`).

    The census lives in the pool's bucket tree (see
    :class:`lss_kernels.kernels.backend.FieldPool`): the grey planes and the census words of
    both views, view 0 the left, 1 the right, in planes of the size bucket's shape.  Its
    kernels read the image's size at run time from the pool's
    :class:`~lss_kernels.kernels.backend.Extent`, so they compile once per size bucket.

    Parameters
    ----------
    pool : FieldPool
    height, width : int
    kind : {"ad", "ad_census"}
    """

    def __init__(self, pool: FieldPool, height, width, kind="ad"):
        if kind not in COSTS:
            raise ValueError(f"matching_cost: expected one of {', '.join(COSTS)}, got {kind!r}")
        self.H, self.W, self.kind = int(height), int(width), kind
        self.census = kind == "ad_census"
        if self.census:
            self.extent = pool.extent(self.H, self.W)
            shape = (2,) + self.extent.bucket
            self.grey = pool.field(ti.f32, shape, bucket=True)
            self.words = pool.vector(2, ti.u32, shape, bucket=True)

    @ti.kernel
    def _load(self, left: ti.template(), right: ti.template()):
        """The images' greys into the bucket.  Each pixel's grey is
        computed once, then compared (:meth:`_bucket_census`): the same colour is the same grey,
        never below the centre, as in the specification
        (:func:`lss_kernels.reference.kernels.census`).  A grey computed at every use, as a
        neighbour and as the centre, may be summed in other orders by LLVM's fast-math
        reassociation, and a neighbour of the centre's own colour could then count as below
        it."""
        for view in ti.static(range(2)):
            img = ti.static((left, right)[view])
            for y, x in ti.ndrange(self.extent.height(), self.extent.width()):
                p = img[y, x]
                self.grey[view, y, x] = 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]

    @ti.kernel
    def _bucket_census(self):
        """The census transforms of both views' greys into ``words``, for the run-time
        ``H x W`` region only."""
        height = self.extent.height()
        width = self.extent.width()
        for view, y, x in ti.ndrange(2, height, width):
            centre = self.grey[view, y, x]
            words = ti.Vector([ti.u32(0), ti.u32(0)])
            bit = 0
            for dy, dx in ti.static(ti.ndrange((-_RADIUS, _RADIUS + 1),
                                               (-_RADIUS, _RADIUS + 1))):
                if ti.static(dy != 0 or dx != 0):
                    # image coordinates clamped: a neighbour clamped onto the centre is the
                    # centre, not below it
                    ny = ti.min(ti.max(y + dy, 0), height - 1)
                    nx = ti.min(ti.max(x + dx, 0), width - 1)
                    if self.grey[view, ny, nx] < centre:
                        words[bit // 32] |= ti.u32(1) << ti.u32(bit % 32)
                    bit += 1
            self.words[view, y, x] = words

    def setup(self, left, right):
        """The census transforms of both views (``left``, ``right``: ``(H, W)`` RGB vector
        fields in [0, 1]); nothing for ``"ad"``."""
        if self.census:
            self._load(left, right)
            self._bucket_census()

    def census_words(self, view):
        """The census of ``view`` (0: left, 1: right) as a ``(H, W, 2)`` uint32 array: bit
        ``b`` of the 48 in word ``b // 32``."""
        return self.words.to_numpy()[view, :self.H, :self.W]

    @ti.func
    def cost(self, left: ti.template(), right: ti.template(), y, xl, xr):
        """M for the left pixel (y, xl) against the right pixel (y, xr) (both in the
        image)."""
        diff = 0.0
        for ch in ti.static(range(3)):
            diff += ti.abs(left[y, xl][ch] - right[y, xr][ch])
        value = diff / 3.0
        if ti.static(self.census):
            a = self.words[0, y, xl]
            b = self.words[1, y, xr]
            bits = ti.math.popcnt(a[0] ^ b[0]) + ti.math.popcnt(a[1] ^ b[1])
            hamming = ti.cast(bits, ti.f32) / 48.0
            value = (1.0 - ti.exp(-value / _LAMBDA_AD)) + \
                (1.0 - ti.exp(-hamming / _LAMBDA_CENSUS))
        return value
