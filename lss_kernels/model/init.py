"""Initial foreground without a hand-drawn ellipse: ``"auto"``, a :class:`Point` or a :class:`Box`.

The paper starts phi from an ellipse placed by hand.  These initialisations find the object
from the method's own machinery instead: the first consensus of the cooperative hierarchy
(Eqs. 5 and 7 with no prior, every patch valid) gives a disparity d-bar per cyclopean pixel with its
precision; pixels of zero precision have no d-bar.  Per pixel, in kernels, d-bar is first
median-filtered (``MEDIAN`` squared, as phi is after each Eq. 2 step), which fills the gaps
and removes stray matches.  Then:

* the *near* pixels are those whose d-bar stands above the background on both sides along
  the epipolar line (the row): ``d - max(min over [x-L, x-1], min over [x+1, x+L]) >
  contrast``, the minima over d-bar's 5x5 maxima, ``L = WINDOW * W``;
* ``Point(x, y)``: the object under the pixel is the 4-connected region grown from it over
  pixels whose d-bar lies within a band of the seed's (the median of a 7x7 window; half-width
  ``BAND`` times the seed's d-bar, at least ``BAND_MIN``) and within the same of a
  neighbour's (a depth-coherent flood fill): over the near pixels when the seed is one of
  them (the band alone would run along a table at the object's depth), else over every
  pixel (an object wider than ``L``, or one beside a nearer one).  A weakly textured object
  has no d-bar to follow: where that region is smaller than ``MIN_AREA`` of the image, or
  where most of the seed's 7x7 window is *uncertain* (precision below ``UNCERTAIN`` of the
  image's median), the region also takes the 4-connected pixels of the seed's *tone*: the
  left image's grey value at the seed's depth within ``TONE_SPREAD`` robust deviations
  (at least ``TONE_MIN``) of the median of the seed's window; only the uncertain ones, in
  the second case.  The object's own matches then set its depth in the evolution, which
  the d-bar of a uniform surface could not;
* ``Box(x0, y0, x1, y1)``: the region of ``Point`` at the box's centre, cut to the box
  (moved to the cyclopean frame by the seed's d-bar); the ellipse inscribed in the box
  (``BOX_SPILL``) when the centre has no confident match, when its region in the box is
  smaller than ``MIN_AREA`` of the image or ``MIN_BOX_COVER`` of the box (the centre is off
  the object, as in the box of an L), or when the left image is periodic
  (:mod:`lss_kernels.checks.periodicity`, which the caller applies);
* ``"auto"``: the near pixels that also stand more than ``CONTRAST`` above the background
  surface, a quadratic fitted to d-bar robustly (:func:`background_fit`, a stand-in for
  the model's Theta_2 before the object is known): a floor or a wall whose depth bulges
  along the rows is near by the row test but not above its own fit.  They are opened by an
  ``OPENING`` square (thin ridges and specks go); their 4-connected components are the
  candidates, and the one with the largest ``area * (1 - 1.5 r)^2`` (``r`` = its
  centroid's distance from the image centre, as a fraction of the half-diagonal) is the
  object: the largest near region closest to the centre.  When no candidate is left, the
  fit is made again from the pixels that are not near, with ``CONTRAST`` as its band: an
  object less than the band in front (``fine_jump3``, 1.5 cyclopean pixels) is among the
  first fit's inliers, and the quadratic bulges over it.  It then takes back the near
  pixels within ``REGROW`` of it: an object large enough to pull the fit up loses its rim
  to the fit.  A candidate over ``NEST_AREA`` of the image is looked into: it may be the
  object with the surface it stands on, nearer than a far wall (paper15 scenes 1 and 13).
  The candidate of its pixels ``NEST_CONTRAST`` above a quadratic fitted to its own d-bar
  is then the object, when it holds ``NEST_SHARE`` of it (a large object's bulge above
  its own quadratic holds less; ``docs/design.md``), and regrows over pixels ``CONTRAST``
  above that fit.  On a periodic left image ``auto`` has no ellipse to fall back on: it
  goes on, and the solver warns :class:`~lss_kernels.start_types.UnreliableStartWarning`.

A found region starts phi widened by ``SPILL`` pixels: a start that spills over the object is
recovered by the evolution, one that covers only part of it is not always (paper15 scene 4:
Theta_2 bulges over the uncovered part).  Except, for a point's and a box's region, towards
the left (``SPILL_LEFT``): the object's left edge is where the background is seen by the
left camera only, and a start that spills over it can carry the foreground on over the
background (paper15 scene 2's tall pin spreads over the wall beside it).

Every choice is reported in :attr:`InitialRegion.info`.
"""
import math

import numpy as np
import taichi as ti

from ..kernels.median import Assign, MedianFilter
from ..start_types import AUTO, Box, InitError, Point
from .quadratic import basis

# the passes of InitialRegion._region_pass
_MARK_NEAR, _KEEP_ABOVE, _PROPAGATE, _SEED, _GROW, _OPEN = range(1, 7)

__all__ = ["InitialRegion", "BOX_SPILL", "MIN_BOX_COVER", "SPILL", "SPILL_LEFT",
           "background_fit", "shift_columns"]

BOX_SPILL = 1.0          # a box's ellipse radii over the box's half sides
MEDIAN = 7               # d-bar's median window, pixels
CONTRAST = 1.0           # near-pixel contrast, cyclopean pixels
WINDOW = 0.5             # row window L of the contrast, fraction of the width
BAND = 0.06              # a point's depth band, fraction of the seed's d-bar
BAND_MIN = 1.0           # ... at least, cyclopean pixels
OPENING = 5              # auto: side of the square that opens the near pixels, pixels
BACKGROUND_BAND = 3.0    # auto: inliers of the background's robust fit, cyclopean pixels,
SPREAD = 2.5             # ... or this many robust deviations (MAD) of its inliers if wider
REGROW = 8               # ... and grows back over near pixels this far, pixels
FIT_ROUNDS = 6           # ... rounds of the fit
FIT_SAMPLES = 20000      # ... at most this many pixels (a regular subsample) enter it
SPILL = 6                # a found region's widening, pixels
SPILL_LEFT = 0           # ... a point's (and a box's) towards the left, pixels
MIN_BOX_COVER = 0.25     # a box's region: smallest fraction of the box it covers
MIN_AREA = 0.005         # smallest candidate region, fraction of the image
NEST_AREA = 0.2          # auto: a candidate over this fraction of the image is looked into,
NEST_CONTRAST = 2.0      # ... for pixels this far above its own quadratic (cyclopean px)
NEST_SHARE = 0.05        # ... forming a candidate of at least this fraction of it
MAX_ROUNDS = 4096        # propagation launches before a region is taken as it stands
UNCERTAIN = 1.0 / 16.0   # a point's tone: d-bar uncertain below this share of the median
                         # precision (its deviation 4 times the median's)
TONE_SPREAD = 3.0        # ... the seed's tone: within this many robust deviations of the
TONE_MIN = 0.03          # ... median grey of its 7x7 window, and at least this (grey, 0-1)



def box_ellipse(box, spill: float = BOX_SPILL) -> tuple:
    """The ellipse ``(cx, cy, rx, ry)`` inscribed in ``box``, radii widened by ``spill``."""
    return ((box.x0 + box.x1) / 2.0, (box.y0 + box.y1) / 2.0,
            spill * (box.x1 - box.x0) / 2.0, spill * (box.y1 - box.y0) / 2.0)


def pick_region(labels: np.ndarray, min_area: int):
    """The candidate of ``labels`` (``-1`` = none) with the largest
    ``area * (1 - 1.5 r)^2``; returns ``(mask, facts)`` or ``(None, facts)``."""
    H, W = labels.shape
    ys, xs = np.nonzero(labels >= 0)
    ids, inverse, area = np.unique(labels[ys, xs], return_inverse=True, return_counts=True)
    large = area >= min_area
    if not large.any():
        return None, {"candidates": 0}
    cy = np.bincount(inverse, weights=ys) / area
    cx = np.bincount(inverse, weights=xs) / area
    r = np.hypot(cx - (W - 1) / 2.0, cy - (H - 1) / 2.0) / math.hypot(W / 2.0, H / 2.0)
    score = np.where(large, area * np.clip(1.0 - 1.5 * r, 0.0, None) ** 2, -1.0)
    best = int(np.argmax(score))
    facts = {"candidates": int(large.sum()), "area": int(area[best]),
             "centroid": [float(cx[best]), float(cy[best])], "score": float(score[best]),
             "rule": "largest area * (1 - 1.5 r)^2, r = distance from the image centre / "
                     "half-diagonal"}
    return labels == ids[best], facts


def _basis(x, y, H: int, W: int) -> np.ndarray:
    """``(x^2, xy, y^2, x, y, 1)`` of the normalised coordinates ``x / W - 1/2``,
    ``y / H - 1/2`` (float64, the last axis)."""
    return basis(np.asarray(x, np.float64) / W - 0.5, np.asarray(y, np.float64) / H - 0.5)


def background_fit(d: np.ndarray, band: float = BACKGROUND_BAND, rounds: int = FIT_ROUNDS,
                   samples: int = FIT_SAMPLES, start: np.ndarray = None):
    """A quadratic fitted to the background of ``d`` (an ``(H, W)`` map, negative = no
    value) robustly: least squares over every value, then ``rounds`` times over the values
    within ``band`` of the last fit (an object in front, or stray matches, drop out).
    The band widens to ``SPREAD`` robust standard deviations (1.4826 times the median
    absolute residual) of the last inliers where d-bar is noisier than ``band``.  ``start``
    (an ``(H, W)`` boolean mask): the first fit is over its values only.  Returns
    ``(coefficients on _basis, facts)``, or ``(None, facts)`` with fewer than 6 values."""
    H, W = d.shape
    ys, xs = np.nonzero(d >= 0)
    if xs.size < 6:
        return None, {"values": int(xs.size)}
    step = max(1, xs.size // samples)
    ys, xs = ys[::step], xs[::step]
    rows, value = _basis(xs, ys, H, W), d[ys, xs].astype(np.float64)
    inliers = np.ones(value.shape, bool)
    if start is not None and start[ys, xs].sum() >= 6:
        inliers = start[ys, xs]
    for _ in range(rounds + 1):
        if inliers.sum() < 6:
            break
        coefficients = np.linalg.lstsq(rows[inliers], value[inliers], rcond=None)[0]
        residual = np.abs(value - rows @ coefficients)
        width = max(band, SPREAD * 1.4826 * float(np.median(residual[inliers])))
        inliers = residual <= width
    return coefficients, {"values": int(value.size), "inliers": float(inliers.mean()),
                          "band": width}


def shift_columns(mask: np.ndarray, shift: float) -> np.ndarray:
    """A boolean mask moved right by ``round(shift)`` columns (left if negative): an initial
    region from one frame to the other (x_left = x_c + c)."""
    k = int(round(shift))
    out = np.zeros_like(mask, dtype=bool)
    if k >= 0:
        out[:, k:] = mask[:, :mask.shape[1] - k]
    else:
        out[:, :k] = mask[:, -k:]
    return out


@ti.data_oriented
class InitialRegion:
    """Fields and kernels that find the initial foreground from the first consensus (all
    ``(H, W)``, cyclopean frame); ``grown``: the last box's region before its cut."""

    def __init__(self, pool, H: int, W: int):
        self.H, self.W = H, W
        self.pool = pool
        self.d = pool.field(ti.f32, (H, W))         # d-bar (-1: no match), then its median
        self.d_hi = pool.field(ti.f32, (H, W))      # d-bar's largest over a 5x5 window
        self.label = pool.field(ti.i32, (H, W))     # region id, -1 outside
        self.inside = pool.field(ti.i32, (H, W))    # a region before widening or opening
        self.changed = pool.field(ti.i32, ())
        pool.host(self.d, self.label)
        self.median = MedianFilter.shared(pool, H, W, MEDIAN)
        self.info, self.grown = {}, None
        #: widest layer in front of the object that a point's region is carried across
        #: (:meth:`_bridge`), cyclopean pixels; 0: none (the paper's two layers)
        self.bridge_gap = 0

    @ti.kernel
    def load(self, mean: ti.template(), precision: ti.template()):
        """d-bar from the first consensus, also into the shared median's source
        (:meth:`smooth`)."""
        for y, x in self.d:
            d = mean[y, x] if precision[y, x] > 0 else -1.0
            self.d[y, x] = d
            self.median.source[y, x] = d

    def smooth(self):
        """d-bar <- its ``MEDIAN`` squared median (symmetric borders; no match counts as -1),
        from the copy that :meth:`load` left in the median's source."""
        self.median.run(self.median.source, Assign(self.d))

    # The start's passes are one kernel (:meth:`_launch`): each pass a parallel loop over the image that runs
    # for its own ``op`` only (the others' loops have no rows), with the pass's arguments.
    @ti.kernel
    def _region_pass(self, op: ti.i32, i0: ti.i32, i1: ti.i32, i2: ti.i32, f0: ti.f32,
                     f1: ti.f32, f2: ti.f32, c: ti.types.vector(6, ti.f32)) -> ti.i32:
        self.changed[None] = 0
        self._mark_near(ti.select(op == _MARK_NEAR, self.H, 0), i0, f0)
        self._keep_above(ti.select(op == _KEEP_ABOVE, self.H, 0), c, f0)
        self._propagate(op == _PROPAGATE)
        self._seed(ti.select(op == _SEED, self.H, 0), i0, i1, i2, f0)
        self._grow(op == _GROW, f0, f1, f2)
        self._bridge(ti.select(op == _GROW and i2 > 0, self.H, 0), f0, f1, i2)
        self._erode(ti.select(op == _OPEN, self.H, 0), i0)
        self._dilate(ti.select(op == _OPEN, self.H, 0), i1, i2)
        return self.changed[None]

    def _launch(self, op, i0=0, i1=0, i2=0, f0=0.0, f1=0.0, f2=0.0, c=(0.0,) * 6):
        """Run pass ``op``; returns whether it changed a label (:meth:`propagate`,
        :meth:`grow`)."""
        return self._region_pass(op, int(i0), int(i1), int(i2), float(f0), float(f1), float(f2),
                          np.asarray(c, np.float32))

    def mark_near(self, window, contrast):
        """Label each near pixel with its own index, the others -1 (the module doc).  The
        minima run over d-bar's 5x5 maxima, so a few stray low matches do not pull the
        ground down."""
        self._launch(_MARK_NEAR, i0=window, f0=contrast)

    def keep_above(self, c, contrast):
        """Labelled pixels whose d-bar is not ``contrast`` above the quadratic ``c``
        (:func:`background_fit`) lose their label."""
        self._launch(_KEEP_ABOVE, f0=contrast, c=c)

    def propagate(self):
        """Each labelled pixel takes the largest label of its run along its row (a sweep each
        way, a thread per row), then along its column: until stable, every 4-connected
        component gets its largest label."""
        return self._launch(_PROPAGATE)

    def seed(self, sy, sx, seed_d=None, keep_near=False):
        """The region is pixel ``(sy, sx)`` alone; with ``keep_near``, first the pixels that
        are not near lose their d-bar (a region grown next stays on near ones); with
        ``seed_d``, the seed's d-bar becomes it."""
        self._launch(_SEED, i0=sy, i1=sx, i2=int(keep_near) + 2 * int(seed_d is not None),
                     f0=seed_d if seed_d is not None else 0.0)

    def grow(self, seed_d, tolerance, step, gap=0):
        """Pixels next to the region whose d-bar is close to the seed's and the neighbour's
        join it; then, with ``gap`` > 0, the region is carried across thin layers in front
        of it (:meth:`_bridge`)."""
        return self._launch(_GROW, i2=gap, f0=seed_d, f1=tolerance, f2=step)

    def open(self, erode, radius, left=None):
        """``inside``: the labelled pixels whose whole ``2 erode + 1`` square (in the image)
        is labelled (``erode`` 0: the labelled pixels); then ``inside`` widened by
        ``radius`` up, down and to the right and by ``left`` (default ``radius``) to the
        left: each pixel with an ``inside`` pixel in rows ``y - radius .. y + radius``,
        columns ``x - radius .. x + left``, is labelled with its own index, the others -1."""
        self._launch(_OPEN, i0=erode, i1=radius, i2=radius if left is None else left)

    @ti.func
    def _mark_near(self, rows, window, contrast):
        for y, x in ti.ndrange(rows, self.W):
            hi = -1.0
            for v, u in ti.ndrange((y - 2, y + 3), (x - 2, x + 3)):
                if 0 <= v < self.H and 0 <= u < self.W:
                    hi = ti.max(hi, self.d[v, u])
            self.d_hi[y, x] = hi
        for y, x in ti.ndrange(rows, self.W):
            d = self.d[y, x]
            lo_l, lo_r = 1e9, 1e9
            for k in range(1, window + 1):
                if x - k >= 0 and self.d_hi[y, x - k] >= 0:
                    lo_l = ti.min(lo_l, self.d_hi[y, x - k])
                if x + k < self.W and self.d_hi[y, x + k] >= 0:
                    lo_r = ti.min(lo_r, self.d_hi[y, x + k])
            ground = ti.max(lo_l, lo_r)
            if lo_l > 1e8 or lo_r > 1e8:
                ground = ti.min(lo_l, lo_r)
            self.label[y, x] = -1
            if d >= 0 and ground < 1e8 and d - ground > contrast:
                self.label[y, x] = y * self.W + x

    @ti.func
    def _keep_above(self, rows, c, contrast):
        for y, x in ti.ndrange(rows, self.W):
            xn = (ti.cast(x, ti.f32) / self.W) - 0.5
            yn = (ti.cast(y, ti.f32) / self.H) - 0.5
            ground = c[0] * xn * xn + c[1] * xn * yn + c[2] * yn * yn + c[3] * xn \
                + c[4] * yn + c[5]
            if self.label[y, x] >= 0 and self.d[y, x] - ground <= contrast:
                self.label[y, x] = -1

    @ti.func
    def _propagate(self, on):
        for y in range(ti.select(on, self.H, 0)):
            for way in ti.static(range(2)):
                run = -1
                for k in range(self.W):
                    run = self._carry(y, k if way == 0 else self.W - 1 - k, run)
        for x in range(ti.select(on, self.W, 0)):
            for way in ti.static(range(2)):
                run = -1
                for k in range(self.H):
                    run = self._carry(k if way == 0 else self.H - 1 - k, x, run)

    @ti.func
    def _carry(self, y, x, run):
        """A sweep's step: the run's largest label so far, given to (y, x); -1 off it."""
        own = self.label[y, x]
        out = -1
        if own >= 0:
            out = ti.max(run, own)
            if out != own:
                self.label[y, x] = out
                self.changed[None] = 1
        return out

    @ti.func
    def _seed(self, rows, sy, sx, how, seed_d):
        for y, x in ti.ndrange(rows, self.W):
            if how % 2 == 1 and self.label[y, x] < 0:      # keep near
                self.d[y, x] = -1.0
            self.label[y, x] = 1 if (y == sy and x == sx) else -1
            if how >= 2 and y == sy and x == sx:
                self.d[y, x] = seed_d

    @ti.func
    def _grow(self, on, seed_d, tolerance, step):
        """Sweeps along each row both ways (a thread per row), then along each column: a
        pixel joins the region from the neighbour just swept, so a run of joining pixels
        joins in one sweep (the region :meth:`grow` reaches, in far fewer launches than a
        step from every labelled neighbour at once)."""
        for y in range(ti.select(on, self.H, 0)):
            for way in ti.static(range(2)):
                for k in range(1, self.W):
                    x = k if way == 0 else self.W - 1 - k
                    self._join(y, x, y, x - 1 if way == 0 else x + 1, seed_d, tolerance, step)
        for x in range(ti.select(on, self.W, 0)):
            for way in ti.static(range(2)):
                for k in range(1, self.H):
                    y = k if way == 0 else self.H - 1 - k
                    self._join(y, x, y - 1 if way == 0 else y + 1, x, seed_d, tolerance, step)

    @ti.func
    def _join(self, y, x, v, u, seed_d, tolerance, step):
        """(y, x) joins the region when its d-bar lies within ``tolerance`` of the seed's and
        within ``step`` of its labelled neighbour (v, u)'s."""
        d = self.d[y, x]
        if self.label[y, x] < 0 and d >= 0 and ti.abs(d - seed_d) <= tolerance:
            if self.label[v, u] == 1 and ti.abs(self.d[v, u] - d) <= step:
                self.label[y, x] = 1
                self.changed[None] = 1

    @ti.func
    def _bridge(self, rows, seed_d, tolerance, max_gap):
        """Carry the region across a thin layer in front of it: from a region pixel, along
        its row and its column, over at most ``max_gap`` pixels whose d-bar stands more than
        ``tolerance`` in front of the seed's, to a pixel within ``tolerance`` of the seed's,
        which joins the region with the pixels crossed."""
        for y, x in ti.ndrange(rows, self.W):
            if self.label[y, x] == 1:
                for k in ti.static(range(4)):
                    dy, dx = ti.static(((0, 1), (0, -1), (1, 0), (-1, 0))[k])
                    far = 0
                    for step in range(1, max_gap + 2):
                        v, u = y + step * dy, x + step * dx
                        if far == 0:
                            if not (0 <= v < self.H and 0 <= u < self.W):
                                far = -1
                            elif self.d[v, u] <= seed_d + tolerance:   # the far side
                                far = -1
                                if step > 1 and self.d[v, u] >= 0 and \
                                        ti.abs(self.d[v, u] - seed_d) <= tolerance:
                                    far = step
                    if far > 1:
                        for step in range(1, far + 1):
                            v, u = y + step * dy, x + step * dx
                            if self.label[v, u] != 1:
                                self.label[v, u] = 1
                                self.changed[None] = 1

    @ti.func
    def _erode(self, rows, radius):
        for y, x in ti.ndrange(rows, self.W):
            keep = 1
            for v, u in ti.ndrange((y - radius, y + radius + 1), (x - radius, x + radius + 1)):
                if 0 <= v < self.H and 0 <= u < self.W and self.label[v, u] < 0:
                    keep = 0
            self.inside[y, x] = keep

    @ti.func
    def _dilate(self, rows, radius, left):
        for y, x in ti.ndrange(rows, self.W):
            hit = 0
            for v, u in ti.ndrange((y - radius, y + radius + 1), (x - radius, x + left + 1)):
                if 0 <= v < self.H and 0 <= u < self.W and self.inside[v, u] == 1:
                    hit = 1
            self.label[y, x] = y * self.W + x if hit == 1 else -1

    def until_stable(self, launch) -> int:
        """Launch a pass (:meth:`propagate`, :meth:`grow`) until it changes nothing; returns
        the rounds it took."""
        for rounds in range(1, MAX_ROUNDS + 1):
            if launch() == 0:
                return rounds
        return MAX_ROUNDS

    def find(self, init, mean, precision, periodic: float = 0.0, tone=None) -> tuple:
        """The initial region for ``init`` (``"auto"``, :class:`Point` or :class:`Box`) as
        ``(ellipse, "left")`` for a box whose centre gives no region, else
        ``(mask, "cyclopean")``, an ``(H, W)`` boolean
        mask, for :class:`~lss_kernels.Solver`; fills :attr:`info`.

        ``mean`` and ``precision`` are the first consensus (cyclopean pixels); ``periodic``
        the share of the left image's tiles that are periodic when the image counts as
        periodic (:mod:`lss_kernels.checks.periodicity`), else 0: a box's start then ignores the
        consensus, and ``auto`` records a warning in :attr:`info` (the caller issues it).
        ``tone``: ``(image, precision)``, the left view's grey values in [0, 1] (the model's
        frame) and ``precision`` on the host, both ``(H, W)``, for a point's tone
        (:meth:`_by_tone`); None: a point's region follows d-bar only."""
        self.load(mean, precision)
        self.smooth()
        self.mark_near(max(int(WINDOW * self.W), 1), CONTRAST)
        if isinstance(init, Box):
            return self._box(init, periodic)
        mask = self._point(init, tone) if isinstance(init, Point) else self._auto()
        self.info["area"] = int(mask.sum())
        if init == AUTO:
            self.info["periodic"] = periodic
            if periodic > 0:
                self.info["warning"] = (
                    f"init auto: the left image is periodic ({periodic:.0%} of its tiles), so "
                    f"the first consensus that the start is found from is ambiguous and the "
                    f"start may be the wrong region; check overlay.png, or start from a "
                    f"point, a box or an ellipse")
        return mask, "cyclopean"

    def _box(self, box, periodic: float = 0.0):
        """The region of the point at the box's centre, cut to the box; else its ellipse
        (always on a periodic left image: ``periodic`` > 0, as for :meth:`find`)."""
        facts = {"kind": "box", "box": [box.x0, box.y0, box.x1, box.y1]}
        centre = Point((box.x0 + box.x1) / 2.0, (box.y0 + box.y1) / 2.0)
        mask = None
        if periodic > 0:
            why = (f"the left image is periodic ({periodic:.0%} of its tiles): the first "
                   f"consensus is not trusted")
        else:
            try:
                mask = self._point(centre)
            except InitError as error:
                why = str(error)
        if mask is not None:
            shift = self.info["seed_disparity"] / 2.0        # x_left = x_c + c
            x = np.arange(self.W) + shift
            y = np.arange(self.H)
            self.grown, mask = mask, mask & ((y >= box.y0) & (y < box.y1))[:, None] & (
                (x >= box.x0) & (x < box.x1))
            area = int(mask.sum())
            cover = area / max((box.x1 - box.x0) * (box.y1 - box.y0), 1.0)
            why = (f"the centre's region has {area} pixels in the box ({cover:.0%} of it), "
                   f"fewer than {MIN_AREA:.1%} of the image or {MIN_BOX_COVER:.0%} of the box")
            if area >= MIN_AREA * self.H * self.W and cover >= MIN_BOX_COVER:
                self.info = {**facts, "centre": self.info, "area": area, "cover": cover,
                             "from": "the region under the box's centre, cut to the box"}
                return mask, "cyclopean"
        ellipse = box_ellipse(box)
        self.info = {**facts, "from": "the inscribed ellipse", "why": why,
                     "ellipse_left": list(ellipse)}
        return ellipse, "left"

    def _widened(self, radius: int = SPILL, left: int = None) -> np.ndarray:
        """The labelled pixels widened by ``radius`` (``left`` to the left), as a mask."""
        self.open(0, radius, left)
        return self.pool.read(self.label) >= 0

    def _candidates(self, background):
        """The near pixels ``contrast`` above ``background`` (None: all of them), opened,
        as 4-connected candidates; the one :func:`pick_region` picks, as ``(mask, facts)``."""
        if background is not None:
            self.keep_above(background.astype(np.float32), CONTRAST)
        self.open(OPENING // 2, OPENING // 2)
        rounds = self.until_stable(self.propagate)
        mask, facts = pick_region(self.pool.read(self.label), int(MIN_AREA * self.H * self.W))
        return mask, {**facts, "rounds": rounds}

    def _nested(self, mask, near, d):
        """The object inside a large candidate ``mask`` (module text): ``(mask, near)``, the
        inner candidate and ``near`` cut to the pixels ``CONTRAST`` above the inner fit
        when it is taken, else the arguments."""
        inner, fit = background_fit(np.where(mask, d, -1.0))
        self.info["nested"] = info = {"outer_area": int(mask.sum()), "fit": fit, "taken": False}
        if inner is None:
            return mask, near
        index = np.arange(self.H * self.W, dtype=np.int32).reshape(self.H, self.W)
        self.pool.write(self.label, np.where(mask, index, -1).astype(np.int32))
        self.keep_above(inner.astype(np.float32), NEST_CONTRAST)
        sub, facts = self._candidates(None)
        info.update(facts)
        if sub is None or sub.sum() < NEST_SHARE * mask.sum():
            return mask, near
        info["taken"] = True
        surface = _basis(*np.mgrid[0:self.H, 0:self.W][::-1], self.H, self.W) @ inner
        return sub, near & (d - surface > CONTRAST)

    def _point(self, point, tone=None):
        """The region of ``point`` (the module text), widened; ``tone``: ``(image,
        precision)`` as :meth:`_by_tone` takes them, for a point's region also of its tone."""
        H, W = self.H, self.W
        d = self.pool.read(self.d)
        y, xc = (min(max(int(round(v)), 0), n - 1) for v, n in ((point.y, H), (point.x, W)))
        for _ in range(3):                       # left view -> cyclopean: x_c = x - c(x_c)
            c = max(float(d[y, xc]), 0.0)
            xc = int(round(min(max(point.x - c, 0.0), W - 1.0)))
        patch = d[max(y - 3, 0):y + 4, max(xc - 3, 0):xc + 4]
        patch = patch[patch >= 0]
        if patch.size == 0:
            raise InitError(f"init: no confident match near the point ({point.x}, {point.y}); "
                            f"pick a textured pixel on the object")
        seed_d = float(np.median(patch))
        band = max(BAND_MIN, BAND * seed_d)
        near = bool(self.pool.read(self.label)[y, xc] >= 0)
        self.seed(y, xc, seed_d, keep_near=near)
        rounds = self.until_stable(lambda: self.grow(seed_d, band, band, self.bridge_gap))
        found = int((self.pool.read(self.label) == 1).sum())
        self.info = {"kind": "point", "point": [point.x, point.y], "seed_cyclopean": [xc, y],
                     "seed_disparity": 2.0 * seed_d, "band_px": 2.0 * band,
                     "over": "near pixels" if near else "all pixels", "found": found,
                     "rounds": rounds, "spill": SPILL, "spill_left": SPILL_LEFT}
        if tone is not None:
            found = self._by_tone(y, xc, seed_d, *tone)
        if self.bridge_gap > 0:
            self.info["bridge_px"] = 2 * self.bridge_gap
        if found < MIN_AREA * H * W:
            raise InitError(f"init: the region under the point ({point.x}, {point.y}) has "
                            f"{found} pixels, fewer than {MIN_AREA:.1%} of the "
                            f"image: no object found there")
        return self._widened(SPILL, SPILL_LEFT)

    def _by_tone(self, y, xc, seed_d, image, precision) -> int:
        """The point's region (label 1) joined, when it is small or its seed uncertain (the
        module text), by the 4-connected pixels of the seed's tone; returns its area and
        records the tone in :attr:`info`.  ``image``: the left view's grey values, ``(H,
        W)``; ``precision``: the first consensus's, ``(H, W)`` (cyclopean frame)."""
        H, W = self.H, self.W
        region = self.pool.read(self.label) == 1
        window = np.s_[max(y - 3, 0):y + 4, max(xc - 3, 0):xc + 4]
        known = precision[precision > 0]
        uncertain = precision < UNCERTAIN * (float(np.median(known)) if known.size else 0.0)
        small = region.sum() < MIN_AREA * H * W
        if not small and not uncertain[window].mean() > 0.5:
            return int(region.sum())
        # the grey value of the left pixel that each cyclopean pixel shows at the seed's
        # depth (x_left = x_c + c)
        columns = np.clip(np.round(np.arange(W) + seed_d).astype(int), 0, W - 1)
        grey = np.asarray(image, np.float64)[:, columns]
        median = float(np.median(grey[window]))
        spread = 1.4826 * float(np.median(np.abs(grey[window] - median)))
        tolerance = max(TONE_MIN, TONE_SPREAD * spread)
        alike = np.abs(grey - median) <= tolerance
        if not small:
            alike &= uncertain
        index = np.arange(H * W, dtype=np.int32).reshape(H, W)
        self.pool.write(self.label, np.where(region | alike, index, -1).astype(np.int32))
        self.until_stable(self.propagate)
        labels = self.pool.read(self.label)
        joined = (labels == labels[y, xc]) if labels[y, xc] >= 0 else region
        self.pool.write(self.label, np.where(joined, 1, -1).astype(np.int32))
        self.info["tone"] = {"why": ("the region of d-bar is small" if small else
                                     "the seed's d-bar is uncertain"),
                             "grey": median, "tolerance": tolerance,
                             "added": int((joined & ~region).sum())}
        return int(joined.sum())

    def _auto(self):
        labels = self.pool.read(self.label)
        near = labels >= 0
        d = self.pool.read(self.d)
        background, fit = background_fit(d)
        mask, facts = self._candidates(background)
        if mask is None and background is not None:
            # a jump below the fit's band leaves the object among the fit's inliers, and the
            # quadratic bulges over it: fit again from the pixels that are not near, with
            # the near pixels' own contrast as the band
            self.pool.write(self.label, labels)
            background, fit = background_fit(d, band=CONTRAST, start=~near)
            mask, facts = self._candidates(background)
            fit["start"] = "the pixels that are not near (no region above the first fit)"
        self.info = {"kind": "auto", "contrast_px": 2.0 * CONTRAST,
                     "window": int(WINDOW * self.W), "background_fit": fit,
                     "opening": OPENING, "spill": SPILL, **facts}
        if mask is None:
            raise InitError("init auto: no foreground found (no region stands nearer than "
                            "its surroundings); give --init point:X,Y, box:X0,Y0,X1,Y1 or "
                            "an ellipse")
        if mask.sum() > NEST_AREA * self.H * self.W:
            mask, near = self._nested(mask, near, d)
        # the object's extent: its near pixels within REGROW of the pixels above the fit
        # (where the object pulls the fit up, its rim is not above it)
        self.pool.write(self.label, np.where(mask, 0, -1).astype(np.int32))
        self.open(0, REGROW)
        mask = ((self.pool.read(self.label) >= 0) & near) | mask
        self.pool.write(self.label, np.where(mask, 0, -1).astype(np.int32))
        return self._widened()
