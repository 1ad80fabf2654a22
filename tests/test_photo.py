"""A whole photo (lss_kernels.photo): the window around the start, its growth as the object
reaches its sides, and the result pasted at the photo's size."""
import numpy as np
import pytest

from lss_kernels import Box, Params, Point, Result
from lss_kernels.photo import MARGIN, MAX_WINDOWS, OUTSIDE, REACH, Window, solve_in_windows

#: The third layer's margin in the tests, left-view pixels.
FRONT_MARGIN = 4.0

SHAPE = (300, 500)


def _result(foreground, disparity=10.0):
    """A stand-in for a solve's :class:`Result` of a window."""
    h, w = foreground.shape
    d = np.full((h, w), 2.0, np.float32)
    d[foreground] = disparity
    zeros = np.zeros((h, w), np.float32)
    return Result(disparity=d, surface=d.copy(), occlusion=np.zeros((h, w), bool),
                  foreground=foreground, confidence=np.ones((h, w), np.float32), phi=zeros, theta_fg=np.zeros(6), theta_bg=np.zeros(6),
                  consensus_mean=zeros, consensus_sigma=zeros, iterations=1, stop_reason="test",
                  layers=foreground.astype(np.uint8))


def test_a_window_holds_the_start_its_margins_and_the_strip_to_the_left():
    w = Window.around((200, 100, 260, 150), 40, SHAPE)
    assert (w.x0, w.y0, w.x1, w.y1) == (200 - MARGIN - 40, 100 - MARGIN, 260 + MARGIN + 1,
                                        150 + MARGIN + 1)
    clipped = Window.around((5, 5, 490, 295), 40, SHAPE)
    assert clipped.as_tuple() == (0, 0, 500, 300)


def test_the_sides_touched_leave_out_the_photos_border():
    w = Window(0, 50, 200, 150)
    mask = np.zeros(w.shape, bool)
    mask[40:60, 0] = True              # on the photo's left border: not a side to grow
    mask[10, -1] = True                # the window's right side, inside the photo
    assert w.sides_touched(mask, SHAPE) == ["right"]
    mask[0, 50] = True
    assert w.sides_touched(mask, SHAPE) == ["top", "right"]


def test_the_window_follows_the_object_until_it_holds_it():
    # a 241 x 331 object under a point at (300, 200) of a 600 x 400 photo, d_max 64: the first
    # window (the point +- REACH, MARGIN around, d_max more to the left) cuts its right
    # side; the second adds the object's box with the margins (its disparity, 30 px, to the
    # left) and holds it
    shape = (400, 600)
    left = np.zeros(shape + (3,), np.float32)
    truth = np.zeros(shape, bool)
    truth[60:301, 150:481] = True
    first = Window(300 - REACH - MARGIN - 64, 200 - REACH - MARGIN, 300 + REACH + MARGIN + 1,
                   200 + REACH + MARGIN + 1)
    second = Window(first.x0, 60 - MARGIN, 460 + MARGIN + 1, first.y1)
    calls = []

    def run(l, r, start, anchor):
        window = (first, second)[len(calls)]
        calls.append((l.shape[:2], start, anchor))
        return _result(window.crop(truth), disparity=30.0), None
    result, _ = solve_in_windows(run, left, left, 64.0, Point(300, 200))
    assert [c[0] for c in calls] == [first.shape, second.shape]
    assert calls[0][1] == Point(300 - first.x0, 200 - first.y0)
    # the second solve starts from the object found in the first, in its own window
    assert calls[1][1].shape == second.shape
    assert calls[1][1].sum() == first.crop(truth).sum()
    # ... and the object must still hold the click, in the second window's pixels
    assert [c[2] for c in calls] == [Point(300 - first.x0, 200 - first.y0),
                                     Point(300 - second.x0, 200 - second.y0)]
    assert result.window == second.as_tuple()
    assert [w["touched"] for w in result.recovery["windows"]] == [["right"], []]
    assert result.disparity.shape == shape and np.isinf(result.disparity[0, -1])
    assert np.array_equal(result.foreground, truth)
    assert (result.layers != OUTSIDE).sum() == second.shape[0] * second.shape[1]
    assert (result.confidence[result.layers == OUTSIDE] == 0).all()


def test_a_points_window_is_the_one_around_its_located_start():
    # the start found under a point at (300, 200) of a 600 x 400 photo is a 41 x 31 region:
    # the solve's window is that region's plus the margins (d_max to the left), not the
    # point's +- REACH
    shape = (400, 600)
    left = np.zeros(shape + (3,), np.float32)
    region = np.zeros(shape, bool)
    region[185:216, 280:321] = True
    reach = Window(300 - REACH - MARGIN - 64, 200 - REACH - MARGIN, 300 + REACH + MARGIN + 1,
                   200 + REACH + MARGIN + 1)
    tight = Window(280 - MARGIN - 64, 185 - MARGIN, 320 + MARGIN + 1, 215 + MARGIN + 1)
    located, solved = [], []

    def locate(l, r, start):
        located.append((l.shape[:2], start))
        return reach.crop(region)

    def run(l, r, start, anchor):
        solved.append((l.shape[:2], start))
        return _result(tight.crop(region)), None
    result, _ = solve_in_windows(run, left, left, 64.0, Point(300, 200), locate)
    assert located == [(reach.shape, Point(300 - reach.x0, 200 - reach.y0))]
    assert solved == [(tight.shape, Point(300 - tight.x0, 200 - tight.y0))]
    assert result.window == tight.as_tuple()
    assert result.recovery["windows"][0]["start"] == list(tight.as_tuple())
    assert np.array_equal(result.foreground, region)
    # a box is its own window: nothing to locate
    solved.clear()
    solve_in_windows(run, left, left, 64.0, Box(280, 185, 320, 215), locate)
    assert len(located) == 1 and solved[0][0] == tight.shape


def test_a_located_window_almost_as_large_as_the_reach_is_not_taken():
    # a start that fills most of the point's reach: the reach is solved (from the set-up
    # that located it), not a window hardly smaller
    left = np.zeros(SHAPE + (3,), np.float32)
    reach = Window.around((250 - REACH, 150 - REACH, 250 + REACH, 150 + REACH), 32.0, SHAPE)
    shapes = []

    def locate(l, r, start):
        region = np.zeros(l.shape[:2], bool)
        region[10:-10, 40:-10] = True
        return region

    def run(l, r, start, anchor):
        shapes.append(l.shape[:2])
        return _result(np.zeros(l.shape[:2], bool)), None
    result, _ = solve_in_windows(run, left, left, 32.0, Point(250, 150), locate)
    assert shapes == [reach.shape]
    assert result.recovery["windows"][0]["start"] == list(reach.as_tuple())


def test_a_point_with_no_start_found_keeps_its_reach():
    left = np.zeros(SHAPE + (3,), np.float32)
    shapes = []

    def run(l, r, start, anchor):
        shapes.append(l.shape[:2])
        return _result(np.zeros(l.shape[:2], bool)), None
    solve_in_windows(run, left, left, 32.0, Point(250, 150),
                     lambda l, r, start: np.zeros(l.shape[:2], bool))
    assert shapes == [Window.around((250 - REACH, 150 - REACH, 250 + REACH, 150 + REACH),
                                    32.0, SHAPE).shape]


def test_the_window_stops_growing_after_max_windows():
    left = np.zeros(SHAPE + (3,), np.float32)
    calls = []

    def run(l, r, start, anchor):         # an object that always fills its window
        calls.append(1)
        return _result(np.ones(l.shape[:2], bool)), None
    result, _ = solve_in_windows(run, left, left, 32.0, Box(200, 100, 240, 140))
    assert 1 < len(calls) <= MAX_WINDOWS


def test_auto_solves_the_whole_photo():
    left = np.zeros(SHAPE + (3,), np.float32)

    def run(l, r, start, anchor):
        assert start == "auto" and l.shape[:2] == SHAPE
        fg = np.zeros(SHAPE, bool)
        fg[100:150, 200:260] = True
        return _result(fg), None
    result, _ = solve_in_windows(run, left, left, 32.0, "auto")
    assert result.window == (0, 0, SHAPE[1], SHAPE[0])


def test_front_margin_is_checked():
    with pytest.raises(ValueError, match="front_margin"):
        Params(front_margin=-1.0)


def _rod_scene():
    """A 400 x 128 photo: an ellipse at 16 px crossed by a rod at 26 px, a box at 12 px far to
    its left, a wall at 6 px."""
    from lss_kernels.scenes import make_multi_scene
    return make_multi_scene(
        width=400, height=128, d_bg=6.0, noise=2 / 255, seed=3, clicked=0,
        objects=({"name": "object", "d": 16.0, "box": (300.0, 64.0, 42.0, 38.0),
                  "outline": "ellipse"},
                 {"name": "rod", "d": 26.0, "box": (294.0, 64.0, 90.0, 3.0), "angle": 75.0},
                 {"name": "box", "d": 12.0, "box": (40.0, 64.0, 20.0, 30.0)}))


@pytest.mark.slow
def test_a_whole_photo_from_a_click(ti_arch):
    from lss_kernels import metrics
    from lss_kernels.model.layers import FRONT, OBJECT
    from lss_kernels.photo import solve_photo
    scene = _rod_scene()
    result = solve_photo(scene.left, scene.right, scene.d_max, Point(*scene.init_point),
                         params=Params(front_margin=FRONT_MARGIN))
    # the window is the one around the start found under the click: it holds the object
    # with its margins, leaves out the box far to the left and ends short of the point's
    # +- REACH (the right border)
    x0, y0, x1, y1 = result.window
    ys, xs = np.nonzero(scene.fg_left)
    assert 60 < x0 <= xs.min() - MARGIN and x1 >= xs.max() + MARGIN and x1 < 400
    assert (y0, y1) == (0, 128)
    assert result.disparity.shape == scene.fg_left.shape
    assert np.isinf(result.disparity[:, :x0]).all() and (result.layers[:, :x0] == OUTSIDE).all()
    assert set(np.unique(result.layers)) <= {0, OBJECT, FRONT, OUTSIDE}
    score = metrics.score(result.disparity, result.occlusion, scene)
    assert score["occ_f1"] > 0.8 and score["bad4"] < 5.0
    fg = result.foreground
    assert (fg & scene.fg_left).sum() / (fg | scene.fg_left).sum() > 0.85
    # the rod over the object is the layer in front, and never the object
    rod = (scene.layers_left == 2) & (result.layers != OUTSIDE)
    assert (result.layers[rod] == FRONT).mean() > 0.2
    assert not (result.foreground & (scene.layers_left == 2)).mean() > 0.02


@pytest.mark.slow
def test_with_nothing_in_front_the_third_layer_changes_no_bit(ti_arch):
    # the paper's two layers are the case of the third layer with no pixel in front: on the
    # easy scene (one object over one wall) the model and its outputs are bit-identical
    from lss_kernels import Solver
    from lss_kernels.scenes import make_scene
    scene = make_scene("easy", noise=0.01)
    results = []
    for margin in (0.0, FRONT_MARGIN):
        solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                        params=Params(front_margin=margin))
        results.append(solver.run())
        solver.close()
    two, three = results
    assert not (three.layers == 2).any()
    for name in ("disparity", "surface", "occlusion", "foreground", "phi", "layers"):
        assert np.array_equal(getattr(two, name), getattr(three, name)), name
    assert two.iterations == three.iterations


@pytest.mark.slow
def test_a_kept_reach_is_solved_from_the_set_up_that_located_the_start(ti_arch, monkeypatch):
    # the easy scene's object fills most of the image: the located window is the whole
    # image, the point's reach; its solve runs from the location's set-up (no set-up more
    # than a solve of the image makes) and gives that solve's answer, bit for bit
    from lss_kernels import Solver, solve
    from lss_kernels.photo import solve_photo
    from lss_kernels.scenes import make_scene
    set_ups = []
    load = Solver._load
    monkeypatch.setattr(Solver, "_load", lambda self, *a: set_ups.append(1) or load(self, *a))
    scene = make_scene("easy", noise=0.01)
    point = Point(68, 45)
    photo = solve_photo(scene.left, scene.right, scene.d_max, point)
    n_photo = len(set_ups)
    whole = solve(scene.left, scene.right, scene.d_max, point)
    assert n_photo == len(set_ups) - n_photo >= 1
    windows = photo.recovery["windows"]
    assert windows[0]["start"] == windows[0]["window"] == [0, 0, 128, 96]
    assert len(windows) == 2 and windows[1]["touched"] == []
    for name in ("disparity", "occlusion", "foreground", "phi"):
        assert np.array_equal(getattr(photo, name), getattr(whole, name)), name
    assert photo.iterations == whole.iterations
