"""The object's layer split in two (lss_kernels.checks.split): a neighbour just behind the
clicked object, which the solve took with it, on hand-made left-view maps."""
import numpy as np
import pytest

from lss_kernels import Result
from lss_kernels.checks import split
from lss_kernels.model.layers import BACKGROUND, OBJECT

H, W = 80, 120
#: The object's columns and rows, and the neighbour's left of it (they meet at column 60).
OBJECT_BOX = (slice(10, 70), slice(60, 100))
NEIGHBOUR_BOX = (slice(15, 65), slice(20, 60))
CLICK = (80, 40)


def _cyclopean(disparity):
    """A left-view disparity map in the cyclopean frame: each pixel at column ``x - d / 2``
    (the nearer where two land on one column), the columns none lands on from their left
    neighbour."""
    out = np.full((H, W), np.nan)
    for y in range(H):
        for x in range(W):
            c = int(round(x - disparity[y, x] / 2.0))
            if 0 <= c < W and not disparity[y, x] <= out[y, c]:
                out[y, c] = disparity[y, x]
        for c in range(W):
            if np.isnan(out[y, c]):
                out[y, c] = out[y, c - 1] if c > 0 else disparity[y, 0]
    return out.astype(np.float32)


def _result(disparity, foreground, consensus=None):
    """A solve's :class:`Result` with the output ``disparity`` and the consensus mean of
    ``consensus`` (a left-view map; default ``disparity``) in the cyclopean frame."""
    zeros = np.zeros((H, W), np.float32)
    mean = _cyclopean(disparity if consensus is None else consensus)
    return Result(disparity=disparity.astype(np.float32), surface=disparity.astype(np.float32),
                  occlusion=np.zeros((H, W), bool), foreground=foreground,
                  confidence=np.ones((H, W), np.float32), phi=zeros, theta_fg=np.zeros(6),
                  theta_bg=np.zeros(6), consensus_mean=mean, consensus_sigma=zeros,
                  iterations=1, stop_reason="test", layers=foreground.astype(np.uint8))


def _swallowed(near=36.0, far=33.0, ramp=8, centre=60, consensus=None):
    """A wall at 10 px; the object at ``near`` and a neighbour at ``far`` left of it, both
    taken as the object, with the refinement's ramp between them over ``ramp`` columns
    about ``centre`` (60: where they meet); the consensus that of ``consensus`` (default:
    the truth, no ramp)."""
    d = np.full((H, W), 10.0)
    fg = np.zeros((H, W), bool)
    d[NEIGHBOUR_BOX] = far
    d[OBJECT_BOX] = near
    fg[NEIGHBOUR_BOX] = fg[OBJECT_BOX] = True
    truth = d.copy()
    both = NEIGHBOUR_BOX[0]
    columns = np.arange(centre - ramp // 2, centre + ramp // 2)
    d[both, columns] = far + (near - far) * (columns - columns[0] + 0.5) / ramp
    return _result(d, fg, truth if consensus is None else consensus)


def _pair(near=36, far=33):
    """The left and right images of the truth of :func:`_swallowed`: a texture of random
    colours in the left view, each pixel seen by the right camera at ``x - d`` where no
    nearer pixel lands (the right image's other pixels a texture of their own)."""
    rng = np.random.default_rng(3)
    d = np.full((H, W), 10)
    d[NEIGHBOUR_BOX] = far
    d[OBJECT_BOX] = near
    left = rng.random((H, W, 3))
    right = rng.random((H, W, 3))
    nearest = np.full((H, W), -1)
    for x in range(W):
        for y in range(H):
            r = x - d[y, x]
            if r >= 0 and d[y, x] > nearest[y, r]:
                nearest[y, r] = d[y, x]
                right[y, r] = left[y, x]
    return left, right


def test_a_neighbour_just_behind_leaves_the_object_and_the_object_hides_its_strip(ti_arch):
    left, right = _pair()
    r = _swallowed()
    facts = split.split_neighbour(r, CLICK, left, right)
    assert facts["split"], facts
    expected = np.zeros((H, W), bool)
    expected[OBJECT_BOX] = True
    neighbour = np.zeros((H, W), bool)
    neighbour[NEIGHBOUR_BOX] = True
    # the object less the neighbour; the last column of the neighbour's first and last rows
    # may stay (the edges move by the median of 5 rows')
    ends = np.zeros((H, W), bool)
    ends[[15, 64], 59] = True
    assert not (r.foreground ^ expected)[~ends].any()
    kept = r.foreground & ends
    assert (r.layers[neighbour & ~kept] == BACKGROUND).all()
    assert (r.layers[expected] == OBJECT).all()
    # each side of the border takes its own surface again (to RAMP), the ramp gone
    assert np.allclose(r.disparity[neighbour & ~kept], 33.0, atol=split.RAMP)
    assert np.allclose(r.disparity[OBJECT_BOX], 36.0, atol=split.RAMP)
    # a 3-px jump hides the 3 columns of the neighbour beside the object, on every row they
    # share, from the right camera (x_right = x - d: 57 - 33 = 60 - 36)
    hidden = np.zeros((H, W), bool)
    hidden[16:64, 57:60] = True
    assert np.array_equal(r.occlusion[16:64], hidden[16:64])
    assert not r.occlusion[:15].any() and not r.occlusion[65:].any()
    assert not r.occlusion[:, :56].any() and not r.occlusion[:, 60:].any()
    assert facts["hidden"] == r.occlusion.sum()
    assert (r.confidence[r.occlusion] == 0).all() and (r.confidence[~r.occlusion] == 1).all()


def test_the_pair_moves_the_edge_from_the_ramp_to_where_the_object_ends(ti_arch):
    # the matches of the object spread 2 px over the strip it hides (the ramp centred at
    # 58): the edges the fits meet at are 2 px left of the object's; the pair puts them back
    left, right = _pair()
    ramped = _swallowed(centre=58)
    r = _swallowed(centre=58, consensus=ramped.disparity)
    facts = split.split_neighbour(r, CLICK, left, right)
    assert facts["split"] and facts["edges_moved"] > 40, facts
    rows = slice(17, 63)
    assert (r.foreground[rows, 60:100]).all() and not r.foreground[rows, :60].any()
    hidden = np.zeros((H, W), bool)
    hidden[rows, 57:60] = True
    assert np.array_equal(r.occlusion[rows], hidden[rows])
    # without the pair, the strip lies where the fits meet
    r = _swallowed(centre=58, consensus=ramped.disparity)
    split.split_neighbour(r, CLICK)
    assert not r.occlusion[rows, 59].any()


def test_one_curved_surface_is_not_split():
    y, x = np.mgrid[0:H, 0:W]
    fg = np.zeros((H, W), bool)
    fg[10:70, 20:100] = True
    d = np.where(fg, 36.0 - 0.004 * ((x - 60.0) ** 2 + (y - 40.0) ** 2), 10.0)
    r = _result(d, fg)
    before = r.disparity.copy()
    facts = split.split_neighbour(r, CLICK)
    assert not facts["split"]
    assert np.array_equal(r.foreground, fg) and np.array_equal(r.disparity, before)


def test_a_fold_is_not_a_step():
    # two planes that meet along a ridge: the second lies behind the first's extension, but
    # not where they meet
    y, x = np.mgrid[0:H, 0:W]
    fg = np.zeros((H, W), bool)
    fg[10:70, 20:100] = True
    d = np.where(fg, np.where(x >= 60, 36.0, 36.0 - 0.3 * (60 - x)), 10.0)
    facts = split.split_neighbour(_result(d, fg), CLICK)
    assert not facts["split"] and "in front" in facts["why"], facts


def test_a_part_in_front_of_the_clicked_one_is_not_taken_for_a_neighbour_behind():
    r = _swallowed(near=33.0, far=36.0)
    facts = split.split_neighbour(r, CLICK)
    assert not facts["split"], facts
    assert r.foreground.sum() == (_swallowed().foreground).sum()


def test_a_part_that_only_d_bar_puts_behind_is_not_split():
    # on a striped object d-bar can take a wrong tooth over part of it: d-bar says 24 px
    # behind, the refined output says the object's own depth
    wrong = np.full((H, W), 10.0)
    wrong[NEIGHBOUR_BOX] = 12.0
    wrong[OBJECT_BOX] = 36.0
    r = _swallowed(near=36.0, far=36.0, consensus=wrong)
    facts = split.split_neighbour(r, CLICK)
    assert not facts["split"] and facts["why"] == "the output does not follow the two surfaces"


def test_a_neighbour_whose_matches_scatter_is_not_split():
    r = _swallowed()
    rng = np.random.default_rng(0)
    d = r.disparity.copy()
    d[NEIGHBOUR_BOX] += rng.uniform(-3.0, 3.0, d[NEIGHBOUR_BOX].shape)
    facts = split.split_neighbour(_result(d, r.foreground), CLICK)
    assert not facts["split"], facts


@pytest.mark.parametrize("click", [(5, 5), (40, 5), (W + 3, 40)])
def test_a_click_off_the_object_changes_nothing(click):
    r = _swallowed()
    facts = split.split_neighbour(r, click)
    assert facts == {"split": False, "why": "the click is not on the object"}


def test_an_object_of_a_few_pixels_is_left_alone():
    fg = np.zeros((H, W), bool)
    fg[38:43, 78:83] = True
    facts = split.split_neighbour(_result(np.where(fg, 36.0, 10.0), fg), CLICK)
    assert facts == {"split": False, "why": "the object is too small"}


def test_the_components_are_the_4_connected_pieces():
    mask = np.array([[1, 1, 0, 1],
                     [0, 1, 0, 1],
                     [1, 0, 0, 1],
                     [1, 1, 1, 1]], bool)
    labels = split._components(mask)
    assert ((labels >= 0) == mask).all()
    # the top-left pair with its lower pixel; the left column's foot joined to the right
    # column through the bottom row; the diagonal touch at (1, 1)-(2, 0) does not join
    assert labels[0, 0] == labels[0, 1] == labels[1, 1]
    assert labels[2, 0] == labels[3, 0] == labels[3, 3] == labels[0, 3]
    assert labels[0, 0] != labels[2, 0]


def test_a_whole_photos_solve_splits_its_window_at_the_click(ti_arch):
    # solve_photo's window loop with a stand-in for the solver cache whose solve swallowed
    # the neighbour: the photo's result holds the object alone, and says why
    from lss_kernels import Params, Point
    from lss_kernels.photo import solve_photo_cached

    class Cache:
        def locate(self, left, right, d_max, start, params):
            return None

        def solve_pair(self, left, right, d_max, start, frame, params, callback, anchor):
            assert (anchor.x, anchor.y) == CLICK
            return _swallowed(), None

        def forget(self):
            pass

    left, right = _pair()
    result, _ = solve_photo_cached(Cache(), left, right, 48, Point(*CLICK), Params())
    assert result.recovery["neighbour"]["split"]
    assert result.foreground[OBJECT_BOX].all() and not result.foreground[30:50, 20:50].any()
    assert result.occlusion[30:50, 57:60].all()
