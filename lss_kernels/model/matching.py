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

The census transform runs once per view (:meth:`MatchingCost.setup`), in a kernel over
ndarrays (:func:`_census`): Taichi compiles a kernel again for every shape of the fields it
reads, not for the shape of an ndarray, so the 48 comparisons a pixel compile once per process
(and come from Taichi's offline cache in the next) whatever the image size; only the copies of
the image in and of the words out, a loop each, compile per size.
"""
import taichi as ti

from ..kernels.backend import FieldPool

__all__ = ["COSTS", "MatchingCost"]

#: The matching costs the solver knows (``Params.matching_cost``).
COSTS = ("ad", "ad_census")

#: Census window radius (7x7 window: 48 neighbours, two 32-bit words).
_RADIUS = 3
#: rho's scales (Mei et al.'s 10 / 255 for AD; 30 of 63 bits, as a fraction, for census).
_LAMBDA_AD = 10.0 / 255.0
_LAMBDA_CENSUS = 30.0 / 63.0


#: A pixel's census: 48 bits in two words.
_WORDS = ti.types.vector(2, ti.u32)


@ti.kernel
def _census(img: ti.types.ndarray(dtype=ti.math.vec3, ndim=2),
            grey: ti.types.ndarray(dtype=ti.f32, ndim=2),
            out: ti.types.ndarray(dtype=_WORDS, ndim=2)):
    """The census transform of the RGB image ``img`` into ``out`` (``grey``: scratch of the
    same shape), for any shape.  Each pixel's grey is computed once, then compared: the same
    colour is the same grey, never below the centre, as in the specification
    (:func:`lss_kernels.reference.kernels.census`).  A grey computed at every use, as a
    neighbour and as the centre, may be summed in other orders by LLVM's fast-math
    reassociation, and a neighbour of the centre's own colour could then count as below it."""
    H, W = img.shape[0], img.shape[1]
    for y, x in ti.ndrange(H, W):
        p = img[y, x]
        grey[y, x] = 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]
    for y, x in ti.ndrange(H, W):
        centre = grey[y, x]
        words = ti.Vector([ti.u32(0), ti.u32(0)])
        bit = 0
        for dy, dx in ti.static(ti.ndrange((-_RADIUS, _RADIUS + 1), (-_RADIUS, _RADIUS + 1))):
            if ti.static(dy != 0 or dx != 0):
                # image coordinates clamped: a neighbour clamped onto the centre is the
                # centre, not below it
                ny = ti.min(ti.max(y + dy, 0), H - 1)
                nx = ti.min(ti.max(x + dx, 0), W - 1)
                if grey[ny, nx] < centre:
                    words[bit // 32] |= ti.u32(1) << ti.u32(bit % 32)
                bit += 1
        out[y, x] = words


@ti.data_oriented
class MatchingCost:
    """Owns what the pixel cost needs besides the images (the census transforms of both
    views, for ``"ad_census"``) and evaluates M at one pixel pair (:meth:`cost`).

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
            shape = (self.H, self.W)
            self.census_left = pool.vector(2, ti.u32, shape)
            self.census_right = pool.vector(2, ti.u32, shape)

    @ti.kernel
    def _load_image(self, img: ti.template(), image: ti.types.ndarray(dtype=ti.math.vec3,
                                                                      ndim=2)):
        """``img`` into the ndarray that :func:`_census` reads."""
        for y, x in img:
            image[y, x] = img[y, x]

    @ti.kernel
    def _store_words(self, words: ti.types.ndarray(dtype=_WORDS, ndim=2),
                     out: ti.template()):
        """:func:`_census`'s words into a census field."""
        for y, x in out:
            out[y, x] = words[y, x]

    def _transform(self, img, out):
        """The census transform of ``img`` (an ``(H, W)`` RGB vector field) into ``out``,
        through :func:`_census` and ndarrays held for the call only."""
        image = ti.Vector.ndarray(3, ti.f32, (self.H, self.W))
        grey = ti.ndarray(ti.f32, (self.H, self.W))
        words = ti.Vector.ndarray(2, ti.u32, (self.H, self.W))
        self._load_image(img, image)
        _census(image, grey, words)
        self._store_words(words, out)

    def setup(self, left, right):
        """The census transforms of both views (``left``, ``right``: ``(H, W)`` RGB vector
        fields in [0, 1]); nothing for ``"ad"``."""
        if self.census:
            self._transform(left, self.census_left)
            self._transform(right, self.census_right)

    @ti.func
    def cost(self, left: ti.template(), right: ti.template(), y, xl, xr):
        """M for the left pixel (y, xl) against the right pixel (y, xr) (both in the
        image)."""
        diff = 0.0
        for ch in ti.static(range(3)):
            diff += ti.abs(left[y, xl][ch] - right[y, xr][ch])
        value = diff / 3.0
        if ti.static(self.census):
            a = self.census_left[y, xl]
            b = self.census_right[y, xr]
            bits = ti.math.popcnt(a[0] ^ b[0]) + ti.math.popcnt(a[1] ^ b[1])
            hamming = ti.cast(bits, ti.f32) / 48.0
            value = (1.0 - ti.exp(-value / _LAMBDA_AD)) + \
                (1.0 - ti.exp(-hamming / _LAMBDA_CENSUS))
        return value
