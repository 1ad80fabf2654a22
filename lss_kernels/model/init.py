"""Initial foreground without a hand-drawn ellipse: ``"auto"``, a :class:`Point` or a :class:`Box`.

The paper starts phi from an ellipse placed by hand.  These initialisations find the object
from the method's own machinery instead: the first consensus of the cooperative hierarchy
(Eqs. 4-6 with no prior and no validity, brought down to the pixels) gives a disparity d-bar
per cyclopean pixel with its precision.  Then, per pixel, in kernels:

* ``Point(x, y)``: the object under the pixel is the 4-connected region grown from it over
  pixels whose d-bar differs from the seed's by at most ``tolerance`` and from a neighbour's
  by at most ``step`` (a depth-coherent flood fill).
* ``Box(x0, y0, x1, y1)``: the object inside the box: the ellipse inscribed in it
  (``BOX_SPILL``; on the paper's scenes with the true boxes, mean F1 0.739 at 1.0 against
  0.658 with the radii widened to 1.15).
* ``"auto"``: the *near* pixels are those whose d-bar stands above the background on both
  sides along the epipolar line (the row): ``d - max(min over [x-L, x-1], min over
  [x+1, x+L]) > contrast``; their 4-connected components are the candidates, and the one
  with the largest ``area * (1 - 1.5 * r)^2`` (``r`` = its centroid's distance from the image
  centre, as a fraction of the half-diagonal) is the object: the largest near region closest
  to the centre.

A region found by a point or ``auto`` starts phi as the ellipse of the region's bounding
box widened by ``REGION_SPILL`` (a start that spills over the object is recovered by the
evolution, one that covers only part of it is not).  Every choice is reported in :attr:`InitialRegion.info`.
"""
from dataclasses import dataclass
import math

import numpy as np
import taichi as ti

__all__ = ["Point", "Box", "AUTO", "InitialRegion", "InitError", "BOX_SPILL", "REGION_SPILL"]

AUTO = "auto"
BOX_SPILL = 1.0          # a box's ellipse radii over the box's half sides
REGION_SPILL = 1.15      # a found region's ellipse radii over its bounding box's half sides
CONTRAST = 1.5           # near-pixel contrast (auto), cyclopean pixels
WINDOW = 0.5             # row window L of the contrast (auto), fraction of the width
MIN_AREA = 0.005         # smallest candidate region, fraction of the image
STEP = 0.75              # flood-fill step between neighbours (point), cyclopean pixels
MAX_ROUNDS = 4096        # propagation launches before a region is taken as it stands


class InitError(ValueError):
    """No foreground could be found from the given initialisation."""


@dataclass(frozen=True)
class Point:
    """A left-view pixel on the object (a click): ``x`` to the right, ``y`` down, 0-based."""
    x: float
    y: float


@dataclass(frozen=True)
class Box:
    """A left-view box around the object (a detector's output): corners ``(x0, y0)`` and
    ``(x1, y1)``, 0-based pixels, ``x0 < x1``, ``y0 < y1``."""
    x0: float
    y0: float
    x1: float
    y1: float


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


def mask_ellipse(mask: np.ndarray, spill: float = REGION_SPILL) -> tuple:
    """The ellipse of the bounding box of ``mask``, radii widened by ``spill``."""
    ys, xs = np.nonzero(mask)
    return box_ellipse(Box(float(xs.min()), float(ys.min()), float(xs.max()) + 1.0,
                           float(ys.max()) + 1.0), spill)


@ti.data_oriented
class InitialRegion:
    """Fields and kernels that find the initial foreground from the first consensus."""

    def __init__(self, pool, H: int, W: int):
        self.H, self.W = H, W
        self.d = pool.field(ti.f32, (H, W))         # d-bar where confident, else -1
        self.d_hi = pool.field(ti.f32, (H, W))    # d-bar's largest over a 5x5 window
        self.label = pool.field(ti.i32, (H, W))     # region id, -1 outside
        self.changed = pool.field(ti.i32, ())
        self.info = {}

    # ------------------------------------------------------------------ kernels
    @ti.kernel
    def load(self, mean: ti.template(), precision: ti.template()):
        for y, x in self.d:
            self.d[y, x] = mean[y, x] if precision[y, x] > 0 else -1.0

    @ti.kernel
    def mark_near(self, window: ti.i32, contrast: ti.f32):
        """Label each near pixel with its own index (Sec. 'auto' of the module doc).  The
        minima run over d-bar's 5x5 maxima, so a few stray low matches do not pull the
        ground down."""
        for y, x in self.d:
            hi = -1.0
            for v, u in ti.ndrange((y - 2, y + 3), (x - 2, x + 3)):
                if 0 <= v < self.H and 0 <= u < self.W:
                    hi = ti.max(hi, self.d[v, u])
            self.d_hi[y, x] = hi
        for y, x in self.d:
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

    @ti.kernel
    def propagate(self):
        """Each labelled pixel takes the largest label among its labelled 4-neighbours."""
        for y, x in self.label:
            own = self.label[y, x]
            if own >= 0:
                best = own
                for k in ti.static(range(4)):
                    dy, dx = ti.static(((0, 1), (0, -1), (1, 0), (-1, 0))[k])
                    v, u = y + dy, x + dx
                    if 0 <= v < self.H and 0 <= u < self.W:
                        best = ti.max(best, self.label[v, u])
                if best != own:
                    self.label[y, x] = best
                    self.changed[None] = 1

    @ti.kernel
    def seed(self, sy: ti.i32, sx: ti.i32):
        for y, x in self.label:
            self.label[y, x] = 1 if (y == sy and x == sx) else -1

    @ti.kernel
    def grow(self, seed_d: ti.f32, tolerance: ti.f32, step: ti.f32):
        """Pixels next to the region whose d-bar is close to the seed's and the neighbour's
        join it."""
        for y, x in self.label:
            d = self.d[y, x]
            if self.label[y, x] < 0 and d >= 0 and ti.abs(d - seed_d) <= tolerance:
                for k in ti.static(range(4)):
                    dy, dx = ti.static(((0, 1), (0, -1), (1, 0), (-1, 0))[k])
                    v, u = y + dy, x + dx
                    if 0 <= v < self.H and 0 <= u < self.W:
                        if self.label[v, u] == 1 and ti.abs(self.d[v, u] - d) <= step:
                            self.label[y, x] = 1
                            self.changed[None] = 1

    def until_stable(self, launch) -> int:
        for rounds in range(1, MAX_ROUNDS + 1):
            self.changed[None] = 0
            launch()
            if self.changed[None] == 0:
                return rounds
        return MAX_ROUNDS

    # ------------------------------------------------------------------ the choices
    def find(self, init, mean, precision) -> tuple:
        """The initial region for ``init`` (``"auto"``, :class:`Point` or :class:`Box`) as
        ``(ellipse, frame)`` for :class:`~lss_kernels.Solver`; fills :attr:`info`.

        ``mean`` and ``precision`` are the first consensus (cyclopean pixels)."""
        if isinstance(init, Box):
            self.info = {"kind": "box", "box": [init.x0, init.y0, init.x1, init.y1]}
            ellipse = box_ellipse(init)
            self.info["ellipse_left"] = list(ellipse)
            return ellipse, "left"
        self.load(mean, precision)
        d = self.d.to_numpy()
        if isinstance(init, Point):
            mask = self._point(init, d)
        else:
            mask = self._auto(d)
        ellipse = mask_ellipse(mask)
        self.info["ellipse_cyclopean"] = list(ellipse)
        return ellipse, "cyclopean"

    def _point(self, point, d):
        H, W = self.H, self.W
        y = int(round(point.y))
        xc = int(round(point.x))
        for _ in range(3):                       # left view -> cyclopean: x_c = x - c(x_c)
            c = max(float(d[y, xc]), 0.0)
            xc = int(round(min(max(point.x - c, 0.0), W - 1.0)))
        patch = d[max(y - 3, 0):y + 4, max(xc - 3, 0):xc + 4]
        patch = patch[patch >= 0]
        if patch.size == 0:
            raise InitError(f"init: no confident match near the point ({point.x}, {point.y}); "
                            f"pick a textured pixel on the object")
        seed_d = float(np.median(patch))
        near = d[d >= 0]
        tolerance = max(CONTRAST, 0.5 * (seed_d - float(np.percentile(near, 10))))
        self.seed(y, xc)
        self.d[y, xc] = seed_d
        rounds = self.until_stable(lambda: self.grow(seed_d, tolerance, STEP))
        mask = self.label.to_numpy() == 1
        self.info = {"kind": "point", "point": [point.x, point.y], "seed_cyclopean":
                     [xc, y], "seed_disparity": 2.0 * seed_d, "tolerance_px": 2.0 * tolerance,
                     "area": int(mask.sum()), "rounds": rounds}
        if mask.sum() < MIN_AREA * H * W:
            raise InitError(f"init: the region under the point ({point.x}, {point.y}) has "
                            f"{int(mask.sum())} pixels, fewer than {MIN_AREA:.1%} of the "
                            f"image: no object found there")
        return mask

    def _auto(self, d):
        H, W = self.H, self.W
        self.mark_near(max(int(WINDOW * W), 1), CONTRAST)
        rounds = self.until_stable(self.propagate)
        mask, facts = pick_region(self.label.to_numpy(), int(MIN_AREA * H * W))
        self.info = {"kind": "auto", "contrast_px": 2.0 * CONTRAST, "window": int(WINDOW * W),
                     "rounds": rounds, **facts}
        if mask is None:
            raise InitError("init auto: no foreground found (no region stands nearer than "
                            "its surroundings); give --init point:X,Y, box:X0,Y0,X1,Y1 or "
                            "an ellipse")
        return mask
