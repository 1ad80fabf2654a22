"""Where the disparity grid starts: at 2 px as in the authors' release, or at 0 px for a pair
whose background lies farther.

The cost volumes sample integer cyclopean disparities ``c = 1 .. c_max`` (the authors'
release; left-view disparity ``2c``), so the smallest disparity the model can hold is 2 px.
A background farther than that is fitted at 2 px, with its occluded strip too short, and one
at 3 px lies within a plane of the floor, where a message has no plane below to be refined
with.

For such a pair the solver moves each view ``SHIFT`` pixels apart before the costs,
``left'(x) = left(x - SHIFT)`` and ``right'(x) = right(x + SHIFT)``: a user disparity ``d`` is
the model's ``d + 2 SHIFT``, so ``c = 1`` is ``d = 0``.  The model's plane ``c + 1`` then
compares the pixels of the unmoved plane ``c``; the cyclopean frame ``(x_left + x_right) / 2``
is the same, so phi, Theta and the consensus need no move, only their disparities less
``2 SHIFT``; the model's left view lies ``SHIFT`` columns right of the user's, so left-view
inputs (an ellipse, a mask, a point, a box) move right on the way in and left-view outputs
back on the way out.  Disparity jumps, Delta-theta and the occluded extents are the same.

Which pairs, with ``Params.zero_floor`` (on by default): those whose first consensus (Eq. 7
with no prior, the map the automatic start reads too) puts at least ``FLOOR_SHARE`` of its
confident pixels near the grid's floor (below ``FLOOR_C``: 4 px).  Such a pair is loaded
again into fields of one plane more, ``c_max = ceil(d_max / 2) + 1``, and searched over
``0 .. 2 ceil(d_max / 2)``; every other pair keeps the authors' grid and fields, bit for
bit: fields of one plane more would move every pair's first consensus a little, through the
levels' min-max normalisation and the messages' sigma.  The floor share of paper15's pairs is
0.00-0.06 (none moves); of rendered pairs with the background at 0-3 px, 0.72-0.82.
"""
import numpy as np

__all__ = ["FLOOR_C", "FLOOR_SHARE", "SHIFT", "floor_share", "info_to_user", "model_pair",
           "search_range", "to_model_left", "to_model_start", "to_user_left"]

#: Columns each view moves for a pair searched from 0 px.
SHIFT = 1
#: Cyclopean disparity below which a first-consensus pixel is at the floor (within one plane
#: of it: 4 px; a layer at 3 px needs the plane below to refine its messages).
FLOOR_C = 2.0
#: Share of the confident pixels at the floor that moves the grid down to 0 px.
FLOOR_SHARE = 0.15


def floor_share(mean: np.ndarray, precision: np.ndarray) -> float:
    """The share of the pixels with a consensus (``precision > 0``) whose mean (cyclopean
    disparity of the unmoved grid) is below ``FLOOR_C``."""
    confident = precision > 0
    n = int(confident.sum())
    return float((mean[confident] < FLOOR_C).sum()) / n if n else 0.0


def search_range(mean: np.ndarray, precision: np.ndarray, zero_floor: bool, c_max: int) -> dict:
    """Where to search a pair whose first consensus (unmoved grid of ``c_max`` candidates) is
    ``mean``, ``precision``: ``from_zero`` with ``zero_floor`` and a :func:`floor_share` of at
    least ``FLOOR_SHARE``; the user's disparities searched, ``[0 or 2, 2 c_max]``."""
    share = floor_share(mean, precision)
    low = bool(zero_floor and share >= FLOOR_SHARE)
    return {"zero_floor": zero_floor, "from_zero": low, "floor_share": share,
            "disparities": [0.0 if low else 2.0, 2.0 * c_max]}


def _columns(image: np.ndarray, move: int) -> np.ndarray:
    """``image`` moved right by ``move`` columns (left if negative), edge columns repeated."""
    cols = np.clip(np.arange(image.shape[1]) - move, 0, image.shape[1] - 1)
    return np.ascontiguousarray(image[:, cols])


def model_pair(left: np.ndarray, right: np.ndarray, shift: int) -> tuple:
    """The pair the model matches: ``left'(x) = left(x - shift)``, ``right'(x) = right(x +
    shift)``, edge columns repeated (as the kernels clamp image coordinates)."""
    return _columns(left, shift), _columns(right, -shift)


def to_model_left(plane: np.ndarray, shift: int) -> np.ndarray:
    """A left-view plane of the user's in the model's left view."""
    return _columns(plane, shift)


def to_user_left(plane: np.ndarray, shift: int) -> np.ndarray:
    """A left-view plane of the model's in the user's left view (the last column repeated)."""
    return _columns(plane, -shift)


def to_model_start(init, shift: int):
    """A :class:`~lss_kernels.start_types.Point` or :class:`~lss_kernels.start_types.Box` of
    the user's left view in the model's; ``"auto"`` as it is."""
    from ..start_types import Box, Point
    if isinstance(init, Point):
        return Point(init.x + shift, init.y)
    if isinstance(init, Box):
        return Box(init.x0 + shift, init.y0, init.x1 + shift, init.y1)
    return init


def info_to_user(info: dict, shift: int) -> dict:
    """An initial region's report (:attr:`lss_kernels.model.init.InitialRegion.info`, in the
    model's left view and disparities) in the user's: ``seed_disparity`` less ``2 shift``;
    ``point``, ``box`` and ``ellipse_left`` ``shift`` columns left (nested reports too)."""
    out = {}
    for key, value in info.items():
        if isinstance(value, dict):
            value = info_to_user(value, shift)
        elif key == "seed_disparity":
            value = value - 2 * shift
        elif key in ("point", "ellipse_left"):
            value = [value[0] - shift] + list(value[1:])
        elif key == "box":
            value = [value[0] - shift, value[1], value[2] - shift, value[3]]
        out[key] = value
    return out
