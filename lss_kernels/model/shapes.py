"""Global shapes Theta_1 (foreground) and Theta_2 (background): Eq. 8 of the paper.

Each is a quadratic in the cyclopean coordinates, ``Theta_j(x, y) = sum_i theta_j[i] U_i(x, y)``
with the paper's basis ``U = {x^2, xy, y^2, x, y, 1}``; internally x and y are normalised to
about [-1, 1] for conditioning (``x_n = (x - cx) / s``, ``y_n = (y - cy) / s``,
``s = max(H, W) / 2``).  The weighted least-squares fit to the consensus means is solved as
the paper proposes, by a hierarchical (distributed-averaging) reduction of the normal
equations: every pixel contributes ``w U U^T`` and ``w U d-bar`` to its region's system, every
tile sums its children's 21 + 6 terms in a fixed order (so the result does not depend on the
number of threads), and the root solves the two 6x6 systems.  A region with fewer than 6
weighted rows, or a singular system, keeps its previous shape.

The rows are weighted as the authors' release weights them, by the consensus precision
(1 / sigma^2 of Eq. 7) to the power ``WEIGHT_POWER`` (Eq. 8 writes the power 1)
(:class:`RegionWeights`).  :meth:`GlobalShapes.update` is the iteration's Theta update: the
fit, then the background's plane sweep (:mod:`lss_kernels.model.sweep`).
"""
import numpy as np
import taichi as ti

from ..kernels.curves import quadratic
from ..params import PHI_SCALE

__all__ = ["GlobalShapes", "RegionWeights", "WEIGHT_POWER", "WeightPlanes",
           "to_pixel_coefficients"]

#: Rows of Eq. 8 are weighted by the consensus precision (1 / sigma^2) to this power: 2, as
#: the authors' release does (the paper writes 1).
WEIGHT_POWER = 2

NB = 6            # basis size
NT = 21 + 6 + 1   # upper triangle of U U^T, U d, row count
TILE = 16         # children per tile side at every level of the reduction
#: Rows of the whole background, targeting Theta_2, in each tile's local fit
#: (:meth:`GlobalShapes.fit_local`).
LOCAL_PRIOR = 64.0
#: A background row whose target lies within this of Theta_1 (cyclopean pixels), or in
#: front of it, is left out of the local fits.
LOCAL_NEAR = 1.5
#: Background rows closer than this to the boundary (pixels of phi) are left out of the
#: local fits: the pixels that the boundary may yet take or give up are not the evidence of
#: the background around the object.
LOCAL_GAP = 10.5
_PAIRS = [(a, b) for a in range(NB) for b in range(a, NB)]  # upper triangle, row-major
_EXPONENTS = [(2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0)]  # U_i = x^p y^q: (p, q)


def _monomial(a, b):
    """(p, q) of U_a U_b = x^p y^q."""
    return _EXPONENTS[a][0] + _EXPONENTS[b][0], _EXPONENTS[a][1] + _EXPONENTS[b][1]


def _lanes(value):
    """The number of lanes of a vector expression, 0 for a scalar (compile time)."""
    if isinstance(value, ti.Matrix) or (hasattr(value, "ptr") and value.ptr.is_tensor()):
        return value.n
    return 0


def to_pixel_coefficients(theta, height, width, scale=1.0):
    """Convert coefficients over normalised coordinates to raw cyclopean pixel coordinates
    (same basis order), multiplied by ``scale`` (2 gives left-view disparity units)."""
    cx, cy, s = (width - 1) / 2.0, (height - 1) / 2.0, max(height, width) / 2.0
    a, b, c, d, e, f = np.asarray(theta, np.float64)
    # x_n = (x - cx)/s, y_n = (y - cy)/s; expand each monomial
    A = a / s ** 2
    B = b / s ** 2
    Cc = c / s ** 2
    D = -2 * a * cx / s ** 2 - b * cy / s ** 2 + d / s
    E = -2 * c * cy / s ** 2 - b * cx / s ** 2 + e / s
    F = a * cx ** 2 / s ** 2 + b * cx * cy / s ** 2 + c * cy ** 2 / s ** 2 - d * cx / s - e * cy / s + f
    return scale * np.array([A, B, Cc, D, E, F])


@ti.data_oriented
class GlobalShapes:
    """Owns Theta (``theta[j, i]``: j = 0 foreground, 1 background; normalised basis,
    cyclopean disparity units) and the reduction tree.

    Its fields are in the pool's bucket tree and the kernels read the image's size and the
    normalisation at run time (from the pool's
    :class:`~lss_kernels.kernels.backend.Extent` and :attr:`frame`), so they compile once
    per size bucket.  The reduction has the levels of the bucket's tiles; those that the
    image leaves out stay zero.

    Parameters
    ----------
    pool : FieldPool
    height, width : int
    weights : RegionWeights, optional
        The rows of :meth:`update`'s fit (Eq. 8) and the planes it reads (for :meth:`update`).
    sweep : BackgroundSweep, optional
        The background's plane sweep that :meth:`update` runs after the fit (for
        :meth:`update`).
    local : int, optional
        Radius, in tiles of ``TILE`` pixels, of the local background (:meth:`fit_local`);
        0 (the default): Theta_2 is the one global quadratic of the paper.
    """

    def __init__(self, pool, height, width, weights=None, sweep=None, local=0):
        self.H, self.W = int(height), int(width)
        self.weights, self.sweep = weights, sweep
        self.local = int(local)
        self.extent = pool.extent(self.H, self.W)
        self.cx, self.cy = (self.W - 1) / 2.0, (self.H - 1) / 2.0
        self.inv_s = 1.0 / (max(self.H, self.W) / 2.0)
        field = lambda dtype, shape: pool.field(dtype, shape, bucket=True)
        # x_n = x inv_s + x_shift, y_n = y inv_s + y_shift (see :meth:`load`)
        self.frame = field(ti.f32, (3,))
        self.theta = field(ti.f32, (2, NB))
        # the shapes at the last call of moved() and how far they have moved since
        self.reference = field(ti.f32, (2, NB))
        self.change = field(ti.f32, ())
        pool.host(self.frame, self.theta)
        self.updated = field(ti.i32, (2,))   # the last fit changed the shape
        self.rows = field(ti.f32, (2,))
        # reduction levels: tiles of TILE x TILE children until one cell is left
        self.tiles = []
        h, w = self.extent.bucket
        while True:
            h, w = -(-h // TILE), -(-w // TILE)
            self.tiles.append(field(ti.f32, (h, w, 2, NT)))
            if h == 1 and w == 1:
                break
        if self.local:
            # Theta_2 of every first-level tile, and whether it holds a fit (see set)
            self.local_theta = field(ti.f32, self.tiles[0].shape[:2] + (NB,))
            self.local_tiles = field(ti.f32, self.tiles[0].shape)
            self._behind = {}
            self.local_ready = field(ti.i32, ())
        pool.on_load(self.load)

    def load(self):
        """Write the normalisation into :attr:`frame` (the pool calls it once finalised and
        after it is zeroed).  ``(x - cx) inv_s`` is computed as ``x inv_s + (-cx inv_s)``, the
        product rounded to float32: the form LLVM's fast-math gives it when ``cx`` and
        ``inv_s`` are compile-time constants, so the shapes are those of kernels compiled
        for one size, bit for bit."""
        f32 = np.float32
        inv_s = f32(self.inv_s)
        self.extent.pool.write(self.frame, np.array([f32(-f32(self.cx)) * inv_s,
                                        f32(-f32(self.cy)) * inv_s, inv_s], np.float32))

    @ti.func
    def normalised(self, x, y):
        """Normalised coordinates ``(x_n, y_n)`` of real cyclopean pixel coordinates."""
        inv_s = self.frame[2]
        return x * inv_s + self.frame[0], y * inv_s + self.frame[1]

    @ti.func
    def value_of_size(self, j, x, y):
        """:meth:`value` with the normalisation as compile-time constants: a kernel that
        uses it compiles once per image size.  LLVM's fast-math reassociates the quadratic
        around its constants in ways that no run-time form reproduces in every context (the
        ray cast's fixed-point steps); kernels that must keep those exact float results use
        it."""
        xn = (x - self.cx) * self.inv_s
        yn = (y - self.cy) * self.inv_s
        return self._at(j, x, y, xn, yn)

    @ti.func
    def value(self, j, x, y):
        """Theta_j at real cyclopean pixel coordinates (x, y); with a local background
        (:meth:`fit_local`), Theta_2 is its blend of the tiles' quadratics."""
        xn, yn = self.normalised(x, y)
        return self._at(j, x, y, xn, yn)

    @ti.func
    def _at(self, j, x, y, xn, yn):
        """Theta_j at (x, y), normalised ``(xn, yn)``: the quadratic, or the local
        background's blend."""
        v = quadratic(self._coefficients(j), xn, yn)
        if ti.static(self.local):
            if j == 1 and self.local_ready[None] == 1:
                v = self._blend(x, y, xn, yn)
        return v

    @ti.func
    def _blend(self, x, y, xn, yn):
        """:meth:`_blend_at` at a point, or lane by lane at a vector of columns ``x`` (a
        vector ``xn``) on row ``y``."""
        v = xn
        if ti.static(_lanes(xn)):
            v = ti.Vector([self._blend_at(x[i], y, xn[i], yn)
                           for i in ti.static(range(_lanes(xn)))])
        else:
            v = self._blend_at(x, y, xn, yn)
        return v

    @ti.func
    def _blend_at(self, x, y, xn, yn):
        """The local background at (x, y): the quadratics of the four tiles whose centres
        surround the point, each evaluated there, weighted bilinearly (constant beyond the
        outermost centres)."""
        columns = self._tiles_of(self.extent.width(), 0)
        rows = self._tiles_of(self.extent.height(), 0)
        u = ti.min(ti.max(x / TILE - 0.5, 0.0), columns - 1.0)
        v = ti.min(ti.max(y / TILE - 0.5, 0.0), rows - 1.0)
        u0 = ti.min(ti.cast(ti.floor(u), ti.i32), columns - 1)
        v0 = ti.min(ti.cast(ti.floor(v), ti.i32), rows - 1)
        u1 = ti.min(u0 + 1, columns - 1)
        v1 = ti.min(v0 + 1, rows - 1)
        fu = u - u0
        fv = v - v0
        top = (1.0 - fu) * self._tile_value(v0, u0, xn, yn) + fu * self._tile_value(v0, u1, xn, yn)
        bottom = ((1.0 - fu) * self._tile_value(v1, u0, xn, yn)
                  + fu * self._tile_value(v1, u1, xn, yn))
        return (1.0 - fv) * top + fv * bottom

    @ti.func
    def _tile_value(self, ty, tx, xn, yn):
        return quadratic(ti.Vector([self.local_theta[ty, tx, a] for a in ti.static(range(NB))]),
                         xn, yn)

    @ti.func
    def _coefficients(self, j):
        """theta_j as a 6-vector."""
        return ti.Vector([self.theta[j, a] for a in ti.static(range(NB))])

    @ti.kernel
    def moved(self, phi: ti.template()) -> ti.f32:
        """How far the shapes have moved since the last call, in cyclopean pixels: ``change``
        is the largest ``|Theta_j - reference_j|`` over the image, each pixel measured on its
        own layer's shape (Theta_1 where ``phi > 0``, else Theta_2); then ``reference`` <-
        Theta (the stopping rule's second test, :mod:`lss_kernels.stopping`); returns
        ``change``."""
        self.change[None] = 0.0
        for y, x in phi:
            if y < self.extent.height() and x < self.extent.width():
                j = 0 if phi[y, x] > 0 else 1
                xn, yn = self.normalised(ti.cast(x, ti.f32), ti.cast(y, ti.f32))
                d = ti.Vector([self.theta[j, a] - self.reference[j, a]
                               for a in ti.static(range(NB))])
                ti.atomic_max(self.change[None], ti.abs(quadratic(d, xn, yn)))
        for j, a in self.theta:
            self.reference[j, a] = self.theta[j, a]
        return self.change[None]

    @ti.func
    def _from_pixels(self, weights: ti.template(), target: ti.template(), out: ti.template()):
        """The tiles' sums of the pixels' terms.  Every term is a monomial
        ``w x_n^p y_n^q`` (times d-bar for ``U d``), so a row of a tile first sums
        ``w x_n^p`` (p <= 4) and ``w d x_n^p`` (p <= 2) over its pixels, and the row's sums
        enter the tile's 21 + 6 terms times the powers of its y_n: 16 multiply-adds per pixel
        and region instead of 54."""
        height, width = self.extent.height(), self.extent.width()
        for ty, tx in ti.ndrange(out.shape[0], out.shape[1]):
            if ty < self._tiles_of(height, 0) and tx < self._tiles_of(width, 0):
                acc = ti.Matrix.zero(ti.f32, 2, NT)
                for iy in range(TILE):
                    y = ty * TILE + iy
                    if y < height:
                        row = ti.Matrix.zero(ti.f32, 2, 9)   # sum w x^p (p <= 4), w d x^p, n
                        for ix in range(TILE):
                            x = tx * TILE + ix
                            if x < width:
                                xn, _ = self.normalised(ti.cast(x, ti.f32), 0.0)
                                d = target[y, x]
                                w_j = weights.row_weights(y, x)
                                for j in ti.static(range(2)):
                                    w = w_j[j]
                                    if w > 0:
                                        wp = w
                                        for q in ti.static(range(5)):
                                            row[j, q] += wp
                                            if ti.static(q < 3):
                                                row[j, 5 + q] += wp * d
                                            wp *= xn
                                        row[j, 8] += 1.0
                        _, yn = self.normalised(0.0, ti.cast(y, ti.f32))
                        ypow = ti.Vector([1.0, yn, yn * yn, yn * yn * yn, yn * yn * yn * yn])
                        for j in ti.static(range(2)):
                            for n in ti.static(range(len(_PAIRS))):
                                px, py = ti.static(_monomial(*_PAIRS[n]))
                                acc[j, n] += row[j, px] * ypow[py]
                            for a in ti.static(range(NB)):
                                px, py = ti.static(_EXPONENTS[a])
                                acc[j, 21 + a] += row[j, 5 + px] * ypow[py]
                            acc[j, 27] += row[j, 8]
                for j, n in ti.static(ti.ndrange(2, NT)):
                    out[ty, tx, j, n] = acc[j, n]

    @ti.func
    def _tiles_of(self, n, level: ti.template()):
        """Tiles along an axis of ``n`` pixels at reduction level ``level`` (run time)."""
        tiles = n
        for _ in ti.static(range(level + 1)):
            tiles = (tiles + TILE - 1) // TILE
        return tiles

    @ti.func
    def _from_tiles(self, src: ti.template(), out: ti.template(), level: ti.template()):
        """Level ``level`` of the reduction (``out``) from the level below (``src``), over
        the tiles that the image covers."""
        height, width = self.extent.height(), self.extent.width()
        rows, columns = self._tiles_of(height, level - 1), self._tiles_of(width, level - 1)
        for ty, tx, j, n in out:
            if ty < self._tiles_of(height, level) and tx < self._tiles_of(width, level):
                s = 0.0
                for iy, ix in ti.ndrange(TILE, TILE):
                    y = ty * TILE + iy
                    x = tx * TILE + ix
                    if y < rows and x < columns:
                        s += src[y, x, j, n]
                out[ty, tx, j, n] = s

    @ti.func
    def _system(self, src: ti.template(), ty, tx, j):
        """The normal equations ``(A, rhs)`` of region ``j`` held in ``src[ty, tx, j]``."""
        A = ti.Matrix.zero(ti.f32, NB, NB)
        rhs = ti.Vector.zero(ti.f32, NB)
        for n in ti.static(range(len(_PAIRS))):
            A[_PAIRS[n][0], _PAIRS[n][1]] = src[ty, tx, j, n]
            A[_PAIRS[n][1], _PAIRS[n][0]] = src[ty, tx, j, n]
        for a in ti.static(range(NB)):
            rhs[a] = src[ty, tx, j, 21 + a]
        return A, rhs

    @ti.func
    def _solve(self, A, rhs, ok):
        """Solve ``A theta = rhs`` (6x6) by Gaussian elimination with partial pivoting
        (unrolled: indices are static); ``ok`` comes in as 1 when the system has enough
        rows and goes out 0 when it is singular.  Returns ``(theta, ok)``."""
        scale = 0.0
        for a in ti.static(range(NB)):
            scale = ti.max(scale, ti.abs(A[a, a]))
        for col in ti.static(range(NB)):
            piv = col
            best = ti.abs(A[col, col])
            for r in ti.static(range(col + 1, NB)):
                if ti.abs(A[r, col]) > best:
                    best = ti.abs(A[r, col])
                    piv = r
            if best <= 1e-7 * scale or scale <= 0:
                ok = 0
            for r in ti.static(range(col + 1, NB)):
                if piv == r:
                    for cc in ti.static(range(NB)):
                        A[col, cc], A[r, cc] = A[r, cc], A[col, cc]
                    rhs[col], rhs[r] = rhs[r], rhs[col]
            if ok == 1:
                for r in ti.static(range(col + 1, NB)):
                    f = A[r, col] / A[col, col]
                    for cc in ti.static(range(col, NB)):
                        A[r, cc] -= f * A[col, cc]
                    rhs[r] -= f * rhs[col]
        sol = ti.Vector.zero(ti.f32, NB)
        if ok == 1:
            for i in ti.static(range(NB - 1, -1, -1)):
                s = rhs[i]
                for cc in ti.static(range(i + 1, NB)):
                    s -= A[i, cc] * sol[cc]
                sol[i] = s / A[i, i]
        return sol, ok

    @ti.func
    def _solve_root(self, root: ti.template()):
        ti.loop_config(serialize=True)
        for j in range(2):
            A, rhs = self._system(root, 0, 0, j)
            self.rows[j] = root[0, 0, j, 27]
            ok = 1 if root[0, 0, j, 27] >= NB else 0
            sol, ok = self._solve(A, rhs, ok)
            if ok == 1:
                for a in ti.static(range(NB)):
                    self.theta[j, a] = sol[a]
            self.updated[j] = ok

    def fit_local(self, weights, target):
        """The local background (:meth:`_fit_local`) from Eq. 8's rows ``weights`` of
        ``target``."""
        key = (id(weights), id(target))
        if key not in self._behind:     # one template argument per pair: one compile
            self._behind[key] = _Behind(weights, self, target)
        self._fit_local(self._behind[key], target)

    @ti.kernel
    def _fit_local(self, behind: ti.template(), target: ti.template()):
        """The local background: for every first-level tile, Eq. 8's weighted least squares
        of the background (the rows of ``weights`` whose ``target`` lies more than
        ``LOCAL_NEAR`` behind Theta_1: what stands in front of the object or on its surface
        is not its background) over the tiles within ``local`` tiles of it, weighted by a
        Gaussian of sigma ``local / 2`` tiles, plus ``LOCAL_PRIOR`` rows of the whole
        background whose targets are Theta_2 itself (the root's system ``A_2 / n_2`` times
        Theta_2).  Where a tile's neighbourhood holds a background of its own, its quadratic
        follows it (a shelf, a neighbour a few pixels behind the object); where it holds
        little (under the object), it stays near Theta_2.  Reads the root of the last
        :meth:`fit`; a singular system keeps Theta_2."""
        self._from_pixels(behind, target, self.local_tiles)
        height, width = self.extent.height(), self.extent.width()
        rows, columns = self._tiles_of(height, 0), self._tiles_of(width, 0)
        top = ti.static(self.tiles[-1])
        A_g, _ = self._system(top, 0, 0, 1)
        n_g = ti.max(top[0, 0, 1, 27], 1.0)
        theta_g = self._coefficients(1)
        prior = A_g * (LOCAL_PRIOR / n_g)
        prior_rhs = prior @ theta_g
        R = ti.static(self.local)
        inv_two_var = 2.0 / (R * R)            # 1 / (2 sigma^2) with sigma = R / 2
        for ty, tx in ti.ndrange(rows, columns):
            A = prior
            rhs = prior_rhs
            for dy, dx in ti.static(ti.ndrange((-R, R + 1), (-R, R + 1))):
                y = ty + dy
                x = tx + dx
                if 0 <= y < rows and 0 <= x < columns:
                    g = ti.exp(-(dy * dy + dx * dx) * inv_two_var)
                    A_t, rhs_t = self._system(self.local_tiles, y, x, 1)
                    A += g * A_t
                    rhs += g * rhs_t
            sol, ok = self._solve(A, rhs, 1)
            if ok == 0:
                sol = theta_g
            for a in ti.static(range(NB)):
                self.local_theta[ty, tx, a] = sol[a]
        self.local_ready[None] = 1

    @ti.kernel
    def fit(self, weights: ti.template(), target: ti.template()):
        """Weighted least squares of ``target`` (``(H, W)``, the consensus mean) over each
        region; updates ``theta``.  ``weights`` has a ``ti.func`` ``row_weights(y, x)``
        giving pixel (y, x)'s row weights ``[w_fg, w_bg]`` (0 outside a region), computed
        as the pixels are summed (no weight planes): :class:`RegionWeights` (Eq. 8's), or
        :class:`WeightPlanes`.  One launch: the reduction's levels run in order."""
        self.fit_func(weights, target)

    @ti.func
    def fit_func(self, weights: ti.template(), target: ti.template()):
        """:meth:`fit`, for a kernel that runs it with other stages."""
        self._from_pixels(weights, target, self.tiles[0])
        for i in ti.static(range(1, len(self.tiles))):
            self._from_tiles(self.tiles[i - 1], self.tiles[i], i)
        self._solve_root(self.tiles[-1])

    def update(self, iteration, params, cost):
        """The Theta update of iteration ``iteration`` (1-based): Eq. 8's fit of the consensus
        mean with :attr:`weights`, then, when it is due, the background's plane sweep over
        the matching cost ``cost`` (:meth:`~lss_kernels.model.sweep.BackgroundSweep.run`).
        Returns the sweep's plane (cyclopean disparity), or None when Theta_2 is the fit's."""
        w = self.weights
        self.fit(w, w.consensus)
        plane = self.sweep.run(iteration, params, cost, self, w.phi, w.phi_plus, w.consensus)
        if self.local:
            self.fit_local(w, w.consensus)
        return plane

    def set(self, theta_fg, theta_bg):
        """Set both shapes from normalised-basis coefficients (cyclopean units); a local
        background is dropped until the next fit."""
        self.extent.pool.write(self.theta, np.stack([theta_fg, theta_bg]).astype(np.float32))
        if self.local:
            self.local_ready.fill(0)

    def pixel_coefficients(self, scale=1.0):
        """``(2, 6)`` coefficients over raw cyclopean pixel coordinates."""
        th = self.extent.pool.read(self.theta)
        return np.stack([to_pixel_coefficients(t, self.H, self.W, scale) for t in th])


@ti.data_oriented
class _Behind:
    """``weights``' rows with the background's set to 0 where ``target`` lies within
    ``LOCAL_NEAR`` of Theta_1 or in front of it, and (when ``weights`` has ``phi``) within
    ``LOCAL_GAP`` pixels of the boundary (:meth:`GlobalShapes.fit_local`)."""

    def __init__(self, weights, shapes, target):
        self.weights, self.shapes, self.target = weights, shapes, target
        self.phi = getattr(weights, "phi", None)     # the boundary's distance, if known
        self.with_phi = self.phi is not None

    @ti.func
    def row_weights(self, y, x):
        w = self.weights.row_weights(y, x)
        front = self.shapes.value(0, ti.cast(x, ti.f32), ti.cast(y, ti.f32))
        if self.target[y, x] > front - LOCAL_NEAR:
            w[1] = 0.0
        if ti.static(self.with_phi):
            if self.phi[y, x] > -LOCAL_GAP * PHI_SCALE:
                w[1] = 0.0
        return w


@ti.data_oriented
class RegionWeights:
    """The rows of Eq. 8 (the ``weights`` of :meth:`GlobalShapes.fit`), read from the planes
    of one grid as the pixels are summed.

    Parameters
    ----------
    extent : Extent
        The image's size.
    precision, consensus : field
        The consensus precision 1 / sigma^2 and mean d-bar (Eq. 7).
    phi, phi_plus : field
        phi and phi(x + delta_theta).
    hidden : field, optional
        1 on the pixels that a layer in front of the object hides
        (:class:`~lss_kernels.model.front.FrontLayer`).
    """

    def __init__(self, extent, precision, consensus, phi, phi_plus, hidden=None):
        self.extent, self.precision, self.consensus = extent, precision, consensus
        self.phi, self.phi_plus, self.hidden = phi, phi_plus, hidden
        self.with_hidden = hidden is not None

    @ti.func
    def row_weights(self, y, x):
        """``[w_fg, w_bg]`` at pixel (y, x): the precision to the power ``WEIGHT_POWER`` on
        the foreground (phi >= 0) and on the visible background (phi < 0 and
        phi(x + delta_theta) < 0), 0 elsewhere, and 0 on the pixels that ``hidden`` marks."""
        p = self.precision[y, x]
        w = p
        for _ in ti.static(range(WEIGHT_POWER - 1)):
            w *= p
        phi = self.phi[y, x]
        # a consensus whose correspondence falls outside the other image (x - c < 0 or
        # x + c > W - 1) is no evidence: its costs compare clamped border columns
        c = self.consensus[y, x]
        xf = ti.cast(x, ti.f32)
        if xf - c < 0.0 or xf + c > self.extent.width() - 1.0:
            w = 0.0
        w_fg = 0.0
        w_bg = 0.0
        if phi >= 0:
            w_fg = w
        elif self.phi_plus[y, x] < 0:
            w_bg = w
        if ti.static(self.with_hidden):
            if self.hidden[y, x] == 1:     # no evidence for either layer
                w_fg = 0.0
                w_bg = 0.0
        return ti.Vector([w_fg, w_bg])


@ti.data_oriented
class WeightPlanes:
    """Row weights held in two ``(H, W)`` planes, ``weight_fg`` and ``weight_bg`` (0 outside
    each region), as the ``weights`` of :meth:`GlobalShapes.fit`.  Each instance is its own
    kernel template argument: build one per pair of planes and reuse it."""

    def __init__(self, weight_fg, weight_bg):
        self.weight_fg, self.weight_bg = weight_fg, weight_bg

    @ti.func
    def row_weights(self, y, x):
        return ti.Vector([self.weight_fg[y, x], self.weight_bg[y, x]])
