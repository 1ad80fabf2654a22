"""A whole photo: the chosen object solved in a window around it, with whatever stands in
front of it as a layer of its own.

The paper's scenes are crops: one object over one background.  In a whole photo the object
is one of many, so:

* the solve works in a :class:`Window` around the start (a point, a box, an ellipse or a
  mask), wide enough to hold the object's occluded strip and the band scored around its
  boundary: the start's box plus ``MARGIN`` pixels on every side and ``d_max`` more to the
  left (the strip lies left of the object, and the background there needs its matches in the
  right view).  A point has no box: its start is found (:mod:`lss_kernels.model.init`) in
  a window ``2 REACH`` pixels square around it, and the solve's first window is the one
  around the region found.  The fewer other objects and surfaces a window holds, the better
  one quadratic background explains what lies behind the object.  Pixels far from the
  object cost nothing: the time grows with the object, not with the photo;
* when the solved object comes within ``TOUCH`` pixels of a side of the window that is not
  the photo's border, the window grows to hold it (its box plus the margins, the left one
  ``MARGIN`` plus the object's largest disparity) and the solve runs again from the object
  found, up to ``MAX_WINDOWS`` windows; a point stays the pair's anchor in every window
  (the checks after a solve keep the object that holds it:
  :func:`~lss_kernels.checks.outline.on_layers`);
* after each window's solve from a point, a neighbour just behind the object that the solve
  took with it is split off (:func:`~lss_kernels.checks.split.split_neighbour`, recorded in
  ``result.recovery["neighbour"]``);
* the window's solve is :func:`lss_kernels.solve` with the given parameters; the third layer
  (``Params.front_margin``, :mod:`lss_kernels.model.front`: what stands in front of the
  object leaves both fits and the data term) is off unless they turn it on.

Outputs are the photo's size: outside the last window the disparity is ``inf`` (unknown, as in
Middlebury's files), the masks are false, the confidence 0 and the layer map holds ``OUTSIDE``; ``phi`` and the
consensus are the window's (``Result.window`` says where).  ``"auto"`` has no object to place
a window around: it solves the whole photo.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from .start_types import Box, Point

__all__ = ["KEEP_REACH", "MARGIN", "MAX_WINDOWS", "OUTSIDE", "REACH", "TOUCH", "Window",
           "solve_in_windows", "solve_photo", "solve_photo_cached"]

#: Half side of a point's first window, pixels.
REACH = 128
#: The window's margin around the object (the scored band is 20 px), pixels.
MARGIN = 32
#: The object this close to a side of the window (not the photo's border) grows it, pixels.
TOUCH = 3
#: At most this many windows (solves) per photo.
MAX_WINDOWS = 3
#: A point's located window is solved when its area is below this share of the point's
#: reach; a larger one is hardly smaller, and the reach is solved from the set-up that
#: located the start.
KEEP_REACH = 0.8
#: The layer map's value outside the window (not solved).
OUTSIDE = 255


@dataclass(frozen=True)
class Window:
    """A window of the left view, columns ``x0 .. x1 - 1`` and rows ``y0 .. y1 - 1``."""

    x0: int
    y0: int
    x1: int
    y1: int

    @classmethod
    def around(cls, box, left, shape) -> "Window":
        """The box ``(x0, y0, x1, y1)`` (inclusive, may be fractional) plus ``MARGIN`` on every
        side and ``left`` more to the left, inside an image of ``shape`` ``(H, W)``."""
        H, W = shape
        bx0, by0, bx1, by1 = box
        return cls(max(0, int(math.floor(bx0 - MARGIN - left))),
                   max(0, int(math.floor(by0 - MARGIN))),
                   min(W, int(math.ceil(bx1 + MARGIN)) + 1),
                   min(H, int(math.ceil(by1 + MARGIN)) + 1))

    def union(self, other: "Window") -> "Window":
        return Window(min(self.x0, other.x0), min(self.y0, other.y0),
                      max(self.x1, other.x1), max(self.y1, other.y1))

    @property
    def shape(self) -> tuple:
        return self.y1 - self.y0, self.x1 - self.x0

    def crop(self, image: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(image[self.y0:self.y1, self.x0:self.x1])

    def paste(self, part: np.ndarray, shape: tuple, fill) -> np.ndarray:
        """``part`` (the window's) in an array of the photo's ``shape``, ``fill`` elsewhere."""
        out = np.full(shape + part.shape[2:], fill, dtype=part.dtype)
        out[self.y0:self.y1, self.x0:self.x1] = part
        return out

    def sides_touched(self, mask: np.ndarray, shape: tuple) -> list:
        """The sides (``"left"``, ``"top"``, ``"right"``, ``"bottom"``) of the window that
        ``mask`` (the window's) comes within ``TOUCH`` pixels of, leaving out the sides on
        the photo's border."""
        H, W = shape
        h, w = self.shape
        t = TOUCH
        sides = {"left": (self.x0 > 0, mask[:, :t]), "top": (self.y0 > 0, mask[:t, :]),
                 "right": (self.x1 < W, mask[:, max(w - t, 0):]),
                 "bottom": (self.y1 < H, mask[max(h - t, 0):, :])}
        return [name for name, (inside, strip) in sides.items() if inside and strip.any()]

    def around_mask(self, mask: np.ndarray, left, shape) -> "Window":
        """The window (:meth:`around`) of the box of ``mask``, a non-empty mask of this
        window, in the photo of ``shape``."""
        ys, xs = np.nonzero(mask)
        return Window.around((xs.min() + self.x0, ys.min() + self.y0, xs.max() + self.x0,
                              ys.max() + self.y0), left, shape)

    @property
    def area(self) -> int:
        return (self.y1 - self.y0) * (self.x1 - self.x0)

    def as_tuple(self) -> tuple:
        return (self.x0, self.y0, self.x1, self.y1)


def _start_box(init, shape) -> tuple | None:
    """The box ``(x0, y0, x1, y1)`` a start covers (left view), or None for ``"auto"``."""
    H, W = shape
    if isinstance(init, Point):
        return (init.x - REACH, init.y - REACH, init.x + REACH, init.y + REACH)
    if isinstance(init, Box):
        return (init.x0, init.y0, init.x1, init.y1)
    if isinstance(init, np.ndarray):
        ys, xs = np.nonzero(init)
        return (xs.min(), ys.min(), xs.max(), ys.max())
    if isinstance(init, tuple):
        cx, cy, rx, ry = init
        return (cx - rx, cy - ry, cx + rx, cy + ry)
    return None


def _in_window(init, window: Window):
    """A start of the photo's left view in the window's."""
    if isinstance(init, str):                        # "auto"
        return init
    if isinstance(init, Point):
        return Point(init.x - window.x0, init.y - window.y0)
    if isinstance(init, Box):
        return Box(init.x0 - window.x0, init.y0 - window.y0, init.x1 - window.x0,
                   init.y1 - window.y0)
    if isinstance(init, np.ndarray):
        return window.crop(init)
    cx, cy, rx, ry = init
    return (cx - window.x0, cy - window.y0, rx, ry)


def _photo_result(result, window: Window, shape: tuple, windows: list):
    """The window's :class:`~lss_kernels.Result` at the photo's size (module text)."""
    layers = result.layers if result.layers is not None else result.foreground.astype(np.uint8)
    timings = dict(result.timings)
    timings["windows_total"] = sum(w["seconds"] for w in windows)
    return replace(
        result,
        disparity=window.paste(result.disparity, shape, np.float32(np.inf)),
        surface=window.paste(result.surface, shape, np.float32(np.inf)),
        occlusion=window.paste(result.occlusion, shape, False),
        foreground=window.paste(result.foreground, shape, False),
        layers=window.paste(layers.astype(np.uint8), shape, np.uint8(OUTSIDE)),
        confidence=(None if result.confidence is None else
                    window.paste(result.confidence, shape, np.float32(0.0))),
        window=window.as_tuple(), timings=timings,
        recovery={**result.recovery, "windows": windows})


def solve_in_windows(run, left, right, d_max, init, locate=None):
    """The window loop of the module text around ``run(left, right, init, anchor) ->
    (result, facts)``, a two-layer-or-more solve of a crop (``anchor``: a point's pixel in
    the crop, which the object must hold, also when a grown window starts from the object
    found; else None.  ``facts``: the solve's left image, its initial foreground in the left
    view and its start report, or None).  ``left``, ``right``
    are the photo's checked images, ``init`` its checked start (left view).  ``locate(left,
    right, init) -> mask``: the initial foreground (left view) a solve of the crop would start
    from; given, a point's first window is the one around that region (module text).

    Returns ``(result, facts)`` at the photo's size (:func:`_photo_result`); ``result.recovery
    ["windows"]`` lists the windows solved, after a point's located start
    (``{"window", "start", "seconds"}``) when ``locate`` is given."""
    shape = left.shape[:2]
    box = _start_box(init, shape)
    if box is None:                                  # "auto": no object to place a window
        window = Window(0, 0, shape[1], shape[0])
    else:
        window = Window.around(box, d_max, shape)
    windows = []
    if isinstance(init, Point) and locate is not None:
        window = _located(locate, left, right, d_max, init, window, windows)
    start, solved = init, 0
    while True:
        t0 = time.perf_counter()
        anchor = _in_window(init, window) if isinstance(init, Point) else None
        result, facts = run(window.crop(left), window.crop(right), _in_window(start, window),
                            anchor)
        touched = window.sides_touched(result.foreground, shape)
        solved += 1
        windows.append({"window": list(window.as_tuple()), "touched": touched,
                        "seconds": round(time.perf_counter() - t0, 3)})
        if not touched or solved == MAX_WINDOWS or not result.foreground.any():
            break
        d_object = float(np.max(result.disparity[result.foreground]))
        grown = window.union(window.around_mask(result.foreground, d_object, shape))
        if grown == window:
            break
        start = window.paste(result.foreground, shape, False)
        window = grown
    if facts is not None:
        image, initial, info = facts
        facts = (left, None if initial is None else window.paste(initial, shape, False),
                 info)
    return _photo_result(result, window, shape, windows), facts


def _located(locate, left, right, d_max, point, window, windows) -> Window:
    """The window around the region a point's solve starts from, found by ``locate`` in
    ``window``; ``window`` itself when no region is found or when the region's window
    covers ``KEEP_REACH`` of its area or more (the set-up made to locate the start is
    then the solve's).  The step is added to ``windows``."""
    t0 = time.perf_counter()
    region = locate(window.crop(left), window.crop(right), _in_window(point, window))
    found = window
    if region is not None and region.any():
        found = window.around_mask(region, d_max, left.shape[:2])
        if found.area >= KEEP_REACH * window.area:      # not worth a second set-up
            found = window
    windows.append({"window": list(window.as_tuple()), "start": list(found.as_tuple()),
                    "seconds": round(time.perf_counter() - t0, 3)})
    return found


def solve_photo_cached(cache, left, right, d_max, init, params, callback=None):
    """:func:`solve_photo` with the solvers of ``cache`` (a
    :class:`~lss_kernels.solver_cache.SolverCache`, left open); returns ``(result, facts)``
    as :func:`solve_in_windows`."""
    from .checks.split import split_neighbour
    from .checks.validate import check_inputs
    left, right, d_max, init = check_inputs(left, right, d_max, init, "left", params)

    def run(l, r, start, anchor):
        result, facts = cache.solve_pair(l, r, d_max, start, "left", params, callback, anchor)
        if anchor is not None:
            result.recovery["neighbour"] = split_neighbour(result, (anchor.x, anchor.y), l, r)
        return result, facts

    def locate(l, r, start):
        return cache.locate(l, r, d_max, start, params)
    try:
        return solve_in_windows(run, left, right, d_max, init, locate)
    finally:
        cache.forget()


def solve_photo(left, right, d_max, init, params=None, arch=None, callback=None):
    """Solve the object under ``init`` in a whole photo (module text).

    Arguments as for :func:`lss_kernels.solve` (``init`` in the left view: a
    :class:`~lss_kernels.Point`, a :class:`~lss_kernels.Box`, an ellipse ``(cx, cy, rx,
    ry)``, a boolean mask or ``"auto"``); ``Params(front_margin=4.0)`` adds the third layer.

    Returns
    -------
    Result
        At the photo's size: ``layers`` (0 behind the object, 1 the object, 2 in front of it
        with the third layer, ``OUTSIDE`` beyond the window), ``window`` ``(x0, y0, x1, y1)``, and
        ``recovery["windows"]``: each window solved, the sides the object touched, seconds.
    """
    from .checks.validate import check_params
    from .kernels import backend
    from .solver_cache import SolverCache
    params = check_params(params)
    if arch is not None:
        backend.init(arch=arch)
    cache = SolverCache()
    try:
        return solve_photo_cached(cache, left, right, d_max, init, params, callback)[0]
    finally:
        cache.close()
